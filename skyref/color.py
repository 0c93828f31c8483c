"""Spectral radiance -> CIE XYZ -> linear sRGB, luminance, display images, colour differences
(through colour-science).

Units: radiance in W m^-2 sr^-1 nm^-1 with the spectral axis last; wavelengths in nm. XYZ is
*absolute*: Y is luminance in cd m^-2 (683 lm/W times the integral of L ybar over wavelength,
CIE 1931 2-degree observer), X and Z on the same scale. Linear sRGB keeps that scale:
R = G = B = 1 is D65 white of luminance 1 cd m^-2.
"""

from __future__ import annotations

import functools

import colour
import numpy as np

__all__ = ["SPARSE_GRID_POINTS", "xyz_matrix", "spectral_to_xyz", "spectral_to_luminance", "xyz_to_linear_srgb",
           "linear_srgb_to_xyz", "spectral_to_linear_srgb", "srgb_luminance", "default_exposure", "tonemap_srgb8",
           "ciede2000"]

#: Wavelength grids with fewer points than this are treated as sparse samples of a smooth
#: spectrum (see :func:`spectral_to_xyz`).
SPARSE_GRID_POINTS = 8

_CMFS_NAME = "CIE 1931 2 Degree Standard Observer"
_DISPLAY_PERCENTILE = 99.0
_DISPLAY_VALUE = 0.8


@functools.lru_cache(maxsize=1)
def _srgb() -> colour.RGB_Colourspace:
    # Matrices derived from the primaries and D65 white: exact inverses of each other, where
    # colour's defaults are the rounded IEC 61966-2-1 matrices (which disagree at 1e-4).
    colourspace = colour.RGB_COLOURSPACES["sRGB"].copy()
    colourspace.use_derived_transformation_matrices(True)
    return colourspace


@functools.lru_cache(maxsize=1)
def _cmfs() -> tuple[np.ndarray, np.ndarray]:
    cmfs = colour.MSDS_CMFS[_CMFS_NAME]
    return np.asarray(cmfs.wavelengths, dtype=np.float64), np.asarray(cmfs.values, dtype=np.float64)


def _trapezoid_weights(wavelengths: np.ndarray) -> np.ndarray:
    """Weights w such that sum(f * w) is the trapezoidal integral of f on the sorted grid, nm."""
    if wavelengths.size == 1:
        return np.ones(1)
    steps = np.diff(wavelengths)
    weights = np.zeros(wavelengths.size)
    weights[:-1] += 0.5 * steps
    weights[1:] += 0.5 * steps
    return weights


def xyz_matrix(wavelengths_nm) -> np.ndarray:
    """(N, 3) matrix M with XYZ = radiance @ M (absolute XYZ, see :func:`spectral_to_xyz`)."""
    wl = np.asarray(wavelengths_nm, dtype=np.float64).reshape(-1)
    if wl.size == 0 or not np.all(np.isfinite(wl)) or np.unique(wl).size != wl.size:
        raise ValueError(f"wavelengths_nm must be distinct finite numbers, got {wl}")
    order = np.argsort(wl)
    cmf_wl, cmf = _cmfs()
    k_m = float(colour.constants.CONSTANT_K_M)
    if wl.size < SPARSE_GRID_POINTS:
        # The spectrum, interpolated linearly onto the CMF grid (constant beyond its ends), is
        # linear in the N samples: interpolating each unit vector gives the (471, N) operator.
        basis = np.stack([np.interp(cmf_wl, wl[order], np.eye(wl.size)[i]) for i in range(wl.size)], axis=1)
        sorted_matrix = basis.T @ (cmf * _trapezoid_weights(cmf_wl)[:, None])
    else:
        sampled = np.stack([np.interp(wl[order], cmf_wl, cmf[:, c], left=0.0, right=0.0) for c in range(3)], axis=1)
        sorted_matrix = sampled * _trapezoid_weights(wl[order])[:, None]
    matrix = np.empty_like(sorted_matrix)
    matrix[order] = sorted_matrix
    return k_m * matrix


def spectral_to_xyz(radiance, wavelengths_nm) -> np.ndarray:
    """Absolute CIE 1931 XYZ (Y in cd m^-2) of spectral radiance ``(..., N)`` sampled at
    ``wavelengths_nm`` (N values in any order): X = 683 * integral L xbar dlambda, etc.

    Dense grids (8 or more wavelengths) use trapezoidal weights on the given grid with the CMFs
    interpolated onto it (zero outside 360-830 nm). Sparse grids (fewer than 8, e.g. skyref's
    "rgb" set 680/550/440 nm) are an approximation: the spectrum is first interpolated linearly
    in wavelength onto 360-830 nm every 1 nm, held constant beyond its first and last samples,
    and then integrated against the CMFs.
    """
    return np.asarray(radiance, dtype=np.float64) @ xyz_matrix(wavelengths_nm)


