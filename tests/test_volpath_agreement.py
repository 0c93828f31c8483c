"""Stock Mitsuba ``volpath`` + skyref's ``atmosphere_medium`` against skyref's ``atmosphere``
integrator, on the same spherical scene (bruneton2017 with a black ground), and the medium's
majorant against the extinction along rays.

The two estimators share nothing but AtmosphereOptics (coefficients and phase functions): free
flights, event probabilities, sun visibility, float32 sphere intersections and Russian roulette
are Mitsuba's on one side and skyref's on the other. The sun is a point in both (Mitsuba's
``directional`` emitter has no disk; the integrator gets a 0.01 degree sun, whose sampled
directions round to its centre in float32), so only sky directions away from the sun are
compared, and the integrator's orders 1..3 (not ``sun_direct``). The "0 m" observer stands
``GROUND_CLEARANCE_M`` = 1 m above the ground in both (Mitsuba's float32 sphere reports a hit at
t = 0 for rays that start on it).

Standard errors come from 64 independent batches of each estimator (rows of volpath's film,
repeated directions for the integrator): with 16 batches the standard errors themselves were
uncertain enough (t with 15 degrees of freedom) for a chance |z| > 4 in a few % of runs.
Every direction and channel must agree within 4 combined standard errors, and so must the
inverse-variance weighted mean relative difference over all of them.
Both estimators are compared with volpath. Measured on the development machine (2 cores,
shared), delta tracking unless said:

* CI version (4 scenes x 8 directions x 64 batches x 12288 samples, ~45 s alone, ~70 s on a
  loaded machine): relative standard error of the difference 0.11-0.53% in the sky views
  (median 0.29%), so a 3% bias fails in every sky direction and channel and ~1% in the median
  one; pooled standard error 0.06-0.08%. Measured: max |z| 1.9, std of z 0.89, max |relative
  difference| 0.61%, median 0.15%. The line integral (2026-12-03, ~70 s with its compile):
  relative standard error of the difference 0.07-0.66% in the two scenes from 1 km, max |z| 2.9
  and pooled z -2.1 at sun zenith 80. With an eighth of volpath's samples
  (``LINE_INTEGRAL_SAMPLE_SHARE``, 2026-12-06): 86 s alone, kernels cached (216 s with all of
  them); pooled z -2.5, 0.5, 0.1 and -2.3 over the four scenes, against -2.7, 0.5, 0.0 and
  -2.1 with all of them (the same volpath renders). Not a bias of the line integral: against
  delta tracking directly on the scene at sun zenith 80 from 1 km (orders 1-3, 134 M delta
  tracking samples per view, 2026-12-06) the pooled difference was +0.002% +- 0.010%.
* ``slow`` version (x 98304 samples, ~8 min): relative standard error 0.04-0.21% (median 0.10%),
  so a 1% bias fails everywhere; pooled 0.02%. Measured: max |z| 2.8, std of z 1.07, max
  |relative difference| 0.41%, median 0.07%, pooled differences -0.02..+0.03% (|z| < 1.5).
  A separate run with 33 M samples per direction (1 km, sun at 30 degrees, zenith and 45
  degrees) agreed to 0.065% (|z| < 1.1).
"""

import functools
import json
import math

import numpy as np
import pytest

from skyref import _llvm

_llvm.configure_libllvm()
mi = pytest.importorskip("mitsuba")
import drjit as dr  # noqa: E402

from skyref.atmosphere import preset  # noqa: E402
from skyref.scene import ESTIMATORS, direction_from_angles  # noqa: E402
from tests.variants import RGB, SPECTRAL  # noqa: E402

SUN_AZIMUTH_DEG = 180.0
#: View directions (zenith, azimuth) in degrees, all >= 20 degrees from the sun at zenith 30 or
#: 80 and azimuth 180: zenith, the anti-solar side, near the horizon and one 20-30 degrees from
#: the sun (in the aerosol's aureole).
SKY_VIEWS_DEG = [(0.0, 0.0), (45.0, 0.0), (60.0, 90.0), (75.0, 270.0), (85.0, 0.0), (89.0, 0.0),
                 (50.0, 180.0)]
