"""What polarization does to the clear sky's radiance, and what it costs: skyref's polarized I
against its scalar radiance on the ground-truth benchmark's skies, measured in one run.

Skies as in ``benchmarks/groundtruth_speed.py`` (bruneton2017; clear, hazy, sunset, twilight;
observer 1 m above the ground, 128x64 equirectangular, pixel centres), at 440 nm (the bluest
RGB channel, where Rayleigh scattering and so polarization matter most) and RGB. Per sky: the
relative difference scalar / polarized I - 1 per pixel (its map as a figure), summarized by
view zenith and by angle from the sun (from the line-integral estimator, the faster; the two
modes trace the same paths, :func:`skyref.render.render_paired`, and the difference's standard
error is the spread of the batches' paired differences); the
polarized degree of linear polarization; and, per estimator, the CPU time to 1% relative RMS
error of I (time x (error / 1%)^2) of the polarized mode against the scalar one.

Usage: ``python benchmarks/polarization.py [--spp N]``; writes ``results/polarization.md``,
``results/polarization.json`` and ``results/polarization.png``.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from groundtruth_speed import BATCHES, SKIES, relative_rms, scene_for, sky_mask  # noqa: E402

from results_files import RESULTS, machine, write_results  # noqa: E402

from skyref.io.atomic import atomic_path  # noqa: E402
from skyref.render import render_paired, render_sky  # noqa: E402

ZENITH_BANDS = ((0.0, 30.0), (30.0, 60.0), (60.0, 80.0), (80.0, 88.0))
SUN_BANDS = ((3.0, 30.0), (30.0, 70.0), (70.0, 110.0), (110.0, 180.0))


ESTIMATORS = ("line_integral", "delta_tracking")


def warm_up(scene, polarized, estimator):
    """Compile the kernels a timed render launches: one sample per batch (they do not depend on
    the launch size, tests/test_integrator_plugin.py)."""
    render_sky(scene, spp=BATCHES, passes=BATCHES, seed=2, polarized=polarized, estimator=estimator, symmetry=False)


def seconds_to_1pct(sky, seconds, mask):
    """CPU seconds to 1% relative RMS error of I over ``mask``: ``seconds`` x (error / 1%)^2."""
    return seconds * (relative_rms(sky.standard_error, sky.radiance, mask) / 0.01) ** 2


def cost(scene, spp, estimator, mask=None):
    """(scalar sky, polarized sky, CPU seconds to 1% of each) with ``estimator``, the two modes
    rendered apart with other seeds than the warm-up's; every pixel traced (symmetry=False): this
    measures the estimators' cost per direction."""
    skies, to_1 = {}, {}
    for mode in ("scalar", "polarized"):
        warm_up(scene, mode == "polarized", estimator)
        start = time.process_time()
        sky = render_sky(scene, spp=BATCHES * spp, passes=BATCHES, seed=3, polarized=mode == "polarized",
                         estimator=estimator, symmetry=False)
        seconds = time.process_time() - start
        mask = sky_mask(scene, sky.directions) if mask is None else mask
        skies[mode], to_1[mode] = sky, seconds_to_1pct(sky, seconds, mask)
    return skies["scalar"], skies["polarized"], to_1


def paired(scene, spp):
    """The line integral's (scalar sky, polarized sky, standard error of their difference, CPU
    seconds to 1% of each), the two modes tracing the same paths."""
    for polarized in (False, True):
        warm_up(scene, polarized, "line_integral")
    settings = dataclasses.replace(scene.render, passes=BATCHES, estimator="line_integral")
    scalar, polarized, difference_error = render_paired(
        scene.replace(render=settings), scene.replace(render=dataclasses.replace(settings, polarized=True)),
        BATCHES * spp, seed=3)
    mask = sky_mask(scene, scalar.directions)
    to_1 = {mode: seconds_to_1pct(sky, sky.metadata["render_cpu_s"], mask)
            for mode, sky in (("scalar", scalar), ("polarized", polarized))}
    return scalar, polarized, difference_error, to_1


