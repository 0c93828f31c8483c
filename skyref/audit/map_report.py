"""``skyref report``: the speed-vs-error map (:mod:`skyref.audit.speed_map`) written out as
``results/README.md`` (one table of every method, the index of the other reports), a Pareto plot
(``results/report/pareto.png``, every point labelled, no two labels overlapping), a contact
sheet of the same skies by every method as sky domes with their error maps on a colour scale
fitted to the data (``results/report/contact_sheet.png``) and the numbers ``skyref advise`` reads
(``results/report/map.json``); beside the costs, what they count (:func:`operations_table`), and
the analytic models' scale and shape apart (:func:`analytic_scale_table`). Every number is
computed by the code from the cached rows.
"""

from __future__ import annotations

import datetime
import json
import os
import platform

import numpy as np

from skyref.audit.metrics import SCALE_DEFINITION
from skyref.audit.speed_map import FRAME_DIRECTIONS, KINDS, MAP_SKIES, cache_path, load_cached
from skyref.batch.provenance import describe_truth, truth_provenance
from skyref.color import default_exposure, spectral_to_linear_srgb, srgb_luminance, tonemap_srgb8
from skyref.errors import ParameterError
from skyref.io.atomic import atomic_path, atomic_write
from skyref.io.exr import read_sky_exr
from skyref.projection import equirectangular_pixel, fisheye_direction
from skyref.sky_method import describe_operations

__all__ = ["ERROR_LINEAR", "LABEL_DIRECTIONS", "LABEL_RINGS_PT", "MARKER_SIZE_PT", "OTHER_REPORTS", "PARETO_DPI",
           "analytic_gap_lines", "analytic_scale_table", "contact_entries", "contact_sheet_figure", "error_norm",
           "labelled_pareto_figure", "map_table", "operations_table", "pareto_figure", "place_labels",
           "plot_contact_sheet", "plot_pareto", "sky_dome", "write_map_report"]

#: Relative luminance error within which the contact sheet's symmetric-log colour scale is linear.
ERROR_LINEAR = 0.01
#: Pareto plot: marker size (points across), resolution (dots per inch), and the offsets tried for
#: a label (points from its marker: rings of growing radius, LABEL_DIRECTIONS directions each).
MARKER_SIZE_PT = 6.5
PARETO_DPI = 120
LABEL_RINGS_PT = (5, 12, 20, 30, 42, 56, 72, 90, 115, 145)
LABEL_DIRECTIONS = 16
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


def operations_table(summaries: list[dict]) -> list[str]:
    """Markdown rows: per measured entry, what its costs count
    (:func:`skyref.sky_method.describe_operations`)."""
    lines = ["| method | setting | what the costs count |", "|---|---|---|"]
    for s in summaries:
        if s.get("operations"):
            lines.append(f"| {s['method']} | {s['label']} | {describe_operations(s['operations'])} |")
    return lines


def analytic_scale_table(summaries: list[dict]) -> list[str]:
    """Markdown rows: per analytic entry and map sky, the sky luminance RMS error as it is ->
    after the best scale factor s (in %; * where not resolved), and s; "refused" where the model
    refuses the sky."""
    lines = ["| method | setting | " + " | ".join(s.name for s in MAP_SKIES) + " |",
             "|---|---|" + "---:|" * len(MAP_SKIES)]
    for s in summaries:
        if s["family"] != "analytic" or "scale" not in s:
            continue
        cells = []
        for sky in MAP_SKIES:
            scale = s["scale"].get(sky.name)
            cells.append("refused" if sky.name in s["refused"] else "–" if scale is None else
                         f"{_percent(scale['rms'], scale['resolved_rms'])} → "
                         f"{_percent(scale['rms_scaled'], scale['resolved_rms_scaled'])} (s = {scale['factor']:.3g})")
        lines.append(f"| {s['method']} | {s['label']} | " + " | ".join(cells) + " |")
    return lines


