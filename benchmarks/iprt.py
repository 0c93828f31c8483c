"""skyref's polarized ground truth against the IPRT intercomparison (phase A/B, MYSTIC), every
direction of the result files, and what scalar transport gets wrong there.

Per setting (case, depolarization, output level, sun; tests/references/iprt.py says what each
case is and which are not set up): skyref's Stokes vectors at a relative standard error of I of
TARGET per direction (16 batches), z-scores of I, Q, U, V against MYSTIC with the combined
standard errors, the RMS relative difference of I, and the CPU time. Then, on case A1 (one
Rayleigh layer of optical thickness 0.5, sun at the zenith), scalar transport's I against the
polarized I by view zenith, the difference the issue measured with DISORT.

Usage: ``python benchmarks/iprt.py [--stride K] [--target T] [--cases a1,b2,...] [--estimator E]``
(every K-th row of each file, of the given cases, by the line integral or delta tracking;
default every row of every case at 0.1%, line integral); writes ``results/iprt.md`` and ``results/iprt.json``
(``{"cases": {name: {"max_abs_z": ..., "rms_rel_diff_I": ..., ...}}}``).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from results_files import machine, write_results  # noqa: E402

from skyref.scene import DEFAULT_ESTIMATOR, ESTIMATORS  # noqa: E402
from tests.references import iprt  # noqa: E402


def compare(setting, rows, target, estimator):
    start = time.process_time()
    mean, se, samples = iprt.estimate(setting, rows, target, estimator=estimator)
    seconds = time.process_time() - start
    z = iprt.z_scores(mean, se, rows)
    lit = rows[:, 6] > 0.0
    rel = mean[lit, 0] / rows[lit, 6] - 1.0
    return {"directions": int(len(rows)), "max_abs_z": float(np.abs(z).max()),
            "max_abs_z_by_component": {c: float(np.abs(z[:, i]).max()) for i, c in enumerate("IQUV")},
            "share_abs_z_above_3": float(np.mean(np.abs(z[lit]) > 3.0)),
            "mean_z_I": float(z[lit, 0].mean()), "rms_rel_diff_I": float(np.sqrt(np.mean(rel ** 2))),
            "median_rel_se_I": float(np.median(se[lit, 0] / mean[lit, 0])),
            "samples_per_direction": float(samples.mean()), "cpu_seconds": seconds}


def scalar_error_a1(target, estimator):
    """Scalar I / polarized I - 1 on A1 (depolarization 0, sun at the zenith), bottom, by view
    zenith (azimuthally symmetric: one azimuth)."""
    setting = iprt.settings("a1")[0]
    rows = setting.rows[setting.rows[:, 5] == 0.0]
    polarized, polarized_se, _ = iprt.estimate(setting, rows, target, estimator=estimator)
    from skyref.atmosphere import solar_irradiance
    from skyref.render import build_integrator
    from skyref.scene import Observer, Scene, Sun

    scene = Scene(atmosphere=iprt.atmosphere(setting), sun=Sun(0.0, 65.0), observer=Observer(0.0),
                  wavelengths=[iprt.WAVELENGTH_NM["a1"]])
    scalar_integrator = build_integrator(scene, geometry="plane_parallel", estimator=estimator)
    batches = scalar_integrator.render_directions(iprt.directions(rows), seed=11, spp=1 << 16, batches=16).numpy()
    sky = batches[:, :, 1:, 0].sum(axis=2) / float(np.asarray(solar_irradiance([iprt.WAVELENGTH_NM["a1"]]))[0])
    scalar, scalar_se = sky.mean(axis=0), sky.std(axis=0, ddof=1) / 4.0
    difference = scalar / polarized[:, 0] - 1.0
    se = np.hypot(scalar_se / scalar, polarized_se[:, 0] / polarized[:, 0])
    return [{"view_zenith_deg": float(v), "scalar_over_polarized_minus_1": float(x), "se": float(s),
             "mystic_I": float(m)} for v, x, s, m in zip(rows[:, 4], difference, se, rows[:, 6])]


def markdown(report):
    lines = ["# skyref vs. IPRT (MYSTIC): polarized ground truth", "",
             f"Produced {report['date']} by `python benchmarks/iprt.py {report['arguments']}` on {report['machine']} "
             "(llvm_ad_rgb, 2 cores). Cases as in `tests/references/iprt.py` (IPRT phase A/B, Emde et al. 2015; "
             f"MYSTIC results CC BY-SA 3.0, the IPRT project); plane-parallel, the {report['estimator'].replace('_', ' ')} "
             "estimator with Stokes vectors, "
             f"relative standard error of I {report['target'] * 100:g}% per direction (16 batches); z-scores "
             "against MYSTIC with the combined standard errors. Not set up: B3 (spheroidal aerosol, no phase "
             "matrix here), B4 (ocean surface).", "",
             "| setting | directions | max abs z (I / Q / U / V) | share abs z > 3 | mean z of I | RMS rel. diff. I "
             "| median rel. SE I | samples / direction | CPU s |", "|---|---:|---|---:|---:|---:|---:|---:|---:|"]
    for name, r in report["cases"].items():
        z = r["max_abs_z_by_component"]
        lines.append(f"| {name} | {r['directions']} | {z['I']:.2f} / {z['Q']:.2f} / {z['U']:.2f} / {z['V']:.2f} | "
                     f"{r['share_abs_z_above_3'] * 100:.2f}% | {r['mean_z_I']:+.2f} | {r['rms_rel_diff_I'] * 100:.3f}% | "
                     f"{r['median_rel_se_I'] * 100:.3f}% | {r['samples_per_direction']:.3g} | {r['cpu_seconds']:.0f} |")
    lines += ["", "## What scalar transport gets wrong (A1: Rayleigh, optical thickness 0.5, sun at the zenith, "
              "seen from the bottom)", "", "| view zenith | scalar I / polarized I - 1 | s.e. |", "|---:|---:|---:|"]
    for r in report["scalar_vs_polarized_a1"]:
        lines.append(f"| {abs(r['view_zenith_deg']):.0f} | {r['scalar_over_polarized_minus_1'] * 100:+.2f}% | "
                     f"{r['se'] * 100:.2f}% |")
    lines += ["", "Scalar transport (the LUT methods' and the analytic models' physics, and skyref's default mode) "
              "treats Rayleigh scattering with its phase function P11 alone; the polarization that single "
              "scattering creates changes how much light the second and later scatterings send each way."]
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stride", type=int, default=1, help="every K-th row of each result file")
    parser.add_argument("--target", type=float, default=0.001, help="relative standard error of I")
    parser.add_argument("--cases", default=",".join(iprt.CASES), help="comma-separated IPRT cases")
    parser.add_argument("--estimator", default=DEFAULT_ESTIMATOR, choices=ESTIMATORS,
                        help="skyref's estimator (default: the ground truth's, the line integral)")
    args = parser.parse_args()
    unknown = sorted(set(args.cases.split(",")) - set(iprt.CASES))
    if unknown:
        parser.error(f"--cases: {', '.join(unknown)} not among {', '.join(iprt.CASES)}")
    report = {"date": datetime.datetime.now().isoformat(timespec="minutes"), "machine": machine(),
              "arguments": " ".join(sys.argv[1:]), "target": args.target, "estimator": args.estimator, "cases": {}}
    for case in args.cases.split(","):
        for setting in iprt.settings(case):
            rows = setting.rows[::args.stride]
            report["cases"][setting.name] = compare(setting, rows, args.target, args.estimator)
            print(setting.name, json.dumps(report["cases"][setting.name]), flush=True)
    report["scalar_vs_polarized_a1"] = scalar_error_a1(args.target, args.estimator)
    write_results("iprt", report, markdown(report))


if __name__ == "__main__":
    main()
