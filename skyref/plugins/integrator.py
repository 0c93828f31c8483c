"""The ``atmosphere`` integrator: skyref's fast, unbiased ground truth.

A spectral path tracer for the atmosphere alone, written directly in Dr.Jit (no Mitsuba shapes
for the planet: the ground and the top of the atmosphere are analytic spheres, or planes, in an
observer-centred frame, see :mod:`skyref.plugins.geometry`).

Two independent estimators (``estimator``): ``line_integral``, the default
(:mod:`skyref.plugins.line_integral`; 9-60x less CPU to a given error, but kernels that compile
for 15 s to minutes per new configuration), and ``delta_tracking``, the baseline described
below, which the tests compare it against. The line integral computes single scattering by
quadrature along the camera ray, the sun's optical depth from a table, and forced collisions,
so that every path scatters; on the path's later segments the scattered sunlight is sampled at
``SAMPLED_SUNLIGHT_POINTS`` stratified points drawn by the segment's lit scattering mass (one
sun lookup each, where the quadrature pays one per node), so orders >= 2 stay unbiased Monte
Carlo, drawn from scrambled Sobol points (:mod:`skyref.plugins.sobol`), with a sun lobe among
the scattering directions where there is aerosol and a guide towards where the scattered light
comes from (:mod:`skyref.plugins.guiding`), that mixture itself mixed over the whole path with
the phase function alone (:class:`PathSampling`), and its directions resampled by phase function x
guide; its Russian roulette weighs what a path is expected to bring by the
guide's radiance (``IMPORTANCE_ROULETTE_WINDOW``); under hazy air a path leaving the ground
draws its direction from the guide too (``GROUND_GUIDE_PROBABILITY``). For a fixed camera
direction the camera segment's light is traced apart, once per few paths. Its quadrature is
within 1e-4 of a refined one (tests/test_line_integral.py) on clear and hazy skies up to the
horizon, with a low sun's finite disk and at twilight (sun zenith 92-100 deg, where the panels
also split at the points whose rays to the sun graze the profiles' levels); see
``results/groundtruth_speed.md`` for its speed and ``docs/design.md`` for why it is built so.
Scenes with objects use delta tracking.

**Polarization** (``polarized``, opt-in): both estimators then transport Stokes vectors. A path
carries its Mueller matrix as the scalar throughput w, updated exactly as in scalar transport,
times a matrix N with N00 = 1 (:class:`~skyref.plugins.polarization.StokesPath`): each
scattering multiplies it by a rotation and the local phase matrix, a ground reflection
depolarizes, and the sunlight gathered at a vertex or along a segment is mapped by it into the
camera's meridian frame (conventions: :mod:`skyref.plugins.polarization`). Every output then has
a Stokes axis (I, Q, U, V). Scalar renders compile none of it. Validated against MYSTIC on the
IPRT cases (tests/test_iprt.py, ``results/iprt.md``).

The delta-tracking estimator, per camera sample:

* **Wavelengths.** A path carries K channels (indices into the wavelength grid of N values):
  by default K = N, all of them in grid order; with fewer, channel k takes index
  (j + k floor(N/K)) mod N with j uniform, so every wavelength is carried with probability K/N
  and the image estimate divides by that.
* **Free flights: spectral tracking** (Kutz et al. 2017) against a *grey* majorant (the largest
  extinction over the channels; per-channel majorants bias and inflate variance, docs/design.md).
  The majorant is the extinction at the lowest point of the next stretch of the segment (as far
  as the ray descends by the smallest scale height), regenerated after every tentative collision
  and at the end of every stretch, so it follows the density as the ray climbs or comes down
  from high up. At a tentative
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

References
----------
E. R. Woodcock, T. Murphy, P. J. Hemmings and T. C. Longworth, "Techniques used in the GEM code
for Monte Carlo neutronics calculations in reactors and other systems of complex geometry",
ANL-7050 (1965) (delta tracking).

J. Vorba and J. Křivánek, "Adjoint-Driven Russian Roulette and Splitting in Light Transport
Simulation", ACM TOG 35(4) (2016) (the line integral's roulette on a path's expected contribution).

P. Kutz, R. Habel, Y. K. Li and J. Novák, "Spectral and Decomposition Tracking for Rendering
Heterogeneous Volumes", ACM TOG 36(4) (2017) (spectral tracking, history-aware probabilities).

J. Novák, A. Selle and W. Jarosz, "Residual Ratio Tracking for Estimating Attenuation in
Participating Media", ACM TOG 33(6) (2014) (ratio tracking).

E. Veach and L. J. Guibas, "Optimally Combining Sampling Techniques for Monte Carlo Rendering",
SIGGRAPH 1995 (the balance heuristic of the sun lobe's one-sample MIS).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from skyref.atmosphere import wavelength_grid
from skyref.atmosphere.phase import henyey_greenstein_phase, sample_henyey_greenstein_cosine
from skyref.atmosphere.sun import SUN_ANGULAR_RADIUS_DEG, SunDisk
from skyref.errors import ParameterError
from skyref.plugins.drjit_namespace import channel_mean, xp
from skyref.plugins.geometry import PlaneParallelSlab, SphericalShell
from skyref.plugins.guiding import ScatteredLightGuide, guide_channels
from skyref.plugins.kernels import cut_kernel, sum_blocks
from skyref.plugins.line_integral import GreyProxy, LineIntegral, ProxyMixture
from skyref.plugins.optics import AtmosphereOptics, atmosphere_from_property, direction_with_cosine
from skyref.plugins.polarization import STOKES, StokesPath, stokes_times, unpolarized
from skyref.plugins.quadrature import panel_levels
from skyref.plugins.sobol import ScrambledSobolSampler, hash_combine
from skyref.plugins.sun_optical_depth import GreySunDepth, SunOpticalDepth
from skyref.scene import DEFAULT_ESTIMATOR, ESTIMATORS, direction_from_angles
from skyref.sky import ORDER_NAMES
from skyref.validation import check_choice, check_number

__all__ = ["ESTIMATORS", "DEFAULT_ESTIMATOR", "MAX_WAVEFRONT", "MAX_LANE_VALUES", "PathVertex", "RadianceByOrder",
           "PathSegment", "ShadowRay", "SunLight", "AtmosphereIntegrator", "register"]

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

#: The line-integral estimator plays Russian roulette from this many vertices on. Where the
#: guide holds no multiply scattered light (its own pilot; twilight until 2026-12-07), on paths whose largest
#: channel throughput has fallen below LINE_ROULETTE_THROUGHPUT times what it was at the first
#: vertex (survival = the ratio / it). Relative, because the forced collision's weight on the
#: camera segment is that segment's scattering probability: ~1e-4 on a ray up from 50 km, where
#: a roulette on the throughput itself (below 0.1) kept paths with probability ~1e-3 and
#: weighted them 1e3x. Measured 2026-12-06 on the LUT audit's clear twilight skies (sun zenith
#: 92; the 8 darkest views, 32 x 16,384 paths each; the largest and median per-sample relative
#: variance over views and channels x CPU per path, against the absolute threshold): 50 km
#: 280x / 65x less, its estimates' correlation with their own error bars (the adaptive render's
#: stopping bias) 0.84-0.96 -> -0.2..+0.4; 1 km 2.6x / 1.9x; the ground 7x / 1.6x. A clear sky
#: at sun 80 (1 km) is unchanged (its roulette is on the guide's radiance).
LINE_ROULETTE_DEPTH = 2
LINE_ROULETTE_THROUGHPUT = 0.1

#: Elsewhere the roulette weighs what a path is expected to bring (adjoint-driven Russian
#: roulette, Vorba and Křivánek 2016): survival = min(1, w E / (this x E_camera)), with w its
#: largest channel throughput, E the guide's radiance arriving at its vertex along its next
#: direction (:meth:`~skyref.plugins.guiding.GuideAtVertex.radiance`) and E_camera the guide's
#: multiply scattered radiance along the camera ray at its start (what the pixel's orders >= 2
#: are expected to be). A path that strays into dark air ends sooner; one heading up towards
#: the sun from low in the haze goes on. On the hazy sky with a low sun (turbidity 6, sun zenith
#: 88, ground, 17 wavelengths, 7 views) the top 0.1% of paths had carried 40% of the squared
#: contributions at the anti-solar horizon (780 nm), mostly sunlight gathered along a segment
#: within 10 deg of the sun 2-8 km up, by paths that the throughput roulette had kept with
#: probability 1/40 in the median (1/7 to 1/330) and so weighted 40x. Measured 2026-12-05
#: against it (per-sample variance, the views' summed worst channel over 3 seeds, x CPU per
#: path): that sky 2.0x better (23.6 -> 10.4 at +13% CPU; the ground at the observer's feet
#: 13.5 -> 2.2), sunset (sun 88, RGB) 1.8x, hazy sun 60 (RGB) 1.3x, clear sun 60 (RGB) 1.25x,
#: turbidity 6, albedo 1, sun 88.6 (21 wavelengths) 1.2x; windows 0.15 / 0.6 within 10% of 0.3
#: but the clear sky at 0.6 (1.3x worse) and 1.0 / 3.0 worse still. At twilight too since
#: 2026-12-07, with the guide's pilot there (``RESAMPLED_DIRECTIONS_HAZY``); before it, read from
#: single scattering alone, it had lowered the variance 3.6x in the median of 5 seeds but doubled
#: it on one (a heavy tail of paths killed where the table foresaw no light).
IMPORTANCE_ROULETTE_WINDOW = 0.3

#: Points per segment at which a line-integral path's segments after the camera's sample their
#: scattered sunlight (:meth:`LineIntegral.sampled_sunlight`). Clear sky, sun zenith 60 deg, RGB,
#: against 1 point: order-2 noise 0.48% -> 0.36% at 9% more time. Where they are drawn with the
#: sun's transmittance (``SUNLIT_SAMPLING_ZENITH_DEG``) one more is drawn without it.
SAMPLED_SUNLIGHT_POINTS = 4

#: Sun zenith (deg, at the observer) beyond which those points are drawn with the sun's
#: transmittance too (:class:`~skyref.plugins.sun_optical_depth.GreySunDepth`, a second kernel):
#: along a segment rising from low air a low sun's transmittance grows by orders of magnitude,
#: and points drawn by sigma_s T alone find its light rarely. Per-sample variance of orders >= 2
#: (21 wavelengths, worst channel per view) x CPU per path: turbidity 10, sun 89.95: 1.29x
#: better; turbidity 6, albedo 1, sun 88.6: 1.07x; RGB twilight (sun 96) ~1.05x, sunset (88)
#: even; a sun at zenith 52-60 gains nothing and would pay 11-16% more CPU.
SUNLIT_SAMPLING_ZENITH_DEG = 80.0

#: Probability with which a line-integral path scatters into the sun lobe where the local
#: scattering is all by forward-peaked constituents (scaled by their local share). On the hazy sky
#: (turbidity 6, sun zenith 60) a lobe cut the variance of double scattering 4x. Against 0.3 x the
#: aerosols' share of the whole column (RGB, 4096 directions, orders >= 2): per-sample variance
#: 11% lower on the hazy sky, 13% at a hazy sunset (sun 88), the same on clear skies at sun
#: zenith 60, 88 and 96; with the guide's share, the mixture now gives the phase function at least
#: half of the directions, which bounds its MIS weight by 2.
SUN_LOBE_PROBABILITY = 0.2

#: Probability with which a line-integral path leaving the Lambertian ground draws its direction
#: from the guide rather than by the cosine (one-sample MIS, balance heuristic), where the
#: atmosphere's forward-peaked constituents carry at least ``HAZY_FORWARD_SHARE`` of its
#: column's scattering (hazy air) and the ground reflects. There the ground's diffuse light comes
#: largely from the aureole around the sun, which a cosine-drawn direction rarely meets: on the
#: LUT audit's hazy skies (turbidity 6, albedo 0.1) the cosine's single-direction relative
#: variance of the ground's diffuse irradiance is 9.4 at 780 nm with the sun at zenith 80 (0.07 at
#: 380 nm), and the views of the ground from 1 km took 95% of a sky's samples, 780 nm their worst
#: channel. Measured 2026-12-06 (per-sample relative variance of each view's worst channel,
#: summed over 8-10 views, 3 seeds x 65,536 paths, 17 wavelengths): hazy, 1 km, sun 80, views of
#: the ground 30.4 -> 14.0 and of the sky 4.2 -> 3.3; 50 km, sun 80: 18.6 -> 7.8; the ground, sun
#: 80: 12.3 -> 9.2, sun 88: 22.9 -> 15.5; at 2-16% more CPU per path (with 0.3; 0.5 did as well
#: on those views, a Henyey-Greenstein lobe around the sun instead of the guide as well on the 1
#: km sky). On the clear sky (aerosol 5% of the scattering) the guide changed the variance by -2%
#: at +9% CPU: hence the switch. 0.3 -> 0.7 measured 2026-12-07 on what a whole sky costs
#: (`skyref batch --forecast` of the LUT truth's hazy skies still to render, two pilot seeds each,
#: CPU to 0.3% per view): 10 km, sun 60: 858 -> 436 CPU s; 50 km, sun 30: 680 -> 466; 1 km, sun
#: 88: 4048 -> 3103; 10 km, sun 88: 1386 -> 1276; 1 km, sun 92 (twilight): 3643 -> 3725, within
#: its noise. 0.85 did as well as 0.7 (sun 60: 426, sun 88: 3170), 0.5 less (sun 88: 3359).
GROUND_GUIDE_PROBABILITY = 0.7

#: Least share of a column's scattering optical depth (at the guide's wavelengths) carried by
#: forward-peaked constituents for its air to count as hazy (turbidity 2.5 and up; the clear
#: presets' aerosol carries 3-5%): :data:`GROUND_GUIDE_PROBABILITY` applies and paths resample
#: among :data:`RESAMPLED_DIRECTIONS_HAZY` candidates.
HAZY_FORWARD_SHARE = 0.5

#: Probability with which a line-integral path draws its direction from the single-scattering
#: guide (:mod:`skyref.plugins.guiding`) where Rayleigh scattering is all of the local scattering
#: (scaled by its share). RGB, 2048 directions, against no guide: per-sample variance of the
#: radiance 2.2x lower on the clear sky (sun zenith 60 deg), 2.7x at sunset (88 deg), 4.3x at
#: twilight (96 deg), unchanged on the hazy sky (turbidity 6); 0.3 and 0.7 did no better.
GUIDE_PROBABILITY = 0.5

#: Prior probability that a line-integral path draws its directions, from its second vertex on,
#: by the guided mixture (guide, sun lobe, phase function) rather than by the phase function
#: alone; the two are combined by the balance heuristic over the whole path
#: (:class:`PathSampling`). With the mixture at every vertex, a direction the phase function
#: drew weighs phase / pdf up to 1 / (1 - guide - sun lobe probabilities), and along the long
#: paths of hazy air these factors multiply. Per-sample variance of orders >= 2, 2^17-2^19 paths
#: per direction, mixture at every vertex -> this prior: hazy sky (turbidity 6, sun zenith 60,
#: RGB 680 / 550 / 440 nm) 1.96 / 2.30 / 4.72 -> 1.76 / 1.92 / 3.38 at view zenith 85, 1.20 /
#: 0.98 / 1.11 -> 1.04 / 0.86 / 0.99 at 60, the same at the zenith; Hosek training skies at 360 nm
#: (21 wavelengths): turbidity 6, albedo 0, sun zenith 52: 82.6 -> 15.8 (view zenith 85), 3.14 ->
#: 1.95 (60); turbidity 6, albedo 1, sun 88.6: 23.4 -> 11.2 (89), 6.48 -> 2.77 (60); clear and
#: sunset skies within -5..+4%; 0.7 and 0.3 no better. At no extra CPU. Not at twilight
#: (``TWILIGHT_GUIDED_PATH_PRIOR``).
GUIDED_PATH_PRIOR = 0.5

#: The prior where the sun is below the observer's horizon (sun zenith > 90 deg): there the
#: light of every order comes from the lit air low over the sun's azimuth, which the guide aims
#: at, at every vertex. Measured (sun zenith 96, RGB, prior 0.5 against 1): per-sample variance
#: of orders >= 2 at 440 nm 7.4 -> 11.8 at the zenith, 10.4 -> 12.7 at the horizon.
TWILIGHT_GUIDED_PATH_PRIOR = 1.0

#: Candidate directions per scattering event of a line-integral path in hazy air (the column's
#: forward-peaked share at least ``HAZY_FORWARD_SHARE``), resampled by phase function x guide
#: density (:meth:`AtmosphereIntegrator._scatter_direction`), with the guide's table holding
#: multiply scattered light from a pilot (:mod:`skyref.plugins.guiding`). Measured 2026-12-05
#: against one direction and the single-scattering guide, per-sample variance of the radiance (6
#: views, RGB unless said; summed worst channel of the views, what an adaptive render pays), CPU
#: per path: hazy sky (turbidity 6, sun zenith 60), three seeds: 7.07 / 6.66 / 5.74 -> 3.99 / 3.63
#: / 3.32, +32% CPU; turbidity 6, albedo 1, sun 88.6, 21 wavelengths: 17.9 -> 12.1 (mean over
#: channels 1.38 -> 0.69) at the same CPU; sunset (sun 88) 0.83 -> 0.44, +17%; clear (sun 60) 0.13
#: -> 0.11 (mean 0.020 -> 0.013), +31%. 4 candidates: 4.95 against 3.63 on the hazy sky, 16: no
#: better than 8. At twilight it was worse then (28.9 -> 40.3), and twilight kept one direction,
#: the single-scattering guide and the throughput roulette until 2026-12-07; with the estimator
#: of that day the pilot, these directions and the roulette on the guide's radiance pay there
#: too: CPU to 0.3% per view forecast for LUT-audit twilight skies (``skyref batch --forecast``,
#: 17 wavelengths), hazy bruneton2017 from 1 km at sun 92 / 96 2,845 -> 1,520 / 2,611 -> 1,138
#: s, hazy hillaire2020 from 1 / 10 km at sun 92 4,925 -> 2,324 / 2,362 -> 1,866 s, clear skies
#: at sun 92 / 96 from the ground 153 -> 122 / 189 -> 76 s, from 1 km 494 -> 475 / 581 -> 234 s;
#: the speed benchmark's twilight sky (sun 96, 1024 samples per pixel) 283 -> 173 CPU s to 1%
#: in RGB, 480 -> 270 at 17 wavelengths.
RESAMPLED_DIRECTIONS_HAZY = 8

#: Candidate directions where Rayleigh scattering carries most of the column's (clear air, the
#: sunset, twilight). Its paths are short and cheap, so 8 candidates cost more than they
#: save. Measured 2026-12-07 on `results/groundtruth_speed.md`'s skies (128 x 64 pixel centres, 1024
#: samples each, CPU to 1% relative RMS over the sky, two seeds, the batch niced beside it), 8 ->
#: 4 candidates: clear RGB 3.58 -> 2.95 CPU s (1.21x), 17 wavelengths 6.66 -> 5.44 (1.22x), sunset
#: RGB 6.72 -> 5.83 (1.15x); 2 candidates 2.91 (clear) and 6.22 (sunset), one 3.43 (clear). The
#: hazy sky there was within 1.07x either way (79.3 against 84.6 s), the 6 views above favour 8.
RESAMPLED_DIRECTIONS = 4

#: The resampling target's uniform part: phase function x (guide density + this / 4 pi); the
#: guide's density integrates to 1 over the sphere. With the single-scattering guide alone (no
#: pilot), 4 candidates: without it (0) the hazy sky's variance of orders >= 3 doubled (paths sent
#: towards the aureole came back with large weights from elsewhere); 1 and 4 gave -17% and -5% of
#: the total. With the pilot's table, 0.3 (the value measured above).
RESAMPLING_UNIFORM_SHARE = 0.3

#: Paths per coarse cell and layer of the guide's pilot (24 x 162 cells: 250,000 paths, about
#: 1 CPU s in RGB, 9 s with 21 wavelengths). 16 paths per fine cell (20x more) guided no better.
GUIDE_PILOT_SAMPLES = 64

#: The pilot's seed (fixed: the guide, and so a render's paths, depend on the render's seed alone).
GUIDE_PILOT_SEED = 0x2545F491

#: Most samples (lanes) one launch traces: bounds the path state (~100 bytes per sample and
#: channel). Fewer, larger launches pay the Python tracing of the kernel once.
MAX_WAVEFRONT = 1 << 21

#: Most per-sample values (samples x 4 orders x wavelengths) one launch holds before they are
#: summed per target (2^27 float32: 512 MB).
MAX_LANE_VALUES = 1 << 27

#: Offset between the seed of a render's paths and that of its single-scattering launch.
SINGLE_SCATTERING_SEED = 0x9E3779B9


def single_scattering_samples(spp: int) -> int:
    """Samples of the camera segment's light per target and batch, for ``spp`` paths, when the
    camera direction is fixed (only the point in the sun's disk varies): about sqrt(spp) / 2, as
    a power of two (the scrambled Sobol points' balanced counts).

    Why that many: its variance falls about as n^-2.5 in its n points (they integrate a smooth
    function of the 2D disk), the paths' as 1 / spp, so a share of the render's variance that is
    small at a few paths shrinks as spp grows. Measured (512 directions, 16 batches, share of the
    render's relative variance): sunset (sun 88, RGB) at spp 16 and n 2, 3.3% (n 1: 25%); at spp
    256, n 8: 1.4%; twilight (sun 96) 1.6% and 0.5%; clear and hazy skies, and turbidity 3 and 6
    under suns at zenith 88.6-90 at 21 wavelengths, at most 0.4%. At one sample per 8 paths, as
    before, it took 9-16% of a render's CPU (clear and sunset RGB, 21 wavelengths)."""
    return 1 << max(0, round(math.log2(math.sqrt(max(spp, 1)) / 2.0)))


class PathVertex:
    """A path between two events, as both estimators carry it: its vertex (``point`` in the
    observer frame and its ``altitude``, m), the unit ``direction`` it leaves in, its
    ``throughput`` per channel, the scattering and ground events so far (``depth``) and whether it
    is still traced (``alive``)."""

    DRJIT_STRUCT = {"point": mi.Point3f, "altitude": mi.Float, "direction": mi.Vector3f,
                    "throughput": mi.ArrayXf, "depth": mi.UInt32, "alive": mi.Bool}

    def __init__(self, point=None, altitude=None, direction=None, throughput=None, depth=None, alive=None):
        self.point, self.altitude, self.direction = point, altitude, direction
        self.throughput, self.depth, self.alive = throughput, depth, alive


class PathSampling:
    """What a line-integral path remembers of how it was sampled, from its second vertex on, for
    the balance heuristic over the whole path: the posterior probabilities of the forced
    collisions' two proxies (``proxy_weights``, :class:`ProxyMixture`) and the posterior
    probability that its directions were drawn by the guided mixture rather than by the phase
    function alone (``guided``, :meth:`AtmosphereIntegrator._scatter_direction`)."""

    DRJIT_STRUCT = {"proxy_weights": mi.ArrayXf, "guided": mi.Float}

    def __init__(self, proxy_weights=None, guided=None):
        self.proxy_weights, self.guided = proxy_weights, guided


class RadianceByOrder:
    """The radiance a camera sample has gathered so far, per channel and scattering order
    (``ORDER_NAMES``): ``direct`` (the solar disk seen through the atmosphere), ``single``,
    ``double`` and ``higher`` (3 or more events), in W m^-2 sr^-1 nm^-1."""

    DRJIT_STRUCT = {"direct": mi.ArrayXf, "single": mi.ArrayXf, "double": mi.ArrayXf, "higher": mi.ArrayXf}

    def __init__(self, direct=None, single=None, double=None, higher=None):
        self.direct, self.single, self.double, self.higher = direct, single, double, higher

    @staticmethod
    def zeros(channels, stokes: int = 1):
        """Nothing gathered yet: K values (:class:`PathChannels` ``channels``) for the solar disk
        (unpolarized), and ``stokes`` x K for each scattering order (radiance, or I, Q, U, V)."""
        return RadianceByOrder(channels.zeros(), channels.zeros(stokes), channels.zeros(stokes),
                               channels.zeros(stokes))

    def file(self, order, light, active, multiple_only=False):
        """Add ``light`` under scattering order ``order`` (1, 2, or 3 and more) where ``active``;
        ``multiple_only``: the caller knows the order is at least 2 (the single-scattering values
        are then left out of the arithmetic, and of a loop's updated state)."""
        if not multiple_only:
            self.single = dr.select(active & (order == 1), self.single + light, self.single)
        self.double = dr.select(active & (order == 2), self.double + light, self.double)
        self.higher = dr.select(active & (order >= 3), self.higher + light, self.higher)

    def by_order(self) -> list:
        """The four orders in ``ORDER_NAMES`` order."""
        return [self.direct, self.single, self.double, self.higher]


class PathSegment:
    """The free segment a delta-tracking path is on (:meth:`AtmosphereIntegrator._segment`):
    the distance left to its end (m), whether it ends on a surface (the ground or an object), the
    altitude at its end (m; exact for the ground and the top), and, for an object, its normal
    (facing the ray) and grey albedo."""

    DRJIT_STRUCT = {"remaining": mi.Float, "on_surface": mi.Bool, "h_end": mi.Float, "on_object": mi.Bool,
                    "object_normal": mi.Vector3f, "object_albedo": mi.Float}

    def __init__(self, remaining=None, on_surface=None, h_end=None, on_object=None, object_normal=None,
                 object_albedo=None):
        self.remaining, self.on_surface, self.h_end = remaining, on_surface, h_end
        self.on_object, self.object_normal, self.object_albedo = on_object, object_normal, object_albedo


class ShadowRay:
    """A delta-tracking lane's shadow ray towards the sun (one in flight at a time): whether one
    is in flight, its point, altitude (m) and direction, the distance left to the top of the
    atmosphere (m), its transmittance so far (ratio tracking, per channel), what it carries (the
    vertex's throughput x response x E_sun, per channel) and the order it is filed under."""

    DRJIT_STRUCT = {"active": mi.Bool, "point": mi.Point3f, "altitude": mi.Float, "direction": mi.Vector3f,
                    "remaining": mi.Float, "transmittance": mi.ArrayXf, "pending": mi.ArrayXf, "order": mi.UInt32}

    def __init__(self, active=None, point=None, altitude=None, direction=None, remaining=None,
                 transmittance=None, pending=None, order=None):
        self.active, self.point, self.altitude, self.direction = active, point, altitude, direction
        self.remaining, self.transmittance, self.pending, self.order = remaining, transmittance, pending, order


class SunLight:
    """The solar disk (:class:`~skyref.atmosphere.sun.SunDisk`) around ``direction`` (unit,
    towards the sun) in kernels: its irradiance per grid wavelength (W m^-2 nm^-1) and the
    sampling of directions inside it."""

    def __init__(self, direction, disk: SunDisk, wavelengths_nm):
        # Opaque: skies that differ only in the sun's position share compiled kernels.
        self.direction = mi.Vector3f(*[dr.opaque(mi.Float, float(x)) for x in direction])
        self.disk = disk
        self.irradiance = mi.Float(np.asarray(disk.irradiance(wavelengths_nm), np.float32))
        self.frame = mi.Frame3f(self.direction)
        # evaluated now: left as an expression, the first render would evaluate it and the
        # second compile every kernel again
        dr.make_opaque(self.frame)

    def radiance_factor(self, cos_angle):
        """Radiance of the disk at angle acos(cos_angle) from its centre, divided by its mean
        (1 everywhere without limb darkening); 0 outside the disk."""
        return self.disk.radiance_factor(cos_angle, xp)

    def channel_irradiance(self, indices):
        return mi.ArrayXf([dr.gather(mi.Float, self.irradiance, i) for i in indices])

    def sample_direction(self, u):
        """A direction uniformly distributed (in solid angle) inside the disk; returns it with
        the factor by which E_sun must be multiplied (the limb-darkening ratio)."""
        local = mi.warp.square_to_uniform_cone(u, self.disk.cos_radius)
        # No inside test here: in float32, cos(radius) ~ 1 - 1e-5 is resolved to ~1/180 of the
        # cone, and a sampled direction must never be rejected by rounding.
        return self.frame.to_world(local), self.disk.limb_darkening_factor(local.z, xp)


def _target_table(values: np.ndarray) -> np.ndarray:
    """Per-target values (first axis: targets) for a kernel to gather by target, at least two
    rows long: Dr.Jit reads a one-entry array as a scalar, which makes another variant of the
    path tracer to compile (the last rounds of an adaptive render often have one pixel left)."""
    return np.concatenate([values, values[:1]]) if len(values) == 1 else values


class AtmosphereIntegrator(mi.SamplingIntegrator):
    """Mitsuba plugin ``atmosphere``. Properties (all optional):

    ``atmosphere`` (string: a preset name or the JSON of ``Atmosphere.to_dict()``;
    default ``bruneton2017``), ``wavelengths`` (string: comma-separated nm, or ``rgb``),
    ``sun_zenith``/``sun_azimuth`` (degrees), ``sun_angular_radius`` (degrees),
    ``limb_darkening`` (bool), ``observer_altitude`` (m), ``geometry`` (``spherical`` or
    ``plane_parallel``), ``polarized`` (bool: Stokes vectors, :mod:`skyref.plugins.polarization`),
    ``max_depth`` (int), ``wavelengths_per_path`` (int, default: all N; fewer
    channels per path are cheaper per sample but noisier per wavelength — on the 48-wavelength
    default sky, carrying all of them was 3x more efficient than 16).

    From Python, :meth:`configure` sets the same things from skyref objects.
    """

    def __init__(self, props=mi.Properties()):
        super().__init__(props)
        atmosphere = atmosphere_from_property(props.get("atmosphere", "bruneton2017"))
        wavelengths = props.get("wavelengths", "rgb")
        grid = wavelength_grid("rgb" if wavelengths == "rgb" else [float(x) for x in wavelengths.split(",")])
        self.configure(atmosphere, grid, sun_zenith_deg=props.get("sun_zenith", 30.0),
                       sun_azimuth_deg=props.get("sun_azimuth", 180.0),
                       sun_angular_radius_deg=props.get("sun_angular_radius", SUN_ANGULAR_RADIUS_DEG),
                       limb_darkening=props.get("limb_darkening", False),
                       observer_altitude_m=props.get("observer_altitude", 0.0),
                       geometry=props.get("geometry", "spherical"),
                       max_depth=props.get("max_depth", 64),
                       wavelengths_per_path=props.get("wavelengths_per_path", 0),
                       estimator=props.get("estimator", DEFAULT_ESTIMATOR),
                       polarized=props.get("polarized", False))

    def configure(self, atmosphere, wavelengths_nm, sun_zenith_deg, sun_azimuth_deg,
                  sun_angular_radius_deg, limb_darkening=False, observer_altitude_m=0.0,
                  geometry="spherical", max_depth=64, wavelengths_per_path=0, estimator=DEFAULT_ESTIMATOR,
                  polarized=False):
        """Set the atmosphere, wavelength grid (nm), sun, observer and estimator settings."""
        check_choice("geometry", geometry, ("spherical", "plane_parallel"))
        self.estimator = check_choice("estimator", estimator, ESTIMATORS)
        self.polarized = bool(check_choice("polarized", polarized, (False, True)))
        #: Values per channel in every output: the Stokes components I, Q, U, V, or radiance.
        self.stokes = len(STOKES) if self.polarized else 1
        self.optics = AtmosphereOptics(atmosphere, wavelengths_nm)
        self.wavelengths_nm = self.optics.wavelengths_nm
        n = len(self.wavelengths_nm)
        k = int(wavelengths_per_path) or n
        if not 1 <= k <= n:
            raise ParameterError("wavelengths_per_path", wavelengths_per_path, f"an integer in [1, {n}]")
        self.channels = k
        self.max_depth = int(check_number("max_depth", max_depth, 1, 100_000))
        h0 = check_number("observer_altitude_m", observer_altitude_m, 0.0, 1.0e8)
        if geometry == "spherical":
            self.geometry = SphericalShell(atmosphere.bottom_radius_m, atmosphere.top_radius_m, h0)
        else:
            self.geometry = PlaneParallelSlab(atmosphere.thickness_m, h0)
        self.sun = SunLight(direction_from_angles(sun_zenith_deg, sun_azimuth_deg),
                            SunDisk(sun_angular_radius_deg, bool(limb_darkening)), self.wavelengths_nm)
        # a literal in the kernels (a new aerosol g compiles them again): an opaque copy, read
        # inside the path's symbolic loop, broke forward-mode AD through it (Dr.Jit 1.5:
        # "derivatives across an edge outside of the current dr.isolate_grad() scope")
        self.sun_lobe_g = self._sun_lobe_g(atmosphere)
        #: The sun below the observer's horizon: the light of every order comes from the lit air
        #: low over the sun's azimuth, and the line integral's paths sample for it
        #: (``TWILIGHT_GUIDED_PATH_PRIOR``, no proxy mixture on the camera segment).
        self.twilight = sun_zenith_deg > 90.0
        #: Altitude over which one majorant of the delta tracking holds (the smallest scale height
        #: of an exponential profile; inf: the whole segment).
        self.majorant_drop = min((float(c.profile.scale_height_m) for c in atmosphere.constituents
                                  if c.profile.kind == "exponential"), default=math.inf)
        #: Optional Mitsuba scene whose shapes stand in the atmosphere (terrain, buildings):
        #: Lambertian, grey albedo = the mean of their BSDF's diffuse reflectance. Objects are
        #: traced by the delta-tracking estimator (the line integral assumes open sky).
        self.objects = None
        #: Candidate directions per scattering event of a line-integral path
        #: (:meth:`_scatter_direction`): ``RESAMPLED_DIRECTIONS`` (``_HAZY`` in hazy air); 1 for
        #: single scattering alone (no guide).
        self.resampled_directions = 1
        #: Whether a line-integral path leaving the ground may draw its direction from the guide
        #: (:meth:`_reflect_direction`).
        self.ground_guided = False
        if self.estimator == "line_integral":
            levels = panel_levels(atmosphere)
            sun_depth = SunOpticalDepth(atmosphere, self.geometry)
            self.line = LineIntegral(self.optics, self.geometry, sun_depth, levels, polarized=self.polarized,
                                     grazing_levels=levels if self.geometry.sun_can_graze(sun_zenith_deg) else (),
                                     sunlit_sampling=self._sunlit_sampling(atmosphere, sun_depth, sun_zenith_deg))
            # paths turn at scattering events only with max_depth > 1 (single scattering alone
            # needs no guide: 0.3 s of CPU and, per atmosphere, a compile of 20-55 s saved)
            self.guide = (ScatteredLightGuide(self.line, self.geometry, self.sun, self.wavelengths_nm)
                          if self.max_depth > 1 else None)
            hazy = self._forward_scattering_share(atmosphere) >= HAZY_FORWARD_SHARE
            if self.guide is not None:
                self._guide_multiple_scattering()
                self.resampled_directions = RESAMPLED_DIRECTIONS_HAZY if hazy else RESAMPLED_DIRECTIONS
            reflects = bool(np.any(atmosphere.ground_albedo(self.wavelengths_nm) > 0.0))
            self.ground_guided = self.guide is not None and reflects and hazy

    def _guide_multiple_scattering(self):
        """The guide's pilot (:mod:`skyref.plugins.guiding`): orders >= 2 traced from its layers
        along :meth:`~skyref.plugins.guiding.ScatteredLightGuide.pilot_directions`,
        ``GUIDE_PILOT_SAMPLES`` paths each with the single-scattering guide, added to its table.
        Its seed is fixed: a render's estimate stays a function of its own seed."""
        altitudes, directions = self.guide.pilot_directions()
        cells = directions.shape[0]
        origins = _target_table(np.repeat(altitudes, cells).astype(np.float32))
        directions = _target_table(np.tile(directions, (altitudes.size, 1)).astype(np.float32))
        altitude_table = mi.Float(origins)
        direction_table = mi.Vector3f(*(mi.Float(column) for column in directions.T))

        def pilot_rays(sampler, target):
            origin = self.geometry.above_observer(dr.gather(mi.Float, altitude_table, target))
            return origin, dr.gather(mi.Vector3f, direction_table, target), mi.Bool(True)

        image = self._launches(GUIDE_PILOT_SEED, altitudes.size * cells, GUIDE_PILOT_SAMPLES, 1, pilot_rays,
                               "multiple", from_observer=False)
        image = image.numpy().reshape(altitudes.size * cells, len(ORDER_NAMES), self.stokes * len(self.wavelengths_nm))
        # radiance, or I (the first of the Stokes components)
        multiple = image[:, ORDER_NAMES.index("double"):, self.guide.channels].sum(axis=1).mean(axis=1)
        self.guide.add_multiple_scattering(multiple.reshape(altitudes.size, cells))

    def _sunlit_sampling(self, atmosphere, sun_depth, sun_zenith_deg):
        """The :class:`GreySunDepth` of the most transparent channel (the smallest extinction of
        each constituent over the wavelength grid) that draws the sampled sunlight's points, for
        a sun beyond ``SUNLIT_SAMPLING_ZENITH_DEG``; else None. Fixed at construction: parameters
        changed later only make it a less apt sampling density."""
        if sun_zenith_deg <= SUNLIT_SAMPLING_ZENITH_DEG:
            return None
        wavelengths = self.optics.wavelengths_nm
        least = [float(np.min(c.extinction_coefficient(wavelengths))) for c in atmosphere.constituents]
        return GreySunDepth(sun_depth, least)

    def _forward_scattering_share(self, atmosphere) -> float:
        """The share of the column's scattering optical depth, at the guide's wavelengths, that
        forward-peaked constituents (aerosols) carry."""
        wavelengths = [self.wavelengths_nm[k] for k in guide_channels(self.wavelengths_nm)]
        scatterers = [c for c in atmosphere.constituents if c.phase is not None]
        depth = [float(np.mean(atmosphere.constituent_optical_depth(c, wavelengths, coefficient="scattering")))
                 for c in scatterers]
        forward = sum(tau for c, tau in zip(scatterers, depth) if c.phase.has_forward_peak)
        return forward / max(sum(depth), 1e-30)

    @staticmethod
    def _sun_lobe_g(atmosphere) -> float:
        """The line integral's sun lobe (:meth:`_scatter_direction`): as peaked as the most
        peaked forward-scattering constituent's sampling density; 0 (no lobe) where none scatters
        forwards (a Rayleigh sky has no forward peak to aim at)."""
        return max((c.phase.sampling_g for c in atmosphere.constituents
                    if c.phase is not None and c.phase.has_forward_peak), default=0.0)

    # --- Mitsuba plumbing ---------------------------------------------------------------------

    def traverse(self, callback):
        for name, value in self.optics.parameters().items():
            callback.put(name, value, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys=[]):
        pass

    def sample(self, scene, sampler, ray, medium=None, active=True):
        """Mitsuba's per-ray entry point, so that ``mi.render`` works in RGB variants with the
        "rgb" grid (channels 680/550/440 nm become R, G, B). skyref itself renders any
        wavelength grid through :meth:`render_orders`. The scene's shapes, if any, are the
        objects (:meth:`scene_objects`) of this render."""
        if dr.size_v(mi.Spectrum) != 3 or len(self.wavelengths_nm) != 3 or self.polarized:
            raise RuntimeError("the atmosphere integrator renders through mi.render only in RGB "
                               "variants with wavelengths='rgb', unpolarized; use skyref.render_sky otherwise")
        indices = [mi.UInt32(i) for i in range(3)]
        objects = self.objects
        self.objects = self.scene_objects(scene) if scene is not None and scene.shapes() else objects
        if self.estimator == "line_integral" and self.objects is None:
            # its path loop draws every decision from a dimension of its own (plugins/sobol.py);
            # Mitsuba's sampler picks a random scramble per camera sample (48 random bits), so
            # the decisions are independent uniform numbers
            bits = [mi.UInt32(sampler.next_1d(active) * 16777216.0) for _ in range(2)]
            sampler = ScrambledSobolSampler(0, hash_combine(bits[0], bits[1]))
        try:
            orders = self.trace(sampler, ray.o, ray.d, indices, mi.Bool(active))
        finally:
            self.objects = objects
        total = orders[0] + orders[1] + orders[2] + orders[3]
        return mi.Spectrum(total[0], total[1], total[2]), mi.Bool(active), []

    @staticmethod
    def scene_objects(scene):
        """``scene`` as :attr:`objects`, once each of its shapes is checked: a ``diffuse`` BSDF
        (grey: the mean of its reflectance over the channels; both sides reflect), no area
        emitter, no medium; in the observer's east-north-up frame, m. Anything else raises a
        ParameterError naming the shape."""
        for shape in scene.shapes():
            bsdf = shape.bsdf().class_name()
            problem = ("an area emitter" if shape.is_emitter() else
                       "a medium" if shape.interior_medium() is not None or shape.exterior_medium() is not None else
                       f"a {bsdf} BSDF" if bsdf != "SmoothDiffuse" else "")
            if problem:
                raise ParameterError(f"shape {shape.id()!r}", shape.class_name(),
                                     "shapes with a 'diffuse' BSDF, no emitter and no medium "
                                     "(the atmosphere integrator's objects are grey Lambertian)", f"has {problem}")
        return scene

    # --- rendering ----------------------------------------------------------------------------

    def render_orders(self, sensor, seed: int, spp: int, pixel_centres: bool = False, batches: int = 1,
                      progress=None, pixels=None) -> mi.TensorXf:
        """Render through a Mitsuba sensor: a tensor (H, W, 4, N) of radiance per pixel,
        scattering order (``ORDER_NAMES``) and grid wavelength, W m^-2 sr^-1 nm^-1, from ``spp``
        samples per pixel; with ``batches`` > 1, (batches, H, W, 4, N) from as many independent
        batches of ``spp`` samples, traced together. Samples cover each pixel uniformly, or look
        along its centre only (``pixel_centres``). With ``pixels`` (flat indices row * W +
        column), only those pixels are traced, and the tensor is (M, 4, N) (or (batches, M, 4,
        N)) in their order. The samples are traced in launches of bounded size
        (:meth:`launch_sizes`); ``progress``, if given, is called with the samples per pixel and
        batch of each launch when it is done."""
        width, height = (int(x) for x in sensor.film().crop_size())
        every_pixel = pixels is None
        pixels = np.arange(width * height) if every_pixel else np.asarray(pixels).reshape(-1)
        if pixels.size and not 0 <= pixels.min() <= pixels.max() < width * height:
            raise ParameterError("pixels", f"[{pixels.min()}, {pixels.max()}]", f"indices in [0, {width * height})",
                                 "outside the sensor's film")
        # Gathered by target even when every pixel is traced: one kernel for both cases.
        table = mi.UInt32(_target_table(pixels.astype(np.uint32)))

        def camera_rays(sampler, target):
            pixel = dr.gather(mi.UInt32, table, target)
            offset = mi.Vector2f(0.5) if pixel_centres else sampler.next_2d()
            position = mi.Vector2f(mi.Float(pixel % width), mi.Float(pixel // width)) + offset
            film_uv = position * mi.Vector2f(1.0 / width, 1.0 / height)
            ray, weight = sensor.sample_ray(time=0.0, sample1=sampler.next_1d(), sample2=film_uv,
                                            sample3=sampler.next_2d(), active=True)
            return ray.o, ray.d, dr.max(mi.Spectrum(weight), axis=0) > 0.0

        image = self._estimate(seed, pixels.size, spp, batches, camera_rays, pixel_centres, progress)
        return self._tensor(image, batches, (height, width) if every_pixel else (pixels.size,))

    def render_directions(self, directions, seed: int, spp: int, batches: int = 1, orders: str = "all") -> mi.TensorXf:
        """Radiance seen from the observer along given unit directions (array (M, 3), east-north-
        up): a tensor (M, 4, N) like :meth:`render_orders` (or (batches, M, 4, N)), without a
        sensor or pixel filter. ``orders="single"`` (line-integral estimator): the camera
        segment's light alone, the solar disk and single scattering (orders 2 and 3+ are 0), with
        ``spp`` points in the sun's disk."""
        check_choice("orders", orders, ("all", "single"))
        if orders == "single" and self.estimator != "line_integral":
            raise ParameterError("orders", orders, "'all' with the delta_tracking estimator",
                                 "single scattering alone is traced apart by the line_integral estimator only")
        directions = np.asarray(directions, dtype=np.float32).reshape(-1, 3)
        table = mi.Vector3f(*(mi.Float(column) for column in _target_table(directions).T))

        def camera_rays(sampler, target):
            return mi.Point3f(0.0), dr.gather(mi.Vector3f, table, target), mi.Bool(True)

        if orders == "single":
            image = self._launches(seed, directions.shape[0], spp, batches, camera_rays, "single")
        else:
            image = self._estimate(seed, directions.shape[0], spp, batches, camera_rays, True)
        return self._tensor(image, batches, (directions.shape[0],))

    def _tensor(self, image, batches, shape):
        stokes = (self.stokes,) if self.polarized else ()
        shape = (*shape, len(ORDER_NAMES), *stokes, len(self.wavelengths_nm))
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

    def _wavefront(self, seed, targets, spp, batches, sample_offset=0):
        """A sampler for ``targets * spp * batches`` samples, and each sample's target and batch
        index. Sample s of a target and batch is number ``sample_offset + s`` of its sequence, so
        that a render split into launches continues its sequences. The line-integral estimator
        draws Owen-scrambled Sobol points (:mod:`skyref.plugins.sobol`), scrambled per target and
        batch; delta tracking, independent numbers. The seed and counts are opaque: calls with
        other seeds or sample counts reuse the compiled kernels (the line-integral estimator's
        take seconds to compile)."""
        wavefront = targets * spp * batches
        # Lanes in the order (batch, target, sample): a target's samples of one batch are
        # contiguous, so that :meth:`_launch` sums them block by block, in a fixed order.
        index = dr.arange(mi.UInt32, wavefront)
        batch = index // dr.opaque(mi.UInt32, targets * spp)
        target = index // dr.opaque(mi.UInt32, spp) % dr.opaque(mi.UInt32, targets)
        if self.estimator == "line_integral":
            sample = index % dr.opaque(mi.UInt32, spp)
            scramble = hash_combine(hash_combine(dr.opaque(mi.UInt32, seed), target), batch)
            return ScrambledSobolSampler(sample + dr.opaque(mi.UInt32, sample_offset), scramble), target, batch
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(dr.opaque(mi.UInt32, (seed * 0x9E3779B1 + sample_offset * 0x85EBCA77) % (1 << 32)), wavefront)
        return sampler, target, batch

    def _estimate(self, seed, targets, spp, batches, camera_rays, fixed_directions, progress=None):
        """The flat (batches, targets, 4, N) radiance buffer from ``spp`` samples per target and
        batch; ``camera_rays(sampler, target)`` gives each sample's (origin, direction, valid).

        With the line-integral estimator and ``fixed_directions`` (one direction per target), the
        camera segment's light (solar disk, single scattering) depends only on the point drawn
        in the sun's disk: it is traced in its own launches, :func:`single_scattering_samples`
        per target and batch, and the ``spp`` paths carry orders >= 2 only."""
        if self.estimator != "line_integral" or self.objects is not None or not fixed_directions:
            return self._launches(seed, targets, spp, batches, camera_rays, "all", progress)
        image = self._launches(seed, targets, spp, batches, camera_rays, "multiple", progress)
        image += self._launches((seed + SINGLE_SCATTERING_SEED) % (1 << 32), targets,
                                single_scattering_samples(spp), batches, camera_rays, "single")
        return image

    def launch_sizes(self, targets: int, spp: int, batches: int = 1) -> list:
        """How ``spp`` samples per target and batch are split into launches: the samples per
        target and batch of each, so that a launch traces at most MAX_WAVEFRONT samples and holds
        at most MAX_LANE_VALUES per-sample values (4 orders x N wavelengths each)."""
        lanes = targets * batches
        step = max(1, min(spp, MAX_WAVEFRONT // lanes,
                          MAX_LANE_VALUES // (lanes * len(ORDER_NAMES) * self.stokes * len(self.wavelengths_nm))))
        return [min(step, spp - done) for done in range(0, spp, step)]

    def _launches(self, seed, targets, spp, batches, camera_rays, orders, progress=None, from_observer=True):
        """:meth:`_launch` in the pieces of :meth:`launch_sizes`, each continuing the samples'
        sequences where the one before stopped, combined by their sample counts."""
        image, done = None, 0
        for count in self.launch_sizes(targets, spp, batches):
            part = self._launch(seed, targets, count, batches, camera_rays, orders, done, from_observer)
            part = part * (count / spp) if count < spp else part
            image = part if image is None else image + part
            done += count
            if progress is not None:
                progress(count)
        return image

    def _launch(self, seed, targets, spp, batches, camera_rays, orders, sample_offset, from_observer=True):
        """Trace one sample per lane (the ``orders`` of :meth:`trace`, ``from_observer`` or not)
        and average into a flat (batches, targets, 4, N) buffer.

        With every wavelength on every path (the default), each target's samples are summed in
        blocks, in a fixed order, so the same seed gives the same bits. With fewer wavelengths
        per path the samples of a target carry different wavelengths and are added atomically
        (the last bits of a sum may then differ between runs)."""
        sampler, target, batch = self._wavefront(seed, targets, spp, batches, sample_offset)
        origin, direction, valid = camera_rays(sampler, target)
        n = len(self.wavelengths_nm)
        # Wavelength channels: all of them in grid order, or index (j + k * stride) mod N with j
        # uniform, each grid wavelength carried with probability K / N.
        if self.channels == n:
            indices = [mi.UInt32(k) for k in range(n)]
        else:
            stride = n // self.channels
            first = dr.minimum(mi.UInt32(sampler.next_1d() * n), n - 1)
            indices = [(first + k * stride) % n for k in range(self.channels)]
        contributions = self.trace(sampler, mi.Point3f(origin), mi.Vector3f(direction), indices, valid, orders,
                                   from_observer)
        scale = dr.opaque(mi.Float, n / (self.channels * spp))
        values_per_order = self.stokes * n                    # (Stokes component, wavelength)
        size = batches * targets * len(ORDER_NAMES) * values_per_order
        if self.channels == n:
            # Each target's samples are contiguous lanes (batch, target, sample): sum them block by
            # block, in a fixed order, into the (batch, target, order, channel) layout, with one
            # path-tracer kernel for all the values (and one for all their tangents).
            group = dr.arange(mi.UInt32, batches * targets)
            values, slots = [], []
            for order, contribution in enumerate(contributions):
                for k, value in enumerate(contribution):
                    values.append(dr.select(valid, value * scale, 0.0))
                    slots.append((group * len(ORDER_NAMES) + order) * values_per_order + k)
            return sum_blocks(values, spp, slots, size)
        image = dr.zeros(mi.Float, size)
        for order, contribution in enumerate(contributions):
            for k, index in enumerate(indices * self.stokes):
                component = k // self.channels
                slot = ((batch * targets + target) * len(ORDER_NAMES) + order) * values_per_order + component * n + index
                # A fixed reduction mode: "Auto" picks one by the buffer's size, and each new
                # choice compiles the whole path tracer again.
                dr.scatter_reduce(dr.ReduceOp.Add, image, contribution[k] * scale, slot, valid,
                                  mode=dr.ReduceMode.Local)
        return image

    # --- the path tracer ------------------------------------------------------------------------

    def _segment(self, p, d, h):
        """The free segment from p along d, as a :class:`PathSegment`."""
        geometry = self.geometry
        t_ground = geometry.distance_to_ground(p, d, h)
        t_top = geometry.distance_to_top(p, d, h)
        on_ground = t_ground < t_top
        length = dr.select(on_ground, t_ground, t_top)
        h_end = dr.select(on_ground, 0.0, geometry.H)
        if dr.hint(self.objects is None, mode="scalar"):
            return PathSegment(length, on_ground, h_end, mi.Bool(False), mi.Vector3f(0.0), mi.Float(0.0))
        si = self.objects.ray_intersect(mi.Ray3f(p, d, length))
        on_object = si.is_valid() & (si.t < length)
        normal = dr.select(dr.dot(si.n, d) > 0.0, -si.n, si.n)
        albedo = channel_mean(mi.Spectrum(si.bsdf().eval_diffuse_reflectance(si, on_object)))
        length = dr.select(on_object, si.t, length)
        h_end = dr.select(on_object, geometry.altitude(p + length * d), h_end)
        return PathSegment(length, on_ground | on_object, h_end, on_object, normal, albedo)

    def _majorant_stretch(self, p, d, length, h, h_end):
        """How far along the segment (length ``length``, altitudes ``h`` at its start and ``h_end``
        at its end) one majorant holds: to where the ray has descended ``majorant_drop``, or
        the whole segment if it never descends that far. Returns (distance, altitude there)."""
        if self.majorant_drop == math.inf:
            return length, h_end
        down, up = self.geometry.level_crossings(p, d, h, h - self.majorant_drop)
        crosses = (down < up) & (down > 0.0) & (down < length)
        return dr.select(crosses, down, length), dr.select(crosses, h - self.majorant_drop, h_end)

    def _majorant(self, channels, p, d, length, h, h_end):
        h_low = self.geometry.lowest_altitude(p, d, length, h, h_end)
        return MAJORANT_SAFETY * self.optics.majorant(channels, h_low, dr.maximum(h, h_end))

    def trace(self, sampler, origin, direction, indices, active, orders="all", from_observer=True):
        """Radiance along camera rays (origin in the observer frame, unit direction) for the
        channels ``indices``: a list of 4 ArrayXf (K channels), one per scattering order
        (``ORDER_NAMES``), by the configured estimator. ``orders`` (line integral only):
        ``"all"``, ``"single"`` or ``"multiple"`` (see :meth:`_trace_line_integral`).
        ``from_observer`` False: the rays start anywhere in the air (the guide's pilot)."""
        if self.estimator == "line_integral" and self.objects is None:
            return self._trace_line_integral(sampler, origin, direction, indices, active, orders, from_observer)
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
        return self.sun.radiance_factor(dr.dot(d, self.sun.direction)) / self.sun.disk.solid_angle_sr

    def _trace_line_integral(self, sampler, origin, direction, indices, active, orders="all", from_observer=True):
        """The line-integral estimator (:mod:`skyref.plugins.line_integral`). One loop iteration
        is one segment of the path: the sunlight scattered once along it (by quadrature on the
        camera segment, sampled at a few points on later ones) is filed under the order
        (vertices so far) + 1, as is the sunlight the ground reflects at its end; the path then
        goes on from a forced collision on the segment (or from the ground), with Russian
        roulette from ``LINE_ROULETTE_DEPTH`` vertices on.
        Camera rays from an observer on the ground only rise, so their segment is peeled off
        the loop with the cheaper rising-only panels.

        ``orders``: ``"all"``; ``"single"``, the light of the camera segment alone (the solar
        disk and single scattering; no path goes on); or ``"multiple"``, orders >= 2 alone (the
        camera segment only places the forced collision). For a fixed camera direction the
        first is deterministic but for the sun's disk, so :meth:`_estimate` traces it once per
        few samples of the second. ``from_observer`` False: the rays start anywhere in the air, not
        at the observer (whose rays only rise where the observer stands on the ground)."""
        channels = self.optics.channel_coefficients(indices)
        e_sun = self.sun.channel_irradiance(indices)
        d = mi.Vector3f(direction)
        p, h, misses = self._enter_atmosphere(origin, d, active)
        radiance = RadianceByOrder.zeros(channels, self.stokes)
        if orders != "multiple":
            radiance.direct = dr.select(misses, e_sun * self._solar_disk(d), radiance.direct)
        camera = PathVertex(p, h, d, channels.zeros() + 1.0, mi.UInt32(0), mi.Bool(active) & ~misses)
        # Polarized: the path's Mueller matrix (w N, polarization.py) starts in the camera's frame.
        stokes = StokesPath.camera(d, self.geometry.up(mi.Point3f(origin)), channels.count) if self.polarized else None

        goes_on = orders != "single" and self.max_depth > 1
        # Where the camera segment only places the first vertex (its light traced apart), the
        # proxy mixture draws it too (its quadrature would need both proxies at every node), but
        # at twilight: there the red light comes from the lit air far along the ray, where the
        # opaque proxy does not go. Hazy sky (turbidity 6, sun 60, RGB, 2^18 paths) at view
        # zenith 85-89, per-sample variance of orders >= 2, grey proxy -> mixture: 440 nm 2.47
        # -> 1.94, 680 nm 1.73 -> 1.86 and 1.85 -> 2.29; clear sky 440 nm 0.138 -> 0.052;
        # twilight (sun 96) 680 nm 1.42 -> 2.84 and 4.96 -> 9.79.
        first_vertex_mixed = orders == "multiple" and not self.twilight
        sampling = PathSampling(ProxyMixture.prior(), mi.Float(1.0)) if first_vertex_mixed else None
        light, sun_disk, path, stokes, sampling = self._line_segment(
            sampler, channels, e_sun, camera, stokes, camera=True, rising_only=from_observer and self.geometry.h0 == 0.0,
            sunlight=None if orders == "multiple" else "quadrature", goes_on=goes_on, sampling=sampling)
        radiance.direct += sun_disk
        radiance.single += light
        if goes_on:
            proxy_weights = ProxyMixture.prior() if sampling is None else sampling.proxy_weights
            # what the path's orders >= 2 are expected to bring, for the roulette
            expected = (None if self.guide.multiple is None
                        else self.guide.at(self.geometry.up(p), h).radiance(d, multiple_only=True))
            # the camera segment and the path's later segments compile as two kernels
            cut_kernel(radiance, path, stokes, proxy_weights, expected)
            self._scattered_light(sampler, channels, e_sun, path, stokes, radiance, proxy_weights, expected)
        orders = radiance.by_order()
        # the solar disk seen through the atmosphere is unpolarized
        return [unpolarized(orders[0]), *orders[1:]] if self.polarized else orders

    @dr.syntax
    def _scattered_light(self, sampler, channels, e_sun, path, stokes, radiance, proxy_weights, expected=None):
        """Orders 2 and >= 3 of a line-integral ``path`` (and its :class:`StokesPath` when
        polarized, else None) that goes on from its first vertex (depth 1), added to
        ``radiance``: one loop iteration per segment. ``proxy_weights``: the posterior
        probabilities of :class:`ProxyMixture` after the first vertex. ``expected``: the guide's
        multiply scattered radiance along the camera ray, for the roulette
        (``IMPORTANCE_ROULETTE_WINDOW``); None: the roulette on the throughput alone
        (``LINE_ROULETTE_THROUGHPUT``)."""
        path.alive &= path.depth < self.max_depth
        # the first vertex's direction was drawn by the guided mixture in either strategy, so the
        # guided share starts at its prior here
        prior = TWILIGHT_GUIDED_PATH_PRIOR if self.twilight else GUIDED_PATH_PRIOR
        sampling = PathSampling(proxy_weights, dr.full(mi.Float, prior, dr.width(path.alive)))
        # the throughput roulette's reference: the largest channel throughput at the first vertex
        first_vertex_throughput = dr.maximum(dr.max(dr.detach(path.throughput), axis=0), 1e-30)

        while dr.hint(path.alive, label="atmosphere line-integral path"):
            light, _, path, stokes, sampling = self._line_segment(
                sampler, channels, e_sun, path, stokes, camera=False, rising_only=False, sunlight="sampled",
                sampling=sampling)
            radiance.file(path.depth, light, True, multiple_only=True)  # scattered (or reflected) path.depth >= 2 times
            # Russian roulette: on what the path is expected to bring from here against what its
            # pixel's orders >= 2 are, or on the largest channel throughput against the first
            # vertex's (a layer that the guide sees no light in at all: there it foresees nothing)
            largest = dr.max(dr.detach(path.throughput), axis=0)
            survival = dr.minimum(largest / (LINE_ROULETTE_THROUGHPUT * first_vertex_throughput), 1.0)
            if expected is not None:
                ahead = self.guide.at(self.geometry.up(path.point), path.altitude).radiance(path.direction)
                foreseen = dr.detach(ahead * dr.rcp(dr.maximum(IMPORTANCE_ROULETTE_WINDOW * expected, 1e-30)))
                survival = dr.select((ahead > 0.0) & (expected > 0.0), dr.minimum(largest * foreseen, 1.0), survival)
            roulette = path.alive & (path.depth >= LINE_ROULETTE_DEPTH)
            survives = sampler.next_1d() < survival
            path.throughput = dr.select(roulette & survives, path.throughput / survival, path.throughput)
            path.alive &= ~(roulette & ~survives) & (path.depth < self.max_depth)

    def _line_segment(self, sampler, channels, e_sun, path, stokes, camera, rising_only, sunlight="quadrature",
                      goes_on=True, sampling=None):
        """One segment of a line-integral ``path`` (a :class:`PathVertex`, with its
        :class:`StokesPath` ``stokes`` when polarized, else None) from its vertex along its
        direction. Returns (the light gathered along the segment: sunlight scattered once on it,
        or reflected by the ground at its end, so path.depth + 1 events: radiance, or Stokes
        vectors; the solar disk seen through it when ``camera``; the path at its next vertex,
        one event deeper; its StokesPath there; its :class:`PathSampling` after the vertex). Where
        ``sampling`` is None (a camera segment whose single scattering is integrated here, or one
        at twilight), the next vertex is drawn by the path's :class:`GreyProxy` and its direction
        by the guided mixture; else by :class:`ProxyMixture` and the mixture of the guided
        directions with the phase function's (on the camera segment, its guided share is 1),
        with the posterior probabilities ``sampling`` holds. ``sunlight``:
        the segment's scattered sunlight by ``"quadrature"`` or ``"sampled"`` at
        ``SAMPLED_SUNLIGHT_POINTS`` points (:meth:`LineIntegral.sampled_sunlight`), or None: not
        computed (the light is 0), only where the path goes on. ``goes_on`` False: the path
        ends here (single scattering alone), and the next vertex returned is None."""
        geometry, optics, sun = self.geometry, self.optics, self.sun
        p, d, h, throughput, alive = path.point, path.direction, path.altitude, path.throughput, path.alive
        t_ground = geometry.distance_to_ground(p, d, h)
        t_top = geometry.distance_to_top(p, d, h)
        on_ground = t_ground < t_top
        length = dr.select(on_ground, t_ground, t_top)
        sun_direction, sun_factor = sun.sample_direction(sampler.next_2d())
        proxy = GreyProxy(channels, throughput) if sampling is None else ProxyMixture(channels, throughput,
                                                                                      sampling.proxy_weights)
        scattered, transmittance, quadrature = self.line.integrate(
            channels, p, d, h, length, sun_direction, proxy, rising_only, sunlight, forced_collision=goes_on)
        if goes_on:
            quadrature, ground_mass, mixture = proxy.mix(quadrature, on_ground)
        ground = p + length * d
        up = geometry.up(ground)
        light, sun_disk = channels.zeros(self.stokes), channels.zeros()
        if sunlight is not None:
            if sunlight == "sampled":
                scattered = self.line.sampled_sunlight(channels, quadrature, p, d, sun_direction, sampler.next_1d(),
                                                       SAMPLED_SUNLIGHT_POINTS)
            intensity = mi.ArrayXf([scattered[k] for k in range(channels.count)])
            light = throughput * intensity * e_sun * sun_factor
            if self.polarized:
                # the segment's scattered sunlight, (P11, P12) parts, through the path's matrix
                linear = mi.ArrayXf([scattered[channels.count + k] for k in range(channels.count)])
                light = stokes_times(stokes.scattered_source(sun_direction, d, [linear * dr.rcp(
                    dr.maximum(intensity, 1e-30))]), light)
            if camera:
                sun_disk = dr.select(alive & ~on_ground, throughput * transmittance * e_sun * self._solar_disk(d),
                                     sun_disk)
            # -- the ground at the segment's end reflects sunlight (Lambertian; lit iff the sun
            # is above its horizon: the planet is convex) ---------------------------------------
            cos_sun = dr.dot(up, sun_direction)
            tau_sun = self.line.sun_depth(mi.Float(0.0), cos_sun)
            reflected = (throughput * transmittance * channels.albedo * e_sun * sun_factor
                         * dr.exp(-channels.optical_depth(tau_sun)) * (dr.maximum(cos_sun, 0.0) / math.pi))
            if self.polarized:
                reflected = stokes_times(stokes.unpolarized_source(), reflected)
            light += dr.select(on_ground & (cos_sun > 0.0), reflected, 0.0)
            light = dr.select(alive, light, 0.0)

        if not goes_on:
            return light, sun_disk, None, stokes, sampling
        # -- where the path goes on: a forced collision in the air, or the ground --------------------
        air_mass = sum(quadrature.masses, mi.Float(0.0))
        p_air = air_mass / dr.maximum(air_mass + ground_mass, 1e-30)
        alive &= (air_mass + ground_mass) > 0.0
        # One decision places the next vertex and turns the path there: (where, cos, azimuth);
        # "where" < p_air picks the air, and its position within [0, p_air) the collision point.
        vertex_sample = sampler.next_3d()
        in_air = vertex_sample.x < p_air
        u_air = dr.minimum(vertex_sample.x / dr.maximum(p_air, 1e-30), 1.0 - 2.0 ** -24)
        x, hx, weight, (parts, sigma_s, _), joint = self.line.sample_collision(channels, quadrature, p, d, u_air)
        u_direction = mi.Point2f(vertex_sample.y, vertex_sample.z)
        d_air, scattering_weight, guided = self._scatter_direction(parts, sigma_s, d, x, hx, sampler.next_1d(), u_direction,
                                                                   sampler, None if sampling is None else sampling.guided)
        if sampling is not None:
            sampling = PathSampling(ProxyMixture.posterior(mixture, ground_mass, joint, in_air),
                                    dr.select(in_air, guided, sampling.guided))
        if self.polarized:
            _, reduced = self.optics.phase_matrix(parts, sigma_s, dr.clip(dr.dot(d, d_air), -1.0, 1.0))
            stokes, factor = stokes.scatter(d_air, d, reduced, in_air)
            stokes = stokes.reflect(~in_air)
            scattering_weight = scattering_weight * factor
        air_throughput = throughput * weight * scattering_weight * dr.rcp(dr.maximum(p_air, 1e-30))
        # the ground's choice of strategy has its own number: "where" rescaled to [p_air, 1) keeps
        # only a few distinct values where the ground's share 1 - p_air is tiny
        d_ground, reflection_weight = self._reflect_direction(
            up, sampler.next_1d() if self.ground_guided else None, u_direction)
        ground_throughput = (throughput * transmittance * channels.albedo * reflection_weight
                             / dr.maximum(1.0 - p_air, 1e-30))
        next_vertex = PathVertex(dr.select(in_air, x, ground), dr.select(in_air, hx, 0.0),
                                 dr.select(in_air, d_air, d_ground),
                                 dr.select(in_air, air_throughput, ground_throughput), path.depth + 1, alive)
        return light, sun_disk, next_vertex, stokes, sampling

    def _reflect_direction(self, up, u_choice, u_direction):
        """The direction a line-integral path takes off the Lambertian ground (normal ``up``)
        and its weight (cos theta / pi) / pdf, the albedo apart: by the cosine, or where
        ``ground_guided``, with probability :data:`GROUND_GUIDE_PROBABILITY` (``u_choice``
        below it; None where not guided) from the guide's lowest layer, one-sample MIS of the
        two (balance heuristic: the weight stays below 1 / (1 - that probability)); a guided
        direction below the horizon weighs 0."""
        direction = mi.Frame3f(up).to_world(mi.warp.square_to_cosine_hemisphere(u_direction))
        if not self.ground_guided:
            return direction, mi.Float(1.0)
        guide, a = self.guide.at(up, mi.Float(0.0)), GROUND_GUIDE_PROBABILITY
        guided = guide.sample(u_choice / a, u_direction.x, u_direction.y)
        direction = dr.select(u_choice < a, guided, direction)
        cosine_pdf = dr.maximum(dr.dot(up, direction), 0.0) / math.pi
        pdf = (1.0 - a) * cosine_pdf + a * guide.pdf(direction)
        return direction, dr.detach(dr.select(pdf > 0.0, cosine_pdf * dr.rcp(pdf), 0.0))

    def _scatter_direction(self, parts, sigma_s, d, point, altitude, u_choice, u_direction, sampler,
                           guided_share=None):
        """The direction a line-integral path takes at a scattering event (incident direction d,
        at ``point`` and ``altitude``), its weight sigma_s p / pdf per channel (the volume
        scattering function over the direction's density, m^-1), and the posterior
        probability that the path's directions so far were drawn by the guided mixture.
        ``u_choice`` picks one of three ways to draw it:

        * with probability alpha = ``GUIDE_PROBABILITY`` x the local share of the scattering
          without a forward peak (Rayleigh's), from the :class:`ScatteredLightGuide`: towards
          where the sky's scattered light comes from (at twilight, the lit air low over the
          sun's azimuth);
        * with probability beta = ``SUN_LOBE_PROBABILITY`` x the local share of the scattering
          with a forward peak (the aerosols'), from a Henyey–Greenstein lobe around the sun
          (parameter ``sun_lobe_g``): light that scatters once more on the way towards the sun
          meets the aerosol's forward peak there, which the local phase function rarely sends a
          path into;
        * otherwise from the local phase function.

        The pdf is the mixture of the three (one-sample MIS, balance heuristic). The guide's share
        follows the local mixture because an aerosol's forward peak is what carries light through
        hazy air: guided with a fixed probability of 0.5, the variance of orders >= 3 on the hazy
        sky (turbidity 6) grew 4x.

        From the path's second vertex on, that guided mixture is itself mixed with the phase
        function alone by the balance heuristic over the whole path: ``guided_share`` (None: 1)
        is the posterior probability c of the guided mixture q given the path so far, so the
        direction is drawn by c q + (1 - c) p_phase (alpha and beta scaled by c) and afterwards
        c <- c q / (c q + (1 - c) p_phase). The product of the MIS weights along the path then
        stays below 1 / (1 - c_prior) times the phase function's own (``GUIDED_PATH_PRIOR``).

        Where ``resampled_directions`` M > 1 (wherever there is a guide), the direction is then resampled
        (Talbot et al. 2005): M candidates drawn from that mixture q (the first from ``u_choice``
        and ``u_direction``, the others from ``sampler``), one kept with probability proportional
        to w_j = t(omega_j) / q(omega_j) with the target t = phase function x (guide density +
        ``RESAMPLING_UNIFORM_SHARE`` / 4 pi): nearly the product of the phase function and the
        light arriving from each direction, which neither density alone is. Its weight replaces
        1 / q by (sum_j w_j) / (M t(omega)), which keeps the estimate unbiased for any t that is
        positive wherever the phase function is (detached: a sampling weight, as 1 / q). The
        guided posterior is then taken at the kept candidate."""
        optics, guide = self.optics, self.guide.at(self.geometry.up(point), altitude)
        g = self.sun_lobe_g
        lobe = g > 0.0
        rayleigh_share = optics.share_without_forward_peak(parts, sigma_s)
        guided_alpha = GUIDE_PROBABILITY * rayleigh_share
        guided_beta = SUN_LOBE_PROBABILITY * (1.0 - rayleigh_share) if lobe else 0.0
        share = mi.Float(1.0) if guided_share is None else dr.detach(guided_share)
        alpha, beta = share * guided_alpha, share * guided_beta

        def candidate(u_choice, u_direction):
            """A direction drawn from the mixture, its cosine with d, the mixture's density q,
            the guided mixture's alone and the resampling target t."""
            guided = u_choice < alpha
            u_phase = dr.clip((u_choice - alpha - beta) / dr.maximum(1.0 - alpha - beta, 1e-30), 0.0, 1.0)
            mu_phase, _ = optics.sample_phase(parts, sigma_s, u_phase, u_direction.x)
            direction = direction_with_cosine(d, mu_phase, u_direction.y)
            if lobe:
                towards_sun = direction_with_cosine(self.sun.direction, sample_henyey_greenstein_cosine(
                    u_direction.x, g, xp), u_direction.y)
                direction = dr.select(~guided & (u_choice < alpha + beta), towards_sun, direction)
            direction = dr.select(guided, guide.sample(u_choice / dr.maximum(alpha, 1e-30), u_direction.x,
                                                       u_direction.y), direction)
            mu = dr.clip(dr.dot(d, direction), -1.0, 1.0)
            phase_pdf, guide_pdf = optics.phase_pdf(parts, sigma_s, mu), guide.pdf(direction)
            lobe_pdf = henyey_greenstein_phase(dr.dot(self.sun.direction, direction), g, xp) if lobe else 0.0
            guided_pdf = (1.0 - guided_alpha - guided_beta) * phase_pdf + guided_alpha * guide_pdf + guided_beta * lobe_pdf
            pdf = share * guided_pdf + (1.0 - share) * phase_pdf
            target = phase_pdf * (guide_pdf + RESAMPLING_UNIFORM_SHARE / (4.0 * math.pi))
            return direction, mu, pdf, guided_pdf, target

        direction, mu, pdf, guided_pdf, target = candidate(u_choice, u_direction)
        inverse_density = dr.rcp(pdf)
        if self.resampled_directions > 1:
            # streaming resampling: the j-th candidate replaces the one kept with probability
            # w_j / (w_1 + ... + w_j), which keeps each with probability w_j / sum w
            weight_sum = dr.detach(target * dr.rcp(pdf))
            for _ in range(self.resampled_directions - 1):
                other = candidate(sampler.next_1d(), sampler.next_2d())
                weight = dr.detach(other[4] * dr.rcp(other[2]))
                weight_sum += weight
                replace = sampler.next_1d() * weight_sum < weight
                direction, mu, pdf, guided_pdf, target = (dr.select(replace, new, kept) for new, kept in zip(
                    other, (direction, mu, pdf, guided_pdf, target)))
            inverse_density = dr.detach(weight_sum * dr.rcp(self.resampled_directions * dr.maximum(target, 1e-30)))
        scattered = optics.volume_scattering_function(parts, optics.component_phases(mu))
        return direction, scattered * inverse_density, dr.detach(share * guided_pdf * dr.rcp(pdf))

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
        polarized = self.polarized
        radiance = RadianceByOrder.zeros(channels, self.stokes)

        # -- the camera ray; an observer above the atmosphere first moves to where it enters ------
        d = mi.Vector3f(direction)
        p, h, misses = self._enter_atmosphere(origin, d, active)
        radiance.direct = dr.select(misses, e_sun * self._solar_disk(d), radiance.direct)
        # Polarized: the path's Mueller matrix (w N, polarization.py) starts in the camera's frame.
        stokes = StokesPath.camera(d, geometry.up(mi.Point3f(origin)), channels.count) if polarized else None

        path = PathVertex(p, h, d, channels.zeros() + 1.0, mi.UInt32(0), mi.Bool(active) & ~misses)
        segment = self._segment(p, d, h)
        shadow = ShadowRay(mi.Bool(False), mi.Point3f(p), mi.Float(h), mi.Vector3f(d), mi.Float(0.0),
                           channels.zeros(), channels.zeros(self.stokes), mi.UInt32(0))

        while dr.hint(path.alive | shadow.active, label="atmosphere path"):
            # -- one tracking step along the current ray (the shadow ray if one is in flight) ----
            in_shadow = shadow.active
            x = dr.select(in_shadow, shadow.point, path.point)
            w = dr.select(in_shadow, shadow.direction, path.direction)
            length = dr.select(in_shadow, shadow.remaining, segment.remaining)
            hx = dr.select(in_shadow, shadow.altitude, path.altitude)
            hx_end = dr.select(in_shadow, geometry.H, segment.h_end)
            # The majorant holds over the next *stretch* of the segment only: as far as the ray
            # descends by ``majorant_drop``. A ray coming down from high up would otherwise
            # track thin air with the extinction at the ground (from 1000 km, through a
            # turbidity-50 haze: ~10^3 null collisions per ray). Past a stretch without a
            # collision the tracking starts afresh (free flights are memoryless).
            reach, h_reach = self._majorant_stretch(x, w, length, hx, hx_end)
            majorant = self._majorant(channels, x, w, reach, hx, h_reach)
            # Camera rays draw candidate points more densely than the majorant where the segment
            # is optically thin: ~CAMERA_SUN_CONNECTIONS over the rest of the segment, at most
            # CAMERA_MAX_BOOST x the majorant. Each carries a sun connection, which is what makes
            # single scattering converge; thinning the candidates with probability
            # majorant / rate recovers the tracking process exactly.
            camera = ~in_shadow & (path.depth == 0)
            rate = dr.select(camera, dr.clip(CAMERA_SUN_CONNECTIONS / dr.maximum(length, 1e-3), majorant,
                                             CAMERA_MAX_BOOST * majorant), majorant)
            t = -dr.log(1.0 - sampler.next_1d()) / rate
            collides = t < reach
            stretch_done = ~collides & (reach < length)      # no collision in it: on to the next
            x = dr.select(collides, x + t * w, dr.select(stretch_done, x + reach * w, x))
            hx = dr.select(collides, geometry.altitude(x), dr.select(stretch_done, h_reach, hx))
            t = dr.select(stretch_done, reach, t)
            parts, sigma_s, sigma_t = optics.local(channels, hx)

            # -- shadow ray: ratio tracking; file the contribution when it leaves -------------------
            shadow_step = in_shadow & collides
            transmittance = dr.select(shadow_step, shadow.transmittance * dr.maximum(1.0 - sigma_t / majorant, 0.0),
                                      shadow.transmittance)
            # Russian roulette on faint shadow rays (grazing rays at twilight cross tens of
            # optical depths): continue with probability max T / SHADOW_ROULETTE, reweighted.
            faint = shadow_step & (dr.max(transmittance, axis=0) < SHADOW_ROULETTE)
            survival = dr.detach(dr.max(transmittance, axis=0)) / SHADOW_ROULETTE
            survives = sampler.next_1d() < survival
            shadow.transmittance = dr.select(faint, dr.select(survives, transmittance / survival, 0.0), transmittance)
            shadow_moves = shadow_step | (in_shadow & stretch_done)
            shadow.point = dr.select(shadow_moves, x, shadow.point)
            shadow.altitude = dr.select(shadow_moves, hx, shadow.altitude)
            shadow.remaining = dr.select(shadow_moves, shadow.remaining - t, shadow.remaining)
            shadow_done = in_shadow & ((~collides & ~stretch_done) | (dr.max(shadow.transmittance, axis=0) <= 0.0))
            arriving = (stokes_times(shadow.pending, shadow.transmittance) if dr.hint(polarized, mode="scalar")
                        else shadow.pending * shadow.transmittance)
            radiance.file(shadow.order, arriving, shadow_done)
            tracking_path = path.alive & ~in_shadow
            shadow.active = in_shadow & ~shadow_done

            # -- path: a tentative collision in the air ----------------------------------------------
            candidate = collides & tracking_path
            moves_on = tracking_path & stretch_done
            reaches_end = tracking_path & ~candidate & ~stretch_done
            path.point = dr.select(candidate | moves_on, x, path.point)
            path.altitude = dr.select(candidate | moves_on, hx, path.altitude)
            segment.remaining = dr.select(candidate | moves_on, segment.remaining - t, segment.remaining)
            # Next-event estimation at *every* candidate point, weighted by the expected value of
            # the real-scattering branch: P_s * (w sigma_s / (mu P_s)) = w sigma_s / mu, with mu
            # the candidates' rate. The event decision below then only decides how the path goes on.
            sun_direction, sun_factor = sun.sample_direction(sampler.next_2d())
            cos_sun = dr.dot(path.direction, sun_direction)
            if dr.hint(polarized, mode="scalar"):
                phase_sun, reduced_sun = optics.phase_matrix(parts, sigma_s, cos_sun)
            else:
                phase_sun = optics.phase(parts, sigma_s, cos_sun)
            scattered_sunlight = path.throughput * phase_sun * (sigma_s / rate)
            collides = candidate & (sampler.next_1d() * rate < majorant)
            null_weight = dr.maximum(majorant - sigma_t, 0.0)
            a_scatter = dr.max(dr.detach(path.throughput * sigma_s), axis=0)
            a_null = dr.max(dr.detach(path.throughput * null_weight), axis=0)
            p_scatter = a_scatter / dr.maximum(a_scatter + a_null, 1e-30)
            scatters = collides & (sampler.next_1d() < p_scatter)
            is_null = collides & ~scatters
            throughput = path.throughput
            throughput = dr.select(scatters, throughput * sigma_s / (majorant * p_scatter), throughput)
            path.throughput = dr.select(is_null, throughput * null_weight / (majorant * (1.0 - p_scatter)), throughput)

            # -- path: the segment ends on the ground (a Lambertian vertex) or in space -----------
            path.point = dr.select(reaches_end, path.point + segment.remaining * path.direction, path.point)
            path.altitude = dr.select(reaches_end, segment.h_end, path.altitude)
            on_ground = reaches_end & segment.on_surface
            escapes = reaches_end & ~segment.on_surface
            sun_seen = path.throughput * e_sun * self._solar_disk(path.direction)
            radiance.direct = dr.select(escapes & (path.depth == 0), radiance.direct + sun_seen, radiance.direct)
            path.alive &= ~escapes
            # A surface vertex: the planet's ground, or an object (normal offset: no self-hits).
            on_object = on_ground & segment.on_object
            up = dr.select(on_object, segment.object_normal, geometry.up(path.point))
            offset = up * (OBJECT_OFFSET * (1.0 + dr.max(dr.abs(path.point))))
            path.point = dr.select(on_object, path.point + offset, path.point)
            albedo = dr.select(on_object, channels.zeros() + segment.object_albedo, channels.albedo)
            reflected_sunlight = path.throughput * albedo * (dr.maximum(dr.dot(up, sun_direction), 0.0) / math.pi)

            # -- start the shadow ray of this step's next-event estimate -----------------------------
            estimate = candidate | on_ground
            sunlight = dr.select(on_ground, reflected_sunlight, scattered_sunlight) * e_sun * sun_factor
            estimate &= dr.max(dr.detach(sunlight), axis=0) > 0.0   # nothing to connect: no shadow ray
            if dr.hint(polarized, mode="scalar"):
                # the sunlight's Stokes vectors at the camera per unit w: scattered by the air's
                # phase matrix, or reflected unpolarized by the ground
                sunlight = stokes_times(dr.select(on_ground, stokes.unpolarized_source(),
                                                  stokes.scattered_source(sun_direction, path.direction, reduced_sun)),
                                        sunlight)
            visible = estimate & (geometry.distance_to_ground(path.point, sun_direction, path.altitude) == dr.inf)
            if dr.hint(self.objects is not None, mode="scalar"):
                visible &= ~self.objects.ray_test(mi.Ray3f(path.point, sun_direction), visible)
            shadow.active |= visible
            shadow.point = dr.select(visible, path.point, shadow.point)
            shadow.altitude = dr.select(visible, path.altitude, shadow.altitude)
            shadow.direction = dr.select(visible, sun_direction, shadow.direction)
            shadow.remaining = dr.select(visible, geometry.distance_to_top(path.point, sun_direction, path.altitude),
                                         shadow.remaining)
            shadow.transmittance = dr.select(visible, 1.0, shadow.transmittance)
            shadow.pending = dr.select(visible, sunlight, shadow.pending)
            shadow.order = dr.select(visible, path.depth + 1, shadow.order)
            vertex = scatters | on_ground
            path.depth = dr.select(vertex, path.depth + 1, path.depth)

            # -- vertex: continue the path (phase sampling in the air, cosine on the ground) -------
            u_component = sampler.next_1d()
            u_direction = sampler.next_2d()
            mu, pdf = optics.sample_phase(parts, sigma_s, u_component, u_direction.x)
            d_air = direction_with_cosine(path.direction, mu, u_direction.y)
            d_ground = mi.Frame3f(up).to_world(mi.warp.square_to_cosine_hemisphere(u_direction))
            if dr.hint(polarized, mode="scalar"):
                phase, reduced = optics.phase_matrix(parts, sigma_s, mu)
                stokes, factor = stokes.scatter(d_air, path.direction, reduced, scatters)
                stokes = stokes.reflect(on_ground)
                phase = phase * factor
            else:
                phase = optics.phase(parts, sigma_s, mu)
            throughput = dr.select(scatters, path.throughput * phase / pdf, path.throughput)
            path.throughput = dr.select(on_ground, throughput * albedo, throughput)
            path.direction = dr.select(scatters, d_air, dr.select(on_ground, d_ground, path.direction))
            segment = dr.select(vertex, self._segment(path.point, path.direction, path.altitude), segment)

            # -- Russian roulette and termination ------------------------------------------------
            survival = dr.minimum(dr.max(dr.detach(path.throughput), axis=0), 0.95)
            roulette = vertex & (path.depth >= ROULETTE_DEPTH)
            survives = sampler.next_1d() < survival
            path.throughput = dr.select(roulette & survives, path.throughput / survival, path.throughput)
            path.alive &= ~(roulette & ~survives)
            path.alive &= (path.depth < self.max_depth) & (dr.max(path.throughput, axis=0) > 0.0)

        orders = radiance.by_order()
        # the solar disk seen through the atmosphere is unpolarized
        return [unpolarized(orders[0]), *orders[1:]] if polarized else orders


def register():
    mi.register_integrator("atmosphere", lambda props: AtmosphereIntegrator(props))
