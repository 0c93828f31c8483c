"""Skies as spectral OpenEXR files, in the layout of Fichet, Pacanowski & Wilkie 2021 ("An
OpenEXR Layout for Spectral Images", JCGT 10(3)), so spectral viewers and libraries that follow
it (spectral-exr, colour's ``read_spectral_image_Fichet2021``) open them.

Channels, grouped in the layers of :data:`LAYERS` (by default all of them: a complete
reference; ``layers`` picks fewer, e.g. ``("rgb",)`` for an environment map):

- ``radiance``: ``S0.<wavelength>nm``, the spectral radiance, the wavelength in nm written with
  a comma as decimal separator and 6 decimals, e.g. ``S0.550,000000nm`` (the layout reserves
  ``.`` for layers). A polarized sky (``sky.stokes``) has the layout's polarised form: S0 (I,
  ``sky.radiance``), ``S1`` (Q), ``S2`` (U) and ``S3`` (V) channels per wavelength, and two
  layers derived from them, ``DoLP.<wavelength>nm`` (degree of linear polarization,
  sqrt(S1^2 + S2^2) / S0, 0 to 1) and ``AoLP.<wavelength>nm`` (angle of linear polarization,
  0.5 atan2(S2, S1), degrees in [-90, 90]), NaN where S0 is 0 or not finite;
- ``error``: ``stderr.S0.<wavelength>nm``, the standard error of the radiance (polarized:
  ``stderr.S1`` to ``stderr.S3`` too, those of Q, U, V);
- ``orders``: ``<order>.S0.<wavelength>nm`` for each scattering order of
  :data:`skyref.sky.ORDER_NAMES` the sky has (radiance, I when polarized; a polarized sky's
  ``order_stokes`` adds ``<order>.S1`` to ``<order>.S3``);
- ``rgb``: ``R``, ``G``, ``B``, the linear sRGB preview
  (:func:`skyref.color.spectral_to_linear_srgb`, scale: Y in cd m^-2).

Every channel is ZIP-compressed (lossless) 32-bit FLOAT, or with ``half`` 16-bit HALF: about
half the bytes, 11 significant bits (relative rounding 2^-11 = 4.9e-4), values below 6.1e-5
with less, and none above :data:`HALF_MAX`: larger values are clamped to it and reported (the
sun's disk in the RGB preview, ~1.6e9 cd m^-2 at noon; its spectral radiance, ~3e4, fits).

Header: ``spectralLayoutVersion = "1.0"`` and ``emissiveUnits = "W.m^-2.sr^-1"`` as the layout
requires, when spectral channels are written (the only emissive unit it defines; the values are
spectral radiance per nm, which ``skyref.radianceUnits = "W.m^-2.sr^-1.nm^-1"`` states
explicitly); with S1-S3 channels, the layout's ``polarisationHandedness = "right"`` and
``skyref.stokesFrame``, which says in words that every pixel's Stokes vector is referred to the
meridian frame of its own viewing direction (:data:`STOKES_FRAME`;
:mod:`skyref.plugins.polarization`: e_par in the vertical plane through the view direction,
e_perp = normalize(view x up), and e_par, e_perp, view direction a right-handed triple);
``skyref.scene`` (the scene as TOML, when the sky has one) and
``skyref.metadata`` (JSON of ``sky.metadata`` but its timings, :data:`skyref.sky.TIMING_METADATA`:
the same render gives the same bytes).

OpenEXR and colour-science are imported inside the functions that use them: ``skyref --help``
imports this module (through :mod:`skyref.cli`), and colour-science alone takes seconds.

References
----------
A. Fichet, R. Pacanowski, A. Wilkie, "An OpenEXR Layout for Spectral Images", JCGT 10(3), 2021.
"""

from __future__ import annotations

import json
import math
import os
import re
import tomllib
from decimal import Decimal

import numpy as np
import tomli_w

