"""The fit report: skyref's fitted Hosek–Wilkie table, the published Hosek–Wilkie model (1.4a) and
the Perez (Preetham-style) baseline against skyref's ground truth.

Usage: ``python benchmarks/fit_report.py`` (the one command). It

1. reads the ground truth of ``skyref batch grids/hosek_training.toml`` (``out/hosek-training``).
   It renders nothing: run that batch to the end first; the script stops if skies are missing;
2. runs ``skyref fit --grid out/hosek-training --out out/hosek-coefficients`` when ``hosek.npz``
   or ``perez.npz`` there is missing or older than the dataset. The fit time reported is the one
   ``skyref fit`` records in those files (seconds per stage and kind, jit compilation included);
3. compares every table with the ground truth through :func:`skyref.fit.evaluate.error_summary`
   (relative error model / truth - 1 over the directions the fit uses: above the horizon, off the
   solar disk; noise-corrected RMS and 95th percentile, each beside the ground truth's noise), per
   channel of every kind in the dataset (spectral bands, CIE XYZ, linear sRGB): over all skies, by
   solar elevation, by turbidity, and per sky. The published model is evaluated at the same
   turbidity, ground albedo and solar elevation as each sky;
4. measures evaluation throughput with :func:`skyref.fit.evaluate.throughput` (NumPy and JAX);
5. writes ``results/fit_report.md``, ``results/fit_report/errors.csv`` (every sky, channel and
   model), ``results/fit_report/rms_<kind>.png`` (RMS error over solar elevation x turbidity) and
   ``results/fit_report/sky_T<turbidity>.png`` (ground truth, our fit and the published model side
   by side, tone-mapped, with maps of the luminance error), every file atomically.

``--dataset``, ``--coefficients`` and ``--results`` point it at other directories (e.g. a small
synthetic batch while developing).
"""

from __future__ import annotations

import argparse
import csv
import datetime
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from results_files import machine  # noqa: E402

from skyref.analytic.hosek import CHANNELS, published_table  # noqa: E402
from skyref.audit.metrics import NOISE_RATIO, _statistics, shared_estimates  # noqa: E402
from skyref.color import default_exposure, tonemap_srgb8  # noqa: E402
from skyref.fit.cli import FORM_NAMES, noise_line, truth_metadata  # noqa: E402
from skyref.fit.evaluate import (error_summary, interpolation_gap, model_radiance, relative_errors,  # noqa: E402
                                 throughput)
from skyref.fit.export import read_tables  # noqa: E402
from skyref.fit.training import load_batch_dataset  # noqa: E402
from skyref.io.atomic import atomic_path, atomic_write  # noqa: E402

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
DATASET = os.path.join(ROOT, "out", "hosek-training")
COEFFICIENTS = os.path.join(ROOT, "out", "hosek-coefficients")
RESULTS = os.path.join(ROOT, "results")
#: The models compared, in report order: name -> coefficient file in the coefficient directory
#: (None: the published coefficients bundled with skyref).
MODELS = {"ours": "hosek.npz", "published": None, "Perez": "perez.npz"}
#: Sky images: turbidities and solar elevations (deg) shown, at this ground albedo (the dataset's
#: nearest skies).
IMAGE_TURBIDITIES = (2.0, 6.0)
IMAGE_ELEVATIONS_DEG = (3.0, 12.0, 38.0)
IMAGE_ALBEDO = 0.0
#: Regions of the sky reported apart (zenith angle theta and view-sun angle gamma, degrees): the
#: form's horizon term and its aureole terms are tested where each dominates.
HORIZON_ZENITH_DEG = 85.0
AUREOLE_GAMMA_DEG = 15.0
REGIONS = {"horizon, near the sun": f"theta >= {HORIZON_ZENITH_DEG:g}°, gamma < {AUREOLE_GAMMA_DEG:g}°",
           "horizon, away from the sun": f"theta >= {HORIZON_ZENITH_DEG:g}°, gamma >= {AUREOLE_GAMMA_DEG:g}°",
           "aureole above the horizon": f"theta < {HORIZON_ZENITH_DEG:g}°, gamma < {AUREOLE_GAMMA_DEG:g}°",
           "rest of the sky": f"theta < {HORIZON_ZENITH_DEG:g}°, gamma >= {AUREOLE_GAMMA_DEG:g}°"}