def analytic_gap_lines(summaries: list[dict], kind: str = "clear") -> list[str]:
    """Markdown bullets, one per analytic entry: the gap to the ground truth on the map skies of
    ``kind`` that it does not refuse, in plain words: how much too bright (or dark) it is (1 / the
    median best scale factor s) and its median sky luminance RMS error as it is and after s."""
    lines = []
    for s in summaries:
        if s["family"] != "analytic" or "scale" not in s:
            continue
        scales = [s["scale"][sky.name] for sky in MAP_SKIES
                  if sky.kind == kind and sky.name in s["scale"] and sky.name not in s["refused"]]
        if not scales:
            continue
        factor = float(np.median([x["factor"] for x in scales]))
        brightness = (f"{1.0 / factor:.2f}x too bright" if factor < 1.0 else f"{factor:.2f}x too dark")
        lines.append(f"- **{s['method']} {s['label']}**: on the {kind} skies {brightness} (median best scale "
                     f"{factor:.3g}); sky luminance RMS error {100 * np.median([x['rms'] for x in scales]):.1f}% "
                     f"as it is, {100 * np.median([x['rms_scaled'] for x in scales]):.1f}% after that scale "
                     "(the error of shape and colour).")
    return lines


def _distance(point, box) -> float:
    """Display-space distance from ``point`` to the Bbox ``box`` (0 inside it)."""
    return float(np.hypot(max(box.x0 - point[0], 0.0, point[0] - box.x1), max(box.y0 - point[1], 0.0, point[1] - box.y1)))


def place_labels(ax, points, texts, renderer, fontsize: float = 7.0) -> list:
    """Annotate each data point of ``points`` with its text; returns the annotations.

    Placement in display space, greedy in the order given: of the offsets of
    :data:`LABEL_RINGS_PT` x :data:`LABEL_DIRECTIONS` (nearest ring first, each ring from the
    upper right anticlockwise), the first whose box (1 pt margin) lies inside the axes, clear of
    every marker, every label placed before and their leader lines, whose leader line crosses no
    other label or marker (bar those on top of its own), and which, on the first ring (no leader
    line), is nearer its own marker than any other by a marker's width. Labels beyond the first
    ring get a leader line. Where no offset meets all of that, the first with the fewest
    collisions of its box, then of its leader line, then unambiguous.
    Deterministic.
    """
    from matplotlib.path import Path  # lazy: matplotlib stays off the ``skyref --help`` path
    from matplotlib.transforms import Bbox

    radius_px = renderer.points_to_pixels(MARKER_SIZE_PT) / 2.0
    margin_px = renderer.points_to_pixels(1.0)
    centres = ax.transData.transform(points)
    markers = [Bbox.from_bounds(x - radius_px, y - radius_px, 2 * radius_px, 2 * radius_px) for x, y in centres]
    frame = ax.get_window_extent(renderer)
    boxes, leaders, annotations = [], [], []
    for k, (point, text) in enumerate(zip(points, texts)):
        # A leader line starts inside the markers on top of its own: those cannot be avoided.
        others = [m for m in markers if not m.overlaps(markers[k])]
        best = None
        for ring, radius in enumerate(LABEL_RINGS_PT):
            for i in range(LABEL_DIRECTIONS):
                angle = np.pi / 4 + 2 * np.pi * i / LABEL_DIRECTIONS
                dx, dy = radius * np.cos(angle), radius * np.sin(angle)
                ha = "left" if dx > 0.3 * radius else "right" if dx < -0.3 * radius else "center"
                va = "bottom" if dy > 0.3 * radius else "top" if dy < -0.3 * radius else "center"
                label = ax.annotate(text, point, xytext=(dx, dy), textcoords="offset points", ha=ha, va=va,
                                    fontsize=fontsize)
                box = label.get_window_extent(renderer)
                label.remove()
                padded = box.padded(margin_px)
                leader = Path([centres[k], centres[k] + margin_px * np.array([dx, dy])]) if ring else None
                collisions = sum(padded.overlaps(b) for b in boxes + markers)
                collisions += sum(p.intersects_bbox(padded, filled=False) for p in leaders)
                collisions += not (frame.x0 <= padded.x0 and padded.x1 <= frame.x1
                                   and frame.y0 <= padded.y0 and padded.y1 <= frame.y1)
                crossings = 0 if leader is None else sum(leader.intersects_bbox(b, filled=False) for b in boxes + others)
                # Without a leader line a label is read as belonging to the marker nearest to it:
                # every other marker must be farther by a marker's width.
                own = _distance(centres[k], box) + 2 * radius_px
                ambiguous = leader is None and any(_distance(c, box) < own for j, c in enumerate(centres) if j != k)
                score = (collisions, crossings, ambiguous)
                if best is None or score < best[0]:
                    best = (score, ring, dx, dy, ha, va, padded, leader)
                if score == (0, 0, False):
                    break
            if best[0] == (0, 0, False):
                break
        _, ring, dx, dy, ha, va, padded, leader = best
        arrow = dict(arrowstyle="-", color="0.4", lw=0.5, shrinkA=0, shrinkB=MARKER_SIZE_PT / 2) if ring else None
        annotations.append(ax.annotate(text, point, xytext=(dx, dy), textcoords="offset points", ha=ha, va=va,
                                       fontsize=fontsize, arrowprops=arrow))
        boxes.append(padded)
        if leader is not None:
            leaders.append(leader)
    return annotations