from skyref.errors import ParameterError
from skyref.io.atomic import atomic_path
from skyref.io.json_numpy import numpy_default
from skyref.projection import pixel_directions
from skyref.scene import Scene
from skyref.sky import (ORDER_NAMES, STOKES, TIMING_METADATA, Sky, angle_of_linear_polarization,
                        degree_of_linear_polarization)

__all__ = ["SPECTRAL_LAYOUT_VERSION", "EMISSIVE_UNITS", "RADIANCE_UNITS", "STDERR_LAYER", "DOLP_LAYER", "AOLP_LAYER",
           "POLARISATION_HANDEDNESS", "STOKES_FRAME", "LAYERS", "HALF_MAX", "channel_name", "check_layers",
           "write_sky_exr", "read_sky_exr"]

SPECTRAL_LAYOUT_VERSION = "1.0"
EMISSIVE_UNITS = "W.m^-2.sr^-1"
RADIANCE_UNITS = "W.m^-2.sr^-1.nm^-1"
STDERR_LAYER = "stderr"
#: Layers derived from a polarized sky's Stokes channels: degree (0-1) and angle (degrees) of
#: linear polarization per wavelength.
DOLP_LAYER, AOLP_LAYER = "DoLP", "AoLP"
#: The layout's ``polarisationHandedness`` of skyref's Stokes frames (see the module docstring).
POLARISATION_HANDEDNESS = "right"
#: ``skyref.stokesFrame``: the frame of every pixel's Stokes vector, in words.
STOKES_FRAME = ("meridian frame of each pixel's viewing direction d: e_par in the vertical plane through d, "
                "e_perp = normalize(d x up); Q = I_par - I_perp, U = I(+45 deg) - I(-45 deg) with +45 deg along "
                "e_par + e_perp (skyref.plugins.polarization)")
#: The layers :func:`write_sky_exr` can write (see the module docstring), in file order.
LAYERS = ("radiance", "error", "orders", "rgb")
#: The largest finite 16-bit half float.
HALF_MAX = float(np.finfo(np.float16).max)

#: An emissive channel of the layout: Stokes component, number (comma decimal separator,
#: optional exponent), optional SI prefix, unit (m or Hz).
_CHANNEL = re.compile(r"^(?:(?P<layer>[^.]+)\.)?S(?P<stokes>[0-3])\."
                      r"(?P<number>(?:\d+,?\d*|,\d+)(?:[Ee][+-]?\d+)?)"
                      r"(?P<prefix>Y|Z|E|P|T|G|M|k|h|da|d|c|m|u|n|p)?(?P<unit>m|Hz)$")
#: SI prefixes as powers of ten.
_PREFIX_EXPONENT = {"Y": 24, "Z": 21, "E": 18, "P": 15, "T": 12, "G": 9, "M": 6, "k": 3, "h": 2, "da": 1,
                    "": 0, "d": -1, "c": -2, "m": -3, "u": -6, "n": -9, "p": -12}
_SPEED_OF_LIGHT = 299_792_458.0


def _wavelength_text(wavelength_nm: float) -> str:
    """``<wavelength>nm`` with 6 decimals and a decimal comma."""
    return f"{float(wavelength_nm):.6f}".replace(".", ",") + "nm"


def channel_name(wavelength_nm: float, layer: str = "", stokes: int = 0) -> str:
    """``[layer.]S<stokes>.<wavelength>nm`` with 6 decimals and a decimal comma."""
    name = f"S{stokes}." + _wavelength_text(wavelength_nm)
    return f"{layer}.{name}" if layer else name


def _channel_wavelength_nm(match) -> float:
    """The wavelength (nm) of a channel name, read as an exact decimal: ``830,000000nm`` is
    830.0, not 830 x 1e-9 x 1e9 = 830.0000000000001. A frequency (Hz) becomes c / f."""
    number = Decimal(match["number"].replace(",", "."))
    exponent = _PREFIX_EXPONENT[match["prefix"] or ""]
    if match["unit"] == "m":
        return float(number.scaleb(exponent + 9))
    frequency = float(number.scaleb(exponent))
    return _SPEED_OF_LIGHT / frequency * 1e9 if frequency > 0.0 else math.inf


