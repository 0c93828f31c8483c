"""Mitsuba sensors for whole skies: ``equirectangular`` and ``fisheye`` (Python plugins).

Mitsuba 3.9.1 has no full-sky sensor; these follow :mod:`skyref.projection` exactly, with the
projection evaluated on Dr.Jit arrays. Both take the usual ``to_world`` (camera -> world; its
translation is the ray origin, its rotation turns the camera's local frame - +z view direction,
+y image up, +x image left - into the world, e.g. ``projection.camera_to_world(camera)``) and
``film``; ``fisheye`` also takes ``fov`` (degrees across the image circle, default 180).

In spectral variants wavelengths are sampled as Mitsuba's own sensors do (``sample_wavelengths``:
the sensor's spectral response function if it has one, otherwise ``sample_rgb_spectrum``) and the
returned weight is the wavelength-sampling weight; in RGB variants it is 1. The fisheye returns
weight 0 for samples outside its image circle.

Call :func:`register_sensors` after ``mi.set_variant``; then ``{"type": "equirectangular"}``
or ``{"type": "fisheye", "fov": 180}`` work in ``mi.load_dict`` and XML scenes.
"""

from __future__ import annotations

from skyref import _llvm

_llvm.configure_libllvm()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from skyref import projection  # noqa: E402
from skyref.plugins.drjit_namespace import xp as DRJIT_NAMESPACE  # noqa: E402

__all__ = ["register_sensors"]

#: Variants whose sensors are registered (a plugin is registered per variant).
_REGISTERED = set()


def _make_sensor_classes():
    """Define the sensor classes against the current variant's ``mi.Sensor``."""

    class _SkySensor(mi.Sensor):
        """Shared ray generation: subclasses map film coordinates to local directions."""

        def _film_uv(self, sample2):
            # Mitsuba's position sample spans the film's crop window; map it to the full film.
            film = self.film()
            size, crop_size, crop_offset = film.size(), film.crop_size(), film.crop_offset()
            u = (crop_offset[0] + sample2.x * crop_size[0]) * (1.0 / size[0])
            v = (crop_offset[1] + sample2.y * crop_size[1]) * (1.0 / size[1])
            return u, v

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            wavelengths, weight = self.sample_wavelengths(dr.zeros(mi.SurfaceInteraction3f), sample1, active)
            local, valid = self._local_direction(*self._film_uv(sample2))
            to_world = self.world_transform()
            ray = mi.Ray3f(mi.Point3f(to_world.translation()), dr.normalize(to_world @ local),
                           time, wavelengths)
            if valid is not None:
                weight = dr.select(valid, weight, 0.0)
            return ray, weight

        def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
            ray, weight = self.sample_ray(time, sample1, sample2, sample3, active)
            return mi.RayDifferential3f(ray), weight

        def bbox(self):
            origin = self.world_transform().translation()
            return mi.ScalarBoundingBox3f(mi.ScalarPoint3f(origin.x[0], origin.y[0], origin.z[0]))

    class EquirectangularSensor(_SkySensor):
        """Whole sphere: film u -> azimuth 2 pi u (clockwise from north), v -> zenith pi v."""

        def _local_direction(self, u, v):
            return mi.Vector3f(*projection.equirectangular_direction(u, v, DRJIT_NAMESPACE)), None

        def to_string(self):
            return f"EquirectangularSensor[film={self.film()}]"

    class FisheyeSensor(_SkySensor):
        """Equidistant fisheye of ``fov`` degrees looking along local +z (image up +y, left +x)."""

        def __init__(self, props):
            super().__init__(props)
            self.fov_deg = float(props.get("fov", 180.0))
            if not 0.0 < self.fov_deg <= 360.0:
                raise ValueError(f"fisheye: fov = {self.fov_deg!r}: out of range (valid: (0, 360] degrees)")

        def _local_direction(self, u, v):
            x, y, z, valid = projection.fisheye_direction(u, v, self.fov_deg, DRJIT_NAMESPACE)
            return mi.Vector3f(x, y, z), valid

        def to_string(self):
            return f"FisheyeSensor[fov={self.fov_deg}, film={self.film()}]"

    return EquirectangularSensor, FisheyeSensor


def register_sensors() -> None:
    """Register ``equirectangular`` and ``fisheye`` for the current Mitsuba variant (idempotent)."""
    variant = mi.variant()
    if variant is None:
        raise RuntimeError("register_sensors(): call mi.set_variant(...) first")
    if variant in _REGISTERED:
        return
    equirectangular, fisheye = _make_sensor_classes()
    mi.register_sensor("equirectangular", lambda props: equirectangular(props))
    mi.register_sensor("fisheye", lambda props: fisheye(props))
    _REGISTERED.add(variant)
