"""Is a batch's ground truth what its error bars say? Views of its finished skies rendered again
at a fixed sample count, with seeds the batch never uses, against the batch's values.

A sky rendered to an error target (:func:`skyref.render.render_to_error`) stops each pixel when
its own standard error reaches the target. Where the noise is a heavy tail, a pixel that has not
yet drawn its rare large contributions has a low estimate *and* a low standard error, and stops
there: the LUT audit's 50 km skies came out up to 9% low in their dark upward views that way
(docs/design.md, "Adaptive stopping on a heavy tail"). Its own error bars cannot show it; a
render whose sample count does not depend on its own samples can.

Per sky: the views (traced pixels, :func:`skyref.render.traced_views`) of the sky whose radiance
is lowest (the dark upward views of a high observer, where the tail was) and as many drawn at
random (a fixed seed per sky). Each is rendered in two stages: a pilot of ``PILOT_SPP`` samples,
thrown away, whose spread sets the sample count at which the check's standard error is half the
truth's (at most ``MAX_SPP``); then that many samples, which alone make the check's estimate (its
count does not depend on them: no stopping bias). Per view and wavelength z = (truth - check) /
combined standard error: the mean z of an unbiased truth is 0 within about 1/sqrt(count), and a
truth biased low has mean z < 0 in its dark views. Both error bars are estimated, each from the
spread of 16 passes (:func:`honest_z`): honest ones give z a distribution with heavier tails
than a normal, mean z^2 about 1.1 and |z| > 5 about once in 20,000 values, and a mean z^2
above that means error bars too small.

Usage: ``python benchmarks/truth_check.py [--grid grids/lut_audit.toml] [--skies 0-5,21]
[--views 8]`` (default: every finished sky of the grid not checked yet); writes ``results/truth_check.md`` and
``results/truth_check.json``, keeping the rows of skies checked before with the same settings
and views (each row says when it was checked).
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from results_files import RESULTS, machine, write_results  # noqa: E402

from skyref.audit.metrics import DYNAMIC_RANGE  # noqa: E402
from skyref.batch.grid import load_grid  # noqa: E402
from skyref.batch.store import BatchStore  # noqa: E402
from skyref.io.exr import read_sky_exr  # noqa: E402
from skyref.render import render_views, rendered_pixels, traced_views  # noqa: E402

ROOT = os.path.join(os.path.dirname(__file__), "..")

#: Samples per view of the pilot stage (thrown away: it only sets the second stage's count).
PILOT_SPP = 1024
#: Most samples per view of the check's own estimate.
MAX_SPP = 1 << 20
#: The check's standard error aimed at, as a share of the truth's.
ERROR_SHARE = 0.5
#: Seeds of the checks: far above any a batch uses ((seed * MAX_ROUNDS + r) * skies + i).
CHECK_SEEDS = 1 << 30


def chosen_views(scene, truth, count: int, rng) -> np.ndarray:
    """Flat pixel indices of ``count`` traced views with the lowest mean radiance over the
    wavelengths and ``count`` others drawn at random (``rng``), among the views the LUT audit
    measures: brighter than its ``DYNAMIC_RANGE`` times the brightest view (the night side seen
    from 1000 km, at 1e-10 of the day side, is neither audited nor a meaningful check: a pilot
    there can see no light at all)."""
    pixels = rendered_pixels(scene)
    traced, _, _ = traced_views(scene, pixels)
    views = pixels[traced]
    mean = truth.radiance.reshape(-1, truth.radiance.shape[-1])[views].mean(axis=1)
    brightest = np.max(np.where(np.isfinite(mean), mean, 0.0), initial=0.0)
    is_lit = np.isfinite(mean) & (mean > DYNAMIC_RANGE * brightest) & (mean > 0)
    lit = views[is_lit]
    darkest = lit[np.argsort(mean[is_lit])[:count]]
    others = rng.choice(np.setdiff1d(lit, darkest), size=min(count, lit.size - darkest.size), replace=False)
    return np.concatenate([darkest, np.sort(others)])


def check_sky(grid, index: int, views_per_kind: int, variant=None) -> dict:
    """Render the chosen views of finished sky ``index`` and compare them with its EXR."""
    spec = grid.sky(index)
    truth = read_sky_exr(BatchStore(grid).exr_path(spec.sky_id))
    scene = truth.scene
    rng = np.random.default_rng(index)
    views = chosen_views(scene, truth, views_per_kind, rng)
    flat_truth = truth.radiance.reshape(-1, truth.radiance.shape[-1])[views]
    flat_error = truth.standard_error.reshape(-1, truth.standard_error.shape[-1])[views]
    passes = scene.render.passes
    start = time.process_time()
    _, pilot_error = render_views(scene, views, PILOT_SPP, CHECK_SEEDS + 2 * index, variant)
    # the samples at which the check's error is ERROR_SHARE x the truth's, in the worst wavelength
    wanted = (pilot_error ** 2 * PILOT_SPP / np.maximum((ERROR_SHARE * flat_error) ** 2, 1e-300)).max(axis=1)
    radiance, error = np.empty_like(flat_truth), np.empty_like(flat_truth)
    counts = np.minimum(passes * 2 ** np.ceil(np.log2(np.maximum(wanted / passes, 1.0))), MAX_SPP).astype(int)
    for count in np.unique(counts):
        members = counts == count
        radiance[members], error[members] = render_views(scene, views[members], int(count),
                                                         CHECK_SEEDS + 2 * index + 1, variant)
    cpu = time.process_time() - start
    z = (flat_truth - radiance) / np.sqrt(flat_error ** 2 + error ** 2)
    dark = np.arange(views.size) < min(views_per_kind, views.size)
    return {"sky": spec.sky_id, "coordinates": spec.coordinates, "views": views.tolist(),
            "dark_views": int(dark.sum()), "check_spp": counts.tolist(), "cpu_s": cpu,
            "mean_z": float(z.mean()), "mean_z2": float((z ** 2).mean()), "max_abs_z": float(np.abs(z).max()),
            "dark_mean_z": float(z[dark].mean()) if dark.any() else math.nan,
            "dark_mean_z2": float((z[dark] ** 2).mean()) if dark.any() else math.nan,
            "relative_difference_dark": float(np.median(flat_truth[dark] / radiance[dark] - 1.0))
            if dark.any() else math.nan,
            "truth_relative_error_median": float(np.median(flat_error / flat_truth)),
            "check_relative_error_median": float(np.median(error / radiance))}


def honest_z(passes: int, error_share: float = ERROR_SHARE, draws: int = 1 << 20) -> dict:
    """What z looks like when both error bars are honest: the truth's and the check's estimates
    each the mean of ``passes`` independent normal pass values, the check's true standard error
    ``error_share`` x the truth's, each error bar the spread of its passes / sqrt(passes) (a
    view's truth from one launch; pooled over rounds it has more passes and z is closer to a
    normal). Simulated with a fixed seed: mean z^2 and the share of |z| above 3, 4 and 5."""
    rng = np.random.default_rng(0)
    truth = rng.standard_normal((draws, passes))
    check = error_share * rng.standard_normal((draws, passes))
    z = (truth.mean(axis=1) - check.mean(axis=1)) / np.sqrt(
        (truth.var(axis=1, ddof=1) + check.var(axis=1, ddof=1)) / passes)
    return {"passes": passes, "mean_z2": float(np.mean(z ** 2)),
            **{f"share_above_{k}": float(np.mean(np.abs(z) > k)) for k in (3, 4, 5)}}


def truth_sha256(store, sky_id: str) -> str:
    """The SHA-256 of a finished sky's EXR, from its marker."""
    with open(store.marker_path(sky_id)) as f:
        return json.load(f)["exr_sha256"]


