"""One audit: a method against the ground truth on one scene, and its report.

The method sees exactly what the path tracer sees: the scene's atmosphere, wavelengths,
observer altitude, sun direction and the pixel-centre directions of its camera (the ground
truth samples only those directions, not the pixels' areas). Both skies exclude
the solar disk (the path tracer's ``sun_direct`` layer is removed). The ground truth is refined
(4x the samples per step) until the luminance RMS error of every region is resolved
(:data:`skyref.audit.metrics.NOISE_RATIO`), or ``max_spp`` is reached; the report marks every
statistic that remains noise-limited.

Costs are wall times of skyref's own implementation on this machine's CPU, each beside what it
counts (:class:`skyref.sky_method.Operations`: table fetches per direction, per-view cells x
samples), which is what an engine on a GPU would pay for. Per-view and lookup times are taken
warm: first-call work (Dr.Jit compiling its kernels) is done by a call that is not timed
(:func:`compare`). The precompute time is that of the one precomputation, compilation included.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from dataclasses import dataclass

import numpy as np
import OpenEXR

from skyref.validation import check_number
from skyref.audit.groundtruth import ground_truth
from skyref.audit.metrics import (DYNAMIC_RANGE, MAX_PIXEL_NOISE, METRICS, NOISE_RATIO, STATISTICS, error_maps,
                                  SCALE_DEFINITION, region_statistics, scale_statistics)
from skyref.audit.regions import REGIONS, region_masks
from skyref.color import default_exposure, spectral_to_linear_srgb, tonemap_srgb8
from skyref.errors import ParameterError
from skyref.io.atomic import atomic_path, atomic_write
from skyref.sky_method import SkyMethod, describe_operations

__all__ = ["FINEST_TARGET", "INITIAL_TARGET", "WARM_UP_SUN_OFFSET_DEG", "AuditResult", "all_resolved", "audit",
           "compare", "scale_table", "summary_table", "warm_up_sun", "write_report"]

#: Relative error target of the first ground-truth render (95th percentile of SE / radiance).
INITIAL_TARGET = 0.02
#: Smallest target the refinement goes down to.
FINEST_TARGET = 0.0025
#: The untimed warm-up view's sun is this far (deg) from the audited one (:func:`warm_up_sun`).
WARM_UP_SUN_OFFSET_DEG = 1.0


@dataclass
class AuditResult:
    method: str
    options: dict
    scene: object
    radiance: np.ndarray          # (H, W, N) the method's, W m^-2 sr^-1 nm^-1
    truth: object                 # the ground-truth Sky (solar disk included in its layers)
    truth_radiance: np.ndarray    # (H, W, N) ground truth without the solar disk
    maps: object                  # skyref.audit.metrics.ErrorMaps
    statistics: dict              # region -> metric -> statistics (see region_statistics)
    precompute_s: float
    per_view_s: float
    lookup_s_per_direction: float
    operations: dict | None       # skyref.sky_method.Operations.to_dict(); None if the method has none
    scale: dict | None            # the sky's skyref.audit.metrics.scale_statistics

    def summary(self) -> dict:
        """A JSON-ready digest: timings and the operations they count, ground-truth samples, the
        statistics and the sky's scale statistics."""
        return {"method": self.method, "options": self.options, "scene": self.scene.name,
                "precompute_s": self.precompute_s, "per_view_s": self.per_view_s,
                "lookup_s_per_direction": self.lookup_s_per_direction, "operations": self.operations,
                "ground_truth_spp": self.truth.metadata.get("spp"), "statistics": self.statistics,
                "scale": self.scale}


def all_resolved(statistics: dict) -> bool:
    """True when every region's luminance RMS error is resolved (the refinement criterion)."""
    return all(row["luminance"]["resolved_rms"] for row in statistics.values())


