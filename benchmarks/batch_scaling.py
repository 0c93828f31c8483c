"""Skies per hour of ``skyref batch`` with 1 and 2 local workers, and the batch layer's
overhead against calling the renderer directly, in one run.

Workload: the default clear sky (48 wavelengths, 360-830 nm) on a 64x32 equirectangular image,
``--skies`` sun zeniths between 5 and 85 degrees, a fixed spp per sky (a few seconds each).

- direct: one process loops ``render_sky`` + ``write_sky_exr`` over the same skies (Dr.Jit on
  all cores) — what a user without the batch layer would run;
- batch, 1 worker: ``run_batch`` on a LocalCluster with one worker process (Dr.Jit on all
  cores), fresh output directory; includes starting the cluster and the dataset;
- batch, 2 workers: two worker processes with one Dr.Jit thread each.

Overhead = batch-1 CPU time / direct CPU time - 1 (robust to other load: the batch's CPU time is
its client process, which hosts the scheduler, plus the workers' task CPU times from the
markers); also in wall time (whole run, cluster start included) and per sky from the workers'
own task times (render + EXR + dataset + marker vs render +
EXR in the direct loop). Worker peak memory comes from the completion markers; the memory test
renders a grid of ``--skies`` and one of 10x as many tiny skies and compares peak worker RSS.

Usage: ``python benchmarks/batch_scaling.py [--skies 8] [--spp 256] [--rounds 2]``; writes
results/batch_scaling.md.
"""

from __future__ import annotations

import argparse
import datetime
import os
import shutil
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from results_files import machine  # noqa: E402

from skyref.batch import load_grid, run_batch  # noqa: E402
from skyref.io.atomic import atomic_write  # noqa: E402

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def grid_file(directory, skies, spp, width=64, height=32, name="out"):
    zeniths = ", ".join(f"{z:.3f}" for z in np.linspace(5.0, 85.0, skies))
    path = os.path.join(directory, f"{name}.toml")
    with open(path, "w") as f:
        f.write(f'[base]\nscene = "{os.path.join(ROOT, "scenes", "earth-clear.toml")}"\n'
                f'[axes]\n"sun.zenith_deg" = [{zeniths}]\n'
                f'[output]\ndirectory = "{name}"\nwidth = {width}\nheight = {height}\nspp = {spp}\npasses = 4\n')
    return load_grid(path)


def direct(grid):
    """Render and write every sky of ``grid`` in this process, without the batch layer."""
    from skyref.io.exr import write_sky_exr
    from skyref.render import render_sky
    from skyref.scene import Scene

    os.makedirs(grid.output.directory, exist_ok=True)
    per_sky = []
    start, start_cpu = time.perf_counter(), time.process_time()
    for spec in grid.skies():
        t0, c0 = time.perf_counter(), time.process_time()
        sky = render_sky(Scene.from_dict(spec.scene), spp=grid.output.spp, seed=spec.seed)
        write_sky_exr(sky, os.path.join(grid.output.directory, f"{spec.sky_id}.exr"))
        per_sky.append((time.perf_counter() - t0, time.process_time() - c0))
    return time.perf_counter() - start, per_sky, time.process_time() - start_cpu


