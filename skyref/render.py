"""``render_sky``: render a :class:`~skyref.scene.Scene` with the ``atmosphere`` integrator.

The samples per pixel are split into ``passes`` independent batches; the sky is their mean and
its standard error the spread of the batch means / sqrt(passes) (16 batches by default: with 4,
the standard error has 3 degrees of freedom and 7-10% of estimates fall beyond 3 sigma). All
batches are traced together, in launches whose size the integrator bounds
(:meth:`~skyref.plugins.integrator.AtmosphereIntegrator.launch_sizes`).
"""

from __future__ import annotations

import math
import time

import numpy as np

from tqdm import tqdm

from skyref import __version__
from skyref.errors import ParameterError
from skyref.plugins import load_mitsuba
from skyref.projection import camera_to_world, pixel_directions
from skyref.scene import RenderSettings
from skyref.sky import ORDER_NAMES, Sky
from skyref.validation import check_choice

__all__ = ["MAX_IMAGE_VALUES", "GEOMETRIES", "sensor_dict", "build_integrator", "check_image_size", "render_sky",
           "relative_error_percentile", "combine_skies", "render_to_error"]

#: Most values (passes x pixels x scattering orders x wavelengths) one render accumulates: each
#: takes ~12 bytes across the device buffer and its host copies, so this is ~13 GB.
MAX_IMAGE_VALUES = 1 << 30

GEOMETRIES = ("spherical", "plane_parallel")


def sensor_dict(camera) -> dict:
    """The Mitsuba sensor for a :class:`~skyref.scene.Camera` (observer at the origin of the
    east-north-up frame): skyref's ``equirectangular`` / ``fisheye`` or stock ``perspective``."""
    import mitsuba as mi  # lazy: Mitsuba is loaded by skyref.plugins.load_mitsuba (libLLVM first)

    sensor = {"type": camera.type,
              "to_world": mi.ScalarTransform4f(camera_to_world(camera).tolist()),
              "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height,
                       "rfilter": {"type": "box"}, "pixel_format": "rgb"}}
    if camera.type == "fisheye":
        sensor["fov"] = camera.fov_deg
    elif camera.type == "perspective":
        sensor.update(fov=camera.fov_deg, fov_axis="x")
    return sensor


def build_integrator(scene, geometry: str = "spherical", wavelengths_per_path: int = 0,
                     estimator: str | None = None):
    """An ``atmosphere`` integrator configured for ``scene`` (Mitsuba must be loaded), with the
    ``estimator`` ``delta_tracking`` or ``line_integral`` (experimental; default: the
    integrator's ``DEFAULT_ESTIMATOR``)."""
    import mitsuba as mi  # lazy: Mitsuba and its plugins are loaded by skyref.plugins.load_mitsuba

    from skyref.plugins.integrator import AtmosphereIntegrator

    integrator = AtmosphereIntegrator(mi.Properties())
    integrator.configure(scene.atmosphere, scene.wavelengths_nm, scene.sun.zenith_deg, scene.sun.azimuth_deg,
                         scene.sun.angular_radius_deg, scene.sun.limb_darkening, scene.observer.altitude_m,
                         geometry=geometry, max_depth=scene.render.max_depth,
                         wavelengths_per_path=wavelengths_per_path,
                         **({} if estimator is None else {"estimator": estimator}))
    return integrator


def check_image_size(scene, passes: int) -> None:
    """Refuse, before any work, a render whose per-pass images would exceed MAX_IMAGE_VALUES,
    saying how large a camera fits and the ways around (tiles, fewer passes or wavelengths)."""
    camera, wavelengths = scene.camera, len(scene.wavelengths_nm)
    per_pixel = passes * len(ORDER_NAMES) * wavelengths
    if camera.width * camera.height * per_pixel > MAX_IMAGE_VALUES:
        raise ParameterError("camera", f"{camera.width}x{camera.height}",
                             f"at most {MAX_IMAGE_VALUES // per_pixel:,} pixels at {wavelengths} wavelengths and "
                             f"{passes} passes", "too large for one render: render it in tiles (cameras "
                             "covering parts of the view), or with fewer passes or wavelengths")


