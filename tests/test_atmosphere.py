"""The atmosphere model against closed forms, independent quadrature and published numbers."""

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from scipy.integrate import quad

import skyref.atmosphere as sa
from skyref.atmosphere import (Absorber, Aerosol, Atmosphere, CornetteShanks, ExponentialProfile,
                               HenyeyGreenstein, PiecewiseLinearProfile, Rayleigh, TabulatedPhase,
                               TabulatedProfile, TabulatedSpectrum)
from skyref.atmosphere.phase import (RayleighPhase, cornette_shanks_asymmetry, cornette_shanks_phase,
                                     henyey_greenstein_phase, rayleigh_phase)

# --- independent reference model of the Bruneton 2017 atmosphere -----------------------------
# Everything below is written from the published numbers (docs/design.md, Bruneton 2017), not from
# skyref's code.

R_BOTTOM = 6_360_000.0
R_TOP = 6_420_000.0
DU = 2.6867e20  # molecules m^-2
OZONE_CSV = Path(sa.__file__).parent / "data" / "ozone_cross_section_233K_10nm.csv"
_OZ = np.array([[float(x) for x in line.split(",")] for line in OZONE_CSV.read_text().splitlines()
                if line.strip() and line[0].isdigit()])
WL = np.array([680.0, 550.0, 440.0])


def sigma_ozone(wl_nm):
    return np.interp(wl_nm, _OZ[:, 0], _OZ[:, 1])


def rayleigh_coeff(wl_nm):
    return 1.24062e-6 * (np.asarray(wl_nm) / 1000.0) ** -4


def tent(h):
    h = np.asarray(h, dtype=float)
    return np.clip(np.minimum((h - 10_000.0) / 15_000.0, (40_000.0 - h) / 15_000.0), 0.0, None)


MIE_EXT = 5.328e-3 / 1200.0              # beta / H_M, alpha = 0
OZONE_PEAK_N = 300.0 * DU / 15_000.0     # number density at the tent's peak, m^-3


def reference_extinction(wl_nm, h):
    """sigma_t(h, lambda) of Bruneton 2017's atmosphere, m^-1."""
    return (rayleigh_coeff(wl_nm) * math.exp(-h / 8000.0) + MIE_EXT * math.exp(-h / 1200.0)
            + OZONE_PEAK_N * sigma_ozone(wl_nm) * float(tent(h)))


def reference_vertical_tau(wl_nm, top=R_TOP - R_BOTTOM):
    ray = rayleigh_coeff(wl_nm) * 8000.0 * (1.0 - math.exp(-top / 8000.0))
    mie = MIE_EXT * 1200.0 * (1.0 - math.exp(-top / 1200.0))
    ozone = OZONE_PEAK_N * sigma_ozone(wl_nm) * 0.5 * 30_000.0 * 1.0  # triangle area
    return ray + mie + ozone


# --- transmittance and optical depth -------------------------------------------------------

def test_vertical_transmittance_closed_form():
    atm = sa.bruneton2017()
    got = atm.transmittance(WL, 0.0, 1.0)
    np.testing.assert_allclose(got, np.exp(-reference_vertical_tau(WL)), rtol=1e-6)
    np.testing.assert_allclose(atm.vertical_optical_depth(WL), reference_vertical_tau(WL), rtol=1e-10)


def test_vertical_transmittance_luminance_grid():
    atm = sa.bruneton2017()
    wl = np.arange(380.0, 790.0, 10.0)
    np.testing.assert_allclose(atm.transmittance(wl, 0.0, 1.0), np.exp(-reference_vertical_tau(wl)), rtol=1e-6)


def _ray_altitude(r0, mu, t):
    """Altitude at distance t along a ray from radius r0 with zenith cosine mu (float64, law of
    cosines written as a difference of squares to avoid cancellation)."""
    r2 = r0 * r0 + 2.0 * r0 * mu * t + t * t
    return (r2 - R_BOTTOM * R_BOTTOM) / (math.sqrt(r2) + R_BOTTOM)