def label(coordinates: dict) -> str:
    atmosphere = coordinates["atmosphere"]
    name = atmosphere["preset"] + (f" T={atmosphere['turbidity']:g}" if "turbidity" in atmosphere else " clear")
    return (f"{name}, {coordinates['observer.altitude_m'] / 1000:g} km, sun {coordinates['sun.zenith_deg']:g}")


def markdown(grid_path: str, rows: list, views_per_kind: int, wavelengths: int, honest: dict) -> str:
    values = len(rows) * 2 * views_per_kind * wavelengths
    all_z2 = np.mean([r["mean_z2"] for r in rows]) if rows else math.nan
    lines = ["# The ground truth against fixed-count renders of its views", "",
             f"Generated by `python benchmarks/truth_check.py` ({datetime.date.today()}; {machine()}"
             f"; each row on the date it gives) for finished skies of `{grid_path}`: per sky its {views_per_kind} "
             f"darkest views and {views_per_kind} drawn at random, among those brighter than {DYNAMIC_RANGE:g} x the "
             "brightest (what the LUT audit measures), each rendered again with seeds the batch never "
             f"uses: a pilot of {PILOT_SPP} samples (thrown away) sets a fixed count at which the check's standard "
             f"error is {ERROR_SHARE:g} x the truth's (at most {MAX_SPP:,}); that count's samples alone are the "
             "check. z = (truth - check) / combined standard error, per view and wavelength "
             f"({len(rows)} skies, {values:,} values; mean z^2 over them {all_z2:.2f}). A truth biased low by "
             "stopping on a heavy tail (docs/design.md) has mean z < 0 in its dark views. Each error bar is "
             f"the spread of {honest['passes']} passes, itself an estimate: honest ones give mean z^2 "
             f"{honest['mean_z2']:.2f} (not 1) and |z| above 4 in {100 * honest['share_above_4']:.3f}% of values, "
             f"above 5 in {100 * honest['share_above_5']:.4f}% (here {values * honest['share_above_4']:.0f} and "
             f"{values * honest['share_above_5']:.1f} values, fewer independent ones: a view's wavelengths share "
             "their paths), simulated with normal pass means.", "",
             "| sky | checked | check CPU (s) | check spp (median) | mean z | mean z^2 | max abs z | dark views: mean z | "
             "dark: mean z^2 | dark: truth / check - 1 (median) |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['sky']}: {label(r['coordinates'])} | {r['checked']} | {r['cpu_s']:.0f} | "
                     f"{np.median(r['check_spp']):,.0f} | "
                     f"{r['mean_z']:+.2f} | {r['mean_z2']:.2f} | {r['max_abs_z']:.1f} | {r['dark_mean_z']:+.2f} | "
                     f"{r['dark_mean_z2']:.2f} | {100 * r['relative_difference_dark']:+.2f}% |")
    return "\n".join(lines) + "\n"


