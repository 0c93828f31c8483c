"""PNG previews: tone-mapped 8-bit sRGB images of skies.

Pillow and colour-science are imported inside :func:`write_png`: ``skyref --help`` imports this
module (through :mod:`skyref.cli`), and colour-science alone takes seconds.
"""

from __future__ import annotations

import numpy as np

from skyref.errors import ParameterError
from skyref.io.atomic import atomic_path

__all__ = ["write_png"]


def write_png(sky_or_rgb, path, exposure: float | None = None) -> None:
    """Write a tone-mapped 8-bit sRGB PNG, atomically.

    ``sky_or_rgb`` is a :class:`skyref.sky.Sky` (its spectral radiance is converted to linear
    sRGB) or a linear sRGB array ``(H, W, 3)``; ``exposure`` multiplies the linear values before
    the tone curve (default: the 99th percentile of luminance becomes 0.8, see
    :func:`skyref.color.tonemap_srgb8`).
    """
    from PIL import Image  # Pillow: a dependency of matplotlib

    from skyref.color import tonemap_srgb8

    rgb = sky_or_rgb.rgb() if hasattr(sky_or_rgb, "radiance") else np.asarray(sky_or_rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ParameterError("sky_or_rgb", f"array of shape {rgb.shape}", "a Sky or a (height, width, 3) array",
                             "not an RGB image")
    image = tonemap_srgb8(rgb, exposure)
    with atomic_path(path) as tmp:
        Image.fromarray(image, mode="RGB").save(tmp, format="PNG")