#: The eighth view: from 1 km, 5 degrees below the horizon (the black ground 11.5 km away: only
#: the air in front of it shines); on the ground, 2 degrees above the horizon instead. Seen from
#: 1 m, the ground 5 degrees down is 11.4 m away, and Mitsuba's float32 sphere intersection puts
#: it ~2 m short (measured: volpath 16-20% darker there, z = -4..-6 with 4 M samples).
GROUND_VIEW_DEG = {0.0: (88.0, 90.0), 1000.0: (95.0, 90.0)}
CONFIGS = [(0.0, 30.0), (0.0, 80.0), (1000.0, 30.0), (1000.0, 80.0)]  # (observer m, sun zenith)
#: The line integral traces this share of volpath's samples: per sample, its noise is far below
#: volpath's (per-batch relative standard deviation in the sky views at 4096 samples, 2026-12-06:
#: median 0.11-0.16% against 3.0-3.5%, at most 0.16 of volpath's), and it costs 3x volpath's CPU
#: per sample. At an eighth, its standard error is at most ~half volpath's, which widens the
#: difference's by ~10%.
LINE_INTEGRAL_SAMPLE_SHARE = 8


@pytest.fixture(scope="module")
def rgb():
    mi.set_variant(RGB)
    from skyref.plugins import integrator, volpath_scene

    volpath_scene.register()
    integrator.register()
    return mi


def black_ground_atmosphere():
    return preset("bruneton2017").replace(ground_albedo=0.0)


def directions(observer_m=0.0):
    zenith, azimuth = np.array(SKY_VIEWS_DEG + [GROUND_VIEW_DEG[observer_m]]).T
    return direction_from_angles(zenith, azimuth)


