"""Colour conversions against CIE definitions computed here from colour-science's tables."""

import colour
import numpy as np
import pytest

from skyref import color

CMFS = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
CMF_WL = np.asarray(CMFS.wavelengths)
CMF = np.asarray(CMFS.values)
K_M = 683.0


def trapezoid(y, x):
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(x)))


def test_flat_spectrum_luminance():
    wl = np.arange(360.0, 831.0, 1.0)
    ybar_integral = trapezoid(CMF[:, 1], CMF_WL)
    assert abs(ybar_integral - 106.86) < 0.01                      # the CIE's published value
    luminance = color.spectral_to_luminance(np.ones(wl.size), wl)
    assert luminance == pytest.approx(K_M * ybar_integral, rel=1e-12)
    assert color.spectral_to_xyz(np.ones(wl.size), wl)[1] == pytest.approx(luminance, rel=1e-12)


def test_equal_energy_chromaticity():
    wl = np.arange(380.0, 781.0, 5.0)
    xyz = color.spectral_to_xyz(np.full(wl.size, 0.02), wl)
    x, y = xyz[:2] / xyz.sum()
    assert x == pytest.approx(1 / 3, abs=2e-3) and y == pytest.approx(1 / 3, abs=2e-3)


def test_sparse_rgb_grid_is_interpolated_then_integrated():
    # A flat spectrum sampled at 680/550/440 nm stays flat after interpolation with constant
    # extrapolation: the full CIE integrals.
    xyz = color.spectral_to_xyz(np.full(3, 2.0), [680.0, 550.0, 440.0])
    expected = 2.0 * K_M * np.array([trapezoid(CMF[:, c], CMF_WL) for c in range(3)])
    assert np.allclose(xyz, expected, rtol=1e-12)
    # A linear ramp in wavelength is reproduced exactly between the samples and held beyond.
    wl = np.array([440.0, 550.0, 680.0])
    ramp = (wl - 400.0) / 100.0
    held = np.interp(CMF_WL, wl, ramp)
    expected_y = K_M * trapezoid(held * CMF[:, 1], CMF_WL)
    assert color.spectral_to_luminance(ramp[::-1], wl[::-1]) == pytest.approx(expected_y, rel=1e-12)


def test_dense_grid_uses_trapezoid_on_given_grid():
    wl = np.arange(400.0, 701.0, 20.0)
    radiance = np.linspace(1.0, 3.0, wl.size)
    ybar = np.interp(wl, CMF_WL, CMF[:, 1])
    assert color.spectral_to_luminance(radiance, wl) == pytest.approx(K_M * trapezoid(radiance * ybar, wl), rel=1e-12)


def test_d65_is_srgb_white():
    d65 = colour.SDS_ILLUMINANTS["D65"]
    rgb = color.spectral_to_linear_srgb(np.asarray(d65.values) * 0.01, np.asarray(d65.wavelengths))
    assert np.all(rgb > 0)
    assert np.ptp(rgb) / rgb.mean() < 0.01
    # Absolute scale: R = G = B = Y for white.
    y = color.spectral_to_luminance(np.asarray(d65.values) * 0.01, np.asarray(d65.wavelengths))
    assert rgb.mean() == pytest.approx(y, rel=0.01)


def test_shapes_and_spectral_axis_last():
    wl = np.array([680.0, 550.0, 440.0])
    radiance = np.random.default_rng(0).random((4, 5, 3))
    rgb = color.spectral_to_linear_srgb(radiance, wl)
    assert rgb.shape == (4, 5, 3)
    assert np.allclose(rgb[2, 3], color.spectral_to_linear_srgb(radiance[2, 3], wl))
    assert np.allclose(color.linear_srgb_to_xyz(rgb), color.spectral_to_xyz(radiance, wl))


def test_tonemap():
    rng = np.random.default_rng(3)
    rgb = rng.random((20, 30, 3)) * 5000.0
    rgb[0, 0] = np.nan
    image = color.tonemap_srgb8(rgb)
    assert image.dtype == np.uint8 and image.shape == (20, 30, 3)
    assert np.all(image[0, 0] == 0)
    # Grey of luminance equal to the 99th percentile: exposure 0.8, Reinhard 0.8 / 1.8, sRGB OETF.
    grey = np.full((1, 1, 3), 7.0)
    expected = 1.055 * (0.8 / 1.8) ** (1 / 2.4) - 0.055
    assert int(color.tonemap_srgb8(grey)[0, 0, 0]) == round(expected * 255)
    # Explicit exposure; black stays black and order is kept.
    ramp = np.linspace(0, 10, 50)[:, None, None] * np.ones((1, 1, 3))
    out = color.tonemap_srgb8(ramp, exposure=0.5)[:, 0, 0].astype(int)
    assert out[0] == 0 and np.all(np.diff(out) >= 0) and out[-1] < 255


def test_ciede2000():
    rgb = np.random.default_rng(4).random((6, 6, 3)) * 100.0
    assert np.all(color.ciede2000(rgb, rgb) == 0.0)
    # A common normalisation: scaling both images by the same factor changes nothing.
    assert np.allclose(color.ciede2000(rgb, rgb * 1.05), color.ciede2000(rgb * 7, rgb * 7 * 1.05))
    # Against a hand-built reference: pure white vs 2x darker grey at the given white.
    white = np.array([1.0, 1.0, 1.0])
    de = color.ciede2000(white, white * 0.5, white_luminance=1.0)
    l_half = 116 * 0.5 ** (1 / 3) - 16
    # CIEDE2000 for a pure lightness difference: dL / S_L, S_L = 1 + 0.015 (L_mean - 50)^2 / sqrt(20 + (L_mean - 50)^2)
    l_mean = (100 + l_half) / 2
    s_l = 1 + 0.015 * (l_mean - 50) ** 2 / np.sqrt(20 + (l_mean - 50) ** 2)
    assert float(de) == pytest.approx((100 - l_half) / s_l, rel=1e-4)
