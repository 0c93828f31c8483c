"""What tracing symmetric views once saves (skyref.symmetry), and that it changes nothing else:
skies of the consumers' grids rendered to their grid's target twice in one run, tracing one view
of each symmetry group and tracing every pixel.

Each sky is rendered as its batch renders it (:func:`skyref.render.render_to_error`, the grid's
target, sample cap and passes), once with ``symmetry=True`` and once with ``symmetry=False`` and
other seeds. Reported per sky: the views traced, CPU seconds of each render (process time, both
Dr.Jit threads; the kernels are compiled by a small render first), the ratio, the mean samples per
pixel, and how the two skies agree: per pixel and wavelength z = difference / combined standard
error, its mean square (1 if both are unbiased estimates with honest errors) and largest |z|,
over I and, for the polarized sky, Q and U too.

Usage: ``python benchmarks/symmetry.py``; writes ``results/symmetry.md`` and
``results/symmetry.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from results_files import machine, write_results  # noqa: E402

from skyref.batch.grid import load_grid  # noqa: E402
from skyref.render import render_sky, render_to_error, rendered_pixels  # noqa: E402
from skyref.scene import Scene  # noqa: E402
from skyref.symmetry import MIRROR_STOKES_SIGNS, view_groups  # noqa: E402

ROOT = os.path.join(os.path.dirname(__file__), "..")

#: (name, grid, sky index, polarized, target relative error or None for the grid's): the Hosek
#: training grid's mirror pairs on column centres (sky only), the LUT audit's on column edges
#: with the ground at the observer's feet (one view below the horizon), its zenith sun (one view
#: per row), a hazy sky, and a polarized one (U and V turned over in the copies).
SKIES = (
    ("Hosek training: turbidity 5, albedo 0, sun zenith 52", "grids/hosek_training.toml", 113, False, None),
    ("LUT audit: clear, ground, sun zenith 60", "grids/lut_audit.toml", 2, False, None),
    ("LUT audit: clear, ground, sun at the zenith", "grids/lut_audit.toml", 0, False, None),
    ("LUT audit: hazy (T=6), ground, sun zenith 30", "grids/lut_audit.toml", 43, False, None),
    ("LUT audit: clear, ground, sun zenith 60, polarized", "grids/lut_audit.toml", 2, True, 0.01),
)
#: The full render's seeds are the grid's plus this: an independent estimate.
OTHER_SEEDS = 1_000_003


def agreement(scene, symmetric, every_pixel, symmetric_error, every_pixel_error, signs=1.0) -> dict:
    """Each independent estimate of the symmetric render against the full render's pixels that
    took it: z = (estimate - mean of those pixels) / combined standard error, per group of
    :func:`skyref.symmetry.view_groups` and wavelength (one z per estimate: a copied estimate is one
    noise draw, and counted once per copy it would weigh as many). ``signs``: what a mirrored pixel's
    value is multiplied by to be that of its group's first (U: -1). Mean z^2 and max |z| where the
    combined error is > 0."""
    pixels = rendered_pixels(scene)
    groups, mirrored = view_groups(scene, pixels)
    flat = [np.asarray(x).reshape(-1, x.shape[-1])[pixels].astype(np.float64)
            for x in (symmetric, every_pixel, symmetric_error, every_pixel_error)]
    a, b, a_error, b_error = flat
    b = b * np.where(mirrored, signs, 1.0)[:, None]
    first, group = np.unique(groups, return_inverse=True)
    count = np.bincount(group)[:, None]
    b_mean = np.stack([np.bincount(group, weights=column) for column in b.T], axis=1) / count
    b_mean_error = np.sqrt(np.stack([np.bincount(group, weights=column ** 2) for column in b_error.T], axis=1)) / count
    error = np.hypot(a_error[first], b_mean_error)
    valid = error > 0
    z = (a[first][valid] - b_mean[valid]) / error[valid]
    return {"mean_z2": float(np.mean(z ** 2)), "max_abs_z": float(np.max(np.abs(z))), "values": int(z.size)}


def measure(name, grid_path, index, polarized, target) -> dict:
    grid = load_grid(os.path.join(ROOT, grid_path))
    spec = grid.sky(index)
    scene = Scene.from_dict(spec.scene).replace(name=spec.sky_id)
    if polarized:
        scene = scene.replace(render=dataclasses.replace(scene.render, polarized=True))
    target = target or grid.output.target_relative_error
    seeds = [grid.seed(index, r) for r in range(16)]
    passes = scene.render.passes
    render_sky(scene, spp=passes, passes=passes, seed=2)             # compile the kernels
    skies, cpu = {}, {}
    for symmetry in (True, False):
        start = time.process_time()
        skies[symmetry] = render_to_error(scene, target, [s + (0 if symmetry else OTHER_SEEDS) for s in seeds],
                                          grid.output.max_spp, symmetry=symmetry)
        cpu[symmetry] = time.process_time() - start
        print(f"{name}, symmetry={symmetry}: {cpu[symmetry]:.0f} CPU s", flush=True)
    a, b = skies[True], skies[False]
    components = {"I": (a.radiance, b.radiance, a.standard_error, b.standard_error)}
    if polarized:
        for k, label in ((1, "Q"), (2, "U")):
            components[label] = (a.stokes[..., k, :], b.stokes[..., k, :], a.stokes_error[..., k, :],
                                 b.stokes_error[..., k, :], MIRROR_STOKES_SIGNS[k])
    return {"grid": grid_path, "sky_id": spec.sky_id, "coordinates": spec.coordinates, "polarized": polarized,
            "target_relative_error": target, "pixels": int(np.isfinite(a.radiance[..., 0]).sum()),
            "views_traced": {"symmetric": a.metadata["views_traced"], "every_pixel": b.metadata["views_traced"]},
            "cpu_s": {"symmetric": cpu[True], "every_pixel": cpu[False]},
            "speedup": cpu[False] / cpu[True],
            "mean_spp": {"symmetric": a.metadata["spp"], "every_pixel": b.metadata["spp"]},
            "pixels_at_target": {"symmetric": a.metadata["pixels_at_target"],
                                 "every_pixel": b.metadata["pixels_at_target"]},
            "agreement": {label: agreement(scene, *values) for label, values in components.items()}}


def markdown(report) -> str:
    lines = ["# Symmetric views traced once", "",
             f"Produced {report['date']} by `python benchmarks/symmetry.py` on {report['machine']} (llvm_ad_rgb, "
             "2 cores, other batches running beside it). Each sky of a consumer's grid rendered as its batch renders "
             "it (adaptive per direction to the target, the grid's sample cap and 16 passes), tracing one view of "
             "each symmetry group (`skyref/symmetry.py`) and, with other seeds, every pixel. CPU: process time of "
             "the render, kernels compiled before. Agreement: each independent estimate of the symmetric render "
             "(one per group of views) against the mean of the full render's pixels in its group, z = difference / "
             "combined standard error, per wavelength (and Stokes component; a mirrored pixel's U turned over).", "",
             "| sky | target | views traced | CPU s | speed-up | mean spp | mean z^2 | max abs z |",
             "|---|---:|---:|---:|---:|---:|---|---|"]
    for name, r in report["skies"].items():
        views, cpu, spp = r["views_traced"], r["cpu_s"], r["mean_spp"]
        z2 = ", ".join(f"{k} {v['mean_z2']:.2f}" for k, v in r["agreement"].items())
        zmax = ", ".join(f"{k} {v['max_abs_z']:.2f}" for k, v in r["agreement"].items())
        lines.append(f"| {name} | {100 * r['target_relative_error']:.1f}% | {views['symmetric']} / "
                     f"{views['every_pixel']} | {cpu['symmetric']:.0f} / {cpu['every_pixel']:.0f} | "
                     f"{r['speedup']:.2f}x | {spp['symmetric']:,} / {spp['every_pixel']:,} | {z2} | {zmax} |")
    lines += ["", "Pairs are symmetric / every pixel. The speed-up is the CPU ratio; the views traced bound it "
              "(a sky's cost is not spread evenly over its directions: the copies of the brightest, cheapest ones "
              "save least). A mean z^2 near 1 says the two renders are the same sky within their stated errors (with "
              "standard errors from 16 batches, t-distributed z's have a mean square up to 15/13 = 1.15 and "
              "heavier tails than a normal's); one z per estimate, since a copied estimate is one noise draw (per "
              "pixel, the ground of a ground-level observer, one estimate copied to half the sky's pixels, would "
              "weigh as much as every other estimate together). The ground is unpolarized (Q = U = 0 exactly): Q "
              "and U count the sky's estimates only.", ""]
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.parse_args()
    report = {"date": datetime.datetime.now().isoformat(timespec="minutes"),
              "machine": machine(),
              "skies": {name: measure(name, *rest) for name, *rest in SKIES}}
    write_results("symmetry", report, markdown(report))
    print(markdown(report))


if __name__ == "__main__":
    main()