def warm_up_sun(sun_direction) -> np.ndarray:
    """A unit sun direction :data:`WARM_UP_SUN_OFFSET_DEG` lower than ``sun_direction`` (higher
    within that of the nadir), at the same azimuth: another view, whose per-view tables need the
    same kernels."""
    sun = np.asarray(sun_direction, dtype=np.float64)
    zenith = float(np.arccos(np.clip(sun[2], -1.0, 1.0)))
    offset = np.radians(WARM_UP_SUN_OFFSET_DEG)
    zenith += offset if zenith + offset <= np.pi else -offset
    horizontal = np.hypot(sun[0], sun[1])
    azimuth = sun[:2] / horizontal if horizontal > 0.0 else np.array([1.0, 0.0])
    return np.array([*(np.sin(zenith) * azimuth), np.cos(zenith)])


def compare(method, truth, scene) -> dict:
    """Evaluate a precomputed ``method`` along the pixel directions of the ground-truth sky
    ``truth`` of ``scene`` and compare: returns radiance, truth radiance (solar disk removed),
    error maps, region statistics, the sky's scale statistics, the method's operations (None if
    it counts none), the time to build its per-view tables (s) and the lookup time per direction
    (s), both warm: the per-view tables of a warm-up view (:func:`warm_up_sun`) and the lookups
    that give the radiance are built untimed first, then this view's tables and the same
    lookups again are timed."""
    sun = scene.sun.direction
    altitude = scene.observer.altitude_m
    directions = truth.directions.reshape(-1, 3)
    finite = np.all(np.isfinite(directions), axis=1)
    radiance = np.full((directions.shape[0], len(scene.wavelengths_nm)), np.nan)
    prepare = getattr(method, "prepare_view", None)
    per_view_s = 0.0
    if prepare is not None:
        prepare(warm_up_sun(sun), altitude)
        per_view_s = prepare(sun, altitude)
    radiance[finite] = method.radiance(directions[finite], sun, altitude)
    start = time.perf_counter()
    method.radiance(directions[finite], sun, altitude)
    lookup_s = (time.perf_counter() - start) / max(int(finite.sum()), 1)
    radiance = radiance.reshape(truth.radiance.shape)
    truth_radiance = truth.radiance - truth.orders.get("sun_direct", 0.0)
    maps = error_maps(radiance, truth_radiance, truth.standard_error, scene.wavelengths_nm)
    masks = region_masks(truth.directions, sun, scene.atmosphere.bottom_radius_m, altitude)
    operations = getattr(method, "operations", None)
    return {"radiance": radiance, "truth_radiance": truth_radiance, "maps": maps,
            "statistics": region_statistics(maps, masks),
            "scale": scale_statistics(maps, radiance, truth_radiance, masks["sky"]),
            "operations": operations().to_dict() if operations is not None else None,
            "lookup_s_per_direction": lookup_s, "per_view_s": per_view_s}