def _distance_to_boundary(r0, mu):
    sin2 = 1.0 - mu * mu
    if mu < 0 and R_BOTTOM ** 2 - r0 * r0 * sin2 >= 0:
        return -r0 * mu - math.sqrt(R_BOTTOM ** 2 - r0 * r0 * sin2)
    return -r0 * mu + math.sqrt(R_TOP ** 2 - r0 * r0 * sin2)


@pytest.mark.parametrize("altitude,mu", [(0.0, 0.0), (0.0, 0.2), (2_000.0, 0.0), (5_000.0, -0.05),
                                         (30_000.0, -0.1)])
def test_slant_optical_depth_against_quad(altitude, mu):
    atm = sa.bruneton2017()
    r0 = R_BOTTOM + altitude
    length = _distance_to_boundary(r0, mu)
    # Break the quadrature where the ray crosses the ozone tent's corners: |p(t)| = R + h_c.
    corners = []
    for hc in (10_000.0, 25_000.0, 40_000.0):
        disc = (r0 * mu) ** 2 - r0 * r0 + (R_BOTTOM + hc) ** 2
        if disc > 0:
            corners += [t for t in (-r0 * mu - math.sqrt(disc), -r0 * mu + math.sqrt(disc)) if 0 < t < length]
    for k, wl in enumerate(WL):
        expected, err = quad(lambda t: reference_extinction(wl, _ray_altitude(r0, mu, t)), 0.0, length,
                             points=sorted(corners) + [min(length, 2e5)], limit=500, epsabs=0.0,
                             epsrel=1e-9)
        got = atm.optical_depth([wl], altitude, mu)[0]
        assert got == pytest.approx(expected, rel=1e-5), (wl, got, expected)


def test_optical_depth_with_explicit_distance():
    atm = sa.rayleigh_only()
    # Horizontal ray over 100 km from the ground: only Rayleigh.
    length = 100_000.0
    expected, _ = quad(lambda t: rayleigh_coeff(550.0) * math.exp(-_ray_altitude(R_BOTTOM, 0.0, t) / 8000.0),
                       0.0, length, epsrel=1e-10)
    assert atm.optical_depth([550.0], 0.0, 0.0, distance_m=length)[0] == pytest.approx(expected, rel=1e-6)
    assert atm.transmittance([550.0], 0.0, 0.0, distance_m=length)[0] == pytest.approx(math.exp(-expected),
                                                                                        rel=1e-6)


def test_distance_to_boundary():
    atm = sa.bruneton2017()
    d, ground = atm.distance_to_boundary(0.0, 1.0)
    assert d == pytest.approx(60_000.0) and not ground
    d, ground = atm.distance_to_boundary(0.0, 0.0)
    assert d == pytest.approx(math.sqrt(R_TOP ** 2 - R_BOTTOM ** 2)) and not ground
    d, ground = atm.distance_to_boundary(1_000.0, -1.0)
    assert d == pytest.approx(1_000.0) and ground


# --- ozone, Rayleigh, published presets ------------------------------------------------------

def test_ozone_column_is_300_du():
    atm = sa.bruneton2017().without("rayleigh").without("aerosol")
    wl = 550.0
    sigma = float(sigma_ozone(wl))

    def number_density(h):
        return atm.extinction_coefficient([wl], h)[0] / sigma

    column, _ = quad(number_density, 0.0, 60_000.0, points=[10_000.0, 25_000.0, 40_000.0], epsabs=1.0)
    assert column / DU == pytest.approx(300.0, rel=1e-6)


def test_ozone_absent_below_and_above_tent():
    atm = sa.bruneton2017().without("rayleigh").without("aerosol")
    assert np.all(atm.extinction_coefficient(WL, np.array([0.0, 5_000.0, 9_999.0, 40_001.0, 55_000.0])) == 0.0)