def shown(path) -> str:
    """``path`` relative to the repository when inside it, else absolute."""
    relative = os.path.relpath(os.path.abspath(path), ROOT)
    return os.path.abspath(path) if relative.startswith("..") else relative


def log(message):
    print(message, flush=True)


def newest_mtime(directory) -> float:
    """Latest modification time (s since the epoch) of any file under ``directory``."""
    times = [os.path.getmtime(os.path.join(path, name)) for path, _, names in os.walk(directory) for name in names]
    return max(times, default=os.path.getmtime(directory))


def ensure_fit(dataset, coefficients):
    """Run ``skyref fit`` unless every coefficient file is newer than the dataset."""
    from skyref.cli import main as skyref

    paths = [os.path.join(coefficients, name) for name in MODELS.values() if name]
    stale = newest_mtime(dataset)
    if all(os.path.exists(p) and os.path.getmtime(p) > stale for p in paths):
        log(f"tables in {coefficients} are newer than the dataset: not refitting")
        return
    log(f"fitting: skyref fit --grid {dataset} --out {coefficients}")
    code = skyref(["fit", "--grid", dataset, "--out", coefficients])
    if code:
        sys.exit(f"skyref fit failed (exit status {code})")


def elevation_deg(training) -> np.ndarray:
    """(S,) solar elevation of each sky, degrees (rounded, to group skies by it)."""
    return np.round(np.degrees(training.solar_elevation), 6)


def turbidity(training) -> np.ndarray:
    """(S,) turbidity of each sky (rounded, to group skies by it)."""
    return np.round(training.turbidity, 6)


def grouped_statistics(table, training, keys) -> dict:
    """{key: {channel: statistics}} of :func:`error_summary` over the skies sharing each key
    (``keys``: one hashable per sky)."""
    return {key: error_summary(table, training.select(np.array([k == key for k in keys])))["channels"]
            for key in sorted(set(keys))}


def region_masks(training) -> dict:
    """{region: (S, P) mask} of :data:`REGIONS`."""
    horizon = np.degrees(np.arccos(np.clip(training.cos_theta, -1.0, 1.0)))[None, :] >= HORIZON_ZENITH_DEG
    aureole = np.degrees(training.gamma) < AUREOLE_GAMMA_DEG
    return dict(zip(REGIONS, (horizon & aureole, horizon & ~aureole, ~horizon & aureole, ~horizon & ~aureole)))


def region_statistics(table, training) -> dict:
    """{region: statistics} over every channel of the kind pooled, plus "median" |error| and
    "share" (of the fitted directions' solid angle)."""
    error, noise = relative_errors(table, training)
    estimates = shared_estimates(training.radiance, training.standard_error)     # (S, P)
    channels = np.arange(error.shape[-1])
    weights = training.weights()
    found = {}
    for region, mask in region_masks(training).items():
        e, n = error[mask], noise[mask]
        stats = _statistics(e.ravel(), n.ravel(), (estimates[mask][:, None] * channels.size + channels).ravel())
        if stats is not None:
            stats["median"] = float(np.nanmedian(np.abs(e)))
            stats["share"] = float(weights[mask].sum() / weights.sum())
        found[region] = stats
    return found


def evaluate_models(tables, training_sets):
    """Per kind and model: statistics over all skies ("all"), per sky ("skies"), by solar
    elevation, by turbidity and by (elevation, turbidity) cell."""
    results = {}
    for kind, training in training_sets.items():
        elevations, turbidities = elevation_deg(training), turbidity(training)
        for model, by_kind in tables.items():
            if kind not in by_kind:
                continue
            log(f"  {model} {kind}")
            table = by_kind[kind]
            summary = error_summary(table, training)
            results.setdefault(kind, {})[model] = {
                "all": summary["channels"], "skies": summary["skies"],
                "elevation": grouped_statistics(table, training, list(elevations)),
                "turbidity": grouped_statistics(table, training, list(turbidities)),
                "cells": grouped_statistics(table, training, list(zip(elevations, turbidities))),
                "regions": region_statistics(table, training)}
    return results


