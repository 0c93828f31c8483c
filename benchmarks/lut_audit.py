"""The LUT audit: Bruneton 2017, Elek 2009 / Bodare–Sandberg and Hillaire 2020 at their papers'
default settings against skyref's ground truth over the standard grid, then sweeps of table
resolution, scattering orders, sample counts and storage precision (speed against error).

Ground truth: ``grids/lut_audit.toml`` (168 skies: bruneton2017 and hillaire2020, each clear
and at turbidity 6; observer 0, 1, 10, 50, 100 and 1000 km; sun zenith 0-96 deg; 64x32
pixel-centre directions over the whole sphere, 17 wavelengths 380-780 nm), rendered by
``skyref batch`` (resumable; this script runs it first and it skips finished skies). The
finished skies ship in the repository, results/lut_audit/truth (a piece of the grid's output:
EXRs, markers, grid.json; about 0.35 MB a sky), and this script imports them into the grid's
output directory first (:func:`skyref.batch.merge.import_skies`, checked by SHA-256), so a fresh
clone rebuilds the report without rendering them again; ``--part ship`` copies the skies
finished since into it (:func:`skyref.batch.merge.export_skies`).

Per sky the methods are compared with :func:`skyref.audit.audit.compare`: luminance errors
(signed mean, noise-corrected RMS, p95, max) per region, CIEDE2000 on an absolute basis, each
beside the ground truth's own noise; statistics whose noise exceeds 1/5 of them are marked *.

Usage: ``python benchmarks/lut_audit.py`` (everything; hours on 2 cores, Bruneton's precompute
dominates). Parts can run separately: ``--part grid|sweeps`` and ``--methods NAME ...`` (the
sweeps render only their own 12 skies of the grid: hours on 2 cores at the grid's 0.3% target); each
part's numbers are kept in results/lut_audit/<part>_<method>.json and the report is rebuilt from
every JSON present, so a long audit can be completed in pieces. ``--rendered-only`` audits the
grid on the skies whose ground truth is already rendered and renders nothing (the report says how
many of each atmosphere's skies its rows cover), so a truth that takes days to render is audited
as it grows. ``--part polarized``: every method at the papers' settings against the polarized
truth's I as well, made from each scalar truth sky plus the change polarized transport makes,
rendered for it with the two transports on the same paths
(:func:`skyref.audit.groundtruth.with_polarization`; ``POLARIZATION_SPP`` samples per direction,
kept in out/lut-audit-polarization). Writes results/lut_audit.md, results/lut_audit.csv and
results/lut_audit/*.png.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from results_files import machine  # noqa: E402

from skyref.audit.audit import compare  # noqa: E402
from skyref.audit.groundtruth import polarization_change, with_polarization  # noqa: E402
from skyref.batch.provenance import describe_truth, truth_provenance  # noqa: E402
from skyref.batch import load_grid, run_batch  # noqa: E402
from skyref.batch.merge import LUT_AUDIT_TRUTH, export_skies, import_skies  # noqa: E402
from skyref.batch.store import BatchStore  # noqa: E402
from skyref.io.atomic import atomic_path, atomic_write  # noqa: E402
from skyref.io.exr import read_sky_exr  # noqa: E402
from skyref.lut import METHODS, lut_method  # noqa: E402

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
GRID = os.path.join(ROOT, "grids", "lut_audit.toml")
RESULTS = os.path.join(ROOT, "results")
#: The grid's finished skies, shipped in the repository (see the module docstring).
SHIPPED_TRUTH = os.path.join(ROOT, LUT_AUDIT_TRUTH)
#: The polarization change of each truth sky (:func:`polarization_change`): samples per
#: direction, seeds (above any the batch uses, clear of benchmarks/truth_check.py's) and where the
#: changes are kept (one .npz per sky, reused by later runs).
POLARIZATION_SPP = 2048
POLARIZATION_SEEDS = (1 << 30) + (1 << 20)
POLARIZATION_DIR = os.path.join(ROOT, "out", "lut-audit-polarization")

#: Bruneton 2017 on hazy skies, two mechanisms (issue 15): (A) 50 uniform steps along 300-900 km
#: horizon rays against a 1.2 km aerosol scale height; (B) 32 mu_s cells against the aerosol's
#: forward peak in the scattering density. The sweep entries that remove each, at the paper's sizes:
MECHANISM_A = "500 samples along rays (hazy)"
MECHANISM_B = "mu_s 128 (hazy)"
MECHANISMS_AB = "mu_s 128, 500 samples along rays (hazy)"

#: The grid's atmospheres (its ``atmosphere`` axis, in order) in the report's words.
ATMOSPHERE_LABELS = ("bruneton2017 clear", "bruneton2017 T=6", "hillaire2020 clear", "hillaire2020 T=6")

#: Regions whose errors the sweeps report (skyref.audit.regions), with their column titles.
SWEEP_REGIONS = (("sky", "sky"), ("horizon", "horizon"), ("sun", "sun"), ("antisolar", "anti-solar"))

#: The sweeps: per method, (label, options[, atmosphere]) entries; the papers' defaults are {}
#: (evaluated again on the sweep skies); the atmosphere is an index on the
#: grid's atmosphere axis (default 0, clear; 1: turbidity 6, where Bruneton's 50 samples along
#: rays under-resolve the dense haze near the ground). Bruneton's storage variants need no precomputation
#: of their own: "float16" and "combined Mie" are the paper-default tables re-read through
#: Bruneton2017.stored_as (see DERIVED), and report the precompute time of those tables.
SWEEPS = {
    "bruneton2017": [("paper (32x128x32x8, 4 orders)", {}),
                     ("table x0.5", {"r_size": 16, "mu_size": 64, "mu_s_size": 16, "nu_size": 4}),
                     ("1 order", {"scattering_orders": 1}), ("2 orders", {"scattering_orders": 2}),
                     ("float16", {"precision": "float16"}),
                     ("combined Mie", {"combined_mie": True}),
                     ("paper (hazy)", {}, 1),
                     ("table x0.5 (hazy)", {"r_size": 16, "mu_size": 64, "mu_s_size": 16, "nu_size": 4}, 1),
                     ("table x0.5, 500 samples along rays (hazy)", {"r_size": 16, "mu_size": 64, "mu_s_size": 16,
                                                                    "nu_size": 4, "integration_samples": 500}, 1),
                     (MECHANISM_A, {"integration_samples": 500}, 1),
                     (MECHANISM_B, {"mu_s_size": 128}, 1),
                     (MECHANISMS_AB, {"mu_s_size": 128, "integration_samples": 500}, 1)],
    "elek2009": [("paper (32x128x32, 4 orders)", {}),
                 ("table x0.5", {"scattering_size": (16, 64, 16)}),
                 ("table x2", {"scattering_size": (64, 256, 64)}),
                 ("1 order", {"scattering_orders": 1}), ("8 orders", {"scattering_orders": 8}),
                 ("Elek's Rayleigh phase", {"rayleigh_phase": "elek"}), ("float16", {"precision": "float16"})],
    "hillaire2020": [("reference (sky view 192x108, 4-14 samples)", {}),
                     ("sky view 30 samples", {"sky_view_samples": (30, 30)}),
                     ("sky view 128 samples", {"sky_view_samples": (128, 128)}),
                     ("sky view x0.5", {"sky_view_size": (96, 54)}),
                     ("sky view x2", {"sky_view_size": (384, 216)}),
                     ("multiple-scattering LUT 64x64", {"multiple_scattering_size": (64, 64)}),
                     ("single scattering only", {"multiple_scattering": False}),
                     ("float16", {"precision": "float16"})],
}


#: (method, sweep label) -> function of the paper-default method giving the variant.
DERIVED = {("bruneton2017", "float16"): lambda method: method.stored_as(precision="float16"),
           ("bruneton2017", "combined Mie"): lambda method: method.stored_as(combined_mie=True)}

#: Skies of the sweeps: clear bruneton2017, observer 0 and 10 km, sun zenith 30, 80, 92 deg.
SWEEP_SKIES = {"atmosphere": 0, "observer.altitude_m": (0.0, 10000.0), "sun.zenith_deg": (30.0, 80.0, 92.0)}


def truth_skies(grid, directory):
    """(index, coordinates, path) of every sky of the grid."""
    for spec in grid.skies():
        yield spec.index, spec.coordinates, os.path.join(directory, "skies", f"{spec.sky_id}.exr")


def rendered_skies(grid, directory):
    """:func:`truth_skies` whose ground truth is finished (its marker written, after its EXR)."""
    store = BatchStore(grid, directory=directory)
    return [sky for sky in truth_skies(grid, directory) if store.is_finished(grid.sky_id(sky[0]))]


def evaluate(name, options, skies, log, derive=None, built=None, truth_of=read_sky_exr):
    """Audit method ``name`` with ``options`` on ``skies`` (list of (index, coordinates, path)),
    building it once per atmosphere; with ``derive``, audit ``derive(method)`` instead, and keep
    the built methods in the dict ``built`` (atmosphere key -> method) for reuse; ``truth_of``:
    the truth Sky of a sky's EXR path. Returns one row per sky."""
    rows = []
    built = {} if built is None else built
    method, atmosphere_key = None, None
    for index, coordinates, path in skies:
        truth = truth_of(path)
        scene = truth.scene
        key = json.dumps(scene.atmosphere.to_dict(), sort_keys=True)
        if key != atmosphere_key:
            if key not in built:
                built.clear()   # one atmosphere's tables at a time
                built[key] = lut_method(name, scene.atmosphere, scene.wavelengths_nm, **options)
                built[key].precompute()
            method = derive(built[key]) if derive else built[key]
            precompute_s = built[key].precompute_seconds
            atmosphere_key = key
            log(f"  {name} {options or ''}: precompute {precompute_s:.1f} s ({scene.atmosphere.name})")
        found = compare(method, truth, scene)
        rows.append({"method": name, "options": options, "index": index, "coordinates": coordinates,
                     "precompute_s": precompute_s, "per_view_s": found["per_view_s"],
                     "lookup_ns": 1e9 * found["lookup_s_per_direction"],
                     "truth_spp": truth.metadata.get("spp"), "statistics": found["statistics"]})
    return rows


