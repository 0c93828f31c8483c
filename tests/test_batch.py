"""Batch generation: grid checks before any work, deterministic seeds, resumability after
kill -9, and the dataset matching the EXRs."""

import json
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from skyref.batch.grid import MAX_ROUNDS, load_grid
from skyref.errors import ParameterError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture
def write_grid(earth_clear_baseline):
    """Writes a grid file over scenes/earth-clear.toml rendered by the baseline estimator (the
    batch machinery is the subject here, not the estimator; conftest.earth_clear_baseline)."""
    def write(path, axes: str, output: str):
        path.write_text(f'[base]\nscene = "{earth_clear_baseline}"\n[axes]\n{axes}\n[output]\n{output}\n')
        return str(path)
    return write


GOOD_AXES = '"sun.zenith_deg" = [20.0, 60.0, 85.0]\n"atmosphere.ground_albedo" = [0.0, 0.5]'
GOOD_OUTPUT = 'directory = "out"\nwidth = 12\nheight = 6\nspp = 8\npasses = 2'


@pytest.mark.parametrize("axes,output,name", [
    ('"sun.zenith" = [10.0]', GOOD_OUTPUT, "axes.sun.zenith"),
    ('"sun.zenith_deg" = [10.0, 200.0]', GOOD_OUTPUT, "axes.sun.zenith_deg"),
    ('"atmosphere.constituents.aerosol.angstrom_beta" = [0.01, -1.0]', GOOD_OUTPUT,
     "axes.atmosphere.constituents.aerosol.angstrom_beta"),
    ('"sun.zenith_deg" = []', GOOD_OUTPUT, "axes.sun.zenith_deg"),
    ('"sun.zenith_deg" = [10.0, 10.0]', GOOD_OUTPUT, "axes.sun.zenith_deg"),
    ('"camera.width" = [10, 20]', GOOD_OUTPUT, "axes.camera.width"),
    ('"atmosphere.preset" = ["bruneton2017", "mars"]', GOOD_OUTPUT, "axes.atmosphere.preset"),
    (GOOD_AXES, 'directory = "out"\nspp = 8\ntarget_relative_error = 0.1', "output.spp"),
    (GOOD_AXES, 'directory = "out"\nspp = 8\nformat = "hdr"', "output.format"),
    (GOOD_AXES, 'directory = "out"\nspp = 8\ncolour = 1', "output.colour"),
    (GOOD_AXES, 'directory = "out"\nspp = 32\ntargets = [{where = {"sun.zenith_deg" = 85.0}, '
     'target_relative_error = 0.1}]', "output.targets"),
    (GOOD_AXES, 'directory = "out"\ntarget_relative_error = 0.01\ntargets = [{where = {"sun.azimuth_deg" = 0.0}, '
     'target_relative_error = 0.1}]', "output.targets[0].where.sun.azimuth_deg"),
    (GOOD_AXES, 'directory = "out"\ntarget_relative_error = 0.01\ntargets = [{where = {"sun.zenith_deg" = 80.0}, '
     'target_relative_error = 0.1}]', "output.targets[0].where.sun.zenith_deg"),
    (GOOD_AXES, 'directory = "out"\ntarget_relative_error = 0.01\ntargets = [{where = {"sun.zenith_deg" = 85.0}, '
     'target_relative_error = 2.0}]', "output.targets[0].target_relative_error"),
    (GOOD_AXES, 'directory = "out"\ntarget_relative_error = 0.01\ntargets = [{where = {"sun.zenith_deg" = 85.0}}]',
     "output.targets[0]"),
    (GOOD_AXES, 'directory = "out"\nspp = 32\ndynamic_range = 1e-4', "output.dynamic_range"),
    (GOOD_AXES, 'directory = "out"\ntarget_relative_error = 0.01\ndynamic_range = 0.5', "output.dynamic_range"),
])
def test_bad_grid_is_rejected_naming_the_entry(write_grid, tmp_path, axes, output, name):
    with pytest.raises(ParameterError) as info:
        grid = load_grid(write_grid(tmp_path / "grid.toml", axes, output))
        grid.validate()
    assert info.value.name == name, str(info.value)
    assert not (tmp_path / "out").exists()