# --- markdown -----------------------------------------------------------------------------------

def channel_label(kind, channel) -> str:
    return f"{channel} nm" if kind == "spectral" else channel


def rms_cell(stats) -> str:
    return "–" if stats is None else f"{100 * stats['rms']:.2f} ±{100 * stats['noise_rms']:.2f}"


def p95_cell(stats) -> str:
    return "–" if stats is None else f"{100 * stats['p95']:.2f}"


def error_table(first_column, rows, models) -> list[str]:
    """A markdown table: ``rows`` is a list of (label, {model: statistics}); RMS and p95 per
    model, then the truth's noise p95 (the same data for every model)."""
    lines = [f"| {first_column} | " + " | ".join(f"{m} RMS | {m} p95" for m in models) + " | truth noise p95 |",
             "|---|" + "---:|---:|" * len(models) + "---:|"]
    for label, by_model in rows:
        noise = next((s for s in by_model.values() if s is not None), None)
        noise_cell = "–" if noise is None else f"{100 * noise['noise_p95']:.2f}"
        lines.append(f"| {label} | " + " | ".join(f"{rms_cell(by_model[m])} | {p95_cell(by_model[m])}" for m in models)
                     + f" | {noise_cell} |")
    return lines


def timing_table(metadata, speeds) -> list[str]:
    """Fit time per stage (recorded by ``skyref fit``) and evaluation throughput, per model and kind."""
    stages = list(dict.fromkeys(stage for fits in metadata.values() for run in fits.get("fits", {}).values()
                                for stage in run["timings_s"]))
    lines = ["| model | kind | channels fitted | " + " | ".join(f"{s} (s)" for s in stages) +
             " | fit total (s) | unconverged problems | NumPy (M directions/s) | JAX (M directions/s) |",
             "|---|---|---|" + "---:|" * (len(stages) + 4)]
    totals = {}
    for model, fitted in metadata.items():
        for kind, run in fitted.get("fits", {}).items():
            total = sum(run["timings_s"].values())
            totals[model] = totals.get(model, 0.0) + total
            speed = speeds[model][kind]
            unconverged = ", ".join(f"{k} {v}" for k, v in run["unconverged"].items())
            lines.append(f"| {model} | {kind} | {', '.join(run['channels_fitted'])} | " +
                         " | ".join(f"{run['timings_s'][s]:.1f}" if s in run["timings_s"] else "–" for s in stages) +
                         f" | {total:.1f} | {unconverged} | {speed['numpy'] / 1e6:.2f} | {speed['jax'] / 1e6:.2f} |")
    lines += [""] + [f"- Whole {FORM_NAMES[metadata[m]['form']]} table ({', '.join(metadata[m]['fits'])}): "
                     f"fitted in {t:.1f} s." for m, t in totals.items()]
    return lines


