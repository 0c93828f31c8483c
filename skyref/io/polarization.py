"""PNG previews of a polarized sky's linear polarization: the images to look at first.

Both are computed from the sky's *luminance-weighted* Stokes vector, per pixel: I, Q and U each
integrated against the CIE photopic luminous efficiency (:func:`skyref.color.spectral_to_luminance`,
linear in the spectrum), what a polarimeter with the eye's spectral response would measure. Its
Stokes frame is each pixel's meridian frame (:mod:`skyref.plugins.polarization`).

- ``dolp``: the degree of linear polarization sqrt(Q^2 + U^2) / I on matplotlib's perceptually
  uniform ``viridis`` colour map, on a fixed scale: 0 dark violet, 1 yellow (a clear sky is
  most polarized about 90 deg from the sun), so that previews compare side by side.
- ``aolp``: the angle of linear polarization 0.5 atan2(U, Q) as a hue (once round the colour
  circle from -90 to 90 deg: 0 deg, polarized in the vertical plane through the view direction,
  is cyan; +-90 deg, horizontally, red), with the DoLP as brightness, so that unpolarized light,
  whose angle means nothing, is black.

Pixels that were not traced (NaN) are black. They are written beside the sRGB preview:
``sky.png`` -> ``sky.dolp.png``, ``sky.aolp.png`` (:func:`preview_paths`).

matplotlib and colour-science are imported inside the functions that use them: ``skyref --help``
imports this module (through :mod:`skyref.cli`).
"""

from __future__ import annotations

import os

import numpy as np

from skyref.io.png import annotated, save_png
from skyref.sky import angle_of_linear_polarization, degree_of_linear_polarization

__all__ = ["PREVIEWS", "luminance_stokes", "dolp_image", "aolp_image", "preview_paths", "write_polarization_pngs"]


def luminance_stokes(sky) -> np.ndarray:
    """The (H, W, 4) luminance-weighted Stokes vectors (I, Q, U, V) of a polarized sky, cd m^-2."""
    from skyref.color import spectral_to_luminance  # lazy: see the module docstring

    return spectral_to_luminance(sky.stokes_vectors(), sky.wavelengths_nm)


def _to_uint8(rgb) -> np.ndarray:
    return np.round(np.clip(np.nan_to_num(rgb, nan=0.0), 0.0, 1.0) * 255.0).astype(np.uint8)


def dolp_image(sky, annotate: bool = False) -> np.ndarray:
    """The (H, W, 3) uint8 DoLP preview of a polarized sky (see the module docstring);
    ``annotate`` draws the horizon, N/E/S/W and the sun (:func:`skyref.io.png.annotated`)."""
    from matplotlib import colormaps  # lazy: see the module docstring

    dolp = degree_of_linear_polarization(luminance_stokes(sky), axis=-1)
    rgb = colormaps["viridis"](np.clip(np.nan_to_num(dolp, nan=0.0), 0.0, 1.0))[..., :3]
    return annotated(_to_uint8(np.where(np.isfinite(dolp)[..., None], rgb, 0.0)), sky, annotate)


def aolp_image(sky, annotate: bool = False) -> np.ndarray:
    """The (H, W, 3) uint8 AoLP preview of a polarized sky: hue the angle, brightness the DoLP
    (see the module docstring); ``annotate`` as for :func:`dolp_image`."""
    from matplotlib.colors import hsv_to_rgb  # lazy: see the module docstring

    stokes = luminance_stokes(sky)
    dolp = np.clip(np.nan_to_num(degree_of_linear_polarization(stokes, axis=-1), nan=0.0), 0.0, 1.0)
    hue = np.nan_to_num((angle_of_linear_polarization(stokes, axis=-1) + 90.0) / 180.0 % 1.0, nan=0.0)
    return annotated(_to_uint8(hsv_to_rgb(np.stack([hue, np.ones_like(hue), dolp], axis=-1))), sky, annotate)


#: The polarization previews by name, in the order they are written.
PREVIEWS = {"dolp": dolp_image, "aolp": aolp_image}


def preview_paths(png_path) -> dict:
    """Where the previews of :data:`PREVIEWS` go beside the sRGB preview ``png_path``:
    ``sky.png`` -> {"dolp": ``sky.dolp.png``, "aolp": ``sky.aolp.png``}."""
    stem = os.path.splitext(os.fspath(png_path))[0]
    return {name: f"{stem}.{name}.png" for name in PREVIEWS}


def write_polarization_pngs(sky, png_path, annotate: bool = False) -> list[str]:
    """Write the previews of a polarized sky at :func:`preview_paths` of ``png_path``,
    atomically; returns their paths."""
    paths = preview_paths(png_path)
    images = {name: PREVIEWS[name](sky, annotate) for name in paths}   # every image before any file
    for name, path in paths.items():
        save_png(images[name], path)
    return list(paths.values())
