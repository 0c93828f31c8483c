"""``Sky``: a rendered sky, the product every skyref job consumes.

Radiance is spectral: ``radiance[row, column, k]`` is in W m^-2 sr^-1 nm^-1 at
``wavelengths_nm[k]``. Every sky carries its own Monte Carlo error bar (``standard_error``,
same shape, from the spread of independent passes) and its decomposition by scattering order.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from skyref.errors import ParameterError

__all__ = ["ORDER_NAMES", "SAVE_FORMATS", "TIMING_METADATA", "Sky"]

#: Names of the per-order layers: the sun seen directly (through the atmosphere), light
#: scattered once, twice, and three or more times (a ground reflection counts as a scattering).
ORDER_NAMES = ("sun_direct", "single", "double", "higher")

#: File extensions :meth:`Sky.save` writes, and what each holds.
SAVE_FORMATS = {".exr": "spectral OpenEXR", ".png": "tone-mapped sRGB preview"}

#: Metadata that differ between runs of the same render (timings): shown to the user, kept in
#: batch markers and manifests, never written into data files, so that the same seed gives the
#: same bytes.
TIMING_METADATA = ("render_time_s", "samples_per_second")


@dataclass
class Sky:
    radiance: np.ndarray                 # (H, W, N) W m^-2 sr^-1 nm^-1
    standard_error: np.ndarray           # (H, W, N) same unit: standard error of the mean
    wavelengths_nm: np.ndarray           # (N,)
    directions: np.ndarray               # (H, W, 3) unit view direction of each pixel centre, east-north-up
    orders: dict = field(default_factory=dict)   # name in ORDER_NAMES -> (H, W, N)
    scene: object = None                 # the skyref.scene.Scene that was rendered
    metadata: dict = field(default_factory=dict)

    @property
    def shape(self) -> tuple:
        return self.radiance.shape

    def relative_error(self) -> np.ndarray:
        """Standard error / radiance per pixel and wavelength (NaN where radiance is 0)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.radiance > 0, self.standard_error / self.radiance, np.nan)

    def rgb(self) -> np.ndarray:
        """Linear sRGB, absolute: R = G = B = Y in cd m^-2 for D65 white (see skyref.color)."""
        from skyref.color import spectral_to_linear_srgb  # lazy: colour-science takes ~3 s to import

        return spectral_to_linear_srgb(self.radiance, self.wavelengths_nm)

    def luminance(self) -> np.ndarray:
        """Luminance, cd m^-2."""
        from skyref.color import spectral_to_luminance  # lazy: colour-science's import cost

        return spectral_to_luminance(self.radiance, self.wavelengths_nm)

    def save(self, path, **options) -> None:
        """Write the sky to ``path``, by its extension: ``.exr``, the spectral OpenEXR
        (:func:`skyref.io.exr.write_sky_exr`; ``options``: ``layers``, ``half``), or ``.png``, the
        tone-mapped sRGB preview (:func:`skyref.io.png.write_png`; ``options``: ``exposure``,
        ``annotate``)."""
        # Lazy: the writers import this module (a cycle at import time), and this module stays
        # light for everything that only passes skies around.
        from skyref.io.exr import write_sky_exr
        from skyref.io.png import write_png

        extension = os.path.splitext(os.fspath(path))[1].lower()
        if extension not in SAVE_FORMATS:
            raise ParameterError("path", os.fspath(path), ", ".join(f"a {e} file ({kind})" for e, kind in
                                                                   SAVE_FORMATS.items()), "unknown file extension")
        (write_sky_exr if extension == ".exr" else write_png)(self, path, **options)