def polarization_path(path) -> str:
    """Where the polarization change of the truth sky in the EXR ``path`` is kept."""
    return os.path.join(POLARIZATION_DIR, os.path.basename(path).replace(".exr", f"-{POLARIZATION_SPP}spp.npz"))


def render_polarization_changes(skies, log) -> None:
    """The :func:`polarization_change` of each of ``skies`` ((index, coordinates, path)) that has
    none kept yet, rendered along the truth's own scene with POLARIZATION_SEEDS + index."""
    os.makedirs(POLARIZATION_DIR, exist_ok=True)
    for index, _, path in skies:
        target = polarization_path(path)
        if os.path.exists(target):
            continue
        scene = read_sky_exr(path).scene
        change, change_error, cpu_s = polarization_change(scene, POLARIZATION_SPP, POLARIZATION_SEEDS + index)
        with atomic_path(target) as tmp, open(tmp, "wb") as f:
            np.savez(f, change=change, change_error=change_error, cpu_s=cpu_s,
                     scene=json.dumps(scene.to_dict(), sort_keys=True))
        log(f"  polarization change of {os.path.basename(path)}: {cpu_s:.0f} CPU s")


def polarized_truth(path):
    """The polarized truth's I of the truth sky in the EXR ``path`` (:func:`with_polarization`),
    checked to be the change of that sky's scene."""
    truth = read_sky_exr(path)
    with np.load(polarization_path(path)) as kept:
        if str(kept["scene"]) != json.dumps(truth.scene.to_dict(), sort_keys=True):
            sys.exit(f"{polarization_path(path)} is the polarization change of another scene than {path}: "
                     "delete it and rerun --part polarized")
        return with_polarization(truth, kept["change"], kept["change_error"])


