"""Elek 2009, as extended by Bodare and Sandberg 2014: a 3D scattering table with deferred phase
functions, multiple scattering by gathering, and an aerial-perspective volume for the ground.

O. Elek, "Rendering Parametrizable Planetary Atmospheres with Multiple Scattering in Real-Time",
CESCG 2009; G. Bodare and E. Sandberg, "Efficient and Dynamic Atmospheric Scattering", MSc
thesis, Chalmers 2014. (The view-zenith mapping below is Yusov's, "Outdoor Light Scattering
Sample Update", Intel 2013, which the thesis adopts.)

The idea: Bruneton's 4D in-scattering table S(h, mu, mu_s, nu) loses its fourth axis, the view–
sun angle nu. The phase functions are taken out of the integral ("deferred") and applied at
lookup, so the table stores, for Rayleigh and Mie separately and per wavelength, the in-scattered
light per unit solar irradiance without phase,

    S_R(x, v) = int_0^d T(x, y) beta_R(y) [T_sun(y) + G(y)] dt,   (S_M likewise with beta_M)

along the view ray v from x to the top of the atmosphere or the ground (y = x + t v), and the sky
radiance is L = E_sun [p_R(nu) S_R + p_M(nu) S_M]. For single scattering (G = 0) this is exact
up to one assumption: along a ray the sun's zenith angle changes with the planet's curvature,
which depends on the view–sun azimuth the table no longer has. This implementation computes the
table with the sun in the vertical plane of the view ray, on the side the ray points to (azimuth
0, nu = cos(theta_v - theta_s)); rays at other azimuths see that sun height. The error is small
for short rays and grows towards the horizon at low sun (tests: 0.5% towards a sun at 85 deg
zenith, +8% to +29% away from it at 88 deg view zenith).

Multiple scattering (Elek's gathering). The light gathered at y from all directions in order k,

    G_k(h, mu_s) = int_4pi [p_R(w.s) S_R,k(h, w, mu_s) + p_M(w.s) S_M,k(h, w, mu_s)] dw,

is the order-k radiance (per unit solar irradiance) integrated over the sphere: a 2D "gathering
table" over height and sun zenith. Order k + 1 in-scatters it as if isotropically incident, then
the deferred phase is applied: J_{k+1}(y, v) ~ beta(y) p(v.s) G_k(y) instead of beta(y) int
p(v.w) L_k(y, w) dw (equal for isotropic light, since the phase functions average to 1/(4 pi)).
So multiple scattering inherits the single-scattering angular shape p(nu), and loses its real
azimuth dependence: this is the method's main error, which Elek's modified Rayleigh phase
function (below) is meant to soften. S_{k+1} = int T beta G_k dt, and the table holds the sum
over orders 1..K. The gathering integrates the in-scattering table only: light reflected by the
ground is not gathered (the ground enters only as shaded below), one more error against the
ground truth.

Phase functions at lookup: Mie is the atmosphere's own (Cornette–Shanks with its g, as
:class:`~skyref.lut.base.LutOptics` gives it); Rayleigh is ``"rayleigh"``, 3/(16 pi) (1 + nu^2),
or ``"elek"``, Elek's modified 0.8 (1.4 + 0.5 nu) / (4 pi) (written, like Rayleigh's 3/4 (1 +
nu^2), over 4 pi; it integrates to 1.12 over the sphere, not 1; it is brighter than Rayleigh's
towards the sun and darker away from it, and flatter at right angles). The precomputation (the
gathering) always uses the physical phase functions.

Parametrizations. Each maps a quantity to a unit-range value x in [0, 1]; cells are placed with
their centres at x = 0 and x = 1 (:func:`skyref.lut.table.texture_coordinate`), as Yusov places
the view axis, so the table reaches the ground, the top, the zenith and the horizon exactly.

- height (Elek): x_h = (h / H_atm)^0.5.
- view zenith (Yusov, Bodare–Sandberg): split at the horizon cosine mu_h = -sqrt(r^2 - R^2) / r
  of the current height. Above it x = ((mu - mu_h) / (1 - mu_h))^0.2, below it x = ((mu_h - mu)
  / (1 + mu_h))^0.2; each half has its own n/2 cells (upper half of the axis: rays to the top;
  lower half: rays to the ground), so lookups never blend sky with ground. The exponent 0.2
  concentrates cells at the horizon, where in-scattering changes fastest.
- sun zenith (Bruneton 2008's "better formula", used by Yusov and the thesis):
  x_s = 0.5 (atan(max(mu_s, -0.1975) tan(1.26 * 1.1)) / 1.1 + (1 - 0.26)); the table spans
  mu_s from -0.198 (sun 11.4 deg below the horizon) to 1; inside the tables lower suns are
  clamped, and a view whose sun is lower than that gets no light (not the clamped row's).

The half table (this implementation's reading of Bodare–Sandberg). Once the gathering is done,
only the upper half of the view axis (rays that reach the top of the atmosphere: the sky) is
kept for rendering; rays that hit the ground are shaded through the aerial-perspective volume.
``half_table=False`` keeps Elek's whole table and reads in-scattering to the ground from its
lower half.

Aerial perspective (Bodare–Sandberg). A 3D volume computed per frame (per :meth:`radiance` call:
one observer, one sun) over the view frustum, holding for each direction and depth the in-
scattered radiance (phase applied, the direction being known) and the transmittance from the
observer to that depth. The thesis aligns it with a camera; :meth:`radiance` is asked for any
set of directions, so the volume spans the frustum of every ground-seeing direction: view-zenith
cosine over the cone below the horizon (the lower-half mapping above), azimuth from the sun in
[0, pi] (the sky is symmetric about the sun's vertical plane), and depth along the ray from
where it enters the atmosphere, quadratic in depth (x_d = (t / D)^0.5) up to D, the longest
ground distance (the horizon's); the ground falls between depth slices, which costs 0.3-4% of
its radiance from 1-10 km and up to 12% from space at 32^3. Its integrals use the exact sun
geometry of each direction, the transmittance table for the sun and the gathering table for
multiple scattering. The ground seen at distance d: L = E_sun [A(d) + T(d) (rho / pi)
T_sun(ground) max(mu_s,ground, 0)], the direct sun on a Lambertian ground (no sky light: the
method has no irradiance table).

Observer above the atmosphere: the view ray is moved to where it enters the top sphere, at
distance d = -r mu - sqrt(r^2 (mu^2 - 1) + R_t^2), with mu' = (r mu + d) / R_t and mu_s' = (r
mu_s + d nu) / R_t; rays that miss the atmosphere see nothing (the aerial-perspective volume
starts each ray at that entry point the same way).

Transmittance: Bruneton's table (:class:`~skyref.lut.transmittance.TransmittanceTable`) for the
sun, with the sun disk's fraction above the horizon. Along view rays the precomputation
accumulates the optical depth itself (trapezoidal rule on the same samples), which avoids the
precision a ratio of two table values loses near the horizon. Integrals along rays use Simpson's
rule on ``integration_samples`` intervals (100 agree with 400 to 0.1% on horizon rays at
sunset). Ozone (and any absorber) is in the extinction.

References
----------
O. Elek, "Rendering Parametrizable Planetary Atmospheres with Multiple Scattering in Real-Time",
CESCG 2009.

G. Bodare, E. Sandberg, "Efficient and Dynamic Atmospheric Scattering", MSc thesis, Chalmers
University of Technology, 2014.

E. Yusov, "Outdoor Light Scattering Sample Update", Intel, 2013 (the view-zenith mapping).

E. Bruneton, F. Neyret, "Precomputed Atmospheric Scattering", Computer Graphics Forum 27(4)
(Proc. EGSR 2008), 2008 (the sun-zenith mapping).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from skyref.validation import check_choice, check_int, check_int_tuple
from skyref.errors import ParameterError
from skyref.lut import planet
from skyref.lut.base import LutMethod
from skyref.sky_method import Operations
from skyref.lut.table import Table, texture_coordinate, unit_range
from skyref.lut.transmittance import TransmittanceTable
from skyref.atmosphere.sun import SUN_ANGULAR_RADIUS_DEG

__all__ = ["VIEW_EXPONENT", "SUN_MU_MIN", "SUN_ANGLE_SCALE", "SUN_ANGLE_SPAN", "AZIMUTH_SAMPLES", "RAYLEIGH_PHASES",
           "height_unit", "altitude_from_height_unit", "cos_horizon", "view_unit", "mu_from_view_unit",
           "view_texture_coordinate", "sun_unit", "mu_s_from_sun_unit", "elek_rayleigh_phase", "Elek2009",
           "AerialPerspectiveVolume"]

VIEW_EXPONENT = 0.2            # horizon-split view mapping (Yusov 2013, Bodare–Sandberg 2014)
SUN_MU_MIN = -0.1975           # sun-zenith mapping constants (Bruneton 2008)
SUN_ANGLE_SCALE = 1.1
SUN_ANGLE_SPAN = 1.26
AZIMUTH_SAMPLES = 256          # midpoint samples of the gathering's azimuth integral of the phase
RAYLEIGH_PHASES = ("rayleigh", "elek")


# --- parametrizations (Dr.Jit Float64 arrays) ---------------------------------------------------


def height_unit(altitude, atmosphere_height: float):
    """x_h = (h / H_atm)^0.5 of ``altitude`` (m) in an atmosphere ``atmosphere_height`` thick."""
    return dr.sqrt(dr.clip(altitude / atmosphere_height, 0.0, 1.0))


def altitude_from_height_unit(x, atmosphere_height: float):
    """Inverse of :func:`height_unit`, m."""
    return atmosphere_height * x * x


def cos_horizon(r, bottom_radius: float):
    """Cosine of the view zenith angle of the ground's horizon seen from radius ``r`` >= R."""
    return -dr.safe_sqrt(r * r - bottom_radius * bottom_radius) / r


