"""PNG previews: tone-mapped 8-bit sRGB images of skies, optionally annotated.

Tone mapping (:func:`skyref.color.tonemap_srgb8`): linear sRGB in cd m^-2 (R = G = B = Y for D65
white) is multiplied by an exposure k, its luminance compressed with Reinhard's curve
kY / (1 + kY) and encoded with the sRGB OETF. The exposure is either automatic, per image (the
99th percentile of luminance becomes 0.8), or absolute, from an exposure value at ISO 100
(:func:`exposure_from_ev100`): then the same luminance gives the same pixel in every image, and
skies can be compared side by side. A D65-white pixel of luminance L shows as
sRGB_OETF(x / (1 + x)) with x = L / (1.2 * 2**EV100).

Pillow and colour-science are imported inside the functions that need them: ``skyref --help``
imports this module (through :mod:`skyref.cli`), and colour-science alone takes seconds.
"""

from __future__ import annotations

import math

import numpy as np

from skyref.errors import ParameterError
from skyref.io.annotate import draw_overlay
from skyref.io.atomic import atomic_path
from skyref.validation import check_number

__all__ = ["EV100_RANGE", "exposure_from_ev100", "ev100_from_exposure", "annotated", "preview_image", "save_png",
           "write_png"]

#: Accepted exposure values at ISO 100: from a moonless night to beyond the sun's disk.
EV100_RANGE = (-10.0, 40.0)

#: Luminance (cd m^-2) that saturates a camera at EV100 = 0: 78 / (S q) with ISO S = 100 and lens
#: transmission q = 0.65 (ISO 12232's saturation-based speed; Lagarde & de Rousiers 2014).
_SATURATION_LUMINANCE_EV0 = 78.0 / (100.0 * 0.65)


def exposure_from_ev100(ev100: float, parameter: str = "ev100") -> float:
    """The exposure k (1 / (cd m^-2)) of a camera set to exposure value ``ev100`` at ISO 100:
    the saturation luminance L_max = 1.2 * 2**EV100 cd m^-2 maps to 1 before the tone curve,
    k = 1 / L_max. A clear daytime sky is about EV100 12-14."""
    ev100 = check_number(parameter, ev100, *EV100_RANGE)
    return 1.0 / (_SATURATION_LUMINANCE_EV0 * 2.0 ** ev100)


def ev100_from_exposure(exposure: float) -> float:
    """Inverse of :func:`exposure_from_ev100`: the EV100 of exposure k (1 / (cd m^-2))."""
    return -math.log2(_SATURATION_LUMINANCE_EV0 * exposure)


def annotated(image, sky, annotate: bool) -> np.ndarray:
    """``image`` (H, W, 3) uint8 of ``sky`` with the horizon, N/E/S/W and the sun drawn on it
    (:func:`skyref.io.annotate.draw_overlay`) if ``annotate``, else ``image``; annotations
    need a Sky that carries its scene (its camera and sun)."""
    if not annotate:
        return image
    if getattr(sky, "scene", None) is None:
        raise ParameterError("annotate", True, "a Sky with its scene (camera and sun)",
                             "nothing to place the annotations with")
    return draw_overlay(image, sky.scene.camera, sky.scene.sun.direction)


def preview_image(sky_or_rgb, exposure: float | None = None, annotate: bool = False) -> np.ndarray:
    """The (H, W, 3) uint8 sRGB preview of a :class:`skyref.sky.Sky` (its spectral radiance
    converted to linear sRGB) or of a linear sRGB array (H, W, 3) in cd m^-2.

    ``exposure`` multiplies the linear values before the tone curve (default: per image, the
    99th percentile of luminance becomes 0.8; :func:`exposure_from_ev100` for an absolute one).
    ``annotate`` draws the horizon, N/E/S/W and the sun (:func:`skyref.io.annotate.draw_overlay`)
    and needs a Sky that carries its scene (its camera and sun).
    """
    from skyref.color import tonemap_srgb8  # lazy: see the module docstring

    rgb = sky_or_rgb.rgb() if hasattr(sky_or_rgb, "radiance") else np.asarray(sky_or_rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ParameterError("sky_or_rgb", f"array of shape {rgb.shape}", "a Sky or a (height, width, 3) array",
                             "not an RGB image")
    if exposure is not None:
        check_number("exposure", exposure, 0.0, math.inf, lo_open=True)
    return annotated(tonemap_srgb8(rgb, exposure), sky_or_rgb, annotate)


def save_png(image, path) -> None:
    """Write an (H, W, 3) uint8 sRGB image as a PNG, atomically."""
    from PIL import Image  # lazy: see the module docstring

    with atomic_path(path) as tmp:
        Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8), mode="RGB").save(tmp, format="PNG")


def write_png(sky_or_rgb, path, exposure: float | None = None, annotate: bool = False) -> None:
    """Write the :func:`preview_image` of a Sky or a linear sRGB array as a PNG, atomically."""
    save_png(preview_image(sky_or_rgb, exposure, annotate), path)