def test_rayleigh_sea_level_550():
    atm = sa.rayleigh_only()
    got = atm.scattering_coefficient([550.0], 0.0)[0]
    assert got == pytest.approx(1.24062e-6 * 0.55 ** -4, rel=0.01)
    # Pure scatterer: extinction equals scattering; density falls by e over 8 km.
    assert atm.extinction_coefficient([550.0], 8_000.0)[0] == pytest.approx(got / math.e, rel=1e-12)


def test_hillaire2020_published_values():
    atm = sa.hillaire2020()
    np.testing.assert_allclose(atm["rayleigh"].scattering_coefficient(WL), [5.802e-6, 13.558e-6, 33.1e-6],
                               rtol=5e-3)
    np.testing.assert_allclose(atm["aerosol"].scattering_coefficient(WL), 3.996e-6, rtol=5e-3)
    np.testing.assert_allclose(atm["aerosol"].extinction_coefficient(WL), 4.44e-6, rtol=5e-3)
    ozone = atm["ozone"]
    at_peak = ozone.absorption_coefficient(WL) * ozone.profile.density(25_000.0)
    np.testing.assert_allclose(at_peak, [0.650e-6, 1.881e-6, 0.085e-6], rtol=5e-3)
    assert np.all(ozone.scattering_coefficient(WL) == 0.0)
    assert atm.top_radius_m == 6_460_000.0
    assert atm.bottom_radius_m == 6_360_000.0
    assert np.all(atm.ground_albedo(WL) == 0.0)
    # Sea-level total extinction: Rayleigh + Mie (no ozone at the ground).
    np.testing.assert_allclose(atm.extinction_coefficient(WL, 0.0),
                               np.array([5.802e-6, 13.558e-6, 33.1e-6]) + 4.44e-6, rtol=5e-3)


def test_bruneton2016_measured():
    atm = sa.bruneton2016_measured()
    aer = atm["aerosol"]
    assert aer.angstrom_alpha == 0.8
    assert aer.angstrom_beta == 0.04
    assert isinstance(aer.phase, CornetteShanks) and aer.phase.g == 0.7
    assert aer.single_scattering_albedo == 0.8
    # Angstrom's law: the vertical aerosol optical depth is beta (lambda / 1 um)^-alpha.
    for wl in WL:
        tau, _ = quad(lambda h: aer.extinction_coefficient([wl])[0] * math.exp(-h / 1200.0), 0.0, math.inf)
        assert tau == pytest.approx(0.04 * (wl / 1000.0) ** -0.8, rel=1e-8)
    np.testing.assert_allclose(aer.scattering_coefficient(WL) / aer.extinction_coefficient(WL), 0.8)
    # The rest is Bruneton 2017's.
    assert atm["rayleigh"] == sa.bruneton2017()["rayleigh"]
    assert atm["ozone"] == sa.bruneton2017()["ozone"]
    assert atm.top_radius_m == R_TOP and float(atm.ground_albedo(550.0)) == 0.1


def test_bruneton2017_mie():
    aer = sa.bruneton2017()["aerosol"]
    np.testing.assert_allclose(aer.extinction_coefficient(WL), 4.44e-6, rtol=1e-9)
    np.testing.assert_allclose(aer.scattering_coefficient(WL), 0.9 * 4.44e-6, rtol=1e-9)
    assert aer.phase == CornetteShanks(0.8)


# --- turbidity -------------------------------------------------------------------------------

