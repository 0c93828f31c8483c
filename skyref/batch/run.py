"""Run a grid: check it, find the skies still to do, and render them on dask workers.

By default a ``dask.distributed.LocalCluster`` sized to this machine runs the skies (one sky
per worker process at a time; Dr.Jit's threads split between the workers); ``scheduler`` names
any running dask scheduler instead (``tcp://host:8786``), so a Slurm or Kubernetes dask cluster
scales the same grid out — workers then need the output directory on a shared file system.
At most two skies per worker are in flight, so the client's memory does not grow with the
grid. A sky that fails is reported and left unmarked; the next run retries it.

dask and tqdm are imported inside the functions that use them: :mod:`skyref.batch` (and so this
module) is imported to read and check grids too, and dask alone takes about a second to import.
"""

from __future__ import annotations

import logging
import os
import threading
import time

from skyref.batch.grid import MAX_ROUNDS, Grid
from skyref.batch.dataset import check_netcdf_size
from skyref.batch.store import NETCDF, BatchStore
from skyref.batch.worker import render_and_store
from skyref.errors import ParameterError
from skyref.extras import require
from skyref.render import AdaptiveProgress
from skyref.validation import check_int

__all__ = ["make_task", "SCHEDULER_TIMEOUT_S", "check_workers", "local_cluster", "connect", "run_batch"]


def make_task(grid: Grid, spec, variant, drjit_threads) -> dict:
    return {"grid": grid, "sky": spec, "variant": variant, "drjit_threads": drjit_threads,
            "max_rounds": MAX_ROUNDS}


#: Seconds to wait for a dask scheduler named by ``--scheduler`` to answer.
SCHEDULER_TIMEOUT_S = 10

#: Seconds between looks at the checkpoints of the skies in flight (the progress bar's note).
PARTIAL_LOOK_S = 10.0