def test_unwritable_output_is_rejected_before_rendering(write_grid, tmp_path, monkeypatch):
    import skyref.batch.run as batch_run
    from skyref.batch import run_batch

    def no_cluster(*args, **kwargs):
        raise AssertionError("a cluster was started before the output directory was checked")

    monkeypatch.setattr(batch_run, "local_cluster", no_cluster)
    (tmp_path / "a-file").write_text("not a directory")
    grid = load_grid(write_grid(tmp_path / "grid.toml", GOOD_AXES,
                                GOOD_OUTPUT.replace('"out"', '"a-file/out"')))
    with pytest.raises(ParameterError) as info:
        run_batch(grid, workers=1, progress=False)
    assert info.value.name == "output.directory"


def test_cli_reports_bad_grid_in_one_line(write_grid, tmp_path):
    from skyref.cli import main

    path = write_grid(tmp_path / "grid.toml", '"sun.zenith_deg" = [10.0, 200.0]', GOOD_OUTPUT)
    assert main(["batch", path, "-q"]) == 2


def test_the_forecast_prints_each_sky_still_to_render_and_writes_nothing(write_grid, tmp_path, capsys):
    """``skyref batch --forecast``: one line per unfinished sky (its axis values, CPU, views and
    samples), then the total; the output directory is not created. Bad input gets one line naming
    the parameter and exit status 2, before any pilot: a pilot count below the passes, --pilot-spp
    without --forecast, a grid with a fixed spp (nothing adaptive to forecast)."""
    from skyref.cli import main

    output = 'directory = "out"\nwidth = 8\nheight = 4\ntarget_relative_error = 0.05\nmax_spp = 4096\npasses = 16'
    path = write_grid(tmp_path / "grid.toml", '"sun.zenith_deg" = [20.0, 60.0]', output)
    assert main(["batch", path, "--forecast", "--pilot-spp", "256", "--skies", "1"]) == 0
    printed = capsys.readouterr().out
    assert re.search(r"sky-1 \(sun\.zenith_deg=60\.0\): [\d,]+ CPU s \[[\d,]+\], \d+ views x [\d,]+ samples", printed), printed
    assert "sky-0" not in printed and "1 skies to render" in printed
    assert not (tmp_path / "out").exists()
    for arguments, name in [(["--forecast", "--pilot-spp", "8"], "--pilot-spp"), (["--pilot-spp", "256"], "--pilot-spp"),
                            (["--forecast", "--dry-run"], "--forecast")]:
        assert main(["batch", path, *arguments]) == 2
        assert name in capsys.readouterr().err
    fixed = write_grid(tmp_path / "fixed.toml", '"sun.zenith_deg" = [20.0]', GOOD_OUTPUT)
    assert main(["batch", fixed, "--forecast"]) == 2
    assert "output.target_relative_error" in capsys.readouterr().err


def test_seeds_are_distinct_across_skies_rounds_and_base_seeds(write_grid, tmp_path):
    seen = set()
    for base_seed in (0, 1, 2):
        grid = load_grid(write_grid(tmp_path / "grid.toml", GOOD_AXES, GOOD_OUTPUT + f"\nseed = {base_seed}"))
        seeds = [grid.seed(i, r) for i in range(len(grid)) for r in range(MAX_ROUNDS)]
        assert len(set(seeds)) == len(seeds)
        assert not seen & set(seeds)
        seen |= set(seeds)
    # The same grid file gives the same seed and scene for every sky.
    again = load_grid(write_grid(tmp_path / "grid.toml", GOOD_AXES, GOOD_OUTPUT + "\nseed = 2"))
    assert [again.sky(i) for i in range(len(again))] == [grid.sky(i) for i in range(len(grid))]


