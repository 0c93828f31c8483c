"""skyref's polarized ground truth against the IPRT intercomparison (phase A/B, MYSTIC), every
direction of the result files, and what scalar transport gets wrong there.

Per setting (case, depolarization, output level, sun; tests/references/iprt.py says what each
case is and which are not set up): skyref's Stokes vectors at a relative standard error of I of
``--target`` per direction (``iprt.BATCHES`` batches), z-scores of I, Q, U, V against MYSTIC with the combined
standard errors, the RMS relative difference of I, and the CPU time. Then, on case A1 (one
Rayleigh layer of optical thickness 0.5, sun at the zenith), scalar transport's I against the
polarized I by view zenith, the difference the issue measured with DISORT.

Every direction of the files takes about 8.5 CPU hours (2 cores; the B cases' 30-layer profile
costs the line integral ~20 us a sample, and delta tracking is no cheaper to the same error), more
than one sitting, so runs can take a part of the rows each and add up: each direction's estimate
is kept in ``results/iprt/directions_<estimator>_<target>.json`` (committed with the report), a
later run replaces the directions it estimates again, and the report is made from every
direction kept for the run's estimator and target, saying how many of each file's it covers.

Usage: ``python benchmarks/iprt.py [--stride S] [--offset K] [--target T] [--cases a1,b2,...] [--estimator E]``
(rows K, K + S, K + 2S, ... of each setting (the seed is K), of the given cases, by the line
integral or delta tracking; default every row of every case at 0.1%, line integral: ``--stride 30``
with offsets 0 to 29 in turn covers every direction too); writes ``results/iprt.md`` and
``results/iprt.json`` (``{"cases": {name: {"max_abs_z": ..., "rms_rel_diff_I": ..., ...}}}``).
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

from results_files import RESULTS, machine, write_results  # noqa: E402

from skyref.io.atomic import atomic_write  # noqa: E402
from skyref.scene import DEFAULT_ESTIMATOR, ESTIMATORS  # noqa: E402
from tests.references import iprt  # noqa: E402

#: Where each direction's estimate is kept (see the module docstring).
DIRECTIONS_DIR = os.path.join(RESULTS, "iprt")


def directions_path(estimator: str, target: float) -> str:
    return os.path.join(DIRECTIONS_DIR, f"directions_{estimator}_{target:g}.json")


def load_directions(path) -> dict:
    """{setting name: {row number in the setting's block (str): record}} kept in ``path``."""
    if not os.path.exists(path):
        return {}
    with open(path) as f:
        return json.load(f)["settings"]


def save_directions(path, estimator: str, target: float, kept: dict) -> None:
    """Write ``kept`` (as :func:`load_directions` returns it) atomically, one direction a line."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with atomic_write(path) as f:
        f.write(f'{{"estimator": {json.dumps(estimator)}, "target": {json.dumps(target)}, "settings": {{')
        for i, (name, records) in enumerate(kept.items()):
            lines = ",\n".join(f"  {json.dumps(n)}: {json.dumps(records[n])}" for n in sorted(records, key=int))
            f.write(f'{"," if i else ""}\n {json.dumps(name)}: {{\n{lines}\n }}')
        f.write("\n}}\n")


def estimate_directions(setting, numbers, target, estimator, seed) -> dict:
    """skyref's Stokes vectors for the rows ``numbers`` of ``setting``'s block: {row number (str):
    {"mean": I, Q, U, V, "se": their standard errors, "samples", "cpu_seconds" (the run's CPU
    shared evenly among its directions), "seed", "date"}}."""
    start = time.process_time()
    mean, se, samples = iprt.estimate(setting, setting.rows[numbers], target, seed=seed, estimator=estimator)
    share = (time.process_time() - start) / len(numbers)
    today = str(datetime.date.today())
    return {str(int(n)): {"mean": [float(f"{x:.7g}") for x in m], "se": [float(f"{x:.4g}") for x in e],
                          "samples": int(k), "cpu_seconds": round(share, 3), "seed": seed, "date": today}
            for n, m, e, k in zip(numbers, mean, se, samples)}


def compare(setting, records: dict) -> dict:
    """The comparison with MYSTIC over the directions of ``setting`` that ``records`` holds."""
    numbers = sorted(int(n) for n in records)
    out = {"directions": len(numbers), "directions_in_file": int(len(setting.rows))}
    if not numbers:
        return out
    rows = setting.rows[numbers]
    kept = [records[str(n)] for n in numbers]
    mean = np.array([k["mean"] for k in kept])
    se = np.array([k["se"] for k in kept])
    z = iprt.z_scores(mean, se, rows)
    lit = rows[:, 6] > 0.0
    rel = mean[lit, 0] / rows[lit, 6] - 1.0
    return {**out, "max_abs_z": float(np.abs(z).max()),
            "max_abs_z_by_component": {c: float(np.abs(z[:, i]).max()) for i, c in enumerate("IQUV")},
            "share_abs_z_above_3": float(np.mean(np.abs(z[lit]) > 3.0)),
            "mean_z_I": float(z[lit, 0].mean()), "rms_rel_diff_I": float(np.sqrt(np.mean(rel ** 2))),
            "median_rel_se_I": float(np.median(se[lit, 0] / mean[lit, 0])),
            "samples_per_direction": float(np.mean([k["samples"] for k in kept])),
            "cpu_seconds": float(sum(k["cpu_seconds"] for k in kept)),
            "dates": sorted({k["date"] for k in kept})}


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
    covered = sum(r["directions"] for r in report["cases"].values())
    in_files = sum(r["directions_in_file"] for r in report["cases"].values())
    lines = ["# skyref vs. IPRT (MYSTIC): polarized ground truth", "",
             f"Made {report['date']} from the directions that runs of `python benchmarks/iprt.py` have estimated "
             f"({covered:,} of the files' {in_files:,}; each setting's dates below; the last run: "
             f"`{report['arguments'] or '(no arguments)'}`, on {report['machine']}, "
             "llvm_ad_rgb). Cases as in `tests/references/iprt.py` (IPRT phase A/B, Emde et al. 2015; "
             f"MYSTIC results CC BY-SA 3.0, the IPRT project); plane-parallel, the {report['estimator'].replace('_', ' ')} "
             "estimator with Stokes vectors, "
             f"relative standard error of I {report['target'] * 100:g}% per direction ({iprt.BATCHES} batches); z-scores "
             "against MYSTIC with the combined standard errors. Not set up: B3 (spheroidal aerosol, no phase "
             "matrix here), B4 (ocean surface).", "",
             "| setting | directions (of the file's) | max abs z (I / Q / U / V) | share abs z > 3 | mean z of I "
             "| RMS rel. diff. I | median rel. SE I | samples / direction | CPU s | estimated |",
             "|---|---:|---|---:|---:|---:|---:|---:|---:|---|"]
    for name, r in report["cases"].items():
        count = f"{r['directions']:,} ({r['directions_in_file']:,})"
        if not r["directions"]:
            lines.append(f"| {name} | {count} | – | – | – | – | – | – | – | not yet |")
            continue
        z = r["max_abs_z_by_component"]
        lines.append(f"| {name} | {count} | {z['I']:.2f} / {z['Q']:.2f} / {z['U']:.2f} / {z['V']:.2f} | "
                     f"{r['share_abs_z_above_3'] * 100:.2f}% | {r['mean_z_I']:+.2f} | {r['rms_rel_diff_I'] * 100:.3f}% | "
                     f"{r['median_rel_se_I'] * 100:.3f}% | {r['samples_per_direction']:.3g} | {r['cpu_seconds']:.0f} | "
                     f"{' to '.join(dict.fromkeys((r['dates'][0], r['dates'][-1])))} |")
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
    parser.add_argument("--stride", type=int, default=1, help="every S-th row of each setting")
    parser.add_argument("--offset", type=int, default=0, help="starting at row K (0 <= K < S); the seed is K")
    parser.add_argument("--target", type=float, default=0.001, help="relative standard error of I")
    parser.add_argument("--cases", default=",".join(iprt.CASES), help="comma-separated IPRT cases")
    parser.add_argument("--estimator", default=DEFAULT_ESTIMATOR, choices=ESTIMATORS,
                        help="skyref's estimator (default: the ground truth's, the line integral)")
    args = parser.parse_args()
    cases = args.cases.split(",")
    unknown = sorted(set(cases) - set(iprt.CASES))
    if unknown:
        parser.error(f"--cases: {', '.join(unknown)} not among {', '.join(iprt.CASES)}")
    if args.stride < 1:
        parser.error(f"--stride: {args.stride} is not >= 1")
    if not 0 <= args.offset < args.stride:
        parser.error(f"--offset: {args.offset} is not in [0, {args.stride - 1}] (0 <= offset < stride)")
    if not 0.0 < args.target < 1.0:
        parser.error(f"--target: {args.target} is not in (0, 1)")
    path = directions_path(args.estimator, args.target)
    kept = load_directions(path)
    for case in cases:
        for setting in iprt.settings(case):
            numbers = np.arange(args.offset, len(setting.rows), args.stride)
            kept.setdefault(setting.name, {}).update(
                estimate_directions(setting, numbers, args.target, args.estimator, args.offset))
            print(setting.name, json.dumps(compare(setting, kept[setting.name])), flush=True)
            save_directions(path, args.estimator, args.target, kept)   # after each setting: a killed run keeps them
    earlier = _earlier_report(args.estimator, args.target)
    report = {"date": datetime.datetime.now().isoformat(timespec="minutes"), "machine": machine(),
              "arguments": " ".join(sys.argv[1:]), "target": args.target, "estimator": args.estimator,
              "cases": {setting.name: compare(setting, kept.get(setting.name, {}))
                        for case in iprt.CASES for setting in iprt.settings(case)}}
    report["scalar_vs_polarized_a1"] = (scalar_error_a1(args.target, args.estimator)
                                        if "a1" in cases or "scalar_vs_polarized_a1" not in earlier
                                        else earlier["scalar_vs_polarized_a1"])
    write_results("iprt", report, markdown(report))


def _earlier_report(estimator: str, target: float) -> dict:
    """results/iprt.json if it was made for ``estimator`` and ``target``, else {}."""
    try:
        with open(os.path.join(RESULTS, "iprt.json")) as f:
            earlier = json.load(f)
    except FileNotFoundError:
        return {}
    return earlier if (earlier.get("estimator"), earlier.get("target")) == (estimator, target) else {}


if __name__ == "__main__":
    main()
