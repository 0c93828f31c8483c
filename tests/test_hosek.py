"""The Hosek–Wilkie evaluator: the published coefficients against the formula worked by hand,
NumPy against JAX, stability at the edges of the model's domain, and bad inputs."""

import math

import numpy as np
import pytest

from skyref.analytic.hosek import (BAND_CENTRES_NM, CHANNELS, CoefficientTable, hosek_f, published_arrays,
                                   published_table)
from skyref.errors import ParameterError

KINDS = ("spectral", "xyz", "rgb")


def by_hand(arrays, shape_name, radiance_name, elevation, turbidity, albedo, theta, gamma):
    """The published model computed straight from the flat arrays with explicit loops: the
    reference code's cooking (integer turbidity and remainder, the two albedos, the quintic
    Bezier over x = (elevation / (pi/2))^(1/3)) and F with coefficients at their stored indices
    (A B C D E F G I H)."""
    shape, rad = arrays[shape_name], arrays[radiance_name]
    x = (elevation / (math.pi / 2)) ** (1.0 / 3.0)
    bernstein = [math.comb(5, k) * x ** k * (1 - x) ** (5 - k) for k in range(6)]
    low = int(turbidity)
    rem = turbidity - low
    terms = [(0, low, (1 - albedo) * (1 - rem)), (1, low, albedo * (1 - rem))]
    if low < 10:
        terms += [(0, low + 1, (1 - albedo) * rem), (1, low + 1, albedo * rem)]
    config = [0.0] * 9
    scale = 0.0
    for a, t, weight in terms:
        for k in range(6):
            for i in range(9):
                config[i] += weight * bernstein[k] * shape[((a * 10 + t - 1) * 6 + k) * 9 + i]
            scale += weight * bernstein[k] * rad[(a * 10 + t - 1) * 6 + k]
    A, B, C, D, E, F, G, I, H = config
    chi = (1 + math.cos(gamma) ** 2) / (1 + H * H - 2 * H * math.cos(gamma)) ** 1.5
    f = (1 + A * math.exp(B / (math.cos(theta) + 0.01))) * (
        C + D * math.exp(E * gamma) + F * math.cos(gamma) ** 2 + G * chi + I * math.sqrt(math.cos(theta)))
    return scale * f


CASES = [  # elevation (rad), turbidity, albedo, theta, gamma
    (0.4, 3.0, 0.0, 0.3, 0.5), (0.05, 1.0, 1.0, 1.5, 2.9), (1.2, 10.0, 0.3, 0.9, 0.2),
    (0.8, 9.5, 0.7, 1.2, 1.6), (1.5707963, 6.25, 0.5, 0.0, 1.57), (0.001, 2.7, 0.1, 1.57, 0.01),
]


@pytest.mark.parametrize("kind", KINDS)
def test_published_coefficients_reproduce_the_formula_by_hand(kind):
    arrays = published_arrays()
    table = published_table(kind)
    for elevation, turbidity, albedo, theta, gamma in CASES:
        got = table.radiance(theta, gamma, elevation, turbidity, albedo)
        for index in range(len(table.channels)):
            if kind == "spectral":
                names = (f"dataset{table.channels[index]}", f"datasetRad{table.channels[index]}")
            else:
                names = (f"dataset{kind.upper()}{index + 1}", f"dataset{kind.upper()}Rad{index + 1}")
            expected = by_hand(arrays, *names, elevation, turbidity, albedo, theta, gamma)
            assert got[index] == pytest.approx(expected, rel=1e-12, abs=1e-15), (kind, index, elevation, turbidity)


def test_published_values_are_the_shared_data_and_in_physical_units():
    table = published_table("spectral")
    assert table.coefficients.shape == (11, 2, 10, 6, 9) and table.radiances.shape == (11, 2, 10, 6)
    assert table.channels == tuple(f"{w:g}" for w in BAND_CENTRES_NM)
    # A clear noon sky at 480 nm is of order 0.05-0.2 W m^-2 sr^-1 nm^-1 at the zenith.
    zenith = table.radiance(0.0, math.radians(30.0), math.radians(60.0), 2.0, 0.1)[BAND_CENTRES_NM.index(480.0)]
    assert 0.03 < zenith < 0.3