def test_axis_values_reach_the_scene(write_grid, tmp_path):
    from skyref.scene import Scene

    grid = load_grid(write_grid(tmp_path / "grid.toml", GOOD_AXES + '\n"atmosphere.turbidity" = [2.0, 6.0]',
                                GOOD_OUTPUT))
    assert grid.shape == (3, 2, 2) and len(grid) == 12
    spec = grid.sky(11)  # last axis fastest: indices (2, 1, 1)
    assert spec.coordinates == {"sun.zenith_deg": 85.0, "atmosphere.ground_albedo": 0.5, "atmosphere.turbidity": 6.0}
    scene = Scene.from_dict(spec.scene)
    from skyref.atmosphere import turbidity

    assert scene.sun.zenith_deg == 85.0 and (scene.camera.width, scene.camera.height) == (12, 6)
    assert float(scene.atmosphere.ground_albedo(550.0)) == 0.5
    assert turbidity(scene.atmosphere) == pytest.approx(6.0, rel=1e-6)


def _batch_command(grid_path):
    return [sys.executable, "-m", "skyref.cli", "batch", grid_path, "--workers", "1", "-q"]


def _markers(directory):
    """The finished skies' markers (not a marker being written: a hidden temporary file)."""
    folder = os.path.join(directory, "markers")
    return sorted(n for n in os.listdir(folder) if not n.startswith(".")) if os.path.isdir(folder) else []


def test_kill_9_then_resume_equals_an_uninterrupted_run(write_grid, tmp_path):
    """Kill a running batch with SIGKILL once some skies are finished, rerun it, and compare
    with a run that was never interrupted: every sky once, complete, identical."""
    import xarray as xr

    from skyref.io.exr import read_sky_exr

    axes = '"sun.zenith_deg" = [10.0, 40.0, 70.0, 85.0]\n"atmosphere.ground_albedo" = [0.0, 0.6]'
    output = 'width = 16\nheight = 8\nspp = 64\npasses = 2'
    killed = write_grid(tmp_path / "killed.toml", axes, 'directory = "killed"\n' + output)
    clean = write_grid(tmp_path / "clean.toml", axes, 'directory = "clean"\n' + output)
    killed_dir, clean_dir = str(tmp_path / "killed"), str(tmp_path / "clean")

    process = subprocess.Popen(_batch_command(killed), start_new_session=True,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while len(_markers(killed_dir)) < 2 and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.05)
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    finished_before = {name: open(os.path.join(killed_dir, "markers", name)).read()
                       for name in _markers(killed_dir)}
    assert 2 <= len(finished_before) < 8, "the kill must land mid-run"

    assert subprocess.run(_batch_command(killed), capture_output=True).returncode == 0
    assert subprocess.run(_batch_command(clean), capture_output=True).returncode == 0

    # Skies finished before the kill were skipped (their markers are untouched) ...
    for name, text in finished_before.items():
        assert open(os.path.join(killed_dir, "markers", name)).read() == text
    # ... every sky exists exactly once, no temporary files are left ...
    assert _markers(killed_dir) == _markers(clean_dir) == [f"sky-{i}.json" for i in range(8)]
    assert sorted(os.listdir(os.path.join(killed_dir, "markers"))) == _markers(killed_dir)
    assert sorted(os.listdir(os.path.join(killed_dir, "skies"))) == [f"sky-{i}.exr" for i in range(8)]
    manifest = json.load(open(os.path.join(killed_dir, "manifest.json")))
    assert manifest["skies_finished"] == manifest["skies_total"] == 8
    # ... and the data equal the uninterrupted run's, in the EXRs and in the dataset.
    killed_data = xr.open_zarr(os.path.join(killed_dir, "dataset.zarr")).load()
    clean_data = xr.open_zarr(os.path.join(clean_dir, "dataset.zarr")).load()
    for i in range(8):
        # the same bytes (no timings in data files), so the same SHA-256 in the markers
        exr_a, exr_b = (os.path.join(d, "skies", f"sky-{i}.exr") for d in (killed_dir, clean_dir))
        assert open(exr_a, "rb").read() == open(exr_b, "rb").read(), f"sky-{i}.exr differs"
        markers = [json.load(open(os.path.join(d, "markers", f"sky-{i}.json"))) for d in (killed_dir, clean_dir)]
        assert markers[0]["exr_sha256"] == markers[1]["exr_sha256"]
        a = read_sky_exr(exr_a)
        b = read_sky_exr(exr_b)
        np.testing.assert_array_equal(a.radiance, b.radiance)
        np.testing.assert_array_equal(a.standard_error, b.standard_error)
        zenith, albedo = divmod(i, 2)
        np.testing.assert_array_equal(killed_data.radiance.values[zenith, albedo], a.radiance)
    np.testing.assert_array_equal(killed_data.radiance.values, clean_data.radiance.values)
    assert np.all(np.isfinite(killed_data.radiance.values))  # every sky was written


