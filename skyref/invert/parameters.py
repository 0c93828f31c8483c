"""The unknowns of an inversion: physical parameters with bounds, each free or held fixed, and
how they map onto the differentiable parameters of the ``atmosphere`` integrator
(:meth:`skyref.plugins.optics.AtmosphereOptics.parameters`).

- ``aod_550``: vertical aerosol optical depth at 550 nm (whole column) -> ``<aerosol>.angstrom_beta``
- ``angstrom_alpha``: Angstrom exponent, tau_a(lambda) ~ lambda^-alpha -> ``<aerosol>.angstrom_alpha``
  (and beta, see below)
- ``aerosol_g``: Cornette–Shanks parameter g (not the asymmetry parameter) -> ``<aerosol>.g``
- ``aerosol_ssa``: aerosol single-scattering albedo -> ``<aerosol>.single_scattering_albedo``
- ``ozone_du``: ozone column, Dobson units -> ``<absorber>.column_du``
- ``ground_albedo``: grey Lambertian ground albedo -> ``ground_albedo``
- ``rayleigh_scale``: Rayleigh coefficient / standard (surface pressure / 1013.25 hPa) ->
  ``<rayleigh>.density_scale``

The aerosol is parametrised by its optical depth at 550 nm rather than Angstrom's beta (the
optical depth at 1 um), because that is what photometers report and what the image constrains
best: with tau_550 = s beta 0.55^-alpha (s the aerosol's fixed density scale),
beta = tau_550 0.55^alpha / s, so dbeta/dtau_550 = 0.55^alpha / s and, at fixed tau_550,
dbeta/dalpha = beta ln 0.55. :meth:`ParameterSet.chain` holds these derivatives; everything else
maps one to one.

The optimizer gives every free unknown a weak Gaussian prior centred on its initial value, with
the standard deviation of a uniform distribution over its bounds, (upper - lower) / sqrt 12. It
keeps parameters that the image cannot constrain near their start and makes that visible: their
posterior spread stays close to the prior's.

References
----------
A. Ångström, "On the atmospheric transmission of sun radiation and on dust in the air", Geografiska
Annaler 11, 1929 (tau_a(lambda) = beta lambda^-alpha, lambda in um: the mapping of tau_550 to beta).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from skyref.atmosphere.presets import TURBIDITY_WAVELENGTH_NM
from skyref.validation import check_choice, check_number
from skyref.errors import ParameterError

__all__ = ["DEFAULT_FREE", "UNKNOWNS", "ParameterSet", "Unknown"]

#: tau_550 = beta (550 nm / 1 um)^-alpha.
_REFERENCE_RATIO = TURBIDITY_WAVELENGTH_NM / 1000.0


@dataclass(frozen=True)
class Unknown:
    """An unknown: ``initial`` value (also the prior's mean), default ``bounds``, the ``limits``
    that any user-given bounds must respect (physically meaningful values), and the integrator
    parameter it sets: ``key`` of the first constituent of ``kind`` (``None``: the ground)."""

    name: str
    unit: str
    initial: float
    bounds: tuple
    limits: tuple
    kind: str | None
    key: str
    description: str


UNKNOWNS = {u.name: u for u in (
    Unknown("aod_550", "", 0.1, (0.005, 1.5), (0.0, 10.0), "aerosol", "angstrom_beta",
            "aerosol optical depth at 550 nm"),
    Unknown("angstrom_alpha", "", 1.0, (-0.5, 2.5), (-1.0, 4.0), "aerosol", "angstrom_alpha",
            "Angstrom exponent alpha"),
    Unknown("aerosol_g", "", 0.75, (0.5, 0.95), (0.0, 0.99), "aerosol", "g", "Cornette-Shanks g of the aerosol"),
    Unknown("aerosol_ssa", "", 0.9, (0.6, 1.0), (0.0, 1.0), "aerosol", "single_scattering_albedo",
            "aerosol single-scattering albedo"),
    Unknown("ozone_du", "DU", 300.0, (100.0, 600.0), (0.0, 2000.0), "absorber", "column_du", "ozone column"),
    Unknown("ground_albedo", "", 0.2, (0.0, 0.9), (0.0, 1.0), None, "ground_albedo",
            "ground albedo (grey, Lambertian)"),
    Unknown("rayleigh_scale", "", 1.0, (0.5, 1.2), (0.05, 2.0), "rayleigh", "density_scale",
            "Rayleigh scale (surface pressure / standard)"),
)}

#: Unknowns fitted unless told otherwise. The Rayleigh scale (known from the site's altitude
#: and pressure) and the aerosol's single-scattering albedo (nearly degenerate with its optical
#: depth in a sky image) are held at their initial values.
DEFAULT_FREE = ("aod_550", "angstrom_alpha", "aerosol_g", "ozone_du", "ground_albedo")


def _check_constituent(constituent, unknown):
    """Raise if ``constituent`` cannot carry ``unknown`` (an aerosol without Angstrom's law or
    with a tabulated phase, an absorber given by number density)."""
    if constituent.kind == "aerosol":
        if constituent.extinction is not None:
            raise ParameterError(unknown, None, "an aerosol following Angstrom's law",
                                 f"aerosol {constituent.name!r} has a tabulated extinction")
        if constituent.phase.kind not in ("cornette_shanks", "henyey_greenstein"):
            raise ParameterError(unknown, None, "a Cornette-Shanks or Henyey-Greenstein aerosol phase",
                                 f"aerosol {constituent.name!r} has a {constituent.phase.kind} phase")
    if constituent.kind == "absorber" and constituent.column_du is None:
        raise ParameterError(unknown, None, "an absorber given by its column (column_du)",
                             f"absorber {constituent.name!r} is given by number density")


class ParameterSet:
    """The unknowns of one inversion on a base ``atmosphere`` (which supplies everything else:
    radii, density profiles, the aerosol's density scale).

    ``free``: names of the fitted unknowns; ``values``: name -> initial (free) or fixed value,
    defaults from :data:`UNKNOWNS`; ``bounds``: name -> (lower, upper) for free unknowns.
    An unknown whose constituent the atmosphere lacks (e.g. ozone in ``rayleigh_only``) is
    absent, and an error if it is free. Every value is checked here, before any rendering.
    """

    def __init__(self, atmosphere, free=DEFAULT_FREE, values=None, bounds=None):
        values, bounds = dict(values or {}), dict(bounds or {})
        free = tuple(free)
        for name in (*free, *values, *bounds):
            check_choice("unknown", name, tuple(UNKNOWNS))
        if len(set(free)) != len(free):
            raise ParameterError("free", list(free), "distinct unknowns", "repeated name")
        if not free:
            raise ParameterError("free", [], "at least one of " + ", ".join(UNKNOWNS), "nothing to fit")
        for name in bounds:
            if name not in free:
                raise ParameterError(f"bounds.{name}", bounds[name], "bounds only for free unknowns",
                                     f"{name} is fixed")
        self.atmosphere = atmosphere
        self.free = free
        #: kind -> the constituent that the unknowns of that kind act on.
        self._constituents = {}
        for name, unknown in UNKNOWNS.items():
            if unknown.kind is None or unknown.kind in self._constituents:
                continue
            found = next((c for c in atmosphere.constituents if c.kind == unknown.kind), None)
            if found is not None:
                self._constituents[unknown.kind] = found
        self.present = tuple(name for name, u in UNKNOWNS.items() if u.kind is None or u.kind in self._constituents)
        for name in free:
            if name not in self.present:
                raise ParameterError(name, None, f"an atmosphere with a {UNKNOWNS[name].kind} constituent",
                                     f"atmosphere {atmosphere.name or '(custom)'} has none")
        for name in self.present:
            if UNKNOWNS[name].kind is not None:
                _check_constituent(self._constituents[UNKNOWNS[name].kind], name)
        self.bounds = {}
        for name in free:
            limits = UNKNOWNS[name].limits
            lo, hi = (check_number(f"bounds.{name}", v, *limits) for v in bounds.get(name, UNKNOWNS[name].bounds))
            if not lo < hi:
                raise ParameterError(f"bounds.{name}", (lo, hi), "lower < upper", "empty interval")
            self.bounds[name] = (lo, hi)
        #: name -> value of every unknown present (initial values of the free ones).
        self.values = {}
        for name in self.present:
            unknown = UNKNOWNS[name]
            if name in free:
                lo, hi = self.bounds[name]
                default = unknown.initial if lo <= unknown.initial <= hi else 0.5 * (lo + hi)
                self.values[name] = check_number(name, values.get(name, default), lo, hi)
            else:
                self.values[name] = check_number(name, values.get(name, unknown.initial), *unknown.limits)

    # --- vectors of free unknowns -------------------------------------------------------------

    def vector(self, values=None) -> np.ndarray:
        """The free unknowns of ``values`` (default: the initial ones) as an array."""
        values = self.values if values is None else values
        return np.array([values[name] for name in self.free], dtype=np.float64)

    def with_vector(self, x) -> dict:
        """All values, the free ones taken from ``x`` (in the order of :attr:`free`)."""
        return {**self.values, **{name: float(v) for name, v in zip(self.free, x)}}

    @property
    def lower(self) -> np.ndarray:
        return np.array([self.bounds[name][0] for name in self.free])

    @property
    def upper(self) -> np.ndarray:
        return np.array([self.bounds[name][1] for name in self.free])

    @property
    def prior_std(self) -> np.ndarray:
        """Standard deviation of the uniform prior over each free unknown's bounds."""
        return (self.upper - self.lower) / math.sqrt(12.0)

    # --- the integrator's parameters ------------------------------------------------------

    def integrator_name(self, name: str) -> str:
        """The integrator parameter (``mi.traverse`` name) that unknown ``name`` sets."""
        unknown = UNKNOWNS[name]
        if unknown.kind is None:
            return unknown.key
        return f"{self._constituents[unknown.kind].name}.{unknown.key}"

    def _beta_per_aod(self, values) -> float:
        """dbeta/dtau_550 = 0.55^alpha / s (beta = tau_550 0.55^alpha / s)."""
        return _REFERENCE_RATIO ** values["angstrom_alpha"] / self._constituents["aerosol"].density_scale

    def _beta(self, values) -> float:
        return values["aod_550"] * self._beta_per_aod(values)

    def integrator_values(self, values) -> dict:
        """Integrator parameter name -> value for ``values`` (every unknown present)."""
        mapped = {self.integrator_name(name): values[name] for name in self.present}
        if "aod_550" in self.present:
            mapped[self.integrator_name("aod_550")] = self._beta(values)
        return mapped

    def chain(self, values) -> tuple[list, np.ndarray]:
        """(integrator parameter names q, matrix D (len(q), free)) with D[i, k] = dq_i/dtheta_k
        at ``values``: the derivative of the radiance with respect to free unknown k is
        sum_i dL/dq_i D[i, k]. Only the q that some free unknown moves are listed."""
        entries = {}
        for k, name in enumerate(self.free):
            if name == "aod_550":
                entries[(self.integrator_name(name), k)] = self._beta_per_aod(values)
            elif name == "angstrom_alpha":
                entries[(self.integrator_name(name), k)] = 1.0
                # At fixed tau_550, beta moves with alpha: dbeta/dalpha = beta ln 0.55.
                entries[(self.integrator_name("aod_550"), k)] = self._beta(values) * math.log(_REFERENCE_RATIO)
            else:
                entries[(self.integrator_name(name), k)] = 1.0
        names = list(dict.fromkeys(q for q, _ in entries))
        matrix = np.zeros((len(names), len(self.free)))
        for (q, k), value in entries.items():
            matrix[names.index(q), k] = value
        return names, matrix

    def atmosphere_at(self, values):
        """The base atmosphere with ``values`` in place: e.g. the fitted atmosphere."""
        changed = {}
        for name in self.present:
            unknown = UNKNOWNS[name]
            if unknown.kind is not None:
                fields = changed.setdefault(unknown.kind, {})
                fields[unknown.key] = self._beta(values) if name == "aod_550" else values[name]
        atmosphere = self.atmosphere
        for kind, fields in changed.items():
            constituent = self._constituents[kind]
            if "g" in fields:
                fields["phase"] = dataclasses.replace(constituent.phase, g=fields.pop("g"))
            atmosphere = atmosphere.with_constituent(dataclasses.replace(constituent, **fields))
        return atmosphere.replace(ground_albedo=values["ground_albedo"])