def labelled_pareto_figure(panels, errors, groups, styles: dict, texts, ylabel: str):
    """Two log-log panels of ``errors`` (%, one per point) against each panel's costs
    (``panels``: (x label, costs) pairs), one marker and colour per group (``styles``: group ->
    (marker, colour); ``groups``: each point's group, shown in a legend above), every point
    labelled with its text without overlaps (:func:`place_labels`)."""
    # Lazy: selecting the Agg backend is a side effect, made only when plots are written.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    errors = np.asarray(errors, dtype=np.float64)
    fig, axes = plt.subplots(1, 2, figsize=(14, 6.5), dpi=PARETO_DPI, sharey=True, layout="constrained")
    for ax, (xlabel, costs) in zip(axes, panels):
        costs = np.asarray(costs, dtype=np.float64)
        for group, (marker, colour) in styles.items():
            mine = [i for i, g in enumerate(groups) if g == group]
            if mine:
                ax.scatter(costs[mine], errors[mine], marker=marker, color=colour, s=MARKER_SIZE_PT ** 2,
                           label=group, zorder=3)
        ax.set_xscale("log")
        ax.set_yscale("log")
        # Room for the labels: the data span a middle part of each logarithmic axis.
        ax.set_xlim(costs.min() / 3.0, costs.max() * 3.0)
        ax.set_ylim(errors.min() / 1.6, errors.max() * 1.6)
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3, which="both")
    axes[0].set_ylabel(ylabel)
    fig.legend(*axes[0].get_legend_handles_labels(), loc="outside upper center", ncols=len(styles), frameon=False)
    # Labels are placed on the final layout: lay the figure out once, then keep it.
    fig.canvas.draw()
    fig.set_layout_engine("none")
    renderer = fig.canvas.get_renderer()
    for ax, (_, costs) in zip(axes, panels):
        place_labels(ax, list(zip(costs, errors)), texts, renderer)
    return fig


def pareto_figure(summaries: list[dict]):
    """The Pareto plot of ``summaries`` (:func:`skyref.audit.speed_map.entry_summary`, or the
    ``entries`` of map.json): sky luminance RMS error against the cost of the first frame and of
    each further frame, every measured entry labelled without overlaps
    (:func:`labelled_pareto_figure`)."""
    measured = [s for s in summaries if "frame_s" in s]
    panels = ((f"one frame of {FRAME_DIRECTIONS:,} directions from scratch (s)", [s["frame_s"] for s in measured]),
              ("each further frame, tables kept (s)",
               [s["per_view_s"] + FRAME_DIRECTIONS * s["lookup_s"] for s in measured]))
    return labelled_pareto_figure(panels, [100 * s["sky_rms_median"] for s in measured],
                                  [s["family"] for s in measured],
                                  {"path tracer": ("o", "C0"), "LUT": ("s", "C1"), "analytic": ("D", "C2")},
                                  [f"{s['method']} {s['label']}" for s in measured],
                                  "sky luminance RMS error (%), median of the map's skies")