def _check_layer(name: str, array, shape, axes: str = "height, width, wavelengths") -> np.ndarray:
    array = np.asarray(array)
    if array.shape != shape:
        raise ParameterError(name, f"array of shape {array.shape}", f"shape {shape} ({axes})", "shape mismatch")
    return np.ascontiguousarray(array, dtype=np.float32)


def check_layers(layers, name: str = "layers") -> tuple[str, ...]:
    """``layers`` (names from :data:`LAYERS`, as a sequence or a comma-separated string) as a
    tuple in :data:`LAYERS` order; a ParameterError naming ``name`` if none or an unknown one."""
    valid = "a comma-separated subset of " + ", ".join(LAYERS)
    try:
        items = layers.split(",") if isinstance(layers, str) else list(layers)
    except TypeError:
        raise ParameterError(name, layers, valid, "not a string or a sequence") from None
    items = [item.strip() if isinstance(item, str) else item for item in items]
    items = [item for item in items if item != ""]
    unknown = [item for item in items if item not in LAYERS]
    if unknown:
        raise ParameterError(name, layers, valid, f"unknown layer {', '.join(map(repr, unknown))}")
    if not items:
        raise ParameterError(name, layers, valid, "no layers")
    return tuple(layer for layer in LAYERS if layer in items)


