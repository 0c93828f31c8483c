"""One map of speed against error for every sky method skyref knows: the path tracer at several
sample counts, the LUT methods at several resolutions and precisions, and the analytic models
(classic ones, the published Hosek–Wilkie model and skyref's own fits), each compared with the
same ground truth by :func:`skyref.audit.audit.compare`.

**Skies** (:data:`MAP_SKIES`): eight skies of four kinds (clear, hazy, sunset, high altitude)
taken from the ground truth of the standard LUT audit grid (``grids/lut_audit.toml``: Bruneton
2017's atmosphere as published and at turbidity 6; 64x32 pixel-centre directions over the whole
sphere; 17 wavelengths 380–780 nm; rendered to 0.3% relative standard error per direction).

**Error** per sky: the noise-corrected RMS of the relative luminance error over the sky (every
view that misses the ground, solar disk excluded), the 95th percentile of CIEDE2000 (absolute
basis), and the worst region (horizon band, around the sun, anti-solar, away from both; the
ground, which most analytic models do not model, is left out) by luminance RMS. A model that refuses a sky (outside its stated validity range) is marked so.

**Scale and shape** per sky (analytic models above all): the best single scale factor of the
method and its sky luminance RMS error after it (:func:`skyref.audit.metrics.scale_statistics`).

**Cost**: precompute time (s, once per atmosphere), per-view time (s, tables rebuilt when the
sun or observer moves), and lookup time per direction (s), the last two warm (first-call kernel
compilation excluded, :func:`skyref.audit.audit.compare`), all wall times of skyref's own
implementation on this machine's CPU with 17 wavelengths. Beside them, what they count
(:class:`skyref.sky_method.Operations`: table fetches per direction, per-view cells x samples),
which is what an engine on a GPU pays for. The path tracer's per-direction time is its render
time at that sample count. The cost of a frame of ``n`` directions seen from scratch is
precompute + per view + n x lookup (:func:`frame_seconds`).

Rows are cached per (entry, sky, the truth EXR's content) under ``out/report/cache`` (with
linear sRGB images for the contact sheet), so the map is completed in pieces and rebuilt without
recomputation; rows of an earlier :data:`CACHE_VERSION` or against a re-rendered truth are
measured again.
"""

from __future__ import annotations

import dataclasses
import json
import os
from dataclasses import dataclass, field

import numpy as np

from skyref.analytic import analytic_model
from skyref.analytic.hosek import TURBIDITIES
from skyref.atmosphere import turbidity
from skyref.batch.store import sha256_of
from skyref.errors import ParameterError
from skyref.fit.export import read_spectral_table
from skyref.io.atomic import atomic_path
from skyref.io.exr import read_sky_exr
from skyref.lut import lut_method
from skyref.render import render_sky
from skyref.sky_method import Operations

__all__ = ["CACHE_VERSION", "ENTRIES", "FRAME_DIRECTIONS", "KINDS", "MAP_SKIES", "TRUTH_GRID", "Entry", "MapSky",
           "PathTracerView", "build_method", "cache_path", "entry_summary", "evaluate_map", "fitted_entries",
           "frame_seconds", "load_cached", "save_cached", "map_sky_specs", "truth_skies"]

#: Directions of the frame the map's "frame" cost refers to (1920 x 1080).
FRAME_DIRECTIONS = 1920 * 1080
#: Where the ground truth comes from.
TRUTH_GRID = os.path.join("grids", "lut_audit.toml")
#: Version of the cached rows: 2 added warm per-view times, operation counts and scale statistics.
CACHE_VERSION = 2


@dataclass(frozen=True)
class MapSky:
    """A sky of the map: ``kind`` (clear, hazy, sunset, high altitude), the index of its
    atmosphere on the truth grid's atmosphere axis, the observer's altitude (m) and the sun's
    zenith angle (deg)."""

    name: str
    kind: str
    atmosphere: int
    altitude_m: float
    sun_zenith_deg: float


MAP_SKIES = (MapSky("clear, sun 30°", "clear", 0, 0.0, 30.0),
             MapSky("clear, sun 60°", "clear", 0, 0.0, 60.0),
             MapSky("hazy (T=6), sun 30°", "hazy", 1, 0.0, 30.0),
             MapSky("hazy (T=6), sun 60°", "hazy", 1, 0.0, 60.0),
             MapSky("sunset, clear (sun 88°)", "sunset", 0, 0.0, 88.0),
             MapSky("sunset, hazy (sun 88°)", "sunset", 1, 0.0, 88.0),
             MapSky("10 km, sun 30°", "high altitude", 0, 10000.0, 30.0),
             MapSky("10 km, sun 80°", "high altitude", 0, 10000.0, 80.0))
