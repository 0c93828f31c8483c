"""What a wavelength costs: CPU per sample at 3 and 48 wavelengths, per estimator, against the
code of the day issue 14 was filed, measured in one run.

Issue 14 found that 48 wavelengths cost 12.3x per sample against 3 (0.36-0.39 CPU µs per channel
per sample): the spectral slowdown is per-channel state and arithmetic, not variance, and asked
for that cost to be at least halved. Here each estimator renders the same skies (bruneton2017,
observer 1 m, 64x32 equirectangular, pixel centres as the consumers of the ground truth trace
them; sun zenith 60 clear, by default, and at turbidity 6, and 88) at RGB
(680/550/440 nm) and 48 wavelengths (360-830 nm / 10 nm): this checkout's line integral and delta
tracking (the baseline), and the delta tracking of ``REFERENCE`` (the last commit before the
issue's work, run from a git worktree of it). Each render is timed after one that compiles its
kernels, as the difference between 2N and N samples per pixel; every pixel is traced (no
symmetric views shared). Reported per sample: CPU µs in all,
per channel at 48 wavelengths, and the *marginal* cost of a channel, (cost at 48 - cost at 3) / 45,
which is what a spectral render pays beyond an RGB one.

Usage: ``python benchmarks/channel_cost.py [--reference REV] [--spp N]``; writes
``results/channel_cost.md`` and ``results/channel_cost.json``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(__file__))

from results_files import machine, write_results  # noqa: E402

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

#: The code when issue 14 was filed (2026-11-22): delta tracking, the only estimator then.
REFERENCE = "6c47c82"

SKIES = {"clear": (None, 60.0), "hazy": (6.0, 60.0), "sunset": (None, 88.0)}
GRIDS = {3: "rgb", 48: {"start_nm": 360.0, "stop_nm": 830.0, "step_nm": 10.0}}

#: Run in a fresh interpreter with the checkout under test first on sys.path: uses only what
#: both checkouts have (Scene, render_sky's spp/passes/seed; ``estimator`` and ``symmetry`` only
#: where given). Prints CPU seconds per sample: the difference between renders of 2N and N samples
#: per pixel over N, so what a render pays once (tracing the kernels, the line integral's guide,
#: a launch) drops out; both counts are rendered once before (the reference checkout's kernels
#: depend on the count).
MEASURE = """
import json, sys, time
sys.path.insert(0, sys.argv[1])
import skyref.atmosphere as atm
from skyref.render import render_sky
from skyref.scene import Camera, Observer, RenderSettings, Scene, Sun
job = json.loads(sys.argv[2])
atmosphere = atm.bruneton2017() if job["turbidity"] is None else atm.from_turbidity(job["turbidity"])
scene = Scene(atmosphere=atmosphere, sun=Sun(job["sun_zenith_deg"], 180.0), observer=Observer(1.0),
              camera=Camera(width=64, height=32), wavelengths=job["wavelengths"],
              render=RenderSettings(spp=16, passes=16, pixel_sampling="centre"), name="channel-cost")
options, spp = job["options"], job["spp"]
seconds = {}
for timed in (False, True):              # first compile the kernels of both counts, then time them
    for count in (spp, 2 * spp):
        start = time.process_time()
        render_sky(scene, spp=count, passes=16, seed=1, **options)
        seconds[count] = time.process_time() - start
print(json.dumps((seconds[2 * spp] - seconds[spp]) / (64 * 32 * spp)))
"""


def measure(checkout: str, sky: str, channels: int, spp: int, options: dict) -> float:
    """CPU µs per sample of one estimator of ``checkout`` on ``sky`` at ``channels`` wavelengths."""
    turbidity, sun_zenith = SKIES[sky]
    job = {"turbidity": turbidity, "sun_zenith_deg": sun_zenith, "wavelengths": GRIDS[channels], "spp": spp,
           "options": options}
    done = subprocess.run([sys.executable, "-c", MEASURE, checkout, json.dumps(job)], capture_output=True,
                          text=True, cwd=checkout, check=True)
    return 1e6 * float(done.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--reference", default=REFERENCE, help="git revision of the reference checkout")
    parser.add_argument("--spp", type=int, default=256, help="N: the timed renders take N and 2N samples per pixel")
    parser.add_argument("--skies", nargs="+", choices=list(SKIES), default=["clear"],
                        help="skies to measure (the line integral's kernels for a new sky and wavelength grid "
                             "compile in minutes: 7 and 18 min of CPU for the clear sky at 3 and 48 wavelengths, "
                             "2026-12-05)")
    args = parser.parse_args()
    estimators = {"line integral": (ROOT, {"estimator": "line_integral", "symmetry": False}),
                  "delta tracking (baseline)": (ROOT, {"estimator": "delta_tracking", "symmetry": False})}
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        reference = os.path.join(scratch, "reference")
        subprocess.run(["git", "-C", ROOT, "worktree", "add", "--detach", reference, args.reference],
                       check=True, capture_output=True)
        try:
            estimators[f"delta tracking at {args.reference} (issue filed)"] = (reference, {})
            for sky in args.skies:
                for name, (checkout, options) in estimators.items():
                    cost = {channels: measure(checkout, sky, channels, args.spp, options) for channels in GRIDS}
                    rows.append({"sky": sky, "estimator": name, "us_per_sample": cost,
                                 "us_per_channel_at_48": cost[48] / 48,
                                 "marginal_us_per_channel": (cost[48] - cost[3]) / 45,
                                 "ratio_48_to_3": cost[48] / cost[3]})
                    print(f"{sky}, {name}: {cost[3]:.2f} / {cost[48]:.2f} µs per sample at 3 / 48 wavelengths",
                          flush=True)
        finally:
            subprocess.run(["git", "-C", ROOT, "worktree", "remove", "--force", reference], capture_output=True)
    reference_name = f"delta tracking at {args.reference} (issue filed)"
    for row in rows:
        filed = next(r for r in rows if r["sky"] == row["sky"] and r["estimator"] == reference_name)
        row["marginal_vs_filed"] = filed["marginal_us_per_channel"] / row["marginal_us_per_channel"]
    lines = ["# What a wavelength costs", "",
             f"Generated by `python benchmarks/channel_cost.py` on {datetime.date.today()} ({machine()}"
             f", CPU time, llvm_ad_rgb): bruneton2017, observer 1 m, 64x32 equirectangular pixel centres, "
             f"the CPU of {2 * args.spp} samples per pixel less that of {args.spp} (16 batches each), every pixel "
             "traced, kernels compiled before. Marginal cost: (µs per sample at 48 wavelengths - at 3) / 45, what each channel of a spectral "
             "render adds; `filed / this`: how many times less than the code of the day issue 14 was filed pays.", "",
             "| sky | estimator | µs per sample, 3 wavelengths | 48 wavelengths | 48 / 3 | µs per channel at 48 | "
             "marginal µs per channel | filed / this (marginal) |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['sky']} | {r['estimator']} | {r['us_per_sample'][3]:.2f} | {r['us_per_sample'][48]:.2f} | "
                     f"{r['ratio_48_to_3']:.1f} | {r['us_per_channel_at_48']:.3f} | "
                     f"{r['marginal_us_per_channel']:.3f} | {r['marginal_vs_filed']:.2f}x |")
    print(write_results("channel_cost", {"reference": args.reference, "spp": args.spp, "rows": rows},
                        "\n".join(lines) + "\n"))


if __name__ == "__main__":
    main()
