"""``skyref report``: the speed-vs-error map (:mod:`skyref.audit.speed_map`) written out as
``results/README.md`` (one table of every method, the index of the other reports), a Pareto plot
(``results/report/pareto.png``), a contact sheet of the same skies by every method with their
error maps (``results/report/contact_sheet.png``) and the numbers ``skyref advise`` reads
(``results/report/map.json``). Every number is computed by the code from the cached rows.
"""

from __future__ import annotations

import datetime
import json
import os
import platform

import numpy as np

from skyref.audit.speed_map import FRAME_DIRECTIONS, KINDS, MAP_SKIES, cache_path, load_cached
from skyref.color import default_exposure, spectral_to_linear_srgb, srgb_luminance, tonemap_srgb8
from skyref.io.atomic import atomic_path, atomic_write
from skyref.io.exr import read_sky_exr

__all__ = ["ERROR_SCALE", "OTHER_REPORTS", "contact_entries", "map_table", "plot_contact_sheet", "plot_pareto",
           "write_map_report"]

#: Relative luminance error at the ends of the contact sheet's colour scale.
ERROR_SCALE = 0.25
#: Other reports of results/, indexed by README.md: (file, what it holds).
OTHER_REPORTS = (("lut_audit.md", "LUT methods over the standard grid (168 skies) with resolution / order / "
                  "precision sweeps: `python benchmarks/lut_audit.py`"),
                 ("fit_report.md", "Hosek–Wilkie and Perez fits against the ground truth and the published "
                  "model: `python benchmarks/fit_report.py`"),
                 ("groundtruth_speed.md", "the path tracer against stock Mitsuba volpath at equal error: "
                  "`python benchmarks/groundtruth_speed.py`"),
                 ("batch_scaling.md", "batch generation overhead and scaling: `python benchmarks/batch_scaling.py`"))


def _percent(value, resolved=True) -> str:
    return "–" if value is None else f"{100 * value:.1f}" + ("" if resolved else "*")


def map_table(summaries: list[dict]) -> list[str]:
    lines = ["| family | method | setting | precompute (s) | per view (ms) | lookup (ns/dir) | HD frame (s) | "
             + " | ".join(KINDS) + " | CIEDE2000 p95 | worst region |",
             "|---|---|---|---:|---:|---:|---:|" + "---:|" * len(KINDS) + "---:|---|"]
    for s in summaries:
        if "frame_s" not in s:
            lines.append(f"| {s['family']} | {s['method']} | {s['label']} | refused every sky |" + " |" * (len(KINDS) + 5))
            continue
        kinds = []
        for kind in KINDS:
            k = s["kinds"].get(kind)
            kinds.append("refused" if k is None else _percent(k["rms"], k["resolved"]) + (" (part)" if k["partial"] else ""))
        worst = s["worst_region"]
        lines.append(f"| {s['family']} | {s['method']} | {s['label']} | {s['precompute_s']:.3g} | "
                     f"{1e3 * s['per_view_s']:.3g} | {1e9 * s['lookup_s']:.3g} | {s['frame_s']:.3g} | "
                     + " | ".join(kinds) + f" | {s['delta_e_p95_median']:.2f} | "
                     f"{worst['region']} {100 * worst['rms']:.0f}% ({worst['sky']}) |")
    return lines


def plot_pareto(summaries: list[dict], path: str):
    # Lazy: selecting the Agg backend is a side effect, made only when plots are written.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    families = {"path tracer": ("o", "C0"), "LUT": ("s", "C1"), "analytic": ("D", "C2")}
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), sharey=True, constrained_layout=True)
    panels = ((axes[0], lambda s: s["frame_s"], f"one frame of {FRAME_DIRECTIONS:,} directions from scratch (s)"),
              (axes[1], lambda s: s["per_view_s"] + FRAME_DIRECTIONS * s["lookup_s"],
               "each further frame, tables kept (s)"))
    for ax, cost, xlabel in panels:
        seen = set()
        for s in summaries:
            if "frame_s" not in s:
                continue
            marker, colour = families[s["family"]]
            ax.scatter(cost(s), 100 * s["sky_rms_median"], marker=marker, color=colour, s=40,
                       label=None if s["family"] in seen else s["family"])
            seen.add(s["family"])
            ax.annotate(f"{s['method']} {s['label']}", (cost(s), 100 * s["sky_rms_median"]), fontsize=6,
                        xytext=(3, 3), textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3, which="both")
    axes[0].set_ylabel("sky luminance RMS error (%), median of the map's skies")
    axes[0].legend()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)


def contact_entries(entries) -> list:
    """The first setting of every method (its default), in map order."""
    first = {}
    for entry in entries:
        first.setdefault((entry.method, entry.label if entry.method == "hosek2012" else ""), entry)
    return list(first.values())


