"""What a dask worker does for one sky: render it, write its EXR, its dataset chunk and, last,
its completion marker. It returns only the marker (a few hundred bytes), so the client never
holds sky data, and the worker holds one sky at a time."""

from __future__ import annotations

import contextlib
import datetime
import os
import resource
import time

from skyref.batch.store import BatchStore, sha256_of
from skyref.io.exr import write_sky_exr
from skyref.plugins import load_mitsuba
from skyref.render import relative_error_percentile, render_sky, render_to_error
from skyref.scene import Scene

__all__ = ["render_and_store"]


def render_and_store(task: dict) -> dict:
    """Render the sky described by ``task`` (built by :func:`skyref.batch.run.make_task`) and
    store it; returns its marker."""
    start, start_cpu = time.perf_counter(), time.process_time()
    if task["drjit_threads"]:
        load_mitsuba(task["variant"])
        import drjit as dr  # lazy: only once load_mitsuba has pointed Dr.Jit at a working libLLVM

        dr.set_thread_count(task["drjit_threads"])
    grid, spec = task["grid"], task["sky"]
    output = grid.output
    scene = Scene.from_dict(spec.scene).replace(name=spec.sky_id)
    store = BatchStore(grid)
    checkpoint = None
    if output.spp is not None:
        sky = render_sky(scene, spp=output.spp, seed=spec.seed, variant=task["variant"])
        sky.metadata["relative_error_p95"] = relative_error_percentile(sky)
    else:
        seeds = [grid.seed(spec.index, r) for r in range(task["max_rounds"])]
        checkpoint = store.checkpoint_path(spec.sky_id)
        sky = render_to_error(scene, grid.target_relative_error(spec.coordinates), seeds, output.max_spp,
                              variant=task["variant"], checkpoint=checkpoint, dynamic_range=output.dynamic_range)
    sky.metadata["batch"] = {"sky_id": spec.sky_id, "index": spec.index, "coordinates": spec.coordinates}

    exr_path = store.exr_path(spec.sky_id)
    write_sky_exr(sky, exr_path)
    store.write_sky(spec.index, sky)
    meta = sky.metadata
    marker = {"sky_id": spec.sky_id, "index": spec.index, "coordinates": spec.coordinates,
              "exr": os.path.relpath(exr_path, store.directory), "exr_sha256": sha256_of(exr_path),
              "exr_bytes": os.path.getsize(exr_path), "spp": meta["spp"], "seed": meta["seed"],
              "relative_error_p95": meta["relative_error_p95"], "render_time_s": meta["render_time_s"],
              "task_time_s": time.perf_counter() - start, "variant": meta["variant"],
              # a resumed sky's CPU includes what the runs before this one spent on it
              "task_cpu_s": time.process_time() - start_cpu + meta.get("render_cpu_s_before_resume", 0.0),
              "worker_peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
              "finished_at": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
    store.write_marker(spec.sky_id, marker)
    if checkpoint is not None:
        with contextlib.suppress(FileNotFoundError):    # none if nothing was traced
            os.remove(checkpoint)
    return marker
