"""What compiling a sky's kernels costs: as LLVM tunes the CPU, with AVX2 gather instructions,
and with the line integral's quadrature cut into several kernels.

Dr.Jit compiles each new configuration's kernels with LLVM on first use and caches them on disk.
Two things made the line integral's kernels slow to compile on the AMD machines:

* On CPUs that LLVM tunes as having slow gathers (AMD Zen) it turns every vector gather (a table
  lookup) into one branch per lane, and the line integral's kernels, which hold thousands of
  lookups, spent most of their compile time splitting blocks. :func:`skyref._llvm.allow_vector_gathers`
  lets LLVM emit gather instructions there.
* The time to compile a kernel grows with the square of its length, and a segment's quadrature,
  unrolled panel by panel, made the longest ones. :mod:`skyref.plugins.kernels` cuts it into
  kernels of a few panels each.

Here each configuration renders in a fresh process with an empty kernel cache, three times over:
as LLVM tunes the target without cuts (``SKYREF_LLVM_FAST_GATHER=0``, ``cut_kernel`` replaced by
a no-op), with gathers without cuts, and with both (skyref's default). Each reports the CPU of
the first render (tracing, compiling, running), of a second one with another seed (running
only: the kernels are reused), and whether all three give the same radiance to the last bit.

Usage: ``python benchmarks/kernel_compile.py [--configs NAME ...]``; writes
``results/kernel_compile.md`` and ``results/kernel_compile.json``.
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

#: name: (estimator, turbidity or None for the clear sky, sun zenith deg, wavelengths)
CONFIGS = {
    "clear RGB, line integral": ("line_integral", None, 60.0, "rgb"),
    "clear RGB, delta tracking": ("delta_tracking", None, 60.0, "rgb"),
    "hazy RGB, line integral": ("line_integral", 6.0, 60.0, "rgb"),
    "clear 17 wavelengths, line integral": ("line_integral", None, 60.0,
                                            {"start_nm": 380.0, "stop_nm": 780.0, "step_nm": 25.0}),
}

#: Run in a fresh interpreter: renders a 64x32 sky at pixel centres twice (seeds 1 and 2) and
#: prints the CPU seconds of each, LLVM's target features and the first render's radiance (.npy).
MEASURE = """
import json, sys, time
import numpy as np
import skyref.atmosphere as atm
from skyref._llvm import llvm_target_features
from skyref.plugins import load_mitsuba
from skyref.render import render_sky
from skyref.scene import Camera, Observer, RenderSettings, Scene, Sun
load_mitsuba("llvm_ad_rgb")
job = json.loads(sys.argv[1])
if not job["cuts"]:
    import skyref.plugins.integrator, skyref.plugins.line_integral
    skyref.plugins.integrator.cut_kernel = skyref.plugins.line_integral.cut_kernel = lambda *state: None
atmosphere = atm.bruneton2017() if job["turbidity"] is None else atm.from_turbidity(job["turbidity"])
scene = Scene(atmosphere=atmosphere, sun=Sun(job["sun_zenith_deg"], 180.0), observer=Observer(1.0),
              camera=Camera(width=64, height=32), wavelengths=job["wavelengths"],
              render=RenderSettings(spp=64, passes=16, pixel_sampling="centre"), name="kernel-compile")
seconds = []
for seed in (1, 2):
    start = time.process_time()
    sky = render_sky(scene, seed=seed, estimator=job["estimator"], symmetry=False)
    seconds.append(time.process_time() - start)
    if seed == 1:
        np.save(sys.argv[2], sky.radiance)
