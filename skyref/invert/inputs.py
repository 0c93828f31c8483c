"""What an inversion starts from: the image, its camera, the sun, the observer and the pixels to
use, all checked before any rendering.

Images:

- spectral OpenEXR in the Fichet layout (``S0.<wavelength>nm`` channels, e.g. from ``skyref
  render``): spectral radiance; the fit uses up to ``max_wavelengths`` of its wavelengths;
- linear RGB OpenEXR (``R``, ``G``, ``B``), taken as linear sRGB;
- LDR PNG/JPEG: decoded with the sRGB transfer function into linear sRGB, always relative
  (an unknown exposure), saturated pixels left out.

RGB data are fitted as CIE XYZ (an exact linear transform of linear sRGB, and positive for any
physical spectrum, so its logarithm exists where sRGB may have a negative component); the model's
spectral radiance, rendered on :data:`RGB_MODEL_WAVELENGTHS_NM`, is converted to XYZ with the
same colour-matching functions as :func:`skyref.color.spectral_to_xyz`.

A skyref EXR carries its scene in the header: its camera, sun and observer are used unless given
explicitly (never its atmosphere: that is what the inversion estimates).

Pixels used: wholly inside the image (fisheye circle), finite and positive in every channel, not
excluded by the user's mask, at most ``max_view_zenith_deg`` from the zenith (default 90: the
sky only, since a real ground is not skyref's uniform Lambertian plane) and at least
``sun_exclusion_deg`` plus half a pixel from the sun's centre (the disk and the steepest part of
the aureole).

colour-science (also through :mod:`skyref.color`) and PIL are imported inside the functions that
use them: colour-science takes about 2.5 s to import, and ``skyref --help`` imports this module
(through :mod:`skyref.invert`).
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings
from dataclasses import dataclass, field

import numpy as np
import OpenEXR

from skyref.validation import check_array, check_choice, check_int, check_number
from skyref.errors import ParameterError
from skyref.io.exr import read_sky_exr
from skyref.projection import pixel_directions, solid_angle
from skyref.scene import Camera, Observer, RenderSettings, Scene, Sun

__all__ = ["CHANNEL_CHOICES", "LDR_SATURATED", "LDR_SUFFIXES", "MAX_WAVELENGTHS", "MIN_IMAGE_SIDE",
           "RGB_MODEL_WAVELENGTHS_NM", "SUN_CONTRAST", "Observation", "SkyImage", "estimate_sun", "image_from_sky",
           "observation", "read_exclusion_mask", "read_image", "sun_from_arguments"]

#: Wavelengths (nm) on which RGB images are modelled: the visible range every 40 nm. Eight or more
#: points, so XYZ is integrated on this grid rather than interpolated (skyref.color).
RGB_MODEL_WAVELENGTHS_NM = tuple(float(w) for w in range(400, 681, 40))

#: Most wavelengths of a spectral image that a fit uses by default (evenly spread; each costs
#: rendering time).
MAX_WAVELENGTHS = 16

LDR_SUFFIXES = (".png", ".jpg", ".jpeg")
CHANNEL_CHOICES = ("auto", "spectral", "rgb")

#: 8-bit values at or above this are taken as saturated in an LDR image.
LDR_SATURATED = 254

#: The sun is "visible" in an image when its brightest pixel exceeds the median sky by this.
SUN_CONTRAST = 50.0


#: Smallest image side, pixels: fewer cannot sample the sky's gradients from the sun to the horizon.
MIN_IMAGE_SIDE = 8


@dataclass
class SkyImage:
    """Pixel values as read: ``values`` (H, W, C) linear, spectral radiance (``kind`` "spectral",
    C = len(wavelengths_nm)) or linear sRGB (``kind`` "rgb", C = 3); ``ldr`` for 8-bit images
    (``saturated`` marks their clipped pixels); ``scene`` from a skyref EXR header, or None."""

    values: np.ndarray
    kind: str
    wavelengths_nm: np.ndarray | None = None
    ldr: bool = False
    saturated: np.ndarray | None = None
    scene: object = None
    source: str = ""

    def __post_init__(self):
        height, width = self.values.shape[:2]
        if min(height, width) < MIN_IMAGE_SIDE:
            raise ParameterError("image", self.source or f"{width}x{height} pixels",
                                 f"at least {MIN_IMAGE_SIDE}x{MIN_IMAGE_SIDE} pixels", f"{width}x{height} pixels")

    @property
    def shape(self) -> tuple:
        return self.values.shape[:2]

    def luminance(self) -> np.ndarray:
        """(H, W) luminance, cd m^-2 (or relative for a relative image)."""
        from skyref.color import spectral_to_luminance, srgb_luminance

        if self.kind == "spectral":
            return spectral_to_luminance(self.values, self.wavelengths_nm)
        return srgb_luminance(self.values)

    def linear_srgb(self) -> np.ndarray:
        from skyref.color import spectral_to_linear_srgb

        return spectral_to_linear_srgb(self.values, self.wavelengths_nm) if self.kind == "spectral" else self.values


def image_from_sky(sky, channels: str = "spectral") -> SkyImage:
    """A :class:`SkyImage` of a rendered :class:`~skyref.sky.Sky`: its spectral radiance, or
    (``channels="rgb"``) its linear sRGB."""
    check_choice("channels", channels, ("spectral", "rgb"))
    if channels == "rgb":
        return SkyImage(sky.rgb(), "rgb", scene=sky.scene, source="sky (linear sRGB)")
    return SkyImage(np.asarray(sky.radiance, np.float64), "spectral", np.asarray(sky.wavelengths_nm, np.float64),
                    scene=sky.scene, source="sky (spectral)")


def read_image(path, channels: str = "auto") -> SkyImage:
    """Read an EXR (spectral, or linear RGB) or an LDR PNG/JPEG. ``channels``: ``auto`` (spectral
    when the file has spectral channels), ``spectral`` or ``rgb`` (a spectral file's sRGB)."""
    check_choice("--channels", channels, CHANNEL_CHOICES)
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ParameterError("image", path, "an existing EXR, PNG or JPEG file", "file not found")
    suffix = os.path.splitext(path)[1].lower()
    if suffix in LDR_SUFFIXES:
        if channels == "spectral":
            raise ParameterError("--channels", channels, "rgb or auto for an LDR image", "no spectral channels")
        return _read_ldr(path)
    if suffix != ".exr":
        raise ParameterError("image", path, "an .exr, .png, .jpg or .jpeg file", "unsupported format")
    try:
        with OpenEXR.File(path, separate_channels=True) as exr:
            pixels = exr.channels()
            rgb = (np.stack([np.array(pixels[c].pixels, dtype=np.float64) for c in "RGB"], axis=-1)
                   if {"R", "G", "B"} <= set(pixels) else None)
            spectral = any(name.startswith("S0.") for name in pixels)
    except (RuntimeError, OSError, ValueError) as exc:
        raise ParameterError("image", path, "a readable OpenEXR file", f"unreadable: {exc}") from None
    if not spectral:
        if channels == "spectral" or rgb is None:
            raise ParameterError("image", path, "an EXR with S0.<wavelength>nm channels" +
                                 ("" if channels == "spectral" else " or R, G, B channels"), "no such channels")
        return SkyImage(rgb, "rgb", source=path)
    sky = read_sky_exr(path)
    if channels != "rgb":
        return dataclasses.replace(image_from_sky(sky, "spectral"), source=path)
    if rgb is None:
        rgb = sky.rgb()
    return SkyImage(rgb, "rgb", scene=sky.scene, source=path)


def _read_ldr(path) -> SkyImage:
    import colour
    from PIL import Image

    try:
        with Image.open(path) as im:
            bands = im.getbands()
            pixels = np.asarray(im.convert("RGB"), dtype=np.uint8)
    except OSError as exc:
        raise ParameterError("image", path, "a readable PNG or JPEG", f"unreadable: {exc}") from None
    if len(bands) < 3:
        raise ParameterError("image", path, "a colour (RGB) image", "greyscale: the sky's colour is what tells "
                             "aerosol from brightness; give a colour image (or a spectral EXR)")
    linear = np.asarray(colour.cctf_decoding(pixels / 255.0, function="sRGB"), dtype=np.float64)
    return SkyImage(linear, "rgb", ldr=True, saturated=(pixels >= LDR_SATURATED).any(axis=-1), source=path)


def read_exclusion_mask(path, shape) -> np.ndarray:
    """(H, W) bool, True where pixels are to be left out: an image (PNG/JPEG/EXR; any non-zero
    pixel, e.g. white, is excluded) or a ``.npy`` array of the image's size."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ParameterError("--exclude", path, "an existing mask image or .npy file", "file not found")
    if path.lower().endswith(".npy"):
        mask = np.load(path)
    else:
        mask = read_image(path, channels="rgb").values
    mask = np.asarray(mask)
    mask = mask.reshape(mask.shape[:2] + (-1,)).any(axis=-1) if mask.ndim >= 2 else mask
    if mask.shape != tuple(shape):
        raise ParameterError("--exclude", path, f"a mask of the image's size {shape[1]}x{shape[0]}",
                             f"mask is {mask.shape[1]}x{mask.shape[0]}" if mask.ndim == 2 else "not an image")
    return mask != 0


def sun_from_arguments(zenith_deg=None, azimuth_deg=None, time=None, latitude_deg=None, longitude_deg=None):
    """A :class:`~skyref.scene.Sun` from angles, or from date/time and place (pvlib), or None
    when nothing is given. Partial or conflicting specifications are errors."""
    angles = (zenith_deg, azimuth_deg)
    place = (time, latitude_deg, longitude_deg)
    if any(v is not None for v in angles) and any(v is not None for v in place):
        raise ParameterError("--sun-zenith/--time", (zenith_deg, time), "either sun angles or a date/time and place",
                             "conflicting sun positions")
    if any(v is not None for v in angles):
        if None in angles:
            raise ParameterError("--sun-azimuth" if azimuth_deg is None else "--sun-zenith", None,
                                 "both --sun-zenith and --sun-azimuth", "missing")
        return Sun(zenith_deg=zenith_deg, azimuth_deg=azimuth_deg)
    if any(v is not None for v in place):
        names = ("--time", "--latitude", "--longitude")
        for name, value in zip(names, place):
            if value is None:
                raise ParameterError(name, None, "--time, --latitude and --longitude together", "missing")
        return Sun.at(time, latitude_deg, longitude_deg)
    return None


def estimate_sun(image: SkyImage, directions) -> Sun:
    """The sun's position from the image, where its disk is visible: the luminance-weighted mean
    direction of the pixels at least half as bright as the brightest (for an LDR image: the
    saturated blob), which needs that pixel to outshine the median sky by SUN_CONTRAST."""
    luminance = image.luminance()
    usable = np.isfinite(luminance) & np.all(np.isfinite(directions), axis=-1) & (luminance > 0)
    if not usable.any():
        raise ParameterError("sun", "from the image", "an image with a visible sun disk", "no usable pixels")
    peak = float(luminance[usable].max())
    median = float(np.median(luminance[usable]))
    saturated = image.saturated if image.saturated is not None else np.zeros(image.shape, bool)
    if image.ldr and saturated[usable].any():
        bright = usable & saturated
    elif peak >= SUN_CONTRAST * median:
        bright = usable & (luminance >= 0.5 * peak)
    else:
        raise ParameterError("sun", "from the image", "a visible sun disk (brightest pixel > "
                             f"{SUN_CONTRAST:g}x the median), or --sun-zenith/--sun-azimuth, or --time with "
                             "--latitude/--longitude", f"brightest pixel only {peak / median:.1f}x the median")
    weights = np.ones(int(bright.sum())) if image.ldr else luminance[bright]
    mean = (directions[bright] * weights[:, None]).sum(axis=0)
    mean /= np.linalg.norm(mean)
    zenith = math.degrees(math.acos(float(np.clip(mean[2], -1.0, 1.0))))
    azimuth = math.degrees(math.atan2(mean[0], mean[1])) % 360.0
    return Sun(zenith_deg=zenith, azimuth_deg=azimuth)


@dataclass
class Observation:
    """A checked image ready to invert: ``values`` (H, W, C) in the fit's channels (``channels``
    "spectral": radiance at ``wavelengths_nm``; "xyz": CIE XYZ, modelled from radiance on
    ``wavelengths_nm``), the ``camera``, ``sun`` and ``observer``, the pixels used (``mask``),
    whether the values are absolute radiance (else known up to an exposure scale), and notes
    (warnings, where each input came from)."""

    image: SkyImage
    values: np.ndarray
    channels: str
    wavelengths_nm: np.ndarray
    camera: object
    sun: object
    observer: object
    mask: np.ndarray
    absolute: bool
    directions: np.ndarray
    notes: list = field(default_factory=list)

    @property
    def channel_names(self) -> list[str]:
        return [f"{w:g} nm" for w in self.wavelengths_nm] if self.channels == "spectral" else ["X", "Y", "Z"]

    def scene(self, atmosphere, spp=64, seed=0):
        """A :class:`~skyref.scene.Scene` of this observation's geometry with ``atmosphere``,
        rendered by the delta-tracking estimator: the inversion's forward-mode derivatives have
        been validated and calibrated (results/inversion.md) with it, not yet with the line
        integral, whose derivative kernels compile again for each set of free parameters."""
        return Scene(atmosphere=atmosphere, sun=self.sun, observer=self.observer, camera=self.camera,
                     wavelengths=tuple(self.wavelengths_nm),
                     render=RenderSettings(spp=spp, seed=seed, passes=2, estimator="delta_tracking"), name="fitted")

    def to_channels(self, radiance) -> np.ndarray:
        """Model radiance (..., len(wavelengths_nm)) in the fit's channels (linear in radiance,
        so it applies to derivatives too)."""
        if self.channels == "spectral":
            return np.asarray(radiance, dtype=np.float64)
        from skyref.color import spectral_to_xyz

        return spectral_to_xyz(radiance, self.wavelengths_nm)


def _camera(image, camera):
    height, width = image.shape
    if camera is None:
        if image.scene is None:
            raise ParameterError("--camera", None, "equirectangular, fisheye or perspective (with --fov and "
                                 "orientation)", "missing: the image carries no camera")
        camera = image.scene.camera
    elif isinstance(camera, dict):
        camera = Camera(**{**camera, "width": width, "height": height})
    if (camera.width, camera.height) != (width, height):
        raise ParameterError("camera", f"{camera.width}x{camera.height}", f"the image's size {width}x{height}",
                             "size mismatch")
    return camera


def observation(image: SkyImage, camera=None, sun=None, observer=None, exclude=None, absolute: bool = False,
                max_view_zenith_deg: float = 90.0, sun_exclusion_deg: float = 3.0, wavelengths=None,
                max_wavelengths: int = MAX_WAVELENGTHS, atmosphere=None) -> Observation:
    """Check everything and build an :class:`Observation`.

    ``camera``: a :class:`~skyref.scene.Camera`, or a dict of its fields without the size (taken
    from the image), or None for the image's own (skyref EXR). ``sun``: a Sun, ``"image"`` to
    estimate it from the visible disk, or None for the image's own. ``observer``: an Observer
    (default: the image's, else at 0 m). ``exclude``: (H, W) bool, True = leave out.
    ``wavelengths``: the model's wavelengths (nm) — for a spectral image a subset of its own
    (default: at most ``max_wavelengths`` of them, evenly spread), for RGB the grid the model
    renders before conversion to XYZ (default :data:`RGB_MODEL_WAVELENGTHS_NM`). ``atmosphere``:
    the model's base atmosphere, to check that it covers the wavelengths.
    """
    notes = []
    height, width = image.shape
    camera = _camera(image, camera)
    directions = pixel_directions(camera)
    if sun is None:
        if image.scene is None:
            raise ParameterError("sun", None, "--sun-zenith/--sun-azimuth, --time/--latitude/--longitude, or "
                                 "--sun-from-image", "missing: the image carries no sun position")
        sun = image.scene.sun
        notes.append("sun position from the image's skyref.scene header")
    elif isinstance(sun, str):
        check_choice("sun", sun, ("image",))
        sun = estimate_sun(image, directions)
        notes.append(f"sun position estimated from the image: zenith {sun.zenith_deg:.2f}, "
                     f"azimuth {sun.azimuth_deg:.2f} deg")
    if not isinstance(sun, Sun):
        raise ParameterError("sun", sun, "a skyref.scene.Sun or 'image'", "wrong type")
    check_number("sun.zenith_deg", sun.zenith_deg, 0.0, 90.0)
    if observer is None:
        observer = image.scene.observer if image.scene is not None else Observer()
    absolute = bool(absolute)
    if image.ldr:
        if absolute:
            raise ParameterError("--absolute", True, "relative (the default) for an LDR image",
                                 "an 8-bit image has no absolute scale")
        message = (f"{image.source or 'image'} is an 8-bit image: decoded with the sRGB transfer function and "
                   "fitted as relative radiance; tone curves or white balance applied by the camera bias the result")
        warnings.warn(message, stacklevel=2)
        notes.append(message)
    max_view_zenith_deg = check_number("max_view_zenith_deg", max_view_zenith_deg, 0.0, 180.0, lo_open=True)
    sun_exclusion_deg = check_number("sun_exclusion_deg", sun_exclusion_deg, 0.0, 90.0)

    # -- channels of the fit and the model's wavelengths ------------------------------------------
    if image.kind == "spectral":
        available = np.asarray(image.wavelengths_nm, dtype=np.float64)
        if wavelengths is None:
            count = check_int("max_wavelengths", max_wavelengths, 1, 10_000)
            chosen = np.unique(np.round(np.linspace(0, available.size - 1, min(count, available.size))).astype(int))
        else:
            wanted = check_array("wavelengths", wavelengths, 0.0, math.inf)
            chosen = []
            for w in wanted:
                match = np.flatnonzero(np.abs(available - w) < 1e-3)
                if match.size == 0:
                    raise ParameterError("wavelengths", float(w), "wavelengths of the image: " +
                                         ", ".join(f"{x:g}" for x in available), "not in the image")
                chosen.append(int(match[0]))
            chosen = np.array(sorted(set(chosen)))
        model_wavelengths = available[chosen]
        values = np.asarray(image.values, dtype=np.float64)[..., chosen]
        channels = "spectral"
    else:
        from skyref.color import linear_srgb_to_xyz

        model_wavelengths = check_array("wavelengths", RGB_MODEL_WAVELENGTHS_NM if wavelengths is None else wavelengths,
                                        0.0, math.inf, increasing=True)
        values = linear_srgb_to_xyz(image.values)
        channels = "xyz"
    if atmosphere is not None:
        atmosphere.check_wavelengths(model_wavelengths)

    # -- pixels used ---------------------------------------------------------------------------------
    mask = np.all(np.isfinite(directions), axis=-1) & np.all(np.isfinite(values) & (values > 0.0), axis=-1)
    if image.saturated is not None:
        mask &= ~image.saturated
    if exclude is not None:
        exclude = np.asarray(exclude, dtype=bool)
        if exclude.shape != (height, width):
            raise ParameterError("exclude", f"mask of shape {exclude.shape}", f"the image's shape {(height, width)}",
                                 "size mismatch")
        mask &= ~exclude
    view_zenith = np.degrees(np.arccos(np.clip(np.nan_to_num(directions[..., 2], nan=-1.0), -1.0, 1.0)))
    mask &= view_zenith <= max_view_zenith_deg
    half_pixel = np.degrees(np.sqrt(solid_angle(camera)) / math.sqrt(2.0))
    sun_distance = np.degrees(np.arccos(np.clip(np.nan_to_num(directions @ sun.direction, nan=1.0), -1.0, 1.0)))
    mask &= sun_distance >= sun_exclusion_deg + half_pixel
    if camera.type == "fisheye":
        # Only pixels wholly inside the image circle: the renderer (and a lens) darkens the others.
        a = 2.0 * (np.arange(width) + 0.5) / width - 1.0
        b = 1.0 - 2.0 * (np.arange(height) + 0.5) / height
        radius = np.hypot(a[None, :], b[:, None])
        mask &= radius + math.hypot(1.0 / width, 1.0 / height) <= 1.0
    if not mask.any():
        raise ParameterError("pixels", 0, "some usable sky pixels", "none left after the masks (image circle, "
                             "finite positive values, --exclude, --max-view-zenith, --sun-exclusion)")
    return Observation(image=image, values=values, channels=channels, wavelengths_nm=model_wavelengths,
                       camera=camera, sun=sun, observer=observer, mask=mask, absolute=absolute,
                       directions=directions, notes=notes)
