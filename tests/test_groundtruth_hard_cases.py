"""Hard cases for the ``atmosphere`` integrator: every scattering order must be finite and
non-negative for a grazing, setting or set sun, views at the horizon from just above the ground,
observers on the ground, above the atmosphere and far out in space (limb views), extreme phase
functions, no / enormous aerosol, an empty and a very thick atmosphere; and a few physically
expected signs (twilight darker than day but not black, the ground seen from space, space black
above the atmosphere).

These are stability checks (few samples): the accuracy of the estimates is tested in
test_groundtruth_closed_forms.py and test_groundtruth_energy.py.
"""

import math

import numpy as np
import pytest

from skyref.scene import ESTIMATORS

WL = [680.0, 550.0, 440.0]
SUN_RADIUS_DEG = math.degrees(0.00935 / 2.0)



def bruneton():
    from skyref.atmosphere import preset

    return preset("bruneton2017")


def direction(zenith, azimuth):
    from skyref.scene import direction_from_angles

    return direction_from_angles(np.asarray(zenith, dtype=np.float64), np.asarray(azimuth, dtype=np.float64))


#: A spread of views (zenith, azimuth) around the sky and the ground, horizon included.
VIEWS = [(0.0, 0.0), (30.0, 0.0), (60.0, 90.0), (80.0, 180.0), (85.0, 0.0), (89.0, 270.0), (89.9, 180.0),
         (90.0, 180.0), (90.1, 180.0), (90.0, 0.0), (91.0, 0.0), (95.0, 90.0), (120.0, 180.0), (150.0, 0.0),
         (180.0, 0.0)]


def render(mi, atmosphere, sun_zenith, observer_m=0.0, views=VIEWS, geometry="spherical", spp=1024, seed=0,
           sun_azimuth=180.0, estimator=None):
    """(M, 4, N) radiance for the views plus the sun's own direction (the last row), by the
    ``estimator`` (default: the scene's)."""
    from skyref.render import build_integrator
    from skyref.scene import Observer, Scene, Sun

    scene = Scene(atmosphere=atmosphere, sun=Sun(sun_zenith, sun_azimuth), observer=Observer(observer_m),
                  wavelengths=WL)
    integ = build_integrator(scene, geometry=geometry, estimator=estimator)
    zen, az = np.array(list(views) + [(sun_zenith, sun_azimuth)]).T
    d = direction(zen, az)
    return integ.render_directions(d, seed=seed, spp=spp).numpy(), d, integ


def check_sane(out, d, sun_zenith, sun_azimuth=180.0, label=""):
    """Finite, non-negative, and sun_direct only inside the solar disk."""
    assert np.all(np.isfinite(out)), f"{label}: NaN/Inf in orders {np.argwhere(~np.isfinite(out))[:5]}"
    assert np.all(out >= 0.0), f"{label}: negative values at {np.argwhere(out < 0.0)[:5]}"
    angle = np.degrees(np.arccos(np.clip(d @ direction(sun_zenith, sun_azimuth), -1.0, 1.0)))
    outside = angle > SUN_RADIUS_DEG * 1.01
    assert np.all(out[outside, 0, :] == 0.0), f"{label}: sun_direct outside the disk"


# --- the sun from overhead to well below the horizon ---------------------------------------------

@pytest.mark.parametrize("estimator", ESTIMATORS)
@pytest.mark.parametrize("geometry", ["spherical", "plane_parallel"])
@pytest.mark.parametrize("sun_zenith", [0.0, 45.0, 89.0, 90.0, 92.0, 96.0, 100.0, 108.0])
def test_sun_zenith_sweep(mi, sun_zenith, geometry, estimator):
    """Both estimators. (The line integral's guide was NaN where no sunlight reaches the air, sun
    zenith 108; over a flat Earth it lit the thin air near the top under a sun below the
    horizon.)"""
    out, d, _ = render(mi, bruneton(), sun_zenith, geometry=geometry, estimator=estimator)
    check_sane(out, d, sun_zenith, label=f"sun {sun_zenith} {geometry}")
    sky = out[:, 1:, :].sum(axis=1)
    if sun_zenith <= 89.0:
        assert np.all(sky[:-1] > 0.0)                  # daylight everywhere
        assert np.all(out[-1, 0, :] > 0.0)             # the sun is visible
    if sun_zenith >= 92.0:
        assert np.all(out[:, 0, :] == 0.0)             # the ground hides it
    if geometry == "plane_parallel" and sun_zenith > 90.0:
        assert np.all(out == 0.0)                      # flat Earth: night is black