@pytest.mark.parametrize("T", [1.0, 1.5, 2.0, 3.0, 4.5, 6.0, 8.0, 10.0])
def test_turbidity_round_trip(T):
    atm = sa.from_turbidity(T)
    assert sa.turbidity(atm) == pytest.approx(T, rel=1e-9)
    # Independent tau_a(550): integrate the whole extinction, remove the known Rayleigh and
    # ozone columns.
    thickness = R_TOP - R_BOTTOM
    total, _ = quad(lambda h: atm.extinction_coefficient([550.0], h)[0], 0.0, thickness,
                    points=[1200.0, 8000.0, 10_000.0, 25_000.0, 40_000.0], epsabs=0.0, epsrel=1e-11, limit=200)
    tau_m = rayleigh_coeff(550.0) * 8000.0 * (1.0 - math.exp(-thickness / 8000.0))
    tau_o3 = OZONE_PEAK_N * float(sigma_ozone(550.0)) * 15_000.0
    tau_a = total - tau_m - tau_o3
    assert tau_a == pytest.approx((T - 1.0) * tau_m, rel=1e-6, abs=1e-9)
    # Angstrom alpha 1.3 by default.
    aer = atm["aerosol"]
    ratio = aer.extinction_coefficient([440.0])[0] / max(aer.extinction_coefficient([550.0])[0], 1e-300)
    if T > 1.0:
        assert ratio == pytest.approx((440.0 / 550.0) ** -1.3, rel=1e-12)


def test_turbidity_keeps_other_constituents():
    base = sa.bruneton2016_measured()
    atm = sa.from_turbidity(3.0, base=base)
    assert atm["ozone"] == base["ozone"] and atm["rayleigh"] == base["rayleigh"]
    assert atm["aerosol"].phase == CornetteShanks(0.7)
    assert atm["aerosol"].single_scattering_albedo == 0.8


def test_turbidity_without_aerosol_is_one():
    assert sa.turbidity(sa.rayleigh_only()) == 1.0


# --- phase functions -----------------------------------------------------------------------

def _sphere_integral(f, g=None):
    pts = [] if g is None or abs(g) < 0.5 else [math.copysign(x, g) for x in (0.9, 0.99, 0.999)]
    value, _ = quad(lambda mu: 2.0 * math.pi * f(mu), -1.0, 1.0, points=pts or None, limit=400,
                    epsabs=1e-12, epsrel=1e-11)
    return value


@pytest.mark.parametrize("g", [-0.9, -0.4, 0.0, 0.3, 0.7, 0.8, 0.95, 0.99])
def test_cornette_shanks_normalised_and_asymmetry(g):
    assert _sphere_integral(lambda mu: cornette_shanks_phase(mu, g), g) == pytest.approx(1.0, rel=1e-8)
    mean_mu = _sphere_integral(lambda mu: mu * cornette_shanks_phase(mu, g), g)
    assert cornette_shanks_asymmetry(g) == pytest.approx(mean_mu, rel=1e-7, abs=1e-10)
    assert CornetteShanks(g).asymmetry == pytest.approx(mean_mu, rel=1e-7, abs=1e-10)
    assert _sphere_integral(CornetteShanks(g).evaluate, g) == pytest.approx(1.0, rel=1e-8)


@pytest.mark.parametrize("g", [-0.9, -0.4, 0.0, 0.3, 0.8, 0.99])
def test_henyey_greenstein_normalised_and_asymmetry(g):
    assert _sphere_integral(lambda mu: henyey_greenstein_phase(mu, g), g) == pytest.approx(1.0, rel=1e-8)
    mean_mu = _sphere_integral(lambda mu: mu * henyey_greenstein_phase(mu, g), g)
    assert mean_mu == pytest.approx(g, rel=1e-7, abs=1e-10)
    assert HenyeyGreenstein(g).asymmetry == pytest.approx(mean_mu, rel=1e-7, abs=1e-10)


def test_rayleigh_phase_normalised():
    assert _sphere_integral(rayleigh_phase) == pytest.approx(1.0, rel=1e-12)
    assert _sphere_integral(lambda mu: mu * rayleigh_phase(mu)) == pytest.approx(0.0, abs=1e-14)
    assert rayleigh_phase(1.0) == pytest.approx(3.0 / (8.0 * math.pi))


def test_cornette_shanks_reduces_to_rayleigh_at_g0():
    mu = np.linspace(-1, 1, 11)
    np.testing.assert_allclose(cornette_shanks_phase(mu, 0.0), 3.0 / (16.0 * math.pi) * (1 + mu ** 2))