def write_markdown(path, dataset, coefficients, training_sets, results, metadata, speeds, gaps, figures, load):
    any_set = next(iter(training_sets.values()))
    truth = truth_metadata(any_set)
    truth_text = "the truth's EXRs are not beside its dataset" if truth is None else truth["description"]
    models = list(MODELS)
    ours = metadata["ours"]
    lines = ["# Hosek–Wilkie fit: skyref's table, the published model and a Perez baseline against the ground truth",
             "",
             f"Generated by `python benchmarks/fit_report.py` ({datetime.date.today()}; {machine()}"
             f", load average {load:.1f} at the start) from the ground truth in "
             f"`{shown(dataset)}` ({len(any_set.solar_elevation)} skies: turbidity "
             f"{', '.join(f'{t:g}' for t in np.unique(turbidity(any_set)))}; ground albedo "
             f"{', '.join(f'{a:g}' for a in np.unique(any_set.albedo))}; solar elevation "
             f"{', '.join(f'{e:.2f}' for e in np.unique(elevation_deg(any_set)))} deg; "
             f"{len(any_set.directions)} view directions at or above the horizon; {truth_text}) "
             "and the tables in "
             f"`{shown(coefficients)}` (written {ours.get('created', '?')} by skyref "
             f"{ours.get('skyref_version', '?')}, joint refinement {'on' if ours.get('joint_refinement') else 'off'}).",
             "",
             "Models: **ours** = skyref's Hosek–Wilkie fit (`hosek.npz`); **published** = Hosek & Wilkie's "
             "coefficients (reference implementation 1.4a), evaluated at each sky's turbidity, ground albedo and "
             "solar elevation (skyref turns turbidity into aerosol with `skyref.atmosphere.from_turbidity`, the "
             "published model with its own aerosol model: part of its error is that difference); **Perez** = the "
             "5-coefficient Perez (Preetham-style) form fitted to the same data (`perez.npz`).",
             "",
             "Errors: relative error model / truth - 1 per direction, over the directions the fit uses (at or above "
             "the horizon, off the solar disk), in %. RMS has the ground truth's noise variance removed; `±` is the "
             "noise that the ground truth's own noise leaves on it. p95: 95th percentile of |error| (not corrected: "
             "it includes the truth's noise, whose own 95th percentile is in the last column). Statistics: "
             "`skyref.fit.evaluate.error_summary`.",
             "", "## Fit time and evaluation speed", "",
             *timing_table(metadata, speeds), "",
             f"Throughput: directions per second for one configuration, every channel of the kind at once "
             f"(`skyref.fit.evaluate.throughput`: NumPy float64; JAX jit-compiled float32 on "
             f"{', '.join(sorted({s['jax_device'] for by_kind in speeds.values() for s in by_kind.values()}))}). "
             "The published table has the form "
             "and evaluator of ours, hence its speed.", "",
             "## Between the stored configurations", "",
             "Engines (and the published code) evaluate a sky between the stored turbidities and albedos by "
             "blending the coefficients of its neighbours. The ground truth exists only at the stored "
             "configurations, so this checks the table itself: the sky halfway between two neighbours, as the "
             "model evaluates it, against the mean of the two neighbours' radiances "
             "(`skyref.fit.evaluate.interpolation_gap`; every channel, solar elevations 3, 10, 30 and 60 deg, "
             "directions above the horizon). Radiance is not exactly linear in albedo (light reflected by the "
             "ground returns after scattering), so a gap of a few % at albedo 1/2 is physical; a large one means "
             "neighbouring configurations trade their coefficients against each other differently, and every "
             "sky off the grid inherits the error.", "",
             "| model | kind | turbidity t + 1/2: median | p95 | albedo 1/2: median | p95 |",
             "|---|---|---:|---:|---:|---:|",
             *(f"| {model} | {kind} | {100 * g['turbidity']['median']:.2f}% | {100 * g['turbidity']['p95']:.1f}% | "
               f"{100 * g['albedo']['median']:.2f}% | {100 * g['albedo']['p95']:.1f}% |"
               for model, by_kind in gaps.items() for kind, g in by_kind.items()), ""]
    for kind, training in training_sets.items():
        by_model = results[kind]
        present = [m for m in models if m in by_model]
        lines += [f"## {kind}: errors over all skies", "", noise_line(training) + ".", "",
                  *error_table("channel", [(channel_label(kind, c), {m: by_model[m]["all"][c] for m in present})
                                           for c in training.channels], present), ""]
        lines += [f"By region of the sky (every channel pooled; theta: zenith angle, gamma: angle from the sun; "
                  "share: of the fitted directions' solid angle). RMS (noise-corrected) and median |error|:", "",
                  "| region | share | " + " | ".join(f"{m} RMS | {m} median" for m in present) + " |",
                  "|---|---:|" + "---:|---:|" * len(present)]
        for region, definition in REGIONS.items():
            first = by_model[present[0]]["regions"][region]
            if first is None:
                continue
            lines.append(f"| {region} ({definition}) | {100 * first['share']:.1f}% | " + " | ".join(
                f"{rms_cell(by_model[m]['regions'][region])} | {100 * by_model[m]['regions'][region]['median']:.2f}"
                for m in present) + " |")
        lines.append("")
        if kind in figures.get("rms", {}):
            lines += [f"RMS error by solar elevation and turbidity (both albedos pooled); `x`: not resolved (the "
                      f"noise on the RMS exceeds 1/{NOISE_RATIO:g} of it).", "",
                      f"![{kind} RMS by elevation and turbidity]({figures['rms'][kind]})", ""]
        for channel in training.channels:
            lines += [f"<details><summary>{channel_label(kind, channel)}: by solar elevation and by turbidity"
                      "</summary>", ""]
            for axis, label, fmt in (("elevation", "solar elevation", "{:.2f}°"), ("turbidity", "turbidity", "{:g}")):
                keys = by_model[present[0]][axis]
                lines += error_table(label, [(fmt.format(key), {m: by_model[m][axis][key][channel] for m in present})
                                             for key in keys], present) + [""]
            lines += ["</details>", ""]
    if figures.get("skies"):
        lines += ["## Sky images", "",
                  "Upper hemisphere (equirectangular: azimuth across, elevation up) of each configuration: ground "
                  "truth, our fit and the published model in linear sRGB (the `rgb` kind), tone-mapped with one "
                  "exposure per row (`skyref.color.tonemap_srgb8`, the truth's), then the relative error of "
                  "luminance (the `xyz` kind's Y) of ours, the published model and Perez. Grey: directions not "
                  "compared (solar disk).", ""]
        lines += [f"![sky images, turbidity {t:g}]({p})" for t, p in figures["skies"].items()] + [""]
    else:
        lines += ["## Sky images", "", "None: they need the `rgb` and `xyz` kinds and an equirectangular camera.", ""]
    lines += ["Every statistic per sky, channel and model: [fit_report/errors.csv](fit_report/errors.csv).", ""]
    with atomic_write(path) as f:
        f.write("\n".join(lines))


