"""Hillaire 2020: "A Scalable and Production Ready Sky and Atmosphere Rendering Technique"
(S. Hillaire, EGSR 2020; reference implementation: github.com/sebh/UnrealEngineSkyAtmosphere).

Four small tables replace Bruneton's 4D scattering table:

1. **Transmittance** T(r, mu) to the top of the atmosphere, 256 x 64, Bruneton's
   parametrization (:class:`~skyref.lut.transmittance.TransmittanceTable`).
2. **Multiple scattering** Psi_ms(r, mu_s), 32 x 32 over altitude (linear) and sun zenith
   cosine (linear in [-1, 1]). At a point x, light scattered twice or more is approximated as
   isotropic and as if the point's neighbourhood were uniformly lit like x itself:

   - L_2nd(x) = (1/4pi) int_sphere L'(x, w) dw, with L'(x, w) the single-scattered radiance
     (isotropic phase 1/4pi, per unit solar irradiance) arriving at x from direction w, plus the
     sunlit Lambertian ground seen along w (rho/pi T_sun mu_s);
   - f_ms(x) = (1/4pi) int_sphere int_0^{d(w)} T(x, x + t w) sigma_s(x + t w) dt dw, the fraction
     of light that one more isotropic scattering event around x sends back to x;
   - every further order multiplies by f_ms, so all orders sum to a geometric series:
     Psi_ms = L_2nd (1 + f_ms + f_ms^2 + ...) = L_2nd / (1 - f_ms)   (paper, eq. 10).

   Both sphere integrals use 64 directions (an 8 x 8 stratified grid, uniform in azimuth and
   in cos(zenith)), each ray marched with 20 segments. Psi_ms has units sr^-1 (radiance per
   unit solar irradiance); a point scatters sigma_s Psi_ms towards every direction.
3. **Sky view** L(mu, phi), 192 x 108, for one observer altitude and sun zenith (it is
   recomputed when they change): longitude = view azimuth phi relative to the sun, with
   x = sqrt((1 - cos phi) / 2) (more texels towards the sun); latitude with a square-root
   mapping on each side of the horizon (:func:`sky_view_coordinates`) that puts half the rows
   below the horizon and concentrates texels at it. Every texel is a ray march to the ground or
   the top of the atmosphere of single scattering (Rayleigh and aerosol phase functions, sun
   transmittance from table 1, the planet's shadow) plus sigma_s Psi_ms (table 2). The ground
   itself is *not* in the table (the reference's ``ground = false``); for rays that hit it the
   table holds the in-scattering up to the ground.
4. **Aerial perspective** (:class:`AerialPerspective`), 32^3 froxels over a perspective
   camera's frustum, 4 km per slice with slices spaced quadratically in depth (128 km deep):
   in-scattered radiance and transmittance from the camera to each froxel. Engines apply it to
   geometry (the terrain): L = L_surface T + L_in.

Ray marching (shared by tables 2-4, the reference's ``IntegrateScatteredLuminance``): the ray
is cut into segments; the medium and the sun are sampled 30% into each segment, and the source
S (constant on the segment) is integrated analytically against the segment's transmittance,
int_0^dt S exp(-sigma_t t) dt = S (1 - exp(-sigma_t dt)) / sigma_t (energy-conserving, from
Hillaire's Frostbite 2015 volumetrics). The sky view uses the reference's *variable* segment
count, n = n_min + (n_max - n_min) min(d / 100 km, 1) for a ray of length d with segment edges
at (i / floor(n))^2 (denser near the observer); the defaults (4, 14) are the reference demo's
(``uiViewRayMarchMinSPP/MaxSPP``: with the variable count on, the shader's nominal 30 samples
are unused). The multiple-scattering table uses 20 uniform segments, the aerial perspective
2 (k + 1) uniform segments for slice k.

Ground: a view ray that hits the ground sees the in-scattering up to it (sky-view table, or
aerial-perspective volume through :meth:`AerialPerspective.radiance`) plus the ground's radiance
attenuated by the transmittance to it (table 1). The ground's radiance is what the reference
puts into the multiple-scattering table, rho/pi E T_sun max(mu_s, 0) (sun shadowed by the
atmosphere only), plus light of the higher orders: the ground sees the multiply scattered light
Psi_ms E of table 2 at the ground as an isotropic radiance, whose irradiance is pi Psi_ms E, so it
reflects rho Psi_ms E. That second term is this implementation's choice (the reference demo shades
its terrain with the sun alone); it is omitted in single-scattering mode, where the ground
reflects only the sun, exactly as the ground truth's ``single`` order counts it.

Observers above the atmosphere (the paper's space views): the sky-view table is only defined
inside the atmosphere, so every view ray is ray marched directly, with the sky view's variable
segment count, from the point where it enters the atmosphere (the reference's
``MoveToTopAtmosphere``); rays that miss the atmosphere see black space. The aerial
perspective volume does the same per froxel.

Deviations from the reference code, all for accuracy of the audit and none part of the method:
the ray march covers the whole ray (the reference's fixed-count march sets each segment's
length to the distance from the previous sample, which leaves the last 70% of a segment out);
texture coordinates put the first and last texel centres exactly on the ends of each range
(:func:`~skyref.lut.table.texture_coordinate`; the reference's ``fromUnitToSubUvs`` maps them
1/(2(n + 1)) of a texel inside); transmittance in the aerial perspective volume is stored per
wavelength (the reference keeps one grey value in the alpha channel). Phase functions are the
atmosphere's (the reference demo's aerosol is Cornette–Shanks too). Tables store radiance per
unit solar irradiance (sr^-1, the reference's ``ILLUMINANCE_IS_ONE``); lookups multiply by the
solar spectral irradiance.

References
----------
S. Hillaire, "A Scalable and Production Ready Sky and Atmosphere Rendering Technique", Computer
Graphics Forum 39(4) (Proc. EGSR 2020), 2020.

S. Hillaire, "Physically Based and Unified Volumetric Rendering in Frostbite", SIGGRAPH 2015 course
"Advances in Real-Time Rendering in Games" (the energy-conserving segment integral).

S. Hillaire, UnrealEngineSkyAtmosphere, https://github.com/sebh/UnrealEngineSkyAtmosphere
(the reference implementation).
"""