def test_tabulated_phase_normalised():
    mu = np.linspace(-1.0, 1.0, 41)
    raw = 7.0 * (1.0 + mu ** 2)  # any scale: the class renormalises
    p = TabulatedPhase(tuple(mu), tuple(raw))
    # The linear interpolant integrates to 1 over the sphere (quad broken at every node).
    total, _ = quad(lambda m: 2.0 * math.pi * p.evaluate(m), -1.0, 1.0, points=mu[1:-1], limit=200)
    assert total == pytest.approx(1.0, rel=1e-10)
    # ... and is close to the Rayleigh function it samples (linear interpolation error only).
    np.testing.assert_allclose(p.evaluate(mu), 3.0 / (16.0 * math.pi) * (1 + mu ** 2), rtol=1e-3)
    assert p.asymmetry == pytest.approx(0.0, abs=1e-12)


# --- solar irradiance ------------------------------------------------------------------------

@pytest.fixture(scope="module")
def astm_table():
    pvlib = pytest.importorskip("pvlib")
    table = pvlib.spectrum.get_reference_spectra()
    return table.index.to_numpy(dtype=float), table["extraterrestrial"].to_numpy(dtype=float)


def _brute_bin_mean(grid, values, lo, hi):
    # Exact for the piecewise-linear table: trapezoids on a fine grid that contains every node.
    x = np.union1d(np.linspace(lo, hi, 4001), grid[(grid > lo) & (grid < hi)])
    return np.trapezoid(np.interp(x, grid, values), x) / (hi - lo)


@pytest.mark.parametrize("width", [10.0, 1.0, 25.0])
def test_solar_irradiance_bin_mean(astm_table, width):
    grid, values = astm_table
    wl = np.array([300.0, 305.25, 400.0, 440.0, 550.0, 680.0, 1000.0, 1702.5, 2500.0, 3980.0])
    got = sa.solar_irradiance(wl, bin_width_nm=width)
    expected = [_brute_bin_mean(grid, values, w - width / 2, w + width / 2) for w in wl]
    np.testing.assert_allclose(got, expected, rtol=1e-9)


def test_solar_irradiance_pointwise(astm_table):
    grid, values = astm_table
    wl = np.array([300.0, 300.25, 555.5, 2001.0])
    np.testing.assert_allclose(sa.solar_irradiance(wl, bin_width_nm=0.0), np.interp(wl, grid, values))
    assert sa.solar_irradiance([550.0], 0.0)[0] == values[grid == 550.0][0]


def test_solar_irradiance_total(astm_table):
    grid, values = astm_table
    centres = np.arange(285.0, 4000.0, 10.0)  # 10 nm bins tiling 280-4000 nm
    total = float(np.sum(sa.solar_irradiance(centres)) * 10.0)
    assert total == pytest.approx(np.trapezoid(values, grid), rel=1e-9)
    # ASTM G173 extraterrestrial, 280-4000 nm: about 1348 W m^-2 of the 1366 W m^-2 solar constant.
    assert 1330.0 < total < 1366.1
    # Visible peak: about 1.9-2.1 W m^-2 nm^-1 around 450-550 nm.
    assert 1.8 < sa.solar_irradiance([500.0])[0] < 2.2


# --- serialisation --------------------------------------------------------------------------

