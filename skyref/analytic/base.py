"""What the classic analytic sky models share: the call the audit makes, the view geometry of a
spherical planet, and the atmosphere's constituents as the models see them (NumPy only).

Interface (the same as :class:`skyref.lut.base.LutMethod`'s, so :func:`skyref.audit.audit.compare`
takes either): a model is built from an :class:`~skyref.atmosphere.Atmosphere` and a wavelength
grid, :meth:`AnalyticModel.precompute` builds whatever it tabulates (timed; trivial for most),
and :meth:`AnalyticModel.radiance` returns the radiance an observer sees, W m^-2 sr^-1 nm^-1, along
unit view directions in the observer's east-north-up frame, without the solar disk. Each model
checks its own validity range (:meth:`AnalyticModel._check_validity`) and raises
:class:`~skyref.errors.ParameterError` outside it.

Geometry conventions (as :mod:`skyref.lut.planet`): a point is described by its distance ``r``
from the planet's centre (m) and a ray by the cosine ``mu`` of its angle with the local zenith;
``mu_s`` is the sun's zenith cosine at the observer and ``nu`` the cosine of the angle between
the view direction and the direction to the sun. The scattering angle of sunlight scattered
towards the observer has cosine ``nu`` (light travels along -sun and leaves along -view), so
phase functions are evaluated at ``nu``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skyref.atmosphere.profiles import DensityProfile, ExponentialProfile
from skyref.atmosphere.spectra import solar_irradiance, wavelength_grid
from skyref.errors import ParameterError
from skyref.sky_method import SkyMethod

__all__ = ["Component", "components", "exponential_components", "per_component", "phase_values", "sphere_distances",
           "hits_ground", "Segment", "atmosphere_segment", "radius_along_ray", "altitude_along_ray",
           "zenith_cosine_along_ray", "sun_cosine_along_ray", "column_along_rays", "one_minus_exp_over",
           "PER_VIEW_IN_LOOKUP", "AnalyticModel"]


# --- the atmosphere as the models see it -------------------------------------------------------

@dataclass(frozen=True)
class Component:
    """One constituent on the model's wavelength grid: coefficients at relative density 1 (m^-1,
    shape (N,)), its density profile and its phase function (None for a pure absorber)."""

    name: str
    kind: str                 # "rayleigh", "aerosol" or "absorber"
    profile: DensityProfile
    scattering: np.ndarray
    extinction: np.ndarray
    phase: object

    @property
    def scale_height_m(self) -> float | None:
        """H of an exponential profile; None for any other profile."""
        return self.profile.scale_height_m if isinstance(self.profile, ExponentialProfile) else None


def components(atmosphere, wavelengths_nm) -> list[Component]:
    """The atmosphere's constituents evaluated at ``wavelengths_nm``."""
    return [Component(c.name, c.kind, c.profile, c.scattering_coefficient(wavelengths_nm),
                      c.extinction_coefficient(wavelengths_nm), c.phase)
            for c in atmosphere.constituents]


def exponential_components(atmosphere, wavelengths_nm, model: str) -> tuple[list[Component], list[str]]:
    """The constituents of a model built on exponential density (Nielsen, O'Neil): the ones with an
    exponential profile, and the names of the absorbers it cannot represent (ignored, e.g. the
    ozone tent). A *scattering* constituent with another profile is refused: the model would
    miss part of the sky."""
    kept, ignored = [], []
    for c in components(atmosphere, wavelengths_nm):
        if c.scale_height_m is not None:
            kept.append(c)
        elif c.phase is None:
            ignored.append(c.name)
        else:
            raise ParameterError(f"{c.name}.profile", c.profile.to_dict(), "an exponential profile",
                                 f"{model} assumes exponentially decreasing density")
    return kept, ignored


def per_component(items: list[Component], function, shape=()) -> np.ndarray:
    """``function(component)`` of every component stacked: shape (C,) + ``shape`` (also for C = 0,
    an atmosphere without constituents)."""
    return np.array([np.broadcast_to(function(c), shape) for c in items], dtype=np.float64).reshape(
        (len(items),) + tuple(shape))


def phase_values(component: Component, nu) -> np.ndarray:
    """p(nu) of a scattering component, sr^-1 (0 for absorbers)."""
    return component.phase.evaluate(nu) if component.phase is not None else np.zeros_like(nu)