print(json.dumps({"seconds": seconds, "gathers": "+fast-gather" in llvm_target_features()}))
"""


#: (key, LLVM emits gathers, the quadrature cut into kernels), as compared
SETTINGS = (("as_tuned", False, False), ("with_gathers", True, False), ("with_gathers_and_cuts", True, True))


def measure(name: str, gathers: bool, cuts: bool, scratch: str) -> dict:
    """CPU seconds of the first and second render of configuration ``name`` in a fresh process
    with an empty kernel cache, and the path of its first radiance."""
    estimator, turbidity, sun_zenith, wavelengths = CONFIGS[name]
    job = {"estimator": estimator, "turbidity": turbidity, "sun_zenith_deg": sun_zenith, "wavelengths": wavelengths,
           "cuts": cuts}
    cache = tempfile.mkdtemp(dir=scratch)
    radiance = os.path.join(cache, "radiance.npy")
    environment = dict(os.environ, DRJIT_CACHE_DIR=cache, SKYREF_LLVM_FAST_GATHER="1" if gathers else "0")
    done = subprocess.run([sys.executable, "-c", MEASURE, json.dumps(job), radiance], capture_output=True, text=True,
                          cwd=ROOT, env=environment, check=True)
    result = json.loads(done.stdout.strip().splitlines()[-1])
    return {"first_s": result["seconds"][0], "second_s": result["seconds"][1], "gathers": result["gathers"],
            "radiance": radiance}


def main():
    import numpy as np

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--configs", nargs="+", choices=list(CONFIGS), default=list(CONFIGS)[:3],
                        help="configurations (the line integral's take minutes each to compile as LLVM tunes them)")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for name in args.configs:
            row = {"config": name}
            for key, gathers, cuts in SETTINGS:
                row[key] = measure(name, gathers, cuts, scratch)
                row[key]["compile_s"] = row[key]["first_s"] - row[key]["second_s"]
            radiances = [np.load(row[key].pop("radiance")) for key, _, _ in SETTINGS]
            row["same_radiance"] = all(np.array_equal(radiances[0], r, equal_nan=True) for r in radiances[1:])
            for key, _, _ in SETTINGS[1:]:
                row[key]["compile_ratio"] = row["as_tuned"]["compile_s"] / row[key]["compile_s"]
                row[key]["run_ratio"] = row["as_tuned"]["second_s"] / row[key]["second_s"]
            rows.append(row)
            print(f"{name}: first render " + ", ".join(f"{row[key]['first_s']:.1f} s {key}" for key, _, _ in SETTINGS)
                  + f"; same radiance: {row['same_radiance']}", flush=True)
    changed = any(r["with_gathers"]["gathers"] != r["as_tuned"]["gathers"] for r in rows)
    lines = ["# What compiling a sky's kernels costs", "",
             f"Generated by `python benchmarks/kernel_compile.py` on {datetime.date.today()} ({machine()}"
             f", llvm_ad_rgb, CPU time): sun zenith "
             "60, observer 1 m, 64x32 equirectangular pixel centres, 64 samples per pixel; each render in a fresh process "
             "with an empty kernel cache. *Compile*: the first render's CPU less the second's (another seed, the kernels "
             "reused), so it counts tracing too. *As tuned*: LLVM's own choice for this CPU "
             "(`SKYREF_LLVM_FAST_GATHER=0`), the quadrature whole; *gathers*: `skyref._llvm.allow_vector_gathers`; "
             "*cuts*: the quadrature cut into kernels of a few panels (`skyref.plugins.kernels`). Gathers and cuts "
             "are skyref's default. Ratios are against *as tuned*.", ""]
    if not changed:
        lines += ["LLVM already emits gathers on this CPU (or it has no AVX2): the first two columns measure the same "
                  "code.", ""]
    lines += ["| configuration | compile, as tuned (s) | with gathers (s) | with gathers and cuts (s) | ratio "
              "| second render, as tuned (s) | with gathers and cuts (s) | ratio | same radiance |",
              "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        best = r["with_gathers_and_cuts"]
        lines.append(f"| {r['config']} | {r['as_tuned']['compile_s']:.1f} | {r['with_gathers']['compile_s']:.1f} | "
                     f"{best['compile_s']:.1f} | {best['compile_ratio']:.2f}x | {r['as_tuned']['second_s']:.2f} | "
                     f"{best['second_s']:.2f} | {best['run_ratio']:.2f}x | "
                     f"{'bit for bit' if r['same_radiance'] else 'NO'} |")
    print(write_results("kernel_compile", {"machine": machine(), "rows": rows}, "\n".join(lines) + "\n"))


if __name__ == "__main__":
    main()
