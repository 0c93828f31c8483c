"""``Sky``: a rendered sky, the product every skyref job consumes.

Radiance is spectral: ``radiance[row, column, k]`` is in W m^-2 sr^-1 nm^-1 at
``wavelengths_nm[k]``. Every sky carries its own Monte Carlo error bar (``standard_error``,
same shape, from the spread of independent passes) and its decomposition by scattering order.

A polarized render (``[render] polarized = true``) also carries ``stokes[row, column, s, k]``,
the Stokes vector (I, Q, U, V) in the same unit, referred to the *meridian frame* of each
pixel's viewing direction: Q > 0 is light polarized in the vertical plane through the view
direction, Q < 0 horizontally (conventions, the sign of U among them:
:mod:`skyref.plugins.polarization`). Its ``radiance`` is I, its ``standard_error`` I's, and its
``orders`` I per scattering order, so that consumers of radiance work unchanged; the Stokes
vector of each order is in ``order_stokes`` (the sun seen directly is unpolarized: its Q, U,
V are 0; the orders sum to ``stokes``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from skyref.errors import ParameterError

__all__ = ["ORDER_NAMES", "STOKES", "SAVE_FORMATS", "TIMING_METADATA", "degree_of_linear_polarization",
           "angle_of_linear_polarization", "Sky"]

#: Names of the per-order layers: the sun seen directly (through the atmosphere), light
#: scattered once, twice, and three or more times (a ground reflection counts as a scattering).
ORDER_NAMES = ("sun_direct", "single", "double", "higher")

#: The Stokes components along every polarized axis, in order (the sky's ``stokes``, the
#: integrator's outputs: :mod:`skyref.plugins.polarization`).
STOKES = ("I", "Q", "U", "V")

#: File extensions :meth:`Sky.save` writes, and what each holds.
SAVE_FORMATS = {".exr": "spectral OpenEXR", ".png": "tone-mapped sRGB preview"}

#: Metadata that differ between runs of the same render (timings): shown to the user, kept in
#: batch markers and manifests, never written into data files, so that the same seed gives the
#: same bytes.
TIMING_METADATA = ("render_time_s", "samples_per_second", "render_cpu_s", "render_cpu_s_before_resume")


def degree_of_linear_polarization(stokes, axis: int = -2) -> np.ndarray:
    """sqrt(Q^2 + U^2) / I of Stokes vectors whose components (I, Q, U, V) lie along ``axis``
    (that axis removed); NaN where I <= 0 or is not finite."""
    i, q, u = (np.take(np.asarray(stokes, dtype=np.float64), c, axis=axis) for c in range(3))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(i > 0, np.hypot(q, u) / i, np.nan)


def angle_of_linear_polarization(stokes, axis: int = -2) -> np.ndarray:
    """0.5 atan2(U, Q) in degrees, in [-90, 90], of Stokes vectors whose components lie along
    ``axis`` (that axis removed): 0 is e_par of the Stokes frame (for a sky, the vertical plane
    through the view direction), +-90 e_perp; NaN where I <= 0 or is not finite."""
    i, q, u = (np.take(np.asarray(stokes, dtype=np.float64), c, axis=axis) for c in range(3))
    return np.where(i > 0, 0.5 * np.degrees(np.arctan2(u, q)), np.nan)


@dataclass
class Sky:
    radiance: np.ndarray                 # (H, W, N) W m^-2 sr^-1 nm^-1 (polarized: I)
    standard_error: np.ndarray           # (H, W, N) same unit: standard error of the mean
    wavelengths_nm: np.ndarray           # (N,)
    directions: np.ndarray               # (H, W, 3) unit view direction of each pixel centre, east-north-up
    orders: dict = field(default_factory=dict)   # name in ORDER_NAMES -> (H, W, N) (polarized: I)
    scene: object = None                 # the skyref.scene.Scene that was rendered
    metadata: dict = field(default_factory=dict)
    stokes: np.ndarray | None = None     # (H, W, 4, N) I, Q, U, V (module docstring); None: not polarized
    stokes_error: np.ndarray | None = None   # (H, W, 4, N) their standard errors (None: not polarized)
    order_stokes: dict = field(default_factory=dict)  # polarized: name in ORDER_NAMES -> (H, W, 4, N)

    @property
    def shape(self) -> tuple:
        return self.radiance.shape

    @property
    def polarized(self) -> bool:
        """Whether the sky carries Stokes vectors (a polarized render)."""
        return self.stokes is not None

    def stokes_vectors(self) -> np.ndarray:
        """``stokes`` (H, W, 4, N) of a polarized sky; for any other, a ParameterError saying how
        to render one."""
        if self.stokes is None:
            raise ParameterError("sky.stokes", None, "a polarized render (render_sky(..., polarized=True), "
                                 "[render] polarized = true or skyref render --polarized)",
                                 "this sky was rendered without polarization")
        return self.stokes

    def stokes_component(self, name: str) -> np.ndarray:
        """The (H, W, N) Stokes component ``name`` (one of :data:`STOKES`) of a polarized sky."""
        if name not in STOKES:
            raise ParameterError("name", name, ", ".join(STOKES), "not a Stokes component")
        return self.stokes_vectors()[..., STOKES.index(name), :]

    @property
    def I(self) -> np.ndarray:  # noqa: E743 -- the Stokes parameter's name
        """Total radiance (H, W, N) of a polarized sky, W m^-2 sr^-1 nm^-1 (equal to ``radiance``)."""
        return self.stokes_component("I")

    @property
    def Q(self) -> np.ndarray:
        """Stokes Q (H, W, N): I_par - I_perp in the meridian frame (module docstring)."""
        return self.stokes_component("Q")

    @property
    def U(self) -> np.ndarray:
        """Stokes U (H, W, N): I(+45 deg) - I(-45 deg) in the meridian frame (module docstring)."""
        return self.stokes_component("U")

    @property
    def V(self) -> np.ndarray:
        """Stokes V (H, W, N): circular polarization (:mod:`skyref.plugins.polarization`)."""
        return self.stokes_component("V")

    def degree_of_linear_polarization(self) -> np.ndarray:
        """sqrt(Q^2 + U^2) / I per pixel and wavelength (H, W, N), in [0, 1] (NaN where I = 0
        or the pixel was not traced); needs a polarized sky."""
        return degree_of_linear_polarization(self.stokes_vectors())

    def angle_of_linear_polarization(self) -> np.ndarray:
        """0.5 atan2(U, Q) per pixel and wavelength (H, W, N), degrees in [-90, 90] from the
        vertical plane through the pixel's view direction (0) towards e_perp, the horizontal
        normalize(view x up) (+90): the meridian frame of :mod:`skyref.plugins.polarization`.
        NaN where I = 0 or the pixel was not traced; needs a polarized sky."""
        return angle_of_linear_polarization(self.stokes_vectors())

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
