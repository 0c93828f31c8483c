"""The ``atmosphere`` integrator as a plain Mitsuba plugin: ``mi.load_dict`` + ``mi.render``
give the same sky as skyref's own render loop, and its parameters live in ``mi.traverse``."""

import numpy as np

import skyref.atmosphere as A
from skyref.scene import Camera, Scene, Sun

PLUGIN = {"type": "atmosphere", "atmosphere": "bruneton2017", "wavelengths": "rgb",
          "sun_zenith": 70.0, "sun_azimuth": 180.0}


def test_mi_render_matches_render_orders(mi):
    """Mean of the top row of an 8x4 equirectangular sky, 16 seeds each way: the two estimates
    agree within 4 standard errors (relative standard error 0.25-0.35%: a 1.5% difference fails)."""
    from skyref.render import build_integrator, sensor_dict

    scene = Scene(atmosphere=A.bruneton2017(), sun=Sun(70.0, 180.0), camera=Camera(width=8, height=4))
    sensor = {**sensor_dict(scene.camera), "sampler": {"type": "independent", "sample_count": 4096}}
    plugin_scene = mi.load_dict({"type": "scene", "integrator": PLUGIN, "sensor": sensor})
    # The top row (zenith 0-45 deg): the sun (zenith 70) and the ground stay out of it.
    plugin = np.array([mi.render(plugin_scene, seed=s).numpy()[0, :, :3].mean(axis=0) for s in range(16)])
    integrator = build_integrator(scene)
    own_sensor = mi.load_dict(sensor_dict(scene.camera))
    own = np.array([integrator.render_orders(own_sensor, 1000 + s, 4096).numpy()[0].sum(axis=1).mean(axis=0)
                    for s in range(16)])
    se = np.sqrt(plugin.var(0, ddof=1) / 16 + own.var(0, ddof=1) / 16)
    assert np.all(se / own.mean(0) < 0.005)
    assert np.all(np.abs(plugin.mean(0) - own.mean(0)) < 4 * se)


def test_parameters_in_traverse(mi):
    integrator = mi.load_dict(PLUGIN)
    params = mi.traverse(integrator)
    expected = {"ground_albedo", "rayleigh.density_scale", "aerosol.density_scale",
                "aerosol.single_scattering_albedo", "aerosol.angstrom_alpha", "aerosol.angstrom_beta",
                "aerosol.g", "ozone.column_du"}
    assert expected <= set(params.keys())
    params["aerosol.g"] = mi.Float(0.5)
    params.update()
    assert abs(integrator.optics.parameters()["aerosol.g"][0] - 0.5) < 1e-7