def write_sky_exr(sky: Sky, path, layers=LAYERS, half: bool = False, report=None) -> None:
    """Write ``sky`` to ``path`` (atomically: readers never see a partial file). ``layers``: which
    of :data:`LAYERS` to write (default all); ``half``: store 16-bit HALF channels instead of
    32-bit FLOAT (see the module docstring); ``report``, if given, is called with a line saying
    how many values were clamped to :data:`HALF_MAX`."""
    import OpenEXR  # lazy: see the module docstring

    from skyref.color import spectral_to_linear_srgb  # lazy: see the module docstring

    layers = check_layers(layers)
    if not isinstance(half, (bool, np.bool_)):
        raise ParameterError("half", half, "True or False", "not a bool")
    wavelengths = np.asarray(sky.wavelengths_nm, dtype=np.float64).reshape(-1)
    radiance = np.asarray(sky.radiance)
    if radiance.ndim != 3 or radiance.shape[2] != wavelengths.size:
        raise ParameterError("sky.radiance", f"array of shape {radiance.shape}",
                             f"(height, width, {wavelengths.size}) for {wavelengths.size} wavelengths", "shape mismatch")
    names = [channel_name(w) for w in wavelengths]
    if len(set(names)) != len(names):
        raise ParameterError("sky.wavelengths_nm", wavelengths.tolist(), "values distinct at 1e-6 nm",
                             "duplicate wavelengths")
    shape = radiance.shape
    radiance = _check_layer("sky.radiance", radiance, shape)
    stokes_shape = (shape[0], shape[1], len(STOKES), shape[2])
    polarization = "height, width, Stokes components I Q U V, wavelengths"
    # (channel-name prefix, Stokes component) -> (H, W, N); S0 is always the sky's radiance and
    # standard error, S1-S3 come from a polarized sky's Stokes vectors.
    spectral = {("", 0): radiance} if "radiance" in layers else {}
    if "radiance" in layers and sky.stokes is not None:
        stokes = _check_layer("sky.stokes", sky.stokes, stokes_shape, polarization)
        spectral.update(((("", s), stokes[..., s, :]) for s in range(1, len(STOKES))))
    if "error" in layers:
        spectral[STDERR_LAYER, 0] = _check_layer("sky.standard_error", sky.standard_error, shape)
        if sky.stokes_error is not None:
            errors = _check_layer("sky.stokes_error", sky.stokes_error, stokes_shape, polarization)
            spectral.update((((STDERR_LAYER, s), errors[..., s, :]) for s in range(1, len(STOKES))))
    if "orders" in layers:
        for order, values in sky.orders.items():
            if order not in ORDER_NAMES:
                raise ParameterError("sky.orders", order, ", ".join(ORDER_NAMES), "unknown scattering order")
            spectral[order, 0] = _check_layer(f"sky.orders[{order!r}]", values, shape)
        for order, values in sky.order_stokes.items():
            if order not in sky.orders:
                raise ParameterError("sky.order_stokes", order, "one of the sky's orders: " + ", ".join(sky.orders),
                                     "no such order in sky.orders")
            values = _check_layer(f"sky.order_stokes[{order!r}]", values, stokes_shape, polarization)
            spectral.update((((order, s), values[..., s, :]) for s in range(1, len(STOKES))))

    channels = {}
    if "rgb" in layers:
        rgb = spectral_to_linear_srgb(radiance, wavelengths).astype(np.float32)
        channels.update((c, rgb[..., i]) for i, c in enumerate("RGB"))
    for (prefix, component), values in spectral.items():
        for k, wavelength in enumerate(wavelengths):
            channels[channel_name(wavelength, prefix, component)] = values[..., k]
    if ("", 1) in spectral:
        written = np.stack([spectral["", s] for s in range(len(STOKES))], axis=-2)
        for layer, derived in ((DOLP_LAYER, degree_of_linear_polarization(written)),
                               (AOLP_LAYER, angle_of_linear_polarization(written))):
            for k, wavelength in enumerate(wavelengths):
                channels[f"{layer}.{_wavelength_text(wavelength)}"] = derived[..., k].astype(np.float32)
    if half:
        clamped = sum(int(np.count_nonzero(np.abs(values) > HALF_MAX)) for values in channels.values())
        channels = {name: np.clip(values, -HALF_MAX, HALF_MAX).astype(np.float16) for name, values in channels.items()}
        if clamped and report is not None:
            report(f"{path}: {clamped:,} values above {HALF_MAX:g}, the largest half float, clamped to it")
    channels = {name: np.ascontiguousarray(values) for name, values in channels.items()}

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
              "skyref.metadata": json.dumps({k: v for k, v in sky.metadata.items() if k not in TIMING_METADATA},
                                            default=numpy_default, sort_keys=True)}
    if spectral:  # an RGB-only file does not claim the spectral layout
        header.update({"spectralLayoutVersion": SPECTRAL_LAYOUT_VERSION, "emissiveUnits": EMISSIVE_UNITS,
                       "skyref.radianceUnits": RADIANCE_UNITS})
    if any(component for _, component in spectral):
        header.update({"polarisationHandedness": POLARISATION_HANDEDNESS, "skyref.stokesFrame": STOKES_FRAME})
    if sky.scene is not None:
        header["skyref.scene"] = tomli_w.dumps(sky.scene.to_dict())
    with atomic_path(path) as tmp, OpenEXR.File(header, channels) as exr:
        exr.write(tmp)


