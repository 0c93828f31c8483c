"""A sky scene: atmosphere + sun + observer + camera + spectral sampling + render settings.

Frame convention (observer-centred, east-north-up): x east, y north, z up (local zenith).
Zenith angles are measured from z; azimuths clockwise from north towards east, so a direction
of zenith theta and azimuth phi is (sin theta sin phi, sin theta cos phi, cos theta). The sun
direction points *towards* the sun.

Scenes are stored as TOML (``scenes/*.toml``); :func:`load_scene` and :func:`save_scene`
round-trip.
"""

from __future__ import annotations

import copy
import dataclasses
import datetime as _dt
import math
import os
import tomllib
from dataclasses import dataclass, field

import numpy as np
import tomli_w

from skyref.atmosphere import Atmosphere, from_turbidity, preset, wavelength_grid
from skyref.atmosphere.sun import SUN_ANGULAR_RADIUS_DEG, SunDisk
from skyref.validation import check_array, check_choice, check_fields, check_number
from skyref.errors import ParameterError
from skyref.io.atomic import atomic_write

__all__ = ["direction_from_angles", "Sun", "Observer", "CAMERA_TYPES", "Camera", "PIXEL_SAMPLING", "RENDER_REGIONS",
           "RenderSettings", "OBJECT_TYPES", "SceneObject", "MAX_NAME_LENGTH", "MAX_WAVELENGTHS", "Scene", "atmosphere_from_scene_dict",
           "defaulted_tables", "load_scene", "save_scene"]



def direction_from_angles(zenith_deg, azimuth_deg) -> np.ndarray:
    """Unit vector(s) in the east-north-up frame for zenith/azimuth angles in degrees."""
    theta = np.radians(zenith_deg)
    phi = np.radians(azimuth_deg)
    return np.stack([np.sin(theta) * np.sin(phi), np.sin(theta) * np.cos(phi), np.cos(theta)], axis=-1)


@dataclass(frozen=True)
class Sun:
    """The sun as seen from the observer.

    Either ``zenith_deg``/``azimuth_deg`` directly, or through :meth:`at` (date, time and place,
    via pvlib's solar position algorithm; the geometric zenith is used since skyref does not
    model refraction). ``angular_radius_deg`` sizes the visible disk; ``limb_darkening`` turns
    on the solar limb darkening of the disk's radiance.
    """

    zenith_deg: float = 30.0
    azimuth_deg: float = 180.0
    angular_radius_deg: float = SUN_ANGULAR_RADIUS_DEG
    limb_darkening: bool = False
    time: _dt.datetime | None = None
    latitude_deg: float | None = None
    longitude_deg: float | None = None

    def __post_init__(self):
        check_number("sun.zenith_deg", self.zenith_deg, 0.0, 180.0)
        check_number("sun.azimuth_deg", self.azimuth_deg, -360.0, 720.0)
        if not isinstance(self.limb_darkening, bool):
            raise ParameterError("sun.limb_darkening", self.limb_darkening, "true or false", "not a boolean")
        SunDisk(self.angular_radius_deg, self.limb_darkening)      # checks the angular radius

    @property
    def disk(self) -> SunDisk:
        """The solar disk (angular radius, limb darkening) of :mod:`skyref.atmosphere.sun`."""
        return SunDisk(self.angular_radius_deg, self.limb_darkening)

    @classmethod
    def at(cls, time, latitude_deg: float, longitude_deg: float, altitude_m: float = 0.0, **kwargs) -> "Sun":
        """The sun's position for a time (timezone-aware datetime or ISO 8601 string with an
        offset; naive times are taken as UTC) at a place (degrees north, degrees east)."""
        import pandas as pd  # lazy: pandas and pvlib take ~2 s to import; only Sun.at needs them
        import pvlib

        check_number("sun.latitude_deg", latitude_deg, -90.0, 90.0)
        check_number("sun.longitude_deg", longitude_deg, -180.0, 360.0)
        if isinstance(time, str):
            try:
                time = _dt.datetime.fromisoformat(time)
            except ValueError:
                raise ParameterError("sun.time", time, "ISO 8601, e.g. 2026-06-21T12:00:00+02:00",
                                     "unreadable time") from None
        if not isinstance(time, _dt.datetime):
            raise ParameterError("sun.time", time, "a date and time", "not a datetime")
        if time.tzinfo is None:
            time = time.replace(tzinfo=_dt.timezone.utc)
        position = pvlib.solarposition.get_solarposition(
            pd.DatetimeIndex([time]), latitude_deg, longitude_deg, altitude=altitude_m)
        return cls(zenith_deg=float(position["zenith"].iloc[0]),
                   azimuth_deg=float(position["azimuth"].iloc[0]), time=time,
                   latitude_deg=latitude_deg, longitude_deg=longitude_deg, **kwargs)

    @property
    def direction(self) -> np.ndarray:
        """Unit vector towards the sun, east-north-up."""
        return direction_from_angles(self.zenith_deg, self.azimuth_deg)

    def to_dict(self) -> dict:
        data = {"angular_radius_deg": self.angular_radius_deg, "limb_darkening": self.limb_darkening}
        if self.time is not None:
            data.update(time=self.time, latitude_deg=self.latitude_deg, longitude_deg=self.longitude_deg)
        else:
            data.update(zenith_deg=self.zenith_deg, azimuth_deg=self.azimuth_deg)
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "Sun":
        fields = check_fields("sun", dict(data), cls)
        if "time" in fields:
            for key in ("zenith_deg", "azimuth_deg"):
                if key in fields:
                    raise ParameterError(f"sun.{key}", fields[key], "omitted when sun.time is given",
                                         "conflicting sun position")
            for key in ("latitude_deg", "longitude_deg"):
                if key not in fields:
                    raise ParameterError(f"sun.{key}", None, "degrees; required with sun.time", "missing")
            return cls.at(fields.pop("time"), fields.pop("latitude_deg"), fields.pop("longitude_deg"), **fields)
        return cls(**fields)