from __future__ import annotations

import math
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from skyref.validation import check_array, check_int, check_int_tuple, check_number
from skyref.errors import ParameterError
from skyref.lut import planet
from skyref.lut.base import LutMethod
from skyref.sky_method import Operations
from skyref.lut.table import Table, texture_coordinate, unit_range
from skyref.lut.transmittance import TransmittanceTable
from skyref.atmosphere.sun import SUN_ANGULAR_RADIUS_DEG
from skyref.projection import camera_to_world, perspective_direction

__all__ = ["ISOTROPIC_PHASE", "SEGMENT_SAMPLE_POSITION", "SKY_VIEW_FULL_SAMPLES_DISTANCE", "SKY_VIEW_CACHE_SIZE",
           "cos_view_sun_azimuth", "sky_view_coordinates", "sky_view_direction", "Hillaire2020", "AerialPerspective"]

#: Isotropic phase function, sr^-1.
ISOTROPIC_PHASE = 1.0 / (4.0 * math.pi)

#: Where in each ray-march segment the medium is sampled (the reference's SampleSegmentT).
SEGMENT_SAMPLE_POSITION = 0.3

#: Ray length (m) from which the sky view's variable ray march uses its largest segment count.
SKY_VIEW_FULL_SAMPLES_DISTANCE = 100_000.0

#: Sky-view tables kept for (observer radius, sun zenith cosine) pairs before the oldest goes.
SKY_VIEW_CACHE_SIZE = 16


def _per_lane(values, view):
    """Per-view values (NumPy or Dr.Jit) spread over the (view, channel) lanes of
    :meth:`Hillaire2020._view_lanes`."""
    return dr.gather(mi.Float64, mi.Float64(values), view)


# --- the sky-view parametrization --------------------------------------------------------------

def cos_view_sun_azimuth(mu, mu_s, nu):
    """Cosine of the azimuth between view and sun (angle between their projections on the
    horizontal plane) from the cosines of the view zenith ``mu``, sun zenith ``mu_s`` and
    view–sun angle ``nu``: nu = mu mu_s + sqrt(1 - mu^2) sqrt(1 - mu_s^2) cos(phi). Where the
    view or the sun is at the zenith the azimuth is undefined and any value serves: 1."""
    sines = dr.safe_sqrt(1.0 - mu * mu) * dr.safe_sqrt(1.0 - mu_s * mu_s)
    return dr.select(sines > 1e-12, dr.clip((nu - mu * mu_s) / dr.maximum(sines, 1e-12), -1.0, 1.0), 1.0)


def _horizon_angles(r, bottom_radius):
    """(zenith angle of the horizon, angle between the horizon and the nadir), rad, from radius r:
    cos(beta) = sqrt(r^2 - R^2) / r."""
    beta = dr.acos(dr.clip(dr.safe_sqrt(r * r - bottom_radius * bottom_radius) / r, -1.0, 1.0))
    return math.pi - beta, beta


def sky_view_coordinates(r, mu, cos_azimuth, bottom_radius, ray_hits_ground):
    """Unit-range sky-view coordinates (x_azimuth, x_latitude) of a view from radius ``r`` (m)
    with zenith cosine ``mu`` and azimuth cosine ``cos_azimuth`` relative to the sun.

    Latitude: with theta the view zenith angle, theta_h the horizon's and beta = pi - theta_h,
    x = (1 - sqrt(1 - theta / theta_h)) / 2 above the horizon and x = (1 + sqrt((theta - theta_h)
    / beta)) / 2 below: the horizon sits at x = 1/2, where dtheta/dx vanishes on both sides.
    ``ray_hits_ground`` picks the side (a ray grazing the ground belongs below).
    Longitude: x = sqrt((1 - cos phi) / 2) = sin(phi / 2)."""
    horizon_zenith, beta = _horizon_angles(r, bottom_radius)
    theta = dr.acos(dr.clip(mu, -1.0, 1.0))
    above = 0.5 * (1.0 - dr.safe_sqrt(1.0 - theta / horizon_zenith))
    below = 0.5 * (1.0 + dr.safe_sqrt((theta - horizon_zenith) / beta))
    x_latitude = dr.select(ray_hits_ground, below, above)
    x_azimuth = dr.safe_sqrt(0.5 * (1.0 - cos_azimuth))
    return x_azimuth, x_latitude