def evaluate_polarized(name, skies, log):
    """:func:`evaluate` of method ``name`` at the papers' settings against the polarized truth
    of ``skies``, each row with the CPU seconds of its sky's polarization change."""
    rows = evaluate(name, {}, skies, log, truth_of=polarized_truth)
    for row, (_, _, path) in zip(rows, skies):
        with np.load(polarization_path(path)) as kept:
            row["polarization_cpu_s"] = float(kept["cpu_s"])
    return rows


def polarized_table(grid, rows_by_method, polarized_by_method) -> list:
    """Each method's error against the scalar truth beside its error against the polarized
    truth's I, on the same skies, per atmosphere."""
    if not polarized_by_method:
        return []
    atmospheres = grid.axes["atmosphere"]
    first = next(iter(polarized_by_method.values()))
    lines = ["## Against the polarized truth", "",
             "The LUT methods transport scalar radiance; the trusted reference codes transport Stokes vectors, and "
             "multiple scattering of polarized light changes the radiance itself. Here each method's error against "
             "the scalar truth (left) and against the polarized truth's I (right), on the same skies: median over "
             "them (worst in parentheses), luminance RMS in %, noise-corrected. The polarized "
             "truth is each scalar truth sky plus the change polarized transport makes in it (Rayleigh phase matrix, "
             "depolarization 0 as the presets publish it; the aerosol's phase function scalar), rendered with the "
             f"two transports along the same paths, {POLARIZATION_SPP:,} samples per direction "
             f"({sum(r['polarization_cpu_s'] for r in first) / 3600.0:.2f} CPU hours for {len(first)} skies); "
             "their standard errors add in quadrature.", "",
             "| method | atmosphere | skies | sky RMS | horizon RMS | sun RMS | anti-solar RMS |",
             "|---|---|---:|---:|---:|---:|---:|"]
    for name, polarized_rows in polarized_by_method.items():
        scalar_rows = {r["index"]: r for r in rows_by_method.get(name, [])}
        for a, label in enumerate(ATMOSPHERE_LABELS):
            pol = [r for r in polarized_rows if r["coordinates"]["atmosphere"] == atmospheres[a]
                   and r["index"] in scalar_rows]
            if not pol:
                continue
            sca = [scalar_rows[r["index"]] for r in pol]

            def pair(region):
                medians = [_median(rows, region, "luminance", "rms") for rows in (sca, pol)]
                if not np.all(np.isfinite(medians)):
                    return "–"
                return " / ".join(f"{100 * median:.1f} ({100 * _worst(rows, region, 'luminance', 'rms'):.0f})"
                                  for median, rows in zip(medians, (sca, pol)))

            lines.append(f"| {name} | {label} | {len(pol)} | {pair('sky')} | {pair('horizon')} | {pair('sun')} "
                         f"| {pair('antisolar')} |")
    return lines + [""]