@dataclass(frozen=True)
class Observer:
    """Where the camera is: ``altitude_m`` above the ground (the atmosphere is horizontally
    uniform, so altitude is the whole position), 0 m up to 10,000 km (space)."""

    altitude_m: float = 0.0

    def __post_init__(self):
        check_number("observer.altitude_m", self.altitude_m, 0.0, 1.0e7)

    def to_dict(self) -> dict:
        return {"altitude_m": self.altitude_m}

    @classmethod
    def from_dict(cls, data: dict) -> "Observer":
        return cls(**check_fields("observer", dict(data), cls))


CAMERA_TYPES = ("equirectangular", "fisheye", "perspective")


@dataclass(frozen=True)
class Camera:
    """The image: ``equirectangular`` (rows: zenith 0 to 180 deg, columns: azimuth 0 to 360 deg
    clockwise from north), ``fisheye`` (equidistant, ``fov_deg`` across, centred on the view
    direction: 180 deg looking up is the upper hemisphere) or ``perspective`` (``fov_deg``
    horizontally). The view direction is ``view_zenith_deg``/``view_azimuth_deg``."""

    type: str = "equirectangular"
    width: int = 256
    height: int = 128
    fov_deg: float = 180.0
    view_zenith_deg: float = 0.0
    view_azimuth_deg: float = 0.0

    def __post_init__(self):
        check_choice("camera.type", self.type, CAMERA_TYPES)
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 16384:
                raise ParameterError(f"camera.{name}", value, "an integer in [1, 16384]", "invalid size")
        fov_max = 179.0 if self.type == "perspective" else 360.0
        check_number("camera.fov_deg", self.fov_deg, 0.0, fov_max, lo_open=True)
        check_number("camera.view_zenith_deg", self.view_zenith_deg, 0.0, 180.0)
        check_number("camera.view_azimuth_deg", self.view_azimuth_deg, -360.0, 720.0)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "Camera":
        return cls(**check_fields("camera", dict(data), cls))


PIXEL_SAMPLING = ("area", "centre")
#: The ``atmosphere`` integrator's estimators (:mod:`skyref.plugins.integrator`), independent of each
#: other: ``line_integral`` (the default: single scattering by quadrature along the camera ray,
#: forced collisions; 3-40x less CPU to a given error, see ``results/groundtruth_speed.md``, but
#: its kernels take 15 s to minutes to compile for each new configuration, then come from
#: Dr.Jit's disk cache) and ``delta_tracking`` (spectral tracking with next-event estimation at
#: every candidate point: the baseline, and the default before 2026-12-03).
ESTIMATORS = ("delta_tracking", "line_integral")
DEFAULT_ESTIMATOR = "line_integral"
RENDER_REGIONS = ("all", "above_horizon")