def custom_atmosphere():
    return Atmosphere(
        bottom_radius_m=3_389_500.0, top_radius_m=3_489_500.0, name="custom",
        ground_albedo=TabulatedSpectrum((300.0, 500.0, 900.0), (0.05, 0.2, 0.4), source="made up"),
        constituents=(
            Rayleigh(profile=TabulatedProfile((0.0, 10_000.0, 50_000.0), (1.0, 0.3, 0.0), source="table"),
                     density_scale=0.01),
            Aerosol(name="dust", profile=ExponentialProfile(11_000.0), angstrom_alpha=None, angstrom_beta=None,
                    extinction=TabulatedSpectrum((350.0, 600.0, 850.0), (2e-5, 1.5e-5, 1e-5)),
                    single_scattering_albedo=0.95, phase=HenyeyGreenstein(0.6)),
            Absorber(name="no2", profile=PiecewiseLinearProfile((0.0, 2_000.0, 8_000.0), (1.0, 0.8, 0.0)),
                     cross_section=TabulatedSpectrum((350.0, 450.0, 850.0), (5e-23, 6e-23, 1e-24)),
                     column_du=None, number_density_per_m3=1.0e17),
        ))


ATMOSPHERES = {**{name: f for name, f in sa.PRESETS.items()}, "custom": custom_atmosphere,
               "turbidity4": lambda: sa.from_turbidity(4.0)}


@pytest.mark.parametrize("name", sorted(ATMOSPHERES))
def test_to_dict_from_dict_round_trip(name):
    atm = ATMOSPHERES[name]()
    again = Atmosphere.from_dict(atm.to_dict())
    assert again == atm
    # Through TOML text too (what save_scene writes).
    text = tomli_w.dumps({"atmosphere": atm.to_dict()})
    assert Atmosphere.from_dict(tomllib.loads(text)["atmosphere"]) == atm
    np.testing.assert_array_equal(again.extinction_coefficient([450.0, 600.0], np.array([0.0, 5e3, 2e4])),
                                  atm.extinction_coefficient([450.0, 600.0], np.array([0.0, 5e3, 2e4])))


def test_custom_atmosphere_coefficients():
    atm = custom_atmosphere()
    # Absorber: number density times the cross-section, with the piecewise-linear profile.
    h = 1_000.0
    expected = (1.0e17 * np.interp(400.0, (350.0, 450.0, 850.0), (5e-23, 6e-23, 1e-24)) * 0.9
                + 0.01 * rayleigh_coeff(400.0) * np.interp(h, (0.0, 10_000.0, 50_000.0), (1.0, 0.3, 0.0))
                + np.interp(400.0, (350.0, 600.0, 850.0), (2e-5, 1.5e-5, 1e-5)) * math.exp(-h / 11_000.0))
    assert atm.extinction_coefficient([400.0], h)[0] == pytest.approx(expected, rel=1e-12)
    assert float(atm.ground_albedo(700.0)) == pytest.approx(0.3)


def test_with_constituent_and_without():
    atm = sa.bruneton2017()
    assert [c.name for c in atm.without("ozone").constituents] == ["rayleigh", "aerosol"]
    replaced = atm.with_constituent(Aerosol(angstrom_beta=0.1))
    assert [c.name for c in replaced.constituents] == ["rayleigh", "aerosol", "ozone"]
    assert replaced["aerosol"].angstrom_beta == 0.1
    with pytest.raises(KeyError, match="ozone"):
        atm.without("ozone").without("ozone")


@pytest.mark.parametrize("phase", [RayleighPhase(), CornetteShanks(0.8), HenyeyGreenstein(0.6), HenyeyGreenstein(-0.3),
                                   TabulatedPhase((-1.0, 0.0, 1.0), (0.5, 1.0, 3.0))])
def test_each_phase_function_samples_its_own_sampling_density(phase):
    """sample_cosine inverts the CDF of pdf (each class's own pair): 2 pi integral_-1^mu pdf
    equals u to 1e-6, and pdf integrates to 1 over the sphere (NumPy namespace)."""
    mu = np.linspace(-1.0, 1.0, 200_001)
    pdf = phase.pdf(mu)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (pdf[1:] + pdf[:-1]) * np.diff(mu))]) * 2.0 * np.pi
    assert cdf[-1] == pytest.approx(1.0, abs=1e-6)
    u = np.linspace(0.001, 0.999, 999)
    assert np.allclose(np.interp(phase.sample_cosine(u), mu, cdf), u, atol=1e-6)
