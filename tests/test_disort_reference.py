"""Validation of the plane-parallel DISORT reference (tests/references/disort.py) itself,
independently of skyref's path tracer: phase moments, the direction mapping (against a numerical
single-scattering integral), energy conservation, layering convergence."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("nanodisort")

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # `tests.references` under plain pytest

from skyref.atmosphere import (Aerosol, Atmosphere, CornetteShanks, HenyeyGreenstein,  # noqa: E402
                               RayleighPhase, Rayleigh, bruneton2016_measured, bruneton2017)
from skyref.atmosphere.phase import cornette_shanks_asymmetry  # noqa: E402
from tests.references.disort import (DEFAULT_N_LAYERS, disort_fluxes, disort_radiance,  # noqa: E402
                                     layer_altitudes, layer_optics, legendre_moments,
                                     single_scattering_radiance)

UP_VIEWS = np.array([0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 85.0])
AZIMUTHS = np.array([0.0, 90.0, 180.0])


# --- 1. phase moments ------------------------------------------------------------------------

@pytest.mark.parametrize("g", [0.0, 0.5, 0.8, 0.9, -0.7])
def test_henyey_greenstein_moments_are_powers_of_g(g):
    chi = legendre_moments(HenyeyGreenstein(g), 500, normalise=False)
    assert np.max(np.abs(chi - g ** np.arange(501))) < 1e-9


@pytest.mark.parametrize("g", [0.3, 0.7, 0.8, 0.9])
def test_cornette_shanks_moments(g):
    chi = legendre_moments(CornetteShanks(g), 500, normalise=False)
    assert chi[0] == pytest.approx(1.0, abs=1e-10)          # normalised over the sphere
    assert chi[1] == pytest.approx(cornette_shanks_asymmetry(g), abs=1e-10)
    # Cross-check moment 2 against an independent adaptive integral of the formula.
    from scipy.integrate import quad

    def p2(mu):
        return 2 * math.pi * CornetteShanks(g).evaluate(mu) * 0.5 * (3 * mu * mu - 1)

    ref, _ = quad(p2, -1.0, 1.0, points=[1.0 - (1 - g) ** 2], limit=200, epsabs=1e-13)
    assert chi[2] == pytest.approx(ref, abs=1e-9)
    assert abs(chi[400]) < 1e-8 or g > 0.95                   # 400 moments are enough up to 0.9


def test_rayleigh_moments_exact_and_numerical():
    assert np.array_equal(legendre_moments(RayleighPhase(), 4), [1.0, 0.0, 0.1, 0.0, 0.0])
    numerical = legendre_moments(lambda mu: RayleighPhase().evaluate(mu), 6)
    assert np.allclose(numerical, [1.0, 0.0, 0.1, 0, 0, 0, 0], atol=1e-12)


def test_layer_optics_mix_is_scattering_weighted():
    atm = bruneton2017()
    edges = layer_altitudes(atm, 50, [0.0])
    dtau, ssa, pmom = layer_optics(atm, 550.0, edges, 400)
    assert np.sum(dtau) == pytest.approx(float(atm.vertical_optical_depth(550.0)[0]), rel=1e-12)
    r, a = atm["rayleigh"], atm["aerosol"]
    top_first = edges[::-1]
    tr = r.scattering_coefficient([550.0])[0] * np.array(
        [r.profile.column(lo, hi) for hi, lo in zip(top_first[:-1], top_first[1:])])
    ta = a.scattering_coefficient([550.0])[0] * np.array(
        [a.profile.column(lo, hi) for hi, lo in zip(top_first[:-1], top_first[1:])])
    assert np.allclose(ssa * dtau, tr + ta, rtol=1e-12)
    chi_a = legendre_moments(CornetteShanks(0.8), 400)
    assert np.allclose(pmom[1], ta * chi_a[1] / (tr + ta), rtol=1e-12)
    assert np.allclose(pmom[2], (0.1 * tr + ta * chi_a[2]) / (tr + ta), rtol=1e-12)


# --- 2. single scattering: units and the direction mapping -------------------------------------

def _thin(scale, aerosol_beta=0.0):
    constituents = [Rayleigh(density_scale=scale)]
    if aerosol_beta:
        constituents.append(Aerosol(angstrom_beta=aerosol_beta, single_scattering_albedo=0.9))
    return Atmosphere(constituents=tuple(constituents), ground_albedo=0.0)


@pytest.mark.parametrize("sun_zenith", [30.0, 60.0])
def test_thin_rayleigh_matches_single_scattering(sun_zenith):
    atm = _thin(0.01)  # vertical optical depth 4e-4 at 700 nm
    vza, raz = UP_VIEWS[:, None], AZIMUTHS[None, :]
    dis = disort_radiance(atm, 700.0, sun_zenith, vza, raz, solar_irradiance=1.7, n_streams=16)
    ss = single_scattering_radiance(atm, 700.0, sun_zenith, vza, raz, solar_irradiance=1.7)
    assert dis.shape == (UP_VIEWS.size, AZIMUTHS.size)
    excess = dis / ss - 1.0  # multiple scattering only adds
    assert np.all(excess > -1e-5) and np.all(excess < 5e-3), excess


@pytest.mark.parametrize("sun_zenith", [30.0, 60.0])
def test_thin_aerosol_matches_single_scattering(sun_zenith):
    """Rayleigh + a Cornette–Shanks aerosol: the forward peak makes the azimuth mapping visible;
    views up from the ground, up and down from 5 km, the sun's own direction included; the excess
    over single scattering shrinks in proportion to the optical depth (multiple scattering)."""
    vza = np.concatenate((UP_VIEWS, [sun_zenith - 1.0, sun_zenith, sun_zenith + 1.0]))[:, None]
    raz = np.array([0.0, 5.0, 90.0, 180.0, 270.0])[None, :]
    excess = {}
    for scale in (1e-2, 1e-3):
        atm = _thin(scale, aerosol_beta=0.1 * scale)
        for h, views in ((0.0, vza), (5000.0, vza), (5000.0, 180.0 - vza)):
            dis = disort_radiance(atm, 550.0, sun_zenith, views, raz, observer_altitude_m=h,
                                  n_streams=32)
            ss = single_scattering_radiance(atm, 550.0, sun_zenith, views, raz, observer_altitude_m=h)
            excess[scale, h, views[0, 0]] = dis / ss - 1.0
    for (scale, h, v0), e in excess.items():
        assert np.all(e > -1e-5), (scale, h, v0, e)
        if scale == 1e-3:
            assert np.all(e < 5e-3), (h, v0, e)
            assert np.all(e < 0.15 * excess[1e-2, h, v0] + 1e-5), (h, v0)
    # The aureole is where it should be: looking at the sun beats looking away from it.
    atm = _thin(1e-3, aerosol_beta=1e-4)
    near, far = disort_radiance(atm, 550.0, sun_zenith, sun_zenith + 2.0, [0.0, 180.0], n_streams=16)
    assert near > 10.0 * far


def test_ground_and_symmetry():
    atm = bruneton2017().replace(ground_albedo=0.3)
    # Relative azimuths phi and -phi (and phi + 360) see the same plane-parallel sky.
    a = disort_radiance(atm, 500.0, 40.0, 50.0, [30.0, -30.0, 390.0, 330.0], n_streams=16, n_layers=40)
    assert np.allclose(a, a[0], rtol=1e-12)
    # Looking down from the ground sees the Lambertian ground: albedo * E_down / pi, isotropic.
    down = disort_radiance(atm, 500.0, 40.0, [100.0, 150.0, 180.0], 0.0,
                           n_streams=16, n_layers=40)
    f = disort_fluxes(atm, 500.0, 40.0, [0.0], n_streams=16, n_layers=40)
    e_down = f["direct_down"][0] + f["diffuse_down"][0]
    assert np.allclose(down, 0.3 * e_down / math.pi, rtol=1e-6)


# --- 3. energy conservation ---------------------------------------------------------------------

def test_conservative_atmosphere_over_white_ground_reflects_everything():
    atm = Atmosphere(constituents=(Rayleigh(), Aerosol(single_scattering_albedo=1.0, angstrom_beta=0.1,
                                                       phase=CornetteShanks(0.8))),
                     ground_albedo=1.0)
    top = atm.thickness_m
    for sza in (0.0, 30.0, 60.0, 80.0):
        mu0 = math.cos(math.radians(sza))
        f = disort_fluxes(atm, 450.0, sza, [0.0, top], n_streams=32)
        assert f["diffuse_up"][1] == pytest.approx(mu0, rel=5e-3)
        assert f["diffuse_up"][1] == pytest.approx(mu0, rel=1e-6)  # measured: 1e-8
    # The same from the radiances: integrate the upward radiance at the top over the hemisphere
    # (Gauss–Legendre in mu, trapezoid in azimuth over [0, 180], exact for the Fourier series).
    sza, mu0 = 60.0, 0.5
    x, w = np.polynomial.legendre.leggauss(24)
    mu, w = 0.5 * (x + 1.0), 0.5 * w
    phi = np.linspace(0.0, 180.0, 19)
    w_phi = np.full(phi.size, math.radians(10.0))
    w_phi[[0, -1]] *= 0.5
    radiance = disort_radiance(atm, 450.0, sza, np.degrees(np.arccos(-mu))[:, None], phi[None, :],
                               observer_altitude_m=top, n_streams=32)
    flux = 2.0 * np.sum(radiance * (mu * w)[:, None] * w_phi[None, :])
    assert flux == pytest.approx(mu0, rel=5e-3)
    assert flux == pytest.approx(mu0, rel=1e-5)  # measured: 3e-8


# --- 4. layering ------------------------------------------------------------------------------------

@pytest.mark.parametrize("atm,wl,sza,h", [(bruneton2017(), 550.0, 60.0, 0.0),
                                          (bruneton2016_measured(), 400.0, 80.0, 2000.0)])
def test_layering_is_converged(atm, wl, sza, h):
    vza = np.array([0.0, 30.0, 60.0, 80.0, 85.0, 95.0, 120.0, 180.0])[:, None]
    raz = AZIMUTHS[None, :]
    base = disort_radiance(atm, wl, sza, vza, raz, observer_altitude_m=h, n_streams=32)
    fine = disort_radiance(atm, wl, sza, vza, raz, observer_altitude_m=h, n_streams=32,
                           n_layers=2 * DEFAULT_N_LAYERS)
    assert np.max(np.abs(base / fine - 1.0)) < 5e-4
