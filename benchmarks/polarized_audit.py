"""What the fast methods' errors become against a polarized ground truth: every LUT method and
analytic model of the speed-vs-error map, compared with skyref's scalar radiance and with the I of
its polarized transport, on the map's skies, in one run.

The real-time LUT methods and the analytic models all transport scalar radiance; the trusted
reference codes transport Stokes vectors, and multiple scattering of polarized light changes I
itself by a few percent (``results/polarization.md``). This benchmark says what that does to each
method's error. Skies: the eight of the map (:data:`skyref.audit.speed_map.MAP_SKIES`: clear and
hazy at sun zenith 30 and 60 deg, sunsets at 88 deg, 10 km at 30 and 80 deg), their scenes from
``grids/lut_audit.toml`` (64x32 equirectangular pixel centres, 17 wavelengths 380-780 nm, the
presets' Rayleigh depolarization 0). Each sky is rendered twice by the line-integral estimator
with the same seed and samples, scalar and polarized; every method is compared with each
(:func:`skyref.audit.speed_map.evaluate_map`: noise-corrected RMS of the relative luminance error
over the sky, the solar disk and the ground excluded; per kind of sky, the worst sky). The two
truths' own difference is measured the same way, its noise from the batches' paired differences
(:func:`skyref.render.render_paired`: the two transports trace the same paths, so most of their
noise cancels in the difference; combined as if independent, it had left the hazy skies' difference
unresolved at 2,048 samples).

Usage: ``python benchmarks/polarized_audit.py [--spp N]``; writes ``results/polarized_audit.md``
and ``results/polarized_audit.json``. Truths and comparisons are kept in ``out/polarized-audit``
(a rerun reuses them; delete the directory to redo).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from results_files import machine, write_results  # noqa: E402

from skyref.audit.metrics import error_maps, region_statistics  # noqa: E402
from skyref.audit.regions import region_masks  # noqa: E402
from skyref.audit.speed_map import (ENTRIES, KINDS, TRUTH_GRID, entry_summary, evaluate_map,  # noqa: E402
                                    map_sky_specs)
from skyref.batch.grid import load_grid  # noqa: E402
from skyref.io.atomic import atomic_path, atomic_write  # noqa: E402
from skyref.io.exr import read_sky_exr, write_sky_exr  # noqa: E402
from skyref.render import render_paired  # noqa: E402
from skyref.scene import Scene  # noqa: E402

ROOT = os.path.join(os.path.dirname(__file__), "..")
WORK = os.path.join(ROOT, "out", "polarized-audit")
MODES = ("scalar", "polarized")
PASSES = 16
SEED = 7
#: Methods closer than this to the scalar truth (luminance RMS) are those a truth change of ~2% matters for.
CLOSE = 0.10


def truth_paths(spec, spp: int) -> dict:
    """Where a map sky's truths are kept: mode -> EXR; ``"cpu"``: the CPU seconds of each render,
    ``"difference_error"``: the standard error of polarized I - scalar radiance (.npy)."""
    paths = {mode: os.path.join(WORK, mode, "skies", f"{spec.sky_id}-{spp}spp.exr") for mode in MODES}
    base = os.path.join(WORK, "pairs", f"{spec.sky_id}-{spp}spp")
    return {**paths, "cpu": base + ".cpu.json", "difference_error": base + ".difference-error.npy"}


def render_truths(spp: int) -> tuple[dict, dict, dict]:
    """mode -> [(map sky, EXR path)], rendering the truths that are not on disk yet; the CPU
    seconds each cost (mode -> sky name -> s); and per sky the path of the standard error of
    their difference."""
    grid = load_grid(os.path.join(ROOT, TRUTH_GRID))
    skies, cpu, difference_error = {mode: [] for mode in MODES}, {mode: {} for mode in MODES}, {}
    for index, (sky, spec) in enumerate(map_sky_specs(grid)):
        scene = Scene.from_dict(spec.scene).replace(name=spec.sky_id)
        paths = truth_paths(spec, spp)
        if not all(os.path.exists(path) for path in paths.values()):
            # every pixel traced in both modes, with the same seed and samples (a pair), so that
            # their costs are per direction, as in the polarization benchmark
            settings = dataclasses.replace(scene.render, passes=PASSES, estimator="line_integral")
            pair = render_paired(scene.replace(render=settings),
                                 scene.replace(render=dataclasses.replace(settings, polarized=True)),
                                 spp, seed=SEED + index)
            for path in paths.values():
                os.makedirs(os.path.dirname(path), exist_ok=True)
            for mode, truth in zip(MODES, pair[:2]):
                write_sky_exr(truth, paths[mode])
            with atomic_path(paths["difference_error"]) as tmp, open(tmp, "wb") as f:
                np.save(f, pair[2])
            with atomic_write(paths["cpu"]) as f:
                json.dump({mode: truth.metadata["render_cpu_s"] for mode, truth in zip(MODES, pair[:2])}, f)
            print(f"{sky.name}: " + ", ".join(f"{mode} {truth.metadata['render_cpu_s']:.0f}" for mode, truth in
                                              zip(MODES, pair[:2])) + " CPU s", flush=True)
        with open(paths["cpu"]) as f:
            seconds = json.load(f)
        for mode in MODES:
            cpu[mode][sky.name] = seconds[mode]
            skies[mode].append((sky, paths[mode]))
        difference_error[sky.name] = paths["difference_error"]
    return skies, cpu, difference_error


def truth_difference(scalar_path: str, polarized_path: str, difference_error_path: str) -> dict:
    """The scalar truth against the polarized one, as a method against a truth: luminance RMS of
    scalar / polarized - 1 over the sky (noise-corrected with the standard error of their paired
    difference), its noise and whether it is resolved."""
    scalar, polarized = read_sky_exr(scalar_path), read_sky_exr(polarized_path)
    scene = polarized.scene
    without_disk = [sky.radiance - sky.orders.get("sun_direct", 0.0) for sky in (scalar, polarized)]
    maps = error_maps(without_disk[0], without_disk[1], np.load(difference_error_path), scene.wavelengths_nm)
    masks = region_masks(polarized.directions, scene.sun.direction, scene.atmosphere.bottom_radius_m,
                         scene.observer.altitude_m)
    sky = region_statistics(maps, masks)["sky"]["luminance"]
    return {"rms": sky["rms"], "noise_rms": sky["noise_rms"], "resolved": sky["resolved_rms"]}


def cell(kind_summary) -> str:
    """A table cell: a kind's worst luminance RMS in %, `*` if not resolved, `(part)` if some skies were refused."""
    if kind_summary is None:
        return "refused"
    text = f"{100 * kind_summary['rms']:.2f}" + ("" if kind_summary["resolved"] else "*")
    return text + (" (part)" if kind_summary["partial"] else "")