def test_spectral_radiance_interpolates_linearly_between_band_centres():
    table = published_table("spectral")
    args = (0.7, 1.1, 0.5, 4.0, 0.2)
    bands = table.radiance(*args)
    assert table.spectral_radiance(500.0, *args) == pytest.approx(0.5 * (bands[4] + bands[5]), rel=1e-12)
    assert table.spectral_radiance(720.0, *args) == pytest.approx(bands[10], rel=1e-12)
    both = table.spectral_radiance(np.array([330.0, 710.0]), np.array([0.1, 0.2, 0.3]), 1.0, 0.5, 4.0, 0.2)
    assert both.shape == (3, 2)


@pytest.mark.parametrize("kind", KINDS)
def test_jax_float32_matches_numpy_and_is_jittable(kind):
    import jax
    import jax.numpy as jnp

    table = published_table(kind)
    rng = np.random.default_rng(3)
    theta, gamma = rng.uniform(0, math.pi / 2, 1000), rng.uniform(0, math.pi, 1000)
    expected = table.radiance(theta, gamma, 0.3, 4.5, 0.2)
    evaluate = jax.jit(lambda t, g, e: table.radiance(t, g, e, 4.5, 0.2, xp=jnp))
    got = np.asarray(evaluate(jnp.asarray(theta, jnp.float32), jnp.asarray(gamma, jnp.float32), 0.3))
    scale = np.abs(expected).max(axis=0)
    assert np.max(np.abs(got - expected) / scale) < 2e-5


def view_angles(theta, azimuth, elevation):
    """(theta, gamma) of views at zenith angles ``theta`` (column) and azimuths ``azimuth`` from
    the sun (row), for the sun at ``elevation`` (held at 0 below the horizon, as the model does):
    gamma from the angle between unit vectors, accurate at 0."""
    sun_zenith = math.pi / 2 - max(elevation, 0.0)
    view = np.stack(np.broadcast_arrays(np.sin(theta) * np.cos(azimuth), np.sin(theta) * np.sin(azimuth),
                                        np.cos(theta) + 0 * azimuth), axis=-1)
    sun = np.array([math.sin(sun_zenith), 0.0, math.cos(sun_zenith)])
    gamma = np.arctan2(np.linalg.norm(np.cross(view, sun), axis=-1), view @ sun)
    return np.broadcast_to(theta, gamma.shape), gamma


@pytest.mark.parametrize("kind", KINDS)
def test_stable_at_the_edges_of_the_domain(kind):
    """Sun on and below the horizon, views at and below it, the sun's direction itself, turbidity
    1 and 10: finite, non-negative radiance, positive except in the thin band above the horizon
    where the published coefficients themselves turn F negative (documented in hosek.py)."""
    table = published_table(kind)
    theta = np.array([0.0, 0.5, 1.2, math.radians(88.9), math.pi / 2 - 1e-9, math.pi / 2, 2.0, math.pi])[:, None]
    azimuth = np.array([0.0, 1e-9, 1e-4, 0.5, math.pi / 2, math.pi])[None, :]
    for elevation in (-math.pi / 2, -0.1, 0.0, 1e-6, 0.3, math.pi / 2):
        for turbidity in (1.0, 9.999, 10.0):
            for albedo in (0.0, 1.0):
                value = table.radiance(*view_angles(theta, azimuth, elevation), elevation, turbidity, albedo)
                assert np.all(np.isfinite(value)) and np.all(value >= 0.0), (elevation, turbidity, albedo)
                assert np.all(value[theta[:, 0] < math.radians(89.0)] > 0.0), (elevation, turbidity, albedo)
        on_sun = table.radiance(math.pi / 2 - max(elevation, 0.0), 0.0, elevation, 5.0, 0.5)   # gamma = 0
        assert np.all(np.isfinite(on_sun)) and np.all(on_sun > 0.0)
    angles = view_angles(theta, azimuth, -0.2)
    assert np.array_equal(table.radiance(*angles, -0.2, 3.0, 0.5), table.radiance(*angles, 0.0, 3.0, 0.5))
    np.testing.assert_allclose(table.radiance(math.pi, 1.0, 0.2, 3.0, 0.5),  # sqrt(cos(pi/2)) = 8e-9, not 0
                               table.radiance(math.pi / 2, 1.0, 0.2, 3.0, 0.5), rtol=1e-6)