def _cell(stats, region="sky", metric="luminance", stat="rms"):
    entry = stats.get(region, {}).get(metric)
    if entry is None:
        return "–"
    value = entry[stat]
    text = f"{value:.2f}" if metric == "delta_e" else f"{100 * value:.1f}"
    return text + ("" if entry[f"resolved_{stat}"] else "*")


def _median(rows, region, metric, stat):
    values = [r["statistics"][region][metric][stat] for r in rows if region in r["statistics"]]
    return float(np.median(values)) if values else float("nan")


def _worst(rows, region, metric, stat):
    values = [r["statistics"][region][metric][stat] for r in rows if region in r["statistics"]]
    return float(np.max(values)) if values else float("nan")


def grid_tables(grid, rows_by_method):
    atmospheres = grid.axes["atmosphere"]
    observers = grid.axes["observer.altitude_m"]
    suns = grid.axes["sun.zenith_deg"]
    lines = ["## Summary (papers' default settings)", "",
             "Median over the skies of each atmosphere (worst sky in parentheses); luminance errors in %, "
             "RMS noise-corrected; CIEDE2000 absolute. Regions: sky = every view that misses the ground; "
             "horizon = 5 deg above it; sun = within 10 deg of the sun (disk excluded); anti-solar = within 30 "
             "deg of the anti-sun; ground = views that hit it; `–`: none of the skies has the region (a black ground, "
             "an anti-sun below the horizon).", "",
             "| method | atmosphere | precompute (s) | per view (ms) | lookup (ns/dir) | sky RMS | sky p95 | horizon RMS "
             "| sun RMS | anti-solar RMS | ground RMS | CIEDE2000 p95 |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    per_atmosphere = len(observers) * len(suns)
    for name, rows in rows_by_method.items():
        for a, label in enumerate(ATMOSPHERE_LABELS):
            sub = [r for r in rows if r["coordinates"]["atmosphere"] == atmospheres[a]]
            if not sub:
                continue
            if len(sub) < per_atmosphere:
                label += f" ({len(sub)} of {per_atmosphere} skies)"

            def fmt(region, stat="rms", metric="luminance", scale=100.0):
                median = _median(sub, region, metric, stat)
                if not np.isfinite(median):
                    return "–"
                return f"{scale * median:.1f} ({scale * _worst(sub, region, metric, stat):.0f})"

            lines.append(f"| {name} | {label} | {sub[0]['precompute_s']:.1f} | "
                         f"{1e3 * np.median([r['per_view_s'] for r in sub]):.0f} | {np.median([r['lookup_ns'] for r in sub]):.0f} "
                         f"| {fmt('sky')} | {fmt('sky', 'p95')} | {fmt('horizon')} | {fmt('sun')} | {fmt('antisolar')} "
                         f"| {fmt('ground')} | {fmt('sky', 'p95', 'delta_e', 1.0)} |")
    lines += ["", "## Sky luminance RMS error (%) by sun zenith and observer altitude", "",
              "`*`: not resolved (the ground truth's noise on it exceeds 1/5 of it, or most of the region's "
              "pixels were too noisy to measure: the ground truth needs more samples there); `–`: no lit sky "
              "pixels (from 1000 km no pixel centre of the 64x32 grid falls on the limb); blank: the sky's ground "
              "truth is not rendered yet.", ""]
    for name, rows in rows_by_method.items():
        for a, label in enumerate(ATMOSPHERE_LABELS):
            lookup = {(r["coordinates"]["observer.altitude_m"], r["coordinates"]["sun.zenith_deg"]): r
                      for r in rows if r["coordinates"]["atmosphere"] == atmospheres[a]}
            if not lookup:
                continue
            lines += [f"**{name}, {label}**", "",
                      "| observer \\ sun zenith | " + " | ".join(f"{z:g}°" for z in suns) + " |",
                      "|---|" + "---:|" * len(suns)]
            for h in observers:
                cells = [_cell(lookup[(h, z)]["statistics"]) if (h, z) in lookup else "" for z in suns]
                lines.append(f"| {h / 1000:g} km | " + " | ".join(cells) + " |")
            lines.append("")
    return lines


def plot_grid(grid, rows_by_method, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    observers = grid.axes["observer.altitude_m"]
    fig, axes = plt.subplots(1, len(rows_by_method), figsize=(5 * len(rows_by_method), 3.6), sharey=True,
                             constrained_layout=True)
    for ax, (name, rows) in zip(np.atleast_1d(axes), rows_by_method.items()):
        for h in observers:
            sub = [r for r in rows if r["coordinates"]["observer.altitude_m"] == h
                   and r["coordinates"]["atmosphere"] == grid.axes["atmosphere"][0] and "sky" in r["statistics"]]
            ax.plot([r["coordinates"]["sun.zenith_deg"] for r in sub],
                    [100 * r["statistics"]["sky"]["luminance"]["rms"] for r in sub], "o-", label=f"{h / 1000:g} km")
        ax.set_title(f"{name} (bruneton2017 clear)")
        ax.set_xlabel("sun zenith (deg)")
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("sky luminance RMS error (%)")
    np.atleast_1d(axes)[0].legend(title="observer", fontsize=8)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def sweep_skies(grid, directory, atmosphere: int):
    """(index, coordinates, path) of the sweep skies (SWEEP_SKIES) of the grid's ``atmosphere``."""
    return [s for s in truth_skies(grid, directory)
            if s[1]["atmosphere"] == grid.axes["atmosphere"][atmosphere]
            and s[1]["observer.altitude_m"] in SWEEP_SKIES["observer.altitude_m"]
            and s[1]["sun.zenith_deg"] in SWEEP_SKIES["sun.zenith_deg"]]


def sweep_indices(grid, directory) -> list:
    """Grid indices of the sweep skies of both atmospheres the sweeps use (clear and hazy)."""
    return sorted(index for atmosphere in (0, 1) for index, _, _ in sweep_skies(grid, directory, atmosphere))


def sweep(grid, directory, name, log):
    """The sweep points of method ``name`` (see SWEEPS) on the sweep skies of each entry's
    atmosphere: its cost, and the median over the skies of each SWEEP_REGIONS region's
    luminance RMS error (``<region>_rms``), the sky's p95 and CIEDE2000 p95."""
    default = {}   # the paper-default method, built once for the derived variants
    points = []
    for label, options, *rest in SWEEPS[name]:
        atmosphere = rest[0] if rest else SWEEP_SKIES["atmosphere"]
        skies = sweep_skies(grid, directory, atmosphere)
        derive = DERIVED.get((name, label))
        if derive is not None:
            rows = evaluate(name, {}, skies, log, derive=derive, built=default)
        else:
            rows = evaluate(name, options, skies, log, built=default if not options else None)
        points.append({"method": name, "label": label, "options": options, "atmosphere": atmosphere,
                       "measured": datetime.date.today().isoformat(),
                       "precompute_s": rows[0]["precompute_s"],
                       "lookup_ns": float(np.median([r["lookup_ns"] for r in rows])),
                       **{f"{region}_rms": _median(rows, region, "luminance", "rms") for region, _ in SWEEP_REGIONS},
                       "sky_p95": _median(rows, "sky", "luminance", "p95"),
                       "delta_e_p95": _median(rows, "sky", "delta_e", "p95")})
    return points


def mechanism_lines(points) -> list:
    """Which of Bruneton's two hazy-sky mechanisms limits which region: each region's error with
    the paper's settings, with (A) removed, (B) removed and both, from the sweep points."""
    by_label = {p["label"]: p for p in points if p["method"] == "bruneton2017"}
    labels = ("paper (hazy)", MECHANISM_A, MECHANISM_B, MECHANISMS_AB)
    if not all(label in by_label for label in labels):
        return []
    lines = ["**Bruneton 2017 on hazy skies: which mechanism limits which region.** (A): 50 uniform steps along "
             "rays hundreds of km long against a 1.2 km aerosol scale height (removed: 500 steps); (B): 32 mu_s "
             "cells against the aerosol's forward peak in the scattering density (removed: 128 cells). Median "
             "luminance RMS error (%) of the hazy sweep skies:", "",
             "| region | paper | (A) removed | (B) removed | both removed | limited by |", "|---|---:|---:|---:|---:|---|"]
    for region, title in SWEEP_REGIONS:
        paper, a, b, ab = (by_label[label][f"{region}_rms"] for label in labels)
        gain_a, gain_b = paper - a, paper - b
        if max(gain_a, gain_b) < 0.1 * paper:
            verdict = "neither (less than 1/10 of its error)"
        elif min(gain_a, gain_b) > 0.5 * max(gain_a, gain_b):
            verdict = "both"
        else:
            verdict = "(A) steps along rays" if gain_a > gain_b else "(B) mu_s cells"
        lines.append(f"| {title} | {100 * paper:.1f} | {100 * a:.1f} | {100 * b:.1f} | {100 * ab:.1f} | {verdict} |")
    return lines + [""]


def plot_pareto(points, path):
    """Sky error against precompute and lookup time of every sweep point, one colour and marker
    per method, each point labelled with its setting, no two labels overlapping
    (:func:`skyref.audit.map_report.labelled_pareto_figure`)."""
    import matplotlib.pyplot as plt

    from skyref.audit.map_report import labelled_pareto_figure

    panels = (("precompute time (s, 17 wavelengths)", [p["precompute_s"] for p in points]),
              ("lookup time (ns per direction, 17 wavelengths)", [p["lookup_ns"] for p in points]))
    fig = labelled_pareto_figure(panels, [100 * p["sky_rms"] for p in points], [p["method"] for p in points],
                                 {name: (marker, f"C{i}") for i, (name, marker) in enumerate(zip(SWEEPS, "osD"))},
                                 [p["label"] for p in points], "sky luminance RMS error (%), median of 6 skies")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi="figure", format="png")
    plt.close(fig)


def _json_path(part, method):
    return os.path.join(RESULTS, "lut_audit", f"{part}_{method}.json")


def _save(part, method, data):
    with atomic_write(_json_path(part, method)) as f:
        json.dump(data, f, default=float)


def _load(part):
    found = {}
    for name in METHODS:
        if os.path.exists(_json_path(part, name)):
            with open(_json_path(part, name)) as f:
                found[name] = json.load(f)
    return found


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--part", choices=("all", "grid", "sweeps", "polarized", "report", "ship"), default="all")
    parser.add_argument("--methods", nargs="*", default=list(METHODS))
    parser.add_argument("--rendered-only", action="store_true",
                        help="render nothing; audit the grid on the skies already rendered (the sweeps still "
                             "need all of theirs)")
    args = parser.parse_args()
    grid = load_grid(GRID)
    log = print
    os.makedirs(os.path.join(RESULTS, "lut_audit"), exist_ok=True)
    if args.part == "ship":
        export_skies(grid, SHIPPED_TRUTH, log=log)
        return
    if os.path.isdir(SHIPPED_TRUTH):
        import_skies(grid, SHIPPED_TRUTH, log=log, parameter="results/lut_audit/truth")
    directory = grid.output.directory
    if args.part != "report":
        # The sweeps need only their own skies of the grid; the grid part needs all of them, or
        # with --rendered-only none (it audits those there are).
        needed = sweep_indices(grid, directory) if args.part == "sweeps" else list(range(len(grid)))
        if args.rendered_only:
            needed = sweep_indices(grid, directory) if args.part in ("all", "sweeps") else []
        else:
            run_batch(grid, log=log, indices=needed)
        rendered = {index for index, _, _ in rendered_skies(grid, directory)}
        missing = [index for index in needed if index not in rendered]
        if missing:
            sys.exit(f"ground truth incomplete: {len(missing)} of {len(needed)} skies missing; rerun to resume")
    for name in args.methods:
        if args.part in ("all", "grid"):
            log(f"{name}: the standard grid")
            _save("grid", name, evaluate(name, {}, rendered_skies(grid, directory), log))
        if args.part in ("all", "sweeps"):
            log(f"{name}: sweeps")
            _save("sweeps", name, sweep(grid, directory, name, log))
    if args.part in ("all", "polarized"):
        skies = rendered_skies(grid, directory)
        log(f"polarization changes of {len(skies)} skies")
        render_polarization_changes(skies, log)
        for name in args.methods:
            log(f"{name}: against the polarized truth")
            _save("polarized", name, evaluate_polarized(name, skies, log))
    write_report(grid)


def write_report(grid):
    rows_by_method = _load("grid")
    points = [p for name in METHODS for p in _load("sweeps").get(name, [])]
    if rows_by_method:
        plot_grid(grid, rows_by_method, os.path.join(RESULTS, "lut_audit", "error_vs_sun.png"))
    if points:
        plot_pareto(points, os.path.join(RESULTS, "lut_audit", "pareto.png"))
    # The truth the rows were measured on: the skies of the grid rows and of the sweeps.
    audited = {r["index"] for rows in rows_by_method.values() for r in rows}
    if points:
        audited |= set(sweep_indices(grid, grid.output.directory))
    truth = describe_truth(truth_provenance(path for index, _, path in truth_skies(grid, grid.output.directory)
                                            if index in audited))
    skies = f"{len(grid)} skies" if len(audited) == len(grid) else f"{len(audited)} of its {len(grid)} skies so far"
    lines = ["# LUT audit: Bruneton 2017, Elek 2009 / Bodare–Sandberg, Hillaire 2020 vs skyref's ground truth", "",
             f"Generated by `python benchmarks/lut_audit.py` (report rebuilt {datetime.date.today()}; "
             f"{machine()}, CPU LLVM backend, double-precision lookups) from the "
             f"ground truth of `skyref batch grids/lut_audit.toml` ({skies}; {truth}). "
             "Methods in this report: "
             + (", ".join(rows_by_method) or "none yet") + ".", "",
             "Every method gets the same `Atmosphere`, the same 17 wavelengths (380–780 nm) and the same view "
             "directions (64x32 over the sphere) as the path tracer; the solar disk is excluded from both. "
             "Method notes: each method's module docstring (skyref/lut/*.py) states what its paper leaves open "
             "and what was chosen. Per view: the tables a frame rebuilds when the observer or sun moves "
             "(Hillaire's sky view, Elek's aerial-perspective volume). How far the truth's own error bars hold: "
             "[truth_check.md](truth_check.md) (16 views of every sky rendered again at a count their own samples "
             "do not set).", "",
             *grid_tables(grid, rows_by_method), "![error vs sun zenith](lut_audit/error_vs_sun.png)", "",
             *polarized_table(grid, rows_by_method, _load("polarized"))]
    if points:
        lines += ["## Sweeps: speed against error", "",
                  "Bruneton 2017's atmosphere, clear unless marked (hazy): turbidity 6; observer 0 and 10 km, sun "
                  "zenith 30, 80 and 92 deg (6 skies); errors are medians over them (noise-corrected RMS of the "
                  "relative luminance error per region, regions as above). Precompute times of storage variants "
                  "(float16, combined Mie) are those of the float32 tables they re-store. Measured: the date of the "
                  "run that produced the row (each method's sweeps run as one part; `–`: before the column existed).",
                  "",
                  "| method | setting | measured | precompute (s) | lookup (ns/dir) | "
                  + " | ".join(f"{title} RMS (%)" for _, title in SWEEP_REGIONS) + " | sky p95 (%) | CIEDE2000 p95 |",
                  "|---|---|---|---:|---:|" + "---:|" * (len(SWEEP_REGIONS) + 2)]
        lines += [f"| {p['method']} | {p['label']} | {p.get('measured', '–')} | {p['precompute_s']:.1f} | "
                  f"{p['lookup_ns']:.0f} | "
                  + " | ".join(f"{100 * p.get(f'{region}_rms', float('nan')):.2f}" for region, _ in SWEEP_REGIONS)
                  + f" | {100 * p['sky_p95']:.2f} | {p['delta_e_p95']:.2f} |" for p in points]
        lines += ["", *mechanism_lines(points), "![Pareto](lut_audit/pareto.png)", ""]
    with atomic_write(os.path.join(RESULTS, "lut_audit.md")) as f:
        f.write("\n".join(lines))
    with atomic_write(os.path.join(RESULTS, "lut_audit.csv"), "w") as f:
        writer = csv.writer(f)
        writer.writerow(["method", "atmosphere", "observer_altitude_m", "sun_zenith_deg", "region", "metric",
                         "mean", "rms", "p95", "max", "noise_rms", "noise_p95", "precompute_s", "lookup_ns"])
        for name, rows in rows_by_method.items():
            for r in rows:
                for region, row in r["statistics"].items():
                    for metric in ("luminance", "spectral", "delta_e"):
                        e = row[metric]
                        writer.writerow([name, json.dumps(r["coordinates"]["atmosphere"], sort_keys=True),
                                         r["coordinates"]["observer.altitude_m"], r["coordinates"]["sun.zenith_deg"],
                                         region, metric, e["mean"], e["rms"], e["p95"], e["max"], e["noise_rms"],
                                         e["noise_p95"], r["precompute_s"], r["lookup_ns"]])
    print("\n".join(lines[:22]))


if __name__ == "__main__":
    main()
