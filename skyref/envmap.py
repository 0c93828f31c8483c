"""Environment maps: a skyref sky as the latitude–longitude RGB image that lights a Mitsuba or
Blender scene, with the sun as a separate light or inside the map.

The sky is rendered by the path tracer (:func:`skyref.render.render_sky`) through an
equirectangular camera of ``width`` x ``width / 2`` pixels, each the mean radiance over its solid
angle (or along its centre, with the scene's ``render.pixel_sampling = "centre"``), and laid out
for a renderer (``orientation``; frames and layouts: :mod:`skyref.renderer_frames`):

- ``mitsuba``: Mitsuba 3's ``envmap`` with no ``to_world`` in a y-up world (east +x, up +y,
  north -z): ``width`` x (``width / 2 + 1``) texels whose rows are nodes from the zenith to the
  nadir (the horizon is one: ``width`` is a multiple of 4) and whose columns are centred at
  azimuth 360° (i + 0.5) / width. The pixels are interpolated linearly onto the nodes (a node
  holds the mean of the two pixel rows it separates; the zenith and nadir nodes their pixel).
- ``blender``: Blender's Environment Texture (equirectangular) in a z-up world with north +y
  (the Sun Position add-on's default; the axes of skyref's east-north-up frame): the pixels
  themselves, their columns turned a quarter turn (east in the middle of the image).

Colour and units: linear sRGB (Rec. 709 primaries, D65 white, the OpenEXR default), absolute, on
the photometric scale of :mod:`skyref.color`: R = G = B = the luminance in cd m^-2 for D65 white
(the spectral radiance through the CIE 1931 colour matching functions, times 683 lm/W, then XYZ
-> linear sRGB). The sun's irradiance is on the same scale (R = G = B = the illuminance in lux for
D65 white), so the map integrated against cos(angle) dω plus the sun's irradiance times the
cosine of its angle gives a surface's illuminance, and a white Lambertian surface's luminance is
that over π (divide by 683 for radiometric values weighted by the luminosity function). Values
are not clipped: a colour outside the sRGB gamut (deep twilight blue) may have a slightly
negative channel. Below the horizon: the ground as rendered (the planet's surface lit by sun and
sky, seen through the air); pixels the scene's ``render.region`` skips are black.

The sun (``sun``) carries its transmitted irradiance (:func:`direct_sun_irradiance`):

- ``separate``: the map holds the sky without the solar disk (the path tracer's ``sun_direct``
  order is left out); the sun is a directional light: a Mitsuba ``directional`` emitter in the
  XML scene written beside the EXR (``sky.mitsuba.xml``, to ``<include>`` or load), or a Blender
  Sun light in the Python script written beside it (``sky.blender.py``).
- ``in-map``: the irradiance is spread over the four texels around the sun's direction with
  bilinear weights (which keep its direction to second order in the texel size), each texel's
  value such that the renderer's bilinear interpolation of it integrates to its share. The disk
  (0.53°) is smaller than a texel (0.70° at width 512), so the sun is blurred over about two
  texels: shadows are that soft. Near the poles Mitsuba's ``envmap`` samples directions sparsely
  (its sampling density goes as sin(zenith angle)): a sun within a texel of the zenith is noisy
  there, use ``separate``.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

import numpy as np
import tomli_w

from skyref.errors import ParameterError
from skyref.io.atomic import atomic_path, atomic_write
from skyref.projection import equirectangular_pixel
from skyref.render import render_sky
from skyref.renderer_frames import RENDERERS, latlong_film_coordinates, to_world
from skyref.scene import Camera
from skyref.validation import check_choice, check_int

__all__ = ["ORIENTATIONS", "SUN_MODES", "DEFAULT_WIDTH", "MAX_WIDTH", "UNITS", "EnvironmentMap", "check_width",
           "envmap_scene", "direct_sun_irradiance", "environment_map", "render_environment_map", "snippet_path",
           "mitsuba_emitters", "mitsuba_xml", "blender_script", "write_environment_map"]

ORIENTATIONS = RENDERERS
SUN_MODES = ("separate", "in-map")
#: Columns of the map by default (0.70° per texel; the sky is rendered at 512 x 256 pixels).
DEFAULT_WIDTH = 512
#: The widest map: the widest camera skyref renders.
MAX_WIDTH = 16384
#: What the map's values are (see the module's documentation).
UNITS = ("linear sRGB (Rec. 709 primaries, D65 white), absolute: R = G = B = luminance in cd m^-2 for D65 "
         "white; the sun's irradiance on the same scale (lux)")

#: File names of the snippet written beside the EXR, per orientation.
_SNIPPET_SUFFIX = {"mitsuba": ".mitsuba.xml", "blender": ".blender.py"}


@dataclass(frozen=True)
class EnvironmentMap:
    """A sky laid out for a renderer (see the module's documentation)."""

    rgb: np.ndarray                  # (rows, width, 3) float32, row 0 at the top of the file (the zenith)
    orientation: str                 # one of ORIENTATIONS
    sun_mode: str                    # one of SUN_MODES
    sun_direction: np.ndarray        # (3,) unit, towards the sun, in the renderer's world frame
    sun_irradiance: np.ndarray       # (3,) linear sRGB (lux scale) perpendicular to the beam; 0 if hidden
    sun_angular_radius_deg: float
    scene: object = None             # the skyref.scene.Scene that was rendered

    def header(self) -> dict:
        """What the EXR's ``skyref.envmap`` header attribute says about the map (JSON-ready)."""
        return {"orientation": self.orientation, "sun": self.sun_mode, "units": UNITS,
                "sun_direction_world": self.sun_direction.tolist(),
                "sun_irradiance_rgb": self.sun_irradiance.tolist(),
                "sun_angular_radius_deg": self.sun_angular_radius_deg}


def check_width(width, name: str = "width") -> int:
    """``width`` if it is a multiple of 4 in [8, MAX_WIDTH] (the horizon is a row of Mitsuba's
    map; Blender's columns turn by width / 4), else a ParameterError naming ``name``."""
    width = check_int(name, width, 8, MAX_WIDTH)
    if width % 4:
        raise ParameterError(name, width, f"a multiple of 4 in [8, {MAX_WIDTH}]", "not a multiple of 4")
    return width


def envmap_scene(scene, width: int = DEFAULT_WIDTH):
    """``scene`` with its camera replaced by the equirectangular ``width`` x ``width / 2`` camera
    the map is rendered through."""
    width = check_width(width)
    return scene.replace(camera=Camera(type="equirectangular", width=width, height=width // 2))


def direct_sun_irradiance(scene) -> np.ndarray:
    """The sun's spectral irradiance at the observer, perpendicular to the beam, W m^-2 nm^-1 at
    the scene's wavelengths: the extraterrestrial irradiance times the transmittance along the
    disk's centre (:meth:`skyref.atmosphere.Atmosphere.transmittance`), 0 when the ground hides
    that centre. An observer above the atmosphere sees the sun through the stretch of the ray
    inside it. (A point sun: across the 0.53° disk the transmittance varies appreciably only
    within about a degree of the horizon, where the disk's mean departs from this value.)"""
    atmosphere, wavelengths = scene.atmosphere, scene.wavelengths_nm
    irradiance = scene.sun.disk.irradiance(wavelengths)
    altitude = scene.observer.altitude_m
    mu = math.cos(math.radians(scene.sun.zenith_deg))
    r, top = atmosphere.bottom_radius_m + altitude, atmosphere.top_radius_m
    if r > top:
        # From space: move to where the ray enters the top of the atmosphere (at distance
        # -r mu - sqrt(disc), where its zenith cosine is -sqrt(disc) / top), if it does.
        discriminant = (r * mu) ** 2 - (r * r - top * top)
        if mu >= 0.0 or discriminant <= 0.0:
            return irradiance
        altitude, mu = atmosphere.thickness_m, -math.sqrt(discriminant) / top
    if atmosphere.distance_to_boundary(altitude, mu)[1]:
        return np.zeros_like(irradiance)
    return irradiance * atmosphere.transmittance(wavelengths, altitude, mu)


def _resample(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """An equirectangular image (H, W, C) (pixel centres at film coordinates ((k + 0.5) / W,
    (m + 0.5) / H)) interpolated bilinearly at columns ``u`` and rows ``v``: periodic in u,
    clamped in v (beyond the first and last pixel rows' centres, their values)."""
    height, width = image.shape[:2]
    y = np.clip(v * height - 0.5, 0.0, height - 1.0)
    row = np.minimum(np.floor(y).astype(np.int64), height - 2)
    fy = (y - row)[:, None, None]
    rows = image[row] * (1.0 - fy) + image[row + 1] * fy
    x = u * width - 0.5
    column = np.floor(x).astype(np.int64)
    fx = (x - column)[None, :, None]
    return rows[:, column % width] * (1.0 - fx) + rows[:, (column + 1) % width] * fx


def _ramp_sin_integral(a: float, fa: float, b: float, fb: float) -> float:
    """The integral of f(theta) sin(theta) over [a, b], f linear from fa at a to fb at b."""
    if b <= a:
        return 0.0
    slope = (fb - fa) / (b - a)
    return fa * math.cos(a) - fb * math.cos(b) + slope * (math.sin(b) - math.sin(a))


def _texel_row_solid_angle(theta: np.ndarray, j: int) -> float:
    """The integral over zenith angle of sin(theta) times row j's weight in linear interpolation
    between rows at zenith angles ``theta`` (uniform; clamped beyond the first and last), rad:
    with 2 pi / width, the solid angle a unit texel of that row lights under bilinear
    interpolation."""
    last = theta.size - 1
    left = (_ramp_sin_integral(theta[j - 1], 0.0, theta[j], 1.0) if j > 0
            else _ramp_sin_integral(0.0, 1.0, theta[0], 1.0))
    right = (_ramp_sin_integral(theta[j], 1.0, theta[j + 1], 0.0) if j < last
             else _ramp_sin_integral(theta[last], 1.0, math.pi, 1.0))
    return left + right


def _add_sun(rgb: np.ndarray, u: np.ndarray, v: np.ndarray, sun_enu, irradiance: np.ndarray) -> None:
    """Spread ``irradiance`` (3,) over the four texels of ``rgb`` (texel columns at film
    coordinates ``u``, rows at ``v``, both uniform) around the direction ``sun_enu`` with bilinear
    weights, each texel divided by the solid angle it lights under bilinear interpolation."""
    height, width = rgb.shape[:2]
    sun_u, sun_v = equirectangular_pixel(sun_enu)
    du = u[1] - u[0]
    x = (float(sun_u) - u[0]) / du
    column = math.floor(x)
    fx = x - column
    y = min(max((float(sun_v) - v[0]) / (v[1] - v[0]), 0.0), height - 1.0)
    row = min(math.floor(y), height - 2)
    fy = y - row
    theta = math.pi * v
    for j, wj in ((row, 1.0 - fy), (row + 1, fy)):
        solid_angle = 2.0 * math.pi * du * _texel_row_solid_angle(theta, j)
        for i, wi in ((column, 1.0 - fx), (column + 1, fx)):
            rgb[j, i % width] += (wi * wj / solid_angle) * irradiance


def environment_map(sky, orientation: str = "mitsuba", sun: str = "separate") -> EnvironmentMap:
    """The map of ``sky`` (a :class:`~skyref.sky.Sky` rendered through :func:`envmap_scene`'s
    camera, with its ``sun_direct`` order) for the renderer ``orientation``, with the ``sun``
    ``separate`` or ``in-map`` (see the module's documentation)."""
    from skyref.color import spectral_to_linear_srgb  # lazy: colour-science takes seconds to import

    check_choice("orientation", orientation, ORIENTATIONS)
    check_choice("sun", sun, SUN_MODES)
    scene = sky.scene
    height, width = sky.radiance.shape[:2]
    if scene is None or scene.camera.type != "equirectangular" or width % 4 or height * 2 != width:
        raise ParameterError("sky", f"{width}x{height} {scene.camera.type if scene else 'sky without a scene'}",
                             "a sky rendered through envmap_scene's equirectangular camera (width a multiple "
                             "of 4, height width / 2)", "not an environment-map render")
    if "sun_direct" not in sky.orders:
        raise ParameterError("sky.orders", sorted(sky.orders), "a sky with its sun_direct order",
                             "the solar disk cannot be separated")
    diffuse = np.nan_to_num(np.asarray(sky.radiance, np.float64) - sky.orders["sun_direct"], nan=0.0)
    u, v = latlong_film_coordinates(width, height + 1 if orientation == "mitsuba" else height, orientation)
    rgb = _resample(spectral_to_linear_srgb(diffuse, sky.wavelengths_nm), u, v)
    irradiance = spectral_to_linear_srgb(direct_sun_irradiance(scene), sky.wavelengths_nm)
    if sun == "in-map" and np.any(irradiance != 0.0):
        _add_sun(rgb, u, v, scene.sun.direction, irradiance)
    return EnvironmentMap(rgb=rgb.astype(np.float32), orientation=orientation, sun_mode=sun,
                          sun_direction=to_world(scene.sun.direction, orientation), sun_irradiance=irradiance,
                          sun_angular_radius_deg=scene.sun.angular_radius_deg, scene=scene)


def render_environment_map(scene, width: int = DEFAULT_WIDTH, orientation: str = "mitsuba", sun: str = "separate",
                           spp: int | None = None, passes: int | None = None, seed: int | None = None,
                           variant: str | None = None, progress: bool = False) -> EnvironmentMap:
    """Render ``scene``'s sky through an equirectangular ``width`` x ``width / 2`` camera (the
    scene's own camera is not used; ``spp``, ``passes``, ``seed``: overrides of its render
    settings) and lay it out with :func:`environment_map`. Arguments are checked first."""
    check_choice("orientation", orientation, ORIENTATIONS)
    check_choice("sun", sun, SUN_MODES)
    sky = render_sky(envmap_scene(scene, width), spp=spp, passes=passes, seed=seed, variant=variant,
                     progress=progress)
    return environment_map(sky, orientation, sun)


def snippet_path(path, orientation: str) -> str:
    """The file written beside the EXR ``path``: ``sky.exr`` -> ``sky.mitsuba.xml`` or
    ``sky.blender.py``."""
    return os.path.splitext(os.fspath(path))[0] + _SNIPPET_SUFFIX[check_choice("orientation", orientation,
                                                                                ORIENTATIONS)]


def _light_sun(envmap: EnvironmentMap) -> bool:
    return envmap.sun_mode == "separate" and bool(np.any(envmap.sun_irradiance != 0.0))


def mitsuba_emitters(envmap: EnvironmentMap, filename: str) -> dict:
    """Mitsuba 3 emitters (a dict for ``mi.load_dict``'s scene) lighting a y-up scene with the
    map stored at ``filename``: ``sky``, the ``envmap``; ``sun``, the ``directional`` emitter (its
    ``direction`` the light's, away from the sun), when the sun is separate and not hidden."""
    if envmap.orientation != "mitsuba":
        raise ParameterError("orientation", envmap.orientation, "'mitsuba'", "not a Mitsuba map")
    emitters = {"sky": {"type": "envmap", "filename": os.fspath(filename)}}
    if _light_sun(envmap):
        emitters["sun"] = {"type": "directional", "direction": (-envmap.sun_direction).tolist(),
                           "irradiance": {"type": "rgb", "value": envmap.sun_irradiance.tolist()}}
    return emitters


def _describe(envmap: EnvironmentMap) -> str:
    scene = envmap.scene
    sun = scene.sun if scene is not None else None
    where = f"sun at zenith {sun.zenith_deg:g} deg, azimuth {sun.azimuth_deg:g} deg" if sun else "sun"
    how = ("the sun in the map" if envmap.sun_mode == "in-map" else
           "the sun as a separate light" if _light_sun(envmap) else "no direct sun (hidden by the ground)")
    name = " ".join(scene.name.split()) if scene is not None else ""     # one line, for comments
    return f"skyref sky {name}: {where}; {how}."


def mitsuba_xml(envmap: EnvironmentMap, filename: str) -> str:
    """A Mitsuba 3 XML scene holding :func:`mitsuba_emitters` (``filename``: the EXR, relative
    paths resolving against the including scene's directory), to ``<include>`` in a y-up scene
    or load on its own."""
    emitters = mitsuba_emitters(envmap, filename)
    lines = ['<scene version="3.0.0">',
             f"    <!-- {_describe(envmap).replace('--', '- -')}",
             f"         Units: {UNITS}.",
             "         World frame: y up, east +x, north -z. Colours as given in RGB variants (e.g. llvm_ad_rgb). -->",
             '    <emitter type="envmap">',
             f'        <string name="filename" value={quoteattr(emitters["sky"]["filename"])}/>',
             "    </emitter>"]
    if "sun" in emitters:
        x, y, z = emitters["sun"]["direction"]
        rgb = ", ".join(repr(c) for c in emitters["sun"]["irradiance"]["value"])
        lines += ['    <emitter type="directional">',
                  f'        <vector name="direction" x="{x!r}" y="{y!r}" z="{z!r}"/>',
                  f'        <rgb name="irradiance" value="{rgb}"/>',
                  "    </emitter>"]
    return "\n".join(lines + ["</scene>", ""])


def blender_script(envmap: EnvironmentMap, filename: str) -> str:
    """A Blender Python script that makes the map at ``filename`` the world's Environment
    Texture and, with the sun separate, adds a Sun light (strength: the irradiance on the map's
    scale; angle: the disk's diameter). Run it in Blender's Scripting workspace or with
    ``blender --python``."""
    if envmap.orientation != "blender":
        raise ParameterError("orientation", envmap.orientation, "'blender'", "not a Blender map")
    light_sun = _light_sun(envmap)
    strength = float(np.max(envmap.sun_irradiance)) if light_sun else 0.0
    colour = tuple(float(c) for c in envmap.sun_irradiance / strength) if light_sun else (1.0, 1.0, 1.0)
    return f'''# {_describe(envmap)}
# Units: {UNITS}; set the exposure to taste (Film > Exposure, or the Background's Strength).
# World frame: z up, north +y (the Sun Position add-on's default), east +x.
import math

import bpy
from mathutils import Vector

IMAGE = {os.path.abspath(os.fspath(filename))!r}
SUN_DIRECTION = {tuple(float(c) for c in envmap.sun_direction)!r}  # unit vector towards the sun
SUN_STRENGTH = {strength!r}  # irradiance perpendicular to the beam (largest channel); 0: no Sun light
SUN_COLOR = {colour!r}
SUN_ANGLE_DEG = {2.0 * envmap.sun_angular_radius_deg!r}  # the disk's angular diameter

scene = bpy.context.scene
world = scene.world or bpy.data.worlds.new("skyref")
scene.world = world
world.use_nodes = True
nodes, links = world.node_tree.nodes, world.node_tree.links
nodes.clear()
texture = nodes.new("ShaderNodeTexEnvironment")
texture.image = bpy.data.images.load(IMAGE, check_existing=True)
for name in ("Linear Rec.709", "Linear"):  # Blender 4, Blender 2.8-3
    try:
        texture.image.colorspace_settings.name = name
        break
    except TypeError:
        pass
background = nodes.new("ShaderNodeBackground")
output = nodes.new("ShaderNodeOutputWorld")
links.new(texture.outputs["Color"], background.inputs["Color"])
links.new(background.outputs["Background"], output.inputs["Surface"])

if SUN_STRENGTH > 0.0:
    light = bpy.data.lights.new("skyref sun", type="SUN")
    light.energy = SUN_STRENGTH
    light.color = SUN_COLOR
    light.angle = math.radians(SUN_ANGLE_DEG)
    sun = bpy.data.objects.new("skyref sun", light)
    scene.collection.objects.link(sun)
    sun.rotation_mode = "QUATERNION"
    sun.rotation_quaternion = Vector(SUN_DIRECTION).to_track_quat("Z", "Y")  # a Sun light shines along its -Z
'''


def write_environment_map(envmap: EnvironmentMap, path) -> tuple[str, str]:
    """Write the map to the RGB OpenEXR ``path`` (channels R, G, B, 32-bit float, ZIP; header
    ``skyref.envmap``: :meth:`EnvironmentMap.header` as JSON, and ``skyref.scene``) and its
    snippet beside it (:func:`snippet_path`: Mitsuba XML or Blender script), each atomically.
    Returns both paths."""
    import OpenEXR  # lazy: kept off the `skyref --help` path

    path = os.fspath(path)
    snippet = snippet_path(path, envmap.orientation)
    text = (mitsuba_xml(envmap, os.path.basename(path)) if envmap.orientation == "mitsuba"
            else blender_script(envmap, path))
    channels = {c: np.ascontiguousarray(envmap.rgb[..., i], dtype=np.float32) for i, c in enumerate("RGB")}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
              "skyref.envmap": json.dumps(envmap.header(), sort_keys=True)}
    if envmap.scene is not None:
        header["skyref.scene"] = tomli_w.dumps(envmap.scene.to_dict())
    with atomic_path(path) as tmp, OpenEXR.File(header, channels) as exr:
        exr.write(tmp)
    with atomic_write(snippet) as f:
        f.write(text)
    return path, snippet
