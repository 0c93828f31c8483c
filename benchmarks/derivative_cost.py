"""What a forward-mode derivative render costs, with the tangents of a launch's outputs evaluated
together (skyref's :func:`skyref.plugins.kernels.sum_blocks`) and one by one (as before it).

A launch of the ``atmosphere`` integrator sums each direction's samples per scattering order
and wavelength. Summed with Dr.Jit's own ``block_sum``, whose derivative evaluates its input,
each of the 4 orders x N wavelengths evaluated its own tangent in forward-mode AD: one compile
and one run of the whole differentiated path tracer per output. ``sum_blocks`` evaluates them in
one kernel.

Each configuration runs in a fresh process with an empty kernel cache, twice over: with
``sum_blocks``'s sums called directly instead of as a custom operation (so Dr.Jit differentiates
each on its own, as the integrator summed until 2026-12-06), and as skyref runs. Each process renders the directions once (compiling the plain
kernels), then takes the derivative with respect to one parameter twice (seeds 1 and 2): the
first pays the tangent kernels' compile, the second only their run. Reported: CPU seconds of
the plain render and of both derivative renders, and whether both settings give the same values
and derivatives to the last bit.

Usage: ``python benchmarks/derivative_cost.py``; writes ``results/derivative_cost.md`` and
``results/derivative_cost.json``.
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

#: name: (estimator, wavelengths nm, view directions, samples per direction, parameter)
CONFIGS = {
    "line integral, RGB, 4 views (the CI gradient test's)":
        ("line_integral", [680.0, 550.0, 440.0], "test views", 256, "aerosol.g"),
    "delta tracking, 8 wavelengths, 400 views (skyref invert's)":
        ("delta_tracking", [400.0 + 40.0 * k for k in range(8)], "400 random", 256, "aerosol.g"),
}

#: Run in a fresh interpreter: prints the CPU seconds of a plain render and of two derivative
#: renders, and saves the first derivative render's values and derivatives (.npz).
MEASURE = """
import json, sys, time
import numpy as np
from skyref.atmosphere import preset
from skyref.plugins import load_mitsuba
mi = load_mitsuba("llvm_ad_rgb")
from skyref.render import build_integrator
from skyref.scene import Observer, RenderSettings, Scene, Sun, direction_from_angles
job = json.loads(sys.argv[1])
if not job["together"]:
    # The same sums called directly, not as a custom operation: Dr.Jit differentiates each
    # block sum on its own, as the integrator summed until 2026-12-06.
    import skyref.plugins.integrator
    from skyref.plugins.kernels import _BlockSums
    skyref.plugins.integrator.sum_blocks = lambda *args: _BlockSums().eval(*args)
if job["views"] == "test views":
    angles = [(0.0, 0.0), (40.0, 180.0), (85.0, 0.0), (120.0, 0.0)]
else:
    rng = np.random.default_rng(1)
    angles = list(zip(rng.uniform(0.0, 85.0, 400), rng.uniform(0.0, 360.0, 400)))
directions = np.array([direction_from_angles(z, a) for z, a in angles])
scene = Scene(atmosphere=preset("bruneton2017"), sun=Sun(30.0, 180.0), observer=Observer(1000.0),
              wavelengths=job["wavelengths"], render=RenderSettings(estimator=job["estimator"]))
integrator = build_integrator(scene)
start = time.process_time()
integrator.render_directions(directions, 1, job["spp"]).numpy()
seconds = [time.process_time() - start]
for seed in (1, 2):
    start = time.process_time()
    value, derivative = integrator.directional_derivative(directions, job["parameter"], seed, job["spp"])
    seconds.append(time.process_time() - start)
    if seed == 1:
        np.savez(sys.argv[2], value=value, derivative=derivative)
