"""Time to 1% relative RMS error of the ground truth, per estimator, measured in one run.

Skies (bruneton2017 unless said, observer 1 m above the ground, 128x64 equirectangular):
clear (sun zenith 60), hazy (turbidity 6, sun 60), sunset (sun 88), twilight (sun 96).
Wavelength grids: RGB (680/550/440 nm), 17 wavelengths (380-780 nm / 25 nm), 48 (360-830 / 10).

Estimators: the ``atmosphere`` integrator's ``delta_tracking`` (the baseline) and
``line_integral`` (experimental), and stock Mitsuba ``volpath`` + skyref's ``atmosphere_medium``
(RGB only: in spectral variants volpath samples continuous wavelengths into film bands, another
estimand). Each renders 16 independent batches; the error of a render is the relative RMS of its
per-pixel standard errors over the sky pixels (view zenith < 88 deg, more than 3 deg from the
sun: stock ``directional`` is a delta light without a disk) and the wavelengths. Time to 1% =
CPU time x (error / 1%)^2 (the Monte Carlo rate); CPU time is steadier than wall time on a
shared machine, and kernels are compiled before the timed render.

This measures noise, not bias. The line-integral estimator's agreement with the baseline is
reported beside it: the mean squared z-score of their difference over the same pixels and
wavelengths (about 1.15 when both are unbiased: 16 batches each) and the fraction of |z| > 4.

Usage: ``python benchmarks/groundtruth_speed.py [--quick]``; writes
``results/groundtruth_speed.md`` and ``results/groundtruth_speed.json``
(``{"skies": {name: {"speedup_vs_baseline": x, ...}}}``, x for the RGB grid).
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from skyref.plugins import load_mitsuba  # noqa: E402

mi = load_mitsuba("llvm_ad_rgb")

import skyref.atmosphere as atm  # noqa: E402
from skyref.io.atomic import atomic_write  # noqa: E402
from skyref.io.json_numpy import numpy_default  # noqa: E402
from skyref.plugins.volpath_scene import stock_volpath_scene  # noqa: E402
from skyref.render import render_sky, sensor_dict  # noqa: E402
from skyref.scene import Camera, Observer, RenderSettings, Scene, Sun  # noqa: E402

TARGET = 0.01
BATCHES = 16
RESULTS = os.path.join(os.path.dirname(__file__), "..", "results")

SKIES = {"clear": (None, 60.0), "hazy": (6.0, 60.0), "sunset": (None, 88.0), "twilight": (None, 96.0)}
GRIDS = {"rgb": "rgb", "17 wavelengths": {"start_nm": 380.0, "stop_nm": 780.0, "step_nm": 25.0},
         "48 wavelengths": {"start_nm": 360.0, "stop_nm": 830.0, "step_nm": 10.0}}
#: samples per pixel and batch: (delta tracking, line integral, volpath) per grid
SPP = {"rgb": (16, 4, 4), "17 wavelengths": (8, 2, 0), "48 wavelengths": (4, 1, 0)}


def scene_for(sky, grid):
    turbidity, sun_zenith = SKIES[sky]
    atmosphere = atm.bruneton2017() if turbidity is None else atm.from_turbidity(turbidity)
    return Scene(atmosphere=atmosphere, sun=Sun(sun_zenith, 180.0), observer=Observer(1.0),
                 camera=Camera(width=128, height=64), wavelengths=GRIDS[grid],
                 render=RenderSettings(spp=BATCHES, passes=BATCHES), name=f"groundtruth-speed-{sky}")


def sky_mask(scene, directions):
    cos_sun = directions @ scene.sun.direction
    return (directions[..., 2] > math.cos(math.radians(88.0))) & (cos_sun < math.cos(math.radians(3.0)))


def relative_rms(standard_error, radiance, mask):
    """Relative RMS of the standard errors over the masked, lit pixels and all wavelengths."""
    se, value = standard_error[mask], radiance[mask]
    lit = value > 0.0
    return math.sqrt(float(np.mean((se[lit] / value[lit]) ** 2)))


def time_integrator(scene, spp, estimator, scale):
    # compile first, with the timed render's own launch size (a smaller warm-up was seen to leave
    # a compile inside the timed render of the line-integral estimator)
    render_sky(scene, spp=BATCHES * spp * scale, passes=BATCHES, seed=2, estimator=estimator)
    start = time.process_time()
    sky = render_sky(scene, spp=BATCHES * spp * scale, passes=BATCHES, seed=1, estimator=estimator)
    return time.process_time() - start, sky


def time_volpath(scene, spp, scale, mask):
    description = stock_volpath_scene(scene.atmosphere, scene.sun.zenith_deg, scene.sun.azimuth_deg,
                                      scene.observer.altitude_m, sensor_dict(scene.camera),
                                      max_depth=scene.render.max_depth)
    volpath = mi.load_dict(description)
    mi.render(volpath, spp=2, seed=99).numpy()                   # compile first
    start = time.process_time()
    batches = np.stack([mi.render(volpath, spp=spp * scale, seed=1 + b).numpy()[..., :3] for b in range(BATCHES)])
    seconds = time.process_time() - start
    radiance = batches.mean(axis=0)
    return seconds, relative_rms(batches.std(axis=0, ddof=1) / math.sqrt(BATCHES), radiance, mask)


def consistency(a, b, mask):
    """Mean squared z-score of two skies' difference over the masked pixels and wavelengths
    (about 1.15 for unbiased estimators with 16 batches each: Student's t, 15 degrees of
    freedom), and the fraction of |z| > 4."""
    noise = np.sqrt(a.standard_error ** 2 + b.standard_error ** 2)[mask]
    measured = noise > 0.0
    z = (a.radiance - b.radiance)[mask][measured] / noise[measured]
    return float(np.mean(z ** 2)), float(np.mean(np.abs(z) > 4.0))


def to_target(seconds, error):
    return seconds * (error / TARGET) ** 2


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer samples (a smoke run, noisy numbers)")
    args = parser.parse_args()
    scale = 1 if args.quick else 4

    rows, summary = [], {}
    for sky in SKIES:
        summary[sky] = {}
        for grid in GRIDS:
            scene = scene_for(sky, grid)
            spp_dt, spp_li, spp_vp = SPP[grid]
            print(f"{sky}, {grid} ...", flush=True)
            t_dt, baseline = time_integrator(scene, spp_dt, "delta_tracking", scale)
            mask = sky_mask(scene, baseline.directions)
            e_dt = relative_rms(baseline.standard_error, baseline.radiance, mask)
            t_li, line = time_integrator(scene, spp_li, "line_integral", scale)
            e_li = relative_rms(line.standard_error, line.radiance, mask)
            pixels = mask.size
            entry = {"baseline_cpu_s_to_1pct": to_target(t_dt, e_dt),
                     "line_integral_cpu_s_to_1pct": to_target(t_li, e_li),
                     "speedup_vs_baseline": to_target(t_dt, e_dt) / to_target(t_li, e_li),
                     "line_integral_vs_baseline_mean_z2": consistency(line, baseline, mask)[0],
                     "line_integral_vs_baseline_fraction_z_over_4": consistency(line, baseline, mask)[1],
                     "baseline_cpu_us_per_channel_sample": 1e6 * t_dt / (pixels * BATCHES * spp_dt * scale
                                                                         * len(scene.wavelengths_nm)),
                     "line_integral_cpu_us_per_channel_sample": 1e6 * t_li / (pixels * BATCHES * spp_li * scale
                                                                              * len(scene.wavelengths_nm))}
            rows.append((sky, grid, "atmosphere, delta_tracking (baseline)", pixels * BATCHES * spp_dt * scale,
                         t_dt, e_dt, ""))
            rows.append((sky, grid, "atmosphere, line_integral", pixels * BATCHES * spp_li * scale, t_li, e_li,
                         f"{entry['line_integral_vs_baseline_mean_z2']:.2f} / "
                         f"{100 * entry['line_integral_vs_baseline_fraction_z_over_4']:.2f}%"))
            if spp_vp:
                t_vp, e_vp = time_volpath(scene, spp_vp, scale, mask)
                entry["volpath_cpu_s_to_1pct"] = to_target(t_vp, e_vp)
                entry["speedup_baseline_vs_volpath"] = to_target(t_vp, e_vp) / to_target(t_dt, e_dt)
                rows.append((sky, grid, "stock volpath + atmosphere_medium", pixels * BATCHES * spp_vp * scale,
                             t_vp, e_vp, ""))
            summary[sky][grid] = entry

    lines = [
        "# Ground truth speed: CPU time to 1% relative RMS error",
        "",
        f"Generated by `python benchmarks/groundtruth_speed.py{' --quick' if args.quick else ''}` on "
        f"{datetime.date.today().isoformat()} ({platform.machine()}, {os.cpu_count()} cores, variant llvm_ad_rgb).",
        "",
        "128x64 equirectangular, observer 1 m; 16 independent batches per render. Error: relative RMS of the",
        "per-pixel standard errors over sky pixels (view zenith < 88 deg, > 3 deg from the sun) and wavelengths;",
        "time to 1% = CPU time x (error / 1%)^2. 'vs baseline': mean z^2 of the line-integral estimator's difference",
        "from the baseline (about 1.15 if both are unbiased) / fraction of |z| > 4 (pixels x wavelengths).",
        "",
        "| sky | wavelengths | estimator | samples | CPU (s) | rel. RMS error | CPU s to 1% | vs baseline |",
        "|---|---|---|---:|---:|---:|---:|---:|",
    ]
    for sky, grid, name, samples, seconds, error, systematic in rows:
        lines.append(f"| {sky} | {grid} | {name} | {samples:,} | {seconds:.2f} | {100 * error:.2f}% | "
                     f"{to_target(seconds, error):,.1f} | {systematic} |")
    lines += ["", "Speed-up of the line-integral estimator over the baseline at equal error (CPU time to 1%), and",
              "the per-channel cost of one sample (CPU µs):", "",
              "| sky | wavelengths | speed-up vs baseline | baseline µs/channel/sample | line integral µs/channel/sample |",
              "|---|---|---:|---:|---:|"]
    for sky, grids in summary.items():
        for grid, entry in grids.items():
            lines.append(f"| {sky} | {grid} | {entry['speedup_vs_baseline']:.2f}x | "
                         f"{entry['baseline_cpu_us_per_channel_sample']:.3f} | "
                         f"{entry['line_integral_cpu_us_per_channel_sample']:.3f} |")
    lines.append("")
    os.makedirs(RESULTS, exist_ok=True)
    with atomic_write(os.path.join(RESULTS, "groundtruth_speed.md")) as f:
        f.write("\n".join(lines))
    report = {"generated": datetime.date.today().isoformat(), "quick": args.quick,
              "skies": {sky: {"speedup_vs_baseline": grids["rgb"]["speedup_vs_baseline"], "grids": grids}
                        for sky, grids in summary.items()}}
    with atomic_write(os.path.join(RESULTS, "groundtruth_speed.json")) as f:
        json.dump(report, f, indent=2, default=numpy_default)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
