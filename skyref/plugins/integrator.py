"""The ``atmosphere`` integrator: skyref's fast, unbiased ground truth.

A spectral path tracer for the atmosphere alone, written directly in Dr.Jit (no Mitsuba shapes
for the planet: the ground and the top of the atmosphere are analytic spheres, or planes, in an
observer-centred frame, see :mod:`skyref.plugins.geometry`).

Two independent estimators (``estimator``): ``delta_tracking``, the default, described below,
and ``line_integral`` (experimental, :mod:`skyref.plugins.line_integral`): single scattering by
quadrature along every segment of the path, the sun's optical depth from a table, and forced
collisions, so that every path scatters; orders >= 2 stay unbiased Monte Carlo. Its quadrature
is within 1e-4 of a refined one on clear skies up to the horizon, not yet on optically thick
horizons (hazy: 3e-4) or at twilight (9e-4); see ``results/groundtruth_speed.md`` for its speed.
Scenes with objects use delta tracking.

The delta-tracking estimator, per camera sample:

* **Wavelengths.** A path carries K channels (indices into the wavelength grid of N values;
  by default K = N, all of them): channel k takes index (j + k floor(N/K)) mod N with j uniform,
  so every wavelength is carried with probability K/N and the image estimate divides by that.
* **Free flights: spectral tracking** (Kutz et al. 2017) against a *grey* majorant (the largest
  extinction over the channels; per-channel majorants bias and inflate variance, DESIGN.md).
  The majorant is the extinction at the lowest point of the remaining segment, regenerated after
  every tentative collision, so it follows the density as the ray climbs. At a tentative
  collision the event is real scattering with probability P_s = M_s / (M_s + M_n), with M_s and
  M_n the largest w sigma_s and w (mu - sigma_t) over the channels (history-aware "max"
  probabilities, w the path throughput), and null otherwise; the throughput is multiplied by
  sigma_s / (mu P_s) or (mu - sigma_t) / (mu (1 - P_s)), which keeps every channel unbiased.
  Absorption (ozone, aerosol) acts through the null weight.
* **Next-event estimation to the sun at every candidate point**, not only at real scattering:
  the expected value of the scattering branch, w sigma_s / rate, times the sun's contribution.
  Where a camera ray segment is optically thin, its candidate points are drawn more densely than
  the majorant (at least ``CAMERA_SUN_CONNECTIONS`` over the segment, at most
  ``CAMERA_MAX_BOOST`` x the majorant) and thinned with probability majorant / rate back to the
  tracking process, so single scattering gets several sun connections per path. Each connection samples a direction uniformly inside the solar disk,
  estimates its transmittance by **ratio tracking** (unbiased), and is zero if the ground or an
  object blocks it. Ground vertices connect to the sun the same way. The sun is never hit by
  chance after a scattering event (space is black), so nothing is counted twice; a camera ray that
  leaves the atmosphere without scattering sees the solar disk (``sun_direct``).
* **Phase sampling**: the local mixture of Rayleigh and aerosol phase functions, sampled by a
  one-sample mixture (Rayleigh exactly, Cornette–Shanks via Henyey–Greenstein), weight
  p / pdf.
* **Ground**: Lambertian, cosine-weighted sampling (weight = albedo).
* **Russian roulette** from the third vertex on, on the largest channel throughput.

Each contribution is filed under its scattering order: ``sun_direct`` (0), ``single`` (1),
``double`` (2), ``higher`` (3+); the radiance is their sum.

Differentiable parameters (:class:`skyref.plugins.optics.AtmosphereOptics`) enter only the
throughput weights: sampling decisions (majorants, event and component probabilities, sampling
densities) are detached, so forward-mode derivatives of the estimate are unbiased estimates of
the derivatives of the radiance.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from skyref.atmosphere import solar_irradiance
from skyref.plugins.geometry import PlaneParallelSlab, SphericalShell
from skyref.plugins.line_integral import LineIntegral, grey_sum
from skyref.plugins.optics import AtmosphereOptics, atmosphere_from_property, direction_with_cosine
from skyref.plugins.quadrature import panel_levels
from skyref.plugins.sun_optical_depth import SunOpticalDepth
from skyref.scene import SUN_ANGULAR_RADIUS_DEG, direction_from_angles
from skyref.sky import ORDER_NAMES

#: Limb-darkening coefficient u of the linear law I(mu)/I(1) = 1 - u (1 - mu), grey (a visible
#: band average; Neckel & Labs 1994 give 0.5–0.7 across 450–700 nm).
LIMB_DARKENING_U = 0.6

#: Majorants are inflated by this factor so that float32 rounding of an altitude can never push
#: the local extinction above them (any upper bound keeps delta tracking unbiased).
MAJORANT_SAFETY = 1.001

#: Relative offset of a ray leaving an object's surface (x the largest coordinate), against
#: float32 self-intersection.
OBJECT_OFFSET = 1.0e-5

#: Sun connections drawn at least along each camera ray segment (where the tracking's own
#: tentative collisions would be fewer), and the cap on the candidate rate in majorants.
#: Measured on the benchmark sky (sun zenith 60 deg, RGB): time to 1% error -20%; capped so that
#: optically thick or low-sun scenes, where connections are expensive, do not pay more.
CAMERA_SUN_CONNECTIONS = 8.0
CAMERA_MAX_BOOST = 4.0

#: Shadow rays whose transmittance falls below this (in every channel) play Russian roulette.
SHADOW_ROULETTE = 0.05

#: Russian roulette starts at this scattering order.
ROULETTE_DEPTH = 3

#: The estimators: ``delta_tracking`` (the default: spectral tracking with next-event estimation
#: at every candidate point) and ``line_integral`` (experimental: single scattering by quadrature
#: along every segment, forced collisions; see :mod:`skyref.plugins.line_integral` for where its
#: quadrature does not yet meet its error bound), independent of each other.
ESTIMATORS = ("line_integral", "delta_tracking")
DEFAULT_ESTIMATOR = "delta_tracking"

#: The line-integral estimator plays Russian roulette from this many vertices on, on paths whose
#: largest channel throughput is below LINE_ROULETTE_THROUGHPUT (survival = throughput / it).
LINE_ROULETTE_DEPTH = 2
LINE_ROULETTE_THROUGHPUT = 0.1


class SunLight:
    """The sun as a disk of angular radius ``angular_radius_rad`` around ``direction`` (unit,
    towards the sun) delivering ``irradiance`` (W m^-2 nm^-1 per grid wavelength, perpendicular to
    the beam at the top of the atmosphere)."""

    def __init__(self, direction, angular_radius_rad, irradiance, limb_darkening=False):
        # Opaque: skies that differ only in the sun's position share compiled kernels.
        self.direction = mi.Vector3f(*[dr.opaque(mi.Float, float(x)) for x in direction])
        self.cos_radius = float(math.cos(angular_radius_rad))
        self.solid_angle = 2.0 * math.pi * (1.0 - self.cos_radius)
        self.irradiance = mi.Float(np.asarray(irradiance, np.float32))
        self.limb_darkening = bool(limb_darkening)
        self.frame = mi.Frame3f(self.direction)

    def radiance_factor(self, cos_angle):
        """Radiance of the disk at angle acos(cos_angle) from its centre, divided by its mean
        (1 everywhere without limb darkening); 0 outside the disk."""
        return dr.select(cos_angle >= self.cos_radius, self._limb_darkening(cos_angle), 0.0)

    def _limb_darkening(self, cos_angle):
        """Linear limb-darkening law in mu = cos of the emission angle on the solar surface,
        normalised by its disk mean 1 - u/3; 1 when limb darkening is off."""
        if not self.limb_darkening:
            return mi.Float(1.0)
        sin_ratio2 = dr.clip((1.0 - cos_angle * cos_angle) / (1.0 - self.cos_radius ** 2), 0.0, 1.0)
        mu = dr.safe_sqrt(1.0 - sin_ratio2)
        return (1.0 - LIMB_DARKENING_U * (1.0 - mu)) / (1.0 - LIMB_DARKENING_U / 3.0)

    def channel_irradiance(self, indices):
        return mi.ArrayXf([dr.gather(mi.Float, self.irradiance, i) for i in indices])

    def sample_direction(self, u):
        """A direction uniformly distributed (in solid angle) inside the disk; returns it with
        the factor by which E_sun must be multiplied (the limb-darkening ratio)."""
        local = mi.warp.square_to_uniform_cone(u, self.cos_radius)
        # No inside test here: in float32, cos(radius) ~ 1 - 1e-5 is resolved to ~1/180 of the
        # cone, and a sampled direction must never be rejected by rounding.
        return self.frame.to_world(local), self._limb_darkening(local.z)


class AtmosphereIntegrator(mi.SamplingIntegrator):
    """Mitsuba plugin ``atmosphere``. Properties (all optional):

    ``atmosphere`` (string: a preset name or the JSON of ``Atmosphere.to_dict()``;
    default ``bruneton2017``), ``wavelengths`` (string: comma-separated nm, or ``rgb``),
    ``sun_zenith``/``sun_azimuth`` (degrees), ``sun_angular_radius`` (degrees),
    ``limb_darkening`` (bool), ``observer_altitude`` (m), ``geometry`` (``spherical`` or
    ``plane_parallel``), ``max_depth`` (int), ``wavelengths_per_path`` (int, default: all N; fewer
    channels per path are cheaper per sample but noisier per wavelength — on the 48-wavelength
    default sky, carrying all of them was 3x more efficient than 16).

    From Python, :meth:`configure` sets the same things from skyref objects.
    """

    def __init__(self, props=mi.Properties()):
        super().__init__(props)
        atmosphere = atmosphere_from_property(props.get("atmosphere", "bruneton2017"))
        wavelengths = props.get("wavelengths", "rgb")
        from skyref.atmosphere import wavelength_grid

        grid = wavelength_grid("rgb" if wavelengths == "rgb" else [float(x) for x in wavelengths.split(",")])
        self.configure(atmosphere, grid, sun_zenith_deg=props.get("sun_zenith", 30.0),
                       sun_azimuth_deg=props.get("sun_azimuth", 180.0),
                       sun_angular_radius_deg=props.get("sun_angular_radius", SUN_ANGULAR_RADIUS_DEG),
                       limb_darkening=props.get("limb_darkening", False),
                       observer_altitude_m=props.get("observer_altitude", 0.0),
                       geometry=props.get("geometry", "spherical"),
                       max_depth=props.get("max_depth", 64),
                       wavelengths_per_path=props.get("wavelengths_per_path", 0),
                       estimator=props.get("estimator", DEFAULT_ESTIMATOR))

    def configure(self, atmosphere, wavelengths_nm, sun_zenith_deg, sun_azimuth_deg,
                  sun_angular_radius_deg, limb_darkening=False, observer_altitude_m=0.0,
                  geometry="spherical", max_depth=64, wavelengths_per_path=0, estimator=DEFAULT_ESTIMATOR):
        """Set the atmosphere, wavelength grid (nm), sun, observer and estimator settings."""
        from skyref.atmosphere.validation import check_choice, check_number

        check_choice("geometry", geometry, ("spherical", "plane_parallel"))
        self.estimator = check_choice("estimator", estimator, ESTIMATORS)
        self.optics = AtmosphereOptics(atmosphere, wavelengths_nm)
        self.wavelengths_nm = self.optics.wavelengths_nm
        n = len(self.wavelengths_nm)
        k = int(wavelengths_per_path) or n
        if not 1 <= k <= n:
            from skyref.errors import ParameterError

            raise ParameterError("wavelengths_per_path", wavelengths_per_path, f"an integer in [1, {n}]")
        self.channels = k
        self.max_depth = int(check_number("max_depth", max_depth, 1, 100_000))
        h0 = check_number("observer_altitude_m", observer_altitude_m, 0.0, 1.0e8)
        if geometry == "spherical":
            self.geometry = SphericalShell(atmosphere.bottom_radius_m, atmosphere.top_radius_m, h0)
        else:
            self.geometry = PlaneParallelSlab(atmosphere.thickness_m, h0)
        self.sun = SunLight(direction_from_angles(sun_zenith_deg, sun_azimuth_deg),
                            math.radians(sun_angular_radius_deg), solar_irradiance(self.wavelengths_nm),
                            limb_darkening)
        if self.estimator == "line_integral":
            self.line = LineIntegral(self.optics, self.geometry, SunOpticalDepth(atmosphere, self.geometry),
                                     panel_levels(atmosphere))
        #: Optional Mitsuba scene whose shapes stand in the atmosphere (terrain, buildings):
        #: Lambertian, grey albedo = the mean of their BSDF's diffuse reflectance. Objects are
        #: traced by the delta-tracking estimator (the line integral assumes open sky).
        self.objects = None

    # --- Mitsuba plumbing ---------------------------------------------------------------------

    def traverse(self, callback):
        for name, value in self.optics.parameters().items():
            callback.put(name, value, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys=[]):
        pass

    def sample(self, scene, sampler, ray, medium=None, active=True):
        """Mitsuba's per-ray entry point, so that ``mi.render`` works in RGB variants with the
        "rgb" grid (channels 680/550/440 nm become R, G, B). skyref itself renders any
        wavelength grid through :meth:`render_orders`."""
        if dr.size_v(mi.Spectrum) != 3 or len(self.wavelengths_nm) != 3:
            raise RuntimeError("the atmosphere integrator renders through mi.render only in RGB "
                               "variants with wavelengths='rgb'; use skyref.render_sky otherwise")
        indices = [mi.UInt32(i) for i in range(3)]
        orders = self.trace(sampler, ray.o, ray.d, indices, mi.Bool(active))
        total = orders[0] + orders[1] + orders[2] + orders[3]
        return mi.Spectrum(total[0], total[1], total[2]), mi.Bool(active), []

    # --- rendering ----------------------------------------------------------------------------

    def render_orders(self, sensor, seed: int, spp: int, pixel_centres: bool = False, batches: int = 1) -> mi.TensorXf:
        """Render through a Mitsuba sensor: a tensor (H, W, 4, N) of radiance per pixel,
        scattering order (``ORDER_NAMES``) and grid wavelength, W m^-2 sr^-1 nm^-1, from ``spp``
        samples per pixel; with ``batches`` > 1, (batches, H, W, 4, N) from as many independent
        batches of ``spp`` samples, traced in one launch. Samples cover each pixel uniformly, or
        look along its centre only (``pixel_centres``)."""
        width, height = (int(x) for x in sensor.film().crop_size())
        sampler, pixel, batch = self._wavefront(seed, width * height, spp, batches)
        offset = mi.Vector2f(0.5) if pixel_centres else sampler.next_2d()
        position = mi.Vector2f(mi.Float(pixel % width), mi.Float(pixel // width)) + offset
        film_uv = position * mi.Vector2f(1.0 / width, 1.0 / height)
        ray, weight = sensor.sample_ray(time=0.0, sample1=sampler.next_1d(), sample2=film_uv,
                                        sample3=sampler.next_2d(), active=True)
        valid = dr.max(mi.Spectrum(weight), axis=0) > 0.0
        image = self._estimate(sampler, pixel, batch, width * height, spp, batches, ray.o, ray.d, valid)
        return self._tensor(image, batches, (height, width))

    def render_directions(self, directions, seed: int, spp: int, batches: int = 1) -> mi.TensorXf:
        """Radiance seen from the observer along given unit directions (array (M, 3), east-north-
        up): a tensor (M, 4, N) like :meth:`render_orders` (or (batches, M, 4, N)), without a
        sensor or pixel filter."""
        directions = np.asarray(directions, dtype=np.float32).reshape(-1, 3)
        count = directions.shape[0]
        sampler, target, batch = self._wavefront(seed, count, spp, batches)
        d = dr.gather(mi.Vector3f, mi.Vector3f(*(mi.Float(directions[:, i]) for i in range(3))), target)
        image = self._estimate(sampler, target, batch, count, spp, batches, mi.Point3f(0.0), d, mi.Bool(True))
        return self._tensor(image, batches, (count,))

    def _tensor(self, image, batches, shape):
        shape = (*shape, len(ORDER_NAMES), len(self.wavelengths_nm))
        return mi.TensorXf(image, ((batches,) if batches > 1 else ()) + shape)

    def directional_derivative(self, directions, parameter: str, seed: int, spp: int):
        """Radiance along ``directions`` (as :meth:`render_directions`) and its derivative with
        respect to one parameter (a name from ``mi.traverse``), by forward-mode automatic
        differentiation through the path tracer. Returns two (M, 4, N) NumPy arrays."""
        original = self.optics.parameters()[parameter]
        value = mi.Float(original)
        dr.enable_grad(value)
        self.optics.set_parameter(parameter, value)
        try:
            radiance = self.render_directions(directions, seed, spp)
            dr.forward(value)
            return radiance.numpy(), dr.grad(radiance).numpy()
        finally:
            self.optics.set_parameter(parameter, original)

    def _wavefront(self, seed, targets, spp, batches):
        """A seeded sampler for ``targets * spp * batches`` samples, each sample's target and
        batch index. The seed and counts are opaque: calls with other seeds or sample counts
        reuse the compiled kernels (the line-integral estimator's take seconds to compile)."""
        wavefront = targets * spp * batches
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(dr.opaque(mi.UInt32, seed), wavefront)
        index = dr.arange(mi.UInt32, wavefront)
        return sampler, index // dr.opaque(mi.UInt32, spp * batches), index % dr.opaque(mi.UInt32, batches)

    def _estimate(self, sampler, target, batch, targets, spp, batches, origin, direction, valid):
        """Trace one sample per lane and average into a flat (batches, targets, 4, N) buffer."""
        n = len(self.wavelengths_nm)
        # Wavelength channels: index (j + k * stride) mod N, each grid wavelength carried with
        # probability K / N.
        stride = n // self.channels
        first = dr.minimum(mi.UInt32(sampler.next_1d() * n), n - 1)
        indices = [(first + k * stride) % n for k in range(self.channels)]
        orders = self.trace(sampler, mi.Point3f(origin), mi.Vector3f(direction), indices, valid)
        scale = dr.opaque(mi.Float, n / (self.channels * spp))
        image = dr.zeros(mi.Float, batches * targets * len(ORDER_NAMES) * n)
        for order, contribution in enumerate(orders):
            for k, index in enumerate(indices):
                slot = ((batch * targets + target) * len(ORDER_NAMES) + order) * n + index
                # A fixed reduction mode: "Auto" picks one by the buffer's size, and each new
                # choice compiles the whole path tracer again.
                dr.scatter_reduce(dr.ReduceOp.Add, image, contribution[k] * scale, slot, valid,
                                  mode=dr.ReduceMode.Local)
        return image

    # --- the path tracer ------------------------------------------------------------------------

    def _segment(self, p, d, h):
        """Where the free segment from p along d ends: its length, whether it ends on a surface
        (the ground or an object), the altitude at its end (exact for the ground and the top),
        and, for an object, its normal (facing the ray) and grey albedo."""
        geometry = self.geometry
        t_ground = geometry.distance_to_ground(p, d, h)
        t_top = geometry.distance_to_top(p, d, h)
        on_ground = t_ground < t_top
        length = dr.select(on_ground, t_ground, t_top)
        h_end = dr.select(on_ground, 0.0, geometry.H)
        if dr.hint(self.objects is None, mode="scalar"):
            return length, on_ground, h_end, mi.Bool(False), mi.Vector3f(0.0), mi.Float(0.0)
        si = self.objects.ray_intersect(mi.Ray3f(p, d, length))
        on_object = si.is_valid() & (si.t < length)
        normal = dr.select(dr.dot(si.n, d) > 0.0, -si.n, si.n)
        albedo = dr.mean(mi.Spectrum(si.bsdf().eval_diffuse_reflectance(si, on_object)), axis=0)
        length = dr.select(on_object, si.t, length)
        h_end = dr.select(on_object, geometry.altitude(p + length * d), h_end)
        return length, on_ground | on_object, h_end, on_object, normal, albedo

    def _majorant(self, channels, p, d, length, h, h_end):
        h_low = self.geometry.lowest_altitude(p, d, length, h, h_end)
        return MAJORANT_SAFETY * self.optics.majorant(channels, h_low, dr.maximum(h, h_end))

    def trace(self, sampler, origin, direction, indices, active):
        """Radiance along camera rays (origin in the observer frame, unit direction) for the
        channels ``indices``: a list of 4 ArrayXf (K channels), one per scattering order
        (``ORDER_NAMES``), by the configured estimator."""
        if self.estimator == "line_integral" and self.objects is None:
            return self._trace_line_integral(sampler, origin, direction, indices, active)
        return self._trace_delta_tracking(sampler, origin, direction, indices, active)

    def _enter_atmosphere(self, origin, direction, active):
        """A camera ray's start in the atmosphere: an observer above it first moves to where the
        ray enters. Returns (point, altitude, whether the ray misses the atmosphere)."""
        geometry = self.geometry
        p = mi.Point3f(origin)
        h = geometry.altitude(p)
        outside = h >= geometry.H
        t_entry = geometry.distance_to_entry(p, direction, h)
        enters = outside & (t_entry < dr.inf)
        p = dr.select(enters, p + t_entry * direction, p)
        h = dr.select(enters, geometry.H, h)
        return p, h, mi.Bool(active) & outside & ~enters

    def _solar_disk(self, d):
        """Radiance of the solar disk seen along ``d`` per unit E_sun, sr^-1."""
        return self.sun.radiance_factor(dr.dot(d, self.sun.direction)) / self.sun.solid_angle

    @dr.syntax
    def _trace_line_integral(self, sampler, origin, direction, indices, active):
        """The line-integral estimator (:mod:`skyref.plugins.line_integral`). One loop iteration
        is one segment of the path: the sunlight scattered once along it is integrated by
        quadrature and filed under the order (vertices so far) + 1, as is the sunlight the
        ground reflects at its end; the path then goes on from a forced collision on the segment
        (or from the ground), with Russian roulette from ``LINE_ROULETTE_DEPTH`` vertices on.
        Camera rays from an observer on the ground only rise, so their segment is peeled off
        the loop with the cheaper rising-only panels."""
        channels = self.optics.channel_coefficients(indices)
        e_sun = self.sun.channel_irradiance(indices)
        d = mi.Vector3f(direction)
        p, h, misses = self._enter_atmosphere(origin, d, active)
        direct = dr.select(misses, e_sun * self._solar_disk(d), channels.zeros())
        single, double, higher = channels.zeros(), channels.zeros(), channels.zeros()
        throughput = channels.zeros() + 1.0
        alive = mi.Bool(active) & ~misses

        light, sun_disk, p, d, h, throughput, alive = self._line_segment(
            sampler, channels, e_sun, p, d, h, throughput, alive, camera=True,
            rising_only=self.geometry.h0 == 0.0)
        direct += sun_disk
        single += light
        depth = mi.UInt32(1)
        alive &= depth < self.max_depth

        while dr.hint(alive, label="atmosphere line-integral path"):
            light, _, p, d, h, throughput, alive = self._line_segment(
                sampler, channels, e_sun, p, d, h, throughput, alive, camera=False, rising_only=False)
            double = dr.select(depth == 1, double + light, double)
            higher = dr.select(depth >= 2, higher + light, higher)
            depth += 1
            # Russian roulette once the largest channel throughput falls below LINE_ROULETTE_THROUGHPUT
            survival = dr.minimum(dr.max(dr.detach(throughput), axis=0) / LINE_ROULETTE_THROUGHPUT, 1.0)
            roulette = alive & (depth >= LINE_ROULETTE_DEPTH)
            survives = sampler.next_1d() < survival
            throughput = dr.select(roulette & survives, throughput / survival, throughput)
            alive &= ~(roulette & ~survives) & (depth < self.max_depth)

        return [direct, single, double, higher]

    def _line_segment(self, sampler, channels, e_sun, p, d, h, throughput, alive, camera, rising_only):
        """One segment of a line-integral path from vertex ``p`` (altitude ``h``) along ``d``.
        Returns (light filed under this segment's order, the solar disk seen through it when
        ``camera``, and the next vertex: point, direction, altitude, throughput, alive)."""
        geometry, optics, sun = self.geometry, self.optics, self.sun
        t_ground = geometry.distance_to_ground(p, d, h)
        t_top = geometry.distance_to_top(p, d, h)
        on_ground = t_ground < t_top
        length = dr.select(on_ground, t_ground, t_top)
        sun_direction, sun_factor = sun.sample_direction(sampler.next_2d())
        grey_s, grey_t, grey_albedo = channels.grey(throughput)
        sunlight, transmittance, quadrature = self.line.integrate(
            channels, p, d, h, length, sun_direction, (grey_s, grey_t), rising_only)
        light = throughput * sunlight * e_sun * sun_factor
        sun_disk = channels.zeros()
        if camera:
            sun_disk = dr.select(alive & ~on_ground, throughput * transmittance * e_sun * self._solar_disk(d),
                                 sun_disk)

        # -- the ground at the segment's end reflects sunlight (Lambertian; lit iff the sun is
        # above its horizon: the planet is convex) -------------------------------------------------
        ground = p + length * d
        up = geometry.up(ground)
        cos_sun = dr.dot(up, sun_direction)
        tau_sun = self.line.sun_depth(mi.Float(0.0), cos_sun)
        reflected = (throughput * transmittance * channels.albedo * e_sun * sun_factor
                     * dr.exp(-channels.optical_depth(tau_sun)) * (dr.maximum(cos_sun, 0.0) / math.pi))
        light += dr.select(on_ground & (cos_sun > 0.0), reflected, 0.0)
        light = dr.select(alive, light, 0.0)

        # -- where the path goes on: a forced collision in the air, or the ground --------------------
        air_mass = sum(quadrature.masses, mi.Float(0.0))
        grey_transmittance = dr.exp(-grey_sum(grey_t, quadrature.total))
        ground_mass = dr.select(on_ground, grey_transmittance * grey_albedo, 0.0)
        p_air = air_mass / dr.maximum(air_mass + ground_mass, 1e-30)
        alive &= (air_mass + ground_mass) > 0.0
        in_air = sampler.next_1d() < p_air
        u_panel, u_position = sampler.next_1d(), sampler.next_1d()
        x, hx, weight, (parts, sigma_s, _) = self.line.sample_collision(channels, quadrature, p, d, u_panel,
                                                                        u_position)
        u_component, u_direction = sampler.next_1d(), sampler.next_2d()
        mu, pdf = optics.sample_phase(parts, sigma_s, u_component, u_direction.x)
        d_air = direction_with_cosine(d, mu, u_direction.y)
        air_throughput = throughput * weight * optics.phase(parts, sigma_s, mu) / (pdf * dr.maximum(p_air, 1e-30))
        d_ground = mi.Frame3f(up).to_world(mi.warp.square_to_cosine_hemisphere(u_direction))
        ground_throughput = throughput * transmittance * channels.albedo / dr.maximum(1.0 - p_air, 1e-30)
        p = dr.select(in_air, x, ground)
        h = dr.select(in_air, hx, 0.0)
        d = dr.select(in_air, d_air, d_ground)
        throughput = dr.select(in_air, air_throughput, ground_throughput)
        return light, sun_disk, p, d, h, throughput, alive

    @dr.syntax
    def _trace_delta_tracking(self, sampler, origin, direction, indices, active):
        """The delta-tracking estimator (the baseline, described in the module docstring).

        One loop does everything, one tracking step per iteration, so that it stays a single
        symbolic loop (fast, and differentiable in forward mode: Dr.Jit 1.5 miscompiles forward
        derivatives of nested symbolic loops). A lane is either *tracking its path* (delta/
        spectral tracking along the current segment) or *tracking a shadow ray* to the sun (ratio
        tracking, started at each vertex); the shadow ray's result is filed when it leaves the
        atmosphere, and the path then goes on from the vertex in its already sampled direction.
        """
        geometry, optics, sun = self.geometry, self.optics, self.sun
        channels = optics.channel_coefficients(indices)
        e_sun = sun.channel_irradiance(indices)
        direct, single, double, higher = channels.zeros(), channels.zeros(), channels.zeros(), channels.zeros()

        # -- the camera ray; an observer above the atmosphere first moves to where it enters ------
        d = mi.Vector3f(direction)
        p, h, misses = self._enter_atmosphere(origin, d, active)
        direct = dr.select(misses, e_sun * self._solar_disk(d), direct)

        throughput = channels.zeros() + 1.0
        alive = mi.Bool(active) & ~misses
        depth = mi.UInt32(0)
        remaining, hits_surface, h_end, hits_object, object_normal, object_albedo = self._segment(p, d, h)

        # -- the shadow ray in flight (one at a time per lane) ----------------------------------
        in_shadow = mi.Bool(False)
        q = mi.Point3f(p)
        omega = mi.Vector3f(d)
        q_remaining = mi.Float(0.0)
        hq = mi.Float(h)
        transmittance = channels.zeros()
        pending = channels.zeros()         # throughput x response x E_sun of the vertex
        pending_order = mi.UInt32(0)

        while dr.hint(alive | in_shadow, label="atmosphere path"):
            # -- one tracking step along the current ray (the shadow ray if one is in flight) ----
            x = dr.select(in_shadow, q, p)
            w = dr.select(in_shadow, omega, d)
            length = dr.select(in_shadow, q_remaining, remaining)
            hx = dr.select(in_shadow, hq, h)
            hx_end = dr.select(in_shadow, geometry.H, h_end)
            majorant = self._majorant(channels, x, w, length, hx, hx_end)
            # Camera rays draw candidate points more densely than the majorant where the segment
            # is optically thin: ~CAMERA_SUN_CONNECTIONS over the rest of the segment, at most
            # CAMERA_MAX_BOOST x the majorant. Each carries a sun connection, which is what makes
            # single scattering converge; thinning the candidates with probability
            # majorant / rate recovers the tracking process exactly.
            camera = ~in_shadow & (depth == 0)
            rate = dr.select(camera, dr.clip(CAMERA_SUN_CONNECTIONS / dr.maximum(length, 1e-3), majorant,
                                             CAMERA_MAX_BOOST * majorant), majorant)
            t = -dr.log(1.0 - sampler.next_1d()) / rate
            collides = t < length
            x = dr.select(collides, x + t * w, x)
            hx = dr.select(collides, geometry.altitude(x), hx)
            parts, sigma_s, sigma_t = optics.local(channels, hx)

            # -- shadow ray: ratio tracking; file the contribution when it leaves -------------------
            shadow_step = in_shadow & collides
            transmittance = dr.select(shadow_step, transmittance * dr.maximum(1.0 - sigma_t / majorant, 0.0),
                                      transmittance)
            # Russian roulette on faint shadow rays (grazing rays at twilight cross tens of
            # optical depths): continue with probability max T / SHADOW_ROULETTE, reweighted.
            faint = shadow_step & (dr.max(transmittance, axis=0) < SHADOW_ROULETTE)
            survival = dr.detach(dr.max(transmittance, axis=0)) / SHADOW_ROULETTE
            survives = sampler.next_1d() < survival
            transmittance = dr.select(faint, dr.select(survives, transmittance / survival, 0.0), transmittance)
            q = dr.select(shadow_step, x, q)
            hq = dr.select(shadow_step, hx, hq)
            q_remaining = dr.select(shadow_step, q_remaining - t, q_remaining)
            shadow_done = in_shadow & (~collides | (dr.max(transmittance, axis=0) <= 0.0))
            contribution = pending * transmittance
            single = dr.select(shadow_done & (pending_order == 1), single + contribution, single)
            double = dr.select(shadow_done & (pending_order == 2), double + contribution, double)
            higher = dr.select(shadow_done & (pending_order >= 3), higher + contribution, higher)
            tracking_path = alive & ~in_shadow
            in_shadow &= ~shadow_done

            # -- path: a tentative collision in the air ----------------------------------------------
            candidate = collides & tracking_path
            reaches_end = tracking_path & ~candidate
            p = dr.select(candidate, x, p)
            h = dr.select(candidate, hx, h)
            remaining = dr.select(candidate, remaining - t, remaining)
            # Next-event estimation at *every* candidate point, weighted by the expected value of
            # the real-scattering branch: P_s * (w sigma_s / (mu P_s)) = w sigma_s / mu, with mu
            # the candidates' rate. The event decision below then only decides how the path goes on.
            sun_direction, sun_factor = sun.sample_direction(sampler.next_2d())
            scattered_sunlight = throughput * optics.phase(parts, sigma_s, dr.dot(d, sun_direction)) * (
                sigma_s / rate)
            collides = candidate & (sampler.next_1d() * rate < majorant)
            null_weight = dr.maximum(majorant - sigma_t, 0.0)
            a_scatter = dr.max(dr.detach(throughput * sigma_s), axis=0)
            a_null = dr.max(dr.detach(throughput * null_weight), axis=0)
            p_scatter = a_scatter / dr.maximum(a_scatter + a_null, 1e-30)
            scatters = collides & (sampler.next_1d() < p_scatter)
            is_null = collides & ~scatters
            throughput = dr.select(scatters, throughput * sigma_s / (majorant * p_scatter), throughput)
            throughput = dr.select(is_null, throughput * null_weight / (majorant * (1.0 - p_scatter)), throughput)

            # -- path: the segment ends on the ground (a Lambertian vertex) or in space -----------
            p = dr.select(reaches_end, p + remaining * d, p)
            h = dr.select(reaches_end, h_end, h)
            on_ground = reaches_end & hits_surface
            escapes = reaches_end & ~hits_surface
            direct = dr.select(escapes & (depth == 0), direct + throughput * e_sun * self._solar_disk(d), direct)
            alive &= ~escapes
            # A surface vertex: the planet's ground, or an object (normal offset: no self-hits).
            on_object = on_ground & hits_object
            up = dr.select(on_object, object_normal, geometry.up(p))
            p = dr.select(on_object, p + up * (OBJECT_OFFSET * (1.0 + dr.max(dr.abs(p)))), p)
            albedo = dr.select(on_object, channels.zeros() + object_albedo, channels.albedo)
            reflected_sunlight = throughput * albedo * (dr.maximum(dr.dot(up, sun_direction), 0.0) / math.pi)

            # -- start the shadow ray of this step's next-event estimate -----------------------------
            estimate = candidate | on_ground
            sunlight = dr.select(on_ground, reflected_sunlight, scattered_sunlight) * e_sun * sun_factor
            estimate &= dr.max(dr.detach(sunlight), axis=0) > 0.0   # nothing to connect: no shadow ray
            visible = estimate & (geometry.distance_to_ground(p, sun_direction, h) == dr.inf)
            if dr.hint(self.objects is not None, mode="scalar"):
                visible &= ~self.objects.ray_test(mi.Ray3f(p, sun_direction), visible)
            in_shadow |= visible
            q = dr.select(visible, p, q)
            hq = dr.select(visible, h, hq)
            omega = dr.select(visible, sun_direction, omega)
            q_remaining = dr.select(visible, geometry.distance_to_top(p, sun_direction, h), q_remaining)
            transmittance = dr.select(visible, 1.0, transmittance)
            pending = dr.select(visible, sunlight, pending)
            pending_order = dr.select(visible, depth + 1, pending_order)
            vertex = scatters | on_ground
            depth = dr.select(vertex, depth + 1, depth)

            # -- vertex: continue the path (phase sampling in the air, cosine on the ground) -------
            u_component = sampler.next_1d()
            u_direction = sampler.next_2d()
            mu, pdf = optics.sample_phase(parts, sigma_s, u_component, u_direction.x)
            d_air = direction_with_cosine(d, mu, u_direction.y)
            d_ground = mi.Frame3f(up).to_world(mi.warp.square_to_cosine_hemisphere(u_direction))
            throughput = dr.select(scatters, throughput * optics.phase(parts, sigma_s, mu) / pdf, throughput)
            throughput = dr.select(on_ground, throughput * albedo, throughput)
            d = dr.select(scatters, d_air, dr.select(on_ground, d_ground, d))
            segment = self._segment(p, d, h)
            remaining = dr.select(vertex, segment[0], remaining)
            hits_surface = dr.select(vertex, segment[1], hits_surface)
            h_end = dr.select(vertex, segment[2], h_end)
            hits_object = dr.select(vertex, segment[3], hits_object)
            object_normal = dr.select(vertex, segment[4], object_normal)
            object_albedo = dr.select(vertex, segment[5], object_albedo)

            # -- Russian roulette and termination ------------------------------------------------
            survival = dr.minimum(dr.max(dr.detach(throughput), axis=0), 0.95)
            roulette = vertex & (depth >= ROULETTE_DEPTH)
            survives = sampler.next_1d() < survival
            throughput = dr.select(roulette & survives, throughput / survival, throughput)
            alive &= ~(roulette & ~survives)
            alive &= (depth < self.max_depth) & (dr.max(throughput, axis=0) > 0.0)

        return [direct, single, double, higher]


def register():
    mi.register_integrator("atmosphere", lambda props: AtmosphereIntegrator(props))