@dataclass(frozen=True)
class RenderSettings:
    """Samples per pixel, random seed, number of independent passes (their spread gives each
    pixel's standard error), the longest path (scattering events + 1) and where in a pixel
    the samples look: ``"area"`` (uniformly over the pixel: an image, box filter) or
    ``"centre"`` (the pixel-centre direction only: radiance along exact directions, which is
    what other sky methods evaluate, e.g. in audits); and which pixels are traced: ``"all"``, or
    ``"above_horizon"``, those whose centre looks at or above the observer's horizon (view
    zenith <= 90 deg; the others are NaN), for consumers of the sky alone. ``polarized``
    transports Stokes vectors (I, Q, U, V; :mod:`skyref.plugins.polarization`) instead of
    radiance: the sky then has ``stokes`` too, and its radiance is I. ``estimator``: one of
    :data:`ESTIMATORS`."""

    spp: int = 64
    seed: int = 0
    passes: int = 16
    max_depth: int = 64
    pixel_sampling: str = "area"
    region: str = "all"
    polarized: bool = False
    estimator: str = DEFAULT_ESTIMATOR

    def __post_init__(self):
        for name, lo, hi in (("spp", 1, 1 << 24), ("seed", 0, (1 << 31) - 1), ("passes", 2, 1024),
                             ("max_depth", 1, 100_000)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
                raise ParameterError(f"render.{name}", value, f"an integer in [{lo}, {hi}]", "invalid")
        check_choice("render.pixel_sampling", self.pixel_sampling, PIXEL_SAMPLING)
        check_choice("render.region", self.region, RENDER_REGIONS)
        check_choice("render.estimator", self.estimator, ESTIMATORS)
        if not isinstance(self.polarized, (bool, np.bool_)):
            raise ParameterError("render.polarized", self.polarized, "true or false", "not a boolean")
        object.__setattr__(self, "polarized", bool(self.polarized))

    def to_dict(self) -> dict:
        """The settings as a TOML table; ``polarized`` only when true, so that a scalar scene is
        written (in image headers, cache keys, batch fingerprints) as before it existed. The
        estimator is always written: a scene written without it was rendered with delta
        tracking (the default until 2026-12-03), and must not match one of today's default."""
        data = dataclasses.asdict(self)
        if not self.polarized:
            del data["polarized"]
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "RenderSettings":
        return cls(**check_fields("render", dict(data), cls))


OBJECT_TYPES = ("obj", "ply", "sphere", "rectangle", "cube", "disk", "cylinder")


@dataclass(frozen=True)
class SceneObject:
    """A Lambertian object standing in the atmosphere (terrain, a building, a test target):
    a Mitsuba shape of ``type`` (``filename`` for meshes), scaled by ``scale_m`` and moved by
    ``translate_m`` in the observer's east-north-up frame (metres; the ground under the
    observer is at z = -altitude). ``albedo`` is its grey Lambertian reflectance."""

    type: str
    albedo: float = 0.2
    filename: str = ""
    translate_m: tuple = (0.0, 0.0, 0.0)
    scale_m: tuple = (1.0, 1.0, 1.0)

    def __post_init__(self):
        check_choice("objects.type", self.type, OBJECT_TYPES)
        check_number("objects.albedo", self.albedo, 0.0, 1.0)
        if self.type in ("obj", "ply") and not self.filename:
            raise ParameterError("objects.filename", self.filename, "a mesh file", "missing")
        for name in ("translate_m", "scale_m"):
            value = getattr(self, name)
            if isinstance(value, (int, float)):
                value = (value,) * 3
            object.__setattr__(self, name, tuple(check_array(f"objects.{name}", value, min_length=3)))
            if len(getattr(self, name)) != 3:
                raise ParameterError(f"objects.{name}", value, "three numbers (x, y, z)", "wrong length")
        if min(self.scale_m) <= 0.0:
            raise ParameterError("objects.scale_m", self.scale_m, "three positive numbers", "not positive")

    def mitsuba_dict(self) -> dict:
        import mitsuba as mi  # lazy: Mitsuba's start-up cost; loaded through skyref.plugins.load_mitsuba

        shape = {"type": self.type,
                 "to_world": mi.ScalarTransform4f().translate(list(self.translate_m)).scale(list(self.scale_m)),
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [self.albedo] * 3}}}
        if self.filename:
            shape["filename"] = self.filename
        return shape

    def to_dict(self) -> dict:
        data = dataclasses.asdict(self)
        data["translate_m"], data["scale_m"] = list(self.translate_m), list(self.scale_m)
        if not self.filename:
            del data["filename"]
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "SceneObject":
        return cls(**check_fields("objects", dict(data), cls))


