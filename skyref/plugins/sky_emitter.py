"""The ``skyref_sky`` emitter: a skyref sky method lights a Mitsuba scene.

The sky of any method skyref audits — a Hosek–Wilkie table (the published one, or one fitted by
``skyref fit``), another analytic model, or a LUT method (``bruneton2017``, ``elek2009``,
``hillaire2020``) — is tabulated once, when the plugin is loaded, on a latitude–longitude grid,
and handed to Mitsuba's stock ``envmap``, which evaluates it by bilinear interpolation and
importance-samples it (a hierarchical warp over luminance x sin(zenith angle)): ``mi.load_dict(
{"type": "skyref_sky", ...})`` returns that ``envmap``, and ``mi.traverse`` shows its ``data``,
``scale`` and ``to_world``.

- **Table.** ``width`` columns (azimuth 360° (i + 0.5) / width) and width / 2 + 1 rows of nodes
  from the zenith to the nadir (zenith angle 180° j / (width / 2)), the layout Mitsuba's
  ``envmap`` reads (:func:`skyref.renderer_frames.latlong_directions`); the horizon is a row.
  Between nodes the radiance is bilinear in (azimuth, zenith angle).
- **Sun: excluded.** The table holds the sky without the solar disk (what every sky method
  returns). Light the scene with the sun by adding Mitsuba's ``directional`` emitter with
  ``direction`` = minus the sun's direction in the world frame (``-to_world(direction_from_angles(
  sun_zenith, sun_azimuth))``).
- **Below the horizon: black** (like Mitsuba's ``sunsky``): a scene has its own ground. The
  interpolation fades the horizon's radiance to 0 over the row below it (180° / (width / 2)).
- **Cost at load.** The method's precomputation (Bruneton 2017: ~2.5 min on 2 CPU cores, Elek
  2009: ~30 s, Hillaire 2020 and the analytic models: ~1 s) and (width / 4 + 1) x width lookups.
- **Colour.** R, G, B are the spectral radiance at 680, 550 and 440 nm, W m^-2 sr^-1 nm^-1 (the
  ``atmosphere`` integrator's convention in RGB variants). RGB variants only: in spectral
  variants ``envmap`` would turn R, G, B into a smooth spectrum that is not the sky's.
- **Frame.** The plugin's local frame is skyref's east-north-up; ``to_world`` takes it to the
  scene's world. Default: Mitsuba's y-up convention (east +x, up +y, north -z;
  :data:`skyref.renderer_frames.WORLD_FROM_ENU`), so the sky looks as an ``envmap`` with no
  ``to_world`` would. In a z-up scene (the ``atmosphere`` integrator's frame, or Mitsuba's
  ``sunsky``) pass the identity, ``mi.ScalarTransform4f()``.

Properties (all optional): ``method`` (default ``hosek2012``), ``coefficients`` (a coefficient file
from ``skyref fit`` or the published ``.npz``: ``hosek2012`` evaluates its spectral table),
``turbidity`` (for the models that take one: ``hosek2012``, ``preetham1999``), ``atmosphere`` (a
preset name or the JSON of ``Atmosphere.to_dict()``; default ``bruneton2017``), ``sun_zenith`` and
``sun_azimuth`` (degrees; default 30 and 180), ``observer_altitude`` (m; default 0), ``width``
(a multiple of 4; default :data:`DEFAULT_WIDTH`), ``scale`` (default 1), ``to_world``.
"""

from __future__ import annotations

import mitsuba as mi
import numpy as np

from skyref.analytic import MODELS, analytic_model
from skyref.errors import ParameterError
from skyref.fit.export import read_spectral_table
from skyref.lut import METHODS, lut_method
from skyref.plugins.optics import atmosphere_from_property
from skyref.renderer_frames import WORLD_FROM_ENU, latlong_directions
from skyref.scene import direction_from_angles
from skyref.validation import check_choice, check_int, check_number

__all__ = ["PLUGIN_NAME", "DEFAULT_WIDTH", "MAX_WIDTH", "sky_method", "sky_table", "sky_emitter", "register"]