# --- the horizon from just above the ground --------------------------------------------------------

@pytest.mark.parametrize("observer_m", [0.0, 1.0, 10.0, 1000.0])
@pytest.mark.parametrize("geometry", ["spherical", "plane_parallel"])
def test_horizon_views_near_the_ground(mi, observer_m, geometry):
    views = [(z, a) for z in (89.0, 89.9, 90.0, 90.1, 91.0) for a in (0.0, 90.0, 180.0)]
    out, d, _ = render(mi, bruneton(), 80.0, observer_m=observer_m, views=views, geometry=geometry, spp=4096)
    check_sane(out, d, 80.0, label=f"horizon from {observer_m} m {geometry}")
    sky = out[:-1, 1:, :].sum(axis=1)
    # the horizon is lit: in-scattering along a long path in daylight (or the lit ground below it)
    assert np.all(sky > 0.0)


@pytest.mark.parametrize("geometry", ["spherical", "plane_parallel"])
def test_tangent_ray_from_the_ground_misses_it(mi, geometry):
    """A view at zenith exactly 90 deg from the ground (float32 cos(pi/2) = -4.4e-8) is a
    horizontal ray: it must see the sky along the horizon, not the ground at distance 0. Its
    single scattering lies within 5% of the view 0.01 deg above it (a long bright path) and far
    above the ground 0.01 deg below it (the ground at distance 0, albedo 0.1)."""
    from skyref.render import build_integrator
    from skyref.scene import Scene, Sun

    scene = Scene(atmosphere=bruneton(), sun=Sun(60.0, 180.0), wavelengths=WL)
    integ = build_integrator(scene, geometry=geometry)
    # a horizontal direction as float32 trigonometry gives it (the sensors' pixel directions)
    tangent_z = float(np.cos(np.float32(np.pi / 2)))
    assert tangent_z < 0.0
    d = np.array([direction(89.99, 0.0), [0.0, math.sqrt(1.0 - tangent_z ** 2), tangent_z],
                  direction(90.01, 0.0)])
    out = integ.render_directions(d, seed=0, spp=16384).numpy()
    above, tangent, below = out[:, 1, :]
    assert np.all(np.abs(tangent / above - 1.0) < 0.05), (tangent, above)
    assert np.all(tangent > 1.5 * below), (tangent, below)


# --- observers on the ground, above the atmosphere, far in space ---------------------------------

SPACE_VIEWS = [(0.0, 0.0), (45.0, 0.0), (90.0, 0.0), (110.0, 180.0), (119.0, 180.0), (119.3, 180.0),
               (119.5, 0.0), (120.0, 180.0), (120.2, 90.0), (120.5, 180.0), (150.0, 0.0), (180.0, 0.0)]


@pytest.mark.parametrize("observer_m", [0.0, 60_000.0, 100_000.0, 1_000_000.0])
@pytest.mark.parametrize("sun_zenith", [30.0, 100.0])
def test_observer_altitudes(mi, observer_m, sun_zenith):
    out, d, _ = render(mi, bruneton(), sun_zenith, observer_m=observer_m, views=SPACE_VIEWS)
    check_sane(out, d, sun_zenith, label=f"observer {observer_m} m, sun {sun_zenith}")
    if observer_m >= 100_000.0:
        # above the top: looking up (and, from 1000 km, 45 deg up and at the horizontal) is
        # looking into empty space
        up = d[:-1, 2] >= 0.0
        assert np.all(out[:-1][up] == 0.0)
    if sun_zenith < 90.0 and observer_m == 1_000_000.0:
        down = out[-2]                                 # straight down: the sunlit ground
        assert np.all(down[1] > 0.0)
        # looking at the atmosphere's limb just above the ground's (119.5 deg) shows scattered light
        assert np.all(out[6, 1:, :].sum(axis=0) > 0.0)