def plot_pareto(summaries: list[dict], path: str):
    """Write :func:`pareto_figure` of ``summaries`` to the PNG ``path``."""
    import matplotlib.pyplot as plt  # lazy: matplotlib stays off the ``skyref --help`` path

    fig = pareto_figure(summaries)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi="figure", format="png")
    plt.close(fig)


def contact_entries(entries) -> list:
    """The first setting of every method (its default), in map order."""
    first = {}
    for entry in entries:
        first.setdefault((entry.method, entry.label if entry.method == "hosek2012" else ""), entry)
    return list(first.values())


def sky_dome(image, directions, size: int) -> np.ndarray:
    """``image`` (H, W, ...) of an equirectangular map, resampled (nearest pixel) to a ``size`` x
    ``size`` upward equidistant fisheye of the sky dome (:func:`skyref.projection.fisheye_direction`
    at 180°: zenith in the centre, horizon on the image circle, north up, east left), as float64.
    NaN outside the circle and where the nearest map pixel's centre (``directions``: the map's
    (H, W, 3) east-north-up pixel-centre directions) is not above the horizon."""
    centres = (np.arange(size) + 0.5) / size
    v, u = np.meshgrid(centres, centres, indexing="ij")
    x, y, z, inside = fisheye_direction(u, v, 180.0)
    map_u, map_v = equirectangular_pixel(np.stack([x, y, z], axis=-1))
    height, width = image.shape[:2]
    rows = np.minimum((map_v * height).astype(int), height - 1)
    columns = np.minimum((map_u * width).astype(int), width - 1)
    dome = np.asarray(image, dtype=np.float64)[rows, columns]
    dome[~(inside & (np.asarray(directions)[rows, columns, 2] > 0.0))] = np.nan
    return dome


def error_norm(errors):
    """The contact sheet's colour scale of relative errors: symmetric logarithmic, linear within
    ±:data:`ERROR_LINEAR`, ending at the largest finite ``|error|`` (at least ERROR_LINEAR), so
    that no error saturates it. Returns (norm, that largest error)."""
    from matplotlib.colors import SymLogNorm  # lazy: matplotlib stays off the ``skyref --help`` path

    values = np.abs(np.concatenate([np.ravel(e) for e in errors] or [np.zeros(0)]))
    values = values[np.isfinite(values)]
    limit = max(ERROR_LINEAR, float(values.max()) if values.size else 0.0)
    return SymLogNorm(ERROR_LINEAR, vmin=-limit, vmax=limit, base=10), limit


def _error_ticks(limit: float) -> list[float]:
    """0, ±ERROR_LINEAR, ± every decade above it below ``limit`` / 2, and ±``limit`` (no tick
    below -100%: a relative error cannot be)."""
    decades = [ERROR_LINEAR * 10.0 ** k for k in range(int(np.log10(limit / ERROR_LINEAR)) + 1)]
    ends = sorted({d for d in decades if d <= limit / 2} | {ERROR_LINEAR, limit})
    return sorted({-min(e, 1.0) for e in ends}) + [0.0] + ends