#: Longest scene name, characters (it goes into file names and image headers).
MAX_NAME_LENGTH = 200

#: Most wavelengths one scene renders (each is a channel of every path: ~100 bytes of state per
#: sample and channel).
MAX_WAVELENGTHS = 1000


@dataclass(frozen=True)
class Scene:
    atmosphere: Atmosphere = field(default_factory=lambda: preset("bruneton2017"))
    sun: Sun = Sun()
    observer: Observer = Observer()
    camera: Camera = Camera()
    wavelengths: object = "rgb"
    render: RenderSettings = RenderSettings()
    name: str = ""
    objects: tuple = ()

    def __post_init__(self):
        if not isinstance(self.name, str) or len(self.name) > MAX_NAME_LENGTH:
            raise ParameterError("name", self.name, f"a string of at most {MAX_NAME_LENGTH} characters",
                                 "too long or not a string")
        spec = self.wavelengths
        if isinstance(spec, (list, tuple, np.ndarray)):
            if len(spec) > MAX_WAVELENGTHS:
                raise ParameterError("spectral.wavelengths", f"{len(spec):,} wavelengths",
                                     f"at most {MAX_WAVELENGTHS}", "too many for one render: split the spectrum")
            spec = tuple(float(x) for x in spec)
        object.__setattr__(self, "wavelengths", spec)
        if len(self.wavelengths_nm) > MAX_WAVELENGTHS:
            raise ParameterError("spectral.wavelengths", f"{len(self.wavelengths_nm):,} wavelengths",
                                 f"at most {MAX_WAVELENGTHS}", "too many for one render: a coarser step, or "
                                 "split the spectrum into several scenes")
        object.__setattr__(self, "objects", tuple(self.objects))
        for item in self.objects:
            if not isinstance(item, SceneObject):
                raise ParameterError("objects", item, "SceneObject entries", "wrong type")
        self.atmosphere.check_wavelengths(self.wavelengths_nm)

    @property
    def wavelengths_nm(self) -> np.ndarray:
        return wavelength_grid(list(self.wavelengths) if isinstance(self.wavelengths, tuple) else self.wavelengths)

    def replace(self, **changes) -> "Scene":
        return dataclasses.replace(self, **changes)

    def check_files(self) -> None:
        """Raise a ParameterError if an object's mesh file does not exist (paths are relative to
        the working directory, as Mitsuba reads them). Called before a render starts, not when a
        scene is built: a scene read back from an image header stays readable elsewhere."""
        for i, item in enumerate(self.objects):
            if item.filename and not os.path.isfile(item.filename):
                raise ParameterError(f"objects[{i}].filename", item.filename, "an existing .obj or .ply file",
                                     "file not found")

    def to_dict(self) -> dict:
        wavelengths = list(self.wavelengths) if isinstance(self.wavelengths, tuple) else self.wavelengths
        data = {"atmosphere": self.atmosphere.to_dict(), "sun": self.sun.to_dict(),
                "observer": self.observer.to_dict(), "camera": self.camera.to_dict(),
                "spectral": {"wavelengths": wavelengths}, "render": self.render.to_dict()}
        if self.name:
            data["name"] = self.name
        if self.objects:
            data["objects"] = [item.to_dict() for item in self.objects]
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "Scene":
        known = ("name", "atmosphere", "sun", "observer", "camera", "spectral", "render", "objects")
        for key in data:
            if key not in known:
                raise ParameterError(key, data[key], "top-level tables " + ", ".join(known), "unknown entry")
        spectral = dict(data.get("spectral", {}))
        wavelengths = spectral.pop("wavelengths", "rgb")
        if spectral:
            key = next(iter(spectral))
            raise ParameterError(f"spectral.{key}", spectral[key], "only spectral.wavelengths", "unknown parameter")
        return cls(atmosphere=atmosphere_from_scene_dict(data.get("atmosphere", {"preset": "bruneton2017"})),
                   sun=Sun.from_dict(data.get("sun", {})),
                   observer=Observer.from_dict(data.get("observer", {})),
                   camera=Camera.from_dict(data.get("camera", {})),
                   wavelengths=wavelengths,
                   render=RenderSettings.from_dict(data.get("render", {})),
                   name=data.get("name", ""),
                   objects=tuple(SceneObject.from_dict(item) for item in data.get("objects", [])))


