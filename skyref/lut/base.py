"""What every LUT method shares: the atmosphere's optics on a wavelength grid, precision,
timing, and the one lookup interface the audit calls.

A method is built from an :class:`~skyref.atmosphere.Atmosphere` and a wavelength grid,
:meth:`LutMethod.precompute` fills its tables (timed), and :meth:`LutMethod.radiance` returns
the radiance an observer sees, W m^-2 sr^-1 nm^-1, for view directions in the observer's
east-north-up frame (the frame of :class:`skyref.sky.Sky`), without the solar disk. Where a
view ray hits the ground the method adds the ground's reflected light as its paper does (or
returns NaN there if the paper has no ground model).

Dr.Jit works in double precision here (``mi.Float64``): r^2 - R^2 cancels in float32 near the
ground, and the audit must measure a method's discretization, not float32 round-off. Table
*storage* precision (float32 or float16) is a parameter of each method.
"""

from __future__ import annotations

import time

import drjit as dr
import mitsuba as mi
import numpy as np

from skyref.atmosphere.phase import CornetteShanks, HenyeyGreenstein
from skyref.atmosphere.spectra import solar_irradiance, wavelength_grid
from skyref.validation import check_choice, check_number
from skyref.errors import ParameterError
from skyref.lut.table import PRECISIONS
from skyref.atmosphere.sun import SUN_ANGULAR_RADIUS_DEG
from skyref.sky_method import SkyMethod
from skyref.plugins import load_mitsuba
from skyref.plugins.optics import AtmosphereOptics

__all__ = ["load_lut_backend", "LutOptics", "LutMethod"]


def load_lut_backend(variant: str | None = None):
    """Load Mitsuba (its Dr.Jit backend runs the LUT kernels) and return the module."""
    return load_mitsuba(variant)


class LutOptics:
    """The atmosphere as LUT methods see it: Rayleigh scattering, one aerosol ("Mie": Cornette–
    Shanks or Henyey–Greenstein phase) and absorbers, per lane on a wavelength channel."""

    def __init__(self, atmosphere, wavelengths_nm):
        self.atmosphere = atmosphere
        self.optics = AtmosphereOptics(atmosphere, wavelengths_nm)
        self.wavelengths_nm = self.optics.wavelengths_nm
        self.rayleigh = [c for c in self.optics.components if c.kind == "rayleigh"]
        self.mie = [c for c in self.optics.components if c.kind == "aerosol"]
        self.absorbers = [c for c in self.optics.components if c.kind == "absorber"]
        if len(self.rayleigh) > 1 or len(self.mie) > 1:
            raise ParameterError("atmosphere", [c.name for c in self.optics.components],
                                 "at most one Rayleigh constituent and one aerosol",
                                 "LUT methods store one Rayleigh and one Mie term")
        # the LUT kernels evaluate these two phase functions' formulas with their parameter g
        if self.mie and not isinstance(self.mie[0].model.phase, (CornetteShanks, HenyeyGreenstein)):
            raise ParameterError(f"{self.mie[0].name}.phase", self.mie[0].model.phase.kind,
                                 "cornette_shanks or henyey_greenstein", "not supported by LUT methods")
        self.bottom_radius = float(atmosphere.bottom_radius_m)
        self.top_radius = float(atmosphere.top_radius_m)

    @property
    def mie_g(self) -> float:
        return float(self.mie[0].params["g"].numpy()[0]) if self.mie else 0.0

    def scattering(self, altitude, channel):
        """(Rayleigh scattering, Mie scattering) coefficients at ``altitude`` (m) for the lanes'
        wavelength ``channel``, m^-1 (Float64)."""
        return self._scattering(self._densities(altitude), channel)

    def scattering_by_channel(self, altitude, channels: int):
        """(Rayleigh, Mie) scattering coefficients at ``altitude`` (m) for channels 0 ..
        ``channels`` - 1: two lists of Float64, m^-1, the densities evaluated once."""
        densities = self._densities(altitude)
        pairs = [self._scattering(densities, mi.UInt32(k)) for k in range(channels)]
        return [rayleigh for rayleigh, _ in pairs], [mie for _, mie in pairs]

    def _densities(self, altitude):
        """(Rayleigh densities, Mie densities) at ``altitude`` (m), one per constituent."""
        return [c.density(altitude) for c in self.rayleigh], [c.density(altitude) for c in self.mie]

    def _scattering(self, densities, channel):
        """(Rayleigh, Mie) scattering coefficients, m^-1, for ``channel`` at the relative
        ``densities`` of :meth:`_densities`."""
        rayleigh, mie = mi.Float64(0.0), mi.Float64(0.0)
        for c, rho in zip(self.rayleigh, densities[0]):
            rayleigh += mi.Float64(c.coefficients(channel)[0]) * rho
        for c, rho in zip(self.mie, densities[1]):
            mie += mi.Float64(c.coefficients(channel)[0]) * rho
        return rayleigh, mie

    def extinction(self, altitude, channel):
        """Total extinction coefficient at ``altitude`` (m) for the lanes' ``channel``, m^-1."""
        return self._extinction([c.density(altitude) for c in self.optics.components], channel)

    def extinction_by_channel(self, altitude, channels: int):
        """Total extinction coefficients at ``altitude`` (m) for channels 0 .. ``channels`` - 1: a
        list of Float64, m^-1, the densities evaluated once."""
        densities = [c.density(altitude) for c in self.optics.components]
        return [self._extinction(densities, mi.UInt32(k)) for k in range(channels)]

    def _extinction(self, densities, channel):
        """Total extinction coefficient, m^-1, for ``channel`` at the relative ``densities`` of
        the optics' components."""
        total = mi.Float64(0.0)
        for c, rho in zip(self.optics.components, densities):
            s, a = c.coefficients(channel)
            if s is not None:
                total += mi.Float64(s) * rho
            if a is not None:
                total += mi.Float64(a) * rho
        return total

    def mie_extinction_to_scattering(self, channel):
        """sigma_t / sigma_s of the aerosol for the lanes' channel (1 without aerosol)."""
        if not self.mie:
            return mi.Float64(1.0)
        s, a = self.mie[0].coefficients(channel)
        return mi.Float64((s + a) / dr.maximum(s, 1e-30))

    def rayleigh_phase(self, nu):
        return self.rayleigh[0].phase(nu) if self.rayleigh else 0.0 * nu

    def mie_phase(self, nu):
        return self.mie[0].phase(nu) if self.mie else 0.0 * nu

    def ground_albedo(self, channel):
        albedo = self.optics.ground_albedo
        index = channel if dr.width(albedo) > 1 else 0 * channel
        return mi.Float64(dr.gather(mi.Float, albedo, index))


