"""A batch grid: a base scene, axes to sweep and output settings, read from TOML.

::

    [base]
    scene = "../scenes/earth-clear.toml"     # relative to the grid file; or an inline [base.scene] table

    [axes]                                   # the Cartesian product of all axes is rendered
    "sun.zenith_deg" = [0, 30, 60, 80]
    "atmosphere.turbidity" = [2, 4]
    "atmosphere.constituents.aerosol.phase.g" = [0.7, 0.8]

    [output]
    directory = "out/batch"                  # relative to the grid file
    format = "spectral"                      # dataset holds spectral radiance, or "rgb" (linear sRGB)
    width = 64                               # optional camera overrides
    height = 32
    spp = 64                                 # samples per pixel, or instead:
    # target_relative_error = 0.01           # render each pixel until stderr/radiance <= 1% in every channel
    # max_spp = 16384                        #   (or this many per pixel: skyref.render.render_to_error)
    # dynamic_range = 1e-4                   #   pixels darker than this x the brightest: to target x that floor
    passes = 16
    seed = 0

    [[output.targets]]                       # optional: another target for the skies at these axis values
    where = { "sun.zenith_deg" = 80 }        #   (the first entry that matches wins)
    target_relative_error = 0.03

An axis is a path into the scene's TOML tables (``sun.zenith_deg``, ``observer.altitude_m``,
``atmosphere.preset``, ``atmosphere.turbidity``, ``atmosphere.ground_albedo``,
``atmosphere.constituents.<name>.<field>``, ...); each value replaces that entry of the base
scene (atmosphere entries override its preset as in a scene file); a value may be a whole table,
e.g. ``atmosphere = [{preset = "bruneton2017"}, {preset = "bruneton2017", turbidity = 6.0}]``
(the dataset labels such values by their JSON). Every axis value is checked
by building the scene it makes, before any work starts, and errors name the axis. In the
dataset an axis is a dimension named by :func:`dimension_name` (``sun.zenith_deg`` ->
``sun_zenith_deg``); two axes whose names would coincide are refused.

Skies are numbered in C order over the axes (the last axis fastest); round r of sky i (a
target-error render adds rounds until it is good enough) renders with seed
``(output.seed * MAX_ROUNDS + r) * count + i``: disjoint across skies and rounds, and the same
wherever the grid runs, so a grid gives the same data on any machine or cluster.
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import json
import math
import os
import re
import tomllib
from dataclasses import dataclass

import numpy as np

from skyref.validation import check_choice, check_fields, check_int, check_number
from skyref.errors import ParameterError
from skyref.render import check_image_size
from skyref.scene import Scene, load_scene

__all__ = ["FORMATS", "AXIS_TABLES", "MAX_SPP_LIMIT", "MAX_ROUNDS", "MAX_SKIES", "MAX_AXIS_VALUES", "OutputSettings",
           "dimension_name", "SkySpec", "Grid", "load_grid"]

FORMATS = ("spectral", "rgb")
#: Scene tables an axis may sweep (the camera, wavelengths and render settings fix the shape
#: and sampling of every sky and come from the base scene and [output]).
AXIS_TABLES = ("sun", "observer", "atmosphere")
#: Largest spp / max_spp accepted.
MAX_SPP_LIMIT = 1 << 20
#: Most rendering rounds of one sky (a target-error render).
MAX_ROUNDS = 8

#: Largest grid, skies, and longest axis, values: beyond them the grid's own bookkeeping (the
#: dataset's coordinates, the validation of every axis value) costs minutes and gigabytes
#: before the first sky. Split a larger sweep into several grids.
MAX_SKIES = 100_000
MAX_AXIS_VALUES = 10_000


@dataclass(frozen=True)
class OutputSettings:
    """Where and how skies are written and how many samples they get."""

    directory: str
    format: str = "spectral"
    width: int | None = None
    height: int | None = None
    spp: int | None = None
    target_relative_error: float | None = None
    max_spp: int = 16384
    passes: int = 16
    seed: int = 0
    #: ``[{"where": {axis path: value, ...}, "target_relative_error": x}, ...]``: skies at those
    #: axis values get target x instead (:meth:`Grid.target_relative_error`)
    targets: tuple = ()
    #: With a target: pixels darker than this fraction of the sky's brightest are held to an
    #: absolute error instead (:func:`skyref.render.stopping_error`); None: every pixel to the target
    dynamic_range: float | None = None

    def __post_init__(self):
        check_choice("output.format", self.format, FORMATS)
        for name in ("width", "height"):
            if getattr(self, name) is not None:
                check_int(f"output.{name}", getattr(self, name), 1, 1 << 14)
        if (self.spp is None) == (self.target_relative_error is None):
            raise ParameterError("output.spp", self.spp, "exactly one of output.spp and "
                                 "output.target_relative_error", "give one sample budget")
        if self.spp is not None:
            check_int("output.spp", self.spp, 2, MAX_SPP_LIMIT)
        if self.target_relative_error is not None:
            check_number("output.target_relative_error", self.target_relative_error, 1e-4, 1.0)
        check_int("output.max_spp", self.max_spp, 2, MAX_SPP_LIMIT)
        check_int("output.passes", self.passes, 2, 64)
        check_int("output.seed", self.seed, 0, 1 << 16)
        if self.spp is not None and self.spp < self.passes:
            raise ParameterError("output.spp", self.spp, f">= output.passes ({self.passes})", "too few samples")
        if self.targets and self.target_relative_error is None:
            raise ParameterError("output.targets", self.targets, "only with output.target_relative_error",
                                 "a fixed spp has no target to replace")
        if self.dynamic_range is not None:
            if self.target_relative_error is None:
                raise ParameterError("output.dynamic_range", self.dynamic_range, "only with "
                                     "output.target_relative_error", "a fixed spp has no target to relax")
            check_number("output.dynamic_range", self.dynamic_range, 0.0, 0.1, lo_open=True)
        for i, entry in enumerate(self.targets):
            name = f"output.targets[{i}]"
            if not isinstance(entry, dict) or set(entry) != {"where", "target_relative_error"}:
                raise ParameterError(name, entry, "a table with where = {axis = value, ...} and "
                                     "target_relative_error", "other entries or missing ones")
            if not isinstance(entry["where"], dict) or not entry["where"]:
                raise ParameterError(f"{name}.where", entry["where"], "a non-empty table of axis values", "empty")
            check_number(f"{name}.target_relative_error", entry["target_relative_error"], 1e-4, 1.0)


def dimension_name(path: str) -> str:
    """The dataset dimension of the axis at dotted ``path``: every character other than an ASCII
    letter, digit or underscore becomes an underscore (a valid CF and netCDF name; paths start
    with a scene table's name, so with a letter)."""
    return re.sub(r"[^A-Za-z0-9_]", "_", path)


def _key(value) -> str:
    """An axis value as JSON, to compare values that may be tables (and 80 with 80.0)."""
    return json.dumps(float(value) if isinstance(value, int) and not isinstance(value, bool) else value,
                      sort_keys=True)


def _set_path(data: dict, path: str, value) -> dict:
    """A deep copy of ``data`` with the entry at dotted ``path`` set to ``value``."""
    result = copy.deepcopy(data)
    node = result
    keys = path.split(".")
    for key in keys[:-1]:
        child = node.get(key)
        if not isinstance(child, dict):
            child = {}
            node[key] = child
        node = child
    node[keys[-1]] = value
    return result


@dataclass(frozen=True)
class SkySpec:
    """One sky of a grid: its index, id, axis values, scene (as a TOML dict) and seed."""

    index: int
    sky_id: str
    coordinates: dict
    scene: dict
    seed: int


@dataclass(frozen=True)
class Grid:
    """A base scene (TOML dict), axes (path -> list of values) and output settings."""

    base: dict
    axes: dict
    output: OutputSettings
    source: str = ""

    def __post_init__(self):
        if not self.axes:
            raise ParameterError("axes", {}, "at least one axis with values", "no axes")
        for path, values in self.axes.items():
            if path.split(".")[0] not in AXIS_TABLES:
                raise ParameterError(f"axes.{path}", values, "a path into one of the scene tables "
                                     + ", ".join(AXIS_TABLES), "not a sweepable entry")
            if not isinstance(values, list) or not values:
                raise ParameterError(f"axes.{path}", values, "a non-empty list of values", "empty or not a list")
            if len(values) > MAX_AXIS_VALUES:
                raise ParameterError(f"axes.{path}", f"{len(values):,} values", f"at most {MAX_AXIS_VALUES:,} values",
                                     "too many: split the sweep into several grids")
            if any(isinstance(v, list) for v in values):
                raise ParameterError(f"axes.{path}", values, "a list of numbers, strings or tables", "nested lists")
            if len({_key(v) for v in values}) != len(values):
                raise ParameterError(f"axes.{path}", values, "distinct values", "repeated value")
        names = [dimension_name(path) for path in self.axes]
        for path, name in zip(self.axes, names):
            if names.count(name) > 1:
                raise ParameterError(f"axes.{path}", name, "axis paths whose dataset dimension names (dots "
                                     "and other punctuation as underscores) differ", "two axes share that name")
        for i, entry in enumerate(self.output.targets):
            for path, value in entry["where"].items():
                if path not in self.axes:
                    raise ParameterError(f"output.targets[{i}].where.{path}", value, "one of the axes "
                                         + ", ".join(self.axes), "not an axis")
                if _key(value) not in {_key(v) for v in self.axes[path]}:
                    raise ParameterError(f"output.targets[{i}].where.{path}", value, "one of that axis' values "
                                         + ", ".join(map(str, self.axes[path])), "not among them")
        if len(self) > MAX_SKIES:
            raise ParameterError("axes", " x ".join(f"{len(v):,}" for v in self.axes.values()) + f" = {len(self):,} skies",
                                 f"at most {MAX_SKIES:,} skies", "too many: split the sweep into several grids "
                                 "(e.g. one per value of an axis)")

    # --- the skies --------------------------------------------------------------------------

    @property
    def shape(self) -> tuple:
        return tuple(len(v) for v in self.axes.values())

    def __len__(self) -> int:
        return math.prod(self.shape)

    def scene_dict(self, coordinates: dict) -> dict:
        """The base scene with the axes set to ``coordinates`` and the output overrides applied."""
        data = self.base
        for path, value in coordinates.items():
            data = _set_path(data, path, value)
        camera = dict(data.get("camera", {}))
        for name in ("width", "height"):
            if getattr(self.output, name) is not None:
                camera[name] = getattr(self.output, name)
        data = dict(data, camera=camera)
        data["render"] = dict(data.get("render", {}), passes=self.output.passes)
        return data

    def labels(self, path: str) -> np.ndarray:
        """Coordinate labels of an axis: its values, or their JSON where they are tables."""
        values = self.axes[path]
        if any(isinstance(v, dict) for v in values):
            return np.array([json.dumps(v, sort_keys=True) for v in values])
        return np.asarray(values)

    def target_relative_error(self, coordinates: dict) -> float | None:
        """The relative standard error the sky at ``coordinates`` is rendered to: that of the
        first ``output.targets`` entry whose axis values it has, else ``output.target_relative_error``
        (None for a fixed spp)."""
        for entry in self.output.targets:
            if all(_key(coordinates[path]) == _key(value) for path, value in entry["where"].items()):
                return entry["target_relative_error"]
        return self.output.target_relative_error

    def sky_id(self, index: int) -> str:
        return f"sky-{index:0{len(str(len(self) - 1))}d}"

    def sky(self, index: int) -> SkySpec:
        position = np.unravel_index(index, self.shape)
        coordinates = {path: values[i] for (path, values), i in zip(self.axes.items(), position)}
        return SkySpec(index=index, sky_id=self.sky_id(index), coordinates=coordinates,
                       scene=self.scene_dict(coordinates), seed=self.seed(index, 0))

    def skies(self):
        """Every sky, generated lazily (a grid of 10,000 skies is never held in memory)."""
        return (self.sky(i) for i in range(len(self)))

    def sky_numbers(self, text: str, name: str = "--skies") -> list[int]:
        """The sky numbers ``text`` lists, in the order listed, each once: comma-separated numbers
        and inclusive ranges, e.g. ``"0-9,20,30-39"`` (a part of the grid to render on one
        machine) or ``"70-83,54"`` (cheap skies first); a ParameterError naming ``name`` for
        anything else or a number outside the grid."""
        valid = f"numbers and ranges like 0-9,20 within [0, {len(self) - 1}]"
        numbers = {}    # a dict keeps the order of first appearance
        for part in str(text).split(","):
            match = re.fullmatch(r"\s*(\d+)\s*(?:-\s*(\d+)\s*)?", part)
            if match is None:
                raise ParameterError(name, text, valid, f"{part.strip()!r} is neither a number nor a range")
            first, last = int(match[1]), int(match[2] if match[2] is not None else match[1])
            if first > last or last >= len(self):
                raise ParameterError(name, text, valid, f"{part.strip()!r} is empty or outside the grid")
            numbers.update(dict.fromkeys(range(first, last + 1)))
        return list(numbers)

    def seed(self, index: int, round_index: int) -> int:
        """Seed of sky ``index`` in rendering round ``round_index`` (see module docstring)."""
        return (self.output.seed * MAX_ROUNDS + round_index) * len(self) + index

    # --- checks -----------------------------------------------------------------------------

    def validate(self):
        """Build the base scene, the scene of every axis value (the other axes as in the base)
        and the scenes of the grid's corners; raise :class:`ParameterError` naming the base,
        the axis or the combination at fault. A polarized grid (the render settings are the
        base scene's, the same for every sky) must have the "spectral" format: its dataset holds
        each wavelength's Stokes vector. Returns the scene of sky 0."""
        def build(coordinates, name, value):
            try:
                scene = Scene.from_dict(self.scene_dict(coordinates))
                if scene.render.polarized and self.output.format != "spectral":
                    raise ParameterError("render.polarized", True, 'false, or output.format = "spectral" (the '
                                         "dataset then holds each wavelength's Stokes vector)",
                                         f"output.format = {self.output.format!r} holds radiance only")
                check_image_size(scene, self.output.passes)
                return scene
            except ParameterError as exc:
                raise ParameterError(name, value, exc.valid,
                                     f"gives {exc.name} = {exc.value!r}: {exc.problem}") from None

        build({}, "base.scene", "(with [output] applied)")
        for path, values in self.axes.items():
            for value in values:
                build({path: value}, f"axes.{path}", value)
        for corner in itertools.product(*[(values[0], values[-1]) for values in self.axes.values()]):
            coordinates = dict(zip(self.axes, corner))
            build(coordinates, "axes", coordinates)
        return build(self.sky(0).coordinates, "axes", self.sky(0).coordinates)

    def fingerprint(self) -> str:
        """JSON that identifies the grid's content (not its file location)."""
        # settings added later are left out while unset: a grid's fingerprint from before them holds
        output = {k: v for k, v in dataclasses.asdict(self.output).items()
                  if k != "directory" and not (k in ("targets", "dynamic_range") and v in ((), [], None))}
        return json.dumps({"base": self.base, "axes": self.axes, "output": output}, sort_keys=True)


def load_grid(path) -> Grid:
    """Read a grid TOML file; relative paths in it are relative to the file."""
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise ParameterError("grid", path, "an existing TOML file", "file not found") from None
    except IsADirectoryError:
        raise ParameterError("grid", path, "an existing TOML file", "a directory") from None
    except UnicodeDecodeError:
        raise ParameterError("grid", path, "a UTF-8 TOML text file", "not text (binary?)") from None
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError("grid", path, "valid TOML", f"TOML syntax error: {exc}") from None
    for key in data:
        if key not in ("base", "axes", "output"):
            raise ParameterError(key, data[key], "tables [base], [axes], [output]", "unknown entry")
    here = os.path.dirname(os.path.abspath(path))
    base = data.get("base", {})
    for key in base:
        if key != "scene":
            raise ParameterError(f"base.{key}", base[key], "only base.scene", "unknown entry")
    scene = base.get("scene")
    if isinstance(scene, str):
        scene_path = os.path.join(here, scene)
        load_scene(scene_path)  # validates and names the file in errors
        with open(scene_path, "rb") as f:
            scene = tomllib.load(f)
    elif not isinstance(scene, dict):
        raise ParameterError("base.scene", scene, "a scene file path or a [base.scene] table", "missing")
    output = dict(data.get("output", {}))
    if "directory" not in output:
        raise ParameterError("output.directory", None, "a directory for the skies", "missing")
    output["directory"] = os.path.normpath(os.path.join(here, str(output["directory"])))
    check_fields("output", output, OutputSettings)
    if not isinstance(output.get("targets", []), list):
        raise ParameterError("output.targets", output["targets"], "an array of tables [[output.targets]]", "not one")
    output["targets"] = tuple(output.get("targets", ()))
    return Grid(base=scene, axes=dict(data.get("axes", {})), output=OutputSettings(**output), source=path)
