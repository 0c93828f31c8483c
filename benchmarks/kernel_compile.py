"""What compiling a sky's kernels costs, with and without AVX2 gather instructions.

Dr.Jit compiles each new configuration's kernels with LLVM on first use and caches them on disk.
On CPUs that LLVM tunes as having slow gathers (AMD Zen) it turns every vector gather (a table
lookup) into one branch per lane, and the line integral's kernels, which hold thousands of
lookups, spent most of their compile time splitting blocks. :func:`skyref._llvm.allow_vector_gathers`
lets LLVM emit gather instructions there. Here each configuration renders in a fresh process with
an empty kernel cache, once as LLVM tunes the target (``SKYREF_LLVM_FAST_GATHER=0``) and once
with gathers: the CPU of the first render (tracing, compiling, running), of a second one with
another seed (running only: the kernels are reused), and whether both settings give the same
radiance to the last bit.

Usage: ``python benchmarks/kernel_compile.py [--configs NAME ...]``; writes
``results/kernel_compile.md`` and ``results/kernel_compile.json``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(__file__))

from results_files import write_results  # noqa: E402

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


def measure(name: str, gathers: bool, scratch: str) -> dict:
    """CPU seconds of the first and second render of configuration ``name`` in a fresh process
    with an empty kernel cache, and the path of its first radiance."""
    estimator, turbidity, sun_zenith, wavelengths = CONFIGS[name]
    job = {"estimator": estimator, "turbidity": turbidity, "sun_zenith_deg": sun_zenith, "wavelengths": wavelengths}
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
    parser.add_argument("--configs", nargs="+", choices=list(CONFIGS), default=list(CONFIGS)[:2],
                        help="configurations (the line integral's take minutes each to compile as LLVM tunes them)")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for name in args.configs:
            tuned, gathered = measure(name, False, scratch), measure(name, True, scratch)
            same = bool(np.array_equal(np.load(tuned["radiance"]), np.load(gathered["radiance"]), equal_nan=True))
            row = {"config": name, "as_tuned": tuned, "with_gathers": gathered, "same_radiance": same}
            for entry in (tuned, gathered):
                entry["compile_s"] = entry["first_s"] - entry["second_s"]
                del entry["radiance"]
            row["compile_ratio"] = tuned["compile_s"] / gathered["compile_s"]
            row["run_ratio"] = tuned["second_s"] / gathered["second_s"]
            rows.append(row)
            print(f"{name}: first render {tuned['first_s']:.1f} s as tuned, {gathered['first_s']:.1f} s with gathers; "
                  f"second {tuned['second_s']:.2f} / {gathered['second_s']:.2f} s; same radiance: {same}", flush=True)
    changed = any(r["with_gathers"]["gathers"] != r["as_tuned"]["gathers"] for r in rows)
    lines = ["# What compiling a sky's kernels costs", "",
             f"Generated by `python benchmarks/kernel_compile.py` on {datetime.date.today()} ({platform.machine()}, "
             f"{platform.processor() or 'CPU'}, {os.cpu_count()} cores, llvm_ad_rgb, CPU time): bruneton2017, sun zenith "
             "60, observer 1 m, 64x32 equirectangular pixel centres, 64 samples per pixel; each render in a fresh process "
             "with an empty kernel cache. *Compile*: the first render's CPU less the second's (another seed, the kernels "
             "reused), so it counts tracing too. *As tuned*: LLVM's own choice for this CPU "
             "(`SKYREF_LLVM_FAST_GATHER=0`); *with gathers*: skyref's default (`skyref._llvm.allow_vector_gathers`).", ""]
    if not changed:
        lines += ["LLVM already emits gathers on this CPU (or it has no AVX2): both columns measure the same code.", ""]
    lines += ["| configuration | compile, as tuned (s) | compile, with gathers (s) | ratio | second render, as tuned (s) "
              "| with gathers (s) | ratio | same radiance |",
              "|---|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        lines.append(f"| {r['config']} | {r['as_tuned']['compile_s']:.1f} | {r['with_gathers']['compile_s']:.1f} | "
                     f"{r['compile_ratio']:.2f}x | {r['as_tuned']['second_s']:.2f} | {r['with_gathers']['second_s']:.2f} | "
                     f"{r['run_ratio']:.2f}x | {'bit for bit' if r['same_radiance'] else 'NO'} |")
    print(write_results("kernel_compile", {"machine": platform.machine(), "rows": rows}, "\n".join(lines) + "\n"))


if __name__ == "__main__":
    main()
