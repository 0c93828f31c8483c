"""Polarized transport's pieces: phase matrices (Rayleigh with depolarization, tabulated Mie),
their checks on bad input, and the Stokes conventions of skyref/plugins/polarization.py on a
case with a closed form (an optically thin Rayleigh layer: single scattering, Q / I = P12 / P11).
The whole transport is checked against MYSTIC in tests/test_iprt.py."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from skyref.atmosphere import Atmosphere, Rayleigh
from skyref.atmosphere.phase import MiePhase, RayleighPhase, mie_lognormal, phase_from_dict, read_mie_table
from skyref.atmosphere.spectra import ConstantSpectrum
from skyref.errors import ParameterError

WASO = Path(__file__).parent / "references" / "iprt_phaseA" / "waso.mie.cdf"


def _sphere_integral(f):
    mu, w = np.polynomial.legendre.leggauss(2000)
    return 2.0 * math.pi * float(np.sum(w * f(mu)))


@pytest.mark.parametrize("depolarization", [0.0, 0.0279, 0.1, 0.9])
def test_rayleigh_phase_matrix(depolarization):
    phase = RayleighPhase(depolarization)
    assert _sphere_integral(phase.evaluate) == pytest.approx(1.0, abs=1e-12)
    # Chandrasekhar's form with gamma = rho / (2 - rho), independent of Hansen & Travis's
    gamma = depolarization / (2.0 - depolarization)
    mu = np.linspace(-1.0, 1.0, 41)
    chandrasekhar = 3.0 / (16.0 * math.pi * (1.0 + 2.0 * gamma)) * ((1.0 + 3.0 * gamma) + (1.0 - gamma) * mu ** 2)
    np.testing.assert_allclose(phase.evaluate(mu), chandrasekhar, rtol=1e-12)
    p11, p12, p22, p33, p34, p44 = phase.matrix(mu)
    assert np.all(np.abs([p12, p22, p33, p44]) <= p11 + 1e-15)
    # the degree of polarization of singly scattered light at 90 deg: (1 - rho) / (1 + rho)
    assert -p12[20] / p11[20] == pytest.approx((1.0 - depolarization) / (1.0 + depolarization), rel=1e-12)
    # sampling: the histogram of sampled cosines follows p
    u = (np.arange(200_000) + 0.5) / 200_000
    counts, edges = np.histogram(phase.sample_cosine(u), bins=20, range=(-1.0, 1.0))
    expected = [2.0 * math.pi * np.trapezoid(phase.evaluate(np.linspace(a, b, 51)), np.linspace(a, b, 51))
                for a, b in zip(edges[:-1], edges[1:])]
    np.testing.assert_allclose(counts / u.size, expected, atol=2e-4)


def test_depolarization_out_of_range_is_refused():
    with pytest.raises(ParameterError, match="rayleigh.depolarization"):
        Rayleigh(depolarization=1.0)
    with pytest.raises(ParameterError, match="depolarization"):
        RayleighPhase(-0.1)


def test_mie_table_reads_and_checks():
    phase, albedo = read_mie_table(WASO)
    assert albedo == pytest.approx(0.9757, abs=1e-4)
    assert _sphere_integral(phase.evaluate) == pytest.approx(1.0, rel=1e-3)   # linear in mu vs quadrature
    mu = np.linspace(-1.0, 1.0, 101)
    p11, p12, p22, p33, p34, p44 = phase.matrix(mu)
    assert np.all(np.abs(np.stack([p12, p33, p34])) <= p11 * (1 + 1e-4))
    assert p33[0] == pytest.approx(-p11[0], rel=1e-3) and p12[50] < 0.0     # backscatter, 90 deg
    assert phase_from_dict(phase.to_dict()) == phase
    cosines, values = phase.cosines, list(phase.values)
    with pytest.raises(ParameterError, match="values"):
        MiePhase(cosines, tuple([-1.0] + values[1:]), phase.p12, phase.p33, phase.p34)
    with pytest.raises(ParameterError, match="p12"):
        MiePhase(cosines, tuple(values), tuple(2.0 * v for v in values), phase.p33, phase.p34)
    with pytest.raises(ParameterError, match="mie table"):
        read_mie_table(Path(__file__))


@pytest.mark.parametrize("depolarization", [0.0, 0.03])
def test_thin_rayleigh_layer_polarizes_as_single_scattering(mi, depolarization):
    """Optical thickness 1e-3, sun at zenith 40 deg, seen from the ground. Light scattered once
    (the path tracer's order 1) has Q / I = P12 / P11 exactly in the sun's vertical plane, where
    U = 0 (the meridian frame is the scattering plane's there); off it U is antisymmetric about
    that plane. Order 1 alone, because its I and Q share their noise: their ratio is exact to
    ~1e-4 at this sample count (the whole sky's, to ~3e-3)."""
    from skyref.render import build_integrator
    from skyref.scene import Observer, Scene, Sun, direction_from_angles

    profile_column = 8000.0 * (1.0 - math.exp(-60_000.0 / 8000.0))
    rayleigh = Rayleigh(scattering=ConstantSpectrum(1e-3 / profile_column), depolarization=depolarization)
    scene = Scene(atmosphere=Atmosphere(constituents=(rayleigh,), ground_albedo=0.0), sun=Sun(40.0, 0.0),
                  observer=Observer(0.0), wavelengths=[550.0])
    integrator = build_integrator(scene, geometry="plane_parallel", polarized=True)
    zeniths = np.array([20.0, 50.0, 70.0, 50.0, 50.0])
    azimuths = np.array([180.0, 180.0, 0.0, 90.0, 270.0])
    image = integrator.render_directions(direction_from_angles(zeniths, azimuths), seed=3, spp=1 << 16).numpy()
    stokes = image[:, 1, :, 0]                                                  # order 1: (M, 4)
    q, u = stokes[:, 1] / stokes[:, 0], stokes[:, 2] / stokes[:, 0]
    sun = direction_from_angles(40.0, 0.0)
    mu = direction_from_angles(zeniths, azimuths) @ sun
    p11, p12 = RayleighPhase(depolarization).matrix(mu)[:2]
    np.testing.assert_allclose(q[:3], (p12 / p11)[:3], atol=1e-3)
    np.testing.assert_allclose(u[:3], 0.0, atol=1e-3)
    assert u[3] == pytest.approx(-u[4], abs=1e-3) and abs(u[3]) > 0.1
    assert np.all(image[:, :, 3, :] == 0.0)                                     # no V from Rayleigh


def test_mie_lognormal_small_particles_scatter_like_rayleigh():
    """Particles far smaller than the wavelength (x ~ 0.01) scatter as dipoles: Rayleigh's
    matrix (depolarization 0), and without absorption all of it."""
    phase, albedo = mie_lognormal(550.0, 1.33 + 0.0j, 0.0005, 1.2, max_radius_um=0.002, radii=40)
    mu = np.linspace(-1.0, 1.0, 21)
    p11, p12, _, p33, p34, _ = phase.matrix(mu)
    r11, r12, _, r33, _, _ = RayleighPhase().matrix(mu)
    np.testing.assert_allclose(p11, r11, rtol=2e-3)
    np.testing.assert_allclose(p12 / p11, r12 / r11, atol=2e-3)
    np.testing.assert_allclose(p33 / p11, r33 / r11, atol=2e-3)
    np.testing.assert_allclose(p34 / p11, 0.0, atol=2e-3)
    assert albedo == pytest.approx(1.0, abs=1e-6)


def test_mie_lognormal_has_the_sign_conventions_of_the_iprt_table():
    """A water-soluble-like aerosol (OPAC's parameters; the table's own size distribution is not
    stated in the file) has the IPRT table's signs where both are large: P12 < 0 at 60-120 deg
    (polarized perpendicular to the scattering plane, as Q's sign says), P34 < 0 at 30-60 deg and
    > 0 at 120-150 deg, and absorbs a little."""
    phase, albedo = mie_lognormal(350.0, 1.422 + 0.002649j, 0.0262, 2.24, radii=100)
    table, table_albedo = read_mie_table(WASO)
    mu = np.cos(np.radians([30.0, 60.0, 90.0, 120.0, 150.0]))
    for p in (phase, table):
        p11, p12, _, _, p34, _ = p.matrix(mu)
        assert np.all(p12[1:4] < 0.0) and np.all(p34[:2] < 0.0) and np.all(p34[3:] > 0.0)
    assert 0.97 < albedo < 1.0 and 0.97 < table_albedo < 1.0


def test_mie_lognormal_refuses_bad_particles():
    with pytest.raises(ParameterError, match="refractive_index.imag"):
        mie_lognormal(550.0, 1.5 - 0.01j, 0.1, 2.0)
    with pytest.raises(ParameterError, match="geometric_std"):
        mie_lognormal(550.0, 1.5 + 0.01j, 0.1, 1.0)