def sky_view_direction(x_azimuth, x_latitude, r, bottom_radius):
    """Inverse of :func:`sky_view_coordinates`: (mu, cos_azimuth) of unit-range coordinates."""
    horizon_zenith, beta = _horizon_angles(r, bottom_radius)
    above = horizon_zenith * (1.0 - dr.square(1.0 - 2.0 * x_latitude))
    below = horizon_zenith + beta * dr.square(2.0 * x_latitude - 1.0)
    theta = dr.select(x_latitude < 0.5, above, below)
    return dr.cos(theta), 1.0 - 2.0 * x_azimuth * x_azimuth


# --- the method ---------------------------------------------------------------------------------

class Hillaire2020(LutMethod):
    """Hillaire 2020 (see the module docstring). Table sizes and sample counts default to the
    paper's, the sky view's ray-march segments to the reference demo's (4, 14);
    ``multiple_scattering=False`` drops table 2 (single scattering only: Psi_ms = 0);
    ``ray_march_sky=True`` marches every view ray instead of reading the sky-view table (the
    reference's per-pixel ray-marching path, with the same segment counts).

    ``sky_view_size`` is (longitude, latitude) texels, ``multiple_scattering_size`` (sun zenith
    cosine, altitude) texels, ``sky_view_samples`` the (fewest, most) ray-march segments of the
    sky view, ``aerial_perspective_size`` (width, height, depth slices) froxels. The planet's
    shadow is that of a point sun (the method's hard shadow): ``sun_angular_radius_deg`` does
    not enter the result.
    """

    name = "hillaire2020"

    def __init__(self, atmosphere, wavelengths_nm="rgb", precision: str = "float32",
                 sun_angular_radius_deg: float = SUN_ANGULAR_RADIUS_DEG, variant: str | None = None, *,
                 multiple_scattering: bool = True, ray_march_sky: bool = False, transmittance_size=(256, 64),
                 transmittance_samples: int = 500, multiple_scattering_size=(32, 32),
                 multiple_scattering_directions: int = 64, multiple_scattering_samples: int = 20,
                 sky_view_size=(192, 108), sky_view_samples=(4, 14),
                 aerial_perspective_size=(32, 32, 32), aerial_perspective_slice_km: float = 4.0):
        if not isinstance(multiple_scattering, bool):
            raise ParameterError("multiple_scattering", multiple_scattering, "True or False", "not a boolean")
        self.multiple_scattering = multiple_scattering
        if not isinstance(ray_march_sky, bool):
            raise ParameterError("ray_march_sky", ray_march_sky, "True or False", "not a boolean")
        self.ray_march_sky = ray_march_sky
        self.transmittance_size = check_int_tuple("transmittance_size", transmittance_size, 2, 2, 4096)
        self.transmittance_samples = check_int("transmittance_samples", transmittance_samples, 1, 100_000)
        self.multiple_scattering_size = check_int_tuple("multiple_scattering_size", multiple_scattering_size, 2, 2, 4096)
        directions = check_int("multiple_scattering_directions", multiple_scattering_directions, 1, 4096)
        if math.isqrt(directions) ** 2 != directions:
            raise ParameterError("multiple_scattering_directions", directions,
                                 "a square number (an n x n grid on the sphere): 1, 4, ..., 64, ...", "not a square")
        self.multiple_scattering_directions = directions
        self.multiple_scattering_samples = check_int("multiple_scattering_samples",
                                                        multiple_scattering_samples, 1, 10_000)
        self.sky_view_size = check_int_tuple("sky_view_size", sky_view_size, 2, 2, 4096)
        self.sky_view_samples = check_int_tuple("sky_view_samples", sky_view_samples, 2, 1, 10_000)
        if self.sky_view_samples[0] > self.sky_view_samples[1]:
            raise ParameterError("sky_view_samples", sky_view_samples, "(fewest, most) with fewest <= most",
                                 "fewest > most")
        self.aerial_perspective_size = check_int_tuple("aerial_perspective_size", aerial_perspective_size, 3, 2, 4096)
        self.aerial_perspective_slice_km = check_number("aerial_perspective_slice_km", aerial_perspective_slice_km,
                                                        0.0, 1.0e4, lo_open=True)
        super().__init__(atmosphere, wavelengths_nm, precision, sun_angular_radius_deg, variant)
        self.transmittance = None
        self.multiple_scattering_table = None
        self._sky_views = {}
        self.table_seconds = {}

    # --- precomputation -------------------------------------------------------------------

    def _precompute(self):
        """Tables 1 and 2 (view-independent); sky views are built on demand (:meth:`sky_view`)."""
        start = time.perf_counter()
        width, height = self.transmittance_size
        self.transmittance = TransmittanceTable(self.optics, width, height, self.transmittance_samples,
                                                self.precision)
        dr.eval(self.transmittance.table.values)
        self.table_seconds = {"transmittance": time.perf_counter() - start}
        self._sky_views = {}
        self.multiple_scattering_table = None
        if self.multiple_scattering:
            start = time.perf_counter()
            self.multiple_scattering_table = self._compute_multiple_scattering()
            self.table_seconds["multiple_scattering"] = time.perf_counter() - start

    def _compute_multiple_scattering(self) -> Table:
        """Table 2: Psi_ms = L_2nd / (1 - f_ms) per (altitude, sun zenith cosine) cell, one lane
        per (cell, sphere direction, channel)."""
        n_mu_s, n_r = self.multiple_scattering_size
        grid = math.isqrt(self.multiple_scattering_directions)
        count = self.multiple_scattering_directions
        N = self.channels
        R, Rt = self.optics.bottom_radius, self.optics.top_radius

        lane = dr.arange(mi.UInt32, n_r * n_mu_s * count * N)
        channel = lane % N
        direction = (lane // N) % count
        cell = lane // (N * count)
        mu_s = 2.0 * unit_range((mi.Float64(cell % n_mu_s) + 0.5) / n_mu_s, n_mu_s) - 1.0
        r = R + unit_range((mi.Float64(cell // n_mu_s) + 0.5) / n_r, n_r) * (Rt - R)
        # Stratified directions: azimuth 2 pi a, cos(zenith) 1 - 2 b (uniform on the sphere).
        a = (mi.Float64(direction // grid) + 0.5) / grid
        b = (mi.Float64(direction % grid) + 0.5) / grid
        mu = 1.0 - 2.0 * b
        nu = mu * mu_s + dr.safe_sqrt(1.0 - mu * mu) * dr.sin(2.0 * math.pi * a) * dr.safe_sqrt(1.0 - mu_s * mu_s)

        hits_ground = planet.intersects_ground(r, mu, R)
        length = planet.distance_to_nearest_boundary(r, mu, R, Rt, hits_ground)
        isotropic = mi.Float64(ISOTROPIC_PHASE)
        radiance, transmittance, scattered = self._march(
            r, mu, mu_s, nu, length, mi.Float64(self.multiple_scattering_samples), False,
            isotropic, isotropic, channel)
        # The sunlit ground seen along the ray is a source of the second order too.
        _, mu_s_ground = self._sample_point(r, mu, mu_s, nu, length)
        ground = self._ground_reflected_sun(mu_s_ground, channel)
        radiance += dr.select(hits_ground, transmittance * ground, 0.0)

        per_direction = (self.multiple_scattering_directions, N)
        second_order = radiance.numpy().reshape((-1,) + per_direction).mean(axis=1)       # L_2nd
        f_ms = scattered.numpy().reshape((-1,) + per_direction).mean(axis=1)             # f_ms
        return Table(second_order / (1.0 - f_ms), (n_r, n_mu_s), N, self.precision)

    def sky_view(self, r: float, mu_s: float) -> Table:
        """Table 3 for an observer at radius ``r`` (m, inside the atmosphere) with the sun at
        zenith cosine ``mu_s``: in-scattered radiance per unit solar irradiance, sr^-1, shape
        (latitude, longitude). Cached; :attr:`table_seconds` ["sky_view"] times the last build."""
        R, Rt = self.optics.bottom_radius, self.optics.top_radius
        key = (check_number("r", r, R, Rt), check_number("mu_s", mu_s, -1.0, 1.0))
        if key in self._sky_views:
            return self._sky_views[key]
        start = time.perf_counter()
        n_azimuth, n_latitude = self.sky_view_size
        N = self.channels
        lane = dr.arange(mi.UInt32, n_latitude * n_azimuth * N)
        channel = lane % N
        cell = lane // N
        x_azimuth = unit_range((mi.Float64(cell % n_azimuth) + 0.5) / n_azimuth, n_azimuth)
        x_latitude = unit_range((mi.Float64(cell // n_azimuth) + 0.5) / n_latitude, n_latitude)
        # Opaque: a new observer or sun reuses the compiled kernel.
        r, mu_s = dr.opaque(mi.Float64, key[0]), dr.opaque(mi.Float64, key[1])
        mu, cos_azimuth = sky_view_direction(x_azimuth, x_latitude, r, R)
        nu = mu * mu_s + dr.safe_sqrt(1.0 - mu * mu) * dr.safe_sqrt(1.0 - mu_s * mu_s) * cos_azimuth
        hits_ground = x_latitude >= 0.5
        length = planet.distance_to_nearest_boundary(r, mu, R, Rt, hits_ground)
        radiance, _, _ = self._march(r, mu, mu_s, nu, length, self._sky_view_segments(length), True,
                                     self.optics.rayleigh_phase(nu), self.optics.mie_phase(nu), channel)
        table = Table.from_lanes(radiance, (n_latitude, n_azimuth), N, self.precision)
        if len(self._sky_views) >= SKY_VIEW_CACHE_SIZE:
            self._sky_views.pop(next(iter(self._sky_views)))
        self._sky_views[key] = table
        self.table_seconds["sky_view"] = time.perf_counter() - start
        return table

    def _prepare_view(self, r: float, mu_s: float):
        if r <= self.optics.top_radius and not self.ray_march_sky:
            self.sky_view(r, mu_s)

    def aerial_perspective(self, camera, sun_direction, observer_altitude_m: float) -> "AerialPerspective":
        """Table 4 for a perspective ``camera`` (:class:`skyref.scene.Camera`) at
        ``observer_altitude_m`` with the sun towards ``sun_direction`` (east-north-up)."""
        if self.transmittance is None:
            raise RuntimeError(f"{self.name}: call precompute() before aerial_perspective()")
        return AerialPerspective(self, camera, sun_direction, observer_altitude_m)

    def tables(self) -> dict:
        if self.transmittance is None:
            raise RuntimeError(f"{self.name}: call precompute() before tables()")
        tables = {"transmittance": self.transmittance.table.numpy()}
        if self.multiple_scattering_table is not None:
            tables["multiple_scattering"] = self.multiple_scattering_table.numpy()
        for (r, mu_s), table in self._sky_views.items():
            altitude = r - self.optics.bottom_radius
            tables[f"sky_view(altitude_m={altitude:g}, mu_s={mu_s:.6g})"] = table.numpy()
        return tables

    def operations(self) -> Operations:
        """Fetches per direction of an observer inside the atmosphere, from :meth:`_radiance`:
        the sky reads the sky view once (with ``ray_march_sky``, a march of at most
        ``sky_view_samples[1]`` segments instead); a ground view adds the transmittance at both
        ends of the ray and towards the sun at the ground point, and the multiple-scattering
        table there. Per view: the sky view, every cell a march of ``sky_view_samples`` segments
        (fewest to most, with the ray's length), each reading the transmittance towards the sun
        and the multiple-scattering table (:meth:`_march`). An observer above the atmosphere
        marches every direction."""
        width, height = self.transmittance_size
        tables = {"transmittance": (height, width)}
        per_segment = {"transmittance fetches per segment": 1}
        if self.multiple_scattering:
            tables["multiple_scattering"] = self.multiple_scattering_size[::-1]
            per_segment["multiple_scattering fetches per segment"] = 1
        most = self.sky_view_samples[1]
        if self.ray_march_sky:
            sky = {"ray-march segments (at most)": most, **per_segment}
            per_view = {}
        else:
            tables["sky_view"] = self.sky_view_size[::-1]
            sky = {"sky_view fetches": 1}
            per_view = {"sky_view cells": int(np.prod(self.sky_view_size)), "segments per cell (at most)": most,
                        **per_segment}
        ground = {**sky, "transmittance fetches": 3,
                  **({"multiple_scattering fetches": 1} if self.multiple_scattering else {})}
        return Operations(tables=tables, sky=sky, ground=ground, per_view=per_view,
                          note="this implementation evaluates the ground term for every direction")

    # --- the ray march --------------------------------------------------------------------

    def _sky_view_segments(self, length):
        """The sky view's variable segment count for rays of ``length`` m (non-integer)."""
        fewest, most = self.sky_view_samples
        return fewest + (most - fewest) * dr.clip(length / SKY_VIEW_FULL_SAMPLES_DISTANCE, 0.0, 1.0)

    @staticmethod
    def _segment(index, segments, length, quadratic: bool):
        """Start and end (m) of ray-march segment ``index`` of ``segments`` over ``length``.
        Uniform: edges at i / n. Quadratic (the reference's variable count, n non-integer):
        edges at (i / floor(n))^2 on the first floor(n)/n of the ray, the last segment reaching
        the end."""
        whole = dr.floor(segments)
        whole_length = length * whole / segments
        x0, x1 = index / whole, (index + 1.0) / whole
        if quadratic:
            x0, x1 = x0 * x0, x1 * x1
        return x0 * whole_length, dr.select(x1 > 1.0, length, x1 * whole_length)

    @staticmethod
    def _sample_point(r, mu, mu_s, nu, t):
        """(radius, sun zenith cosine) at distance ``t`` along the ray from (r, mu) whose
        view-sun cosine is ``nu``: the sun's zenith cosine there is (r mu_s + t nu) / r_t."""
        r_t, _ = planet.point_along_ray(r, mu, t)
        return r_t, dr.clip((r * mu_s + t * nu) / dr.maximum(r_t, 1.0), -1.0, 1.0)

    @dr.syntax
    def _march(self, r, mu, mu_s, nu, length, segments, quadratic: bool, phase_rayleigh, phase_mie, channel):
        """Ray march from (r, mu) over ``length`` m (see the module docstring) for the lanes'
        wavelength ``channel``. Returns (in-scattered radiance per unit solar irradiance, sr^-1;
        transmittance over the ray; f = int T sigma_s dt, the light a unit isotropic source along
        the ray would scatter, used for f_ms)."""
        radiance = mi.Float64(0.0)
        transmittance = mi.Float64(1.0)
        scattered = mi.Float64(0.0)
        index = mi.Float64(0.0)
        while index < segments:
            t0, t1 = self._segment(index, segments, length, quadratic)
            dt = t1 - t0
            t = t0 + SEGMENT_SAMPLE_POSITION * dt
            r_t, mu_s_t = self._sample_point(r, mu, mu_s, nu, t)
            altitude = r_t - self.optics.bottom_radius
            rayleigh, mie = self.optics.scattering(altitude, channel)
            extinction = self.optics.extinction(altitude, channel)
            # Sunlight reaches the sample unless the planet is in the way (a hard shadow).
            sun = dr.select(planet.intersects_ground(r_t, mu_s_t, self.optics.bottom_radius), 0.0,
                            self.transmittance.to_top(r_t, mu_s_t, channel))
            source = (sun * (rayleigh * phase_rayleigh + mie * phase_mie)
                      + self._multiple_scattering(r_t, mu_s_t, channel) * (rayleigh + mie))
            segment_transmittance = dr.exp(-extinction * dt)
            # int_0^dt exp(-sigma_t s) ds, = dt where the medium is (numerically) empty
            weight = dr.select(extinction * dt > 1e-12, (1.0 - segment_transmittance) / extinction, dt)
            radiance += transmittance * source * weight
            scattered += transmittance * (rayleigh + mie) * weight
            transmittance *= segment_transmittance
            index += 1.0
        return radiance, transmittance, scattered

    # --- sources --------------------------------------------------------------------------

    def _multiple_scattering(self, r, mu_s, channel):
        """Psi_ms (sr^-1) at radius r and sun zenith cosine mu_s from table 2 (0 without it)."""
        if self.multiple_scattering_table is None:
            return mi.Float64(0.0)
        R, Rt = self.optics.bottom_radius, self.optics.top_radius
        n_mu_s, n_r = self.multiple_scattering_size
        x_r = dr.clip((r - R) / (Rt - R), 0.0, 1.0)
        return self.multiple_scattering_table.lookup(
            (texture_coordinate(x_r, n_r), texture_coordinate(0.5 * mu_s + 0.5, n_mu_s)), channel)

    def _ground_reflected_sun(self, mu_s, channel):
        """Radiance per unit solar irradiance (sr^-1) of the Lambertian ground lit by the sun at
        zenith cosine ``mu_s`` through the atmosphere: rho/pi T_sun max(mu_s, 0)."""
        R = self.optics.bottom_radius
        sun = self.transmittance.to_top(mi.Float64(R), mu_s, channel)
        return self.optics.ground_albedo(channel) / math.pi * sun * dr.maximum(mu_s, 0.0)

    def _ground_radiance(self, mu_s, channel):
        """The ground's radiance per unit solar irradiance (sr^-1): the reflected sun plus the
        multiply scattered light of table 2 taken as an isotropic sky, rho Psi_ms."""
        sky = self._multiple_scattering(mi.Float64(self.optics.bottom_radius), mu_s, channel)
        return self._ground_reflected_sun(mu_s, channel) + self.optics.ground_albedo(channel) * sky

    def _enter_atmosphere(self, r, mu, mu_s, nu):
        """Move ray starts above the atmosphere to where the ray enters it (views from space).
        Returns (r, mu, mu_s) there, the distance moved (m) and a mask of rays that miss it (from
        the top itself, every ray that does not point down into the atmosphere)."""
        Rt = self.optics.top_radius
        outside = r >= Rt
        discriminant = r * r * (mu * mu - 1.0) + Rt * Rt
        misses = outside & ((mu >= 0.0) | (discriminant < 0.0))
        moved = dr.select(outside & ~misses, dr.maximum(-r * mu - dr.safe_sqrt(discriminant), 0.0), 0.0)
        r_entry, mu_entry = planet.point_along_ray(r, mu, moved)
        _, mu_s_entry = self._sample_point(r, mu, mu_s, nu, moved)
        return (dr.select(outside, dr.minimum(r_entry, Rt), r), dr.select(outside, mu_entry, mu),
                dr.select(outside, mu_s_entry, mu_s), moved, misses)

    # --- lookups ----------------------------------------------------------------------------

    def _view_lanes(self, count: int):
        """One lane per (view, channel), channel fastest: (view index, channel, solar irradiance)."""
        lane = dr.arange(mi.UInt32, count * self.channels)
        channel = lane % self.channels
        irradiance = dr.gather(mi.Float64, mi.Float64(self.solar_irradiance), channel)
        return lane // self.channels, channel, irradiance

    def _split_channels(self, values, count: int) -> list:
        """Lanes (view, channel) -> one array of ``count`` views per channel."""
        views = dr.arange(mi.UInt32, count) * self.channels
        return [dr.gather(mi.Float64, values, views + k) for k in range(self.channels)]

    def _radiance(self, r, mu, mu_s, nu):
        """Sky-view table inside the atmosphere, a direct ray march from space (or everywhere with
        ``ray_march_sky``); where the ray hits the ground, plus the ground's radiance attenuated
        by the transmittance table. W m^-2 sr^-1 nm^-1."""
        R, Rt = self.optics.bottom_radius, self.optics.top_radius
        count = dr.width(mu)
        if count == 0:
            return [mi.Float64() for _ in range(self.channels)]
        observer_r, sun_mu = float(r.numpy()[0]), float(mu_s.numpy()[0])
        view, channel, irradiance = self._view_lanes(count)
        r, mu, mu_s, nu = (_per_lane(x, view) for x in (r, mu, mu_s, nu))

        start_r, start_mu, start_mu_s, _, misses = self._enter_atmosphere(r, mu, mu_s, nu)
        hits_ground = planet.intersects_ground(start_r, start_mu, R)
        length = planet.distance_to_nearest_boundary(start_r, start_mu, R, Rt, hits_ground)
        if observer_r <= Rt and not self.ray_march_sky:
            n_azimuth, n_latitude = self.sky_view_size
            x_azimuth, x_latitude = sky_view_coordinates(r, mu, cos_view_sun_azimuth(mu, mu_s, nu), R, hits_ground)
            in_scattered = self.sky_view(observer_r, sun_mu).lookup(
                (texture_coordinate(x_latitude, n_latitude), texture_coordinate(x_azimuth, n_azimuth)), channel)
        else:
            in_scattered, _, _ = self._march(start_r, start_mu, start_mu_s, nu, length, self._sky_view_segments(length),
                                             True, self.optics.rayleigh_phase(nu), self.optics.mie_phase(nu), channel)
        _, ground_mu_s = self._sample_point(start_r, start_mu, start_mu_s, nu, length)
        ground = (self.transmittance.between(start_r, start_mu, length, hits_ground, channel)
                  * self._ground_radiance(ground_mu_s, channel))
        radiance = dr.select(misses, 0.0, in_scattered + dr.select(hits_ground, ground, 0.0)) * irradiance
        return self._split_channels(radiance, count)


# --- the aerial perspective volume ----------------------------------------------------------------

class AerialPerspective:
    """Table 4 of :class:`Hillaire2020` for one perspective camera, observer altitude and sun:
    froxels (slice k, row i, column j) at the camera's pixel directions of a ``width`` x
    ``height`` image and at depth ((k + 1/2) / n)^2 n s (s = ``aerial_perspective_slice_km``),
    holding the in-scattered radiance per unit solar irradiance (sr^-1) and the transmittance
    from the camera to the froxel. As in the reference, a froxel under the ground is moved up to
    the ground along the local vertical (so a lookup at a ground point interpolates between
    froxels on the ground, not under it), and a camera above the atmosphere starts each march
    where the ray enters it."""

    def __init__(self, method: Hillaire2020, camera, sun_direction, observer_altitude_m: float):
        if getattr(camera, "type", None) != "perspective":
            raise ParameterError("camera.type", getattr(camera, "type", camera), "'perspective'",
                                 "the aerial perspective volume needs a frustum")
        check_number("observer_altitude_m", observer_altitude_m, 0.0, 1.0e8)
        sun = check_array("sun_direction", sun_direction, -1.0, 1.0, min_length=3)
        if sun.size != 3 or not np.isclose(np.linalg.norm(sun), 1.0, atol=1e-6):
            raise ParameterError("sun_direction", sun_direction, "a unit vector (3,)", "not a unit vector")
        self.method, self.camera, self.sun_direction = method, camera, sun
        self.observer_altitude_m = float(observer_altitude_m)
        self.rotation = camera_to_world(camera)[:3, :3]
        self.size = method.aerial_perspective_size
        self.slice_length = method.aerial_perspective_slice_km * 1000.0
        optics = method.optics
        R, Rt = optics.bottom_radius, optics.top_radius
        width, height, slices = self.size
        start = time.perf_counter()

        # Froxel centres, planet-centred (the camera at (0, 0, r) looking into east-north-up).
        u = (np.arange(width) + 0.5) / width
        v = (np.arange(height) + 0.5) / height
        vv, uu = np.meshgrid(v, u, indexing="ij")
        local = np.stack(perspective_direction(uu, vv, camera.fov_deg, camera.width / camera.height), axis=-1)
        pixel_directions = local @ self.rotation.T                                      # (H, W, 3)
        depth = ((np.arange(slices) + 0.5) / slices) ** 2 * slices * self.slice_length  # (S,)
        origin = np.array([0.0, 0.0, R + self.observer_altitude_m])
        points = origin + depth[:, None, None, None] * pixel_directions[None]           # (S, H, W, 3)
        radius = np.linalg.norm(points, axis=-1, keepdims=True)
        points = np.where(radius < R, points / radius * R, points)
        offsets = (points - origin).reshape(-1, 3)
        distance = np.linalg.norm(offsets, axis=-1)
        directions = offsets / distance[:, None]
        segments = np.repeat(np.maximum(1.0, 2.0 * (np.arange(slices) + 1.0)), height * width)

        view, channel, _ = method._view_lanes(len(distance))
        r, mu_s = mi.Float64(origin[2]), mi.Float64(sun[2])
        mu, nu, distance, segments = (_per_lane(x, view) for x in (directions[:, 2],
                                                                  np.clip(directions @ sun, -1.0, 1.0),
                                                                  distance, segments))
        start_r, start_mu, start_mu_s, moved, misses = method._enter_atmosphere(r, mu, mu_s, nu)
        hits_ground = planet.intersects_ground(start_r, start_mu, R)
        boundary = planet.distance_to_nearest_boundary(start_r, start_mu, R, Rt, hits_ground)
        length = dr.minimum(dr.maximum(distance - moved, 0.0), boundary)
        in_scattered, transmittance, _ = method._march(
            start_r, start_mu, start_mu_s, nu, length, segments, False,
            optics.rayleigh_phase(nu), optics.mie_phase(nu), channel)
        empty = misses | (distance <= moved)        # the froxel lies before the atmosphere begins
        shape = (slices, height, width)
        self.in_scattering = Table.from_lanes(dr.select(empty, 0.0, in_scattered), shape, method.channels,
                                              method.precision)
        self.transmittance = Table.from_lanes(dr.select(empty, 1.0, transmittance), shape, method.channels,
                                              method.precision)
        self.precompute_seconds = time.perf_counter() - start

    def screen_coordinates(self, directions) -> tuple:
        """Film coordinates (u, v) in [0, 1] of east-north-up ``directions`` (M, 3) in the
        camera's image; ParameterError for directions outside the frustum."""
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        local = d @ self.rotation
        tan_half = math.tan(0.5 * math.radians(self.camera.fov_deg))
        aspect = self.camera.width / self.camera.height
        with np.errstate(divide="ignore", invalid="ignore"):
            u = 0.5 * (1.0 - local[:, 0] / (local[:, 2] * tan_half))
            v = 0.5 * (1.0 - local[:, 1] * aspect / (local[:, 2] * tan_half))
        tolerance = 1e-9
        inside = (local[:, 2] > 0.0) & (np.abs(u - 0.5) <= 0.5 + tolerance) & (np.abs(v - 0.5) <= 0.5 + tolerance)
        if not inside.all():
            raise ParameterError("directions", d[~inside][:3].tolist(), "inside the camera's frustum",
                                 f"{int((~inside).sum())} direction(s) outside it")
        return u, v

    def lookup(self, directions, distances_m) -> tuple:
        """(in-scattered radiance W m^-2 sr^-1 nm^-1, transmittance), each (M, N), from the camera
        to the points at ``distances_m`` (M,) along ``directions`` (M, 3), interpolated in the
        volume. As in the reference, depths under half a slice fade linearly to nothing at the
        camera, and depths beyond the last slice read the last slice (texture clamp)."""
        u, v = self.screen_coordinates(directions)
        distances = check_array("distances_m", np.atleast_1d(distances_m), 0.0, 1.0e9)
        if distances.size != u.size:
            raise ParameterError("distances_m", distances.size, f"{u.size} distances, one per direction",
                                 "wrong length")
        slices = self.size[2]
        depth_slice = distances / self.slice_length
        weight = np.clip(2.0 * depth_slice, 0.0, 1.0)
        w = np.sqrt(np.maximum(depth_slice, 0.5) / slices)
        coords = (mi.Float64(w), mi.Float64(v), mi.Float64(u))
        in_scattered = np.stack([c.numpy() for c in self.in_scattering.lookup(coords)], axis=1)
        transmittance = np.stack([c.numpy() for c in self.transmittance.lookup(coords)], axis=1)
        weight = weight[:, None]
        return (weight * in_scattered * self.method.solar_irradiance[None, :],
                1.0 - weight * (1.0 - transmittance))

    def radiance(self, directions) -> np.ndarray:
        """What the engine shows through this camera, (M, N) W m^-2 sr^-1 nm^-1 without the sun:
        the sky from the sky-view table (:meth:`Hillaire2020.radiance`) and, where the ray hits
        the ground, the ground's radiance seen through the aerial perspective volume,
        L_ground T_AP + L_AP."""
        method, R = self.method, self.method.optics.bottom_radius
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        self.screen_coordinates(d)
        r, mu = mi.Float64(R + self.observer_altitude_m), mi.Float64(d[:, 2])
        ground = planet.intersects_ground(r, mu, R).numpy()
        result = np.empty((len(d), method.channels))
        result[~ground] = method.radiance(d[~ground], self.sun_direction, self.observer_altitude_m)
        if not ground.any():
            return result
        count = int(ground.sum())
        distance = planet.distance_to_bottom(r, mu, R).numpy()[ground]
        view, channel, irradiance = method._view_lanes(count)
        nu = np.clip(d[ground] @ self.sun_direction, -1.0, 1.0)
        _, ground_mu_s = method._sample_point(r, _per_lane(d[ground, 2], view), mi.Float64(self.sun_direction[2]),
                                              _per_lane(nu, view), _per_lane(distance, view))
        surface = method._split_channels(method._ground_radiance(ground_mu_s, channel) * irradiance, count)
        in_scattered, transmittance = self.lookup(d[ground], distance)
        result[ground] = in_scattered + transmittance * np.stack([c.numpy() for c in surface], axis=1)
        return result