def _merge(base: dict, overrides: dict) -> dict:
    merged = copy.deepcopy(base)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = _merge(merged[key], value)
        else:
            merged[key] = value
    return merged


def atmosphere_from_scene_dict(data: dict) -> Atmosphere:
    """Build an atmosphere from a scene's ``[atmosphere]`` table.

    ``preset = NAME`` starts from a preset; every other key overrides it (tables merge key by
    key: ``[atmosphere.constituents.aerosol] angstrom_beta = 0.1``); a constituent set to
    ``false`` is removed; ``turbidity = T`` finally re-derives the aerosol with
    :func:`~skyref.atmosphere.from_turbidity`. Without a preset the table must describe the whole
    atmosphere (as :func:`save_scene` writes it).
    """
    fields = dict(data)
    name = fields.pop("preset", None)
    turbidity = fields.pop("turbidity", None)
    if name is None and "constituents" not in fields:
        raise ParameterError("atmosphere", sorted(data), 'a preset (e.g. preset = "bruneton2017"), or a '
                             "[atmosphere.constituents] table (an empty one for a vacuum)",
                             "neither: the atmosphere would be empty")
    merged = _merge(preset(name).to_dict(), fields) if name is not None else fields
    constituents = merged.get("constituents", {})
    merged["constituents"] = {k: v for k, v in constituents.items() if v is not False}
    atmosphere = Atmosphere.from_dict(merged)
    if turbidity is not None:
        atmosphere = from_turbidity(turbidity, base=atmosphere)
    return atmosphere


def defaulted_tables(scene: Scene, data: dict) -> str:
    """What a scene file left to the defaults, in words ("" if it set every table): an empty
    or name-only file is a whole default scene, and the user should be told which."""
    defaults = {"atmosphere": f"the {scene.atmosphere.name or 'default'} preset",
                "sun": f"sun at zenith {scene.sun.zenith_deg:g} deg, azimuth {scene.sun.azimuth_deg:g} deg",
                "observer": f"observer at {scene.observer.altitude_m:g} m",
                "camera": f"{scene.camera.type} camera {scene.camera.width}x{scene.camera.height}",
                "spectral": f"{len(scene.wavelengths_nm)} wavelengths ({scene.wavelengths})",
                "render": f"{scene.render.spp} spp in {scene.render.passes} passes"}
    missing = [f"no [{table}]: {text}" for table, text in defaults.items() if table not in data]
    return "defaults used: " + "; ".join(missing) if missing else ""


def load_scene(path, report=None) -> Scene:
    """Read a scene TOML file; errors name the file and the offending entry. ``report``, if
    given, is called with a line saying which tables the file left to the defaults."""
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise ParameterError("scene", str(path), "an existing TOML file", "file not found") from None
    except IsADirectoryError:
        raise ParameterError("scene", str(path), "an existing TOML file", "a directory") from None
    except UnicodeDecodeError:
        raise ParameterError("scene", str(path), "a UTF-8 TOML text file", "not text (binary?)") from None
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError("scene", str(path), "valid TOML", f"TOML syntax error: {exc}") from None
    scene = Scene.from_dict(data)
    scene.check_files()
    if not scene.name:
        scene = scene.replace(name=str(path).rsplit("/", 1)[-1].removesuffix(".toml"))
    if report is not None and defaulted_tables(scene, data):
        report(f"{path}: {defaulted_tables(scene, data)}")
    return scene


def save_scene(scene: Scene, path) -> None:
    """Write the scene, fully resolved (no preset), atomically."""
    with atomic_write(path, "wb") as f:
        tomli_w.dump(scene.to_dict(), f)