def audit(method, scene, max_spp: int = 16384, cache_dir: str | None = None, log=print) -> AuditResult:
    """Audit ``method`` (a constructed :class:`skyref.lut.base.LutMethod` or any object with
    ``precompute()`` and ``radiance(directions, sun_direction, observer_altitude_m)``, on
    ``scene``'s atmosphere and wavelengths) against the ground truth of ``scene``."""
    check_number("max_spp", max_spp, 16, 1 << 20)
    if not np.allclose(method.wavelengths_nm, scene.wavelengths_nm):
        raise ParameterError("method.wavelengths_nm", list(method.wavelengths_nm),
                             f"the scene's wavelengths {list(scene.wavelengths_nm)}", "mismatch")
    # Methods give radiance along exact directions: the ground truth looks along pixel centres.
    scene = scene.replace(render=dataclasses.replace(scene.render, pixel_sampling="centre"))
    precompute_s = getattr(method, "precompute_seconds", None)
    if precompute_s is None:  # not precomputed yet (tables given by a user come precomputed)
        log(f"audit {method.name}: precomputing")
        # skyref's own methods show a bar per stage; any object with precompute() is audited too
        precompute_s = (method.precompute(progress=log is print) if isinstance(method, SkyMethod)
                        else method.precompute())
    target = INITIAL_TARGET
    per_view_s = None
    while True:
        log(f"audit {method.name}: ground truth to {100 * target:.2g}% (95th percentile of standard error)")
        truth = ground_truth(scene, target, max_spp, cache_dir)
        found = compare(method, truth, scene)
        # Only the first comparison builds this view's tables; later ones find them kept.
        per_view_s = found["per_view_s"] if per_view_s is None else per_view_s
        if all_resolved(found["statistics"]) or target <= FINEST_TARGET or truth.metadata["spp"] >= max_spp:
            break
        target /= 2.0
    return AuditResult(method=method.name, options=getattr(method, "options", {}), scene=scene,
                       radiance=found["radiance"], truth=truth, truth_radiance=found["truth_radiance"],
                       maps=found["maps"], statistics=found["statistics"], precompute_s=precompute_s,
                       per_view_s=per_view_s, lookup_s_per_direction=found["lookup_s_per_direction"],
                       operations=found["operations"], scale=found["scale"])


# --- reporting -----------------------------------------------------------------------------

_METRIC_LABELS = {"luminance": "luminance rel. error", "spectral": "spectral RMS rel. error",
                  "delta_e": "CIEDE2000 (absolute)"}


def _format(metric, value):
    return f"{value:.2f}" if metric == "delta_e" else f"{100 * value:.2f}%"


def summary_table(result: AuditResult) -> list[str]:
    """Markdown rows: per region and metric, mean / RMS / p95 / max, each with the truth's
    noise in parentheses and * where that noise exceeds 1/NOISE_RATIO of the value."""
    lines = ["| region | pixels (too noisy) | metric | mean (noise) | RMS (noise) | p95 (noise) | max (noise) |",
             "|---|---:|---|---:|---:|---:|---:|"]
    for region in REGIONS:
        row = result.statistics.get(region)
        if row is None:
            continue
        for metric in METRICS:
            entry = row[metric]
            cells = [f"{_format(metric, entry[s])} ({_format(metric, entry['noise_' + s])})"
                     + ("" if entry[f"resolved_{s}"] else " *") for s in STATISTICS]
            lines.append(f"| {region} | {row['pixels']} ({row['unmeasured']}) | {_METRIC_LABELS[metric]} | "
                         + " | ".join(cells) + " |")
    return lines


def scale_table(result: AuditResult) -> list[str]:
    """Markdown rows: the sky's luminance RMS error as it is, the best scale factor and the RMS
    after it (:func:`skyref.audit.metrics.scale_statistics`), noise in parentheses, * where it
    is not resolved; no rows without a measured sky pixel."""
    scale = result.scale
    if scale is None:
        return []

    def rms(key):
        return (f"{_format('luminance', scale[key])} ({_format('luminance', scale['noise_' + key])})"
                + ("" if scale["resolved_" + key] else " *"))

    return ["| region | luminance RMS as is (noise) | best scale factor s | luminance RMS of s x method (noise) |",
            "|---|---:|---:|---:|",
            f"| sky | {rms('rms')} | {scale['factor']:.4g} | {rms('rms_scaled')} |"]