def render_sky(scene, spp: int | None = None, passes: int | None = None, seed: int | None = None,
               variant: str | None = None, geometry: str = "spherical", wavelengths_per_path: int = 0,
               progress: bool = False, estimator: str | None = None) -> Sky:
    """Render ``scene``; ``spp``, ``passes`` and ``seed`` override the scene's render settings.

    Returns a :class:`~skyref.sky.Sky`: radiance (H, W, N) in W m^-2 sr^-1 nm^-1 at the scene's
    wavelengths, its standard error, one layer per scattering order, pixel directions, and
    metadata (samples, time, throughput, variant). ``geometry="plane_parallel"`` flattens the
    planet (for comparisons with plane-parallel solvers such as DISORT); ``estimator`` picks
    the integrator's estimator (see :data:`skyref.plugins.integrator.ESTIMATORS`).
    """
    check_choice("geometry", geometry, GEOMETRIES)
    scene.check_files()
    settings = RenderSettings(spp=scene.render.spp if spp is None else spp,
                              passes=scene.render.passes if passes is None else passes,
                              seed=scene.render.seed if seed is None else seed,
                              max_depth=scene.render.max_depth, pixel_sampling=scene.render.pixel_sampling)
    if settings.spp < settings.passes:
        raise ParameterError("spp", settings.spp, f">= passes ({settings.passes})", "too few samples")
    check_image_size(scene, settings.passes)
    spp_per_pass = settings.spp // settings.passes

    mi = load_mitsuba(variant)
    integrator = build_integrator(scene.replace(render=settings), geometry, wavelengths_per_path, estimator)
    sensor = mi.load_dict(sensor_dict(scene.camera))
    if scene.objects:
        try:
            integrator.objects = mi.load_dict({"type": "scene", **{f"object_{i}": item.mitsuba_dict()
                                                                   for i, item in enumerate(scene.objects)}})
        except RuntimeError as exc:    # an unreadable mesh: Mitsuba's message, first line
            raise ParameterError("objects", [item.filename or item.type for item in scene.objects],
                                 "shapes Mitsuba can load", str(exc).strip().splitlines()[0][:200]) from None
    camera = scene.camera

    bar = None
    if progress:
        bar = tqdm(total=settings.passes * spp_per_pass, unit="spp", desc=f"render {scene.name or 'sky'}")
    start = time.perf_counter()
    per_pass = integrator.render_orders(                 # (P, H, W, orders, N)
        sensor, seed=settings.seed % (1 << 32), spp=spp_per_pass, pixel_centres=settings.pixel_sampling == "centre",
        batches=settings.passes,
        progress=None if bar is None else (lambda count: bar.update(count * settings.passes))).numpy()
    elapsed = time.perf_counter() - start
    if bar is not None:
        bar.close()

    orders_mean = per_pass.mean(axis=0)
    radiance_passes = per_pass.sum(axis=3)            # (P, H, W, N)
    radiance = radiance_passes.mean(axis=0)
    standard_error = radiance_passes.std(axis=0, ddof=1) / math.sqrt(settings.passes)
    samples = camera.width * camera.height * spp_per_pass * settings.passes
    metadata = {"skyref_version": __version__, "integrator": "atmosphere", "variant": mi.variant(),
                "geometry": geometry, "estimator": integrator.estimator,
                "spp": spp_per_pass * settings.passes, "passes": settings.passes,
                "seed": settings.seed, "wavelengths_per_path": integrator.channels,
                "render_time_s": elapsed, "samples_per_second": samples / elapsed}
    return Sky(radiance=radiance.astype(np.float32), standard_error=standard_error.astype(np.float32),
               wavelengths_nm=np.asarray(scene.wavelengths_nm, dtype=np.float64),
               directions=pixel_directions(camera),
               orders={name: orders_mean[..., i, :].astype(np.float32) for i, name in enumerate(ORDER_NAMES)},
               scene=scene, metadata=metadata)


def relative_error_percentile(sky: Sky, percentile: float = 95.0) -> float:
    """The ``percentile`` of standard error / radiance over all pixels and wavelengths with
    radiance > 0: how noisy the sky still is (0 for an all-black sky)."""
    relative = sky.relative_error()
    finite = relative[np.isfinite(relative)]
    return float(np.percentile(finite, percentile)) if finite.size else 0.0


def combine_skies(skies: list) -> Sky:
    """Pool independent renders of one scene: the mean weighted by samples per pixel, with
    standard error sqrt(sum_i (n_i / n)^2 SE_i^2)."""
    counts = np.array([s.metadata["spp"] for s in skies], dtype=np.float64)
    weights = counts / counts.sum()
    first = skies[0]
    radiance = sum(w * s.radiance.astype(np.float64) for w, s in zip(weights, skies))
    variance = sum((w * s.standard_error.astype(np.float64)) ** 2 for w, s in zip(weights, skies))
    orders = {name: sum(w * s.orders[name].astype(np.float64) for w, s in zip(weights, skies)).astype(np.float32)
              for name in first.orders}
    render_time = sum(s.metadata["render_time_s"] for s in skies)
    samples = sum(s.metadata["samples_per_second"] * s.metadata["render_time_s"] for s in skies)
    metadata = dict(first.metadata, spp=int(counts.sum()), passes=sum(s.metadata["passes"] for s in skies),
                    seed=[s.metadata["seed"] for s in skies], render_time_s=render_time,
                    samples_per_second=samples / render_time)
    return Sky(radiance=radiance.astype(np.float32), standard_error=np.sqrt(variance).astype(np.float32),
               wavelengths_nm=first.wavelengths_nm, directions=first.directions, orders=orders,
               scene=first.scene, metadata=metadata)


def render_to_error(scene, target_relative_error: float, seeds, max_spp: int, initial_spp: int | None = None,
                    variant: str | None = None) -> Sky:
    """Render ``scene`` in rounds until :func:`relative_error_percentile` (95th) is at most
    ``target_relative_error`` or ``max_spp`` samples per pixel are spent. Round r uses seed
    ``seeds[r]`` (so rounds are independent); each round after the first is sized by the
    1/sqrt(spp) law with 10% margin. The sky's metadata records the error reached."""
    passes = scene.render.passes
    spp = initial_spp or max(16 * passes, 64)
    skies = [render_sky(scene, spp=min(spp, max_spp), seed=seeds[0], variant=variant)]
    sky = skies[0]
    error = relative_error_percentile(sky)
    for seed in seeds[1:]:
        spent = sky.metadata["spp"]
        if error <= target_relative_error or spent >= max_spp:
            break
        needed = math.ceil(1.1 * spent * (error / target_relative_error) ** 2)
        extra = min(max(needed - spent, passes), max_spp - spent)
        extra = max(passes, extra - extra % passes)
        skies.append(render_sky(scene, spp=extra, seed=seed, variant=variant))
        sky = combine_skies(skies)
        error = relative_error_percentile(sky)
    sky.metadata.update(target_relative_error=target_relative_error, relative_error_p95=error)
    return sky