# --- spherical geometry in NumPy (float64) -----------------------------------------------------

def sphere_distances(r, mu, sphere_radius, bottom_radius):
    """Distances (near, far) from a point at radius ``r`` along rays of zenith cosine ``mu`` to
    the sphere of radius ``sphere_radius`` (NaN where the ray's line misses it; near < 0 where the
    point is inside). Solves t^2 + 2 r mu t + (r^2 - rho^2) = 0 with the stable quadratic formula:
    q = -(b + sign(b) sqrt(b^2 - c)), roots q and c / q, where c = (r - rho)(r + rho) is formed
    from altitudes above ``bottom_radius`` so that it does not cancel."""
    r, mu, rho = np.broadcast_arrays(np.asarray(r, float), np.asarray(mu, float), np.asarray(sphere_radius, float))
    b = r * mu
    c = ((r - bottom_radius) - (rho - bottom_radius)) * (r + rho)
    discriminant = b * b - c
    root = np.sqrt(np.maximum(discriminant, 0.0))
    q = -(b + np.where(b >= 0.0, root, -root))
    with np.errstate(divide="ignore", invalid="ignore"):
        other = np.where(q != 0.0, c / q, -b)
    near, far = np.minimum(q, other), np.maximum(q, other)
    missed = discriminant < 0.0
    return np.where(missed, np.nan, near), np.where(missed, np.nan, far)


def hits_ground(r, mu, bottom_radius):
    """True where the ray from radius ``r`` with zenith cosine ``mu`` meets the ground."""
    r = np.asarray(r, float)
    return (mu < 0.0) & (r * r * (mu * mu - 1.0) + bottom_radius * bottom_radius >= 0.0)


@dataclass
class Segment:
    """The part of each view ray inside the atmosphere: from ``start`` to ``end`` (m along the
    ray; start = end = 0 where the ray misses the atmosphere); ``ground`` where it ends on the
    ground."""

    start: np.ndarray
    end: np.ndarray
    ground: np.ndarray


def atmosphere_segment(r: float, mu, bottom_radius: float, top_radius: float) -> Segment:
    """The segment of rays from radius ``r`` (inside or above the atmosphere) with zenith cosines
    ``mu`` that lies between the ground and the top of the atmosphere."""
    mu = np.asarray(mu, float)
    near_top, far_top = sphere_distances(r, mu, top_radius, bottom_radius)
    ground = hits_ground(r, mu, bottom_radius)
    near_ground, _ = sphere_distances(r, mu, bottom_radius, bottom_radius)
    empty = np.isnan(far_top) | (far_top <= 0.0)
    start = np.where(empty, 0.0, np.maximum(np.nan_to_num(near_top), 0.0))
    end = np.where(ground, np.nan_to_num(near_ground), np.nan_to_num(far_top))
    end = np.where(empty, 0.0, np.maximum(end, start))
    return Segment(start, end, ground & ~empty)


def radius_along_ray(r, mu, t):
    """Distance from the planet's centre of the point at distance ``t`` along the ray (r, mu)."""
    return np.sqrt(np.maximum(r * r + 2.0 * r * mu * t + t * t, 0.0))


def altitude_along_ray(r, mu, t, bottom_radius):
    """Altitude (m) of the point at distance ``t`` along the ray (r, mu), without the
    cancellation of |p| - R: (h0 (2R + h0) + 2 r mu t + t^2) / (|p| + R)."""
    h0 = r - bottom_radius
    return (h0 * (2.0 * bottom_radius + h0) + 2.0 * r * mu * t + t * t) / (
        radius_along_ray(r, mu, t) + bottom_radius)


def zenith_cosine_along_ray(r, mu, t):
    """Cosine of the ray's zenith angle at the point at distance ``t`` along it: (r mu + t) / r_t."""
    return np.clip((r * mu + t) / np.maximum(radius_along_ray(r, mu, t), 1e-9), -1.0, 1.0)


def sun_cosine_along_ray(r, mu, mu_s, nu, t):
    """Cosine of the sun's zenith angle at the point at distance ``t`` along the ray (r, mu), the
    sun at zenith cosine ``mu_s`` at the ray's origin and at cosine ``nu`` from the ray:
    (r mu_s + t nu) / r_t."""
    return np.clip((r * mu_s + t * nu) / np.maximum(radius_along_ray(r, mu, t), 1e-9), -1.0, 1.0)