# --- CSV and figures -------------------------------------------------------------------------------

def write_csv(path, results):
    """Every model's statistics per kind, channel and sky."""
    fields = ("mean", "rms", "noise_rms", "p95", "noise_p95", "max", "noise_max")
    with atomic_write(path) as f:
        writer = csv.writer(f)
        writer.writerow(["model", "kind", "channel", "solar_elevation_deg", "turbidity", "albedo", *fields])
        for kind, by_model in results.items():
            for model, found in by_model.items():
                for sky in found["skies"]:
                    for channel, stats in sky["channels"].items():
                        writer.writerow([model, kind, channel, sky["solar_elevation_deg"], sky["turbidity"],
                                         sky["albedo"], *(("",) * len(fields) if stats is None else
                                                          (stats[k] for k in fields))])


def save_figure(fig, path):
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")


def plot_rms(kind, training, by_model, path):
    """Per channel (rows) and model (columns): RMS error over solar elevation x turbidity, log
    colour scale shared by the figure; x marks RMS values the truth's noise does not resolve."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    elevations, turbidities = np.unique(elevation_deg(training)), np.unique(turbidity(training))
    models = list(by_model)
    grids = {}
    for model in models:
        for channel in training.channels:
            rms = np.full((elevations.size, turbidities.size), np.nan)
            unresolved = np.zeros(rms.shape, dtype=bool)
            for (e, t), stats in by_model[model]["cells"].items():
                if stats[channel] is not None:
                    i, j = np.searchsorted(elevations, e), np.searchsorted(turbidities, t)
                    rms[i, j] = 100 * stats[channel]["rms"]
                    unresolved[i, j] = stats[channel]["noise_rms"] * NOISE_RATIO > stats[channel]["rms"]
            grids[model, channel] = rms, unresolved
    values = np.concatenate([g.ravel() for g, _ in grids.values()])
    values = values[np.isfinite(values) & (values > 0)]
    norm = LogNorm(*(np.percentile(values, (0, 100)) if values.size else (1e-3, 1.0)))
    rows = len(training.channels)
    fig, axes = plt.subplots(rows, len(models), figsize=(2.6 * len(models) + 1.2, 1.9 * rows + 0.6), squeeze=False,
                             sharex=True, sharey=True, constrained_layout=True)
    for r, channel in enumerate(training.channels):
        for c, model in enumerate(models):
            ax = axes[r, c]
            rms, unresolved = grids[model, channel]
            # An RMS that the noise correction takes to 0 is drawn at the scale's bottom (and marked x).
            image = ax.imshow(np.where(rms > 0, rms, norm.vmin), norm=norm, cmap="viridis", origin="lower",
                              aspect="auto")
            for i, j in zip(*np.nonzero(unresolved)):
                ax.text(j, i, "x", ha="center", va="center", color="white", fontsize=6)
            if r == 0:
                ax.set_title(model)
            if c == 0:
                ax.set_ylabel(f"{channel_label(kind, channel)}\nelevation (deg)")
        axes[r, 0].set_yticks(range(elevations.size), [f"{e:.2g}" for e in elevations], fontsize=6)
    for ax in axes[-1]:
        ax.set_xticks(range(turbidities.size), [f"{t:g}" for t in turbidities], fontsize=7)
        ax.set_xlabel("turbidity")
    fig.colorbar(image, ax=axes, label="RMS relative error (%)", shrink=0.6)
    save_figure(fig, path)
    plt.close(fig)


def image_shape(directions):
    """(rows, columns) when ``directions`` are whole rows of constant zenith angle (an
    equirectangular camera's upper rows), else None."""
    z = directions[:, 2]
    columns = int(np.argmax(np.abs(z - z[0]) > 1e-9)) or z.size
    if z.size % columns or np.ptp(z.reshape(-1, columns), axis=1).max() > 1e-9:
        return None
    return z.size // columns, columns


def image_skies(training) -> dict:
    """{turbidity: [sky index, ...]}: the skies nearest to the configurations of the sky images."""
    chosen = {}
    albedo = training.albedo[np.argmin(np.abs(training.albedo - IMAGE_ALBEDO))]
    turbidities, elevations = turbidity(training), elevation_deg(training)
    for target in IMAGE_TURBIDITIES:
        nearest = float(turbidities[np.argmin(np.abs(turbidities - target))])
        candidates = np.nonzero((training.albedo == albedo) & (turbidities == nearest))[0]
        skies = chosen.setdefault(nearest, [])
        for elevation in IMAGE_ELEVATIONS_DEG:
            sky = int(candidates[np.argmin(np.abs(elevations[candidates] - elevation))])
            if sky not in skies:
                skies.append(sky)
    return chosen


def plot_skies(skies, training_sets, tables, path):
    """One row per sky: truth, ours, published (tone-mapped sRGB, one exposure per row), then the
    relative luminance error of each model."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import Normalize

    rgb, xyz = training_sets["rgb"], training_sets["xyz"]
    shape = image_shape(rgb.directions)
    elevations = 90.0 - np.degrees(np.arccos(rgb.cos_theta.reshape(shape)[:, 0]))
    step = elevations[0] - elevations[1] if shape[0] > 1 else 90.0
    extent = (0.0, 360.0, elevations[-1] - step / 2, elevations[0] + step / 2)
    y = xyz.channels.index("Y")
    imaged = ["ours", "published"]
    error_models = [m for m in MODELS if "xyz" in tables[m]]
    rows = []
    for sky in skies:
        mask = np.arange(len(rgb.solar_elevation)) == sky
        truth = rgb.radiance[sky].reshape(shape + (3,))
        exposure = default_exposure(truth)
        images = [tonemap_srgb8(truth, exposure)] + [
            tonemap_srgb8(model_radiance(tables[m]["rgb"], rgb.select(mask))[0].reshape(shape + (3,)), exposure)
            for m in imaged]
        errors = [100 * relative_errors(tables[m]["xyz"], xyz.select(mask))[0][0, :, y].reshape(shape)
                  for m in error_models]
        rows.append((sky, images, errors))
    magnitudes = np.abs(np.concatenate([e.ravel() for _, _, es in rows for e in es]))
    limit = float(np.nanpercentile(magnitudes, 99)) if np.isfinite(magnitudes).any() else 1.0
    norm = Normalize(-limit, limit)
    columns = 3 + len(error_models)
    fig, axes = plt.subplots(len(rows), columns, figsize=(3.0 * columns, 1.2 * len(rows) + 0.8), squeeze=False,
                             constrained_layout=True)
    cmap = plt.get_cmap("RdBu_r").copy()
    cmap.set_bad("0.6")
    for r, (sky, images, errors) in enumerate(rows):
        for c, image in enumerate(images):
            axes[r, c].imshow(image, extent=extent, aspect="auto", interpolation="nearest")
        for c, error in enumerate(errors, start=3):
            mapped = axes[r, c].imshow(error, extent=extent, aspect="auto", interpolation="nearest", cmap=cmap,
                                       norm=norm)
        axes[r, 0].set_ylabel(f"T {rgb.turbidity[sky]:g}, sun {np.degrees(rgb.solar_elevation[sky]):.1f}°\n"
                              f"albedo {rgb.albedo[sky]:g}", fontsize=8)
        for ax in axes[r]:
            ax.tick_params(labelsize=6)
    for c, title in enumerate(["ground truth", "ours", "published"] + [f"error: {m}" for m in error_models]):
        axes[0, c].set_title(title, fontsize=9)
    fig.colorbar(mapped, ax=axes[:, 3:], label="luminance error (%)", shrink=0.8)
    save_figure(fig, path)
    plt.close(fig)


# --- main ------------------------------------------------------------------------------------------

def load_models(coefficients) -> tuple[dict, dict]:
    """({model: {kind: table}}, {model: metadata of its file}) of :data:`MODELS`."""
    tables, metadata = {}, {}
    for model, name in MODELS.items():
        if name is None:
            tables[model] = {kind: published_table(kind) for kind in CHANNELS}
        else:
            tables[model], metadata[model] = read_tables(os.path.join(coefficients, name))
    return tables, metadata


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--dataset", default=DATASET, help="skyref batch output directory (default %(default)s)")
    parser.add_argument("--coefficients", default=COEFFICIENTS,
                        help="skyref fit output directory, fitted here if stale (default %(default)s)")
    parser.add_argument("--results", default=RESULTS, help="report directory (default %(default)s)")
    args = parser.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    load = os.getloadavg()[0]
    begin = time.perf_counter()

    log(f"loading the ground truth from {args.dataset}")
    training_sets = load_batch_dataset(args.dataset)
    any_set = next(iter(training_sets.values()))
    rendered = any_set.rendered
    if not rendered.all():
        sys.exit(f"ground truth incomplete: {int(rendered.sum())}/{rendered.size} skies rendered; finish "
                 "`skyref batch grids/hosek_training.toml` first")
    ensure_fit(args.dataset, args.coefficients)
    tables, metadata = load_models(args.coefficients)

    log("errors against the ground truth")
    results = evaluate_models(tables, training_sets)
    log("between stored configurations")
    gaps = {model: {kind: interpolation_gap(table) for kind, table in by_kind.items() if kind in training_sets}
            for model, by_kind in tables.items()}
    log("evaluation throughput")
    speeds = {model: {kind: throughput(tables[model][kind]) for kind in meta.get("fits", {})}
              for model, meta in metadata.items()}

    directory = os.path.join(args.results, "fit_report")
    figures = {"rms": {}, "skies": {}}
    for kind, training in training_sets.items():
        log(f"figure: {kind} RMS by elevation and turbidity")
        plot_rms(kind, training, results[kind], os.path.join(directory, f"rms_{kind}.png"))
        figures["rms"][kind] = f"fit_report/rms_{kind}.png"
    if {"rgb", "xyz"} <= set(training_sets) and image_shape(training_sets["rgb"].directions):
        for value, skies in image_skies(training_sets["rgb"]).items():
            log(f"figure: sky images, turbidity {value:g}")
            plot_skies(skies, training_sets, tables, os.path.join(directory, f"sky_T{value:g}.png"))
            figures["skies"][value] = f"fit_report/sky_T{value:g}.png"
    write_csv(os.path.join(directory, "errors.csv"), results)
    report = os.path.join(args.results, "fit_report.md")
    write_markdown(report, args.dataset, args.coefficients, training_sets, results, metadata, speeds, gaps, figures,
                   load)
    log(f"wrote {report} and {directory}/ in {time.perf_counter() - begin:.0f} s")


if __name__ == "__main__":
    main()