def earlier_rows(settings: dict, grid, store) -> list:
    """The rows of ``results/truth_check.json`` if it was written with the same ``settings``
    (grid, views, pilot, sample cap, error share), each only while its sky's truth in ``store``
    is the one it checked (the EXR's SHA-256 in its marker) and its views are those
    :func:`chosen_views` picks now; else none."""
    path = os.path.join(RESULTS, "truth_check.json")
    if not os.path.exists(path):
        return []
    with open(path) as f:
        report = json.load(f)
    if not all(report.get(k) == v for k, v in settings.items()):
        return []
    index_of = {grid.sky_id(i): i for i in range(len(grid))}
    kept = []
    for row in report["skies"]:
        index = index_of.get(row["sky"])
        if index is None or not store.is_finished(row["sky"]):
            continue
        if row.get("truth_sha256") != truth_sha256(store, row["sky"]):
            continue                                    # rendered again since
        truth = read_sky_exr(store.exr_path(row["sky"]))
        views = chosen_views(truth.scene, truth, settings["views_per_kind"], np.random.default_rng(index))
        if views.tolist() == row["views"]:
            kept.append(row)
    return kept


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--grid", default=os.path.join(ROOT, "grids", "lut_audit.toml"))
    parser.add_argument("--skies", help="sky numbers, e.g. 0-5,21, checked even if checked before (default: "
                                        "every finished sky without a check of its present truth)")
    parser.add_argument("--views", type=int, default=8, help="dark views and random views per sky (each)")
    args = parser.parse_args()
    grid = load_grid(args.grid)
    store = BatchStore(grid)
    grid_path = os.path.relpath(args.grid, ROOT)
    settings = {"grid": grid_path, "views_per_kind": args.views, "pilot_spp": PILOT_SPP, "max_spp": MAX_SPP,
                "error_share": ERROR_SHARE}
    rows = {r["sky"]: r for r in earlier_rows(settings, grid, store)}
    if args.skies:
        indices = grid.sky_numbers(args.skies)
    else:
        indices = [i for i in range(len(grid)) if grid.sky_id(i) not in rows]
    finished = [i for i in indices if store.is_finished(grid.sky_id(i))]
    for index in finished:
        r = check_sky(grid, index, args.views)
        r["checked"] = str(datetime.date.today())
        r["truth_sha256"] = truth_sha256(store, r["sky"])
        rows[r["sky"]] = r
        print(f"{r['sky']}: mean z {r['mean_z']:+.2f}, mean z^2 {r['mean_z2']:.2f}, max |z| {r['max_abs_z']:.1f}, "
              f"dark mean z {r['dark_mean_z']:+.2f}, {r['cpu_s']:.0f} CPU s", flush=True)
    wavelengths = len(grid.validate().wavelengths_nm)
    rows = [rows[sky] for sky in sorted(rows)]
    honest = honest_z(grid.output.passes)
    report = dict(settings, honest_z=honest, skies=rows)
    print(write_results("truth_check", report, markdown(grid_path, rows, args.views, wavelengths, honest)))


if __name__ == "__main__":
    main()
