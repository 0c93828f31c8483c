"""The atmosphere integrator's spherical scene, described for Mitsuba's stock ``volpath``.

:func:`stock_volpath_scene` returns a dict for ``mi.load_dict``: the planet (a sphere of radius
R centred at (0, 0, -(R + h0)), Lambertian with the atmosphere's ground albedo), the top of the
atmosphere (a sphere of radius R_top with a ``null`` BSDF whose interior is the
``atmosphere_medium``), the sensor (inside the medium) and the sun as a ``directional``
emitter delivering the ASTM G173 top-of-atmosphere irradiance (10 nm bin means, as the
integrator uses). Everything is in the observer-centred east-north-up
frame of the ``atmosphere`` integrator (metres), so both see the same scene.

Differences that remain, by construction:

* Mitsuba's ``directional`` emitter is a delta light: there is no solar disk, neither seen
  directly nor as a source of finite size. Compare the sky away from the sun only (the
  integrator's ``sun_direct`` order has no counterpart here).
* ``volpath``'s ``max_depth`` counts the camera vertex: ``max_depth + 1`` is passed so that both
  integrators allow the same number of scattering events.
* Mitsuba's spheres intersect in float32 in ``*_ad_*`` variants. A ray starting exactly on the
  ground sphere hits it at t = 0 (measured: a sensor at z = 0 sees a black sky), so a sensor
  must not sit on the ground: put it :data:`GROUND_CLEARANCE_M` above (``sensor_origin``); the
  sky changes by ~1e-4 relative or less per metre of altitude. Distances to the ground carry
  errors of metres (measured: looking 5 degrees down from 1 m, the ground 11.4 m away comes
  ~2 m early, and volpath is 16-20% darker than the integrator there), and ground bounces are
  only trustworthy with a black ground (docs/design.md: the float32 sphere self-intersects there).

The ``skyref_directions`` sensor (:class:`DirectionsSensorMethods`) shoots rays along a given
list of M directions, one per film column (the rows are independent repeats), for
per-direction comparisons with the integrator's ``render_directions``;
:func:`directions_sensor` builds its dict.
"""

from __future__ import annotations

import json

import drjit as dr
import mitsuba as mi
import numpy as np

from skyref.atmosphere import ConstantSpectrum, solar_irradiance
from skyref.errors import ParameterError
from skyref.plugins import medium
from skyref.plugins.medium import default_wavelengths
from skyref.plugins.optics import atmosphere_from_property
from skyref.plugins.variant_class import variant_class
from skyref.scene import direction_from_angles

__all__ = ["GROUND_CLEARANCE_M", "MEDIUM_ID", "register", "sensor_origin", "stock_volpath_scene", "directions_sensor",
           "DirectionsSensorMethods", "directions_sensor_class"]

#: Height of the sensor above the ground when the observer stands on it, m (see module notes).
GROUND_CLEARANCE_M = 1.0
#: Identifier of the medium in the scene dict.
MEDIUM_ID = "air"

_registered = set()


def register():
    """Register ``atmosphere_medium``, ``atmosphere_phase`` and ``skyref_directions`` for the
    current variant (idempotent)."""
    if mi.variant() in _registered:
        return
    medium.register()
    cls = directions_sensor_class()
    mi.register_sensor("skyref_directions", lambda props: cls(props))
    _registered.add(mi.variant())


def sensor_origin(observer_altitude_m: float) -> list:
    """Where to put a stock sensor for an observer at ``observer_altitude_m`` (scene frame):
    the origin, lifted to :data:`GROUND_CLEARANCE_M` above the ground when it would be lower."""
    return [0.0, 0.0, max(0.0, GROUND_CLEARANCE_M - float(observer_altitude_m))]


def _spectrum(values_at_grid, grid):
    """A Mitsuba spectrum dict for values on the variant's default grid."""
    values = np.asarray(values_at_grid, dtype=np.float64)
    if mi.is_spectral:
        return {"type": "regular", "wavelength_min": float(grid[0]), "wavelength_max": float(grid[-1]),
                "values": ", ".join(f"{v:.9g}" for v in values)}
    return {"type": "rgb", "value": [float(v) for v in values]}


