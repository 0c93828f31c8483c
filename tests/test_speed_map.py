"""The speed-vs-error map (skyref.audit.speed_map), its report and ``skyref advise``.

The map's machinery is checked where its answer is known independently: the path tracer's
measured error against a ground truth must be the path tracer's own noise (predicted from the
truth's standard error and the sample counts); summaries and advice are checked on hand-made
rows whose right answer is obvious.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os

import numpy as np
import pytest

from skyref.audit.advise import COSTS_MEAN, advice_lines, parse_tolerance, rank, scene_kind
from skyref.audit.speed_map import Entry, MapSky, cache_path, entry_summary, evaluate_map, frame_seconds
from skyref.errors import ParameterError
from skyref.scene import Observer, Sun, load_scene


def scene(path="scenes/earth-clear.toml", **changes):
    return load_scene(path).replace(**changes)


# --- kinds of scene and tolerances ---------------------------------------------------------------

def test_scene_kinds():
    from skyref.atmosphere import from_turbidity

    assert scene_kind(scene(sun=Sun(zenith_deg=40.0)))[0] == "clear"
    assert scene_kind(scene(sun=Sun(zenith_deg=40.0), atmosphere=from_turbidity(6.0)))[0] == "hazy"
    assert scene_kind(scene(sun=Sun(zenith_deg=88.0), atmosphere=from_turbidity(6.0)))[0] == "sunset"
    assert scene_kind(scene(sun=Sun(zenith_deg=88.0), observer=Observer(10000.0)))[0] == "high altitude"
    with pytest.raises(ParameterError, match="sun.zenith_deg.*twilight"):
        scene_kind(scene(sun=Sun(zenith_deg=95.0)))
    with pytest.raises(ParameterError, match="observer.altitude_m"):
        scene_kind(scene(observer=Observer(30000.0)))


@pytest.mark.parametrize("text,value", [("2%", 0.02), ("0.5 %", 0.005), ("0.1", 0.1), ("100%", 1.0)])
def test_tolerance_parsing(text, value):
    assert parse_tolerance(text) == pytest.approx(value)


@pytest.mark.parametrize("text", ["two", "0", "-1%", "150%", ""])
def test_bad_tolerances_are_refused(text):
    with pytest.raises(ParameterError, match="--tolerance"):
        parse_tolerance(text)


# --- summaries and advice on hand-made rows -----------------------------------------------------

#: Operations of the hand-made rows (as a LUT method's Operations.to_dict()).
OPERATIONS = {"tables": {"scattering": [4, 8, 16]}, "sky": {"scattering fetches": 2},
              "ground": {"scattering fetches": 4}, "per_view": {}, "note": ""}


def row(entry, sky, kind, rms, *, precompute=0.0, per_view=0.0, lookup=1e-9, regions=None, refused=False,
        family="LUT", scale=None):
    base = {"entry": entry, "family": family, "method": entry.split()[0], "label": entry.split()[1],
            "sky": sky, "kind": kind}
    if refused:
        return {**base, "refused": "outside its range"}
    statistics = {"sky": {"luminance_rms": rms, "luminance_p95": 2 * rms, "resolved": True, "delta_e_p95": 1.0}}
    for region, value in (regions or {}).items():
        statistics[region] = {"luminance_rms": value, "luminance_p95": value, "resolved": True, "delta_e_p95": 1.0}
    return {**base, "precompute_s": precompute, "per_view_s": per_view, "lookup_s": lookup, "statistics": statistics,
            "operations": OPERATIONS, "scale": scale}


ROWS = [
    # cheap, 5% on clear skies
    row("a cheap", "c1", "clear", 0.03, lookup=1e-9, regions={"ground": 9.0, "horizon": 0.3}),
    row("a cheap", "c2", "clear", 0.05, lookup=1e-9),
    row("a cheap", "h1", "hazy", 0.20, lookup=1e-9),
    # expensive precompute, 1% everywhere
    row("b exact", "c1", "clear", 0.01, precompute=10.0, lookup=2e-9),
    row("b exact", "c2", "clear", 0.008, precompute=10.0, lookup=2e-9),
    row("b exact", "h1", "hazy", 0.01, precompute=10.0, lookup=2e-9),
    # the cheapest and accurate, but refuses one clear sky
    row("c partial", "c1", "clear", 0.001, lookup=1e-10),
    row("c partial", "c2", "clear", 0.0, refused=True),
    row("c partial", "h1", "hazy", 0.0, refused=True),
]


def test_entry_summary_takes_the_worst_sky_of_each_kind():
    summaries = {s["entry"]: s for s in entry_summary(ROWS)}
    a, b, c = summaries["a cheap"], summaries["b exact"], summaries["c partial"]
    assert a["kinds"]["clear"] == {"rms": 0.05, "resolved": True, "partial": False}
    assert a["kinds"]["sunset"] is None
    # The ground is left out of the worst region.
    assert a["worst_region"] == {"region": "horizon", "rms": 0.3, "sky": "c1"}
    assert c["kinds"]["clear"]["partial"] and c["kinds"]["hazy"] is None and c["refused"] == ["c2", "h1"]
    assert b["frame_s"] == pytest.approx(frame_seconds({"precompute_s": 10.0, "per_view_s": 0.0, "lookup_s": 2e-9}))


def test_rank_picks_the_cheapest_method_meeting_the_tolerance():
    summaries = entry_summary(ROWS)
    meeting, others = rank(summaries, "clear", 0.02)
    assert [m["entry"] for m in meeting] == ["b exact"]            # c refuses a clear sky, a is 5%
    assert [o["entry"] for o in others] == ["c partial", "a cheap"]  # most accurate first
    meeting, _ = rank(summaries, "clear", 0.06)
    assert [m["entry"] for m in meeting] == ["a cheap", "b exact"]   # cheapest first
    # With many frames of the same atmosphere the precompute matters less, not the order here.
    meeting, _ = rank(summaries, "hazy", 0.5, directions=10, frames=1000)
    assert meeting[0]["entry"] == "a cheap"
    assert rank(summaries, "sunset", 1.0) == ([], [])


def test_advice_names_method_cost_and_kind():
    lines = advice_lines(entry_summary(ROWS), scene(sun=Sun(zenith_deg=40.0)), 0.02)
    text = "\n".join(lines)
    assert "clear" in lines[0] and "cheapest method meeting it: b (exact)" in text and "1.00%" in text
    lines = advice_lines(entry_summary(ROWS), scene(sun=Sun(zenith_deg=40.0)), 0.001)
    assert any("no measured method meets 0.1%" in line for line in lines)
    assert any(line.startswith("most accurate of them: c (partial)") for line in lines)


def test_advice_says_nothing_above_the_tolerance_once_a_method_meets_it():
    """With a method meeting the tolerance, no 'most accurate' line follows it (a partial method
    below the tolerance read as more accurate than the advice); the costs are explained."""
    for tolerance in (0.02, 0.06):
        lines = advice_lines(entry_summary(ROWS), scene(sun=Sun(zenith_deg=40.0)), tolerance)
        assert lines[2].startswith("cheapest method meeting it")
        assert not any("most accurate" in line for line in lines), lines
        assert lines[-1] == COSTS_MEAN


def test_advice_costs_say_whose_they_are_and_what_they_count():
    """The cost of the advised method is labelled as the map's CPU's and its operation counts
    follow it; the closing line says what the costs are and that per-view and lookup times are
    warm."""
    lines = advice_lines(entry_summary(ROWS), scene(sun=Sun(zenith_deg=40.0)), 0.02)
    advised = lines[2]
    assert "on the map's CPU" in advised
    assert "counts: per sky direction: 2 scattering fetches; per ground direction: 4 scattering fetches" in advised
    assert "tables: scattering 4x8x16" in advised
    assert "first-call kernel compilation excluded" in lines[-1] and "table fetches" in lines[-1]
    # A map written before operations were counted still advises, without the counts.
    old = [{k: v for k, v in s.items() if k != "operations"} for s in entry_summary(ROWS)]
    lines = advice_lines(old, scene(sun=Sun(zenith_deg=40.0)), 0.02)
    assert lines[2].startswith("cheapest method meeting it: b (exact)") and "counts:" not in lines[2]


def test_map_report_tables_show_operations_and_scale():
    """The README's tables: what each entry's costs count, and per analytic entry and map sky the
    RMS as it is -> after the best scale factor (s), refused skies marked, and the gap in plain words."""
    from skyref.audit.map_report import analytic_gap_lines, analytic_scale_table, operations_table
    from skyref.audit.speed_map import MAP_SKIES

    first, second = MAP_SKIES[0].name, MAP_SKIES[1].name
    scale = {"factor": 0.606, "rms": 0.65, "noise_rms": 0.001, "resolved_rms": True,
             "rms_scaled": 0.10, "noise_rms_scaled": 0.05, "resolved_rms_scaled": False}
    rows = ROWS + [row("m published", first, "clear", 0.65, family="analytic", scale=scale),
                   row("m published", second, "clear", 0.0, family="analytic", refused=True)]
    summaries = entry_summary(rows)
    lines = operations_table(summaries)
    assert lines[0] == "| method | setting | what the costs count |"
    assert ("| b | exact | per sky direction: 2 scattering fetches; per ground direction: 4 scattering fetches; "
            "tables: scattering 4x8x16 |") in lines
    lines = analytic_scale_table(summaries)
    assert lines[0].startswith(f"| method | setting | {first} | {second} |")
    assert len(lines) == 3     # the LUT entries have no row
    cells = [c.strip() for c in lines[2].strip("|").split("|")]
    assert cells[:4] == ["m", "published", "65.0 → 10.0* (s = 0.606)", "refused"]
    assert cells[4:] == ["–"] * (len(MAP_SKIES) - 2)
    assert MAP_SKIES[0].kind == "clear" and MAP_SKIES[1].kind == "clear"     # the second is refused
    assert analytic_gap_lines(summaries) == [
        "- **m published**: on the clear skies 1.65x too bright (median best scale 0.606); sky luminance RMS "
        "error 65.0% as it is, 10.0% after that scale (the error of shape and colour)."]


def test_advise_cli(tmp_path, capsys):
    from skyref.cli import main

    path = tmp_path / "map.json"
    path.write_text(json.dumps({"entries": entry_summary(ROWS)}))
    assert main(["advise", "--scene", "scenes/earth-clear.toml", "--tolerance", "6%", "--map", str(path)]) == 0
    assert "cheapest method meeting it: a (cheap)" in capsys.readouterr().out
    assert main(["advise", "--scene", "scenes/earth-clear.toml", "--tolerance", "6", "--map", str(path)]) == 2
    assert main(["advise", "--scene", "scenes/earth-clear.toml", "--tolerance", "2%",
                 "--map", str(tmp_path / "none.json")]) == 2
    assert "skyref report" in capsys.readouterr().err


# --- the map measures what it claims ------------------------------------------------------------

def test_a_refitted_table_is_not_served_from_the_cache(tmp_path):
    table, truth = tmp_path / "hosek.npz", tmp_path / "truth.exr"
    entry = Entry("hosek2012", "analytic", "skyref fit", {"table": str(table)})
    sky = MapSky("clear, sun 30°", "clear", 0, 0.0, 30.0)
    table.write_bytes(b"first fit")
    truth.write_bytes(b"first truth")
    first = cache_path(str(tmp_path), entry, sky, str(truth))
    assert cache_path(str(tmp_path), entry, sky, str(truth)) == first
    table.write_bytes(b"second fit")
    assert cache_path(str(tmp_path), entry, sky, str(truth)) != first


def test_a_rerendered_truth_is_not_served_from_the_cache(tmp_path):
    """The LUT truth's skies are rendered again when the estimator improves: a row measured
    against the old EXR must not stand for the new one."""
    truth = tmp_path / "sky-043.exr"
    entry = Entry("bruneton2017", "LUT", "paper")
    sky = MapSky("hazy (T=6), sun 30°", "hazy", 1, 0.0, 30.0)
    truth.write_bytes(b"rendered to 0.3% by the estimator of 2026-12-05")
    first = cache_path(str(tmp_path), entry, sky, str(truth))
    truth.write_bytes(b"rendered to 0.3% by the estimator of 2026-12-06")
    assert cache_path(str(tmp_path), entry, sky, str(truth)) != first


def test_path_tracer_error_is_its_own_noise(tmp_path, mi, monkeypatch):
    """The map's error of the path tracer at 16 spp against a 256-spp truth is the path tracer's
    noise: its noise-corrected RMS over the sky matches the truth's relative standard error
    scaled by sqrt(256 / 16) = 4 (16 passes of the truth estimate it), within the spread of an
    RMS over these ~250 sky pixels and of the standard-error estimate (+-20%; measured 1.04).
    A cached row is reused without recomputing."""
    from skyref.io.exr import write_sky_exr
    from skyref.render import render_sky
    from skyref.scene import Camera, RenderSettings

    truth_scene = scene(camera=Camera(type="equirectangular", width=32, height=16),
                        wavelengths=(440.0, 550.0, 680.0), sun=Sun(zenith_deg=30.0),
                        render=RenderSettings(spp=256, passes=16, seed=5, pixel_sampling="centre",
                                                      estimator="delta_tracking"))
    truth = render_sky(truth_scene)
    path = tmp_path / "truth.exr"
    write_sky_exr(truth, path)
    sky = MapSky("test", "clear", 0, 0.0, 30.0)
    entry = Entry("skyref", "path tracer", "16 spp", {"spp": 16})
    rows = evaluate_map([entry], [(sky, str(path))], str(tmp_path / "cache"), log=lambda *_: None)
    measured = rows[0]["statistics"]["sky"]["luminance_rms"]

    from skyref.color import spectral_to_luminance

    luminance = spectral_to_luminance(truth.radiance, truth.wavelengths_nm)
    luminance_se = spectral_to_luminance(truth.standard_error, truth.wavelengths_nm)  # upper bound per pixel
    up = truth.directions[..., 2] > 0.05
    predicted = 4.0 * math.sqrt(np.mean((luminance_se[up] / luminance[up]) ** 2))
    print(f"path tracer 16 spp: measured {measured:.4f}, predicted {predicted:.4f}")
    assert 0.8 * predicted < measured < 1.2 * predicted, (measured, predicted)
    assert rows[0]["lookup_s"] > 0 and rows[0]["precompute_s"] == 0.0

    import skyref.audit.audit as audit_module

    monkeypatch.setattr(audit_module, "compare", lambda *a, **k: pytest.fail("recomputed a cached row"))
    again = evaluate_map([entry], [(sky, str(path))], str(tmp_path / "cache"), log=lambda *_: None)
    assert again == rows


def test_refusals_are_recorded_not_raised(tmp_path, mi):
    """A model outside its validity range leaves a 'refused' row naming the parameter."""
    from skyref.io.exr import write_sky_exr
    from skyref.render import render_sky
    from skyref.scene import Camera, RenderSettings

    high = scene(camera=Camera(type="equirectangular", width=8, height=4), wavelengths=(440.0, 550.0, 680.0),
                 observer=Observer(10000.0), render=RenderSettings(spp=8, passes=2, pixel_sampling="centre",
                                                                      estimator="delta_tracking"))
    path = tmp_path / "high.exr"
    write_sky_exr(render_sky(high), path)
    rows = evaluate_map([Entry("hosek2012", "analytic", "published 1.4a")],
                        [(MapSky("high", "high altitude", 0, 10000.0, 30.0), str(path))], str(tmp_path / "cache"),
                        log=lambda *_: None)
    assert "observer_altitude_m" in rows[0]["refused"]
    assert entry_summary(rows)[0]["kinds"]["high altitude"] is None


def test_every_map_sky_is_found_on_the_truth_grid():
    """Each map sky is the truth grid's sky with its atmosphere, altitude and sun, and its truth is
    that sky's EXR in the batch directory."""
    from skyref.audit.speed_map import MAP_SKIES, TRUTH_GRID, map_sky_specs, truth_skies
    from skyref.batch.grid import load_grid
    from skyref.scene import Scene

    grid = load_grid(TRUTH_GRID)
    found = map_sky_specs(grid)
    assert [sky for sky, _ in found] == list(MAP_SKIES)
    for sky, spec in found:
        truth_scene = Scene.from_dict(spec.scene)
        assert truth_scene.observer.altitude_m == sky.altitude_m and truth_scene.sun.zenith_deg == sky.sun_zenith_deg
        assert spec.coordinates["atmosphere"] == grid.axes["atmosphere"][sky.atmosphere]
    assert [path for _, path in truth_skies(grid)] == [
        os.path.join(grid.output.directory, "skies", f"{spec.sky_id}.exr") for _, spec in found]