def test_published_f_is_negative_only_in_a_thin_band_at_the_horizon():
    """Why the evaluator clamps at zero: for the published coefficients F < 0 only within 1 deg
    of the horizon, away from a low sun (here 320 nm, sun on the horizon)."""
    table = published_table("spectral")
    theta = np.radians(np.linspace(0.0, 90.0, 901))[:, None]
    theta, gamma = view_angles(theta, np.radians(np.linspace(0.0, 180.0, 181))[None, :], 0.0)
    coefficients, _ = table.configuration(0.0, 7.0, 0.0)
    f = hosek_f(coefficients[0], np.cos(theta), gamma)
    assert (f < 0).any() and np.all(theta[f < 0] > math.radians(89.0))
    assert np.all(table.radiance(theta, gamma, 0.0, 7.0, 0.0) >= 0.0)


def test_chi_is_finite_and_accurate_near_its_pole():
    """H close to 1 and the view on the sun: the denominator (1 - H)^2 + 4 H sin^2(gamma/2) keeps
    float32 within 1e-5 of float64 (same inputs), where 1 + H^2 - 2 H cos(gamma) loses every digit."""
    import jax.numpy as jnp

    coefficients = np.array([-1.0, -0.3, 0.2, 1.0, -2.0, 0.5, 0.1, 1.0, 0.999], dtype=np.float32)
    gamma = np.array([0.0, 1e-6, 1e-4, 1e-3, 1e-2], dtype=np.float32)
    exact = hosek_f(coefficients.astype(np.float64), 1.0, gamma.astype(np.float64))
    single = np.asarray(hosek_f(jnp.asarray(coefficients), jnp.float32(1.0), jnp.asarray(gamma), jnp))
    assert np.all(np.isfinite(exact)) and np.all(exact > 0) and exact[0] > 1e7
    assert np.max(np.abs(single / exact - 1.0)) < 1e-5
    h, g = coefficients[8], gamma[1]
    naive = np.float32(1) + h * h - np.float32(2) * h * np.cos(g)            # what the textbook form computes
    assert abs(naive / ((1.0 - float(h)) ** 2 + 4.0 * float(h) * math.sin(float(g) / 2) ** 2) - 1.0) > 1e-2


@pytest.mark.parametrize("call,name", [
    (lambda t: t.radiance(0.5, 0.5, 0.3, 0.5, 0.0), "turbidity"),
    (lambda t: t.radiance(0.5, 0.5, 0.3, 11.0, 0.0), "turbidity"),
    (lambda t: t.radiance(0.5, 0.5, 0.3, float("nan"), 0.0), "turbidity"),
    (lambda t: t.radiance(0.5, 0.5, 0.3, 2.0, 1.5), "albedo"),
    (lambda t: t.radiance(0.5, 0.5, 2.0, 2.0, 0.5), "solar_elevation"),
    (lambda t: t.radiance(-0.1, 0.5, 0.3, 2.0, 0.5), "theta"),
    (lambda t: t.radiance(np.array([0.1, 4.0]), 0.5, 0.3, 2.0, 0.5), "theta"),
    (lambda t: t.radiance(0.5, 3.5, 0.3, 2.0, 0.5), "gamma"),
    (lambda t: t.spectral_radiance(300.0, 0.5, 0.5, 0.3, 2.0, 0.5), "wavelength_nm"),
    (lambda t: t.spectral_radiance(750.0, 0.5, 0.5, 0.3, 2.0, 0.5), "wavelength_nm"),
    (lambda t: published_table("xyz").spectral_radiance(500.0, 0.5, 0.5, 0.3, 2.0, 0.5), "kind"),
    (lambda t: CoefficientTable("hosek", "spectral", t.coefficients[:3], t.radiances[:3]), "coefficients"),
    (lambda t: CoefficientTable("hosek", "lms", t.coefficients, t.radiances), "kind"),
    (lambda t: CoefficientTable("preetham", "spectral", t.coefficients, t.radiances), "form"),
    (lambda t: published_table("cmyk"), "kind"),
])
def test_bad_inputs_raise_parameter_error_naming_the_parameter_and_range(call, name):
    with pytest.raises(ParameterError) as info:
        call(published_table("spectral"))
    assert info.value.name == name
    assert "valid:" in str(info.value)