def contact_sheet_figure(entries, skies, cache_dir: str):
    """Rows: the ground truth, then every method's default setting (:func:`contact_entries`);
    per kind of sky (its first sky in ``skies``, (MapSky, truth EXR path) pairs) two columns: the
    sky dome (:func:`sky_dome`) tone-mapped with the truth's exposure, and the method's relative
    luminance error on :func:`error_norm`'s scale. Rows cached by
    :func:`skyref.audit.speed_map.evaluate_map` in ``cache_dir``; an entry without a cached
    image is shown as refused."""
    # Lazy: selecting the Agg backend is a side effect, made only when plots are written.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    first = {}
    for sky, sky_path in skies:
        first.setdefault(sky.kind, (sky, sky_path))
    sheet_skies = [first[kind] for kind in KINDS if kind in first]
    truths = []
    for _, sky_path in sheet_skies:
        truth = read_sky_exr(sky_path)
        camera = truth.scene.camera.type if truth.scene is not None else "no"
        if camera != "equirectangular":
            raise ParameterError("skies", sky_path, "ground truth of an equirectangular camera", f"{camera} camera")
        rgb = spectral_to_linear_srgb(truth.radiance - truth.orders.get("sun_direct", 0.0), truth.wavelengths_nm)
        truths.append((rgb, default_exposure(rgb), truth.directions, 2 * rgb.shape[0]))
    rows = [("ground truth", None)] + [(f"{e.method}\n{e.label}", e) for e in contact_entries(entries)]
    # Every panel first: the error scale is fitted to all of them.
    panels = {}
    for i, (_, entry) in enumerate(rows):
        for j, ((sky, sky_path), (truth_rgb, exposure, directions, size)) in enumerate(zip(sheet_skies, truths)):
            rgb = truth_rgb
            if entry is not None:
                cached = cache_path(cache_dir, entry, sky, sky_path)
                rgb = load_cached(cached)[1] if os.path.exists(cached) else None
            if rgb is None:
                panels[i, j] = None
                continue
            rgb = np.asarray(rgb, dtype=np.float64)
            image = sky_dome(tonemap_srgb8(rgb, exposure), directions, size) / 255.0
            image = np.dstack([np.nan_to_num(image), np.isfinite(image[..., :1])])   # RGBA, clear off the dome
            error = None
            if entry is not None:
                with np.errstate(divide="ignore", invalid="ignore"):
                    error = sky_dome(srgb_luminance(rgb) / srgb_luminance(truth_rgb) - 1.0, directions, size)
            panels[i, j] = (image, error)
    norm, limit = error_norm([p[1] for p in panels.values() if p is not None and p[1] is not None])
    fig, axes = plt.subplots(len(rows), 2 * len(sheet_skies), figsize=(2.4 * len(sheet_skies) + 3.2, 1.2 * len(rows)),
                             squeeze=False, layout="constrained")
    mappable = None
    for (i, j), panel in panels.items():
        label, _ = rows[i]
        sky, size = sheet_skies[j][0], truths[j][3]
        ax_image, ax_error = axes[i, 2 * j], axes[i, 2 * j + 1]
        for ax in (ax_image, ax_error):
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_aspect("equal")
            ax.spines[:].set_visible(False)
        if i == 0:
            ax_image.set_title(sky.name, fontsize=8)
            ax_error.set_title("luminance error", fontsize=7)
        if j == 0:
            ax_image.set_ylabel(label, fontsize=7, rotation=0, ha="right", va="center")
        if panel is None:
            ax_image.text(0.5, 0.5, "refused /\nnot run", ha="center", va="center", fontsize=7,
                          transform=ax_image.transAxes)
            continue
        image, error = panel
        ax_image.imshow(image, interpolation="nearest")
        if error is not None:
            mappable = ax_error.imshow(error, cmap="RdBu_r", norm=norm, interpolation="nearest")
        for ax in ((ax_image, ax_error) if error is not None else (ax_image,)):
            ax.add_patch(plt.Circle((size / 2 - 0.5, size / 2 - 0.5), size / 2, fill=False, lw=0.5, ec="0.6"))
            ax.set_xlim(-0.5, size - 0.5)
            ax.set_ylim(size - 0.5, -0.5)
    if mappable is not None:
        height_in = fig.get_size_inches()[1]
        bar = fig.colorbar(mappable, ax=axes[:, -1], shrink=min(1.0, 5.0 / height_in), ticks=_error_ticks(limit),
                           format=FuncFormatter(lambda value, _: f"{100 * value:+.3g}%" if value else "0"))
        bar.set_label(f"method / truth - 1 (luminance)\nsymmetric log: linear within ±{100 * ERROR_LINEAR:g}%, "
                      f"ends at ±{100 * limit:.3g}% (largest on the sheet)", fontsize=7)
        bar.ax.tick_params(labelsize=7)
    return fig