def _passes(spp, pass_spp):
    """Launches of ``pass_spp`` samples (~2 M paths) run fastest: (passes, samples per pass)."""
    passes = max(1, spp // pass_spp)
    assert passes * pass_spp == spp or passes == 1
    return passes, spp // passes


@functools.lru_cache(maxsize=None)
def render_volpath(observer_m, sun_zenith_deg, spp, batches, seed=0, pass_spp=4096):
    """Stock volpath's radiance (batches, directions, RGB), ``spp`` samples per direction and
    batch; the batches are the rows of its film. Kept for the module: both estimators are
    compared with the same volpath renders (tracing volpath with a Python medium costs ~0.4 s a
    launch)."""
    from skyref.plugins.volpath_scene import directions_sensor, sensor_origin, stock_volpath_scene

    d = directions(observer_m)
    passes, spp_pass = _passes(spp, pass_spp)
    scene = mi.load_dict(stock_volpath_scene(black_ground_atmosphere(), sun_zenith_deg, SUN_AZIMUTH_DEG, observer_m,
                                             directions_sensor(d, sensor_origin(observer_m), spp_pass, rows=batches)))
    return sum(np.asarray(mi.render(scene, spp=spp_pass, seed=1000 * seed + k)) for k in range(passes)) / passes


def render_integrator(observer_m, sun_zenith_deg, spp, batches, seed=0, pass_spp=4096, estimator="line_integral"):
    """The integrator's orders 1..3 with ``estimator`` (batches, directions, RGB), ``spp``
    samples per direction and batch (the line integral: ``spp // LINE_INTEGRAL_SAMPLE_SHARE``),
    in the passes of :func:`render_volpath`; the batches are repeated directions of one launch."""
    from skyref.plugins.volpath_scene import sensor_origin

    atmosphere = black_ground_atmosphere()
    d = directions(observer_m)
    passes, spp_pass = _passes(spp, pass_spp)
    integrator = mi.load_dict({
        "type": "atmosphere", "atmosphere": json.dumps(atmosphere.to_dict()),
        "sun_zenith": sun_zenith_deg, "sun_azimuth": SUN_AZIMUTH_DEG, "sun_angular_radius": 0.01,
        "observer_altitude": observer_m + sensor_origin(observer_m)[2], "max_depth": 64, "estimator": estimator})
    reference_spp = spp_pass // LINE_INTEGRAL_SAMPLE_SHARE if estimator == "line_integral" else spp_pass
    reference = 0.0
    for k in range(passes):
        # Orders 1..3 (single, double, higher): the sky without the solar disk.
        orders = integrator.render_directions(np.tile(d, (batches, 1)), 1000 * seed + k, reference_spp).numpy()
        reference = reference + orders[:, 1:4, :].sum(axis=1).reshape(batches, len(d), -1) / passes
    return reference


def compare(volpath, reference):
    """Per direction and channel: relative difference, z-score and the relative standard error
    of the difference; and the same three for the mean relative difference over all of them."""
    k = volpath.shape[0]
    m1, m2 = volpath.mean(axis=0), reference.mean(axis=0)
    s1, s2 = volpath.std(axis=0, ddof=1) / math.sqrt(k), reference.std(axis=0, ddof=1) / math.sqrt(k)
    se = np.sqrt(s1 ** 2 + s2 ** 2)
    # Pooled: per batch, the inverse-variance weighted mean over directions and channels of
    # radiance / reference mean (weights from the data, then held fixed).
    w = (m2 / se) ** 2
    w /= w.sum()
    a, b = (w * volpath / m2).sum(axis=(1, 2)), (w * reference / m2).sum(axis=(1, 2))
    pooled = a.mean() - b.mean()
    pooled_se = math.sqrt(a.var(ddof=1) / k + b.var(ddof=1) / k)
    return {"relative": m1 / m2 - 1.0, "z": (m1 - m2) / se, "relative_se": se / m2,
            "pooled": pooled, "pooled_z": pooled / pooled_se, "pooled_se": pooled_se}


def check_agreement(spp, batches, detectable_bias, power_over, seed=0, estimator="line_integral"):
    """Every direction and channel within 4 combined standard errors, the pooled relative
    difference too; and the test must have the power it claims: 4 standard errors below
    ``detectable_bias`` in the sky views (``power_over``: "median" or "max" over them), and
    below a quarter of it for the pooled difference."""
    sky = slice(0, len(SKY_VIEWS_DEG))
    for index, (observer_m, sun_zenith) in enumerate(CONFIGS):
        result = compare(render_volpath(observer_m, sun_zenith, spp, batches, seed + index),
                         render_integrator(observer_m, sun_zenith, spp, batches, seed + index, estimator=estimator))
        label = f"{estimator}, observer {observer_m} m, sun zenith {sun_zenith} deg"
        np.set_printoptions(precision=4, suppress=True)
        print(f"\n{label}: relative difference\n{result['relative']}\nz\n{result['z']}\n"
              f"relative standard error of the difference\n{result['relative_se']}\n"
              f"pooled {result['pooled']:.5f} +- {result['pooled_se']:.5f} (z {result['pooled_z']:.2f})")
        assert np.all(np.isfinite(result["z"])), label
        assert np.all(np.abs(result["z"]) < 4.0), f"{label}: z-scores {result['z']}"
        assert abs(result["pooled_z"]) < 4.0, f"{label}: pooled z {result['pooled_z']}"
        power = getattr(np, power_over)(result["relative_se"][sky])
        assert 4.0 * power < detectable_bias, f"{label}: {power_over} relative standard error {power}"
        assert 4.0 * result["pooled_se"] < detectable_bias / 4.0, label


@pytest.mark.parametrize("estimator", ESTIMATORS)
def test_volpath_agrees_with_integrator(rgb, estimator):
    """CI size (~90 s on 2 cores per estimator): a 3% bias fails in every sky direction and
    channel (a ~1% one in the median one), a ~0.5% bias common to all of them fails the pooled test."""
    check_agreement(spp=12288, batches=64, detectable_bias=0.03, power_over="max", estimator=estimator)


@pytest.mark.slow
@pytest.mark.parametrize("estimator", ESTIMATORS)
def test_volpath_agrees_with_integrator_to_1_percent(rgb, estimator):
    """A 1% bias fails in every sky direction and channel (~6 minutes on 2 cores per estimator)."""
    check_agreement(spp=98304, batches=64, detectable_bias=0.01, power_over="max", estimator=estimator)


# --- the majorant -----------------------------------------------------------------------------


def random_rays(rng, atmosphere, observer_m, count):
    """Origins inside the atmosphere up to ~600 km from the observer and directions of three
    kinds: isotropic, grazing (within 1 degree of the local horizontal) and, from the observer,
    downwards to the ground. Float64 NumPy arrays in the observer frame."""
    R, top = atmosphere.bottom_radius_m, atmosphere.top_radius_m
    centre = np.array([0.0, 0.0, -(R + observer_m)])
    # Points: radius R + h in a cone of 5 degrees around the observer's zenith; half of them in
    # the lowest 1.2 km (the aerosol's scale height).
    h = rng.uniform(0.0, top - R, count) * rng.choice([1.0, 0.02], count)
    cos_cone = rng.uniform(math.cos(math.radians(5.0)), 1.0, count)
    phi = rng.uniform(0.0, 2.0 * math.pi, count)
    sin_cone = np.sqrt(1.0 - cos_cone ** 2)
    up = np.stack([sin_cone * np.cos(phi), sin_cone * np.sin(phi), cos_cone], axis=1)
    origins = centre + (R + h)[:, None] * up
    iso = rng.normal(size=(count, 3))
    iso /= np.linalg.norm(iso, axis=1, keepdims=True)
    # Grazing: horizontal at the origin, tilted by up to +-1 degree.
    tangent = np.cross(up, iso)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    tilt = np.radians(rng.uniform(-1.0, 1.0, count))[:, None]
    grazing = np.cos(tilt) * tangent + np.sin(tilt) * up
    kind = rng.integers(0, 3, count)
    d = np.where(kind[:, None] == 0, iso, grazing)
    # From the observer down to the ground (zenith 90..180 degrees).
    down = direction_from_angles(rng.uniform(90.0, 180.0, count), rng.uniform(0.0, 360.0, count))
    origins = np.where(kind[:, None] == 2, 0.0, origins)
    d = np.where(kind[:, None] == 2, down, d)
    return origins, d


def altitude_f64(points, atmosphere, observer_m):
    centre = np.array([0.0, 0.0, -(atmosphere.bottom_radius_m + observer_m)])
    return np.linalg.norm(points - centre, axis=-1) - atmosphere.bottom_radius_m


@pytest.mark.parametrize("observer_m", [0.0, 1000.0])
@pytest.mark.parametrize("name", ["bruneton2017", "bruneton2016_measured"])
def test_majorant_bounds_extinction_along_rays(rgb, observer_m, name):
    """get_majorant (after intersect_aabb, as Medium::sample_interaction calls them) is grey and
    >= sigma_t (float64 NumPy, from the Atmosphere itself) at every point of the ray inside the
    atmosphere, and tight at the lowest point; get_scattering_coefficients' sigma_n is >= 0."""
    from skyref.plugins.medium import MAJORANT_SAFETY

    atmosphere = preset(name)
    medium = mi.load_dict({"type": "atmosphere_medium", "atmosphere": name, "observer_altitude": observer_m})
    rng = np.random.default_rng(7)
    count, points = 6000, 200
    origins, d = random_rays(rng, atmosphere, observer_m, count)
    ray = mi.Ray3f(mi.Point3f(*(mi.Float(origins[:, i]) for i in range(3))),
                   mi.Vector3f(*(mi.Float(d[:, i]) for i in range(3))))
    hit, mint, maxt = medium.intersect_aabb(ray)
    mei = dr.zeros(mi.MediumInteraction3f, count)
    mei.wi = -ray.d
    majorant = np.asarray(medium.get_majorant(mei, hit)).reshape(3, count).T
    assert np.all(hit.numpy())
    assert np.all(majorant[:, 0] == majorant[:, 1]) and np.all(majorant[:, 0] == majorant[:, 2])
    majorant = majorant[:, 0].astype(np.float64)

    # The part of each ray inside the atmosphere (float64): up to the ground or the top.
    R, top = atmosphere.bottom_radius_m, atmosphere.top_radius_m
    oc = origins - np.array([0.0, 0.0, -(R + observer_m)])
    b = np.sum(oc * d, axis=1)
    r2 = np.sum(oc * oc, axis=1)
    disc_ground = b * b - (r2 - R * R)
    t_ground = np.where((b < 0) & (disc_ground >= 0), -b - np.sqrt(np.maximum(disc_ground, 0.0)), np.inf)
    t_top = -b + np.sqrt(b * b - (r2 - top * top))
    t_end = np.minimum(t_ground, t_top)
    assert np.all(t_end <= maxt.numpy() * (1 + 1e-5) + 1.0)
    # Points: stratified along the segment, plus the closest approach to the planet's centre.
    u = (np.arange(points) + rng.uniform(size=(count, points))) / points
    t = np.concatenate([u * t_end[:, None], np.clip(-b, 0.0, t_end)[:, None]], axis=1)
    p = origins[:, None, :] + t[..., None] * d[:, None, :]
    h = np.clip(altitude_f64(p, atmosphere, observer_m), 0.0, atmosphere.thickness_m)
    sigma_t = atmosphere.extinction_coefficient([680.0, 550.0, 440.0], h).max(axis=-1)
    worst = sigma_t.max(axis=1)
    ratio = worst / majorant
    print(f"\n{name}, observer {observer_m} m: max sigma_t / majorant = {ratio.max():.6f}, "
          f"median {np.median(ratio):.4f}")
    assert np.all(ratio <= 1.0 + 1e-4), f"majorant violated: max ratio {ratio.max()}"
    # Reasonably tight: AtmosphereOptics.majorant sums per-constituent maxima (over channels and
    # over the segment's altitudes), so a ray from the ground through the ozone layer gets the
    # ozone peak on top of the ground's Rayleigh + aerosol: ~5% above the true maximum.
    assert np.median(ratio) > 0.9 / MAJORANT_SAFETY

    # Through Mitsuba's own sample_interaction: sigma_n = majorant - sigma_t >= 0, grey majorant.
    for seed in range(3):
        sample = mi.Float(rng.uniform(size=count).astype(np.float32))
        interaction = medium.sample_interaction(ray, sample, mi.UInt32(0), mi.Bool(True))
        valid = interaction.is_valid().numpy()
        sigma_n = np.asarray(interaction.sigma_n).reshape(3, count).T[valid]
        sigma_t_mi = np.asarray(interaction.sigma_t).reshape(3, count).T[valid]
        combined = np.asarray(interaction.combined_extinction).reshape(3, count).T[valid]
        assert valid.sum() > count // 4
        assert np.all(sigma_n >= 0.0)
        np.testing.assert_allclose(sigma_n + sigma_t_mi, combined, rtol=1e-5, atol=1e-12)


def test_global_majorant_and_direct_calls(rgb):
    """majorant='global' and a get_majorant that follows no intersect_aabb: the atmosphere's
    largest extinction (at the ground for bruneton2017), grey."""
    atmosphere = preset("bruneton2017")
    medium = mi.load_dict({"type": "atmosphere_medium", "majorant": "global"})
    mei = dr.zeros(mi.MediumInteraction3f, 4)
    expected = atmosphere.extinction_coefficient([680.0, 550.0, 440.0], np.array([0.0])).max()
    ozone_peak = (atmosphere["ozone"].extinction_coefficient([680.0, 550.0, 440.0]).max())
    majorant = np.asarray(medium.get_majorant(mei)).ravel()
    assert np.all(majorant >= expected) and np.all(majorant <= (expected + ozone_peak) * 1.002)
    segment = mi.load_dict({"type": "atmosphere_medium"})
    np.testing.assert_allclose(np.asarray(segment.get_majorant(mei)).ravel(), majorant, rtol=1e-6)


def test_medium_parameters_traverse(rgb):
    """mi.traverse lists the atmosphere's differentiable parameters (not the ground albedo, which
    belongs to the scene's BSDF) and updates reach the medium and its phase function."""
    medium = mi.load_dict({"type": "atmosphere_medium"})
    params = mi.traverse(medium)
    assert "rayleigh.density_scale" in params and "aerosol.g" in params and "ozone.column_du" in params
    assert "ground_albedo" not in params
    p = mi.Point3f(0.0, 0.0, mi.Float([0.0, 5000.0]))
    before = np.asarray(medium.sigma_t(p))
    params["aerosol.density_scale"] = mi.Float(0.0)
    params.update()
    after = np.asarray(medium.sigma_t(p))
    expected = preset("bruneton2017").without("aerosol").extinction_coefficient([680.0, 550.0, 440.0],
                                                                               np.array([0.0, 5000.0]))
    np.testing.assert_allclose(after.T, expected, rtol=1e-5)
    assert np.all(before > after)
    # The phase function shares the optics: without aerosol it is pure Rayleigh.
    mei = dr.zeros(mi.MediumInteraction3f, 1)
    mei.wi = mi.Vector3f(0.0, 0.0, 1.0)
    ctx = mi.PhaseFunctionContext(None)
    value, _ = medium.phase_function().eval_pdf(ctx, mei, mi.Vector3f(0.0, 0.0, -1.0))
    np.testing.assert_allclose(np.asarray(value).ravel(), 3.0 / (8.0 * math.pi), rtol=1e-5)


def test_phase_function_conventions(rgb):
    """atmosphere_phase: forward scattering at wo = -wi (Mitsuba's convention, as in 'hg'),
    normalised per channel, sampled weights = value / pdf, pdfs of sample and eval_pdf agree."""
    medium = mi.load_dict({"type": "atmosphere_medium", "observer_altitude": 0.0})
    phase = medium.phase_function()
    count = 200_000
    rng = np.random.default_rng(3)
    mei = dr.zeros(mi.MediumInteraction3f, count)
    mei.p = mi.Point3f(0.0, 0.0, mi.Float(rng.uniform(0.0, 3000.0, count).astype(np.float32)))
    wi = rng.normal(size=(count, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    mei.wi = mi.Vector3f(*(mi.Float(wi[:, i]) for i in range(3)))
    mei.sh_frame = mi.Frame3f(mei.wi)
    ctx = mi.PhaseFunctionContext(None)
    forward, _ = phase.eval_pdf(ctx, mei, -mei.wi)
    backward, _ = phase.eval_pdf(ctx, mei, mei.wi)
    assert np.all(np.asarray(forward) > np.asarray(backward))  # the aerosol's forward peak
    # Normalisation: uniform directions, E[p / (1 / 4 pi)] = 1 per channel.
    wo = mi.warp.square_to_uniform_sphere(mi.Point2f(*(mi.Float(rng.uniform(size=count)) for _ in range(2))))
    value, _ = phase.eval_pdf(ctx, mei, wo)
    np.testing.assert_allclose(np.asarray(value).mean(axis=1) * 4.0 * math.pi, 1.0, rtol=0.02)
    # Sampling: weight = value / pdf, pdf(sample) = eval_pdf's pdf, E[weight] = 1.
    wo, weight, pdf = phase.sample(ctx, mei, mi.Float(rng.uniform(size=count)),
                                   mi.Point2f(*(mi.Float(rng.uniform(size=count)) for _ in range(2))))
    value, pdf_eval = phase.eval_pdf(ctx, mei, wo)
    np.testing.assert_allclose(pdf_eval.numpy(), pdf.numpy(), rtol=2e-4)
    np.testing.assert_allclose(np.asarray(weight), np.asarray(value) / pdf.numpy(), rtol=2e-4)
    np.testing.assert_allclose(np.asarray(weight).mean(axis=1), 1.0, rtol=0.01)


def test_spectral_variant_coefficients():
    """The spectral variant: the medium's sigma_t at continuous wavelengths (1 nm grid, linear
    interpolation) matches the Atmosphere to 1e-4, and volpath renders finite radiance."""
    if SPECTRAL not in mi.variants():
        pytest.skip(f"no {SPECTRAL} variant")
    mi.set_variant(SPECTRAL)
    try:
        from skyref.plugins import volpath_scene

        volpath_scene.register()
        atmosphere = preset("bruneton2017")
        medium = mi.load_dict({"type": "atmosphere_medium", "observer_altitude": 0.0})
        rng = np.random.default_rng(5)
        count = 1024
        wavelengths = rng.uniform(360.0, 830.0, size=(count, 4))
        altitude = rng.uniform(0.0, 50_000.0, count)
        p = mi.Point3f(0.0, 0.0, mi.Float(altitude.astype(np.float32)))
        wl = mi.Spectrum(*(mi.Float(wavelengths[:, k].astype(np.float32)) for k in range(4)))
        sigma_t = np.asarray(medium.sigma_t(p, wl)).T
        expected = np.stack([atmosphere.extinction_coefficient(wavelengths[i], altitude[i])
                             for i in range(count)])
        np.testing.assert_allclose(sigma_t, expected, rtol=1e-3, atol=1e-12)
        d = directions()
        from skyref.plugins.volpath_scene import directions_sensor, sensor_origin, stock_volpath_scene

        scene = mi.load_dict(stock_volpath_scene(atmosphere, 30.0, SUN_AZIMUTH_DEG, 0.0,
                                                 directions_sensor(d, sensor_origin(0.0), 256)))
        image = np.asarray(mi.render(scene, spp=256, seed=0))
        assert np.all(np.isfinite(image)) and np.all(image[0, :6] > 0.0)
    finally:
        mi.set_variant(RGB)