def test_report_takes_the_shipped_truth_instead_of_rendering_it(tmp_path, monkeypatch):
    """On a fresh clone, ``skyref report`` imports the map skies from the truth that ships in
    results/lut_audit/truth (hours of rendering each) and renders none of them."""
    import shutil

    import skyref.audit.map_report as map_report
    import skyref.cli as cli
    from skyref.audit.speed_map import MAP_SKIES, map_sky_specs
    from skyref.batch import load_grid
    from skyref.batch.merge import LUT_AUDIT_TRUTH
    from skyref.batch.store import BatchStore

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    clone = tmp_path / "clone"
    for folder in ("grids", "scenes"):
        shutil.copytree(os.path.join(root, folder), clone / folder)
    shipped, piece = os.path.join(root, LUT_AUDIT_TRUTH), clone / LUT_AUDIT_TRUTH
    for folder in ("skies", "markers"):
        (piece / folder).mkdir(parents=True)
    shutil.copy(os.path.join(shipped, "grid.json"), piece / "grid.json")
    specs = map_sky_specs(load_grid(os.path.join(root, "grids", "lut_audit.toml")))
    for _, spec in specs:   # the map's skies alone: the piece is what a clone holds of them
        shutil.copy(os.path.join(shipped, "skies", f"{spec.sky_id}.exr"), piece / "skies")
        shutil.copy(os.path.join(shipped, "markers", f"{spec.sky_id}.json"), piece / "markers")
    monkeypatch.chdir(clone)
    unfinished = []

    def run_batch(grid, log, indices):
        unfinished.extend(i for i in indices if not BatchStore(grid).is_finished(grid.sky_id(i)))

    monkeypatch.setattr(cli, "run_batch", run_batch)
    monkeypatch.setattr(cli, "evaluate_map", lambda entries, skies, cache, log: [])
    monkeypatch.setattr(cli, "entry_summary", lambda rows: {})
    monkeypatch.setattr(map_report, "write_map_report", lambda *args: "results/README.md")
    assert cli.main(["report", "-q"]) == 0
    assert len(specs) == len(MAP_SKIES) and unfinished == []