def spectral_to_luminance(radiance, wavelengths_nm) -> np.ndarray:
    """Luminance (cd m^-2) of spectral radiance ``(..., N)``: the Y of :func:`spectral_to_xyz`."""
    return np.asarray(radiance, dtype=np.float64) @ xyz_matrix(wavelengths_nm)[:, 1]


def xyz_to_linear_srgb(xyz) -> np.ndarray:
    """Linear sRGB of absolute XYZ ``(..., 3)``, on the same scale (R = G = B = Y for D65 white).

    No chromatic adaptation: XYZ here is the radiometric colour of the scene and sRGB's own
    white is D65, so the plain XYZ -> RGB matrix applies (derived from sRGB's primaries and
    white point rather than the rounded matrix of the standard).
    """
    return colour.XYZ_to_RGB(np.asarray(xyz, dtype=np.float64), _srgb(), chromatic_adaptation_transform=None)


def linear_srgb_to_xyz(rgb) -> np.ndarray:
    """Absolute XYZ of linear sRGB ``(..., 3)``; inverse of :func:`xyz_to_linear_srgb`."""
    return colour.RGB_to_XYZ(np.asarray(rgb, dtype=np.float64), _srgb(), chromatic_adaptation_transform=None)


def spectral_to_linear_srgb(radiance, wavelengths_nm) -> np.ndarray:
    """Linear sRGB ``(..., 3)`` of spectral radiance ``(..., N)`` (scale: Y in cd m^-2)."""
    return xyz_to_linear_srgb(spectral_to_xyz(radiance, wavelengths_nm))


def srgb_luminance(rgb) -> np.ndarray:
    """Luminance of linear sRGB ``(..., 3)`` (the Y row of sRGB -> XYZ), same scale."""
    return np.asarray(rgb, dtype=np.float64) @ np.asarray(_srgb().matrix_RGB_to_XYZ)[1]


def default_exposure(linear_rgb) -> float:
    """Exposure that brings the 99th percentile of luminance (finite, positive pixels) to 0.8
    before the tone curve of :func:`tonemap_srgb8`; 1 for an image without such pixels."""
    luminance = srgb_luminance(linear_rgb)
    luminance = luminance[np.isfinite(luminance) & (luminance > 0)]
    if luminance.size == 0:
        return 1.0
    return _DISPLAY_VALUE / float(np.percentile(luminance, _DISPLAY_PERCENTILE))


def tonemap_srgb8(linear_rgb, exposure: float | None = None) -> np.ndarray:
    """8-bit sRGB display image ``(..., 3)`` uint8 from linear sRGB.

    The image is multiplied by ``exposure`` (default :func:`default_exposure`: the 99th
    percentile of luminance becomes 0.8), its luminance Y is compressed with Reinhard's curve
    Y / (1 + Y) (colours scaled by the same factor, then clipped to [0, 1]), and encoded with
    the sRGB OETF. Non-finite pixels (e.g. outside a fisheye's circle) become black.
    """
    rgb = np.asarray(linear_rgb, dtype=np.float64)
    if exposure is None:
        exposure = default_exposure(rgb)
    rgb = np.where(np.isfinite(rgb), rgb * exposure, 0.0)
    luminance = srgb_luminance(rgb)
    scale = np.where(luminance > 0, 1.0 / (1.0 + np.maximum(luminance, 0.0)), 1.0)
    display = np.clip(rgb * scale[..., None], 0.0, 1.0)
    encoded = np.asarray(colour.cctf_encoding(display, function="sRGB"))
    return np.round(np.clip(encoded, 0.0, 1.0) * 255.0).astype(np.uint8)


def ciede2000(rgb_a, rgb_b, white_luminance: float | None = None) -> np.ndarray:
    """CIEDE2000 difference per pixel between two linear sRGB images ``(..., 3)``.

    Both are converted to XYZ and normalised by one common white: Y_white =
    ``white_luminance`` (same unit as the images' Y), by default the largest finite luminance
    found in either image, so that the brighter image's brightest pixel has L* = 100. Lab uses
    the D65 white point; the same normalisation for both keeps absolute brightness differences.
    """
    xyz_a = linear_srgb_to_xyz(rgb_a)
    xyz_b = linear_srgb_to_xyz(rgb_b)
    if white_luminance is None:
        luminance = np.concatenate([xyz_a[..., 1].ravel(), xyz_b[..., 1].ravel()])
        luminance = luminance[np.isfinite(luminance)]
        white_luminance = float(luminance.max()) if luminance.size and luminance.max() > 0 else 1.0
    white = _srgb().whitepoint
    lab_a = colour.XYZ_to_Lab(xyz_a / white_luminance, white)
    lab_b = colour.XYZ_to_Lab(xyz_b / white_luminance, white)
    return np.asarray(colour.delta_E(lab_a, lab_b, method="CIE 2000"))
