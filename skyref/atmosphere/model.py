"""The spherical planetary atmosphere: a planet of radius ``bottom_radius_m`` with a Lambertian
ground, under a shell of air up to ``top_radius_m`` that holds a list of constituents.

This is the one source of physical truth in skyref: the path tracer, the LUT methods, the
analytic models and the fitter all read their coefficients from an :class:`Atmosphere`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np

from skyref.atmosphere.constituents import Constituent, constituent_from_dict
from skyref.atmosphere.spectra import Spectrum, as_spectrum
from skyref.validation import check_number
from skyref.errors import ParameterError

__all__ = ["RADIUS_RANGE_M", "Atmosphere"]

#: Accepted planet radii, m (a 1 km asteroid up to a gas-giant-sized body).
RADIUS_RANGE_M = (1.0e3, 1.0e8)


@functools.lru_cache(maxsize=8)
def _gauss_legendre(nodes: int):
    """Gauss–Legendre nodes and weights on [-1, 1], computed once per size (an eigenproblem:
    14 ms for 256 nodes, and many times that on a loaded machine)."""
    return np.polynomial.legendre.leggauss(nodes)


@dataclass(frozen=True)
class Atmosphere:
    """Planet and atmosphere. Radii in metres; ``ground_albedo`` is the Lambertian
    reflectance of the ground (a number or a spectrum, in [0, 1])."""

    bottom_radius_m: float = 6_360_000.0
    top_radius_m: float = 6_420_000.0
    constituents: tuple = ()
    ground_albedo: Spectrum | float = 0.1
    name: str = ""

    def __post_init__(self):
        check_number("bottom_radius_m", self.bottom_radius_m, *RADIUS_RANGE_M)
        check_number("top_radius_m", self.top_radius_m, self.bottom_radius_m, RADIUS_RANGE_M[1],
                     lo_open=True)
        if not isinstance(self.ground_albedo, (Spectrum, dict)):
            check_number("ground_albedo", self.ground_albedo, 0.0, 1.0)
        albedo = as_spectrum(self.ground_albedo)
        object.__setattr__(self, "ground_albedo", albedo)
        probe = albedo(np.linspace(*albedo.valid_range_nm, 64))
        if np.any(probe < 0.0) or np.any(probe > 1.0):
            raise ParameterError("ground_albedo", albedo.to_dict(), "[0, 1] at every wavelength",
                                 "out of range")
        constituents = tuple(self.constituents)
        for c in constituents:
            if not isinstance(c, Constituent):
                raise ParameterError("constituents", c, "Rayleigh, Aerosol or Absorber objects", "wrong type")
        names = [c.name for c in constituents]
        for c in constituents:
            if names.count(c.name) > 1:
                raise ParameterError("constituents", names, "unique names", f"{c.name!r} appears twice")
        object.__setattr__(self, "constituents", constituents)

    # --- access -------------------------------------------------------------------------

    @property
    def thickness_m(self) -> float:
        return self.top_radius_m - self.bottom_radius_m

    def __contains__(self, name: str) -> bool:
        return any(c.name == name for c in self.constituents)

    def __getitem__(self, name: str) -> Constituent:
        for c in self.constituents:
            if c.name == name:
                return c
        raise KeyError(f"no constituent named {name!r}; this atmosphere has "
                       + ", ".join(repr(c.name) for c in self.constituents))

    def replace(self, **changes) -> "Atmosphere":
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    def with_constituent(self, constituent: Constituent) -> "Atmosphere":
        """A copy in which ``constituent`` replaces the one of the same name (or is added)."""
        kept = [c for c in self.constituents if c.name != constituent.name]
        index = next((i for i, c in enumerate(self.constituents) if c.name == constituent.name), len(kept))
        kept.insert(index, constituent)
        return self.replace(constituents=tuple(kept))

    def without(self, name: str) -> "Atmosphere":
        self[name]
        return self.replace(constituents=tuple(c for c in self.constituents if c.name != name))

    # --- optics ---------------------------------------------------------------------------

    def _local(self, method: str, wavelengths_nm, altitude_m) -> np.ndarray:
        wl = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
        h = np.asarray(altitude_m, dtype=np.float64)[..., None]
        total = np.zeros(h.shape[:-1] + wl.shape)
        for c in self.constituents:
            total = total + getattr(c, method)(wl) * c.profile.density(h)
        return total

    def scattering_coefficient(self, wavelengths_nm, altitude_m) -> np.ndarray:
        """sigma_s(h, lambda), m^-1, shape altitude.shape + (n_wavelengths,)."""
        return self._local("scattering_coefficient", wavelengths_nm, altitude_m)

    def extinction_coefficient(self, wavelengths_nm, altitude_m) -> np.ndarray:
        """sigma_t(h, lambda), m^-1, shape altitude.shape + (n_wavelengths,)."""
        return self._local("extinction_coefficient", wavelengths_nm, altitude_m)

    def constituent_optical_depth(self, constituent: Constituent, wavelengths_nm, lower_m: float = 0.0,
                                  upper_m: float | None = None, coefficient: str = "extinction") -> np.ndarray:
        """One constituent's optical depth straight up from altitude ``lower_m`` to ``upper_m``
        (default: the top): its ``coefficient`` ("extinction" or "scattering", m^-1 at relative
        density 1) times its profile's column (m), integrated analytically; per wavelength."""
        upper = self.thickness_m if upper_m is None else upper_m
        wl = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
        return getattr(constituent, f"{coefficient}_coefficient")(wl) * constituent.profile.column(lower_m, upper)

    def vertical_optical_depth(self, wavelengths_nm, lower_m: float = 0.0,
                               upper_m: float | None = None) -> np.ndarray:
        """Optical depth straight up from altitude ``lower_m`` to ``upper_m`` (default: the top),
        summed over constituents (:meth:`constituent_optical_depth`)."""
        wl = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
        return sum((self.constituent_optical_depth(c, wl, lower_m, upper_m) for c in self.constituents),
                   np.zeros_like(wl))

    def distance_to_boundary(self, altitude_m: float, cos_zenith: float) -> tuple[float, bool]:
        """Distance (m) from a point at ``altitude_m`` along a ray of zenith cosine
        ``cos_zenith`` to the top of the atmosphere or the ground, and whether it is the ground."""
        r = self.bottom_radius_m + altitude_m
        sin2 = max(0.0, 1.0 - cos_zenith * cos_zenith)
        disc_ground = self.bottom_radius_m ** 2 - r * r * sin2
        if cos_zenith < 0.0 and disc_ground >= 0.0:
            return -r * cos_zenith - math.sqrt(disc_ground), True
        return -r * cos_zenith + math.sqrt(max(0.0, self.top_radius_m ** 2 - r * r * sin2)), False

    def optical_depth(self, wavelengths_nm, altitude_m: float, cos_zenith: float,
                      distance_m: float | None = None, nodes: int = 256) -> np.ndarray:
        """Optical depth along a straight ray in the spherical atmosphere, from a point at
        ``altitude_m`` in the direction of zenith cosine ``cos_zenith`` over ``distance_m``
        (default: to the top of the atmosphere or the ground). Numerical: Gauss–Legendre
        quadrature with ``nodes`` nodes on each of 16 panels whose lengths grow geometrically
        (the density falls off exponentially with distance from the observer)."""
        if distance_m is None:
            distance_m, _ = self.distance_to_boundary(altitude_m, cos_zenith)
        x, w = _gauss_legendre(nodes)
        edges = distance_m * (np.geomspace(1.0, 1.0e4, 17) - 1.0) / (1.0e4 - 1.0)
        a, b = edges[:-1, None], edges[1:, None]
        t = (0.5 * (b - a) * x + 0.5 * (a + b)).ravel()
        weights = (0.5 * (b - a) * w).ravel()
        r0 = self.bottom_radius_m + altitude_m
        # Altitude along the ray without cancellation: |p|^2 - R^2 over (|p| + R).
        r2 = r0 * r0 + 2.0 * r0 * cos_zenith * t + t * t
        h = (altitude_m * (2.0 * self.bottom_radius_m + altitude_m) + 2.0 * r0 * cos_zenith * t + t * t) / (
            np.sqrt(r2) + self.bottom_radius_m)
        return np.tensordot(weights, self.extinction_coefficient(wavelengths_nm, h), axes=1)

    def transmittance(self, wavelengths_nm, altitude_m: float, cos_zenith: float,
                      distance_m: float | None = None) -> np.ndarray:
        """exp(-optical depth) along the same ray as :meth:`optical_depth`."""
        return np.exp(-self.optical_depth(wavelengths_nm, altitude_m, cos_zenith, distance_m))

    def check_wavelengths(self, wavelengths_nm) -> np.ndarray:
        """Raise a ParameterError if a wavelength lies outside the data of any spectrum here."""
        wl = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
        self.ground_albedo(wl)
        for c in self.constituents:
            c.extinction_coefficient(wl)
        return wl

    # --- serialisation ----------------------------------------------------------------------

    def to_dict(self) -> dict:
        """A plain dict (TOML-ready) that :meth:`from_dict` turns back into an equal object."""
        return {"name": self.name, "bottom_radius_m": self.bottom_radius_m,
                "top_radius_m": self.top_radius_m, "ground_albedo": self.ground_albedo.to_dict(),
                "constituents": {c.name: {k: v for k, v in c.to_dict().items() if k != "name"}
                                 for c in self.constituents}}

    @classmethod
    def from_dict(cls, data: dict) -> "Atmosphere":
        fields = dict(data)
        known = {"name", "bottom_radius_m", "top_radius_m", "ground_albedo", "constituents"}
        for key in fields:
            if key not in known:
                raise ParameterError(f"atmosphere.{key}", fields[key], "one of " + ", ".join(sorted(known)),
                                     "unknown parameter")
        constituents = tuple(constituent_from_dict({"name": name, **spec})
                             for name, spec in fields.pop("constituents", {}).items())
        return cls(constituents=constituents, **fields)