def test_space_is_black_above_the_atmosphere(mi):
    """From 100 km (above the 60 km top) the sky overhead is space: exactly 0 in every order,
    while the atmosphere below glows."""
    views = [(z, a) for z in (0.0, 30.0, 60.0, 85.0) for a in (0.0, 120.0, 240.0)] + [(150.0, 0.0), (180.0, 0.0)]
    out, d, _ = render(mi, bruneton(), 40.0, observer_m=100_000.0, views=views, spp=4096)
    assert np.all(out[:12] == 0.0)
    assert np.all(out[12:14, 1:, :].sum(axis=1) > 0.0)


def test_ground_from_1000_km(mi):
    """Straight down from 1000 km with the sun up: single scattering (ground + air) is > 0 and of
    the order of albedo/pi E mu0 T (the sunlit ground, albedo 0.1): between 0.2x and 5x of it."""
    from skyref.atmosphere import solar_irradiance

    out, d, _ = render(mi, bruneton(), 30.0, observer_m=1_000_000.0, views=[(180.0, 0.0)], spp=16384)
    single = out[0, 1]
    lambert = 0.1 / math.pi * solar_irradiance(WL) * math.cos(math.radians(30.0))
    assert np.all(single > 0.2 * lambert) and np.all(single < 5.0 * lambert)


def test_twilight_is_darker_than_day_but_not_black(mi):
    """Sun 6 deg below the horizon (civil twilight ends): the zenith sky is lit only above the
    Earth's shadow (~35 km): > 0 but at most a few % of the daylight zenith sky."""
    day, _, _ = render(mi, bruneton(), 30.0, views=[(0.0, 0.0)], spp=16384)
    dusk, _, _ = render(mi, bruneton(), 96.0, views=[(0.0, 0.0)], spp=16384)
    day_sky, dusk_sky = day[0, 1:].sum(axis=0), dusk[0, 1:].sum(axis=0)
    assert np.all(dusk_sky > 0.0)
    assert np.all(dusk_sky < 0.05 * day_sky)
    assert np.all(dusk_sky > 1.0e-6 * day_sky)


# --- extreme constituents -------------------------------------------------------------------------

def _with_aerosol(**changes):
    from skyref.atmosphere import Aerosol

    base = bruneton()
    old = base["aerosol"]
    fields = dict(profile=old.profile, angstrom_alpha=old.angstrom_alpha, angstrom_beta=old.angstrom_beta,
                  single_scattering_albedo=old.single_scattering_albedo, phase=old.phase)
    fields.update(changes)
    return base.with_constituent(Aerosol(**fields))


def _cases():
    from skyref.atmosphere import Atmosphere, CornetteShanks, Rayleigh

    return {
        "cornette_shanks_g0": _with_aerosol(phase=CornetteShanks(0.0)),
        "cornette_shanks_g0.99": _with_aerosol(phase=CornetteShanks(0.99)),
        "aerosol_tau0": _with_aerosol(angstrom_beta=0.0),
        "aerosol_tau50": _with_aerosol(angstrom_beta=50.0, angstrom_alpha=0.0),
        "rayleigh_x100": bruneton().with_constituent(Rayleigh(density_scale=100.0)),
        "empty": Atmosphere(constituents=(), ground_albedo=0.3),
    }


CASES = ["cornette_shanks_g0", "cornette_shanks_g0.99", "aerosol_tau0", "aerosol_tau50", "rayleigh_x100", "empty"]


#: Optically very thick cases are slow (long paths, shadow rays through tau ~ 10^2-10^3 under a
#: low sun): fewer samples there.
SPP = {"aerosol_tau50": 256, "rayleigh_x100": 256}


