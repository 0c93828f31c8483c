"""Bruneton 2017's precomputed atmospheric scattering (skyref.lut.bruneton) against the path
tracer (the ``atmosphere`` integrator's orders ``single``, ``double``, ``higher``) and against
itself (parametrization inverses, storage precision, external tables).

Statistics: the ground truth's standard error comes from the spread over independent seeds;
errors are stated relative to the ground truth with that standard error. Tables are small in the
CI tests (up to ~20 s each); the paper's sizes and beyond are in the ``slow`` tests.

Measured on this machine (bruneton2017 atmosphere, 680/550/440 nm, ground truth with relative
standard errors 0.04-0.2%; the numbers per test are in its docstring):

* single scattering (``scattering_orders=1``, 200 intervals along rays) converges with the table
  size, by 2-7x per doubling of R x MU x MU_S x NU. At the paper's 32 x 128 x 32 x 8 and its 50
  intervals the trapezoidal rule dominates: +0.5% at the zenith (the aerosol's 1.2 km scale
  height against ~1.2 km steps), 1.6% at 25 deg from the sun, 3% at the horizon, 6% at the sun;
  with 400 intervals, <= 0.3% everywhere (sun and horizon included).
* double scattering from the ground, table-free (the same integrals by brute force): with the
  paper's 16 x 32 directions for the scattering density -10% at 680 nm (the bright band at the
  horizon falls between polar samples 11 deg apart), 0.4% with 32 x 64 (Rayleigh-only sky).
* double scattering through the tables is limited by the cells near mu = 1 and mu_s = 1, where
  the orders >= 2, stored divided by the Rayleigh phase function of the cell's clamped nu, are
  interpolated with the wrong phase factor (module docstring of skyref.lut.bruneton): at the
  paper's sizes -13% .. +11% for views 10-40 deg from the zenith (sun at 60 deg); at
  16 x 64 x 16 x 8 with the sun at 30 deg, -20% (30 deg from the zenith), -14% (60 deg), +26%
  (85 deg), which MU_S = 128 brings to -15%, -1.3%, +4.4%, and MU = 512 brings the near-zenith
  errors (Rayleigh-only sky, sun at 60 deg) from -15% .. +16% to -3% .. +6% (-10% at 10 deg).
* total sky radiance: :func:`test_paper_configuration_total_radiance` and
  :func:`test_high_resolution_total_radiance` (slow).
"""

import math

import numpy as np
import pytest

from skyref.errors import ParameterError

WL = [680.0, 550.0, 440.0]
R_GROUND, R_TOP = 6_360_000.0, 6_420_000.0
SMALL = dict(r_size=8, mu_size=32, mu_s_size=8, nu_size=4)
MEDIUM = dict(r_size=16, mu_size=64, mu_s_size=16, nu_size=8)


def atmosphere():
    from skyref.atmosphere import preset

    return preset("bruneton2017")


def method(mi, wavelengths=WL, **kwargs):
    from skyref.lut.bruneton import Bruneton2017

    return Bruneton2017(atmosphere(), wavelengths, **kwargs)


def direction(zenith, azimuth):
    from skyref.scene import direction_from_angles

    return direction_from_angles(np.asarray(zenith, dtype=np.float64), np.asarray(azimuth, dtype=np.float64))


def ground_truth(mi, sun_zenith, observer_m, views, spp, seeds, max_depth=64):
    """(mean, standard error) of every order, shapes (M, 4, N), for views (zenith, azimuth) deg;
    the sun at azimuth 180."""
    from skyref.render import build_integrator
    from skyref.scene import Observer, RenderSettings, Scene, Sun

    scene = Scene(atmosphere=atmosphere(), sun=Sun(sun_zenith, 180.0), observer=Observer(observer_m),
                  wavelengths=WL, render=RenderSettings(max_depth=max_depth))
    # the LUT method is the subject: the path tracer renders with the baseline estimator,
    # whose kernels compile in seconds (the line integral's in 15 s to minutes per configuration)
    integ = build_integrator(scene, estimator="delta_tracking")
    zen, az = np.array(views, dtype=np.float64).T
    out = np.stack([integ.render_directions(direction(zen, az), seed=s, spp=spp).numpy()
                    for s in range(seeds)]).astype(np.float64)
    return out.mean(axis=0), out.std(axis=0, ddof=1) / math.sqrt(seeds)