def test_error_message_states_the_range():
    with pytest.raises(ParameterError, match=r"turbidity = 0\.5: out of range \(valid: \[1, 10\]\)"):
        published_table("rgb").radiance(0.5, 0.5, 0.3, 0.5, 0.0)


def test_channels_of_each_kind():
    assert CHANNELS["xyz"] == ("X", "Y", "Z") and len(published_table("rgb").channels) == 3


# --- the Hosek–Wilkie sky on a skyref atmosphere ---------------------------------------------------

def test_hosek_sky_looks_up_the_table_along_the_view_geometry():
    """HosekWilkie2012 on an atmosphere: the radiance along a view is the table's at the view's
    zenith angle theta and sun angle gamma (computed here from the directions), the solar
    elevation, the atmosphere's turbidity and its albedo at 550 nm; above 720 nm the 720 nm band."""
    from skyref.analytic.hosek_sky import HosekWilkie2012
    from skyref.atmosphere import from_turbidity
    from skyref.scene import direction_from_angles

    atmosphere = from_turbidity(4.0)
    wavelengths = np.array([400.0, 550.0, 700.0, 760.0])
    sky = HosekWilkie2012(atmosphere, wavelengths)
    sky.precompute()
    views = direction_from_angles(np.array([0.0, 45.0, 80.0, 89.0]), np.array([0.0, 100.0, 180.0, 270.0]))
    sun = direction_from_angles(np.array(35.0), np.array(180.0))
    out = sky.radiance(views, sun, 0.0)
    theta = np.radians([0.0, 45.0, 80.0, 89.0])
    gamma = np.arccos(np.clip(views @ sun, -1.0, 1.0))
    table = published_table("spectral")
    expected = table.spectral_radiance(np.array([400.0, 550.0, 700.0, 720.0]), theta, gamma, math.radians(55.0),
                                       4.0, 0.1)
    np.testing.assert_allclose(out, expected, rtol=1e-9)
    assert sky.turbidity == pytest.approx(4.0) and sky.albedo == pytest.approx(0.1)


@pytest.mark.parametrize("change,name", [
    (dict(wavelengths_nm=[300.0, 550.0]), "wavelengths_nm"),
    (dict(turbidity=12.0), "turbidity"),
    (dict(atmosphere_turbidity=12.0), "turbidity"),
])
def test_hosek_sky_refuses_what_its_data_do_not_cover(change, name):
    from skyref.analytic.hosek_sky import HosekWilkie2012
    from skyref.atmosphere import from_turbidity

    atmosphere = from_turbidity(change.pop("atmosphere_turbidity", 3.0))
    with pytest.raises(ParameterError, match=name):
        HosekWilkie2012(atmosphere, change.pop("wavelengths_nm", [550.0]), **change)


def test_hosek_sky_refuses_observers_and_suns_outside_its_data():
    from skyref.analytic.hosek_sky import HosekWilkie2012
    from skyref.atmosphere import preset
    from skyref.scene import direction_from_angles

    sky = HosekWilkie2012(preset("bruneton2017"), [550.0])
    sky.precompute()
    views = direction_from_angles(np.array([30.0]), np.array([0.0]))
    with pytest.raises(ParameterError, match="observer_altitude_m"):
        sky.radiance(views, direction_from_angles(np.array(30.0), np.array(0.0)), 5000.0)
    with pytest.raises(ParameterError, match="sun zenith"):
        sky.radiance(views, direction_from_angles(np.array(95.0), np.array(0.0)), 0.0)


# --- Bruneton 2017's solar-spectrum correction ------------------------------------------------------