KINDS = ("clear", "hazy", "sunset", "high altitude")


@dataclass(frozen=True)
class Entry:
    """A method at one setting. ``family``: "path tracer", "LUT" or "analytic"; ``method``: its
    registry name (:data:`skyref.lut.METHODS`, :data:`skyref.analytic.MODELS`; "skyref" for the
    path tracer); ``options``: the method's own options (``spp`` for the path tracer;
    ``turbidity="clamp"`` clamps the atmosphere's turbidity into the model's range;
    ``table=PATH`` reads a fitted coefficient table; ``solar_spectrum_correction`` rescales the
    published Hosek–Wilkie sky to skyref's sun); ``stored_as``: options of
    Bruneton2017.stored_as applied to the tables of the same method without them."""

    method: str
    family: str
    label: str
    options: dict = field(default_factory=dict)
    stored_as: dict | None = None

    @property
    def key(self) -> str:
        return f"{self.method} {self.label}"


#: The map's settings of every method; fitted Hosek–Wilkie / Perez tables join when present.
ENTRIES = (Entry("skyref", "path tracer", "16 spp", {"spp": 16}),
           Entry("skyref", "path tracer", "64 spp", {"spp": 64}),
           Entry("skyref", "path tracer", "256 spp", {"spp": 256}),
           Entry("bruneton2017", "LUT", "paper (32x128x32x8, 4 orders)"),
           Entry("bruneton2017", "LUT", "float16", stored_as={"precision": "float16"}),
           Entry("bruneton2017", "LUT", "table x0.5", {"r_size": 16, "mu_size": 64, "mu_s_size": 16, "nu_size": 4}),
           Entry("elek2009", "LUT", "paper (32x128x32, 4 orders)"),
           Entry("elek2009", "LUT", "table x0.5", {"scattering_size": (16, 64, 16)}),
           Entry("hillaire2020", "LUT", "reference (192x108, 4-14 samples)"),
           Entry("hillaire2020", "LUT", "sky view 30 samples", {"sky_view_samples": (30, 30)}),
           Entry("hillaire2020", "LUT", "float16", {"precision": "float16"}),
           Entry("preetham1999", "analytic", "T clamped to [2, 10]", {"turbidity": "clamp"}),
           Entry("hoffman_preetham2002", "analytic", "default"),
           Entry("nielsen2003", "analytic", "default"),
           Entry("nishita1993", "analytic", "default"),
           Entry("oneil2005", "analytic", "default"),
           Entry("hosek2012", "analytic", "published 1.4a"),
           Entry("hosek2012", "analytic", "published 1.4a, skyref's sun", {"solar_spectrum_correction": True}))


def fitted_entries(coefficients_dir: str) -> list[Entry]:
    """Hosek–Wilkie and Perez tables fitted by ``skyref fit`` in ``coefficients_dir``, if any."""
    entries = []
    for name, label in (("hosek.npz", "skyref fit"), ("perez.npz", "Perez form, skyref fit")):
        path = os.path.join(coefficients_dir, name)
        if os.path.exists(path):
            entries.append(Entry("hosek2012", "analytic", label, {"table": path}))
    return entries


# --- building a method --------------------------------------------------------------------------

def _clamped_turbidity(name: str, atmosphere) -> float:
    # Lazy: skyref.analytic.preetham imports colour-science (seconds); ``skyref --help`` imports this module.
    from skyref.analytic.preetham import TURBIDITY_RANGE

    lo, hi = {"preetham1999": TURBIDITY_RANGE, "hosek2012": (TURBIDITIES[0], TURBIDITIES[-1])}[name]
    return float(np.clip(turbidity(atmosphere), lo, hi))


def build_method(entry: Entry, atmosphere, wavelengths_nm):
    """The method of ``entry`` (LUT or analytic) for ``atmosphere``, not yet precomputed."""
    options = dict(entry.options)
    if options.get("turbidity") == "clamp":
        options["turbidity"] = _clamped_turbidity(entry.method, atmosphere)
    if "table" in options:
        options["table"] = read_spectral_table(options["table"], "table")
    if entry.family == "LUT":
        return lut_method(entry.method, atmosphere, wavelengths_nm, **options)
    return analytic_model(entry.method, atmosphere, wavelengths_nm, **options)