def check_workers(workers: int | None) -> int:
    """The local worker processes: ``workers``, or one per two cores (at least one) if None."""
    cores = os.cpu_count() or 1
    if workers is None:
        return max(1, cores // 2)
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= cores:
        raise ParameterError("workers", workers, f"an integer in [1, {cores}] (this machine's cores)", "invalid")
    return workers


def local_cluster(workers: int | None):
    """A LocalCluster of ``workers`` single-threaded processes (default: one per two cores,
    at least one) sharing this machine's memory; returns (cluster, Dr.Jit threads per worker)."""
    require("batch")
    from dask.distributed import LocalCluster  # lazy: dask takes ~1 s to import (see module docstring)

    import dask

    workers = check_workers(workers)
    # No worker time-to-live: the scheduler would drop a worker not heard from for 5 minutes, and
    # a batch paused that long (SIGSTOP, a suspended laptop) lost its workers on resuming, each
    # sky queued on one counted as killed by it (a sky fails after 3): on 2026-12-05 a 17-minute
    # pause failed two LUT-audit skies. A local worker that dies is seen by its nanny all the same.
    with dask.config.set({"distributed.scheduler.worker-ttl": None}):
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.ERROR)
    return cluster, max(1, (os.cpu_count() or 1) // workers)


def connect(scheduler: str):
    """A client of the dask scheduler at ``scheduler``; a ParameterError if none answers within
    SCHEDULER_TIMEOUT_S seconds or the address is malformed."""
    require("batch")
    from dask.distributed import Client  # lazy: dask's import cost

    valid = "the address of a running dask scheduler, e.g. tcp://host:8786"
    try:
        return Client(scheduler, timeout=SCHEDULER_TIMEOUT_S)
    except (OSError, TimeoutError) as exc:
        raise ParameterError("scheduler", scheduler, valid,
                             f"no scheduler answered within {SCHEDULER_TIMEOUT_S} s ({type(exc).__name__})") from None
    except (ValueError, TypeError) as exc:
        raise ParameterError("scheduler", scheduler, valid, f"not an address ({exc})") from None


def run_batch(grid: Grid, scheduler: str | None = None, workers: int | None = None, variant: str | None = None,
              verify: bool = False, progress: bool = True, log=print, netcdf: bool = False,
              indices=None) -> dict:
    """Render every unfinished sky of ``grid`` (or of those among the sky numbers ``indices``,
    e.g. the part of a grid a benchmark needs: the same skies, ids and seeds as in the whole
    grid's run), submitted in the order of ``indices``; returns the manifest (see :class:`skyref.batch.store.BatchStore`) plus
    ``failed`` (sky id -> error message), ``wall_time_s`` and ``netcdf``: with ``netcdf``, the
    dataset is copied to ``dataset.nc`` once every sky is finished, and this is its path (else
    None)."""
    require("batch")
    from dask.distributed import Client  # lazy: dask's import cost

    # Everything is checked, and the scheduler reached, before anything is written.
    first_scene = grid.validate()
    if indices is None:
        indices = range(len(grid))
    else:
        indices = list(dict.fromkeys(check_int("indices", i, 0, len(grid) - 1) for i in indices))
    if workers is not None and scheduler is not None:
        raise ParameterError("workers", workers, "only without --scheduler (the cluster sizes itself)", "conflict")
    if scheduler is None:
        check_workers(workers)
    store = BatchStore(grid)
    store.check_writable()
    if netcdf:
        check_netcdf_size(grid, first_scene)
    cluster = None
    if scheduler is None:
        cluster, threads = local_cluster(workers)
        client = Client(cluster)
    else:
        client, threads = connect(scheduler), None
    try:
        return _run(grid, store, first_scene, client, threads, variant, verify, progress, log, netcdf, indices)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _run(grid, store, first_scene, client, threads, variant, verify, progress, log, netcdf, indices) -> dict:
    """The body of :func:`run_batch`, once the cluster is up."""
    from dask.distributed import as_completed  # lazy: dask's import cost

    with store.lock():
        store.prepare(first_scene)
        pending_indices = [i for i in indices if not store.is_finished(grid.sky_id(i), verify)]
        pending = (grid.sky(i) for i in pending_indices)
        done_before = len(indices) - len(pending_indices)
        part = "" if len(indices) == len(grid) else f"{len(indices)} of the "
        log(f"skyref batch: {part}{len(grid)} skies on a {' x '.join(map(str, grid.shape))} grid, "
            f"{done_before} already finished, output {store.directory}")
        start = time.perf_counter()
        failed, in_flight = {}, {}
        bar, stop, watcher = None, threading.Event(), None
        if progress:
            from tqdm import tqdm  # lazy: tqdm's import cost, paid only with a progress bar

            bar = tqdm(total=len(indices), initial=done_before, unit="sky", desc="skyref batch", smoothing=0.1)
            if grid.output.target_relative_error is not None:
                watcher = threading.Thread(target=_note_skies_in_flight, daemon=True,
                                           args=(store, in_flight, bar, stop))
                watcher.start()
        try:
            window = 2 * max(1, len(client.scheduler_info(n_workers=-1)["workers"]))
            queue = as_completed()

            def submit_next():
                spec = next(pending, None)
                if spec is not None:
                    future = client.submit(render_and_store, make_task(grid, spec, variant, threads), pure=False,
                                           key=f"{spec.sky_id}-{os.getpid()}-{time.monotonic_ns()}")
                    in_flight[future] = spec
                    queue.add(future)

            for _ in range(window):
                submit_next()
            for future in queue:
                spec = in_flight.pop(future)
                try:
                    future.result()
                except Exception as exc:  # reported, left unmarked, retried by the next run
                    failed[spec.sky_id] = f"{type(exc).__name__}: {exc}"
                    log(f"skyref batch: {spec.sky_id} {spec.coordinates} failed: {failed[spec.sky_id]}")
                if bar is not None:
                    bar.update(1)
                submit_next()
        finally:
            stop.set()
            if watcher is not None:
                watcher.join()
                bar.set_postfix_str("")         # no note left of the last sky in flight
            if bar is not None:
                bar.close()
        manifest = store.write_manifest()
        unfinished = len(grid) - manifest["skies_finished"]
        if netcdf and not unfinished:
            store.write_netcdf()
        elif netcdf:
            log(f"skyref batch: {NETCDF} not written: {unfinished} skies unfinished (run again to finish them)")
    manifest.update(failed=failed, wall_time_s=time.perf_counter() - start,
                    netcdf=store.netcdf_path if netcdf and not unfinished else None)
    return manifest


def _note_skies_in_flight(store, in_flight: dict, bar, stop) -> None:
    """Until ``stop`` is set, say on ``bar`` how far each sky in flight is, from its checkpoint
    (:meth:`skyref.render.AdaptiveProgress.describe`): one sky of a hard grid can take hours."""
    while not stop.wait(PARTIAL_LOOK_S):
        try:
            specs = list(in_flight.values())
        except RuntimeError:            # changed while it was read: look again next time
            continue
        notes = [f"{spec.sky_id}: {note}" for spec in specs
                 if (note := AdaptiveProgress.describe(store.checkpoint_path(spec.sky_id),
                                                       store.grid.target_relative_error(spec.coordinates)))]
        bar.set_postfix_str("; ".join(notes))