def test_a_directory_holding_another_grid_is_refused(write_grid, tmp_path):
    from skyref.batch import run_batch
    from skyref.batch.store import BatchStore

    grid = load_grid(write_grid(tmp_path / "grid.toml", GOOD_AXES, GOOD_OUTPUT))
    BatchStore(grid).check_writable()
    BatchStore(grid).prepare(grid.validate())
    other = load_grid(write_grid(tmp_path / "grid.toml", GOOD_AXES, GOOD_OUTPUT.replace("spp = 8", "spp = 16")))
    with pytest.raises(ParameterError, match="different grid"):
        run_batch(other, workers=1, progress=False)


def test_rgb_dataset_holds_the_colorimetric_rgb_of_each_exr(write_grid, tmp_path):
    import xarray as xr

    from skyref.batch import run_batch
    from skyref.io.exr import read_sky_exr

    grid = load_grid(write_grid(tmp_path / "grid.toml", '"sun.zenith_deg" = [30.0, 60.0]',
                                'directory = "rgb"\nformat = "rgb"\nwidth = 8\nheight = 4\nspp = 8\npasses = 2'))
    manifest = run_batch(grid, workers=1, progress=False, log=lambda *_: None)
    assert manifest["skies_finished"] == 2 and not manifest["failed"]
    data = xr.open_zarr(str(tmp_path / "rgb" / "dataset.zarr")).load()
    assert list(data.channel.values) == ["R", "G", "B"]
    for i, marker in enumerate(manifest["skies"]):
        sky = read_sky_exr(tmp_path / "rgb" / marker["exr"])
        np.testing.assert_allclose(data.rgb.values[i], sky.rgb(), rtol=1e-5, atol=1e-6)
        assert data.spp.values[i] == marker["spp"] == 8


def test_runs_on_a_given_dask_scheduler(write_grid, tmp_path):
    """--scheduler: the same grid on an external dask cluster gives the same skies."""
    from dask.distributed import LocalCluster

    from skyref.batch import run_batch
    from skyref.io.exr import read_sky_exr

    axes = '"sun.zenith_deg" = [30.0, 70.0]'
    output = 'width = 8\nheight = 4\nspp = 8\npasses = 2'
    external = load_grid(write_grid(tmp_path / "a.toml", axes, 'directory = "external"\n' + output))
    local = load_grid(write_grid(tmp_path / "b.toml", axes, 'directory = "local"\n' + output))
    with LocalCluster(n_workers=1, threads_per_worker=1, dashboard_address=None) as cluster:
        manifest = run_batch(external, scheduler=cluster.scheduler_address, progress=False, log=lambda *_: None)
    assert manifest["skies_finished"] == 2 and not manifest["failed"]
    run_batch(local, workers=1, progress=False, log=lambda *_: None)
    for i in range(2):
        a = read_sky_exr(tmp_path / "external" / "skies" / f"sky-{i}.exr")
        b = read_sky_exr(tmp_path / "local" / "skies" / f"sky-{i}.exr")
        np.testing.assert_array_equal(a.radiance, b.radiance)


def test_sky_numbers_keep_the_order_listed(write_grid, tmp_path):
    """--skies "5,1-2,1": 5, 1, 2 (a batch renders cheap skies first when told so), each once;
    a range past the grid's end, a reversed range or a word are refused naming --skies."""
    grid = load_grid(write_grid(tmp_path / "g.toml", '"sun.zenith_deg" = [0.0, 10.0, 20.0, 30.0, 40.0, 50.0]',
                                'directory = "g"\nwidth = 8\nheight = 4\nspp = 8\npasses = 2'))
    assert grid.sky_numbers("5,1-2,1") == [5, 1, 2]
    assert grid.sky_numbers(" 3 , 0-1") == [3, 0, 1]
    for bad in ("4-6", "2-1", "two"):
        with pytest.raises(ParameterError, match="--skies"):
            grid.sky_numbers(bad)