def plot_contact_sheet(entries, skies, cache_dir: str, path: str):
    """Rows: the ground truth, then every method's default setting; per sky two columns: the
    tone-mapped image (the truth's exposure) and the relative luminance error."""
    # Lazy: selecting the Agg backend is a side effect, made only when plots are written.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sheet_skies = [next((s, p) for s, p in skies if s.kind == kind) for kind in KINDS]
    truths = []
    for _, sky_path in sheet_skies:
        truth = read_sky_exr(sky_path)
        rgb = spectral_to_linear_srgb(truth.radiance - truth.orders.get("sun_direct", 0.0), truth.wavelengths_nm)
        truths.append((rgb, default_exposure(rgb)))
    rows = [("ground truth", None)] + [(f"{e.method}\n{e.label}", e) for e in contact_entries(entries)]
    fig, axes = plt.subplots(len(rows), 2 * len(sheet_skies), figsize=(4.2 * len(sheet_skies), 1.15 * len(rows)),
                             constrained_layout=True)
    image = None
    for i, (label, entry) in enumerate(rows):
        for j, ((sky, _), (truth_rgb, exposure)) in enumerate(zip(sheet_skies, truths)):
            ax_image, ax_error = axes[i, 2 * j], axes[i, 2 * j + 1]
            for ax in (ax_image, ax_error):
                ax.set_xticks([])
                ax.set_yticks([])
            if i == 0:
                ax_image.set_title(sky.name, fontsize=8)
                ax_error.set_title("relative luminance error", fontsize=7)
            if j == 0:
                ax_image.set_ylabel(label, fontsize=7, rotation=0, ha="right", va="center")
            rgb = truth_rgb
            if entry is not None:
                cached = cache_path(cache_dir, entry, sky)
                rgb = load_cached(cached)[1] if os.path.exists(cached) else None
            if rgb is None:
                ax_image.text(0.5, 0.5, "refused / not run", ha="center", va="center", fontsize=7)
                ax_error.set_facecolor("0.85")
                continue
            rgb = np.asarray(rgb, dtype=np.float64)
            ax_image.imshow(tonemap_srgb8(rgb, exposure), interpolation="nearest", aspect="auto")
            if entry is None:
                ax_error.set_facecolor("white")
                continue
            with np.errstate(divide="ignore", invalid="ignore"):
                error = srgb_luminance(rgb) / srgb_luminance(truth_rgb) - 1.0
            image = ax_error.imshow(error, cmap="RdBu_r", vmin=-ERROR_SCALE, vmax=ERROR_SCALE,
                                    interpolation="nearest", aspect="auto")
    if image is not None:
        fig.colorbar(image, ax=axes[:, -1], shrink=0.3, label="method / truth - 1 (luminance)")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=80, format="png")
    plt.close(fig)


def write_map_report(entries, skies, rows, summaries, cache_dir: str, results_dir: str = "results") -> str:
    """Write map.json, the plots and results/README.md; returns the README's path."""
    report_dir = os.path.join(results_dir, "report")
    os.makedirs(report_dir, exist_ok=True)
    machine = f"{platform.machine()}, {os.cpu_count()} cores, CPU (LLVM backend)"
    with atomic_write(os.path.join(report_dir, "map.json")) as f:
        json.dump({"generated": str(datetime.date.today()), "machine": machine, "frame_directions": FRAME_DIRECTIONS,
                   "skies": [{"name": s.name, "kind": s.kind} for s in MAP_SKIES],
                   "entries": summaries, "rows": rows}, f, indent=1, default=float)
    plot_pareto(summaries, os.path.join(report_dir, "pareto.png"))
    plot_contact_sheet(entries, skies, cache_dir, os.path.join(report_dir, "contact_sheet.png"))
    spp = 1024
    lines = [
        "# skyref results", "",
        f"Regenerate this page with `skyref report` (rebuilt {datetime.date.today()} on {machine}). "
        "It reads the ground truth of `grids/lut_audit.toml` (rendered first if missing, resumable) and "
        "caches every (method, sky) comparison under `out/report/cache`.", "",
        "## Speed against error, every method", "",
        f"Skies: {len(MAP_SKIES)} of the standard grid — "
        + "; ".join(f"{s.kind}: {s.name}" for s in MAP_SKIES)
        + f". Ground truth: skyref's path tracer, 64x32 pixel-centre directions, 17 wavelengths 380–780 nm, "
        f"{spp} samples per direction. Error: noise-corrected RMS of the relative luminance error over the sky "
        "(views that miss the ground, solar disk excluded), the worst sky of each kind, in %; `*` where the "
        "ground truth's noise exceeds 1/5 of the error (not resolved); `refused` where the model refuses the "
        "sky (outside its stated range; `(part)` if some skies of the kind were refused). CIEDE2000: median "
        "over skies of the 95th percentile (absolute basis). Worst region: the largest luminance RMS over "
        "the sky's regions (horizon band, sun, anti-solar, away; not the ground) and skies. Analytic models "
        "run in NumPy (float64, one CPU thread, not optimised), LUT lookups in Dr.Jit: their per-direction "
        "times compare implementations here, not what a shader would take. Costs on this CPU for 17 "
        "wavelengths: precompute once per atmosphere, per view when the sun or observer moves, lookup per "
        f"direction; HD frame = precompute + per view + {FRAME_DIRECTIONS:,} lookups. The path tracer's "
        "lookup is its render time per direction at that sample count; its error is its own noise.", "",
        *map_table(summaries), "",
        "![speed against error](report/pareto.png)", "",
        "## Contact sheet", "",
        "The first sky of each kind by every method at its default setting (tone-mapped with the ground "
        f"truth's exposure), each beside its relative luminance error (±{100 * ERROR_SCALE:.0f}%).", "",
        "![contact sheet](report/contact_sheet.png)", "",
        "## Advice", "",
        "`skyref advise --scene SCENE --tolerance 2%` names the cheapest method meeting the tolerance on the "
        "scene's kind of sky, from `report/map.json` (see `skyref advise --help`).", "",
        "## Other reports", ""]
    lines += [f"- [{name}]({name}): {what}" for name, what in OTHER_REPORTS
              if os.path.exists(os.path.join(results_dir, name))]
    path = os.path.join(results_dir, "README.md")
    with atomic_write(path) as f:
        f.write("\n".join(lines) + "\n")
    return path