def markdown(report) -> str:
    lines = ["# The fast methods against a polarized ground truth", "",
             f"Produced {report['date']} by `python benchmarks/polarized_audit.py --spp {report['spp']}` on "
             f"{report['machine']} (llvm_ad_rgb, 2 cores). The skies of the speed-vs-error map (`skyref report`), "
             "scenes from `grids/lut_audit.toml` (64x32 pixel-centre directions, 17 wavelengths 380-780 nm, "
             "Rayleigh depolarization 0 as the presets publish it), each rendered by skyref's line-integral estimator "
             f"twice with the same seed and {report['spp']:,} samples per direction ({PASSES} batches): scalar "
             "radiance, and I of polarized transport (Stokes vectors, Rayleigh phase matrix; the aerosol's "
             "Cornette-Shanks phase function scalar, P11 only). Every LUT method and analytic model of the map is "
             "compared with each truth: noise-corrected RMS of the relative luminance error over the sky (the "
             "solar disk and the ground excluded), in %, the worst sky of each kind; `*`: not resolved (the "
             "truth's noise exceeds 1/5 of the error). CPU for the truths: "
             f"{report['truth_cpu_s']['scalar']:.0f} s scalar, {report['truth_cpu_s']['polarized']:.0f} s "
             "polarized (measured when each was rendered, a kernel compilation included where that run "
             "compiled one).", "",
             "How far apart the two truths are (luminance, scalar / polarized I - 1, RMS over the sky; its noise "
             "from the batches' paired differences, the two transports tracing the same paths):", "",
             "| sky | RMS | its noise |", "|---|---:|---:|"]
    for name, d in report["truth_difference"].items():
        lines.append(f"| {name} | {100 * d['rms']:.2f}%{'' if d['resolved'] else '*'} | {100 * d['noise_rms']:.2f}% |")
    changes = [(abs(e["polarized"][k]["rms"] - e["scalar"][k]["rms"]), e["entry"], k, e["scalar"][k]["rms"])
               for e in report["entries"]
               for k in KINDS if e["scalar"][k] is not None and e["polarized"][k] is not None
               and e["scalar"][k]["resolved"] and e["polarized"][k]["resolved"]]
    close = [c for c in changes if c[3] < CLOSE]
    if close:
        largest = max(close)
        lines += ["", f"For the methods within {100 * CLOSE:.0f}% of the scalar truth on a kind of sky (both errors "
                  f"resolved; {len(close)} cases), the polarized truth moves the error by at most "
                  f"{100 * largest[0]:.2f} percentage points ({largest[1]}, {largest[2]}), by "
                  f"{100 * float(np.median([c[0] for c in close])):.2f} points in the median."]
    lines += ["", "Each method's error against the scalar truth / against the polarized truth's I, in %:", "",
              "| method | setting | " + " | ".join(KINDS) + " |", "|---|---|" + "---:|" * len(KINDS)]
    for entry in report["entries"]:
        cells = [f"{cell(entry['scalar'][kind])} / {cell(entry['polarized'][kind])}" for kind in KINDS]
        lines.append(f"| {entry['method']} | {entry['label']} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp", type=int, default=2048, help="samples per direction of each truth (default 2048)")
    args = parser.parse_args()
    if args.spp < PASSES or args.spp % PASSES:
        parser.error(f"--spp: a multiple of {PASSES}")
    skies, cpu, difference_error = render_truths(args.spp)
    entries = [e for e in ENTRIES if e.family != "path tracer"]
    summaries = {}
    for mode in MODES:
        rows = evaluate_map(entries, skies[mode], os.path.join(WORK, mode, f"cache-{args.spp}spp"))
        summaries[mode] = {s["entry"]: s["kinds"] for s in entry_summary(rows)}
    report = {"date": datetime.datetime.now().isoformat(timespec="minutes"), "machine": machine(),
              "spp": args.spp, "truth_cpu_s": {mode: sum(cpu[mode].values()) for mode in MODES},
              "truth_difference": {sky.name: truth_difference(path, polarized_path, difference_error[sky.name])
                                   for (sky, path), (_, polarized_path) in zip(skies["scalar"], skies["polarized"])},
              "entries": [{"entry": e.key, "method": e.method, "label": e.label,
                           "scalar": summaries["scalar"][e.key], "polarized": summaries["polarized"][e.key]}
                          for e in entries]}
    print(f"wrote {write_results('polarized_audit', report, markdown(report))}")


if __name__ == "__main__":
    main()