def test_part_of_a_grid_renders_those_skies_as_the_whole_grid_would(write_grid, tmp_path):
    """run_batch(indices=...): only those skies, with the whole grid's ids and seeds (the same
    EXRs as a run of the whole grid); a number outside the grid is refused naming ``indices``
    before anything is written."""
    from skyref.batch import run_batch
    from skyref.io.exr import read_sky_exr

    axes = '"sun.zenith_deg" = [20.0, 50.0, 80.0]'
    output = 'width = 8\nheight = 4\nspp = 8\npasses = 2'
    part = load_grid(write_grid(tmp_path / "a.toml", axes, 'directory = "part"\n' + output))
    whole = load_grid(write_grid(tmp_path / "b.toml", axes, 'directory = "whole"\n' + output))
    with pytest.raises(ParameterError, match="indices"):
        run_batch(part, workers=1, progress=False, log=lambda *_: None, indices=[0, 3])
    assert not (tmp_path / "part").exists()
    manifest = run_batch(part, workers=1, progress=False, log=lambda *_: None, indices=[2])
    assert manifest["skies_finished"] == 1 and [m["exr"] for m in manifest["skies"]] == ["skies/sky-2.exr"]
    run_batch(whole, workers=1, progress=False, log=lambda *_: None)
    a = read_sky_exr(tmp_path / "part" / "skies" / "sky-2.exr")
    b = read_sky_exr(tmp_path / "whole" / "skies" / "sky-2.exr")
    np.testing.assert_array_equal(a.radiance, b.radiance)


def test_the_truth_says_what_it_is_and_what_it_cost(tmp_path):
    """truth_provenance reads the estimator and samples from each truth EXR and the CPU time
    from the batch's markers; a truth written before EXRs named their estimator was delta
    tracking's; without a marker the cost is unknown (None), not 0."""
    from skyref.batch.provenance import batch_skies, describe_truth, truth_provenance
    from skyref.io.exr import write_sky_exr
    from skyref.projection import pixel_directions
    from skyref.scene import Camera, Scene
    from skyref.sky import Sky

    (tmp_path / "skies").mkdir()
    (tmp_path / "markers").mkdir()
    truth_scene = Scene(camera=Camera(type="equirectangular", width=8, height=4), wavelengths=(440.0, 550.0))
    for name, spp, estimator in (("sky-000", 16, "line_integral"), ("sky-001", 32, None)):
        # sky-001 as EXRs were written before the line integral: no estimator in the metadata
        metadata = {"spp": spp} if estimator is None else {"spp": spp, "estimator": estimator}
        values = np.ones((4, 8, 2), dtype=np.float32)
        write_sky_exr(Sky(radiance=values, standard_error=0.01 * values, wavelengths_nm=np.array([440.0, 550.0]),
                          directions=pixel_directions(truth_scene.camera), scene=truth_scene, metadata=metadata),
                      tmp_path / "skies" / f"{name}.exr")
        (tmp_path / "markers" / f"{name}.json").write_text(json.dumps({"task_cpu_s": 1800.0 + spp}))
    skies = batch_skies(tmp_path)
    assert [os.path.basename(path) for path in skies] == ["sky-000.exr", "sky-001.exr"]
    found = truth_provenance(skies)
    assert found == {"estimators": ["delta_tracking", "line_integral"], "camera": "8x4 equirectangular",
                     "wavelengths": (2, 440.0, 550.0), "spp": (16.0, 32.0), "cpu_s": 3648.0}
    assert describe_truth(found) == ("delta tracking and line integral estimators, 8x4 equirectangular pixel-centre "
                                     "directions, 2 wavelengths 440–550 nm, 16–32 samples per direction on average "
                                     "(rendered to an error target), 1.01 CPU hours")
    (tmp_path / "markers" / "sky-001.json").unlink()
    assert truth_provenance(skies)["cpu_s"] is None
    with pytest.raises(ParameterError, match="truth skies"):
        truth_provenance(batch_skies(tmp_path / "no-batch-here"))


