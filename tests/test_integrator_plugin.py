"""The ``atmosphere`` integrator as a plain Mitsuba plugin: ``mi.load_dict`` + ``mi.render``
give the same sky as skyref's own render loop, and its parameters live in ``mi.traverse``."""

import numpy as np
import pytest

import skyref.atmosphere as A
from skyref.atmosphere.sun import SUN_ANGULAR_RADIUS_DEG
from skyref.scene import ESTIMATORS, Camera, Scene, Sun

PLUGIN = {"type": "atmosphere", "atmosphere": "bruneton2017", "wavelengths": "rgb",
          "sun_zenith": 70.0, "sun_azimuth": 180.0}


#: Samples per pixel and seed in test_mi_render_matches_render_orders. The line integral's noise
#: per sample is low: at 4096 the relative standard deviation of a seed's row mean was 0.11-0.12%
#: through ``mi.render`` and 0.04-0.05% through ``render_orders`` (2026-12-06, 2.6 CPU s per seed
#: each), so 512 keep the standard error near 0.07%, well below the 0.25% asserted.
MI_RENDER_SPP = {"delta_tracking": 4096, "line_integral": 512}


@pytest.mark.parametrize("estimator", ESTIMATORS)
def test_mi_render_matches_render_orders(mi, estimator):
    """Mean of the top row of an 8x4 equirectangular sky, 32 seeds each way: the two estimates
    agree within 4 standard errors, asserted below 0.25% of the radiance (a 1% difference fails).
    Through ``mi.render`` the line integral draws from Mitsuba's sampler (it had asked it for
    ``next_3d``, which Mitsuba's samplers lack)."""
    from skyref.render import build_integrator, sensor_dict

    seeds, spp = 32, MI_RENDER_SPP[estimator]
    scene = Scene(atmosphere=A.bruneton2017(), sun=Sun(70.0, 180.0), camera=Camera(width=8, height=4))
    sensor = {**sensor_dict(scene.camera), "sampler": {"type": "independent", "sample_count": spp}}
    plugin_scene = mi.load_dict({"type": "scene", "integrator": {**PLUGIN, "estimator": estimator}, "sensor": sensor})
    # The top row (zenith 0-45 deg): the sun (zenith 70) and the ground stay out of it.
    plugin = np.array([mi.render(plugin_scene, seed=s).numpy()[0, :, :3].mean(axis=0) for s in range(seeds)])
    integrator = build_integrator(scene, estimator=estimator)
    own_sensor = mi.load_dict(sensor_dict(scene.camera))
    own = np.array([integrator.render_orders(own_sensor, 1000 + s, spp).numpy()[0].sum(axis=1).mean(axis=0)
                    for s in range(seeds)])
    se = np.sqrt(plugin.var(0, ddof=1) / seeds + own.var(0, ddof=1) / seeds)
    print(f"{estimator}: relative standard error {se / own.mean(0)}, z {(plugin.mean(0) - own.mean(0)) / se}")
    assert np.all(se / own.mean(0) < 0.0025), se / own.mean(0)
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


@pytest.mark.parametrize("estimator", ESTIMATORS)
def test_new_sample_counts_reuse_the_compiled_path_kernels(mi, estimator):
    """Renders with other numbers of samples, directions, seeds, a new turbidity and a new
    observer altitude launch the same kernels, by hash: nothing per launch is baked into the
    path tracer, and configuring the integrator (the line integral's guide) launches the same
    kernels again. (``dr.mean`` over a path's channels baked the lane count in, so each round of
    an adaptive render compiled the path tracer again: 3-24 s for the line integral; the sun
    lobe's probability baked the turbidity in; the guide's cell directions, loaded from NumPy
    arrays, specialised its kernel on their memory's alignment, which differs from run to run: a
    17 s compile in most new processes; the observer's altitude, a literal in the guide's kernel,
    compiled it again for each observer; with one sample per target in the line integral's
    single-scattering launch, a scatter left pending fused into it: 2 and 9 samples per
    direction compiled it twice; one direction alone, its one-entry table read as a scalar,
    compiled both path kernels again.) Both turbidities are above the ground guide's switch
    (``HAZY_FORWARD_SHARE``, about turbidity 2.5), which compiles a second variant of the
    line integral's path kernel on purpose."""
    import drjit as dr

    from skyref.plugins.integrator import AtmosphereIntegrator

    rng = np.random.default_rng(3)
    hashes = []
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        for turbidity, count, spp, seed, observer_m in [(3.0, 64, 2, 1, 1.0), (3.0, 96, 3, 2, 1.0),
                                                        (4.0, 40, 5, 3, 500.0), (4.0, 40, 9, 4, 1.0),
                                                        (4.0, 1, 9, 5, 1.0)]:
            directions = rng.normal(size=(count, 3))
            directions[:, 2] = np.abs(directions[:, 2])
            directions /= np.linalg.norm(directions, axis=1, keepdims=True)
            dr.kernel_history()                             # clears the history
            integrator = AtmosphereIntegrator()
            integrator.configure(A.from_turbidity(turbidity), A.wavelength_grid("rgb"), 60.0, 180.0,
                                 SUN_ANGULAR_RADIUS_DEG, observer_altitude_m=observer_m, estimator=estimator)
            integrator.render_directions(directions, seed=seed, spp=spp, batches=2).numpy()
            # the guide's and the path tracer's kernels: the large ones (the others fill tables,
            # sum and scatter the results)
            hashes.append(sorted(k["hash"] for k in dr.kernel_history()
                                 if k["type"] == dr.KernelType.JIT and k["operation_count"] > 500))
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert hashes[0], "no path kernel was launched"
    assert all(h == hashes[0] for h in hashes[1:]), hashes