print(json.dumps({"seconds": seconds}))
"""

#: (key, tangents evaluated together), as compared
SETTINGS = (("per_output", False), ("together", True))


def measure(name: str, together: bool, scratch: str) -> dict:
    """CPU seconds of configuration ``name`` in a fresh process with an empty kernel cache, and
    the path of its first derivative render."""
    estimator, wavelengths, views, spp, parameter = CONFIGS[name]
    job = {"estimator": estimator, "wavelengths": wavelengths, "views": views, "spp": spp, "parameter": parameter,
           "together": together}
    cache = tempfile.mkdtemp(dir=scratch)
    output = os.path.join(cache, "derivative.npz")
    done = subprocess.run([sys.executable, "-c", MEASURE, json.dumps(job), output], capture_output=True, text=True,
                          cwd=ROOT, env=dict(os.environ, DRJIT_CACHE_DIR=cache), check=True)
    seconds = json.loads(done.stdout.strip().splitlines()[-1])["seconds"]
    return {"plain_s": seconds[0], "first_derivative_s": seconds[1], "second_derivative_s": seconds[2],
            "output": output}


def main():
    import numpy as np

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--configs", nargs="+", choices=list(CONFIGS), default=list(CONFIGS))
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for name in args.configs:
            estimator, wavelengths, views, spp, parameter = CONFIGS[name]
            row = {"config": name, "estimator": estimator, "wavelengths": len(wavelengths), "spp": spp,
                   "parameter": parameter}
            for key, together in SETTINGS:
                row[key] = measure(name, together, scratch)
            outputs = [np.load(row[key].pop("output")) for key, _ in SETTINGS]
            row["same_values"] = all(np.array_equal(outputs[0][k], outputs[1][k]) for k in ("value", "derivative"))
            for kind in ("first_derivative_s", "second_derivative_s"):
                row[kind.replace("_s", "_ratio")] = row["per_output"][kind] / row["together"][kind]
            rows.append(row)
            print(f"{name}: first derivative render {row['per_output']['first_derivative_s']:.1f} s per output, "
                  f"{row['together']['first_derivative_s']:.1f} s together; second "
                  f"{row['per_output']['second_derivative_s']:.2f} s, {row['together']['second_derivative_s']:.2f} s; "
                  f"same values: {row['same_values']}", flush=True)
    lines = ["# What a forward-mode derivative render costs", "",
             f"Generated by `python benchmarks/derivative_cost.py` on {datetime.date.today()} ({machine()}"
             f", llvm_ad_rgb, CPU time): bruneton2017, sun "
             "zenith 30, observer 1 km, `directional_derivative` with respect to the parameter shown; each setting in a "
             "fresh process with an empty kernel cache. *Plain*: a render of the same directions first (it compiles "
             "the plain kernels). *First derivative*: the first derivative render (compiling and running the tangent "
             "kernels); *second*: another seed (running only). *Per output*: each scattering order's and "
             "wavelength's tangent evaluated apart, as Dr.Jit's own derivative of a block sum does (skyref until "
             "2026-12-06); *together*: `skyref.plugins.kernels.sum_blocks`, all of a launch's tangents in one kernel "
             "(skyref's default). Ratios: per output / together.", "",
             "| configuration | samples per view | parameter | plain render, first (s) | first derivative, per output (s) "
             "| together (s) | ratio | second derivative, per output (s) | together (s) | ratio | same values |",
             "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        a, b = r["per_output"], r["together"]
        lines.append(f"| {r['config']} | {r['spp']} | {r['parameter']} | {b['plain_s']:.2f} | "
                     f"{a['first_derivative_s']:.1f} | {b['first_derivative_s']:.1f} | {r['first_derivative_ratio']:.1f}x | "
                     f"{a['second_derivative_s']:.2f} | {b['second_derivative_s']:.2f} | "
                     f"{r['second_derivative_ratio']:.1f}x | {'bit for bit' if r['same_values'] else 'NO'} |")
    print(write_results("derivative_cost", {"machine": machine(), "rows": rows}, "\n".join(lines) + "\n"))


if __name__ == "__main__":
    main()