def write_report(result: AuditResult, directory: str) -> str:
    """Write ``report.md``, ``summary.json``, PNG plots and ``error_maps.exr`` into
    ``directory`` (each file atomically); returns the report's path."""
    os.makedirs(directory, exist_ok=True)
    _write_plots(result, directory)
    _write_error_exr(result, os.path.join(directory, "error_maps.exr"))
    with atomic_write(os.path.join(directory, "summary.json")) as f:
        json.dump(result.summary(), f, indent=1, default=float)
    truth_meta = result.truth.metadata
    counted = ([] if result.operations is None else
               ["- what these costs count (what an engine on a GPU pays for): "
                + describe_operations(result.operations)])
    lines = [f"# Audit: {result.method} on {result.scene.name or 'scene'}", "",
             f"- method options: `{json.dumps(result.options, default=str)}`",
             f"- costs of skyref's implementation on this machine's CPU ({len(result.scene.wavelengths_nm)} "
             f"wavelengths, double precision): precompute {result.precompute_s:.2f} s (once per atmosphere); "
             f"per-view tables {1e3 * result.per_view_s:,.1f} ms (when the sun or the observer moves); lookup "
             f"{1e9 * result.lookup_s_per_direction:,.0f} ns per direction; per view and lookup timed warm "
             "(first-call kernel compilation excluded)",
             *counted,
             f"- ground truth: skyref path tracer, {truth_meta.get('spp')} spp; noise in parentheses is the "
             f"ground truth's own on the same statistic; * marks statistics whose noise exceeds 1/{NOISE_RATIO:g} "
             "of the error, or whose region lost most pixels as too noisy (not resolved)",
             f"- pixels darker than {DYNAMIC_RANGE:g} of the brightest, or whose truth is uncertain by more than "
             f"{100 * MAX_PIXEL_NOISE:g}% (too noisy), are left out",
             "- CIEDE2000 on an absolute basis (one white for both: the truth's brightest sky pixel); the solar "
             "disk is excluded from both skies", "",
             *summary_table(result), "",
             *(["## Scale and shape", "", *scale_table(result), "", f"The best scale factor: {SCALE_DEFINITION}.", ""]
               if result.scale else []),
             "![method, ground truth](images.png)", "", "![errors](errors.png)", ""]
    path = os.path.join(directory, "report.md")
    with atomic_write(path) as f:
        f.write("\n".join(lines))
    return path


def _write_plots(result: AuditResult, directory: str):
    # Lazy: selecting the Agg backend is a side effect, made only when plots are written.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    wl = result.scene.wavelengths_nm
    rgb_truth = spectral_to_linear_srgb(result.truth_radiance, wl)
    rgb_method = spectral_to_linear_srgb(np.nan_to_num(result.radiance), wl)
    exposure = default_exposure(rgb_truth)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.2), constrained_layout=True)
    for ax, image, title in zip(axes, (rgb_method, rgb_truth), (result.method, "ground truth (skyref)")):
        ax.imshow(tonemap_srgb8(image, exposure))
        ax.set_title(title)
        ax.axis("off")
    with atomic_path(os.path.join(directory, "images.png")) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.2), constrained_layout=True)
    lum = 100 * result.maps.error["luminance"]
    limit = max(1.0, float(np.nanpercentile(np.abs(lum), 95))) if np.isfinite(lum).any() else 1.0
    shown = axes[0].imshow(lum, cmap="RdBu_r", vmin=-limit, vmax=limit)
    fig.colorbar(shown, ax=axes[0], label="relative luminance error, %")
    axes[0].set_title("(method - truth) / truth")
    shown = axes[1].imshow(result.maps.error["delta_e"], cmap="magma", vmin=0)
    fig.colorbar(shown, ax=axes[1], label="CIEDE2000")
    axes[1].set_title("colour difference")
    for ax in axes:
        ax.axis("off")
    with atomic_path(os.path.join(directory, "errors.png")) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def _write_error_exr(result: AuditResult, path: str):
    """Error maps as float32 EXR channels: ``<metric>`` and ``noise.<metric>``."""
    channels = {}
    for metric in METRICS:
        channels[metric] = np.ascontiguousarray(result.maps.error[metric].astype(np.float32))
        channels[f"noise.{metric}"] = np.ascontiguousarray(result.maps.noise[metric].astype(np.float32))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
              "skyref.audit": json.dumps({"method": result.method, "options": result.options}, default=str)}
    with atomic_path(path) as tmp, OpenEXR.File(header, channels) as exr:
        exr.write(tmp)