def plot_contact_sheet(entries, skies, cache_dir: str, path: str):
    """Write :func:`contact_sheet_figure` to the PNG ``path``."""
    import matplotlib.pyplot as plt  # lazy: matplotlib stays off the ``skyref --help`` path

    fig = contact_sheet_figure(entries, skies, cache_dir)
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
    lines = [
        "# skyref results", "",
        f"Regenerate this page with `skyref report` (rebuilt {datetime.date.today()} on {machine}). "
        "It reads the ground truth of `grids/lut_audit.toml` (imported from `results/lut_audit/truth`, where it "
        "ships; what is missing is rendered first, resumable) and caches every (method, sky) comparison under "
        "`out/report/cache`.", "",
        "## Speed against error, every method", "",
        f"Skies: {len(MAP_SKIES)} of the standard grid — "
        + "; ".join(f"{s.kind}: {s.name}" for s in MAP_SKIES)
        + f". Ground truth: skyref's path tracer, {describe_truth(truth_provenance(path for _, path in skies))}. "
        "Error: noise-corrected RMS of the relative luminance error over the sky "
        "(views that miss the ground, solar disk excluded), the worst sky of each kind, in %; `*` where the "
        "ground truth's noise exceeds 1/5 of the error (not resolved); `refused` where the model refuses the "
        "sky (outside its stated range; `(part)` if some skies of the kind were refused). CIEDE2000: median "
        "over skies of the 95th percentile (absolute basis). Worst region: the largest luminance RMS over "
        "the sky's regions (horizon band, sun, anti-solar, away; not the ground) and skies. Costs are wall "
        "times of skyref's own implementations on this CPU for 17 wavelengths: analytic models in NumPy "
        "(float64, one CPU thread, not optimised), LUT methods in Dr.Jit (LLVM, double precision); they "
        "compare implementations here, not what a shader would take (see what they count, below). "
        "Precompute once per atmosphere, per view when the sun or observer moves, lookup per direction, the "
        "last two warm (first-call kernel compilation excluded); HD frame = precompute + per view + "
        f"{FRAME_DIRECTIONS:,} lookups. The path tracer's lookup is its render time per direction at that "
        "sample count; its error is its own noise.", "",
        *map_table(summaries), "",
        "What the costs count, machine-independently (what an engine on a GPU pays for): table fetches per "
        "view direction (one interpolated read of a table, every wavelength at once: bilinear in 2D, "
        "trilinear in 3D), for a direction that misses the ground and one that meets it, and the per-view "
        "work (cells x samples); the tables' cells per axis.", "",
        *operations_table(summaries), "",
        "![speed against error](report/pareto.png)", "",
        "## Analytic models: scale and shape", "",
        "Per sky: the sky luminance RMS error as the model is (%) -> after multiplying it by the best "
        f"single scale factor s, and s: {SCALE_DEFINITION}. An error that s removes is one of overall "
        "brightness (the model's sun or calibration); what remains is one of shape and colour.", "",
        *analytic_scale_table(summaries), "",
        "The gap in plain words (medians over the clear skies):", "", *analytic_gap_lines(summaries), "",
        "## Contact sheet", "",
        "The first sky of each kind by every method at its default setting, as the sky dome (upward fisheye: "
        "zenith in the centre, horizon on the circle, north up, east left; tone-mapped with the ground truth's "
        "exposure), each beside its relative luminance error (symmetric logarithmic colour scale, linear "
        f"within ±{100 * ERROR_LINEAR:g}%, ending at the largest error on the sheet).", "",
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