def batch(grid, workers):
    """Wall time, manifest and CPU time (this client process, which also hosts the scheduler,
    plus every worker's task CPU time from the markers) of a batch run."""
    start, start_cpu = time.perf_counter(), time.process_time()
    manifest = run_batch(grid, workers=workers, progress=False, log=lambda *_: None)
    wall = time.perf_counter() - start
    cpu = time.process_time() - start_cpu + sum(s["task_cpu_s"] for s in manifest["skies"])
    assert manifest["skies_finished"] == len(grid) and not manifest["failed"], manifest["failed"]
    return wall, manifest, cpu


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--skies", type=int, default=8)
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=2, help="interleaved repetitions (best of each kept)")
    args = parser.parse_args()
    from skyref.plugins import load_mitsuba

    load_mitsuba()
    work = tempfile.mkdtemp(prefix="skyref-batch-bench-")
    try:
        load_before = os.getloadavg()[0]
        direct(grid_file(work, 2, 8, name="warmup"))  # compile kernels, load data
        # Interleaved rounds, best of each: a background load then hits every contender alike.
        runs = {"direct": [], "one": [], "two": []}
        for round_index in range(args.rounds):
            runs["direct"].append(direct(grid_file(work, args.skies, args.spp, name=f"direct{round_index}")))
            runs["one"].append(batch(grid_file(work, args.skies, args.spp, name=f"one{round_index}"), 1))
            runs["two"].append(batch(grid_file(work, args.skies, args.spp, name=f"two{round_index}"), 2))
        t_direct, per_sky_direct, cpu_direct = min(runs["direct"], key=lambda run: run[0])
        t1, m1, cpu1 = min(runs["one"], key=lambda run: run[0])
        t2, m2, _ = min(runs["two"], key=lambda run: run[0])
        cpu_direct = min(run[2] for run in runs["direct"])
        cpu1 = min(run[2] for run in runs["one"])
        _, small, _ = batch(grid_file(work, args.skies, 4, width=8, height=4, name="small"), 1)
        _, large, _ = batch(grid_file(work, 10 * args.skies, 4, width=8, height=4, name="large"), 1)
        load_after = os.getloadavg()[0]
    finally:
        shutil.rmtree(work, ignore_errors=True)

    task1 = np.array([s["task_time_s"] for s in m1["skies"]])
    render1 = np.array([s["render_time_s"] for s in m1["skies"]])
    # Steady state: a worker's first sky also compiles the kernels (the direct loop was warmed up).
    steady_cpu = np.median([s["task_cpu_s"] for s in m1["skies"] if s["index"] > 0])
    direct_cpu = np.median([c for _, c in per_sky_direct])
    n = args.skies
    rows = [("direct loop (1 process, all cores)", t_direct, 3600 * n / t_direct),
            ("skyref batch, 1 worker (all cores)", t1, 3600 * n / t1),
            ("skyref batch, 2 workers (1 core each)", t2, 3600 * n / t2)]
    peak = lambda m: max(s["worker_peak_rss_mb"] for s in m["skies"])  # noqa: E731
    lines = [
        "# Batch scaling: skies per hour and the batch layer's overhead",
        "",
        f"**Overhead of the batch layer in CPU time: {100 * (cpu1 / cpu_direct - 1):+.1f}%** ({cpu1:.1f} s vs "
        f"{cpu_direct:.1f} s for {n} skies: client + scheduler process and the workers' tasks, against the direct "
        "loop's process). CPU time hardly depends on other load on the machine; the wall times below do. "
        "Most of it is paid once per run (starting the cluster and its worker processes, importing Mitsuba, "
        "compiling the kernels in the fresh worker): per sky in steady state the worker spends "
        f"**{100 * (steady_cpu / direct_cpu - 1):+.1f}%** CPU time over the direct loop (median {steady_cpu:.2f} s "
        f"vs {direct_cpu:.2f} s: dataset chunk, marker, SHA-256), so the whole-run overhead falls below 5% once a "
        f"run has more than about {max(1, int(np.ceil((cpu1 - n * steady_cpu) / (0.05 * direct_cpu))))} skies "
        "of this size.",
        "",
        f"Generated by `python benchmarks/batch_scaling.py --skies {n} --spp {args.spp} --rounds {args.rounds}` "
        "(best of the interleaved rounds) on "
        f"{datetime.date.today()} ({machine()}, load average "
        f"{load_before:.1f} before / {load_after:.1f} after).",
        "",
        f"Workload: {n} skies of the default clear sky (48 wavelengths), 64x32 equirectangular, "
        f"{args.spp} spp, sun zenith 5-85 deg. Times include writing the spectral EXRs; batch runs also "
        "start the dask LocalCluster, create the zarr dataset and write markers and the manifest.",
        "",
        "| how | wall time (s) | skies per hour |",
        "|---|---:|---:|",
        *[f"| {name} | {t:.1f} | {rate:.0f} |" for name, t, rate in rows],
        "",
        f"- Overhead of the batch layer, whole run (cluster start included): "
        f"**{100 * (t1 / t_direct - 1):+.1f}%** ({t1 - t_direct:+.1f} s over {n} skies).",
        f"- Overhead per sky inside the worker (dataset chunk + marker + SHA-256 on top of render + EXR): "
        f"**{100 * (task1.sum() / sum(t for t, _ in per_sky_direct) - 1):+.1f}%** (mean task {task1.mean():.2f} s, "
        f"of which rendering {render1.mean():.2f} s; direct loop {np.mean([t for t, _ in per_sky_direct]):.2f} s "
        "per sky; wall times, load-dependent).",
        f"- 2 workers vs 1: {t1 / t2:.2f}x the throughput (the machine has {os.cpu_count()} cores; Dr.Jit already "
        "uses all of them in one process, so extra workers mostly overlap the serial parts).",
        f"- Memory: peak worker RSS {peak(small):.0f} MB for a {n}-sky grid and {peak(large):.0f} MB for a "
        f"{10 * n}-sky grid of the same tiny skies (a worker holds one sky at a time; the client keeps "
        "only the indices of unfinished skies).",
    ]
    os.makedirs(os.path.join(ROOT, "results"), exist_ok=True)
    with atomic_write(os.path.join(ROOT, "results", "batch_scaling.md")) as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
