"""``render_sky``: render a :class:`~skyref.scene.Scene` with the ``atmosphere`` integrator.

The samples per pixel are split into ``passes`` independent batches; the sky is their mean and
its standard error the spread of the batch means / sqrt(passes) (16 batches by default: with 4,
the standard error has 3 degrees of freedom and 7-10% of estimates fall beyond 3 sigma). All
batches are traced together, in launches whose size the integrator bounds
(:meth:`~skyref.plugins.integrator.AtmosphereIntegrator.launch_sizes`).

A polarized render (the scene's ``render.polarized``, or ``render_sky(..., polarized=True)``)
carries a Stokes axis (I, Q, U, V) through every step, passes, adaptive rounds and regions
alike: per pass (passes, M, orders, 4, N), pooled per component, and the sky's ``stokes``
(:class:`~skyref.sky.Sky`); a scalar render is the same with that axis of length 1, dropped in
the sky. Adaptive rounds aim at I's error.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import os
import time

import numpy as np

from tqdm import tqdm

from skyref import __version__
from skyref.errors import ParameterError
from skyref.io.atomic import atomic_path
from skyref.io.json_numpy import numpy_default
from skyref.plugins import load_mitsuba
from skyref.projection import camera_to_world, pixel_directions
from skyref.scene import RenderSettings
from skyref.sky import ORDER_NAMES, STOKES, Sky
from skyref.symmetry import copy_estimates, view_groups
from skyref.validation import check_choice, check_int, check_number, check_output_file

__all__ = ["MAX_IMAGE_VALUES", "GEOMETRIES", "sensor_dict", "build_integrator", "stokes_components",
           "check_image_size", "render_sky",
           "rendered_pixels", "relative_error_percentile", "pixel_relative_error", "stopping_error", "PixelPool",
           "AdaptiveProgress", "render_to_error", "round_launches", "forecast_render_to_error", "ROUND_MARGIN",
           "LAUNCH_SAMPLES", "launch_parts", "launch_seed", "PILOT_SPP", "traced_views", "render_views", "render_paired"]

#: Most values (passes x pixels x scattering orders x Stokes components (polarized: 4) x
#: wavelengths) one render accumulates: each takes ~12 bytes across the device buffer and its host
#: copies, so this is ~13 GB.
MAX_IMAGE_VALUES = 1 << 30

#: :func:`render_to_error` gives a pixel this margin over the samples the 1/sqrt(spp) law says it
#: needs, so that most pixels rounded down reach the target in the next round all the same.
ROUND_MARGIN = 1.1

#: Most samples (views x samples per view) in one launch of :func:`render_to_error`: a round's
#: launch of more is split into launches over parts of its views, so that a checkpoint is written
#: (and a batch's progress told) every few minutes of a hard sky, not every ~15 (the LUT audit's
#: hazy sky at sun 92 seen from 1 km, 17 wavelengths: one launch of its second round took 887 s
#: on 2 cores). 2^25 samples are ~5 CPU minutes at 17 wavelengths (~10 us a sample); tracing a
#: launch costs ~1-2 s.
LAUNCH_SAMPLES = 1 << 25

#: Samples per view of :func:`forecast_render_to_error`'s pilot unless told (``skyref batch
#: --forecast --pilot-spp``): about 10-20 CPU s for a LUT-audit sky's 1024 views at 17
#: wavelengths, and a quarter of that again to time its groups of views (``COST_GROUPS``).
PILOT_SPP = 2048

#: Groups of views (equal in number, by the samples each is forecast to take) whose CPU per
#: sample :func:`forecast_render_to_error` times apart. A sample's cost differs between views: on
#: the LUT audit's hazy twilight skies the quarter of the views that takes most of the samples
#: (78-87%) costs 1.5-1.9x the mean sample of the pilot (sky 69: 8.9 against 5.8 us, sky 76: 9.7
#: against 5.0; the cheapest half 1.4-3.2 us), where a clear sky's views cost the same (sky 10:
#: 4.4-4.9 us).
COST_GROUPS = 4

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
                     estimator: str | None = None, polarized: bool = False):
    """An ``atmosphere`` integrator configured for ``scene`` (Mitsuba must be loaded), with the
    ``estimator`` ``delta_tracking`` or ``line_integral`` (default: the scene's
    ``render.estimator``), transporting Stokes vectors if ``polarized``."""
    import mitsuba as mi  # lazy: Mitsuba and its plugins are loaded by skyref.plugins.load_mitsuba

    from skyref.plugins.integrator import AtmosphereIntegrator

    # constructed with the cheaper estimator's defaults (the line integral's would build a sun
    # table and a guide for a default sky), then configured for the scene
    properties = mi.Properties()
    properties["estimator"] = "delta_tracking"
    integrator = AtmosphereIntegrator(properties)
    integrator.configure(scene.atmosphere, scene.wavelengths_nm, scene.sun.zenith_deg, scene.sun.azimuth_deg,
                         scene.sun.angular_radius_deg, scene.sun.limb_darkening, scene.observer.altitude_m,
                         geometry=geometry, max_depth=scene.render.max_depth,
                         wavelengths_per_path=wavelengths_per_path, polarized=polarized,
                         estimator=scene.render.estimator if estimator is None else estimator)
    return integrator


def stokes_components(scene) -> int:
    """Values per wavelength in the scene's render: the Stokes components if it is polarized,
    else 1 (radiance)."""
    return len(STOKES) if scene.render.polarized else 1


def check_image_size(scene, passes: int) -> None:
    """Refuse, before any work, a render whose per-pass images would exceed MAX_IMAGE_VALUES,
    saying how large a camera fits and the ways around (tiles, fewer passes or wavelengths)."""
    camera, wavelengths = scene.camera, len(scene.wavelengths_nm)
    per_pixel = passes * len(ORDER_NAMES) * stokes_components(scene) * wavelengths
    if camera.width * camera.height * per_pixel > MAX_IMAGE_VALUES:
        polarized = f" (polarized: {len(STOKES)} Stokes components each)" if scene.render.polarized else ""
        raise ParameterError("camera", f"{camera.width}x{camera.height}",
                             f"at most {MAX_IMAGE_VALUES // per_pixel:,} pixels at {wavelengths} wavelengths"
                             f"{polarized} and {passes} passes", "too large for one render: render it in tiles "
                             "(cameras covering parts of the view), or with fewer passes or wavelengths")


def _settings(scene, spp, passes, seed, polarized=None, estimator=None) -> RenderSettings:
    """The scene's render settings with ``spp``, ``passes``, ``seed``, ``polarized`` and
    ``estimator`` overridden (None: the scene's); checked like the scene's own."""
    render = scene.render
    return dataclasses.replace(render, spp=render.spp if spp is None else spp,
                               passes=render.passes if passes is None else passes,
                               seed=render.seed if seed is None else seed,
                               polarized=render.polarized if polarized is None else polarized,
                               estimator=render.estimator if estimator is None else estimator)


def rendered_pixels(scene) -> np.ndarray:
    """Flat indices (row * width + column) of the pixels the scene's ``render.region`` asks
    for: every pixel, or (``"above_horizon"``) those whose centre direction is at or above the
    observer's horizon (view zenith <= 90 deg). A camera too large for one render
    (:func:`check_image_size`) is refused first."""
    check_image_size(scene, scene.render.passes)
    camera = scene.camera
    if scene.render.region == "all":
        return np.arange(camera.width * camera.height)
    return np.flatnonzero(pixel_directions(camera)[..., 2].reshape(-1) >= 0.0)


def traced_views(scene, pixels: np.ndarray, symmetry: bool = True) -> tuple:
    """Which of the rendered ``pixels`` to trace: (their positions in ``pixels``; for each pixel
    the position of its estimate among them; for each pixel whether it sees that view's mirror
    image, for :func:`skyref.symmetry.copy_estimates`). With ``symmetry``, one view of each group
    that sees the same sky (:func:`skyref.symmetry.view_groups`); else every pixel."""
    if not isinstance(symmetry, (bool, np.bool_)):
        raise ParameterError("symmetry", symmetry, "true or false", "not a boolean")
    if not symmetry:
        everything = np.arange(len(pixels))
        return everything, everything, np.zeros(len(pixels), dtype=bool)
    groups, mirrored = view_groups(scene, pixels)
    traced = np.unique(groups)
    return traced, np.searchsorted(traced, groups), mirrored


class _PixelRenderer:
    """The integrator and sensor of one scene, to trace any set of its pixels in passes; polarized
    if the scene's ``render.polarized`` says so."""

    def __init__(self, scene, variant, geometry, wavelengths_per_path):
        check_choice("geometry", geometry, GEOMETRIES)
        scene.check_files()
        self.mi = load_mitsuba(variant)
        self.scene, self.geometry = scene, geometry
        self.integrator = build_integrator(scene, geometry, wavelengths_per_path, polarized=scene.render.polarized)
        self.sensor = self.mi.load_dict(sensor_dict(scene.camera))
        if scene.objects:
            try:
                self.integrator.objects = self.mi.load_dict(
                    {"type": "scene", **{f"object_{i}": item.mitsuba_dict() for i, item in enumerate(scene.objects)}})
            except RuntimeError as exc:    # an unreadable mesh: Mitsuba's message, first line
                raise ParameterError("objects", [item.filename or item.type for item in scene.objects],
                                     "shapes Mitsuba can load", str(exc).strip().splitlines()[0][:200]) from None

    def passes(self, pixels, spp_per_pass: int, passes: int, seed: int, progress=None) -> np.ndarray:
        """(passes, M, orders, S, N) radiance of the ``pixels`` from independent passes of
        ``spp_per_pass`` samples each: S = 4 Stokes components if polarized, else 1."""
        per_pass = self.integrator.render_orders(
            self.sensor, seed=seed % (1 << 32), spp=spp_per_pass, batches=passes, progress=progress,
            pixel_centres=self.scene.render.pixel_sampling == "centre", pixels=pixels).numpy()
        return per_pass.reshape(passes, len(pixels), len(ORDER_NAMES), stokes_components(self.scene), -1)

    @staticmethod
    def statistics(per_pass: np.ndarray) -> tuple:
        """The mean per order (M, orders, S, N) of :meth:`passes`' output and the standard error
        of the total (M, S, N): the spread of the pass means / sqrt(passes)."""
        return per_pass.mean(axis=0), per_pass.sum(axis=2).std(axis=0, ddof=1) / math.sqrt(per_pass.shape[0])

    def metadata(self, spp: int, passes: int, seed, elapsed: float, samples: int, views_traced: int) -> dict:
        """``spp``: samples per pixel; ``samples``: samples traced in all; ``views_traced``: the
        directions traced (fewer than the pixels where symmetric views share one, :func:`traced_views`)."""
        return {"skyref_version": __version__, "integrator": "atmosphere", "variant": self.mi.variant(),
                "geometry": self.geometry, "estimator": self.integrator.estimator, "spp": spp, "passes": passes,
                "seed": seed, "wavelengths_per_path": self.integrator.channels, "region": self.scene.render.region,
                "views_traced": views_traced, "render_time_s": elapsed, "samples_per_second": samples / elapsed}


def _sky(scene, pixels, radiance, standard_error, orders, metadata) -> Sky:
    """A :class:`Sky` from per-pixel values of the rendered ``pixels``: ``radiance`` and
    ``standard_error`` (M, S, N), ``orders`` (M, orders, S, N), with S Stokes components if
    the scene is polarized (the sky's ``stokes``; I is its radiance), else 1; pixels that were
    not rendered are NaN."""
    camera = scene.camera
    count, n = camera.width * camera.height, len(scene.wavelengths_nm)
    components = stokes_components(scene)

    def image(values, shape):
        full = np.full((count, *shape), np.nan, dtype=np.float32)
        full[pixels] = values
        return full.reshape(camera.height, camera.width, *shape)

    by_order = image(orders, (len(ORDER_NAMES), components, n))
    total, error = image(radiance, (components, n)), image(standard_error, (components, n))
    polarized = scene.render.polarized
    return Sky(radiance=np.ascontiguousarray(total[..., 0, :]), standard_error=np.ascontiguousarray(error[..., 0, :]),
               wavelengths_nm=np.asarray(scene.wavelengths_nm, dtype=np.float64),
               directions=pixel_directions(camera),
               orders={name: np.ascontiguousarray(by_order[..., i, 0, :]) for i, name in enumerate(ORDER_NAMES)},
               scene=scene, metadata=metadata, stokes=total if polarized else None,
               stokes_error=error if polarized else None,
               order_stokes={name: np.ascontiguousarray(by_order[..., i, :, :]) for i, name in enumerate(ORDER_NAMES)}
               if polarized else {})


def render_sky(scene, spp: int | None = None, passes: int | None = None, seed: int | None = None,
               variant: str | None = None, geometry: str = "spherical", wavelengths_per_path: int = 0,
               progress: bool = False, estimator: str | None = None, polarized: bool | None = None,
               symmetry: bool = True) -> Sky:
    """Render ``scene``; ``spp``, ``passes``, ``seed`` and ``polarized`` override the scene's
    render settings.

    Returns a :class:`~skyref.sky.Sky`: radiance (H, W, N) in W m^-2 sr^-1 nm^-1 at the scene's
    wavelengths, its standard error, one layer per scattering order, pixel directions, and
    metadata (samples, time, throughput, variant). Pixels outside the scene's
    ``render.region`` are not traced and are NaN. ``geometry="plane_parallel"`` flattens the
    planet (for comparisons with plane-parallel solvers such as DISORT); ``estimator`` picks
    the integrator's estimator (:data:`skyref.scene.ESTIMATORS`; default: the scene's
    ``render.estimator``). ``polarized`` transports Stokes vectors (either estimator): the sky
    then also has ``stokes`` (H, W, 4, N) and its radiance is I. ``symmetry``: views that see
    the same sky share one estimate (:mod:`skyref.symmetry`; the metadata's ``views_traced``).
    """
    settings = _settings(scene, spp, passes, seed, polarized, estimator)
    if settings.spp < settings.passes:
        raise ParameterError("spp", settings.spp, f">= passes ({settings.passes})", "too few samples")
    scene = scene.replace(render=settings)
    pixels = rendered_pixels(scene)
    traced, estimate_of, mirrored = traced_views(scene, pixels, symmetry)
    renderer = _PixelRenderer(scene, variant, geometry, wavelengths_per_path)
    spp_per_pass = settings.spp // settings.passes

    bar, advance = None, None
    if progress:
        bar = tqdm(total=settings.passes * spp_per_pass, unit="spp", desc=f"render {scene.name or 'sky'}")
        # Dr.Jit compiles a new configuration's path kernels in the first launch (the line
        # integral's for up to minutes, docs/design.md); they are cached on disk after that
        bar.set_postfix_str("compiling the path kernels unless cached")

        def advance(count):
            bar.set_postfix_str("", refresh=False)
            bar.update(count * settings.passes)
    start = time.perf_counter()
    per_pass = renderer.passes(pixels[traced], spp_per_pass, settings.passes, settings.seed, advance)
    elapsed = time.perf_counter() - start
    if bar is not None:
        bar.close()

    orders, standard_error = renderer.statistics(per_pass)
    orders = copy_estimates(orders, estimate_of, mirrored, settings.polarized)
    standard_error = standard_error[estimate_of]
    spp_total = spp_per_pass * settings.passes
    metadata = renderer.metadata(spp_total, settings.passes, settings.seed, elapsed, traced.size * spp_total,
                                 traced.size)
    return _sky(scene, pixels, orders.sum(axis=1), standard_error, orders, metadata)


def render_paired(scene, other, spp: int, seed: int, variant: str | None = None) -> tuple:
    """``scene`` and ``other`` (the same camera, wavelengths, region and passes: e.g. scalar and
    polarized transport of one sky) rendered with the same ``seed`` and ``spp`` samples per pixel,
    every pixel traced; returns (sky, other's sky, standard error of other's radiance minus
    scene's (H, W, N)). Where the two draw their paths alike (scalar and polarized transport do:
    the Mueller arithmetic rides on the scalar paths) most of their noise is common and cancels
    in the difference; its standard error is the spread of the batches' paired differences /
    sqrt(passes), whatever their correlation (the LUT audit's hazy sky at sun zenith 30, 17
    wavelengths: 5x smaller than the two standard errors combined as if independent, a
    correlation of 0.98 between the batches). Each sky's metadata has its ``render_cpu_s``."""
    settings = [_settings(s, spp, None, seed) for s in (scene, other)]
    scenes = [s.replace(render=r) for s, r in zip((scene, other), settings)]
    if (scenes[0].camera != scenes[1].camera or list(scenes[0].wavelengths_nm) != list(scenes[1].wavelengths_nm)
            or settings[0].passes != settings[1].passes or settings[0].region != settings[1].region):
        raise ParameterError("other", other.name or "scene", "the scene's camera, wavelengths, passes and region",
                             "a pair must render the same pixels the same way")
    if spp < settings[0].passes:
        raise ParameterError("spp", spp, f">= passes ({settings[0].passes})", "too few samples")
    pixels = rendered_pixels(scenes[0])
    passes, spp_per_pass = settings[0].passes, spp // settings[0].passes
    skies, intensity = [], []
    for one in scenes:
        renderer = _PixelRenderer(one, variant, "spherical", 0)
        start, start_cpu = time.perf_counter(), time.process_time()
        per_pass = renderer.passes(pixels, spp_per_pass, passes, seed)
        elapsed, cpu = time.perf_counter() - start, time.process_time() - start_cpu
        orders, standard_error = renderer.statistics(per_pass)
        metadata = renderer.metadata(spp_per_pass * passes, passes, seed, elapsed, pixels.size * spp_per_pass * passes,
                                     pixels.size)
        metadata["render_cpu_s"] = cpu
        skies.append(_sky(one, pixels, orders.sum(axis=1), standard_error, orders, metadata))
        intensity.append(per_pass.sum(axis=2)[:, :, 0])                 # (passes, M, N): I per pass
    difference = intensity[1] - intensity[0]
    camera = scene.camera
    error = np.full((camera.width * camera.height, difference.shape[-1]), np.nan, dtype=np.float32)
    error[pixels] = difference.std(axis=0, ddof=1) / math.sqrt(passes)
    return skies[0], skies[1], error.reshape(camera.height, camera.width, -1)


def render_views(scene, pixels, spp: int, seed: int, variant: str | None = None) -> tuple:
    """The radiance (M, N) and its standard error (M, N) of the chosen ``pixels`` (flat indices,
    row * width + column) of ``scene``'s camera, ``spp`` samples each in ``scene.render.passes``
    passes with ``seed``: a few directions checked at a fixed sample count, apart from the
    render of the rest of the image."""
    pixels = np.asarray(pixels, dtype=np.int64)
    check_int("spp", spp, scene.render.passes, 1 << 30)
    renderer = _PixelRenderer(scene, variant, "spherical", 0)
    orders, standard_error = renderer.statistics(renderer.passes(pixels, spp // scene.render.passes,
                                                                 scene.render.passes, seed))
    return orders.sum(axis=1)[:, 0], standard_error[:, 0]


def relative_error_percentile(sky: Sky, percentile: float = 95.0) -> float:
    """The ``percentile`` of standard error / radiance over all pixels and wavelengths with
    radiance > 0: how noisy the sky still is (0 for an all-black sky)."""
    relative = sky.relative_error()
    finite = relative[np.isfinite(relative)]
    return float(np.percentile(finite, percentile)) if finite.size else 0.0


def pixel_relative_error(radiance: np.ndarray, standard_error: np.ndarray) -> np.ndarray:
    """Per pixel, the largest standard error / radiance over the wavelengths (last axis): 0 for
    a pixel that is black with no error, inf where a radiance of 0 has an error."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(radiance > 0, standard_error / radiance, np.where(standard_error > 0, np.inf, 0.0))
    return ratio.max(axis=-1)


def stopping_error(orders: np.ndarray, standard_error: np.ndarray, wavelengths_nm,
                   dynamic_range: float | None = None) -> np.ndarray:
    """Per view, the error :func:`render_to_error` holds to its target, from per-order means
    (M, orders, N) and standard errors (M, N) (Stokes I): :func:`pixel_relative_error`, except
    that with ``dynamic_range`` a view *dark* beside the sky, whose diffuse luminance (solar disk
    excluded) is below ``dynamic_range`` x the brightest view's even at its radiance + 3 standard
    errors (Y + 3 sum_i y_i SE_i, an upper bound whatever the channels' correlation), measures its
    error per wavelength against max(radiance, ``dynamic_range`` x that wavelength's brightest
    diffuse radiance): it is done at an absolute error of target x that floor. A consumer that
    leaves out what is darker than ``dynamic_range`` of the brightest (the LUT audit's
    :data:`~skyref.audit.metrics.DYNAMIC_RANGE`: the night side seen from space, at 1e-10 of the
    day side) then does not pay for it."""
    radiance = orders.sum(axis=1)
    if dynamic_range is None or len(radiance) == 0:
        return pixel_relative_error(radiance, standard_error)
    from skyref.color import xyz_matrix  # lazy: colour-science's import cost

    diffuse = radiance - orders[:, ORDER_NAMES.index("sun_direct")]
    y = xyz_matrix(wavelengths_nm)[:, 1]
    luminance, luminance_error = diffuse @ y, standard_error @ np.abs(y)
    dark = luminance + 3.0 * luminance_error < dynamic_range * np.max(luminance)
    floor = np.where(dark[:, None], dynamic_range * np.max(diffuse, axis=0), 0.0)
    return pixel_relative_error(np.maximum(radiance, floor), standard_error)


class PixelPool:
    """Independent estimates of the same M pixels pooled per pixel, each weighted by its number of
    samples: mean = sum_i n_i x_i / n, standard error sqrt(sum_i (n_i / n)^2 SE_i^2), with n_i
    the samples of estimate i at that pixel (pixels may have different counts)."""

    def __init__(self, pixels: int, orders: int, wavelengths: int, stokes: int | None = None):
        """``stokes``: values per wavelength of each estimate (Stokes components, or 1), on an
        axis before the wavelengths; None: no such axis."""
        values = (wavelengths,) if stokes is None else (stokes, wavelengths)
        self.samples = np.zeros(pixels, dtype=np.int64)
        self.orders = np.zeros((pixels, orders, *values))      # mean per order
        self.variance = np.zeros((pixels, *values))            # of the mean radiance

    @property
    def radiance(self) -> np.ndarray:
        return self.orders.sum(axis=1)

    @property
    def standard_error(self) -> np.ndarray:
        return np.sqrt(self.variance)

    def add(self, pixels: np.ndarray, samples: int, orders: np.ndarray, standard_error: np.ndarray) -> None:
        """Pool an estimate of ``pixels`` (indices into the pool) from ``samples`` samples each:
        its per-order means (len(pixels), orders, [S,] N) and standard error (len(pixels), [S,] N)."""
        before = self.samples[pixels]
        total = before + samples
        share = (1,) * (self.variance.ndim - 1)
        old, new = (before / total).reshape(-1, *share), (samples / total).reshape(-1, *share)
        self.orders[pixels] = old[:, None] * self.orders[pixels] + new[:, None] * orders
        self.variance[pixels] = old ** 2 * self.variance[pixels] + new ** 2 * standard_error.astype(np.float64) ** 2
        self.samples[pixels] = total


class AdaptiveProgress:
    """Where an adaptive render (:func:`render_to_error`) stands: its pooled estimates, the
    rounds done and the seeds they used, the current round's launches (samples per pass, the
    views, the seed) and how many of them are done, and the render's wall and CPU time so far
    (over every run that worked on it).

    Kept in a checkpoint file (``.npz``, written atomically after every launch) it lets a render
    that was killed part-way resume at its next launch when called again with the same arguments:
    hours of a hard sky are not lost with the process. Resuming continues the round as it was
    planned: planned again from the part-pooled estimates, a view could be traced twice with one
    seed and count, the same samples counted twice."""

    #: Bump when the file's layout or the meaning of its values changes: older files are not used.
    FORMAT = 2

    def __init__(self, pool: PixelPool, key: str, wavelengths_nm, dynamic_range: float | None = None):
        """``key``: what the render is (:func:`_adaptive_key`); a file with another key is not
        used. ``wavelengths_nm``, ``dynamic_range``: how the views' error is measured
        (:func:`stopping_error`)."""
        self.pool, self.key = pool, key
        self.wavelengths_nm, self.dynamic_range = np.asarray(wavelengths_nm, dtype=np.float64), dynamic_range
        self.round, self.launches, self.done, self.elapsed, self.used_seeds = 0, None, 0, 0.0, []
        #: CPU seconds of the process in the render's launches, and of that, the runs' before this one.
        self.cpu, self.cpu_before = 0.0, 0.0

    def save(self, path) -> None:
        pool = self.pool
        launches = self.launches or []
        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            np.savez(f, key=np.array(self.key), round=self.round, done=self.done, elapsed=self.elapsed, cpu=self.cpu,
                     used_seeds=np.asarray(self.used_seeds, dtype=np.int64), planned=self.launches is not None,
                     launch_spp=np.asarray([c for c, _, _ in launches], dtype=np.int64),
                     launch_seeds=np.asarray([s for _, _, s in launches], dtype=np.int64),
                     launch_sizes=np.asarray([m.size for _, m, _ in launches], dtype=np.int64),
                     launch_views=np.concatenate([m for _, m, _ in launches] or [np.zeros(0, dtype=np.int64)]),
                     samples=pool.samples, orders=pool.orders, variance=pool.variance,
                     wavelengths_nm=self.wavelengths_nm,
                     dynamic_range=np.nan if self.dynamic_range is None else self.dynamic_range)

    def error(self) -> np.ndarray:
        """Per view, the error held to the target (:func:`stopping_error`)."""
        return stopping_error(self.pool.orders[:, :, 0], self.pool.standard_error[:, 0], self.wavelengths_nm,
                              self.dynamic_range)

    def resume(self, path) -> bool:
        """Take up the state kept in ``path`` if it holds this render's; whether it did."""
        if not os.path.exists(path):
            return False
        with np.load(path) as kept:
            if str(kept["key"]) != self.key or kept["orders"].shape != self.pool.orders.shape:
                return False
            self.pool.samples[:], self.pool.orders[:], self.pool.variance[:] = \
                kept["samples"], kept["orders"], kept["variance"]
            self.round, self.done, self.elapsed = int(kept["round"]), int(kept["done"]), float(kept["elapsed"])
            self.cpu = self.cpu_before = float(kept["cpu"])
            self.used_seeds = [int(seed) for seed in kept["used_seeds"]]
            views = np.split(kept["launch_views"], np.cumsum(kept["launch_sizes"])[:-1])
            self.launches = ([(int(c), v, int(s)) for c, v, s in zip(kept["launch_spp"], views, kept["launch_seeds"])]
                             if bool(kept["planned"]) else None)
        return True

    @staticmethod
    def describe(path, target_relative_error: float) -> str | None:
        """How far the render kept in the checkpoint ``path`` is, in a few words (rounds done, the
        launches done of the round under way, the share of its views at ``target_relative_error``,
        render time); None while there is none."""
        try:
            with np.load(path) as kept:
                orders, variance = kept["orders"][:, :, 0], kept["variance"][:, 0]
                rounds, elapsed = int(kept["round"]), float(kept["elapsed"])
                done, launches = int(kept["done"]), len(kept["launch_spp"]) if bool(kept["planned"]) else 0
                wavelengths_nm, dynamic_range = kept["wavelengths_nm"], float(kept["dynamic_range"])
        except (FileNotFoundError, OSError, KeyError, ValueError):     # not written yet, or replaced meanwhile
            return None
        error = stopping_error(orders, np.sqrt(variance), wavelengths_nm,
                               None if math.isnan(dynamic_range) else dynamic_range)
        if launches and done == launches:          # saved after a round's last launch: that round is done
            rounds, launches = rounds + 1, 0
        under_way = f" (round {rounds + 1}: {done} of {launches} launches)" if launches else ""
        return (f"{rounds} round{'s' if rounds != 1 else ''} done{under_way}, "
                f"{np.mean(error <= target_relative_error):.0%} of {error.size} views at "
                f"{100 * target_relative_error:g}%, render time {elapsed:.0f} s")


def _adaptive_key(scene, target_relative_error, seeds, max_spp, initial_spp, views, dynamic_range) -> str:
    """What an adaptive render is, as a digest: the scene (its render settings too), the target
    (and its dynamic range, where there is one), seeds and sample counts, the views traced, and
    :attr:`AdaptiveProgress.FORMAT`."""
    what = {"format": AdaptiveProgress.FORMAT, "scene": scene.to_dict(), "target": target_relative_error,
            "seeds": [int(seed) for seed in seeds], "max_spp": int(max_spp), "initial_spp": int(initial_spp),
            "views": hashlib.sha256(np.asarray(views, dtype=np.int64).tobytes()).hexdigest()}
    if dynamic_range is not None:
        what["dynamic_range"] = dynamic_range
    return hashlib.sha256(json.dumps(what, sort_keys=True, default=numpy_default).encode()).hexdigest()


def _adaptive_views(scene, max_spp: int, initial_spp: int | None, seed: int, symmetry: bool) -> tuple:
    """What an adaptive render of ``scene`` traces: (the scene with its first round's settings,
    that round's samples per pixel, the rendered pixels, the views traced, each pixel's view and
    whether it sees its mirror image (:func:`traced_views`), the samples each view may take:
    ``max_spp`` x its pixels)."""
    passes = scene.render.passes
    spp = min(initial_spp or max(16 * passes, 64), max_spp)
    if spp < passes:
        raise ParameterError("max_spp", max_spp, f">= passes ({passes})", "too few samples")
    scene = scene.replace(render=_settings(scene, spp, None, seed))
    pixels = rendered_pixels(scene)
    traced, estimate_of, mirrored = traced_views(scene, pixels, symmetry)
    views = pixels[traced]
    return scene, spp, pixels, views, estimate_of, mirrored, max_spp * np.bincount(estimate_of, minlength=views.size)


def launch_parts(spp_per_pass: int, positions, passes: int) -> list:
    """The views ``positions`` that take ``spp_per_pass`` x ``passes`` samples each, in launches
    of at most LAUNCH_SAMPLES samples (at least one view each): (samples per pass, positions,
    part number) per launch."""
    per_launch = max(1, LAUNCH_SAMPLES // (spp_per_pass * passes))
    return [(spp_per_pass, positions[first:first + per_launch], part)
            for part, first in enumerate(range(0, len(positions), per_launch))]


def round_launches(samples, error, target_relative_error: float, budget, passes: int) -> list:
    """A later round of :func:`render_to_error`: (samples per pass, positions, part number) of
    each launch, given each view's ``samples`` so far, its :func:`stopping_error` and its
    ``budget`` (most samples). A view above the target asks for what the 1/sqrt(spp) law says it
    still needs, with ``ROUND_MARGIN``, rounded to ``passes`` x the nearest power of two, within
    its budget; the views of one count are traced in :func:`launch_parts`."""
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        wanted = np.ceil(ROUND_MARGIN * samples * (error / target_relative_error) ** 2) - samples
    room = (budget - samples) // passes                            # samples per pass left
    counts = 2 ** np.round(np.log2(np.maximum(np.nan_to_num(wanted, posinf=budget.max()) / passes, 1.0)))
    counts = np.minimum(counts, 2 ** np.floor(np.log2(np.maximum(room, 1))))
    active = (error > target_relative_error) & (room >= 1)
    return [launch for count in np.unique(counts[active])
            for launch in launch_parts(int(count), np.flatnonzero(active & (counts == count)), passes)]


def render_to_error(scene, target_relative_error: float, seeds, max_spp: int, initial_spp: int | None = None,
                    variant: str | None = None, symmetry: bool = True, checkpoint=None,
                    dynamic_range: float | None = None) -> Sky:
    """Render ``scene`` until every rendered pixel's :func:`pixel_relative_error` is at most
    ``target_relative_error``, or it has had ``max_spp`` samples: adaptive per direction, so a
    dark pixel costs its own samples, not the sky's. ``dynamic_range`` (in (0, 0.1]; None: none):
    a pixel darker than that fraction of the brightest is held to an absolute error instead
    (:func:`stopping_error`), for a consumer that does not look at it. A view traced once for n pixels
    (``symmetry``) may take n x ``max_spp``, what those pixels would have cost traced apart: the
    ground at a ground observer's feet, one view for the half of the sphere below the horizon,
    ended at 0.48% with 2^20 samples on a hazy sky with a low sun (turbidity 6, sun zenith 88 deg,
    780 nm; the LUT audit's target 0.3% asks for about 2.7 million), which cost little beside
    its sky's 513 views.

    Round r uses seed ``seeds[r]`` (rounds are independent). The first gives every pixel
    ``initial_spp``; each later one gives each pixel still above the target what the
    1/sqrt(spp) law asks for (with a ROUND_MARGIN), rounded to ``passes`` x the nearest power of
    two (so a round is a few launches, one per count; rounding up instead cost 7-15% more CPU on
    the Hosek training skies, pixels ending at 0.83% for a 1% target in the median), within
    each view's budget. The sky's metadata records the mean, smallest and largest samples per pixel,
    the share of pixels at the target and the 95th percentile of the relative error. A polarized scene (``render.polarized``)
    pools every Stokes component and aims at I's error. ``symmetry``: as in :func:`render_sky`.
    ``checkpoint``: a file (``.npz``) where the render keeps its state after every launch
    (:class:`AdaptiveProgress`), and from which a call with the same arguments resumes (a file
    there of another render is removed at the start); it is left in place (a later call returns
    the finished sky at once), for the caller to remove."""
    check_number("target_relative_error", target_relative_error, 1e-5, 1.0)
    if dynamic_range is not None:
        check_number("dynamic_range", dynamic_range, 0.0, 0.1, lo_open=True)
    if checkpoint is not None:
        check_output_file(checkpoint, ".npz", "checkpoint")
    passes = scene.render.passes
    scene, spp, pixels, views, estimate_of, mirrored, budget = _adaptive_views(scene, max_spp, initial_spp, seeds[0],
                                                                               symmetry)
    renderer = _PixelRenderer(scene, variant, "spherical", 0)
    pool = PixelPool(views.size, len(ORDER_NAMES), len(scene.wavelengths_nm), stokes_components(scene))
    progress = AdaptiveProgress(pool, _adaptive_key(scene, target_relative_error, seeds, max_spp, spp, views,
                                                    dynamic_range), scene.wavelengths_nm, dynamic_range)
    if checkpoint is not None and not progress.resume(checkpoint):
        with contextlib.suppress(FileNotFoundError):    # another render's state: not shown as this one's
            os.remove(checkpoint)

    def plan(round_index, seed) -> list:
        """The launches of a round: (samples per pass, positions in ``views``, seed) each; the
        seed differs between a round's counts and between the parts of one count."""
        if round_index == 0:
            launches = launch_parts(spp // passes, np.arange(views.size), passes)
        else:
            launches = round_launches(pool.samples, progress.error(), target_relative_error, budget, passes)
        return [(count, members, launch_seed(seed, count if round_index else 0, part))
                for count, members, part in launches]

    while progress.round < len(seeds):
        if progress.launches is None:
            progress.launches, progress.done = plan(progress.round, seeds[progress.round]), 0
            if not progress.launches:
                break
        for spp_per_pass, members, seed in progress.launches[progress.done:]:
            start, start_cpu = time.perf_counter(), time.process_time()
            per_pass = renderer.passes(views[members], spp_per_pass, passes, seed)
            progress.elapsed += time.perf_counter() - start
            progress.cpu += time.process_time() - start_cpu
            pool.add(members, spp_per_pass * passes, *renderer.statistics(per_pass))
            progress.done += 1
            if checkpoint is not None:
                progress.save(checkpoint)
        progress.used_seeds.append(seeds[progress.round])
        progress.round, progress.launches = progress.round + 1, None

    # per pixel from here on: a pixel that shares its view's estimate has its samples and error
    error = progress.error()[estimate_of]
    samples = pool.samples[estimate_of]
    metadata = renderer.metadata(round(samples.sum() / max(pixels.size, 1)), passes, progress.used_seeds,
                                 progress.elapsed, int(pool.samples.sum()), views.size)
    metadata.update(target_relative_error=target_relative_error, dynamic_range=dynamic_range, render_cpu_s=progress.cpu,
                    render_cpu_s_before_resume=progress.cpu_before,
                    spp_range=[int(samples.min()), int(samples.max())] if pixels.size else [0, 0],
                    pixels_at_target=float(np.mean(error <= target_relative_error)) if pixels.size else 1.0)
    orders = copy_estimates(pool.orders, estimate_of, mirrored, scene.render.polarized)
    sky = _sky(scene, pixels, orders.sum(axis=1), pool.standard_error[estimate_of], orders, metadata)
    sky.metadata["relative_error_p95"] = relative_error_percentile(sky)
    return sky


def launch_seed(round_seed: int, spp_per_pass: int, part: int) -> int:
    """The seed of one launch of a :func:`render_to_error` round: the round's own seed, mixed in
    later rounds (``spp_per_pass`` > 0) with the launch's count, and for every part of a count
    after the first with the part's number."""
    if spp_per_pass:
        round_seed = (round_seed + 0x9E3779B1 * spp_per_pass.bit_length()) % (1 << 31)
    return (round_seed + 0x85EBCA77 * part) % (1 << 31) if part else round_seed


def forecast_render_to_error(scene, target_relative_error: float, rounds: int, max_spp: int,
                             pilot_spp: int = PILOT_SPP, seed: int = 0, initial_spp: int | None = None,
                             variant: str | None = None, symmetry: bool = True,
                             dynamic_range: float | None = None) -> dict:
    """What :func:`render_to_error` with these arguments (``rounds`` seeds) would cost, from a
    pilot render of every view it traces at ``pilot_spp`` samples (seed ``seed``, thrown away):
    each view's relative variance of one sample (its :func:`stopping_error` squared x the pilot's
    samples), then :func:`render_to_error`'s rounds replayed (:func:`round_launches`) as if each
    view's error fell exactly as 1/sqrt(samples). Its CPU is each view's samples at the CPU per
    sample of its group (``COST_GROUPS`` groups of views by the samples forecast, each timed at a
    quarter of the pilot's samples per view) plus, per launch, what a launch of a few samples
    costs (tracing the kernels: on a small sky most of it); compiling the kernels is not counted.
    It does not see a heavy tail the pilot did not draw, nor the noise of the rounds' own
    estimates. The LUT audit's skies (17 wavelengths, 0.3%; 1% at sun zenith 96) against this
    forecast (2026-12-07): hazy sky 45 (the ground, sun 80) took 1.41x its CPU and 1.24x its
    samples (50-52: 1.16-1.21x the samples); the hazy twilight skies 69 and 76 (sun 96, from 50
    and 100 km) 2.37x / 2.36x the CPU and 2.27x / 2.45x the samples, where the pilot draws too
    little of their tails. (Timed at the pilot's mean CPU per sample, those two were forecast at
    537 and 436 s instead of 707 and 561.)

    Returns {"cpu_s", "samples" (traced in all), "launches", "views" (traced), "samples_per_view"
    (mean), "views_short" (left above the target when their budget, ``max_spp`` x their pixels,
    or the rounds run out), "pilot_cpu_s" (the pilot's and the timing launches'), "groups" (per
    group of views, from the fewest samples to the most: {"views", "samples", "us_per_sample"})}."""
    check_number("target_relative_error", target_relative_error, 1e-5, 1.0)
    check_int("rounds", rounds, 1, 64)
    if dynamic_range is not None:
        check_number("dynamic_range", dynamic_range, 0.0, 0.1, lo_open=True)
    passes = scene.render.passes
    check_int("pilot_spp", pilot_spp, passes, 1 << 20)
    scene, spp, _, views, _, _, budget = _adaptive_views(scene, max_spp, initial_spp, seed, symmetry)
    if not views.size:
        return {"cpu_s": 0.0, "samples": 0, "launches": 0, "views": 0, "samples_per_view": 0.0, "views_short": 0,
                "pilot_cpu_s": 0.0, "groups": []}
    renderer = _PixelRenderer(scene, variant, "spherical", 0)
    renderer.passes(views[:8], 1, passes, seed)                    # compiles the kernels: not timed
    start = time.process_time()
    renderer.passes(views[:8], 1, passes, seed + 1)
    launch_cpu = time.process_time() - start                       # a launch's own cost (tracing, setup)
    pilot_samples = passes * (pilot_spp // passes)
    start = time.process_time()
    orders, standard_error = renderer.statistics(renderer.passes(views, pilot_spp // passes, passes, seed))
    pilot_cpu = time.process_time() - start
    with np.errstate(over="ignore", invalid="ignore"):
        variance = stopping_error(orders[:, :, 0, :], standard_error[:, 0, :], scene.wavelengths_nm,
                                  dynamic_range) ** 2 * pilot_samples
    samples, launches = np.full(views.size, spp, dtype=np.int64), len(launch_parts(spp // passes, views, passes))
    for _ in range(rounds - 1):
        round_plan = round_launches(samples, np.sqrt(variance / samples), target_relative_error, budget, passes)
        for count, members, _ in round_plan:
            samples[members] += count * passes
        launches += len(round_plan)
        if not round_plan:
            break
    # each group of views (COST_GROUPS, by the samples forecast) at its own CPU per sample, timed
    # with a quarter of the pilot's samples per view
    timing_spp = max(pilot_spp // (4 * passes), 1)
    groups = []
    for number, group in enumerate(np.array_split(np.argsort(samples, kind="stable"), min(COST_GROUPS, views.size))):
        start = time.process_time()
        renderer.passes(views[group], timing_spp, passes, seed + 2 + number)
        cpu = time.process_time() - start
        pilot_cpu += cpu
        groups.append({"views": int(group.size), "samples": int(samples[group].sum()),
                       "us_per_sample": 1e6 * max(cpu - launch_cpu, 0.5 * cpu) / (group.size * timing_spp * passes)})
    return {"cpu_s": launch_cpu * launches + sum(1e-6 * g["us_per_sample"] * g["samples"] for g in groups),
            "samples": int(samples.sum()), "launches": launches, "views": int(views.size),
            "samples_per_view": float(samples.mean()),
            "views_short": int(np.sum(np.sqrt(variance / samples) > target_relative_error)), "pilot_cpu_s": pilot_cpu,
            "groups": groups}