def read_sky_exr(path) -> Sky:
    """Read a sky written by :func:`write_sky_exr` (or any emissive file of the layout).

    The radiance layer is required (a ParameterError names what the file holds instead);
    radiance, standard error and orders come back as float32 arrays (HALF channels widened),
    ``orders`` with the order layers the file has (none: empty). A polarised file (S1-S3
    channels) gives a polarized sky: ``stokes`` (and ``stokes_error`` with stderr.S1-S3,
    ``order_stokes`` with <order>.S1-S3); the derived DoLP and AoLP layers are not read (the
    sky computes them). Wavelengths are in
    ascending order, or in the scene's order when the file holds a scene with the same set.
    ``directions`` come from the scene's camera (:func:`skyref.projection.pixel_directions`),
    NaN without a scene; ``standard_error`` is NaN when the file has no ``stderr`` layer.
    Metadata arrays come back as lists (JSON).
    """
    import OpenEXR  # lazy: see the module docstring

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ParameterError("path", path, "an existing OpenEXR file", "file not found")
    try:
        with OpenEXR.File(path, separate_channels=True) as exr:
            header = dict(exr.header())
            pixels = {name: np.array(channel.pixels, dtype=np.float32) for name, channel in exr.channels().items()}
    except (RuntimeError, OSError, ValueError) as exc:
        raise ParameterError("path", path, "a readable OpenEXR file", f"unreadable: {exc}") from None

    layers: dict[tuple[str, int], dict[float, str]] = {}       # (layer, Stokes component) -> channels
    for name in pixels:
        match = _CHANNEL.match(name)
        if match:
            layers.setdefault((match["layer"] or "", int(match["stokes"])), {})[_channel_wavelength_nm(match)] = name
    if ("", 0) not in layers:
        held = [layer for layer, present in (("error", (STDERR_LAYER, 0) in layers),
                                             ("orders", any((order, 0) in layers for order in ORDER_NAMES)),
                                             ("rgb", {"R", "G", "B"} <= set(pixels))) if present]
        raise ParameterError("path", path, "an emissive spectral OpenEXR (channels S0.<wavelength>nm: the "
                             "radiance layer)", "no spectral channels" +
                             (f" (it holds {', '.join(held)}: written without the radiance layer?)" if held else ""))

    scene = None
    if "skyref.scene" in header:
        try:
            scene = Scene.from_dict(tomllib.loads(str(header["skyref.scene"])))
        except tomllib.TOMLDecodeError as exc:
            raise ParameterError("path", path, "a valid skyref.scene TOML attribute", f"TOML error: {exc}") from None
    # The channels in ascending wavelength, or, when the scene in the header names exactly the
    # file's channels, in the scene's order and with the scene's exact wavelengths (a name keeps
    # 6 decimals).
    keys = sorted(layers["", 0])
    wavelengths = np.array(keys)
    if scene is not None:
        by_name = {channel_name(w): w for w in keys}
        exact = [float(w) for w in scene.wavelengths_nm]
        if sorted(channel_name(w) for w in exact) == sorted(by_name):
            keys = [by_name[channel_name(w)] for w in exact]
            wavelengths = np.array(exact)

    def stack(layer, component=0):
        names = layers[layer, component]
        if set(names) != set(keys):
            label = f"{layer}.S{component}" if layer else f"S{component}"
            raise ParameterError("path", path, "the same wavelengths in every layer",
                                 f"layer {label!r} has {sorted(names)}")
        return np.stack([pixels[names[k]] for k in keys], axis=-1)

    def stokes(layer, component_0):
        """(H, W, 4, N) of S0 (given) and the layer's S1-S3, or None without all three."""
        if not all((layer, c) in layers for c in range(1, len(STOKES))):
            return None
        return np.stack([component_0, *(stack(layer, c) for c in range(1, len(STOKES)))], axis=-2)

    radiance = stack("")
    standard_error = stack(STDERR_LAYER) if (STDERR_LAYER, 0) in layers else np.full_like(radiance, np.nan)
    orders = {order: stack(order) for order in ORDER_NAMES if (order, 0) in layers}
    stokes_values = stokes("", radiance)
    stokes_error = None if stokes_values is None else stokes(STDERR_LAYER, standard_error)
    order_stokes = {order: vectors for order, values in orders.items()
                    if (vectors := stokes(order, values)) is not None}
    height, width = radiance.shape[:2]
    if scene is not None:
        if (scene.camera.height, scene.camera.width) != (height, width):
            raise ParameterError("path", path, f"a scene camera of {width}x{height} pixels",
                                 f"scene camera is {scene.camera.width}x{scene.camera.height}")
        directions = pixel_directions(scene.camera)
    else:
        directions = np.full((height, width, 3), math.nan)
    metadata = json.loads(str(header.get("skyref.metadata", "{}")))
    return Sky(radiance=radiance, standard_error=standard_error, wavelengths_nm=wavelengths,
               directions=directions, orders=orders, scene=scene, metadata=metadata, stokes=stokes_values,
               stokes_error=stokes_error, order_stokes=order_stokes)