def lut_radiance(lut, sun_zenith, observer_m, views):
    zen, az = np.array(views, dtype=np.float64).T
    return lut.radiance(direction(zen, az), direction(sun_zenith, 180.0), observer_m)


def report(label, lut, mean, se):
    error = lut / mean - 1.0
    print(f"{label}: max |rel. error| {np.abs(error).max():.3%} (per view {np.round(100 * np.abs(error).max(1), 3)} %), "
          f"rel. se <= {(se / mean).max():.3%}")
    return error


# --- parametrizations ------------------------------------------------------------------------

def test_scattering_parametrization_round_trips(mi):
    """Texture coordinates -> (r, mu, mu_s, nu, hits ground) -> texture coordinates over the
    texel-centre range (both halves of the mu axis), and (r, mu, mu_s, nu) -> coordinates ->
    (r, mu, mu_s, nu) for rays to the sky and to the ground; the same for the irradiance table.
    Near the ground the ground half of the mu axis degenerates (d_min = r - R and d_max = rho
    both tend to 0) and mu = -(rho^2 + d^2) / (2 r d) loses digits: u_mu comes back within
    1.3e-8 at 8 cm (2e-5 at 8 micrometres), so points below rho = 1e-3 H (6 cm) are left out and
    u_mu is allowed 1e-7 (1e-5 of a cell)."""
    from skyref.lut.table import texture_coordinate

    lut = method(mi, r_size=32, mu_size=128, mu_s_size=32, nu_size=8)
    rng = np.random.default_rng(1)
    n = 4000

    def texel_range(size, count):
        return rng.uniform(0.5 / size, 1.0 - 0.5 / size, count)

    u_mu = np.concatenate([rng.uniform(0.5 / 128, 0.5 - 0.5 / 128, n // 2), rng.uniform(0.5 + 0.5 / 128,
                                                                                          1.0 - 0.5 / 128, n // 2)])
    u_r = rng.uniform(texture_coordinate(1e-3, 32), 1.0 - 0.5 / 32, n)
    u = [rng.uniform(0.0, 1.0, n), texel_range(32, n), u_mu, u_r]
    r, mu, mu_s, nu, hits = lut.scattering_parameters(*[mi.Float64(x) for x in u])
    assert np.array_equal(hits.numpy(), u_mu < 0.5)
    back = lut.scattering_coordinates(r, mu, mu_s, nu, hits)
    for original, result, tolerance in zip(u, back, (1e-12, 1e-9, 1e-7, 1e-10)):
        assert np.allclose(result.numpy(), original, rtol=0, atol=tolerance)

    r = R_GROUND + (R_TOP - R_GROUND) * rng.uniform(1e-3, 1.0, n) ** 2
    horizon = -np.sqrt(1.0 - (R_GROUND / r) ** 2)
    hits = rng.uniform(size=n) < 0.5
    mu = np.where(hits, rng.uniform(-1.0, horizon - 1e-6), rng.uniform(horizon + 1e-6, 1.0))
    mu_s = rng.uniform(lut.mu_s_min, 1.0, n)
    nu = rng.uniform(-1.0, 1.0, n)
    params = [mi.Float64(x) for x in (r, mu, mu_s, nu)]
    result = lut.scattering_parameters(*lut.scattering_coordinates(*params, mi.Bool(hits)))
    for original, value, tolerance in zip((r, mu, mu_s, nu), result, (1e-12, 1e-8, 1e-9, 1e-12)):
        assert np.allclose(value.numpy(), original, rtol=tolerance, atol=tolerance)
    assert np.array_equal(result[4].numpy(), hits)

    u_irr = [texel_range(64, n), texel_range(16, n)]
    back = lut.irradiance_coordinates(*lut.irradiance_parameters(*[mi.Float64(x) for x in u_irr]))
    for original, value in zip(u_irr, back):
        assert np.allclose(value.numpy(), original, rtol=0, atol=1e-12)


# --- invalid input -----------------------------------------------------------------------------

@pytest.mark.parametrize("name, value", [
    ("scattering_orders", 0), ("scattering_orders", 2.5), ("mu_size", 33), ("mu_size", 2), ("r_size", 1),
    ("nu_size", True), ("irradiance_samples", 31), ("combined_mie", "yes"), ("precision", "float64"),
    ("max_sun_zenith_deg", 80.0), ("integration_samples", 0), ("sun_angular_radius_deg", 0.0),
])
def test_invalid_parameters_raise(mi, name, value):
    from skyref.errors import ParameterError

    with pytest.raises(ParameterError, match=name):
        method(mi, **{name: value})


def test_invalid_external_tables_raise(mi):
    from skyref.errors import ParameterError
    from skyref.lut.bruneton import Bruneton2017

    good = dict(transmittance=np.full((8, 16, 3), 0.5), scattering=np.zeros((4, 8, 12, 3)),
                irradiance=np.zeros((4, 8, 3)), single_mie=np.zeros((4, 8, 12, 3)), mu_s_size=4)
    bad = [("transmittance", dict(transmittance=np.full((8, 16, 3), 1.5))),
           ("transmittance", dict(transmittance=np.full((8, 16), 0.5))),
           ("scattering", dict(scattering=np.zeros((4, 8, 12, 2)))),
           ("scattering", dict(scattering=np.full((4, 8, 12, 3), np.nan))),
           ("single_mie", dict(single_mie=np.zeros((4, 8, 6, 3)))),
           ("scattering", dict(single_mie=None)),
           ("irradiance", dict(irradiance=np.zeros((4, 8, 4)))),
           ("mu_s_size", dict(mu_s_size=5))]
    for name, change in bad:
        with pytest.raises(ParameterError, match=name):
            Bruneton2017.from_tables(atmosphere(), WL, **{**good, **change})


def test_radiance_before_precompute_raises(mi):
    lut = method(mi, **SMALL)
    with pytest.raises(RuntimeError, match="precompute"):
        lut.radiance(direction([0.0], [0.0]), direction(30.0, 0.0), 0.0)


# --- single scattering against the path tracer ------------------------------------------------

#: (sun zenith, observer altitude m, views): from the ground; from 5 km with views of the ground
#: (its Lambertian reflection of the direct sun is part of ``single``); from 1000 km in space,
#: with limb views through the atmosphere, the ground seen through it, and a view missing it.
SINGLE_GEOMETRIES = [
    (60.0, 0.0, [(0, 0), (30, 0), (45, 90), (60, 180), (75, 90), (85, 180), (89, 90), (89.5, 0)]),
    (30.0, 5000.0, [(0, 0), (45, 90), (80, 0), (89, 180), (91, 0), (95, 180), (120, 90), (150, 0)]),
    (60.0, 1.0e6, [(119.6, 0), (119.6, 180), (122, 90), (135, 0), (150, 180), (180, 0), (100, 0)]),
]


@pytest.mark.parametrize("sun_zenith, observer_m, views", SINGLE_GEOMETRIES, ids=["ground", "5km", "space"])
def test_single_scattering_converges_to_the_path_tracer(mi, sun_zenith, observer_m, views):
    """``scattering_orders=1`` (fine quadrature: 200 intervals) against ``single``: the largest
    relative error over the views falls by > 2x as every table size doubles, and is < 1.2% with
    16 x 64 x 16 x 8 tables. Measured, 8 x 32 x 8 x 4 -> 16 x 64 x 16 x 8: ground 1.7% -> 0.5%,
    5 km 2.7% -> 0.9% (a ground view), space 6.5% -> 0.8% (a limb view). Ground truth: 32 seeds x
    20k samples per view, rel. se <= 0.25% (measured up to 0.21%, towards the sun; 16 seeds left
    no margin over the noise of the standard error itself). A view that misses the atmosphere is
    black in both."""
    mean, se = ground_truth(mi, sun_zenith, observer_m, views, spp=20_000, seeds=32, max_depth=1)
    mean, se = mean[:, 1], se[:, 1]
    misses = np.all(mean == 0.0, axis=1)
    errors = []
    for size in (SMALL, MEDIUM):
        lut = method(mi, scattering_orders=1, integration_samples=200, **size)
        lut.precompute()
        radiance = lut_radiance(lut, sun_zenith, observer_m, views)
        assert np.all(radiance[misses] == 0.0)
        errors.append(report(f"single, {size}", radiance[~misses], mean[~misses], se[~misses]))
    assert np.all(se[~misses] / mean[~misses] < 2.5e-3)
    assert np.abs(errors[1]).max() < np.abs(errors[0]).max() / 2.0
    assert np.abs(errors[1]).max() < 1.2e-2


def test_single_scattering_with_the_papers_tables_and_quadrature(mi):
    """The paper's 32 x 128 x 32 x 8 tables and 50 intervals, from the ground, sun at 60 deg,
    views up to 80 deg from the zenith and >= 60 deg from the sun: |error| < 0.75% (measured
    0.5-0.6%, at the zenith and at 80 deg: the trapezoidal rule on the aerosol; 1.7% at 25 deg
    from the sun). Ground truth: 16 x 20k samples per view, rel. se <= 0.25%."""
    views = [(0, 0), (30, 0), (45, 90), (60, 0), (75, 90), (80, 0)]
    mean, se = ground_truth(mi, 60.0, 0.0, views, spp=20_000, seeds=16, max_depth=1)
    lut = method(mi, scattering_orders=1)
    lut.precompute()
    error = report("single, paper's tables", lut_radiance(lut, 60.0, 0.0, views), mean[:, 1], se[:, 1])
    assert np.all(se[:, 1] / mean[:, 1] < 2.5e-3)
    assert np.abs(error).max() < 7.5e-3


# --- multiple scattering and ground irradiance --------------------------------------------------

def test_two_scattering_orders_against_the_path_tracer(mi):
    """``scattering_orders=2`` (16 x 64 x 16 x 8 tables) against single + double, from the
    ground, views up to 80 deg from the zenith and >= 40 deg from the sun. Measured: sun at 60
    deg, <= 1.3% except -4.1% at 30 deg from the zenith opposite the sun (the near-zenith mu
    cells); sun at 30 deg, -6.1% there and -5.5% at 60 deg from the zenith opposite the sun (the
    mu_s cells: 30 deg lies between cells at 0 and 58 deg, where the nu of the zenith-sun cell is
    clamped to mu; see the module docstring). Ground truth: 16 x 20k samples, rel. se < 0.25%."""
    views = [(0, 0), (30, 0), (45, 90), (60, 0), (60, 90), (75, 90), (80, 0)]
    lut = method(mi, scattering_orders=2, **MEDIUM)
    lut.precompute()
    for sun_zenith, bound in ((60.0, 0.05), (30.0, 0.07)):
        mean, se = ground_truth(mi, sun_zenith, 0.0, views, spp=20_000, seeds=16)
        reference, reference_se = mean[:, 1] + mean[:, 2], np.hypot(se[:, 1], se[:, 2])
        error = report(f"orders 1-2 vs single + double, sun {sun_zenith}", lut_radiance(lut, sun_zenith, 0.0, views),
                       reference, reference_se)
        assert np.all(reference_se / reference < 2.5e-3)
        assert np.abs(error).max() < bound


def test_sky_irradiance_against_the_path_tracer(mi):
    """With 3 orders the irradiance table holds the sky irradiance of orders 1-2 on horizontal
    ground (16 x 64 x 16 x 8 tables): against the hemisphere integral of the path tracer's
    single + double radiance (Gauss-Legendre in mu, 12 x 24 directions; 8 seeds x 4000 samples,
    rel. se < 0.05%), sun at 60 deg. Measured: +1.7%, +0.7%, +0.3% at 680, 550, 440 nm. The direct
    sun irradiance is E T(sun) mu_s with T from the transmittance table."""
    sun_zenith = 60.0
    x, w = np.polynomial.legendre.leggauss(12)
    mu, weight_mu = 0.5 * (x + 1.0), 0.5 * w
    azimuths = (np.arange(24) + 0.5) * 15.0
    views = [(math.degrees(math.acos(m)), a) for m in mu for a in azimuths]
    weights = np.repeat(weight_mu * mu, 24) * (2.0 * math.pi / 24)
    mean, se = ground_truth(mi, sun_zenith, 0.0, views, spp=4000, seeds=8)
    sky = weights @ (mean[:, 1] + mean[:, 2])
    sky_se = np.sqrt((weights ** 2) @ (se[:, 1] ** 2 + se[:, 2] ** 2))
    lut = method(mi, scattering_orders=3, **MEDIUM)
    lut.precompute()
    sun, lut_sky = lut.sun_and_sky_irradiance(mi.Float64(R_GROUND), mi.Float64(math.cos(math.radians(sun_zenith))))
    lut_sky = np.array([e.numpy()[0] for e in lut_sky])
    error = lut_sky / sky - 1.0
    print(f"sky irradiance: LUT {lut_sky}, path tracer {sky} (rel. se {sky_se / sky}), rel. error {error}")
    assert np.all(sky_se / sky < 2e-3)
    assert np.abs(error).max() < 0.025
    transmittance = np.array([t.numpy()[0] for t in lut.transmittance.to_top(mi.Float64(R_GROUND), mi.Float64(0.5))])
    assert np.allclose([e.numpy()[0] for e in sun], lut.solar_irradiance * transmittance * 0.5, rtol=1e-12)


def test_more_orders_add_light_and_converge(mi):
    """Every order adds radiance, and the added light shrinks geometrically (orders 6 -> 8 add
    < 0.5% in blue, sun at 30 deg, small tables)."""
    views = [(0, 0), (45, 90), (80, 0), (120, 0)]
    radiance = []
    for orders in (1, 2, 4, 6, 8):
        lut = method(mi, scattering_orders=orders, **SMALL)
        lut.precompute()
        radiance.append(lut_radiance(lut, 30.0, 1000.0, views))
    radiance = np.array(radiance)
    assert np.all(np.diff(radiance, axis=0) > 0.0)
    assert np.all(radiance[4] / radiance[3] - 1.0 < 5e-3)


def test_wavelengths_are_independent_lanes(mi):
    """Any wavelength list: a LUT on one wavelength and one on five give the radiance of a
    three-wavelength LUT at the wavelengths they share (to rounding)."""
    views = [(0, 0), (60, 90), (89, 180), (120, 0)]
    luts = {}
    for wavelengths in ([550.0], WL, [400.0, 440.0, 550.0, 680.0, 700.0]):
        luts[len(wavelengths)] = method(mi, wavelengths, scattering_orders=2, **SMALL)
        luts[len(wavelengths)].precompute()
    three = lut_radiance(luts[3], 40.0, 500.0, views)
    assert np.allclose(lut_radiance(luts[1], 40.0, 500.0, views)[:, 0], three[:, 1], rtol=1e-12, atol=0)
    assert np.allclose(lut_radiance(luts[5], 40.0, 500.0, views)[:, [3, 2, 1]], three, rtol=1e-12, atol=0)


# --- the sun -------------------------------------------------------------------------------------

@pytest.mark.parametrize("observer_m", [0.0, 1.0e6])
def test_sun_radiance_against_the_path_tracer(mi, observer_m):
    """The solar disk's radiance E / (pi alpha^2) T against the path tracer's ``sun_direct`` at
    the disk's centre, E / Omega exp(-tau) (ratio tracking), sun at 60 deg, from the ground and
    from space (T = 1 there). They differ by the disk's solid angle, pi alpha^2 against
    Omega = 2 pi (1 - cos alpha): a factor 1 - 2e-6. 48 seeds x 20k samples: rel. se < 0.1%
    from the ground; |LUT - path tracer| < 4 se + 1e-4 (the path tracer's float32 sums: from
    space, where se ~ 1e-6, the two differ by 2.5e-5 with channel-dependent signs)."""
    mean, se = ground_truth(mi, 60.0, observer_m, [(60.0, 180.0)], spp=20_000, seeds=48, max_depth=1)
    lut = method(mi, scattering_orders=1, **SMALL)
    lut.precompute()
    r = mi.Float64(R_GROUND + observer_m)
    radiance = np.array([x.numpy()[0] for x in lut.sun_radiance(r, mi.Float64(0.5))])
    reference, reference_se = mean[0, 0], se[0, 0]
    print(f"sun radiance from {observer_m} m: LUT {radiance}, path tracer {reference} (rel. se "
          f"{reference_se / reference}), rel. difference {radiance / reference - 1}")
    assert np.all(reference_se / reference < 1e-3)
    assert np.all(np.abs(radiance - reference) < 4.0 * reference_se + 1e-4 * reference)


# --- storage ---------------------------------------------------------------------------------

def daylight_views():
    zen, az = np.meshgrid(np.linspace(0.0, 180.0, 19), np.linspace(0.0, 330.0, 12))
    return list(zip(zen.ravel(), az.ravel()))


def test_float16_tables_stay_close_to_float32(mi):
    """float16 scattering tables (same lowest sun as float32, to compare storage only) change
    daylight radiance (directions brighter than 1e-3 of the brightest) by < 1e-3 relative: half
    precision rounds to 2^-11 = 4.9e-4, and interpolation mixes 16 rounded values. Measured on
    these 228 views: 2.5e-4 .. 6.7e-4 for the sun at 30 and 80 deg from 0, 3 km and space (on a
    finer grid up to 7e-3 in dim limb directions from space under the sun at 80 deg)."""
    views = daylight_views()
    luts = {"float32": method(mi, max_sun_zenith_deg=120.0, scattering_orders=3, **SMALL)}
    luts["float32"].precompute()
    luts["float16"] = direct = method(mi, precision="float16", max_sun_zenith_deg=120.0, scattering_orders=3, **SMALL)
    direct.precompute()
    # The float32 tables re-stored in float16 are close to the tables precomputed in float16 (those
    # also round the intermediate orders' tables).
    restored = luts["float32"].stored_as(precision="float16")
    assert restored.precision == "float16" and restored.precompute_seconds == luts["float32"].precompute_seconds
    a, b = lut_radiance(restored, 30.0, 0.0, views), lut_radiance(direct, 30.0, 0.0, views)
    assert not np.array_equal(a, b) and np.abs(a / b - 1.0).max() < 1e-3
    for sun_zenith in (30.0, 80.0):
        for observer_m in (0.0, 3000.0, 1.0e6):
            single = lut_radiance(luts["float32"], sun_zenith, observer_m, views)
            half = lut_radiance(luts["float16"], sun_zenith, observer_m, views)
            lit = single > 1e-3 * single.max()
            assert np.abs(half[lit] / single[lit] - 1.0).max() < 1e-3
    assert np.all(np.abs(luts["float16"].tables()["scattering"]) < 65504.0)


def test_tables_round_trip_through_from_tables(mi):
    """tables() -> from_tables() -> the same tables and the same radiance, for separate and
    combined single Mie; the arrays have Bruneton 2017's texture layout. The radiance agrees to
    float32 rounding, not bit for bit: the copy's optical depths are -ln of the float32
    transmittances, the original's are integrated (measured: at most 3e-8 relative)."""
    from skyref.lut.bruneton import Bruneton2017

    views = daylight_views()
    for combined in (False, True):
        lut = method(mi, scattering_orders=2, combined_mie=combined, precision="float16", **SMALL)
        lut.precompute()
        tables = lut.tables()
        assert tables["transmittance"].shape == (64, 256, 3)
        assert tables["scattering"].shape == (8, 32, 4 * 8, 3 + combined)
        assert tables["irradiance"].shape == (16, 64, 3)
        assert ("single_mie" in tables) == (not combined)
        copy = Bruneton2017.from_tables(atmosphere(), WL, mu_s_size=8, precision="float16", **tables)
        assert copy.combined_mie == combined
        for key, value in copy.tables().items():
            assert np.array_equal(value, tables[key])
        for sun_zenith, observer_m in ((30.0, 0.0), (85.0, 2000.0), (60.0, 1.0e6)):
            a, b = lut_radiance(copy, sun_zenith, observer_m, views), lut_radiance(lut, sun_zenith, observer_m, views)
            lit = b > 0.0
            print(f"sun {sun_zenith}, {observer_m} m: largest relative difference "
                  f"{np.abs(a[lit] / b[lit] - 1.0).max():.1e}")
            assert np.allclose(a, b, rtol=1e-6, atol=0.0)


def test_combined_mie_extrapolation(mi):
    """With ``combined_mie`` only channel 0's single Mie is stored (in the alpha channel): channel 0
    equals the separate-Mie radiance to double-precision rounding (the two kernels order some
    sums differently: 1e-16 measured); the other channels carry the paper's extrapolation
    error, largest in the aureole and at the horizon under the sun (measured from the ground
    <= 2.8% for the sun at 30 deg, 14% at 80 deg; from space <= 0.03% and 0.3%)."""
    views = daylight_views()
    separate = method(mi, scattering_orders=2, **SMALL)
    combined = method(mi, scattering_orders=2, combined_mie=True, **SMALL)
    separate.precompute()
    combined.precompute()
    for sun_zenith, observer_m, bound in ((30.0, 0.0, 0.03), (80.0, 0.0, 0.15), (80.0, 1.0e6, 0.005)):
        a = lut_radiance(separate, sun_zenith, observer_m, views)
        b = lut_radiance(combined, sun_zenith, observer_m, views)
        assert np.allclose(a[:, 0], b[:, 0], rtol=1e-12, atol=0.0)
        lit = a > 1e-3 * a.max()
        assert np.abs(b[lit] / a[lit] - 1.0).max() < bound
    # Combining the separate tables afterwards gives the combined precomputation; not the reverse.
    assert np.array_equal(lut_radiance(separate.stored_as(combined_mie=True), 30.0, 0.0, views),
                          lut_radiance(combined, 30.0, 0.0, views))
    with pytest.raises(ParameterError, match="combined_mie"):
        combined.stored_as(combined_mie=False)


# --- the paper's configuration and beyond (slow) ----------------------------------------------------

#: Sky views from the ground, up to 80 deg from the zenith and >= 40 deg from a sun at 60 deg
#: zenith, 180 deg azimuth.
SKY_VIEWS = [(0, 0), (10, 0), (20, 0), (30, 0), (30, 90), (45, 90), (50, 0), (60, 0), (75, 90), (80, 0)]


def total_radiance_errors(mi, lut, sun_zenith, views, wavelengths):
    """Relative errors of the LUT's radiance against single + double + higher (16 seeds x 50k
    samples per view), channels of ``wavelengths`` within WL."""
    mean, se = ground_truth(mi, sun_zenith, 0.0, views, spp=50_000, seeds=16)
    channels = [WL.index(w) for w in wavelengths]
    total = mean[:, 1:, channels].sum(axis=1)
    total_se = np.sqrt((se[:, 1:, channels] ** 2).sum(axis=1))
    assert np.all(total_se / total < 2.5e-3)
    return report(f"{lut.scattering_orders} orders, sun {sun_zenith}", lut_radiance(lut, sun_zenith, 0.0, views),
                  total, total_se)


@pytest.mark.slow
def test_paper_configuration_total_radiance(mi):
    """The paper's defaults (32 x 128 x 32 x 8, 4 orders, 50 intervals, 16 x 32 density samples)
    against single + double + higher from the ground, views up to 80 deg from the zenith and >= 40
    deg from the sun. Measured |error| (max over 680/550/440 nm per view, views in SKY_VIEWS'
    order): sun at 60 deg, 1.6 5.4 6.6 4.6 2.5 2.3 1.0 0.7 2.5 0.1% (worst 10-30 deg from the
    zenith opposite the sun: the near-zenith mu cells; orders >= 5 missing cost 1-2% in blue);
    sun at 30 deg, 1.4 4.1 6.7 8.6 3.2 3.6 9.0 7.7 2.4 1.2% (worst opposite the sun: at the
    paper's 32 mu_s cells a sun at 30 deg lies between cells at 0 and 45 deg). Precompute 86 s on
    2 idle cores (up to 254 s when they are shared)."""
    lut = method(mi)
    print(f"precompute: {lut.precompute():.1f} s")
    for sun_zenith, bound in ((60.0, 0.075), (30.0, 0.10)):
        error = total_radiance_errors(mi, lut, sun_zenith, SKY_VIEWS, WL)
        assert np.abs(error).max() < bound


@pytest.mark.slow
def test_high_resolution_total_radiance(mi):
    """More cells where the paper's are scarce (MU = 512), 8 orders, 100 intervals and 24 x 48
    density samples (16 x 512 x 16 x 8 tables, 680 and 440 nm only, to keep the precompute at
    ~8.5 min on 2 busy cores), against single + double + higher from the ground, sun at 60 deg.
    The ~1% target is reached on average, not everywhere: measured |error| per view (SKY_VIEWS'
    order, max over both wavelengths) 0.1 2.9 0.8 0.3 0.3 0.1 1.6 1.6 0.2 1.6%: -1.5% / -3.0%
    (680 / 440 nm) at 10 deg from the zenith (the zenith cell, see the module docstring) and
    +0.6 .. +1.7% at 50-80 deg from the zenith opposite the sun (views on the edge of the nu
    range that their mu and mu_s allow, where neighbouring cells hold clamped nu). Asserted:
    max < 3.5%, mean < 1%."""
    wavelengths = [680.0, 440.0]
    lut = method(mi, wavelengths, r_size=16, mu_size=512, mu_s_size=16, nu_size=8, scattering_orders=8,
                 density_samples=24, integration_samples=100)
    print(f"precompute: {lut.precompute():.1f} s")
    error = total_radiance_errors(mi, lut, 60.0, SKY_VIEWS, wavelengths)
    assert np.abs(error).max() < 0.035
    assert np.abs(error).mean() < 0.01