class PathTracerView:
    """The path tracer at ``spp`` samples per direction as a method :func:`compare` can call:
    it renders ``scene`` (its camera's pixel-centre directions must be the ones asked for) with
    seed ``seed``, returns radiance without the solar disk, and costs no precomputation."""

    def __init__(self, scene, spp: int, seed: int):
        self.scene = scene.replace(render=dataclasses.replace(scene.render, pixel_sampling="centre"))
        self.spp, self.seed = spp, seed
        self.precompute_seconds = 0.0

    def operations(self) -> Operations:
        """Per direction: ``spp`` paths of the path tracer; nothing tabulated."""
        return Operations(sky={"paths": self.spp}, ground={"paths": self.spp})

    def radiance(self, directions, sun_direction, observer_altitude_m: float) -> np.ndarray:
        expected = self.scene.camera.width * self.scene.camera.height
        if len(directions) != expected:
            raise ParameterError("directions", f"{len(directions)} directions",
                                 f"the {expected} pixel directions of the scene's camera", "the path tracer renders its camera")
        # every direction traced (symmetry=False): a frame's directions need not come in mirror pairs
        sky = render_sky(self.scene, spp=self.spp, passes=2, seed=self.seed, symmetry=False)
        radiance = sky.radiance - sky.orders.get("sun_direct", 0.0)
        return radiance.reshape(expected, -1).astype(np.float64)


# --- evaluating the map -------------------------------------------------------------------------

def map_sky_specs(grid) -> list:
    """(sky, its :class:`~skyref.batch.grid.SkySpec` on ``grid``) of every map sky, in map order."""
    atmospheres = grid.axes["atmosphere"]
    found = {}
    for spec in grid.skies():
        c = spec.coordinates
        for sky in MAP_SKIES:
            if (c["atmosphere"] == atmospheres[sky.atmosphere] and c["observer.altitude_m"] == sky.altitude_m
                    and c["sun.zenith_deg"] == sky.sun_zenith_deg):
                found[sky] = spec
    missing = [s.name for s in MAP_SKIES if s not in found]
    if missing:
        raise ParameterError("truth grid", TRUTH_GRID, "a grid holding every map sky", f"missing: {missing}")
    return [(sky, found[sky]) for sky in MAP_SKIES]


def truth_skies(grid) -> list[tuple[MapSky, str]]:
    """(sky, path of its ground-truth EXR) of every map sky, from the truth grid."""
    return [(sky, os.path.join(grid.output.directory, "skies", f"{spec.sky_id}.exr")) for sky, spec in map_sky_specs(grid)]


def _summary(found: dict) -> dict:
    """The numbers of a :func:`compare` result the map keeps."""
    statistics = {}
    for region, row in found["statistics"].items():
        statistics[region] = {"luminance_rms": row["luminance"]["rms"], "luminance_p95": row["luminance"]["p95"],
                              "resolved": row["luminance"]["resolved_rms"], "delta_e_p95": row["delta_e"]["p95"]}
    return {"statistics": statistics, "scale": found["scale"], "operations": found["operations"],
            "per_view_s": found["per_view_s"], "lookup_s": found["lookup_s_per_direction"]}


def cache_path(cache_dir: str, entry: Entry, sky: MapSky, truth_path: str) -> str:
    """The cached row of ``entry`` on ``sky`` against the ground truth in ``truth_path``, keyed by
    that EXR's content (a re-rendered truth is measured against again) and, for an entry that
    reads a coefficient table, by the table's content (a refitted table is measured again)."""
    tag = f"v{CACHE_VERSION}__{entry.key}__{sky.name}__{sha256_of(truth_path)[:12]}"
    if "table" in entry.options:
        tag += "__" + sha256_of(entry.options["table"])[:12]
    safe = "".join(ch if ch.isalnum() else "_" for ch in tag)
    return os.path.join(cache_dir, f"{safe}.npz")


def save_cached(path: str, row: dict, srgb):
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, row=json.dumps(row), srgb=np.zeros((0, 0, 3), np.float32) if srgb is None else srgb)


def load_cached(path: str) -> tuple[dict, np.ndarray | None]:
    with np.load(path) as data:
        srgb = data["srgb"]
        return json.loads(str(data["row"])), (srgb if srgb.size else None)