PLUGIN_NAME = "skyref_sky"
#: Columns of the table by default (0.35° apart; 1024 x 513 texels, 6 MB).
DEFAULT_WIDTH = 1024
MAX_WIDTH = 16384


def sky_method(name: str, atmosphere, coefficients: str = "", turbidity: float | None = None):
    """The sky method ``name`` (:data:`skyref.analytic.MODELS` or :data:`skyref.lut.METHODS`) on
    ``atmosphere`` at the RGB wavelengths (680, 550, 440 nm), precomputed. ``coefficients``: a
    coefficient file whose spectral table ``hosek2012`` evaluates instead of the published one;
    ``turbidity``: the value a model that takes one uses."""
    check_choice("method", name, (*MODELS, *METHODS))
    options = {} if turbidity is None else {"turbidity": turbidity}
    if coefficients:
        if name != "hosek2012":
            raise ParameterError("coefficients", coefficients, "a file only with method 'hosek2012'",
                                 f"{name} has no coefficient table")
        options["table"] = read_spectral_table(coefficients)
    if name in METHODS:
        method = lut_method(name, atmosphere, "rgb", variant=mi.variant(), **options)
    else:
        method = analytic_model(name, atmosphere, "rgb", **options)
    method.precompute()
    return method


def sky_table(method, sun_direction, observer_altitude_m: float, width: int = DEFAULT_WIDTH) -> np.ndarray:
    """The table of the module's documentation: ``method``'s radiance (W m^-2 sr^-1 nm^-1, one
    channel per wavelength) at the nodes of Mitsuba's ``envmap`` layout, ``(width / 2 + 1,
    width, N)`` float32, 0 below the horizon. ``sun_direction``: unit, east-north-up."""
    width = check_int("width", width, 8, MAX_WIDTH)
    if width % 4:
        raise ParameterError("width", width, f"a multiple of 4 in [8, {MAX_WIDTH}]", "the horizon must be a row")
    directions = latlong_directions(width, width // 2 + 1, "mitsuba")
    sky_rows = width // 4 + 1                               # the zenith down to the horizon
    radiance = method.radiance(directions[:sky_rows].reshape(-1, 3), sun_direction, observer_altitude_m)
    table = np.zeros(directions.shape[:2] + (radiance.shape[-1],), dtype=np.float32)
    table[:sky_rows] = radiance.reshape(sky_rows, width, -1)
    return table


def sky_emitter(props):
    """The ``skyref_sky`` plugin: Mitsuba's ``envmap`` holding :func:`sky_table` of the
    properties (see the module's documentation)."""
    variant = mi.variant()
    if "rgb" not in variant.split("_"):
        raise ParameterError("variant", variant, "an RGB variant (e.g. llvm_ad_rgb)",
                             f"{PLUGIN_NAME} holds R, G, B = radiance at 680, 550, 440 nm")
    method = sky_method(props.get("method", "hosek2012"), atmosphere_from_property(props.get("atmosphere", "bruneton2017")),
                        props.get("coefficients", ""), props.get("turbidity", None))
    sun = direction_from_angles(check_number("sun_zenith", props.get("sun_zenith", 30.0), 0.0, 180.0),
                                check_number("sun_azimuth", props.get("sun_azimuth", 180.0)))
    table = sky_table(method, sun, props.get("observer_altitude", 0.0), props.get("width", DEFAULT_WIDTH))
    # The envmap's texel at its local direction l shows the ENU direction R^T l (R: ENU -> y-up),
    # which to_world takes to the world: the envmap's own to_world is to_world @ R^T.
    enu_from_envmap = np.eye(4)
    enu_from_envmap[:3, :3] = WORLD_FROM_ENU["mitsuba"].T
    to_world = props.get("to_world", None)
    to_world = np.linalg.inv(enu_from_envmap) if to_world is None else np.array(to_world.matrix)
    return mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(table), "scale": props.get("scale", 1.0),
                         "to_world": mi.ScalarTransform4f(to_world @ enu_from_envmap)})


def register():
    mi.register_emitter(PLUGIN_NAME, sky_emitter)
