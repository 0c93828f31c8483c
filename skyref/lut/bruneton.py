"""Bruneton 2017, "Precomputed Atmospheric Scattering: a New Implementation".

E. Bruneton's 2017 rewrite of Bruneton & Neyret 2008 precomputes, for a spherical planet with a
horizontally uniform atmosphere, four tables (GPU textures) from which a shader reads the sky,
the aerial perspective and the ground lighting in a handful of lookups:

================  ===========================  =================================================
transmittance     T(r, mu), 256 x 64           to the top of the atmosphere
                                               (:class:`~skyref.lut.transmittance.TransmittanceTable`)
scattering        S(r, mu, mu_s, nu),          single Rayleigh scattering without its phase
                  32 x 128 x 32 x 8            function plus every higher order divided by the
                                               Rayleigh phase function, W m^-2 nm^-1
single Mie        same grid                    single Mie scattering without its phase function
                                               (or only its first channel, in the alpha channel
                                               of ``scattering``: ``combined_mie``)
irradiance        E(r, mu_s), 64 x 16          sky irradiance on a horizontal surface (no direct
                                               sun), W m^-2 nm^-1
================  ===========================  =================================================

Notation (Bruneton 2017): r is the distance of a point from the planet's centre, mu the cosine of
the view zenith angle, mu_s that of the sun zenith angle and nu that of the angle between view
and sun. "Scattering" at (r, mu, mu_s, nu) is the radiance arriving at the point from the
direction mu, summed along the ray up to the nearest boundary (the top of the atmosphere or the
ground), light whose *last* bounce is a reflection on the ground excluded: it is added at render
time with the true albedo. A "bounce" is a scattering event or a ground reflection, as for the
ground truth's orders.

Precomputation: the transmittance table; the direct sun irradiance on the ground (order 0);
single Rayleigh and Mie scattering (order 1, a ray march towards the nearest boundary with the
sun's transmittance at every point); then for each order n = 2 .. K (K = ``scattering_orders``):

1. the scattering density J_n(r, mu, mu_s, nu): the radiance scattered at a point towards -mu
   after n bounces, an integral over the sphere of incident directions (16 x 32 midpoint samples
   in theta, phi) of the order n-1 radiance (a lookup), plus, for directions that hit the ground,
   the ground's Lambertian reflection of the order n-2 ground irradiance, times the local
   scattering coefficients and phase functions. The paper lays its sample directions out in the
   view's frame, so every cell looks the incident radiance up anew (16 x 32 x 4D lookups per cell
   and wavelength: 88% of the precomputation). skyref lays the same midpoint rule out in the
   sun's frame (turned about the zenith), where the incident radiance at (r, mu_s) depends on
   neither mu nor nu: it is looked up once per (r, mu_s) and direction, and each cell only sums it
   with its phase functions, all wavelengths in one lane (8 x 64 x 16 x 8 cells, 4 orders, 17
   wavelengths: the whole precomputation 169 s -> 30 s; tables within 0.4% of the view-frame
   rule, 0.06% at the 99th percentile);
2. the ground irradiance of order n-1 (hemisphere integral of the order n-1 radiance), added to
   the irradiance table;
3. the order n radiance: J_n integrated along the ray with the transmittance (trapezoidal rule,
   50 intervals), added to the scattering table divided by the Rayleigh phase function of the
   cell's nu.

The scattering stages (single scattering, density, order n radiance) run one Dr.Jit lane per
cell with the wavelength channels in lists, so that the geometry, the table coordinates and the
phase functions are paid once for all wavelengths; the irradiance stages and the incident field
of the density run one lane per (cell, channel). Double precision; the integrals are flat
symbolic loops.
Table storage precision (float32 or float16) applies to the 3D scattering tables, as in
Bruneton's code; transmittance and irradiance are always float32 there and here.

Parametrizations (Bruneton 2017 section "Single scattering precomputation"): with
H = sqrt(R_t^2 - R^2) and rho = sqrt(r^2 - R^2),

- r: x_r = rho / H;
- mu: the upper half of the axis holds rays that reach the top, mapped by their distance d to
  the top between d_min = R_t - r and d_max = rho + H; the lower half holds rays that hit the
  ground, mapped by their distance to the ground between d_min = r - R and d_max = rho (the
  horizon, where the sky radiance is discontinuous, falls between the two halves);
- mu_s: from the distance d to the top along the sun ray *from the ground*,
  a = (d - d_min) / (d_max - d_min) and A the same for the lowest sun stored (mu_s_min, from
  ``max_sun_zenith_deg``), x_mu_s = max(1 - a / A, 0) / (1 + a);
- nu: u_nu = (nu + 1) / 2, on grid points (not texel centres); a cell's nu is clamped to the
  range its mu and mu_s allow.

Each unit-range x is mapped onto texel centres (:func:`~skyref.lut.table.texture_coordinate`).
A 4D table is stored as a 3D texture [r][mu][nu x mu_s] (nu slices side by side) and read with
two trilinear lookups and a linear blend in nu, as a GPU does.

Accuracy against skyref's path tracer (tests/test_lut_bruneton.py has the numbers): single
scattering converges with the table sizes, but the paper's 50 intervals bias it (+0.5% at the
zenith, a few % at the horizon and the sun). Multiple scattering suffers where the
parametrization has few cells: near mu = 1 seen from the ground, and near mu_s = 1 (at the
paper's 32 mu_s cells, suns between 0 and 45 deg from the zenith fall between two cells). There
the range of nu allowed by mu and mu_s collapses, the cells hold a clamped nu (nu = mu_s at
mu = 1, nu = mu at mu_s = 1), and since orders >= 2 are stored divided by the Rayleigh phase
function of that clamped nu, interpolating scales them by P_R(nu) / P_R(nu_cell): with the
paper's sizes double scattering is off by -13% .. +11% 10-40 deg from the zenith (sun at 60 deg)
and the total sky radiance by up to -9% (sun at 30 deg). The 16 x 32 samples of the scattering
density miss the bright horizon band: double scattering near the ground -10% at 680 nm.
On hazy skies (turbidity 6, results/lut_audit.md's sweeps) the 50 steps along rays hundreds of
km long limit it most: 500 steps cut the median sky error 23% -> 7% and the horizon's 89% ->
17%; 128 mu_s cells instead of 32 (the aerosol's forward peak in the scattering density) help
near the sun (14% -> 7%; with 500 steps, 2.9%).

References
----------
E. Bruneton, F. Neyret, "Precomputed Atmospheric Scattering", Computer Graphics Forum 27(4)
(Proc. EGSR 2008), 2008.

E. Bruneton, "Precomputed Atmospheric Scattering: a New Implementation", 2017,
https://ebruneton.github.io/precomputed_atmospheric_scattering/ (code and documentation).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from skyref.validation import check_choice, check_int, check_number
from skyref.errors import ParameterError
from skyref.lut import planet
from skyref.lut.base import LutMethod
from skyref.sky_method import Operations
from skyref.lut.table import PRECISIONS, Table, channel_values, texture_coordinate, unit_range
from skyref.lut.transmittance import TransmittanceTable
from skyref.atmosphere.sun import SUN_ANGULAR_RADIUS_DEG

__all__ = ["METRES_PER_KM", "MAX_INCIDENT_VALUES", "Bruneton2017"]


#: The scattering density is stored per kilometre (W m^-2 sr^-1 nm^-1 km^-1), as in Bruneton's
#: code, whose length unit is the km: per metre its values (~1e-8) would underflow float16.
METRES_PER_KM = 1000.0


def _smoothstep(edge0: float, edge1: float, x):
    t = dr.clip((x - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


#: Most values the incident radiance field of the scattering-density stage may hold (float64: 1 GB).
MAX_INCIDENT_VALUES = 1 << 27


class Bruneton2017(LutMethod):
    """Bruneton 2017's precomputed atmospheric scattering (see the module docstring).

    Table sizes default to the paper's: ``r_size`` x ``mu_size`` x ``mu_s_size`` x ``nu_size``
    = 32 x 128 x 32 x 8 for scattering, 256 x 64 transmittance, 64 x 16 irradiance (width x
    height). Sample counts default to the paper's too: ``integration_samples`` intervals along
    rays (50), ``density_samples`` polar angles of the scattering-density integral (16, with
    twice as many azimuths), ``irradiance_samples`` (32: 16 polar angles over the hemisphere x
    64 azimuths), ``transmittance_samples`` (500). ``max_sun_zenith_deg`` is the lowest sun
    stored (the paper's demo: 120 deg, or 102 deg with float16 tables; default accordingly).
    """

    name = "bruneton2017"

    def __init__(self, atmosphere, wavelengths_nm="rgb", precision: str = "float32",
                 sun_angular_radius_deg: float = SUN_ANGULAR_RADIUS_DEG, variant: str | None = None, *,
                 scattering_orders: int = 4, combined_mie: bool = False,
                 r_size: int = 32, mu_size: int = 128, mu_s_size: int = 32, nu_size: int = 8,
                 transmittance_width: int = 256, transmittance_height: int = 64,
                 irradiance_width: int = 64, irradiance_height: int = 16,
                 max_sun_zenith_deg: float | None = None, integration_samples: int = 50,
                 density_samples: int = 16, irradiance_samples: int = 32, transmittance_samples: int = 500):
        check_choice("precision", precision, PRECISIONS)
        self.scattering_orders = check_int("scattering_orders", scattering_orders, 1, 100)
        if not isinstance(combined_mie, bool):
            raise ParameterError("combined_mie", combined_mie, "true or false", "not a boolean")
        self.combined_mie = combined_mie
        self.r_size = check_int("r_size", r_size, 2, 1024)
        self.mu_size = check_int("mu_size", mu_size, 4, 4096, even=True)
        self.mu_s_size = check_int("mu_s_size", mu_s_size, 2, 1024)
        self.nu_size = check_int("nu_size", nu_size, 2, 1024)
        self.transmittance_width = check_int("transmittance_width", transmittance_width, 2, 8192)
        self.transmittance_height = check_int("transmittance_height", transmittance_height, 2, 8192)
        self.irradiance_width = check_int("irradiance_width", irradiance_width, 2, 8192)
        self.irradiance_height = check_int("irradiance_height", irradiance_height, 2, 8192)
        self.integration_samples = check_int("integration_samples", integration_samples, 1, 100_000)
        self.density_samples = check_int("density_samples", density_samples, 2, 1024)
        self.irradiance_samples = check_int("irradiance_samples", irradiance_samples, 2, 1024, even=True)
        self.transmittance_samples = check_int("transmittance_samples", transmittance_samples, 1, 100_000)
        if max_sun_zenith_deg is None:
            max_sun_zenith_deg = 102.0 if precision == "float16" else 120.0
        self.max_sun_zenith_deg = check_number("max_sun_zenith_deg", max_sun_zenith_deg, 90.0, 180.0,
                                               lo_open=True)
        super().__init__(atmosphere, wavelengths_nm, precision, sun_angular_radius_deg, variant)
        incident_values = self.r_size * self.mu_s_size * 2 * self.density_samples ** 2 * self.channels
        if incident_values > MAX_INCIDENT_VALUES:
            raise ParameterError("density_samples", density_samples,
                                 f"r_size x mu_s_size x 2 density_samples^2 x wavelengths <= {MAX_INCIDENT_VALUES:,}",
                                 f"the incident radiance field would hold {incident_values:,} values: fewer density "
                                 "samples, r or mu_s cells, or wavelengths")

        self.bottom_radius = self.optics.bottom_radius
        self.top_radius = self.optics.top_radius
        self.horizon_distance = math.sqrt(self.top_radius ** 2 - self.bottom_radius ** 2)
        self.mu_s_min = math.cos(math.radians(self.max_sun_zenith_deg))
        self.lowest_sun_fraction = float(self._sun_distance_fraction(self.mu_s_min))   # "A" in the paper
        # Per-channel constants for the lookups (coefficients at relative density 1, m^-1).
        channels = [mi.UInt32(k) for k in range(self.channels)]
        rayleigh, mie = zip(*(self.optics.scattering(mi.Float64(0.0), ch) for ch in channels))
        self.rayleigh_scattering = np.array([float(x.numpy()[0]) for x in rayleigh])
        self.mie_scattering = np.array([float(x.numpy()[0]) for x in mie])
        self.ground_albedo = np.array([float(self.optics.ground_albedo(ch).numpy()[0]) for ch in channels])
        # The ratio of the paper's extrapolation of single Mie from its first channel:
        # mie_k = S_k * mie_0 / S_0 * (beta_R,0 / beta_M,0) * (beta_M,k / beta_R,k).
        if combined_mie:
            if np.any(self.rayleigh_scattering <= 0.0):
                raise ParameterError("combined_mie", True, "false for an atmosphere without Rayleigh scattering",
                                     "single Mie is extrapolated through Rayleigh's coefficients")
            first = self.mie_scattering[0]
            self.mie_extrapolation = (np.zeros(self.channels) if first <= 0.0 else
                                      self.rayleigh_scattering[0] / first * self.mie_scattering
                                      / self.rayleigh_scattering)
        self.transmittance = self.scattering = self.single_mie = self.irradiance = None

    # --- parametrizations --------------------------------------------------------------------

    def scattering_coordinates(self, r, mu, mu_s, nu, ray_hits_ground):
        """(u_nu, u_mu_s, u_mu, u_r) texture coordinates of (r, mu, mu_s, nu) in the 4D
        scattering table (Bruneton 2017, GetScatteringTextureUvwzFromRMuMuSNu)."""
        R, Rt, H = self.bottom_radius, self.top_radius, self.horizon_distance
        rho = dr.safe_sqrt(r * r - R * R)
        u_r = texture_coordinate(rho / H, self.r_size)
        r_mu = r * mu
        discriminant = r_mu * r_mu - r * r + R * R
        half = self.mu_size // 2
        # Rays to the ground: distance to the ground between r - R (straight down) and rho
        # (tangent to the ground), on the lower half of the axis, reversed.
        d_ground = -r_mu - dr.safe_sqrt(discriminant)
        d_min, d_max = r - R, rho
        x_ground = dr.select(d_max == d_min, 0.0, (d_ground - d_min) / dr.maximum(d_max - d_min, 1e-30))
        u_mu_ground = 0.5 - 0.5 * texture_coordinate(x_ground, half)
        # Rays to the sky: distance to the top between R_t - r (straight up) and rho + H.
        d_top = -r_mu + dr.safe_sqrt(discriminant + H * H)
        d_min, d_max = Rt - r, rho + H
        u_mu_sky = 0.5 + 0.5 * texture_coordinate((d_top - d_min) / (d_max - d_min), half)
        u_mu = dr.select(ray_hits_ground, u_mu_ground, u_mu_sky)
        a = self._sun_distance_fraction(mu_s)
        A = self.lowest_sun_fraction
        u_mu_s = texture_coordinate(dr.maximum(1.0 - a / A, 0.0) / (1.0 + a), self.mu_s_size)
        return (nu + 1.0) / 2.0, u_mu_s, u_mu, u_r

    def _sun_distance_fraction(self, mu_s):
        """a = (d - d_min) / (d_max - d_min): the distance d from the ground to the top along a
        sun ray, between d_min = R_t - R (sun at the zenith) and d_max = H (sun on the horizon)."""
        R, Rt, H = self.bottom_radius, self.top_radius, self.horizon_distance
        d = -R * mu_s + dr.safe_sqrt(R * R * (mu_s * mu_s - 1.0) + Rt * Rt)
        return (d - (Rt - R)) / (H - (Rt - R))

    def scattering_parameters(self, u_nu, u_mu_s, u_mu, u_r):
        """Inverse of :meth:`scattering_coordinates`: (r, mu, mu_s, nu, ray_hits_ground)
        (Bruneton 2017, GetRMuMuSNuFromScatteringTextureUvwz)."""
        R, Rt, H = self.bottom_radius, self.top_radius, self.horizon_distance
        rho = H * unit_range(u_r, self.r_size)
        r = dr.sqrt(rho * rho + R * R)
        half = self.mu_size // 2
        ray_hits_ground = u_mu < 0.5
        d_min, d_max = r - R, rho
        d = d_min + (d_max - d_min) * unit_range(1.0 - 2.0 * u_mu, half)
        mu_ground = dr.select(d == 0.0, -1.0, -(rho * rho + d * d) / dr.maximum(2.0 * r * d, 1e-30))
        d_min, d_max = Rt - r, rho + H
        d = d_min + (d_max - d_min) * unit_range(2.0 * u_mu - 1.0, half)
        mu_sky = dr.select(d == 0.0, 1.0, (H * H - rho * rho - d * d) / dr.maximum(2.0 * r * d, 1e-30))
        mu = dr.clip(dr.select(ray_hits_ground, mu_ground, mu_sky), -1.0, 1.0)

        x_mu_s = unit_range(u_mu_s, self.mu_s_size)
        A = self.lowest_sun_fraction
        a = (A - x_mu_s * A) / (1.0 + x_mu_s * A)
        d_min, d_max = Rt - R, H
        d = d_min + dr.minimum(a, A) * (d_max - d_min)
        mu_s = dr.clip(dr.select(d == 0.0, 1.0, (H * H - d * d) / dr.maximum(2.0 * R * d, 1e-30)), -1.0, 1.0)
        nu = dr.clip(u_nu * 2.0 - 1.0, -1.0, 1.0)
        return r, mu, mu_s, nu, ray_hits_ground

    def irradiance_coordinates(self, r, mu_s):
        """(u_mu_s, u_r) of the irradiance table: both affine (the irradiance is smooth)."""
        x_r = (r - self.bottom_radius) / (self.top_radius - self.bottom_radius)
        return (texture_coordinate(mu_s * 0.5 + 0.5, self.irradiance_width),
                texture_coordinate(x_r, self.irradiance_height))

    def irradiance_parameters(self, u_mu_s, u_r):
        """Inverse of :meth:`irradiance_coordinates`: (r, mu_s)."""
        r = self.bottom_radius + unit_range(u_r, self.irradiance_height) * (self.top_radius - self.bottom_radius)
        return r, dr.clip(2.0 * unit_range(u_mu_s, self.irradiance_width) - 1.0, -1.0, 1.0)

    # --- table cells as lanes ------------------------------------------------------------------

    def _scattering_cells(self):
        """(r, mu, mu_s, nu, ray_hits_ground) of every scattering cell, one lane each, in the 3D
        texture's order [r][mu][nu * mu_s_size + mu_s]. nu sits on grid points i / (nu_size - 1)
        and is clamped to the range that mu and mu_s allow (nu is not independent of them: the
        view and the sun are both unit vectors)."""
        width = self.nu_size * self.mu_s_size
        cell = dr.arange(mi.UInt32, self.r_size * self.mu_size * width)
        x = cell % width
        i_mu = (cell // width) % self.mu_size
        i_r = cell // (width * self.mu_size)
        u_nu = mi.Float64(x // self.mu_s_size) / (self.nu_size - 1)
        u_mu_s = (mi.Float64(x % self.mu_s_size) + 0.5) / self.mu_s_size
        u_mu = (mi.Float64(i_mu) + 0.5) / self.mu_size
        u_r = (mi.Float64(i_r) + 0.5) / self.r_size
        r, mu, mu_s, nu, ray_hits_ground = self.scattering_parameters(u_nu, u_mu_s, u_mu, u_r)
        spread = dr.safe_sqrt((1.0 - mu * mu) * (1.0 - mu_s * mu_s))
        nu = dr.clip(nu, mu * mu_s - spread, mu * mu_s + spread)
        return r, mu, mu_s, nu, ray_hits_ground

    def _irradiance_cells(self):
        """(r, mu_s, channel) of every (irradiance cell, channel) lane, cells [r][mu_s]."""
        lane = dr.arange(mi.UInt32, self.irradiance_width * self.irradiance_height * self.channels)
        channel = lane % self.channels
        cell = lane // self.channels
        u_mu_s = (mi.Float64(cell % self.irradiance_width) + 0.5) / self.irradiance_width
        u_r = (mi.Float64(cell // self.irradiance_width) + 0.5) / self.irradiance_height
        r, mu_s = self.irradiance_parameters(u_mu_s, u_r)
        return r, mu_s, channel

    def _scattering_table(self, per_channel, scale: float = 1.0) -> Table:
        """A scattering table from one Dr.Jit array per channel (one lane per cell), times ``scale``."""
        return Table.from_channels(per_channel, (self.r_size, self.mu_size, self.nu_size * self.mu_s_size),
                                   self.precision, scale)

    def _irradiance_table(self, values) -> Table:
        return Table(values, (self.irradiance_height, self.irradiance_width), self.channels, "float32")

    # --- 4D lookups ------------------------------------------------------------------------------

    def _lookup(self, table: Table, coordinates, channel=None):
        """Quadrilinear lookup at (u_nu, u_mu_s, u_mu, u_r) in a 4D table stored as 3D: two
        trilinear lookups in the neighbouring nu slices, blended linearly (GetScattering).
        ``channel`` as in :meth:`Table.lookup`."""
        u_nu, u_mu_s, u_mu, u_r = coordinates
        x = u_nu * (self.nu_size - 1)
        slice_index = dr.floor(x)
        weight = x - slice_index
        lower = table.lookup((u_r, u_mu, (slice_index + u_mu_s) / self.nu_size), channel)
        upper = table.lookup((u_r, u_mu, (slice_index + 1.0 + u_mu_s) / self.nu_size), channel)
        if channel is not None:
            return lower * (1.0 - weight) + upper * weight
        return [a * (1.0 - weight) + b * weight for a, b in zip(lower, upper)]

    def _irradiance_lookup(self, table: Table, r, mu_s, channel=None):
        u_mu_s, u_r = self.irradiance_coordinates(r, mu_s)
        return table.lookup((u_r, u_mu_s), channel)

    # --- precomputation ------------------------------------------------------------------------

    def _precompute(self):
        optics = self.optics
        self.transmittance = TransmittanceTable(optics, self.transmittance_width, self.transmittance_height,
                                                self.transmittance_samples, "float32")
        r_e, mu_s_e, channel_e = self._irradiance_cells()
        ground_irradiance = self._irradiance_table(self._direct_irradiance(r_e, mu_s_e, channel_e).numpy())
        sky_irradiance = np.zeros(self.irradiance_width * self.irradiance_height * self.channels)
        self._stage_done("transmittance and direct irradiance")

        r, mu, mu_s, nu, hits = self._scattering_cells()
        rayleigh, mie = self._single_scattering(r, mu, mu_s, nu, hits)
        dr.eval(rayleigh, mie)                     # one kernel for every channel
        single_rayleigh = self._scattering_table(rayleigh)
        single_mie = self._scattering_table(mie)
        scattering = channel_values(rayleigh).reshape(-1)
        single_mie_values = channel_values(mie).reshape(-1)
        self._stage_done("single scattering")

        previous_order = self._single_order(single_rayleigh, single_mie)
        rayleigh_phase = optics.rayleigh_phase(nu)
        for order in range(2, self.scattering_orders + 1):
            incident = self._incident_radiance(previous_order, ground_irradiance)
            density = self._scattering_density(r, mu, mu_s, nu, incident)
            dr.eval(density)                       # one kernel for every channel
            density = self._scattering_table(density, METRES_PER_KM)
            self._stage_done(f"order {order}: scattering density")
            delta = self._indirect_irradiance(r_e, mu_s_e, channel_e, previous_order).numpy()
            sky_irradiance += delta
            ground_irradiance = self._irradiance_table(delta)
            radiance = self._multiple_scattering(r, mu, mu_s, nu, hits, density)
            dr.eval(radiance)                      # one kernel for every channel
            previous_order = self._multiple_order(self._scattering_table(radiance))
            # Stored divided by the Rayleigh phase function, multiplied back at lookup.
            scattering += channel_values([x / rayleigh_phase for x in radiance]).reshape(-1)
            self._stage_done(f"order {order}: irradiance and radiance")

        shape = (self.r_size, self.mu_size, self.nu_size * self.mu_s_size)
        if self.combined_mie:
            combined = np.concatenate([scattering.reshape(-1, self.channels),
                                       single_mie_values.reshape(-1, self.channels)[:, :1]], axis=1)
            self.scattering = Table(combined, shape, self.channels + 1, self.precision)
            self.single_mie = None
        else:
            self.scattering = Table(scattering, shape, self.channels, self.precision)
            self.single_mie = Table(single_mie_values, shape, self.channels, self.precision)
        self.irradiance = self._irradiance_table(sky_irradiance)

    def precompute_stages(self) -> list:
        return (["transmittance and direct irradiance", "single scattering"]
                + [f"order {n}: {stage}" for n in range(2, self.scattering_orders + 1)
                   for stage in ("scattering density", "irradiance and radiance")])

    def _single_order(self, rayleigh: Table, mie: Table):
        """Order-1 radiance from the single Rayleigh and Mie tables, phase functions applied:
        a function of (r, mu, mu_s, nu, ray_hits_ground, channel)."""
        def radiance(r, mu, mu_s, nu, ray_hits_ground, channel):
            coordinates = self.scattering_coordinates(r, mu, mu_s, nu, ray_hits_ground)
            return (self._lookup(rayleigh, coordinates, channel) * self.optics.rayleigh_phase(nu)
                    + self._lookup(mie, coordinates, channel) * self.optics.mie_phase(nu))
        return radiance

    def _multiple_order(self, table: Table):
        """Order-n radiance (n >= 2) from its table, like :meth:`_single_order`."""
        def radiance(r, mu, mu_s, nu, ray_hits_ground, channel):
            return self._lookup(table, self.scattering_coordinates(r, mu, mu_s, nu, ray_hits_ground), channel)
        return radiance

    def _solar_irradiance(self, channel):
        return dr.gather(mi.Float64, mi.Float64(self.solar_irradiance), channel)

    def _direct_irradiance(self, r, mu_s, channel):
        """Direct sun irradiance on a horizontal surface, W m^-2 nm^-1: E T(r, mu_s) times the
        mean of the cosine factor over the visible part of the disk, (mu_s + alpha)^2 / (4 alpha)
        while the disk straddles the horizontal (ComputeDirectIrradiance)."""
        alpha = self.sun_angular_radius
        cosine_factor = dr.select(mu_s < -alpha, 0.0, dr.select(mu_s > alpha, mu_s,
                                                                (mu_s + alpha) ** 2 / (4.0 * alpha)))
        return self._solar_irradiance(channel) * self.transmittance.to_top(r, mu_s, channel) * cosine_factor

    @dr.syntax
    def _single_scattering(self, r, mu, mu_s, nu, ray_hits_ground):
        """Single Rayleigh and Mie scattering without phase functions, W m^-2 nm^-1: along the
        ray to the nearest boundary, E T(sun -> q) sigma_s(q) T(q -> p) integrated over the
        scattering point q at distance d, with r_d = |q| and the sun's cosine there
        mu_s,d = (r mu_s + d nu) / r_d (trapezoidal rule, ComputeSingleScattering). One lane per
        scattering cell, its channels in lists: the ray's geometry is paid once for all
        wavelengths. Returns (Rayleigh, Mie), a list of arrays each, one per channel."""
        n = self.integration_samples
        channels = range(self.channels)
        dx = planet.distance_to_nearest_boundary(r, mu, self.bottom_radius, self.top_radius, ray_hits_ground) / n
        at_start = self.transmittance.ray_start(r, mu, ray_hits_ground)
        rayleigh = [mi.Float64(0.0) for _ in channels]
        mie = [mi.Float64(0.0) for _ in channels]
        i = mi.UInt32(0)
        while i <= n:
            d = mi.Float64(i) * dx
            r_d, _ = planet.point_along_ray(r, mu, d)
            r_d = dr.clip(r_d, self.bottom_radius, self.top_radius)
            mu_s_d = dr.clip((r * mu_s + d * nu) / r_d, -1.0, 1.0)
            to_point = self.transmittance.between_from(at_start, r, mu, d, ray_hits_ground)
            to_sun = self.transmittance.to_sun(r_d, mu_s_d, self.sun_angular_radius)
            sigma_rayleigh, sigma_mie = self.optics.scattering_by_channel(r_d - self.bottom_radius, self.channels)
            end_point = dr.select((i == 0) | (i == n), 0.5, 1.0)
            weight = [end_point * (to_point[k] * to_sun[k]) for k in channels]
            rayleigh = [rayleigh[k] + weight[k] * sigma_rayleigh[k] for k in channels]
            mie = [mie[k] + weight[k] * sigma_mie[k] for k in channels]
            i += 1
        solar = [float(self.solar_irradiance[k]) * dx for k in channels]
        return [rayleigh[k] * solar[k] for k in channels], [mie[k] * solar[k] for k in channels]

    def _density_directions(self, index):
        """Direction ``index`` (UInt32 < 2 n^2) of the scattering-density quadrature, n =
        ``density_samples``: the midpoints of n polar x 2n azimuthal angles in the *sun's* frame
        (zenith z, the sun in the xz-plane). Returns (wx, wy, wz, solid-angle weight)."""
        n = self.density_samples
        step = math.pi / n
        theta = (mi.Float64(index // (2 * n)) + 0.5) * step
        phi = (mi.Float64(index % (2 * n)) + 0.5) * step
        sin_theta, cos_theta = dr.sincos(theta)
        sin_phi, cos_phi = dr.sincos(phi)
        return cos_phi * sin_theta, sin_phi * sin_theta, cos_theta, sin_theta * step * step

    def _incident_radiance(self, previous_order, ground_irradiance) -> mi.Float64:
        """The order n-1 radiance arriving at every (r, mu_s) of the scattering table from every
        direction omega_i of the density quadrature, times its solid angle (flat Float64 in the
        order [r][mu_s][direction][channel]): [order n-1 radiance from omega_i
        (``previous_order``) + for omega_i that hit the ground, T(to the ground) albedo / pi
        E_{n-2}(ground point) (``ground_irradiance``)]. In the sun's frame this field depends on
        neither the view's mu nor nu, so it is looked up once per (r, mu_s), not once per cell."""
        R = self.bottom_radius
        directions = 2 * self.density_samples ** 2
        lane = dr.arange(mi.UInt32, self.r_size * self.mu_s_size * directions * self.channels)
        channel = lane % self.channels
        direction = (lane // self.channels) % directions
        i_mu_s = (lane // (self.channels * directions)) % self.mu_s_size
        i_r = lane // (self.channels * directions * self.mu_s_size)
        r, _, mu_s, _, _ = self.scattering_parameters(mi.Float64(0.5), (mi.Float64(i_mu_s) + 0.5) / self.mu_s_size,
                                                      mi.Float64(0.75), (mi.Float64(i_r) + 0.5) / self.r_size)
        sin_s = dr.safe_sqrt(1.0 - mu_s * mu_s)
        wx, _, wz, weight = self._density_directions(direction)
        hits_ground = planet.intersects_ground(r, wz, R)
        incident = previous_order(r, wz, mu_s, sin_s * wx + mu_s * wz, hits_ground, channel)
        # Light whose last bounce was the ground: the ground point at distance d has the normal
        # (omega_i d + r z) / R, and the sun's cosine there is its dot with omega_s.
        d = planet.distance_to_bottom(r, wz, R)
        mu_s_ground = (sin_s * wx * d + mu_s * (r + wz * d)) / R
        reflected = (self.transmittance.between(r, wz, d, hits_ground, channel) * self.optics.ground_albedo(channel)
                     / math.pi * self._irradiance_lookup(ground_irradiance, mi.Float64(R), mu_s_ground, channel))
        incident += dr.select(hits_ground, reflected, 0.0)
        result = incident * weight
        dr.eval(result)
        return result

    @dr.syntax
    def _scattering_density(self, r, mu, mu_s, nu, incident):
        """Radiance scattered at radius r towards -omega (zenith cosine mu) after n bounces,
        W m^-3 sr^-1 nm^-1 (ComputeScatteringDensity): the sphere integral over incident
        directions omega_i of the ``incident`` radiance (:meth:`_incident_radiance`) x sum over
        Rayleigh and Mie of sigma_s p(omega . omega_i), by the midpoint rule of
        :meth:`_density_directions` in the sun's frame (the paper integrates in the view's frame;
        the same rule turned about the zenith). One lane per scattering cell, its channels in a
        list: the geometry and the phase functions are paid once for all wavelengths."""
        R = self.bottom_radius
        directions = 2 * self.density_samples ** 2
        channels = range(self.channels)
        # omega in the sun's frame: omega . z = mu, omega . sun = nu, sun = (sin_s, 0, mu_s)
        sin_s = dr.safe_sqrt(1.0 - mu_s * mu_s)
        omega_x = dr.select(sin_s == 0.0, dr.safe_sqrt(1.0 - mu * mu), (nu - mu * mu_s) / dr.maximum(sin_s, 1e-30))
        omega_y = dr.safe_sqrt(1.0 - mu * mu - omega_x * omega_x)
        sigma_rayleigh, sigma_mie = self.optics.scattering_by_channel(r - R, self.channels)
        # the (r, mu_s) row of the incident field this cell reads
        cell = dr.arange(mi.UInt32, dr.width(mu))
        width = self.nu_size * self.mu_s_size
        row = (cell // (width * self.mu_size)) * self.mu_s_size + cell % self.mu_s_size
        start = row * (directions * self.channels)
        # the quadrature's directions, computed once and read by every cell
        direction_x, direction_y, direction_z, _ = self._density_directions(dr.arange(mi.UInt32, directions))
        dr.eval(direction_x, direction_y, direction_z)
        total = [mi.Float64(0.0) for _ in channels]
        i = mi.UInt32(0)
        while i < directions:
            wx = dr.gather(mi.Float64, direction_x, i)
            wy = dr.gather(mi.Float64, direction_y, i)
            wz = dr.gather(mi.Float64, direction_z, i)
            cos_scatter = omega_x * wx + omega_y * wy + mu * wz
            phase_rayleigh = self.optics.rayleigh_phase(cos_scatter)
            phase_mie = self.optics.mie_phase(cos_scatter)
            offset = start + i * self.channels
            total = [total[k] + dr.gather(mi.Float64, incident, offset + k)
                     * (sigma_rayleigh[k] * phase_rayleigh + sigma_mie[k] * phase_mie) for k in channels]
            i += 1
        return total

    @dr.syntax
    def _indirect_irradiance(self, r, mu_s, channel, previous_order):
        """Irradiance of order n-1 sky light on a horizontal surface, W m^-2 nm^-1: the
        hemisphere integral of the order n-1 radiance times the cosine factor
        (ComputeIndirectIrradiance; midpoint rule, ``irradiance_samples``/2 polar x
        2 ``irradiance_samples`` azimuthal angles)."""
        n = self.irradiance_samples
        step = math.pi / n
        sun_x = dr.safe_sqrt(1.0 - mu_s * mu_s)
        total = mi.Float64(0.0)
        i = mi.UInt32(0)
        while i < n * n:
            theta = (mi.Float64(i // (2 * n)) + 0.5) * step
            phi = (mi.Float64(i % (2 * n)) + 0.5) * step
            sin_theta, cos_theta = dr.sincos(theta)
            nu = dr.cos(phi) * sin_theta * sun_x + cos_theta * mu_s
            radiance = previous_order(r, cos_theta, mu_s, nu, mi.Bool(False), channel)
            total += radiance * cos_theta * sin_theta * (step * step)
            i += 1
        return total

    @dr.syntax
    def _multiple_scattering(self, r, mu, mu_s, nu, ray_hits_ground, density: Table):
        """Order n radiance, W m^-2 sr^-1 nm^-1: the density J_n (``density``, stored per km) at
        the points q of the ray to the nearest boundary times T(p -> q), trapezoidal rule
        (ComputeMultipleScattering). One lane per scattering cell, its channels in a list."""
        n = self.integration_samples
        channels = range(self.channels)
        dx = planet.distance_to_nearest_boundary(r, mu, self.bottom_radius, self.top_radius, ray_hits_ground) / n
        at_start = self.transmittance.ray_start(r, mu, ray_hits_ground)
        total = [mi.Float64(0.0) for _ in channels]
        i = mi.UInt32(0)
        while i <= n:
            d = mi.Float64(i) * dx
            r_d, mu_d = planet.point_along_ray(r, mu, d)
            r_d = dr.clip(r_d, self.bottom_radius, self.top_radius)
            mu_s_d = dr.clip((r * mu_s + d * nu) / r_d, -1.0, 1.0)
            coordinates = self.scattering_coordinates(r_d, mu_d, mu_s_d, nu, ray_hits_ground)
            source = self._lookup(density, coordinates)
            transmittance = self.transmittance.between_from(at_start, r, mu, d, ray_hits_ground)
            end_point = dr.select((i == 0) | (i == n), 0.5, 1.0)
            total = [total[k] + end_point * (source[k] * transmittance[k]) for k in channels]
            i += 1
        return [t * (dx / METRES_PER_KM) for t in total]

    # --- lookups (rendering) -------------------------------------------------------------------

    def _enter_atmosphere(self, r, mu, mu_s, nu):
        """A viewer in space whose ray meets the atmosphere is moved along it to the top
        boundary. Returns (r, mu, mu_s there, the distance moved, whether the ray misses the
        atmosphere altogether)."""
        Rt = self.top_radius
        r_mu = r * mu
        discriminant = r_mu * r_mu - r * r + Rt * Rt
        d = -r_mu - dr.safe_sqrt(discriminant)
        in_space = r > Rt
        enters = in_space & (discriminant >= 0.0) & (d > 0.0)
        d = dr.select(enters, d, 0.0)
        mu_new = dr.select(enters, (r_mu + d) / Rt, mu)
        mu_s_new = dr.select(enters, (r * mu_s + d * nu) / Rt, mu_s)
        r_new = dr.clip(r, self.bottom_radius, Rt)
        return r_new, dr.clip(mu_new, -1.0, 1.0), dr.clip(mu_s_new, -1.0, 1.0), d, in_space & ~enters

    def _scattering_and_mie(self, r, mu, mu_s, nu, ray_hits_ground):
        """(scattering, Mie part) lookups for every channel: Mie part = the single Mie values,
        or [its first channel] with ``combined_mie`` (GetCombinedScattering)."""
        coordinates = self.scattering_coordinates(r, mu, mu_s, nu, ray_hits_ground)
        scattering = self._lookup(self.scattering, coordinates)
        if self.combined_mie:
            return scattering[:self.channels], scattering[self.channels:]
        return scattering, self._lookup(self.single_mie, coordinates)

    def _single_mie(self, scattering, mie_part):
        """Single Mie scattering for every channel; with ``combined_mie``, extrapolated from the
        first channel: mie_k = S_k mie_0 / S_0 (beta_R,0 / beta_M,0) (beta_M,k / beta_R,k)
        (Bruneton & Neyret 2008; GetExtrapolatedSingleMieScattering)."""
        if not self.combined_mie:
            return mie_part
        first = scattering[0]
        ratio = dr.select(first <= 0.0, 0.0, mie_part[0] / dr.maximum(first, 1e-300))
        return [s * ratio * float(k) for s, k in zip(scattering, self.mie_extrapolation)]

    def _phase_sum(self, scattering, mie, nu):
        rayleigh_phase, mie_phase = self.optics.rayleigh_phase(nu), self.optics.mie_phase(nu)
        return [s * rayleigh_phase + m * mie_phase for s, m in zip(scattering, mie)]

    def sky_radiance(self, r, mu, mu_s, nu):
        """Radiance of the sky (no sun disk) seen from radius r (m, may be in space) along mu,
        and the transmittance of the ray (0 where it hits the ground, 1 where it misses the
        atmosphere): two lists of Float64 arrays, one per channel (GetSkyRadiance, without
        light shafts). Where the ray hits the ground this is the in-scattering up to it."""
        r, mu, mu_s, _, misses = self._enter_atmosphere(r, mu, mu_s, nu)
        hits = planet.intersects_ground(r, mu, self.bottom_radius)
        transmittance = [dr.select(hits, 0.0, dr.select(misses, 1.0, t))
                         for t in self.transmittance.to_top(r, mu)]
        scattering, mie_part = self._scattering_and_mie(r, mu, mu_s, nu, hits)
        radiance = self._phase_sum(scattering, self._single_mie(scattering, mie_part), nu)
        return [dr.select(misses, 0.0, value) for value in radiance], transmittance

    def sky_radiance_to_point(self, r, mu, mu_s, nu, d):
        """In-scattered radiance between the viewer (radius r, m) and the point at distance d
        (m) along mu, and the transmittance between them: lists per channel
        (GetSkyRadianceToPoint): the scattering lookup at the viewer minus T times the lookup at
        the point. Single Mie is faded out over 0 < mu_s < 0.01, as in the paper (a hack there
        against artifacts for a sun below the horizon)."""
        r, mu, mu_s, entered, _ = self._enter_atmosphere(r, mu, mu_s, nu)
        d = dr.maximum(d - entered, 0.0)
        hits = planet.intersects_ground(r, mu, self.bottom_radius)
        transmittance = self.transmittance.between(r, mu, d, hits)
        scattering, mie_part = self._scattering_and_mie(r, mu, mu_s, nu, hits)
        r_p, mu_p = planet.point_along_ray(r, mu, d)
        r_p = dr.clip(r_p, self.bottom_radius, self.top_radius)
        mu_s_p = dr.clip((r * mu_s + d * nu) / r_p, -1.0, 1.0)
        scattering_p, mie_part_p = self._scattering_and_mie(r_p, mu_p, mu_s_p, nu, hits)
        # With combined Mie the alpha channel holds channel 0, so it takes channel 0's T.
        mie_transmittance = transmittance[:1] if self.combined_mie else transmittance
        scattering = [a - t * b for a, b, t in zip(scattering, scattering_p, transmittance)]
        mie_part = [a - t * b for a, b, t in zip(mie_part, mie_part_p, mie_transmittance)]
        fade = _smoothstep(0.0, 0.01, mu_s)
        mie = [m * fade for m in self._single_mie(scattering, mie_part)]
        return self._phase_sum(scattering, mie, nu), transmittance

    def sun_radiance(self, r, mu_s):
        """Radiance of the solar disk seen from radius r (m) looking at the sun:
        E / (pi alpha^2) x T along the sun ray (GetSolarRadiance x GetSkyRadiance's
        transmittance); pi alpha^2 is the paper's disk solid angle (the exact cap
        2 pi (1 - cos alpha) is smaller by a factor 1 - alpha^2 / 12, 2e-6 for the sun). List
        per channel."""
        _, transmittance = self.sky_radiance(r, mu_s, mu_s, dr.full(mi.Float64, 1.0, dr.width(mu_s)))
        disk = math.pi * self.sun_angular_radius ** 2
        return [t * float(e / disk) for t, e in zip(transmittance, self.solar_irradiance)]

    def sun_and_sky_irradiance(self, r, mu_s, normal_dot_up=1.0, normal_dot_sun=None):
        """(sun, sky) irradiance, W m^-2 nm^-1, on a surface at radius r (m) whose normal has
        cosines ``normal_dot_up`` with the local zenith and ``normal_dot_sun`` with the sun
        (default: a horizontal surface, mu_s): sun = E T_sun max(n.s, 0); sky = the horizontal
        sky irradiance x (1 + n.z) / 2 (GetSunAndSkyIrradiance). Lists per channel."""
        normal_dot_sun = mu_s if normal_dot_sun is None else normal_dot_sun
        sky = [e * ((1.0 + normal_dot_up) * 0.5) for e in self._irradiance_lookup(self.irradiance, r, mu_s)]
        sun_transmittance = self.transmittance.to_sun(r, mu_s, self.sun_angular_radius)
        sun = [t * float(e) * dr.maximum(normal_dot_sun, 0.0) for t, e in zip(sun_transmittance, self.solar_irradiance)]
        return sun, sky

    def _radiance(self, r, mu, mu_s, nu):
        """The sky where the ray misses the ground; where it hits it, the ground as the paper's
        demo shades it: albedo / pi (sun + sky irradiance at the ground point) x T to it +
        the in-scattering to it."""
        sky, _ = self.sky_radiance(r, mu, mu_s, nu)
        r_a, mu_a, mu_s_a, entered, misses = self._enter_atmosphere(r, mu, mu_s, nu)
        hits = planet.intersects_ground(r_a, mu_a, self.bottom_radius) & ~misses
        d_ground = planet.distance_to_bottom(r_a, mu_a, self.bottom_radius)
        mu_s_ground = dr.clip((r_a * mu_s_a + d_ground * nu) / self.bottom_radius, -1.0, 1.0)
        sun, sky_irradiance = self.sun_and_sky_irradiance(mi.Float64(self.bottom_radius), mu_s_ground)
        in_scattering, transmittance = self.sky_radiance_to_point(r, mu, mu_s, nu, entered + d_ground)
        ground = [float(a / math.pi) * (e_sun + e_sky) * t + s for a, e_sun, e_sky, t, s
                  in zip(self.ground_albedo, sun, sky_irradiance, transmittance, in_scattering)]
        return [dr.select(hits, g, s) for g, s in zip(ground, sky)]

    # --- tables in Bruneton 2017's texture layout ------------------------------------------------

    def tables(self) -> dict:
        """The stored tables as NumPy arrays in the layout of Bruneton 2017's textures:
        ``transmittance`` [height=64][width=256][C], ``scattering`` [R][MU][NU * MU_S][C]
        (C + 1 with ``combined_mie``: single Mie of channel 0 last, the alpha channel),
        ``single_mie`` (separate Mie only) like scattering with C channels, ``irradiance``
        [16][64][C]."""
        if self.scattering is None:
            raise RuntimeError(f"{self.name}: call precompute() before tables()")
        out = {"transmittance": self.transmittance.table.numpy(), "scattering": self.scattering.numpy(),
               "irradiance": self.irradiance.numpy()}
        if self.single_mie is not None:
            out["single_mie"] = self.single_mie.numpy()
        return out

    def operations(self) -> Operations:
        """Fetches per direction, from :meth:`_radiance`: the sky reads the scattering table (and
        single Mie, unless combined) in the two nu slices around the view's nu (:meth:`_lookup`);
        a ground view reads them at the viewer and at the ground point
        (:meth:`sky_radiance_to_point`), the transmittance at both ends and towards the sun, and
        the irradiance at the ground point. Nothing is rebuilt per view."""
        mie = {} if self.combined_mie else {"single_mie": 2}
        scattering = (self.r_size, self.mu_size, self.nu_size * self.mu_s_size)
        tables = {"transmittance": (self.transmittance_height, self.transmittance_width), "scattering": scattering,
                  **({} if self.combined_mie else {"single_mie": scattering}),
                  "irradiance": (self.irradiance_height, self.irradiance_width)}
        return Operations(
            tables=tables,
            sky={"scattering fetches": 2, **{f"{k} fetches": v for k, v in mie.items()}},
            ground={"scattering fetches": 4, **{f"{k} fetches": 2 * v for k, v in mie.items()},
                    "transmittance fetches": 3, "irradiance fetches": 1},
            note="this implementation evaluates the sky and the ground terms for every direction")

    def stored_as(self, precision: str | None = None, combined_mie: bool | None = None) -> "Bruneton2017":
        """These tables stored differently, without precomputing again: ``precision`` "float16"
        or "float32", and/or ``combined_mie`` True (single Mie kept only for channel 0, the
        paper's alpha channel; a combined table cannot be split again). The lowest sun stays
        this method's; ``precompute_seconds`` is this method's."""
        tables = self.tables()
        if combined_mie is not None and combined_mie != self.combined_mie:
            if not combined_mie:
                raise ParameterError("combined_mie", False, "true, or the tables' own setting",
                                     "combined tables lack single Mie of all but channel 0")
            tables["scattering"] = np.concatenate([tables["scattering"], tables.pop("single_mie")[..., :1]], axis=-1)
        method = type(self).from_tables(self.atmosphere, self.wavelengths_nm, mu_s_size=self.mu_s_size,
                                        precision=precision or self.precision,
                                        sun_angular_radius_deg=float(np.degrees(self.sun_angular_radius)),
                                        max_sun_zenith_deg=self.max_sun_zenith_deg, **tables)
        method.transmittance = self.transmittance   # float32 at any precision: keeps its optical depths
        method.scattering_orders = self.scattering_orders
        method.precompute_seconds = self.precompute_seconds
        return method

    @classmethod
    def from_tables(cls, atmosphere, wavelengths_nm, transmittance, scattering, irradiance, single_mie=None, *,
                    mu_s_size: int = 32, precision: str = "float32",
                    sun_angular_radius_deg: float = SUN_ANGULAR_RADIUS_DEG, max_sun_zenith_deg: float | None = None,
                    variant: str | None = None) -> "Bruneton2017":
        """A method reading tables computed elsewhere (e.g. by Bruneton's own code, in radiance
        mode, with the same atmosphere, wavelengths, solar irradiance in W m^-2 nm^-1 and
        ``max_sun_zenith_deg``), in the layout of :meth:`tables`: transmittance [H][W][C],
        scattering [R][MU][NU * MU_S][C or C + 1 (combined Mie)], irradiance [H][W][C],
        single_mie [R][MU][NU * MU_S][C] or None (then ``scattering`` must hold C + 1 channels).
        Table sizes come from the arrays; ``mu_s_size`` splits the scattering width into NU x
        MU_S. No precomputation happens (``precompute_seconds`` is 0)."""
        arrays = {}
        for key, value, ndim in (("transmittance", transmittance, 3), ("scattering", scattering, 4),
                                 ("irradiance", irradiance, 3), ("single_mie", single_mie, 4)):
            if value is None and key == "single_mie":
                continue
            array = np.asarray(value, dtype=np.float64)
            if array.ndim != ndim or min(array.shape) < 1:
                raise ParameterError(key, f"array of shape {array.shape}", f"a {ndim}-D array in Bruneton 2017's "
                                     "texture layout (see Bruneton2017.tables)", "wrong shape")
            if not np.all(np.isfinite(array)):
                raise ParameterError(key, "array with NaN or Inf", "finite values", "not finite")
            arrays[key] = array
        if arrays["transmittance"].min() < 0.0 or arrays["transmittance"].max() > 1.0:
            raise ParameterError("transmittance", "array", "values in [0, 1]", "out of range")
        r_size, mu_size, width, stored = arrays["scattering"].shape
        mu_s_size = check_int("mu_s_size", mu_s_size, 2, 1024)
        if width % mu_s_size:
            raise ParameterError("mu_s_size", mu_s_size, f"a divisor of the scattering width {width}",
                                 "does not split the width into nu x mu_s")
        combined = single_mie is None
        if not combined and arrays["single_mie"].shape[:3] != (r_size, mu_size, width):
            raise ParameterError("single_mie", f"array of shape {arrays['single_mie'].shape}",
                                 f"shape ({r_size}, {mu_size}, {width}, C) like scattering", "wrong shape")
        method = cls(atmosphere, wavelengths_nm, precision, sun_angular_radius_deg, variant,
                     combined_mie=combined, r_size=r_size, mu_size=mu_size, mu_s_size=mu_s_size,
                     nu_size=width // mu_s_size, transmittance_width=arrays["transmittance"].shape[1],
                     transmittance_height=arrays["transmittance"].shape[0],
                     irradiance_width=arrays["irradiance"].shape[1], irradiance_height=arrays["irradiance"].shape[0],
                     max_sun_zenith_deg=max_sun_zenith_deg)
        channels = method.channels
        expected = {"transmittance": channels, "irradiance": channels, "scattering": channels + combined,
                    "single_mie": channels}
        for key, array in arrays.items():
            if array.shape[-1] != expected[key]:
                raise ParameterError(key, f"array with {array.shape[-1]} channels",
                                     f"{expected[key]} channels for {channels} wavelengths"
                                     + (" (+1: single Mie of channel 0, as no single_mie table is given)"
                                        if key == "scattering" and combined else ""), "wrong channel count")
        # A TransmittanceTable for its parametrization and lookups, built with one integration
        # interval since its values are replaced by the given ones.
        method.transmittance = TransmittanceTable(method.optics, method.transmittance_width,
                                                  method.transmittance_height, values=arrays["transmittance"])
        method.scattering = Table(arrays["scattering"], (r_size, mu_size, width), stored, precision)
        method.single_mie = None if combined else Table(arrays["single_mie"], (r_size, mu_size, width), channels,
                                                        precision)
        method.irradiance = method._irradiance_table(arrays["irradiance"])
        method.scattering_orders = None   # unknown: the tables were computed elsewhere
        method.precompute_seconds = 0.0
        return method