def stock_volpath_scene(atmosphere, sun_zenith_deg: float, sun_azimuth_deg: float,
                        observer_altitude_m: float, sensor_dict: dict, max_depth: int = 64,
                        majorant: str = "segment") -> dict:
    """A ``mi.load_dict`` scene for stock ``volpath`` equal to what the ``atmosphere``
    integrator renders (see the module notes for what differs). ``atmosphere`` is an Atmosphere,
    a preset name or its JSON; angles in degrees (azimuth clockwise from north); the sensor is
    given ``medium`` = the atmosphere. ``max_depth`` counts scattering events as in the
    integrator."""
    register()
    atmosphere = atmosphere_from_property(atmosphere)
    h0 = float(observer_altitude_m)
    centre = [0.0, 0.0, -(atmosphere.bottom_radius_m + h0)]
    grid = default_wavelengths()
    albedo = atmosphere.ground_albedo
    reflectance = ({"type": "uniform", "value": float(albedo.value)} if isinstance(albedo, ConstantSpectrum)
                   else _spectrum(albedo(grid), grid))
    towards_sun = direction_from_angles(sun_zenith_deg, sun_azimuth_deg)
    sensor = dict(sensor_dict)
    sensor["medium"] = {"type": "ref", "id": MEDIUM_ID}
    return {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": int(max_depth) + 1},
        MEDIUM_ID: {"type": medium.PLUGIN_NAME, "atmosphere": json.dumps(atmosphere.to_dict()),
                    "observer_altitude": h0, "majorant": majorant},
        "planet": {"type": "sphere", "center": centre, "radius": float(atmosphere.bottom_radius_m),
                   "bsdf": {"type": "diffuse", "reflectance": reflectance}},
        "atmosphere_boundary": {"type": "sphere", "center": centre,
                                "radius": float(atmosphere.top_radius_m), "bsdf": {"type": "null"},
                                "interior": {"type": "ref", "id": MEDIUM_ID}},
        "sun": {"type": "directional", "direction": [float(-x) for x in towards_sun],
                "irradiance": _spectrum(solar_irradiance(grid), grid)},
        "sensor": sensor,
    }


def directions_sensor(directions, origin=(0.0, 0.0, 0.0), spp: int = 64, rows: int = 1) -> dict:
    """A ``skyref_directions`` sensor dict: pixel (i, j) of an M x ``rows`` film (box filter)
    sees the unit direction ``directions[i]`` from ``origin``. The rows are independent
    estimates of the same radiances (batches for standard errors, from one render)."""
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    return {"type": "skyref_directions", "directions": " ".join(f"{x:.9g}" for x in d.ravel()),
            "to_world": mi.ScalarTransform4f().translate([float(x) for x in origin]),
            "film": {"type": "hdrfilm", "width": int(d.shape[0]), "height": int(rows),
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": int(spp)}}


class DirectionsSensorMethods:
    """Plugin ``skyref_directions``: film pixel (i, j) looks along direction i (property
    ``directions``: 3M numbers, world frame; the film is M pixels wide, any number of rows high)
    from the ``to_world`` translation. Wavelengths are
    sampled as Mitsuba's sensors do (weight 1 in RGB variants). The plugin class is these methods
    on the current variant's ``mi.Sensor`` (:func:`directions_sensor_class`)."""

    def __init__(self, props):
        self._mitsuba_base.__init__(self, props)
        values = np.array([float(x) for x in props.get("directions", "0 0 1").replace(",", " ").split()])
        if values.size == 0 or values.size % 3:
            raise ParameterError("directions", props.get("directions", ""), "3 numbers per direction")
        d = values.reshape(-1, 3)
        d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
        self.count = d.shape[0]
        self.directions = mi.Vector3f(*(mi.Float(d[:, i]) for i in range(3)))

    def sample_ray(self, time, sample1, sample2, sample3, active=True):
        wavelengths, weight = self.sample_wavelengths(dr.zeros(mi.SurfaceInteraction3f), sample1, active)
        film = self.film()
        u = (film.crop_offset()[0] + sample2.x * film.crop_size()[0]) * (1.0 / film.size()[0])
        index = dr.minimum(mi.UInt32(u * self.count), self.count - 1)
        d = dr.gather(mi.Vector3f, self.directions, index)
        origin = mi.Point3f(self.world_transform().translation())
        return mi.Ray3f(origin, d, time, wavelengths), weight

    def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
        ray, weight = self.sample_ray(time, sample1, sample2, sample3, active)
        return mi.RayDifferential3f(ray), weight

    def bbox(self):
        o = self.world_transform().translation()
        return mi.ScalarBoundingBox3f(mi.ScalarPoint3f(o.x[0], o.y[0], o.z[0]))

    def to_string(self):
        return f"DirectionsSensor[{self.count} directions]"


def directions_sensor_class():
    """The ``skyref_directions`` class of the current Mitsuba variant."""
    return variant_class(DirectionsSensorMethods, "DirectionsSensor", "Sensor")