def test_pieces_rendered_apart_import_into_the_same_directory_a_whole_run_makes(write_grid, tmp_path):
    """A grid rendered in two pieces in two directories (as on two machines; one piece by
    ``skyref batch --skies``), one imported into the other: the same EXRs and the same dataset as
    one run of the whole grid; the imported markers say where from; importing again changes
    nothing; an EXR that does not match its marker is left out; another grid's directory, and
    --skies beside --import-from, are refused naming the option, nothing written."""
    import xarray as xr

    from skyref.batch import run_batch
    from skyref.batch.merge import import_skies
    from skyref.batch.store import sha256_of
    from skyref.cli import main

    axes = '"sun.zenith_deg" = [20.0, 50.0, 80.0]'
    output = 'width = 8\nheight = 4\nspp = 8\npasses = 2'
    quiet = dict(workers=1, progress=False, log=lambda *_: None)
    here = load_grid(write_grid(tmp_path / "here.toml", axes, 'directory = "here"\n' + output))
    there = load_grid(write_grid(tmp_path / "there.toml", axes, 'directory = "there"\n' + output))
    whole = load_grid(write_grid(tmp_path / "whole.toml", axes, 'directory = "whole"\n' + output))
    run_batch(here, indices=[0], **quiet)
    assert main(["batch", str(tmp_path / "there.toml"), "--skies", "1-3", "-q"]) == 2    # no sky 3
    assert not (tmp_path / "there").exists()
    assert main(["batch", str(tmp_path / "there.toml"), "--skies", "1-2", "--workers", "1", "-q"]) == 0
    run_batch(whole, **quiet)

    other = write_grid(tmp_path / "other.toml", '"sun.zenith_deg" = [20.0, 50.0]', 'directory = "here"\n' + output)
    before = sorted(os.listdir(tmp_path / "here" / "skies"))
    assert main(["batch", other, "--import-from", str(tmp_path / "there")]) == 2
    assert main(["batch", str(tmp_path / "here.toml"), "--skies", "1", "--import-from", str(tmp_path / "there")]) == 2
    with pytest.raises(ParameterError, match="source"):
        import_skies(here, str(tmp_path / "nowhere"))
    assert sorted(os.listdir(tmp_path / "here" / "skies")) == before

    report = import_skies(here, str(tmp_path / "there"), log=lambda *_: None)
    assert report == {"imported": ["sky-1", "sky-2"], "kept": [], "corrupt": []}
    for i in range(3):
        assert sha256_of(tmp_path / "here" / "skies" / f"sky-{i}.exr") == \
            sha256_of(tmp_path / "whole" / "skies" / f"sky-{i}.exr")
    ours = xr.open_zarr(str(tmp_path / "here" / "dataset.zarr")).load()
    reference = xr.open_zarr(str(tmp_path / "whole" / "dataset.zarr")).load()
    for name in ("radiance", "standard_error", "spp", "relative_error_p95"):
        np.testing.assert_array_equal(ours[name].values, reference[name].values)
    with open(tmp_path / "here" / "markers" / "sky-2.json") as f:
        assert json.load(f)["imported_from"] == str(tmp_path / "there")
    with open(tmp_path / "here" / "manifest.json") as f:
        assert json.load(f)["skies_finished"] == 3
    assert import_skies(here, str(tmp_path / "there"), log=lambda *_: None)["imported"] == []

    with open(tmp_path / "there" / "skies" / "sky-2.exr", "r+b") as f:   # same size, other bytes
        f.seek(-1, os.SEEK_END)
        last = f.read(1)
        f.seek(-1, os.SEEK_END)
        f.write(bytes([last[0] ^ 0xFF]))
    fresh = load_grid(write_grid(tmp_path / "fresh.toml", axes, 'directory = "fresh"\n' + output))
    assert import_skies(fresh, str(tmp_path / "there"), log=lambda *_: None) == \
        {"imported": ["sky-1"], "kept": [], "corrupt": ["sky-2"]}
    assert not (tmp_path / "fresh" / "skies" / "sky-2.exr").exists()