def column_along_rays(profile: DensityProfile, bottom_radius: float, altitude, mu, length,
                      panels: int = 16, nodes: int = 16) -> np.ndarray:
    """Integral of the profile's relative density along rays (m), from points at ``altitude`` with
    zenith cosines ``mu`` over ``length`` metres (arrays broadcast together). Gauss–Legendre with
    ``nodes`` nodes on each of ``panels`` panels whose lengths grow geometrically from the start
    (density falls off roughly exponentially with distance from it)."""
    altitude, mu, length = np.broadcast_arrays(np.asarray(altitude, float), np.asarray(mu, float),
                                               np.asarray(length, float))
    x, w = np.polynomial.legendre.leggauss(nodes)
    fractions = (np.geomspace(1.0, 1.0e4, panels + 1) - 1.0) / (1.0e4 - 1.0)
    a, b = fractions[:-1, None], fractions[1:, None]
    t_unit = (0.5 * (b - a) * x + 0.5 * (a + b)).ravel()          # positions as fractions of length
    w_unit = (0.5 * (b - a) * w).ravel()
    t = length[..., None] * t_unit
    r = bottom_radius + altitude[..., None]
    h = altitude_along_ray(r, mu[..., None], t, bottom_radius)
    return length * (profile.density(np.maximum(h, 0.0)) @ w_unit)


def one_minus_exp_over(x):
    """(1 - exp(-x)) / x, with its limit 1 at x = 0 (the mean of exp(-s) over s in [0, x])."""
    x = np.asarray(x, float)
    small = np.abs(x) < 1e-8
    safe = np.where(small, 1.0, x)
    return np.where(small, 1.0 - 0.5 * x, -np.expm1(-safe) / safe)


# --- the interface -----------------------------------------------------------------------------

#: The note of an analytic model's :class:`~skyref.sky_method.Operations` that has per-view work.
PER_VIEW_IN_LOOKUP = "skyref does the per-view work in every radiance call: its time is part of the lookup's"


class AnalyticModel(SkyMethod):
    """Base class: subclasses set :attr:`name`, may override ``_precompute()`` and
    ``_check_validity(altitude_m, mu_s)``, and implement ``_radiance(r, mu, mu_s, nu)``
    (observer radius r in m and sun cosine mu_s, both scalars; view cosines mu and nu, arrays of
    shape (M,)) returning (M, N) radiance."""

    name = ""

    def __init__(self, atmosphere, wavelengths_nm="rgb"):
        grid = wavelength_grid(wavelengths_nm) if isinstance(wavelengths_nm, (str, dict)) else wavelengths_nm
        self.atmosphere = atmosphere
        self.wavelengths_nm = atmosphere.check_wavelengths(grid)
        self.solar_irradiance = solar_irradiance(self.wavelengths_nm)
        self.bottom_radius = float(atmosphere.bottom_radius_m)
        self.top_radius = float(atmosphere.top_radius_m)
        #: The model's own settings, for reports.
        self.options: dict = {}

    def _precompute(self):
        """Nothing to tabulate by default."""

    def _check_validity(self, altitude_m: float, mu_s: float):
        """Raise a ParameterError if the observer or the sun is outside the model's range."""

    def radiance(self, directions, sun_direction, observer_altitude_m: float) -> np.ndarray:
        """Radiance seen from ``observer_altitude_m`` (m) along unit ``directions`` (M, 3),
        east-north-up, with the sun towards ``sun_direction`` (3,): (M, N) W m^-2 sr^-1 nm^-1,
        solar disk excluded."""
        dirs, sun, altitude = self._checked_view(directions, sun_direction, observer_altitude_m)
        self._check_validity(altitude, float(sun[2]))
        mu = np.clip(dirs[:, 2], -1.0, 1.0)
        nu = np.clip(dirs @ sun, -1.0, 1.0)
        return self._radiance(self.bottom_radius + altitude, mu, float(sun[2]), nu)

    def _radiance(self, r: float, mu, mu_s: float, nu) -> np.ndarray:
        raise NotImplementedError