def evaluate_map(entries, skies, cache_dir: str, log=print) -> list[dict]:
    """One row per (entry, sky): {"entry", "family", "method", "label", "sky", "kind",
    "precompute_s", "per_view_s", "lookup_s", "statistics"} or, where the method refuses the
    sky, "refused": the reason. Rows found in ``cache_dir`` are reused."""
    # Lazy: both import colour-science (seconds), and ``skyref --help`` imports this module.
    from skyref.audit.audit import compare
    from skyref.color import spectral_to_linear_srgb

    os.makedirs(cache_dir, exist_ok=True)
    rows = {}
    built = {}   # (method, options, atmosphere index) -> precomputed method, kept for stored_as entries
    for entry in entries:
        base = (entry.method, json.dumps(entry.options, sort_keys=True))
        built = {k: v for k, v in built.items() if k[:2] == base}
        # Skies grouped by atmosphere: each atmosphere's tables are precomputed once per entry.
        order = sorted(range(len(skies)), key=lambda i: skies[i][0].atmosphere)
        for sky_index in order:
            sky, path = skies[sky_index]
            cached = cache_path(cache_dir, entry, sky, path)
            if os.path.exists(cached):
                rows[entry.key, sky_index] = load_cached(cached)[0]
                continue
            truth = read_sky_exr(path)
            scene = truth.scene
            row = {"entry": entry.key, "family": entry.family, "method": entry.method, "label": entry.label,
                   "sky": sky.name, "kind": sky.kind}
            try:
                if entry.family == "path tracer":
                    method = PathTracerView(scene, entry.options["spp"], seed=(1 << 30) + sky_index)
                else:
                    key = base + (sky.atmosphere,)
                    if key not in built:
                        built[key] = build_method(entry, scene.atmosphere, scene.wavelengths_nm)
                        built[key].precompute()
                        log(f"  {entry.key}: precompute {built[key].precompute_seconds:.2f} s ({scene.atmosphere.name})")
                    method = built[key]
                    if entry.stored_as is not None:
                        method = method.stored_as(**entry.stored_as)
                found = compare(method, truth, scene)
            except ParameterError as error:
                row["refused"] = str(error)
                save_cached(cached, row, None)
                rows[entry.key, sky_index] = row
                log(f"  {entry.key} / {sky.name}: refused ({error})")
                continue
            row.update(precompute_s=float(method.precompute_seconds), **_summary(found))
            srgb = spectral_to_linear_srgb(np.nan_to_num(found["radiance"]), scene.wavelengths_nm).astype(np.float32)
            save_cached(cached, row, srgb)
            rows[entry.key, sky_index] = row
            sky_rms = row["statistics"].get("sky", {}).get("luminance_rms", float("nan"))
            log(f"  {entry.key} / {sky.name}: sky luminance RMS {100 * sky_rms:.2f}%")
    return [rows[entry.key, i] for entry in entries for i in range(len(skies))]


def frame_seconds(row: dict, directions: int = FRAME_DIRECTIONS, frames: int = 1) -> float:
    """Seconds to produce ``frames`` frames of ``directions`` directions each from scratch:
    precompute + frames x (per view + directions x lookup)."""
    return row["precompute_s"] + frames * (row["per_view_s"] + directions * row["lookup_s"])


def entry_summary(rows: list[dict]) -> list[dict]:
    """Per entry (in order of appearance): costs (medians over its skies) and the operations they
    count, the worst sky luminance RMS per kind of sky (None where every sky of the kind was
    refused; "resolved" False if any measured value was not resolved; "partial" if some were
    refused), the median CIEDE2000 p95, the worst region of the sky (the ground excluded: most
    analytic models do not model it) over all skies, and the scale statistics of each measured
    sky ("scale": sky name -> :func:`skyref.audit.metrics.scale_statistics`)."""
    order = list(dict.fromkeys(r["entry"] for r in rows))
    summaries = []
    for key in order:
        mine = [r for r in rows if r["entry"] == key]
        measured = [r for r in mine if "refused" not in r and "sky" in r["statistics"]]
        summary = {k: mine[0][k] for k in ("entry", "family", "method", "label")}
        summary["kinds"] = {}
        for kind in KINDS:
            values = [r["statistics"]["sky"] for r in measured if r["kind"] == kind]
            total = sum(r["kind"] == kind for r in mine)
            summary["kinds"][kind] = None if not values else {
                "rms": max(v["luminance_rms"] for v in values), "resolved": all(v["resolved"] for v in values),
                "partial": len(values) < total}
        if measured:
            for k in ("precompute_s", "per_view_s", "lookup_s"):
                summary[k] = float(np.median([r[k] for r in measured]))
            summary["frame_s"] = frame_seconds(summary)
            summary["sky_rms_median"] = float(np.median([r["statistics"]["sky"]["luminance_rms"] for r in measured]))
            summary["delta_e_p95_median"] = float(np.median([r["statistics"]["sky"]["delta_e_p95"] for r in measured]))
            worst = max(((region, s["luminance_rms"], r["sky"]) for r in measured
                         for region, s in r["statistics"].items() if region != "ground"), key=lambda t: t[1])
            summary["worst_region"] = {"region": worst[0], "rms": worst[1], "sky": worst[2]}
            summary["operations"] = measured[0]["operations"]
            summary["scale"] = {r["sky"]: r["scale"] for r in measured if r["scale"] is not None}
        summary["refused"] = sorted({r["sky"] for r in mine if "refused" in r})
        summaries.append(summary)
    return summaries
