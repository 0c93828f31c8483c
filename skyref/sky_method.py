"""What the audit's sky methods share, analytic models (:mod:`skyref.analytic`) and LUT methods
(:mod:`skyref.lut`) alike: a registry of them by name, timed precomputation, and the check every
lookup starts with.

A sky method is built from an :class:`~skyref.atmosphere.Atmosphere` and a wavelength grid,
:meth:`SkyMethod.precompute` builds its tables (timed), and ``radiance(directions,
sun_direction, observer_altitude_m)`` returns W m^-2 sr^-1 nm^-1 along unit view directions
in the observer's east-north-up frame, without the solar disk. :meth:`SkyMethod.operations`
counts what its lookups and per-view tables cost (:class:`Operations`), beside the timings of
skyref's own CPU implementation.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import inspect
import time
from dataclasses import dataclass, field

from tqdm import tqdm

from skyref._llvm import configure_libllvm
from skyref.validation import check_choice, check_view
from skyref.errors import ParameterError

__all__ = ["Operations", "Registry", "SkyMethod", "describe_operations"]


class Registry:
    """Sky methods by name: ``entries`` maps name -> (module, class name); classes are imported
    only when asked for. ``parameter`` names the choice in errors ("method", "model")."""

    def __init__(self, parameter: str, entries: dict):
        self.parameter = parameter
        self.entries = entries

    def cls(self, name: str):
        """The class registered as ``name`` (a ParameterError listing the names otherwise)."""
        module, cls = self.entries[check_choice(self.parameter, name, tuple(self.entries))]
        configure_libllvm()  # LUT methods import Dr.Jit, which loads libLLVM when it is imported
        return getattr(importlib.import_module(module), cls)

    def check_options(self, name: str, options, factory=None, parameter: str = "option",
                      required: bool = False) -> None:
        """Raise a ParameterError naming ``parameter`` if a name in ``options`` is not a keyword
        of the method's constructor (or of ``factory``, e.g. its ``from_tables``), listing the
        valid ones; with ``required``, also if one without a default is missing."""
        signature = inspect.signature(factory or self.cls(name))
        keywords = [p for p in signature.parameters.values()
                    if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)][2:]   # after atmosphere, wavelengths
        accepted = [p.name for p in keywords]
        if not any(p.kind is p.VAR_KEYWORD for p in signature.parameters.values()):
            for option in options:
                if option not in accepted:
                    raise ParameterError(parameter, option, ", ".join(accepted) or "none",
                                         f"not a parameter of {name}")
        if required:
            for p in keywords:
                if p.default is p.empty and p.name not in options:
                    raise ParameterError(parameter, sorted(options), f"all of {', '.join(accepted)} "
                                         "without a default", f"{p.name!r} missing")

    def build(self, name: str, atmosphere, wavelengths_nm="rgb", **options):
        """The method ``name`` for ``atmosphere``, not yet precomputed; ``options`` are its own
        (resolutions, orders, precision, ...) and are added to its ``options`` attribute, beside
        the settings it records itself, for reports."""
        self.check_options(name, options)
        method = self.cls(name)(atmosphere, wavelengths_nm, **options)
        method.options = {**getattr(method, "options", {}), **options}
        return method


@dataclass(frozen=True)
class Operations:
    """What a sky method's costs pay for, counted from its table sizes and algorithm (not timed),
    so that a user of another engine (a GPU shader) can read its CPU timings.

    ``tables``: name -> cells per axis of each table the lookups read (every cell holds all the
    wavelength channels). ``sky`` and ``ground``: what one view direction that misses (meets) the
    ground costs, what -> count; ``ground`` empty where the method has no ground. A *fetch* of a
    table is one interpolated read at one point, every channel at once (bilinear in a 2D table,
    trilinear in a 3D one: one ``texture()`` call where the channels fit a texel). ``per_view``:
    the work when the sun or the observer moves, what -> count. ``note``: what the counts leave
    out, in words.
    """

    tables: dict = field(default_factory=dict)
    sky: dict = field(default_factory=dict)
    ground: dict = field(default_factory=dict)
    per_view: dict = field(default_factory=dict)
    note: str = ""

    def to_dict(self) -> dict:
        """JSON-ready: table shapes as lists."""
        return {**dataclasses.asdict(self), "tables": {k: list(v) for k, v in self.tables.items()}}


def describe_operations(operations: dict) -> str:
    """One line of text for :meth:`Operations.to_dict`'s dict (as read back from JSON)."""

    def counts(items: dict) -> str:
        return ", ".join(f"{value:,} {what}" for what, value in items.items())

    parts = [f"per sky direction: {counts(operations['sky']) or 'nothing'}"]
    if operations["ground"]:
        parts.append(f"per ground direction: {counts(operations['ground'])}")
    if operations["per_view"]:
        parts.append(f"per view: {counts(operations['per_view'])}")
    if operations["tables"]:
        parts.append("tables: " + ", ".join(f"{name} {'x'.join(map(str, shape))}"
                                            for name, shape in operations["tables"].items()))
    return "; ".join(parts) + (f" ({operations['note']})" if operations["note"] else "")


class SkyMethod:
    """Base class: subclasses set :attr:`name` and implement ``_precompute()``; their
    ``radiance`` starts with :meth:`_checked_view`."""

    name = ""
    #: Wall time of the last :meth:`precompute`, s (None: not precomputed yet).
    precompute_seconds: float | None = None

    def precompute(self, progress: bool = False) -> float:
        """Build the method's tables; returns (and stores in :attr:`precompute_seconds`) the
        wall time, s, including the wait for work queued on the device (:meth:`_finish`). With
        ``progress``, a bar over the stages of :meth:`precompute_stages`."""
        start = time.perf_counter()
        with self._stage_bar(progress):
            self._precompute()
            self._finish()
        self.precompute_seconds = time.perf_counter() - start
        return self.precompute_seconds

    def precompute_stages(self) -> list:
        """The stages of :meth:`_precompute`, in order, for the progress bar; a method that has
        several calls :meth:`_stage_done` at the end of each."""
        return ["tables"]

    #: Called by :meth:`_precompute` with the name of each stage it finishes.
    _stage_done = staticmethod(lambda stage: None)

    @contextlib.contextmanager
    def _stage_bar(self, progress: bool):
        """While open, with ``progress``: :meth:`_stage_done` advances a bar over the stages."""
        if not progress:
            yield
            return
        with tqdm(total=len(self.precompute_stages()), desc=f"{self.name} precompute", unit="stage") as bar:
            self._stage_done = lambda stage: (bar.set_postfix_str(stage, refresh=False), bar.update(1))
            try:
                yield
            finally:
                del self._stage_done                     # back to the class's no-op
            bar.update(bar.total - bar.n)

    def _precompute(self):
        raise NotImplementedError

    def operations(self) -> Operations:
        """What a lookup and a new view cost, counted (see :class:`Operations`)."""
        raise NotImplementedError

    def _finish(self):
        """Wait for asynchronous work (Dr.Jit kernels); nothing for NumPy methods."""

    def _checked_view(self, directions, sun_direction, observer_altitude_m: float) -> tuple:
        """(directions (M, 3), sun (3,), altitude m) validated by
        :func:`~skyref.validation.check_view`, once the tables exist."""
        if self.precompute_seconds is None:
            raise RuntimeError(f"{self.name}: call precompute() before radiance()")
        return check_view(directions, sun_direction, observer_altitude_m)
