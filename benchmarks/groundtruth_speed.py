"""Time to 1% relative RMS error: the ``atmosphere`` integrator against stock ``volpath`` +
skyref's ``atmosphere_medium``, on the same spherical sky, in one run.

Scene: preset ``bruneton2017``, sun zenith 60 deg, observer 1 m above the ground (stock
Mitsuba's float32 ground sphere needs the clearance), 128x64 equirectangular image. Both
estimators render the RGB wavelength grid (680/550/440 nm) in ``llvm_ad_rgb``, where they
estimate exactly the same three numbers per pixel. (In spectral variants ``volpath`` samples
continuous wavelengths into film bands, a different estimand; the integrator's time on the full
48-wavelength grid is reported on its own.)

Error: relative RMS over the sky pixels (view zenith < 88 deg, more than 3 deg from the sun:
stock ``directional`` is a delta light without a disk, so pixels near the sun are not the same
quantity) and over wavelengths, against a reference rendered by the integrator with many more
samples; the reference's own variance (from its independent passes) is subtracted. Time to 1%
extrapolates the measured error with the Monte Carlo rate err ~ 1/sqrt(time).

Usage: ``python benchmarks/groundtruth_speed.py [--quick]``; writes results/groundtruth_speed.md.
"""

from __future__ import annotations

import argparse
import datetime
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
from skyref.plugins.volpath_scene import stock_volpath_scene  # noqa: E402
from skyref.render import render_sky, sensor_dict  # noqa: E402
from skyref.scene import Camera, Observer, RenderSettings, Scene, Sun  # noqa: E402

TARGET = 0.01
RESULTS = os.path.join(os.path.dirname(__file__), "..", "results", "groundtruth_speed.md")


def scene_for(wavelengths):
    return Scene(atmosphere=atm.bruneton2017(), sun=Sun(60.0, 180.0), observer=Observer(1.0),
                 camera=Camera(width=128, height=64), wavelengths=wavelengths,
                 render=RenderSettings(spp=64, passes=4), name="groundtruth-speed")


def error_mask(scene, directions):
    cos_sun = directions @ scene.sun.direction
    return (directions[..., 2] > math.cos(math.radians(88.0))) & (cos_sun < math.cos(math.radians(3.0)))


def relative_rms(image, reference, reference_se, mask):
    """Relative RMS error over masked pixels and all wavelengths, reference variance removed."""
    rel = (image - reference)[mask] / reference[mask]
    rel_se = reference_se[mask] / reference[mask]
    return math.sqrt(max(float(np.mean(rel ** 2 - rel_se ** 2)), 0.0))


def time_integrator(scene, spp, reference, mask):
    render_sky(scene, spp=4, passes=2)                      # compile the kernels first
    sky = render_sky(scene, spp=spp, passes=4, seed=1)
    seconds = sky.metadata["render_time_s"]
    samples = scene.camera.width * scene.camera.height * spp
    return seconds, samples, relative_rms(sky.radiance, reference.radiance, reference.standard_error, mask)


def time_volpath(scene, spp, reference, mask):
    description = stock_volpath_scene(scene.atmosphere, scene.sun.zenith_deg, scene.sun.azimuth_deg,
                                      scene.observer.altitude_m, sensor_dict(scene.camera),
                                      max_depth=scene.render.max_depth)
    volpath = mi.load_dict(description)
    mi.render(volpath, spp=2, seed=99)                      # compile the kernels first
    start = time.perf_counter()
    image = mi.render(volpath, spp=spp, seed=1).numpy()[..., :3]
    seconds = time.perf_counter() - start
    samples = scene.camera.width * scene.camera.height * spp
    return seconds, samples, relative_rms(image, reference.radiance, reference.standard_error, mask)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer samples (a smoke run, noisy numbers)")
    args = parser.parse_args()
    scale = 1 if args.quick else 4

    rgb = scene_for("rgb")
    print("reference (integrator, many samples) ...", flush=True)
    reference = render_sky(rgb, spp=1024 * scale, passes=8, seed=12345)
    mask = error_mask(rgb, reference.directions)

    rows = []
    print("atmosphere integrator ...", flush=True)
    seconds, samples, err = time_integrator(rgb, 64 * scale, reference, mask)
    rows.append(("atmosphere integrator", "rgb (3)", samples, seconds, err))
    print("stock volpath + atmosphere_medium ...", flush=True)
    seconds, samples, err = time_volpath(rgb, 16 * scale, reference, mask)
    rows.append(("stock volpath + atmosphere_medium", "rgb (3)", samples, seconds, err))

    spectral = scene_for({"start_nm": 360.0, "stop_nm": 830.0, "step_nm": 10.0})
    print("spectral reference ...", flush=True)
    spectral_reference = render_sky(spectral, spp=256 * scale, passes=8, seed=12345)
    seconds, samples, err = time_integrator(spectral, 16 * scale, spectral_reference,
                                            error_mask(spectral, spectral_reference.directions))
    rows.append(("atmosphere integrator", "360-830 nm / 10 nm (48)", samples, seconds, err))

    def to_target(seconds, err):
        return seconds * (err / TARGET) ** 2 if err > 0 else float("nan")

    ratio = to_target(rows[1][3], rows[1][4]) / to_target(rows[0][3], rows[0][4])
    lines = [
        "# Ground truth speed: time to 1% relative RMS error",
        "",
        f"Generated by `python benchmarks/groundtruth_speed.py{' --quick' if args.quick else ''}` on "
        f"{datetime.date.today().isoformat()} ({platform.machine()}, {os.cpu_count()} cores, variant llvm_ad_rgb).",
        "",
        "Scene: bruneton2017, sun zenith 60 deg, observer 1 m, 128x64 equirectangular. Error: relative RMS",
        "over sky pixels (view zenith < 88 deg, > 3 deg from the sun) and wavelengths, against an",
        "integrator reference with its own variance removed; time to 1% = time x (error / 1%)^2.",
        "",
        "| estimator | wavelengths | samples | time (s) | samples/s | rel. RMS error | time to 1% (s) |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for name, grid, samples, seconds, err in rows:
        lines.append(f"| {name} | {grid} | {samples:,} | {seconds:.2f} | {samples / seconds:,.0f} | "
                     f"{100 * err:.2f}% | {to_target(seconds, err):,.1f} |")
    lines += ["", f"**Speed-up at equal error (RGB grid): {ratio:.1f}x** "
              "(volpath's time to 1% / the integrator's, same run).", ""]
    with atomic_write(RESULTS) as f:
        f.write("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
