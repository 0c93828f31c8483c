"""Density profiles: analytic columns against closed forms and quadrature, majorants, and the
same formula in NumPy and JAX."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from skyref.atmosphere import ExponentialProfile, PiecewiseLinearProfile, TabulatedProfile

# A made-up standard-atmosphere-like table (altitude m, relative density); not monotonic, with a
# non-zero end value so that the constant extension beyond the last node matters.
TABLE_H = (0.0, 2_000.0, 5_000.0, 11_000.0, 20_000.0, 32_000.0)
TABLE_D = (1.0, 0.82, 0.6, 0.3, 0.35, 0.05)


def tent_area(bottom, peak, top, height, lower, upper):
    """Area of the triangle (bottom, 0)-(peak, height)-(top, 0) between lower and upper, by
    integrating each linear flank in closed form."""

    def rising(a, b):  # integral of height (h - bottom)/(peak - bottom) over [a, b]
        return height * ((b - bottom) ** 2 - (a - bottom) ** 2) / (2.0 * (peak - bottom))

    def falling(a, b):  # integral of height (top - h)/(top - peak) over [a, b]
        return height * ((top - a) ** 2 - (top - b) ** 2) / (2.0 * (top - peak))

    area = 0.0
    a, b = max(lower, bottom), min(upper, peak)
    if b > a:
        area += rising(a, b)
    a, b = max(lower, peak), min(upper, top)
    if b > a:
        area += falling(a, b)
    return area


def table_density(h):
    """Independent linear interpolation of the table, constant outside it."""
    return float(np.interp(h, TABLE_H, TABLE_D))


# --- exponential -------------------------------------------------------------------------

@pytest.mark.parametrize("H", [1200.0, 8000.0, 250.0])
@pytest.mark.parametrize("lower,upper", [(0.0, 60_000.0), (0.0, math.inf), (3_000.0, 4_500.0),
                                         (10_000.0, 100_000.0)])
def test_exponential_column_closed_form(H, lower, upper):
    p = ExponentialProfile(H)
    top_term = 0.0 if math.isinf(upper) else math.exp(-upper / H)
    expected = H * (math.exp(-lower / H) - top_term)
    assert p.column(lower, upper) == pytest.approx(expected, rel=1e-12)
    numeric, _ = quad(lambda h: float(p.density(h)), lower, upper, epsabs=0.0, epsrel=1e-11,
                      limit=200, points=None if math.isinf(upper) else [lower + H, lower + 5 * H])
    assert p.column(lower, upper) == pytest.approx(numeric, rel=1e-8)


def test_exponential_density_values():
    p = ExponentialProfile(8000.0)
    assert float(p.density(0.0)) == 1.0
    assert float(p.density(8000.0)) == pytest.approx(math.exp(-1.0), rel=1e-14)
    assert float(p.density(-8000.0)) == pytest.approx(math.e, rel=1e-14)


# --- piecewise linear / tent ------------------------------------------------------------

@pytest.mark.parametrize("lower,upper", [(0.0, 60_000.0), (0.0, math.inf), (12_000.0, 30_000.0),
                                         (26_000.0, 38_000.0), (0.0, 15_000.0), (45_000.0, 80_000.0)])
def test_tent_column_is_triangle_area(lower, upper):
    p = PiecewiseLinearProfile.tent(10_000.0, 25_000.0, 40_000.0, peak_density=2.5)
    expected = tent_area(10_000.0, 25_000.0, 40_000.0, 2.5, lower, upper)
    assert p.column(lower, upper) == pytest.approx(expected, rel=1e-12, abs=1e-9)
    if math.isfinite(upper):
        numeric, _ = quad(lambda h: float(p.density(h)), lower, upper, epsabs=1e-9,
                          points=[x for x in (10_000.0, 25_000.0, 40_000.0) if lower < x < upper])
        assert p.column(lower, upper) == pytest.approx(numeric, rel=1e-9, abs=1e-6)


def test_full_tent_column_is_half_base_times_height():
    p = PiecewiseLinearProfile.tent(10_000.0, 25_000.0, 40_000.0)
    assert p.column() == pytest.approx(0.5 * 30_000.0 * 1.0, rel=1e-14)


def test_tent_density_shape():
    p = PiecewiseLinearProfile.tent(10_000.0, 25_000.0, 40_000.0)
    h = np.array([0.0, 10_000.0, 17_500.0, 25_000.0, 32_500.0, 40_000.0, 90_000.0])
    np.testing.assert_allclose(p.density(h), [0, 0, 0.5, 1, 0.5, 0, 0], atol=1e-15)


def test_piecewise_column_with_constant_extensions():
    # Nodes (1 km, 2), (3 km, 4): constant 2 below 1 km, constant 4 above 3 km.
    p = PiecewiseLinearProfile((1_000.0, 3_000.0), (2.0, 4.0))
    expected = 2.0 * 1_000.0 + 0.5 * (2.0 + 4.0) * 2_000.0 + 4.0 * 2_000.0  # over [0, 5 km]
    assert p.column(0.0, 5_000.0) == pytest.approx(expected, rel=1e-13)
    assert p.column(0.0, math.inf) == math.inf


@pytest.mark.parametrize("lower,upper", [(0.0, 40_000.0), (1_000.0, 15_000.0), (12_000.0, 50_000.0),
                                         (-500.0, 500.0)])
def test_tabulated_column(lower, upper):
    p = TabulatedProfile(TABLE_H, TABLE_D, source="test table")
    # Closed form: trapezoids over the breakpoints, plus the constant tails.
    nodes = sorted({lower, upper, *[h for h in TABLE_H if lower < h < upper]})
    expected = sum(0.5 * (table_density(a) + table_density(b)) * (b - a) for a, b in zip(nodes, nodes[1:]))
    assert p.column(lower, upper) == pytest.approx(expected, rel=1e-12)
    numeric, _ = quad(table_density, lower, upper, points=[h for h in TABLE_H if lower < h < upper],
                      epsabs=1e-9, limit=200)
    assert p.column(lower, upper) == pytest.approx(numeric, rel=1e-8)
    h = np.linspace(lower, upper, 101)
    np.testing.assert_allclose(p.density(h), [table_density(x) for x in h], rtol=1e-12, atol=1e-15)


def test_tabulated_from_csv(tmp_path):
    path = tmp_path / "profile.csv"
    path.write_text("# altitude_m, density\n" + "\n".join(f"{h},{d}" for h, d in zip(TABLE_H, TABLE_D)))
    p = TabulatedProfile.from_csv(path)
    assert p.altitudes_m == TABLE_H and p.densities == TABLE_D
    assert p.source == str(path)


# --- majorants ------------------------------------------------------------------------------

PROFILES = {
    "exponential": ExponentialProfile(1200.0),
    "tent": PiecewiseLinearProfile.tent(10_000.0, 25_000.0, 40_000.0),
    "tabulated": TabulatedProfile(TABLE_H, TABLE_D),
}


@pytest.mark.parametrize("name", sorted(PROFILES))
@settings(max_examples=40, deadline=None)
@given(a=st.floats(0.0, 60_000.0), b=st.floats(0.0, 60_000.0),
       u=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=20))
def test_max_density_bounds_density(name, a, b, u):
    p = PROFILES[name]
    lower, upper = min(a, b), max(a, b)
    bound = float(p.max_density(lower, upper))
    h = lower + (upper - lower) * np.asarray(u)
    assert np.all(p.density(h) <= bound * (1 + 1e-12) + 1e-300)


@pytest.mark.parametrize("name", sorted(PROFILES))
@pytest.mark.parametrize("lower,upper", [(0.0, 60_000.0), (5_000.0, 12_000.0), (20_000.0, 30_000.0),
                                         (26_000.0, 35_000.0), (12_500.0, 13_000.0), (41_000.0, 55_000.0)])
def test_max_density_is_tight(name, lower, upper):
    p = PROFILES[name]
    # Dense sampling that includes every node inside the interval: the true maximum of a
    # piecewise-linear or monotone function is on this grid.
    nodes = [h for h in getattr(p, "altitudes_m", ()) if lower <= h <= upper]
    h = np.unique(np.concatenate([np.linspace(lower, upper, 20_001), nodes]))
    assert float(p.max_density(lower, upper)) == pytest.approx(float(np.max(p.density(h))), rel=1e-12,
                                                               abs=1e-15)


def test_max_density_vectorised():
    p = PROFILES["tent"]
    lower = np.array([0.0, 30_000.0, 0.0])
    upper = np.array([5_000.0, 35_000.0, 60_000.0])
    expected = [0.0, float(p.density(30_000.0)), 1.0]
    np.testing.assert_allclose(p.max_density(lower, upper), expected, atol=1e-15)


# --- NumPy vs JAX ----------------------------------------------------------------------------

@pytest.mark.parametrize("name", sorted(PROFILES))
def test_density_numpy_equals_jax(name):
    jax = pytest.importorskip("jax")
    import jax.numpy as jnp

    p = PROFILES[name]
    h = np.linspace(-1_000.0, 70_000.0, 997)
    with jax.enable_x64(True):
        got = np.asarray(p.density(jnp.asarray(h), xp=jnp))
        got_max = np.asarray(p.max_density(jnp.asarray(h[:-1]), jnp.asarray(h[1:]), xp=jnp))
    np.testing.assert_allclose(got, p.density(h, xp=np), rtol=1e-14, atol=1e-300)
    np.testing.assert_allclose(got_max, p.max_density(h[:-1], h[1:], xp=np), rtol=1e-14, atol=1e-300)