def _independent_correction(wavelength_nm):
    """E / (Omega L_HW) at one wavelength from the data files, without skyref's code: L_HW read
    from the bundled CSV and interpolated linearly between its two neighbouring band centres (or
    the 720 nm value above it); E the mean of pvlib's ASTM G173 extraterrestrial table over the
    10 nm bin around it (trapezoid on a fine grid); Omega the cap of Bruneton's 0.00935 / 2 rad
    solar radius."""
    import csv
    from importlib import resources

    import pvlib

    text = (resources.files("skyref.analytic") / "data" / "hosek_solar_radiance.csv").read_text()
    rows = list(csv.reader(line for line in text.splitlines() if not line.startswith("#")))[1:]
    table = {float(w): float(v) for w, v in rows}
    at = min(wavelength_nm, 720.0)
    below = 320.0 + 40.0 * math.floor((at - 320.0) / 40.0)
    above = min(below + 40.0, 720.0)
    weight = 0.0 if above == below else (at - below) / 40.0
    radiance = (1.0 - weight) * table[below] + weight * table[above]
    astm = pvlib.spectrum.get_reference_spectra(standard="ASTM G173-03")
    fine = np.linspace(at - 5.0, at + 5.0, 20001)
    values = np.interp(fine, astm.index.to_numpy(float), astm["extraterrestrial"].to_numpy(float))
    irradiance = float(np.sum(0.5 * (values[1:] + values[:-1]) * np.diff(fine)) / 10.0)
    solid_angle = 2.0 * math.pi * (1.0 - math.cos(0.00935 / 2.0))
    return irradiance / (solid_angle * radiance)


def test_solar_spectrum_correction_is_the_ratio_of_the_two_suns():
    """With solar_spectrum_correction the published sky at each wavelength is multiplied by
    skyref's solar irradiance over the one the model assumes (Omega L_HW), computed here from the
    data files; above 720 nm the model's 720 nm sky keeps the 720 nm factor. The correction is
    large below 400 nm and small in the visible (the atmosphere's ozone data start at 360 nm)."""
    from skyref.analytic import analytic_model
    from skyref.atmosphere import from_turbidity
    from skyref.scene import direction_from_angles

    wavelengths = [365.0, 380.0, 500.0, 560.0, 760.0]
    atmosphere = from_turbidity(3.0)
    plain = analytic_model("hosek2012", atmosphere, wavelengths)
    corrected = analytic_model("hosek2012", atmosphere, wavelengths, solar_spectrum_correction=True)
    views = direction_from_angles(np.array([0.0, 60.0, 85.0]), np.array([0.0, 90.0, 200.0]))
    sun = direction_from_angles(np.array(40.0), np.array(180.0))
    for model in (plain, corrected):
        model.precompute()
    ratio = corrected.radiance(views, sun, 0.0) / plain.radiance(views, sun, 0.0)
    expected = np.array([_independent_correction(w) for w in wavelengths])
    np.testing.assert_allclose(ratio, np.broadcast_to(expected, ratio.shape), rtol=1e-6)
    assert expected[0] > 1.15 and abs(expected[3] - 1.0) < 0.06     # 365 nm: +20%; 560 nm: +5%
    assert corrected.options["solar_spectrum_correction"] and not plain.options["solar_spectrum_correction"]


def test_solar_spectrum_correction_is_an_option_of_the_published_model_only():
    """The option passes the CLI's --option parsing and the registry's check; a fitted table
    (already in skyref's sun) and a non-boolean are refused, naming the option."""
    from skyref.analytic import REGISTRY, analytic_model
    from skyref.atmosphere import from_turbidity
    from skyref.cli import _option_value

    name, value = _option_value("solar_spectrum_correction=true")
    assert (name, value) == ("solar_spectrum_correction", True)
    REGISTRY.check_options("hosek2012", {name: value}, parameter="--option")
    atmosphere = from_turbidity(3.0)
    with pytest.raises(ParameterError, match="solar_spectrum_correction.*fitted table"):
        analytic_model("hosek2012", atmosphere, [550.0], table=published_table("spectral"),
                       solar_spectrum_correction=True)
    with pytest.raises(ParameterError, match="solar_spectrum_correction"):
        analytic_model("hosek2012", atmosphere, [550.0], solar_spectrum_correction="yes")