def test_an_adaptive_sky_killed_mid_render_resumes_from_its_checkpoint(write_grid, tmp_path):
    """An adaptive sky (target_relative_error) keeps its state in partial/<id>.npz after every
    launch: a batch killed with SIGKILL mid-render resumes the sky from there, and its EXR is the
    uninterrupted run's byte for byte; the checkpoint is gone once the sky is marked."""
    axes = '"sun.zenith_deg" = [40.0]'
    output = 'width = 8\nheight = 4\ntarget_relative_error = 0.01\nmax_spp = 32768\npasses = 16'
    killed = write_grid(tmp_path / "killed.toml", axes, 'directory = "killed"\n' + output)
    clean = write_grid(tmp_path / "clean.toml", axes, 'directory = "clean"\n' + output)
    killed_dir, clean_dir = str(tmp_path / "killed"), str(tmp_path / "clean")
    checkpoint = os.path.join(killed_dir, "partial", "sky-0.npz")

    process = subprocess.Popen(_batch_command(killed), start_new_session=True,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while not os.path.exists(checkpoint) and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.02)
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    assert os.path.exists(checkpoint) and _markers(killed_dir) == [], "the kill must land mid-render"
    dry_run = subprocess.run([*_batch_command(killed)[:-3], "--dry-run"], capture_output=True, text=True)
    assert "0 of 1 skies finished (0.00 CPU hours), 1 rendered part-way, 0 not started" in dry_run.stdout
    assert re.search(r"sky-0: \d+ rounds? done( \(round \d+: \d+ of \d+ launches\))?, \d+% of \d+ views at 1%, render time \d+ s", dry_run.stdout)
    with np.load(checkpoint) as kept:
        assert int(kept["samples"].min()) > 0                  # the first round was kept
        state = dict(kept)
    # a render time and CPU the rerun can only have from the checkpoint (they change no data): that
    # it was resumed, and that the marker counts the killed run's CPU
    state["elapsed"], state["cpu"] = np.float64(1e6), np.float64(2e6)
    with open(checkpoint, "wb") as f:
        np.savez(f, **state)

    assert subprocess.run(_batch_command(killed), capture_output=True).returncode == 0
    assert subprocess.run(_batch_command(clean), capture_output=True).returncode == 0
    assert not os.path.exists(checkpoint) and _markers(killed_dir) == ["sky-0.json"]
    exr_a, exr_b = (os.path.join(d, "skies", "sky-0.exr") for d in (killed_dir, clean_dir))
    assert open(exr_a, "rb").read() == open(exr_b, "rb").read()
    marker = json.load(open(os.path.join(killed_dir, "markers", "sky-0.json")))
    assert marker["render_time_s"] > 1e6 and len(marker["seed"]) >= 2     # resumed; more than one round
    assert marker["task_cpu_s"] > 2e6


def test_skies_matched_by_a_target_entry_are_rendered_to_its_target(write_grid, tmp_path):
    """``[[output.targets]]``: the skies at its axis values get its target, the others the grid's
    (the LUT audit asks 0.3% of its skies up to sun zenith 92 deg, less of the twilight ones); the
    grid's ``dynamic_range`` reaches every sky's render; a grid without entries or dynamic range
    keeps the fingerprint it had before they existed."""
    from skyref.batch import run_batch
    from skyref.io.exr import read_sky_exr

    axes = '"sun.zenith_deg" = [40.0, 60.0]'
    output = ('directory = "out"\nwidth = 8\nheight = 4\ntarget_relative_error = 0.02\nmax_spp = 65536\n'
              'passes = 16\ndynamic_range = 1e-4\n'
              'targets = [{where = {"sun.zenith_deg" = 60}, target_relative_error = 0.08}]')
    grid = load_grid(write_grid(tmp_path / "grid.toml", axes, output))
    assert [grid.target_relative_error(spec.coordinates) for spec in grid.skies()] == [0.02, 0.08]
    run_batch(grid, workers=1, progress=False, log=lambda *_: None)
    skies = [read_sky_exr(str(tmp_path / "out" / "skies" / f"sky-{i}.exr")) for i in (0, 1)]
    assert [sky.metadata["target_relative_error"] for sky in skies] == [0.02, 0.08]
    assert [sky.metadata["dynamic_range"] for sky in skies] == [1e-4, 1e-4]
    assert skies[0].metadata["spp"] > 4 * skies[1].metadata["spp"]         # (0.08 / 0.02)^2 = 16 x the samples

    plain = load_grid(write_grid(tmp_path / "plain.toml", axes, output.split("\ndynamic_range")[0]))
    assert '"targets"' not in plain.fingerprint() and '"targets"' in grid.fingerprint()
    assert '"dynamic_range"' not in plain.fingerprint() and '"dynamic_range": 0.0001' in grid.fingerprint()