def compare(sky_name, spp):
    scene = scene_for(sky_name, "rgb")
    scalar, polarized, difference_error, to_1 = paired(scene, spp)
    costs = {"line_integral": to_1, "delta_tracking": cost(scene, max(16, spp // 8), "delta_tracking")[2]}
    mask = sky_mask(scene, scalar.directions)
    blue = 2                                                       # 440 nm
    i_pol, i_scalar = polarized.radiance[..., blue], scalar.radiance[..., blue]
    # scalar / polarized - 1 = (I_s - I_p) / I_p: its noise is the paired difference's, relative
    se = np.where(mask, difference_error[..., blue] / i_pol, np.nan)
    difference = np.where(mask, i_scalar / i_pol - 1.0, np.nan)
    zenith = np.degrees(np.arccos(np.clip(scalar.directions[..., 2], -1, 1)))
    from_sun = np.degrees(np.arccos(np.clip(scalar.directions @ scene.sun.direction, -1, 1)))

    def band(values, lo, hi):
        inside = mask & (values >= lo) & (values < hi)
        return {"range_deg": [lo, hi], "pixels": int(inside.sum()),
                "mean_rel_diff": float(np.nanmean(difference[inside])) if inside.any() else None,
                "max_abs_rel_diff": float(np.nanmax(np.abs(difference[inside]))) if inside.any() else None}

    dolp = polarized.degree_of_linear_polarization()[..., blue]
    return {"sun_zenith_deg": SKIES[sky_name][1], "turbidity": SKIES[sky_name][0],
            # noise-corrected: the mean square of the difference less that of its noise
            "rms_rel_diff_440nm": float(np.sqrt(max(0.0, np.nanmean(difference ** 2) - np.nanmean(se ** 2)))),
            "median_rel_se_440nm": float(np.nanmedian(se)),
            "by_view_zenith": [band(zenith, lo, hi) for lo, hi in ZENITH_BANDS],
            "by_angle_from_sun": [band(from_sun, lo, hi) for lo, hi in SUN_BANDS],
            "max_dolp_440nm": float(np.nanmax(np.where(mask, dolp, np.nan))),
            "cpu_seconds_to_1pct": costs,
            "polarized_cost_ratio": {name: c["polarized"] / c["scalar"] for name, c in costs.items()},
            "map": difference}


def figure(report, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(report["skies"])
    fig, axes = plt.subplots(len(names), 1, figsize=(7, 2.4 * len(names)), constrained_layout=True)
    for ax, name in zip(np.atleast_1d(axes), names):
        image = ax.imshow(100.0 * report["skies"][name]["map"], cmap="RdBu_r", vmin=-10, vmax=10, aspect="auto")
        ax.set_title(f"{name}: scalar / polarized I - 1 at 440 nm (ground and sun masked)")
        ax.set_ylabel("pixel row")
        fig.colorbar(image, ax=ax, label="%")
    np.atleast_1d(axes)[-1].set_xlabel("pixel column (the benchmark's 128x64 equirectangular camera)")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)


def markdown(report):
    lines = ["# Polarization: what scalar transport gets wrong, and what polarized transport costs", "",
             f"Produced {report['date']} by `python benchmarks/polarization.py {report['arguments']}` on "
             f"{report['machine']} (llvm_ad_rgb, 2 cores shared). Skies of `benchmarks/groundtruth_speed.py`, "
             "16 batches, pixel centres; differences from the line-integral estimator at 440 nm over the sky (view "
             "zenith < 88 deg, > 3 deg from the sun; columns: mean by view zenith), both modes tracing the same "
             "paths (the RMS noise-corrected, the s.e. that of the batches' paired differences). Cost: CPU time "
             "to 1% relative RMS error of I, polarized / scalar, per estimator (the same run). Map: "
             "`polarization.png`.", "",
             "| sky | RMS scalar/polarized - 1 | median s.e. | zenith 0-30 | 30-60 | 60-80 | 80-88 | max DoLP "
             "| cost, line integral | cost, delta tracking |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in report["skies"].items():
        bands = " | ".join(f"{b['mean_rel_diff'] * 100:+.2f}%" for b in r["by_view_zenith"])
        lines.append(f"| {name} | {r['rms_rel_diff_440nm'] * 100:.2f}% | {r['median_rel_se_440nm'] * 100:.2f}% | "
                     f"{bands} | {r['max_dolp_440nm']:.2f} | {r['polarized_cost_ratio']['line_integral']:.2f}x | "
                     f"{r['polarized_cost_ratio']['delta_tracking']:.2f}x |")
    lines += ["", "By angle from the sun (mean scalar / polarized I - 1 at 440 nm):", "",
              "| sky | 3-30 deg | 30-70 | 70-110 | 110-180 |", "|---|---:|---:|---:|---:|"]
    for name, r in report["skies"].items():
        lines.append(f"| {name} | " + " | ".join(f"{b['mean_rel_diff'] * 100:+.2f}%" for b in r["by_angle_from_sun"])
                     + " |")
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp", type=int, default=256, help="samples per pixel and batch")
    args = parser.parse_args()
    report = {"date": datetime.datetime.now().isoformat(timespec="minutes"),
              "machine": machine(), "arguments": " ".join(sys.argv[1:]),
              "skies": {name: compare(name, args.spp) for name in SKIES}}
    os.makedirs(RESULTS, exist_ok=True)
    figure(report, os.path.join(RESULTS, "polarization.png"))
    for r in report["skies"].values():
        del r["map"]
    write_results("polarization", report, markdown(report))
    print(markdown(report))


if __name__ == "__main__":
    main()