def view_unit(mu, mu_horizon, ray_hits_ground):
    """x_v in [0, 1] within the view axis' half: ((mu - mu_h) / (1 - mu_h))^0.2 for rays above
    the horizon, ((mu_h - mu) / (1 + mu_h))^0.2 for rays that hit the ground; 0 at the horizon."""
    above = (mu - mu_horizon) / (1.0 - mu_horizon)
    below = (mu_horizon - mu) / (1.0 + mu_horizon)
    return dr.power(dr.clip(dr.select(ray_hits_ground, below, above), 0.0, 1.0), VIEW_EXPONENT)


def mu_from_view_unit(x, mu_horizon, ray_hits_ground):
    """Inverse of :func:`view_unit`."""
    s = dr.power(x, 1.0 / VIEW_EXPONENT)
    return dr.select(ray_hits_ground, mu_horizon - s * (1.0 + mu_horizon), mu_horizon + s * (1.0 - mu_horizon))


def view_texture_coordinate(x, ray_hits_ground, size: int):
    """Texture coordinate of x_v on a view axis of ``size`` cells: rays to the ground on the
    lower half [0, 1/2), rays to the top on the upper half, each half with its end cell centres
    at x_v = 0 and 1."""
    half = texture_coordinate(x, size // 2)
    return dr.select(ray_hits_ground, 0.5 * half, 0.5 + 0.5 * half)


def sun_unit(mu_s):
    """x_s = 0.5 (atan(max(mu_s, -0.1975) tan(1.26 * 1.1)) / 1.1 + (1 - 0.26))."""
    mu_s = dr.maximum(mu_s, SUN_MU_MIN)
    angle = dr.atan(mu_s * math.tan(SUN_ANGLE_SPAN * SUN_ANGLE_SCALE))
    return 0.5 * (angle / SUN_ANGLE_SCALE + (1.0 - (SUN_ANGLE_SPAN - 1.0)))


def mu_s_from_sun_unit(x):
    """Inverse of :func:`sun_unit` (x_s = 0 gives mu_s = -0.19825, just below -0.1975)."""
    angle = (2.0 * x - (1.0 - (SUN_ANGLE_SPAN - 1.0))) * SUN_ANGLE_SCALE
    return dr.tan(angle) / math.tan(SUN_ANGLE_SPAN * SUN_ANGLE_SCALE)


def elek_rayleigh_phase(nu):
    """Elek's modified Rayleigh phase function 0.8 (1.4 + 0.5 nu) / (4 pi), sr^-1 (integral over
    the sphere 1.12)."""
    return 0.8 * (1.4 + 0.5 * nu) / (4.0 * math.pi)


# --- the method ------------------------------------------------------------------------------


class Elek2009(LutMethod):
    """Elek 2009 / Bodare–Sandberg 2014 (see the module docstring).

    ``scattering_size``: (height, view zenith, sun zenith) cells of the 3D table (view even);
    the gathering table has the same height and sun axes. ``scattering_orders``: K (1: single
    scattering only). ``rayleigh_phase``: ``"rayleigh"`` or ``"elek"`` at lookup.
    ``half_table``: keep only the sky half of the table and shade the ground through the
    aerial-perspective volume (Bodare–Sandberg), else read it from the whole table (Elek).
    ``gathering_samples``: view-zenith cosines of the gathering integral (midpoint rule).
    ``aerial_perspective_size``: (view zenith, azimuth, depth) cells of the volume.
    ``transmittance_size``: (width, height) of the transmittance table. ``integration_samples``:
    Simpson intervals along each ray (even)."""

    name = "elek2009"

    def __init__(self, atmosphere, wavelengths_nm="rgb", precision: str = "float32",
                 sun_angular_radius_deg: float = SUN_ANGULAR_RADIUS_DEG, variant: str | None = None, *,
                 scattering_size=(32, 128, 32), scattering_orders: int = 4, rayleigh_phase: str = "rayleigh",
                 half_table: bool = True, gathering_samples: int = 128,
                 aerial_perspective_size=(32, 32, 32), transmittance_size=(256, 64),
                 integration_samples: int = 100):
        self.scattering_size = check_int_tuple("scattering_size", scattering_size, 3, 2, 1024, even_axes=(1,))
        if self.scattering_size[1] < 4:
            raise ParameterError("scattering_size[1]", scattering_size[1], "an even integer in [4, 1024]",
                                 "each half of the view axis needs 2 cells")
        self.scattering_orders = check_int("scattering_orders", scattering_orders, 1, 50)
        self.rayleigh_phase_name = check_choice("rayleigh_phase", rayleigh_phase, RAYLEIGH_PHASES)
        if not isinstance(half_table, bool):
            raise ParameterError("half_table", half_table, "True or False", "not a bool")
        self.half_table = half_table
        self._volume_key = None
        self.gathering_samples = check_int("gathering_samples", gathering_samples, 4, 100_000)
        self.aerial_perspective_size = check_int_tuple("aerial_perspective_size", aerial_perspective_size, 3, 2, 1024)
        self.transmittance_size = check_int_tuple("transmittance_size", transmittance_size, 2, 2, 4096)
        self.integration_samples = check_int("integration_samples", integration_samples, 2, 100_000, even=True)
        super().__init__(atmosphere, wavelengths_nm, precision, sun_angular_radius_deg, variant)
        self.atmosphere_height = self.optics.top_radius - self.optics.bottom_radius

    # --- lookups into the 3D and 2D tables ----------------------------------------------------

    def _scattering_coordinates(self, r, mu, mu_s, ray_hits_ground, sky_half: bool = False):
        """(u_h, u_v, u_s) for view rays from (r, mu) with the sun at mu_s in the whole 3D table,
        or, with ``sky_half``, in the half table (the sky half of the view axis alone)."""
        n_h, n_v, n_s = self.scattering_size
        altitude = r - self.optics.bottom_radius
        x_v = view_unit(mu, cos_horizon(r, self.optics.bottom_radius), ray_hits_ground)
        u_v = texture_coordinate(x_v, n_v // 2) if sky_half else view_texture_coordinate(x_v, ray_hits_ground, n_v)
        return (texture_coordinate(height_unit(altitude, self.atmosphere_height), n_h), u_v,
                texture_coordinate(sun_unit(mu_s), n_s))

    def _gathering_coordinates(self, r, mu_s):
        """(u_h, u_s) of the gathering table at radius r with the sun at mu_s."""
        n_h, _, n_s = self.scattering_size
        altitude = r - self.optics.bottom_radius
        return (texture_coordinate(height_unit(altitude, self.atmosphere_height), n_h),
                texture_coordinate(sun_unit(mu_s), n_s))

    def _rendering_phases(self, nu):
        """(Rayleigh, Mie) phase functions applied at lookup, sr^-1."""
        rayleigh = elek_rayleigh_phase(nu) if self.rayleigh_phase_name == "elek" else self.optics.rayleigh_phase(nu)
        return rayleigh, self.optics.mie_phase(nu)

    # --- precomputation -----------------------------------------------------------------------

    def _precompute(self):
        self._volume_key = None  # a volume built from earlier tables is stale
        optics = self.optics
        n_h, n_v, n_s = self.scattering_size
        shape = (n_h, n_v, n_s)
        self.transmittance = TransmittanceTable(optics, *self.transmittance_size, precision=self.precision)
        r, mu, mu_s, ray_hits_ground, channel = self._scattering_cells()

        def sunlight(r_y, mu_s_y, channel_y):
            return self.transmittance.to_sun(r_y, mu_s_y, self.sun_angular_radius, channel_y)

        order = [Table.from_lanes(s, shape, self.channels, self.precision)
                 for s in self._inscattering(r, mu, mu_s, ray_hits_ground, channel, sunlight)]
        total = [t.numpy() for t in order]
        gathered_sum = np.zeros((n_h, n_s, self.channels))
        azimuth_integrated = self._azimuth_integrated_phases() if self.scattering_orders > 1 else None
        for _ in range(2, self.scattering_orders + 1):
            gathered = self._gather(order, azimuth_integrated)
            gathered_sum += gathered.numpy()

            def gathered_light(r_y, mu_s_y, channel_y, table=gathered):
                return table.lookup(self._gathering_coordinates(r_y, mu_s_y), channel_y)

            order = [Table.from_lanes(s, shape, self.channels, self.precision)
                     for s in self._inscattering(r, mu, mu_s, ray_hits_ground, channel, gathered_light)]
            total = [t + o.numpy() for t, o in zip(total, order)]
        self.gathering = Table(gathered_sum, (n_h, n_s), self.channels, self.precision)
        if self.half_table:          # keep the sky half: view cells n/2 .. n-1
            total = [t[:, n_v // 2:] for t in total]
        view_cells = n_v // 2 if self.half_table else n_v
        self.scattering_rayleigh, self.scattering_mie = (
            Table(t, (n_h, view_cells, n_s), self.channels, self.precision) for t in total)

    def _scattering_cells(self):
        """One lane per (cell, channel) of the whole 3D table: (r, mu, mu_s, ray_hits_ground,
        channel) at the cell centres."""
        n_h, n_v, n_s = self.scattering_size
        lane = dr.arange(mi.UInt32, n_h * n_v * n_s * self.channels)
        channel = lane % self.channels
        cell = lane // self.channels
        i_s, i_v, i_h = cell % n_s, (cell // n_s) % n_v, cell // (n_s * n_v)
        half = n_v // 2
        ray_hits_ground = i_v < half
        i_half = dr.select(ray_hits_ground, i_v, i_v - half)
        altitude = altitude_from_height_unit(unit_range((mi.Float64(i_h) + 0.5) / n_h, n_h), self.atmosphere_height)
        r = self.optics.bottom_radius + altitude
        x_v = unit_range((mi.Float64(i_half) + 0.5) / half, half)
        mu = mu_from_view_unit(x_v, cos_horizon(r, self.optics.bottom_radius), ray_hits_ground)
        mu_s = mu_s_from_sun_unit(unit_range((mi.Float64(i_s) + 0.5) / n_s, n_s))
        return r, dr.clip(mu, -1.0, 1.0), dr.clip(mu_s, -1.0, 1.0), ray_hits_ground, channel

    @dr.syntax
    def _inscattering(self, r, mu, mu_s, ray_hits_ground, channel, light):
        """(S_R, S_M): int_0^d T(x, y) beta(y) light(y) dt along the ray from (r, mu) to the ground
        or the top, with the sun in the ray's vertical plane (azimuth 0). ``light(r_y, mu_s_y,
        channel)`` is the light reaching y per unit solar irradiance (sun transmittance, or the
        gathered light of the previous order). Simpson's rule; optical depth by trapezoids."""
        optics = self.optics
        n = self.integration_samples
        nu = mu * mu_s + dr.safe_sqrt(1.0 - mu * mu) * dr.safe_sqrt(1.0 - mu_s * mu_s)
        d = dr.select(ray_hits_ground, planet.distance_to_bottom(r, mu, optics.bottom_radius),
                      planet.distance_to_top(r, mu, optics.top_radius))
        dt = d / n
        rayleigh, mie = mi.Float64(0.0), mi.Float64(0.0)
        optical_depth = mi.Float64(0.0)
        previous_extinction = mi.Float64(0.0)
        i = mi.UInt32(0)
        while i <= n:
            t = mi.Float64(i) * dt
            r_y, _ = planet.point_along_ray(r, mu, t)
            altitude = dr.maximum(r_y - optics.bottom_radius, 0.0)
            mu_s_y = dr.clip((r * mu_s + t * nu) / r_y, -1.0, 1.0)
            extinction = optics.extinction(altitude, channel)
            optical_depth += dr.select(i > 0, 0.5 * dt * (previous_extinction + extinction), 0.0)
            previous_extinction = extinction
            beta_rayleigh, beta_mie = optics.scattering(altitude, channel)
            reaching = dr.exp(-optical_depth) * light(r_y, mu_s_y, channel)
            weight = dr.select((i == 0) | (i == n), 1.0, dr.select(i % 2 == 1, 4.0, 2.0))
            rayleigh += weight * beta_rayleigh * reaching
            mie += weight * beta_mie * reaching
            i += 1
        return rayleigh * dt / 3.0, mie * dt / 3.0

    def _azimuth_integrated_phases(self):
        """Azimuth integrals Phi(mu, mu_s) = int_0^2pi p(w.s) dphi of the physical Rayleigh and
        Mie phase functions, on the gathering's view cosines (rows) x the table's sun cosines
        (columns): two row-major Float64 arrays."""
        n_mu, n_s = self.gathering_samples, self.scattering_size[2]
        lane = dr.arange(mi.UInt32, n_mu * n_s * AZIMUTH_SAMPLES)
        i_phi, i_s, i_mu = lane % AZIMUTH_SAMPLES, (lane // AZIMUTH_SAMPLES) % n_s, lane // (AZIMUTH_SAMPLES * n_s)
        mu = -1.0 + (mi.Float64(i_mu) + 0.5) * (2.0 / n_mu)
        mu_s = dr.clip(mu_s_from_sun_unit(unit_range((mi.Float64(i_s) + 0.5) / n_s, n_s)), -1.0, 1.0)
        phi = (mi.Float64(i_phi) + 0.5) * (math.pi / AZIMUTH_SAMPLES)
        cos_angle = mu * mu_s + dr.safe_sqrt(1.0 - mu * mu) * dr.safe_sqrt(1.0 - mu_s * mu_s) * dr.cos(phi)
        step = 2.0 * math.pi / AZIMUTH_SAMPLES    # phi over [0, pi], doubled by symmetry
        integrated = []
        for phase in (self.optics.rayleigh_phase(cos_angle), self.optics.mie_phase(cos_angle)):
            values = step * phase.numpy().reshape(n_mu, n_s, AZIMUTH_SAMPLES).sum(axis=2)
            # Normalise each column so the quadrature integrates the phase function to exactly 1
            # (the Mie peak is narrower than the view-cosine steps near the poles).
            values /= np.maximum(values.sum(axis=0, keepdims=True) * (2.0 / n_mu), 1e-30)
            integrated.append(mi.Float64(values.reshape(-1)))
        return integrated

    @dr.syntax
    def _gather(self, inscattering, azimuth_integrated):
        """The gathering table G(h, mu_s) = int_4pi [p_R S_R + p_M S_M] dw of one order's
        in-scattering tables (a midpoint rule in the view cosine; the azimuth integral of the
        phase functions is done beforehand)."""
        n_h, n_v, n_s = self.scattering_size
        n_mu = self.gathering_samples
        lane = dr.arange(mi.UInt32, n_h * n_s * self.channels)
        channel = lane % self.channels
        cell = lane // self.channels
        i_s, i_h = cell % n_s, cell // n_s
        r = self.optics.bottom_radius + altitude_from_height_unit(
            unit_range((mi.Float64(i_h) + 0.5) / n_h, n_h), self.atmosphere_height)
        mu_s = dr.clip(mu_s_from_sun_unit(unit_range((mi.Float64(i_s) + 0.5) / n_s, n_s)), -1.0, 1.0)
        table_rayleigh, table_mie = inscattering
        phase_rayleigh, phase_mie = azimuth_integrated
        gathered = mi.Float64(0.0)
        j = mi.UInt32(0)
        while j < n_mu:
            mu = -1.0 + (mi.Float64(j) + 0.5) * (2.0 / n_mu)
            hits = planet.intersects_ground(r, mu, self.optics.bottom_radius)
            coords = self._scattering_coordinates(r, mu, mu_s, hits)
            index = j * n_s + i_s
            gathered += (dr.gather(mi.Float64, phase_rayleigh, index) * table_rayleigh.lookup(coords, channel)
                         + dr.gather(mi.Float64, phase_mie, index) * table_mie.lookup(coords, channel))
            j += 1
        return Table.from_lanes(gathered * (2.0 / n_mu), (n_h, n_s), self.channels, self.precision)

    def tables(self) -> dict:
        return {"transmittance": self.transmittance.table.numpy(),
                "scattering_rayleigh": self.scattering_rayleigh.numpy(),
                "scattering_mie": self.scattering_mie.numpy(),
                "gathering": self.gathering.numpy()}

    def operations(self) -> Operations:
        """Fetches per direction, from :meth:`_radiance`: the sky reads the Rayleigh and Mie
        tables once each; a ground view reads the transmittance towards the sun at the ground
        point and, with the half table, the view's aerial-perspective volume (in-scattering and
        transmittance), else both scattering tables at their ground half and the transmittance
        at the ray's two ends. Per view (half table only): the volume, every cell an
        ``integration_samples``-interval Simpson march that reads the transmittance towards the
        sun and, with multiple scattering, the gathering table at every node."""
        n_h, n_v, n_s = self.scattering_size
        scattering = (n_h, n_v // 2 if self.half_table else n_v, n_s)
        tables = {"transmittance": self.transmittance_size[::-1], "scattering_rayleigh": scattering,
                  "scattering_mie": scattering}
        sky = {"scattering_rayleigh fetches": 1, "scattering_mie fetches": 1}
        if not self.half_table:
            return Operations(tables=tables, sky=sky, ground={**sky, "transmittance fetches": 3})
        gathered = self.scattering_orders > 1
        if gathered:
            tables["gathering"] = (n_h, n_s)
        tables["aerial_perspective"] = self.aerial_perspective_size
        nodes = self.integration_samples + 1
        return Operations(
            tables=tables, sky=sky,
            ground={"transmittance fetches": 1, "aerial_perspective fetches (in-scattering, transmittance)": 2},
            per_view={"aerial_perspective cells": int(np.prod(self.aerial_perspective_size)),
                      "samples per cell": nodes, "transmittance fetches per sample": 1,
                      **({"gathering fetches per sample": 1} if gathered else {})},
            note="this implementation evaluates the sky and the ground terms for every direction")

    # --- lookups ------------------------------------------------------------------------------

    def _radiance(self, r, mu, mu_s, nu):
        optics = self.optics
        R, Rt = optics.bottom_radius, optics.top_radius
        # An observer above the atmosphere looks from where the ray enters it.
        outside = r > Rt
        entry_discriminant = r * r * (mu * mu - 1.0) + Rt * Rt
        enters = ~outside | ((mu < 0.0) & (entry_discriminant >= 0.0))
        entry = dr.select(outside, dr.maximum(-r * mu - dr.safe_sqrt(entry_discriminant), 0.0), 0.0)
        r0 = dr.select(outside, Rt, r)
        mu0 = dr.clip((r * mu + entry) / r0, -1.0, 1.0)
        mu_s0 = dr.clip((r * mu_s + entry * nu) / r0, -1.0, 1.0)
        hits = planet.intersects_ground(r0, mu0, R)

        phase_rayleigh, phase_mie = self._rendering_phases(nu)
        sky_coords = self._scattering_coordinates(r0, mu0, mu_s0, mi.Bool(False), sky_half=self.half_table)
        sky = [phase_rayleigh * s_r + phase_mie * s_m for s_r, s_m in
               zip(self.scattering_rayleigh.lookup(sky_coords), self.scattering_mie.lookup(sky_coords))]

        ground_distance = planet.distance_to_bottom(r0, mu0, R)
        reflected = self._ground_reflection(r0, mu_s0, nu, ground_distance)
        if self.half_table:          # the view's volume, built by _prepare_view
            inscattered, transmittance = self._volume.lookup(mu, nu, entry + ground_distance)
        else:
            ground_coords = self._scattering_coordinates(r0, mu0, mu_s0, mi.Bool(True))
            inscattered = [phase_rayleigh * s_r + phase_mie * s_m for s_r, s_m in
                           zip(self.scattering_rayleigh.lookup(ground_coords),
                               self.scattering_mie.lookup(ground_coords))]
            transmittance = self.transmittance.between(r0, mu0, ground_distance, mi.Bool(True))
        ground = [a + t * g for a, t, g in zip(inscattered, transmittance, reflected)]
        # The tables end at mu_s = SUN_MU_MIN (the sun 11.4 deg below the horizon where the ray
        # starts): a lower sun would read their last row, clamped, and light the sky at midnight as
        # at 101.4 deg. It gives no light. The true sky is dark there too but for a faint arch over
        # the sun's horizon (the path tracer, Bruneton 2017 atmosphere, ground: at most 2e-4 of
        # the noon mean at sun zenith 102 deg, 2e-5 at 104, < 1e-6 from 106 on).
        lit = enters & (mu_s0 >= SUN_MU_MIN)
        return [dr.select(lit, float(e) * dr.select(hits, g, s), 0.0)
                for e, g, s in zip(self.solar_irradiance, ground, sky)]

    def _prepare_view(self, r: float, mu_s: float):
        """The aerial-perspective volume for an observer at radius ``r`` and sun cosine ``mu_s``
        (half table only), kept until the observer or the sun changes."""
        key = (r, mu_s)
        if self.half_table and self._volume_key != key:
            self._volume, self._volume_key = AerialPerspectiveVolume(self, r, mu_s), key

    def _ground_reflection(self, r, mu_s, nu, distance):
        """Radiance of the Lambertian ground per unit solar irradiance where the ray from radius
        r meets it after ``distance``: (albedo / pi) T_sun max(mu_s at the ground, 0), per channel."""
        R = self.optics.bottom_radius
        mu_s_ground = dr.clip((r * mu_s + distance * nu) / R, -1.0, 1.0)
        sun = self.transmittance.to_sun(mi.Float64(R), mu_s_ground, self.sun_angular_radius)
        cosine = dr.maximum(mu_s_ground, 0.0)
        return [self.optics.ground_albedo(mi.UInt32(k)) / math.pi * t * cosine for k, t in enumerate(sun)]


def _opaque(value: float) -> mi.Float64:
    """A per-view value as an opaque Float64 (not baked into kernels)."""
    return dr.opaque(mi.Float64, value)


class AerialPerspectiveVolume:
    """In-scattered radiance and transmittance from an observer at radius ``r`` (m) to every
    depth along every ground-seeing direction, with the sun at cosine ``mu_s``; built from an
    :class:`Elek2009` method's transmittance and gathering tables (see the module docstring)."""

    def __init__(self, method: Elek2009, r: float, mu_s: float):
        optics = method.optics
        self.method = method
        R, Rt = optics.bottom_radius, optics.top_radius
        #: whether the observer is above the atmosphere (the only view-dependent branch)
        self.outside = float(r) > Rt
        # The view's values enter kernels as opaque Float64s: a new observer or sun reuses the
        # compiled kernels (as literals, each view compiled 17 of its 18 kernels again).
        r, mu_s = float(r), float(mu_s)
        self.r, self.mu_s = _opaque(r), _opaque(mu_s)
        self.sin_s = _opaque(math.sqrt(max(1.0 - mu_s * mu_s, 0.0)))
        self.mu_horizon = _opaque(-math.sqrt(max(r * r - R * R, 0.0)) / r)
        # The longest in-atmosphere path to the ground: along the horizon ray.
        self.depth = _opaque(max(math.sqrt(max(min(r, Rt) ** 2 - R * R, 0.0)), 1.0))
        # One lane per cell, the channels in lists: the ray's geometry is paid once for all of them.
        n_mu, n_phi, n_d = method.aerial_perspective_size
        cell = dr.arange(mi.UInt32, n_mu * n_phi * n_d)
        i_d, i_phi, i_mu = cell % n_d, (cell // n_d) % n_phi, cell // (n_d * n_phi)
        mu = dr.clip(mu_from_view_unit(mi.Float64(i_mu) / (n_mu - 1), self.mu_horizon, mi.Bool(True)), -1.0, 1.0)
        nu = self._nu(mu, mi.Float64(i_phi) * (math.pi / (n_phi - 1)))
        depth = self.depth * dr.square(mi.Float64(i_d) / (n_d - 1))
        inscattered, transmittance = self._integrate(mu, nu, depth)
        dr.eval(inscattered, transmittance)         # one kernel for every channel
        shape = (n_mu, n_phi, n_d)
        self.inscattered = Table.from_channels(inscattered, shape, method.precision)
        self.transmittance = Table.from_channels(transmittance, shape, method.precision)

    def _nu(self, mu, phi):
        """Cosine of the view–sun angle of a view with zenith cosine mu at azimuth phi from the sun."""
        return dr.clip(mu * self.mu_s + dr.safe_sqrt(1.0 - mu * mu) * self.sin_s * dr.cos(phi), -1.0, 1.0)

    def _entry(self, mu):
        """Distance from the observer to where the ray enters the atmosphere (0 inside it)."""
        Rt = self.method.optics.top_radius
        if not self.outside:
            return 0.0 * mu
        return dr.maximum(-self.r * mu - dr.safe_sqrt(self.r * self.r * (mu * mu - 1.0) + Rt * Rt), 0.0)

    @dr.syntax
    def _integrate(self, mu, nu, depth):
        """In-scattered radiance (phase applied) per unit solar irradiance, and transmittance,
        from the atmosphere entry to ``depth`` beyond it (stopping at the ground): two lists of
        Float64, one per channel."""
        method, optics = self.method, self.method.optics
        n = method.integration_samples
        channels = range(method.channels)
        r = self.r
        start = self._entry(mu)
        ground = planet.distance_to_bottom(r, mu, optics.bottom_radius)
        end = dr.minimum(start + depth, dr.maximum(ground, start))
        dt = (end - start) / n
        phase_rayleigh, phase_mie = method._rendering_phases(nu)

        def light(r_y, mu_s_y):
            """Sunlight plus the gathered light of all orders (per unit solar irradiance), per channel."""
            sun = method.transmittance.to_sun(r_y, mu_s_y, method.sun_angular_radius)
            if method.scattering_orders == 1:
                return sun
            gathered = method.gathering.lookup(method._gathering_coordinates(r_y, mu_s_y))
            return [sun[k] + gathered[k] for k in channels]

        inscattered = [mi.Float64(0.0) for _ in channels]
        optical_depth = [mi.Float64(0.0) for _ in channels]
        previous_extinction = [mi.Float64(0.0) for _ in channels]
        i = mi.UInt32(0)
        while i <= n:
            t = start + mi.Float64(i) * dt
            r_y, _ = planet.point_along_ray(r, mu, t)
            altitude = dr.clip(r_y - optics.bottom_radius, 0.0, method.atmosphere_height)
            mu_s_y = dr.clip((r * self.mu_s + t * nu) / r_y, -1.0, 1.0)
            extinction = optics.extinction_by_channel(altitude, method.channels)
            optical_depth = [optical_depth[k] + dr.select(i > 0, 0.5 * dt * (previous_extinction[k] + extinction[k]),
                                                          0.0) for k in channels]
            previous_extinction = extinction
            beta_rayleigh, beta_mie = optics.scattering_by_channel(altitude, method.channels)
            weight = dr.select((i == 0) | (i == n), 1.0, dr.select(i % 2 == 1, 4.0, 2.0))
            reaching = light(r_y, mu_s_y)
            inscattered = [inscattered[k] + (weight * (phase_rayleigh * beta_rayleigh[k] + phase_mie * beta_mie[k])
                                             * dr.exp(-optical_depth[k]) * reaching[k]) for k in channels]
            i += 1
        return [inscattered[k] * dt / 3.0 for k in channels], [dr.exp(-optical_depth[k]) for k in channels]

    def lookup(self, mu, nu, distance):
        """(in-scattered radiance, transmittance) per channel (lists of Float64) from the observer
        to ``distance`` (m) along rays (mu, nu) that hit the ground, interpolated in the volume."""
        n_mu, n_phi, n_d = self.method.aerial_perspective_size
        sin_product = dr.safe_sqrt(1.0 - mu * mu) * self.sin_s
        cos_phi = dr.select(sin_product > 1e-9, (nu - mu * self.mu_s) / dr.maximum(sin_product, 1e-9), 1.0)
        x_mu = view_unit(mu, self.mu_horizon, mi.Bool(True))
        x_phi = dr.acos(dr.clip(cos_phi, -1.0, 1.0)) / math.pi
        x_d = dr.sqrt(dr.clip((distance - self._entry(mu)) / self.depth, 0.0, 1.0))
        coords = (texture_coordinate(x_mu, n_mu), texture_coordinate(x_phi, n_phi), texture_coordinate(x_d, n_d))
        return self.inscattered.lookup(coords), self.transmittance.lookup(coords)