def test_exported_skies_import_into_a_fresh_directory_as_rendered(write_grid, tmp_path):
    """``export_skies``: the skies finished in a grid's output become a piece (EXRs, markers,
    grid.json; how the LUT audit's ground truth ships) that a fresh directory imports byte for
    byte; exporting again copies nothing; a sky whose EXR does not match its marker stays out;
    a piece of another grid is refused, nothing written."""
    from skyref.batch import run_batch
    from skyref.batch.merge import export_skies, import_skies
    from skyref.batch.store import sha256_of

    axes = '"sun.zenith_deg" = [20.0, 50.0, 80.0]'
    output = 'width = 8\nheight = 4\nspp = 8\npasses = 2'
    quiet = dict(log=lambda *_: None)
    rendered = load_grid(write_grid(tmp_path / "rendered.toml", axes, 'directory = "rendered"\n' + output))
    fresh = load_grid(write_grid(tmp_path / "fresh.toml", axes, 'directory = "fresh"\n' + output))
    run_batch(rendered, workers=1, progress=False, **quiet)
    with open(tmp_path / "rendered" / "skies" / "sky-2.exr", "r+b") as f:   # same size, other bytes
        f.seek(-1, os.SEEK_END)
        last = f.read(1)
        f.seek(-1, os.SEEK_END)
        f.write(bytes([last[0] ^ 1]))

    piece = str(tmp_path / "piece")
    assert export_skies(rendered, piece, **quiet) == ["sky-0", "sky-1"]
    assert sorted(os.listdir(piece)) == ["grid.json", "markers", "skies"]
    assert export_skies(rendered, piece, **quiet) == []
    assert import_skies(fresh, piece, **quiet)["imported"] == ["sky-0", "sky-1"]
    for i in (0, 1):
        assert sha256_of(tmp_path / "fresh" / "skies" / f"sky-{i}.exr") == \
            sha256_of(tmp_path / "rendered" / "skies" / f"sky-{i}.exr")

    other = load_grid(write_grid(tmp_path / "other.toml", '"sun.zenith_deg" = [20.0]',
                                 'directory = "other"\n' + output))
    run_batch(other, workers=1, progress=False, **quiet)
    before = sorted(os.listdir(os.path.join(piece, "skies")))
    with pytest.raises(ParameterError, match="destination"):
        export_skies(other, piece, **quiet)
    assert sorted(os.listdir(os.path.join(piece, "skies"))) == before


def test_the_local_cluster_keeps_a_worker_it_has_not_heard_from():
    """A batch paused for longer than dask's worker time-to-live (5 minutes; SIGSTOP, a suspended
    laptop) must not lose its workers on resuming: each sky queued on a dropped worker counts it as
    a death, and a sky fails after three (two LUT-audit skies did, 2026-12-05). The local
    cluster's scheduler keeps no time-to-live; a worker process that dies is seen by its nanny."""
    import dask
    import distributed  # noqa: F401  (loads dask's distributed settings)

    from skyref.batch.run import local_cluster

    assert dask.config.get("distributed.scheduler.worker-ttl") is not None   # dask's default: 5 minutes
    cluster, _ = local_cluster(1)
    try:
        assert cluster.scheduler.worker_ttl is None
    finally:
        cluster.close()