@pytest.mark.parametrize("estimator", ESTIMATORS)
@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("sun_zenith", [30.0, 85.0])
def test_extreme_constituents(mi, case, sun_zenith, estimator):
    atmosphere = _cases()[case]
    out, d, integ = render(mi, atmosphere, sun_zenith, views=VIEWS + [(sun_zenith + 1.0, 180.0)],
                           spp=SPP.get(case, 1024), estimator=estimator)
    check_sane(out, d, sun_zenith, label=f"{case}, sun {sun_zenith}")
    if case == "empty":
        from skyref.atmosphere import solar_irradiance

        # only the sun's disk: the sky is exactly 0 (even the ground's albedo 0.3 is dark from
        # above: nothing scatters its light back)
        sky_views = d[:-1, 2] > 0.0
        assert np.all(out[:-1][sky_views] == 0.0)
        assert np.allclose(out[-1, 0], solar_irradiance(WL) / integ.sun.disk.solid_angle_sr, rtol=1e-5)
        assert np.all(out[-1, 1:] == 0.0)
        # the ground, looking down, is lit by the sun: single = albedo/pi E mu0 (no air). mu0 varies
        # over the solar disk by +-0.27 deg x tan(zenith) (+-0.3% at 30 deg, +-5% at 85 deg), and
        # one disk direction is sampled per path: noise 0.01% / 0.2% with 1024 samples.
        down = d[:, 2] < -1e-3
        mu0 = math.cos(math.radians(sun_zenith))
        rtol = 1e-3 if sun_zenith < 60.0 else 1e-2
        assert np.allclose(out[down, 1, :], 0.3 / math.pi * solar_irradiance(WL) * mu0, rtol=rtol)
        assert np.all(out[down, 2:] == 0.0)
    elif case == "aerosol_tau50":
        # the sun is all but gone behind a vertical optical depth > 50 (beta 50 at 1 um): its disk's
        # radiance is at most E / Omega exp(-50 / mu0) (2e-21 at sun zenith 30; delta tracking's
        # ratio tracking returns 0, the line integral the transmittance itself)
        from skyref.atmosphere import solar_irradiance

        disk = solar_irradiance(WL) / integ.sun.disk.solid_angle_sr
        assert np.all(out[-1, 0] <= disk * math.exp(-50.0 / math.cos(math.radians(sun_zenith))))
    elif case != "rayleigh_x100" or sun_zenith < 60.0:
        # (Rayleigh x100 under a low sun: the light reaches the ground by diffusion through
        # tau ~ 27, ~10^3 scatterings, beyond max_depth 64: the sky may truncate to 0 there.)
        assert np.all(out[:, 1:, :].sum(axis=1)[d[:, 2] > 0.0] > 0.0)


# --- a haze of optical depth 50 seen from 1000 km at sunset -------------------------------------------

def test_thick_haze_from_space_costs_what_an_easy_sky_costs_and_agrees_with_the_line_integral(mi):
    """Aerosol optical depth ~50 (Angstrom beta 50), observer at 1000 km, sun zenith 89.9: rays
    come down 60 km through thin air onto a haze 1.2 km thick. With a majorant taken at the
    lowest point of the whole segment (the haze's), delta tracking took ~3 ms per sample (a
    16x8 image at 64 spp and 48 wavelengths: 363 s); with one majorant per descent of a scale
    height it costs at most 30x a clear day-time sky per sample (CPU time, same run; measured
    ~8x), and agrees with the independent line-integral estimator (|z| < 4 at 0.5-5% precision)."""
    import dataclasses
    import time

    from skyref.render import build_integrator
    from skyref.scene import Observer, Scene, Sun

    thick = bruneton().with_constituent(dataclasses.replace(bruneton()["aerosol"], angstrom_beta=50.0))
    views = direction(*np.array([(180.0, 0.0), (170.0, 180.0), (160.0, 0.0), (150.0, 180.0), (148.0, 90.0)]).T)

    def cpu_and_radiance(atmosphere, sun_zenith, observer_m, estimator, spp):
        scene = Scene(atmosphere=atmosphere, sun=Sun(sun_zenith, 180.0), observer=Observer(observer_m), wavelengths=WL)
        integ = build_integrator(scene, estimator=estimator)
        integ.render_directions(views, seed=1, spp=16, batches=16)          # compile
        start = time.process_time()
        x = integ.render_directions(views, seed=2, spp=spp, batches=16).numpy().sum(axis=2)   # (16, M, N)
        return time.process_time() - start, x.mean(axis=0), x.std(axis=0, ddof=1) / 4.0

    easy, _, _ = cpu_and_radiance(bruneton(), 45.0, 1.0, "delta_tracking", 8192)
    hard, tracked, se_tracked = cpu_and_radiance(thick, 89.9, 1.0e6, "delta_tracking", 8192)
    _, line, se_line = cpu_and_radiance(thick, 89.9, 1.0e6, "line_integral", 2048)
    print(f"thick haze from space: {hard / easy:.1f}x the CPU time of a clear sky per sample")
    assert hard < 30.0 * easy
    z = (tracked - line) / np.hypot(se_tracked, se_line)
    assert np.all(se_tracked / tracked < 0.03) and np.all(se_line / line < 0.05)
    assert np.all(np.abs(z) < 4.0), z
