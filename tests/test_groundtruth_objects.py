"""Objects in the atmosphere (Mitsuba shapes, Lambertian): a second estimator for the ground,
and occlusion of the sun."""

import numpy as np

import skyref.atmosphere as A
from skyref.plugins import load_mitsuba
from skyref.scene import Observer, Scene, SceneObject, Sun, direction_from_angles
from tests.variants import RGB

mi = load_mitsuba(RGB)
from skyref.render import build_integrator  # noqa: E402  (needs Mitsuba loaded)

SEEDS = 8
#: Objects are traced by delta tracking (the line integral assumes open sky); the skies without
#: them are too, so that each comparison is about the objects alone.
ESTIMATOR = "delta_tracking"


def _sky(integrator, directions, seeds, spp):
    runs = np.array([integrator.render_directions(directions, seed, spp).numpy() for seed in seeds])
    return runs.mean(0), runs.std(0, ddof=1) / np.sqrt(len(seeds))


def _with_objects(scene, geometry, objects):
    integrator = build_integrator(scene, geometry=geometry, estimator=ESTIMATOR)
    integrator.objects = mi.load_dict({"type": "scene", **{f"o{i}": o.mitsuba_dict() for i, o in enumerate(objects)}})
    return integrator


def test_rectangle_ground_equals_analytic_ground():
    """A 1000 km Lambertian rectangle laid 10 cm above the plane-parallel ground, with the
    ground's albedo, must give the same sky and ground radiance as the analytic ground.
    Independent seeds; relative standard error ~0.05% looking down, ~0.6% looking up, so a 1%
    bias of the surface term is > 4 sigma."""
    atmosphere = A.bruneton2017().replace(ground_albedo=0.3)
    scene = Scene(atmosphere=atmosphere, sun=Sun(40.0, 180.0), observer=Observer(1000.0),
                  wavelengths=[680.0, 550.0, 440.0])
    directions = direction_from_angles(np.array([150.0, 120.0, 30.0]), np.array([0.0, 90.0, 0.0]))
    rectangle = SceneObject(type="rectangle", albedo=0.3, translate_m=(0.0, 0.0, -999.9), scale_m=(5e5, 5e5, 1.0))

    analytic_ground = build_integrator(scene, geometry="plane_parallel", estimator=ESTIMATOR)
    ground_mean, ground_se = _sky(analytic_ground, directions, range(SEEDS), 20000)
    object_mean, object_se = _sky(_with_objects(scene, "plane_parallel", [rectangle]), directions,
                                  range(100, 100 + SEEDS), 20000)
    ground_total, object_total = ground_mean[:, 1:].sum(1), object_mean[:, 1:].sum(1)
    se = np.sqrt((ground_se[:, 1:] ** 2).sum(1) + (object_se[:, 1:] ** 2).sum(1))
    assert np.all(se[:2] / ground_total[:2] < 0.0025)
    z = (object_total - ground_total) / se
    assert np.all(np.abs(z) < 4.0), z


def test_object_blocks_the_sun():
    """A 100 m sphere 1 km from the observer towards the sun hides the solar disk, and the side
    the observer sees (turned away from the sun) is lit by skylight only."""
    sun = Sun(60.0, 180.0)
    scene = Scene(atmosphere=A.bruneton2017(), sun=sun, observer=Observer(10.0), wavelengths=[550.0])
    towards_sun = sun.direction
    sphere = SceneObject(type="sphere", albedo=0.5, translate_m=tuple(1000.0 * towards_sun), scale_m=100.0)
    integrator = _with_objects(scene, "spherical", [sphere])
    free = build_integrator(scene, estimator=ESTIMATOR)
    mean_blocked, _ = _sky(integrator, towards_sun[None], range(2), 2000)
    mean_free, _ = _sky(free, towards_sun[None], range(2), 2000)
    assert mean_free[0, 0, 0] > 1e3          # the bare disk: E / Omega * T ~ 2e4
    assert mean_blocked[0, 0, 0] == 0.0       # hidden behind the sphere
    assert np.all(np.isfinite(mean_blocked)) and mean_blocked.min() >= 0.0
    # The observer sees the sphere's shadowed side (the sun is behind it): only skylight lights it,
    # far less than what a sunlit Lambertian surface would send.
    lit = 0.5 / np.pi * 1.87 * np.cos(np.radians(60.0))
    assert 0.0 < mean_blocked[0, 1:].sum() < 0.2 * lit