def _lanes(values) -> mi.Float64:
    """Per-direction input values as a Float64 array that kernels read by gathers. A kernel that
    loads an array lane by lane is specialised on its memory's alignment (Dr.Jit 1.5 emits
    aligned vector loads when it can), which varies from call to call: the lookups compiled
    their kernels again on about every call (~1 s for 2048 directions). The index is offset by
    an opaque 0 so that Dr.Jit cannot turn the gather back into a load."""
    values = mi.Float64(np.asarray(values, dtype=np.float64))
    return dr.gather(mi.Float64, values, dr.arange(mi.UInt32, dr.width(values)) + dr.opaque(mi.UInt32, 0))


class LutMethod(SkyMethod):
    """Base class: subclasses set :attr:`name`, implement ``_precompute()`` and
    ``_radiance(r, mu, mu_s, nu)`` (view at radius r, m; cosines of view and sun zenith and of
    the view–sun angle; returns a list of one Float64 array per wavelength)."""

    name = ""

    def __init__(self, atmosphere, wavelengths_nm="rgb", precision: str = "float32",
                 sun_angular_radius_deg: float = SUN_ANGULAR_RADIUS_DEG, variant: str | None = None):
        load_lut_backend(variant)
        self.precision = check_choice("precision", precision, PRECISIONS)
        self.sun_angular_radius = np.radians(check_number("sun_angular_radius_deg", sun_angular_radius_deg,
                                                          0.0, 5.0, lo_open=True))
        grid = wavelength_grid(wavelengths_nm) if isinstance(wavelengths_nm, (str, dict)) else wavelengths_nm
        self.atmosphere = atmosphere
        self.optics = LutOptics(atmosphere, grid)
        self.wavelengths_nm = self.optics.wavelengths_nm
        self.channels = len(self.wavelengths_nm)
        self.solar_irradiance = solar_irradiance(self.wavelengths_nm)

    # --- precomputation -------------------------------------------------------------------

    def _finish(self):
        dr.sync_thread()

    def tables(self) -> dict:
        """name -> NumPy array of every precomputed table (as stored)."""
        raise NotImplementedError

    def prepare_view(self, sun_direction, observer_altitude_m: float) -> float:
        """Build the tables that depend on the observer and the sun (a frame's work in an
        engine: Hillaire's sky view, Elek's aerial-perspective volume); :meth:`radiance` builds
        them itself when missing, so calling this first only separates their cost from the
        lookups'. Returns the wall time, s."""
        start = time.perf_counter()
        sun = np.asarray(sun_direction, dtype=np.float64).reshape(3)
        self._prepare_view(self.optics.bottom_radius + float(observer_altitude_m),
                           float(sun[2] / np.linalg.norm(sun)))
        dr.sync_thread()
        return time.perf_counter() - start

    def _prepare_view(self, r: float, mu_s: float):
        """Per-view tables for an observer at radius ``r`` (m) with the sun at zenith cosine
        ``mu_s``, built once per view (:meth:`radiance` calls this before ``_radiance``);
        nothing for methods whose tables are all view-independent."""

    # --- lookups ----------------------------------------------------------------------------

    def radiance(self, directions, sun_direction, observer_altitude_m: float) -> np.ndarray:
        """Radiance seen from ``observer_altitude_m`` (m) along unit ``directions`` (M, 3),
        east-north-up, with the sun towards ``sun_direction`` (3,): (M, N) W m^-2 sr^-1 nm^-1,
        solar disk excluded."""
        dirs, sun, altitude = self._checked_view(directions, sun_direction, observer_altitude_m)
        n = len(dirs)
        r = self.optics.bottom_radius + altitude
        self._prepare_view(r, float(sun[2]))       # kept while the observer and the sun stay
        channels = self._radiance(_lanes(np.full(n, r)), _lanes(dirs[:, 2]), _lanes(np.full(n, sun[2])),
                                  _lanes(np.clip(dirs @ sun, -1.0, 1.0)))
        dr.eval(channels)                          # one kernel for every channel
        return np.stack([np.asarray(c.numpy(), dtype=np.float64) for c in channels], axis=1)

    def _radiance(self, r, mu, mu_s, nu):
        raise NotImplementedError

    def lookup_seconds_per_direction(self, directions, sun_direction, observer_altitude_m: float,
                                     repeats: int = 3) -> float:
        """Best-of-``repeats`` wall time of :meth:`radiance` per direction, s (all wavelengths)."""
        self.radiance(directions[:16], sun_direction, observer_altitude_m)  # compile kernels
        best = np.inf
        for _ in range(repeats):
            start = time.perf_counter()
            self.radiance(directions, sun_direction, observer_altitude_m)
            best = min(best, time.perf_counter() - start)
        return best / len(directions)
