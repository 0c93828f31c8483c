"""Hard inputs through the command line: each is refused before any work with exit status 2 and
one error line that names the parameter, and leaves nothing behind in the output's place."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from skyref.cli import main
from skyref.errors import ParameterError

ROOT = Path(__file__).resolve().parent.parent
EARTH_CLEAR = ROOT / "scenes" / "earth-clear.toml"
SMALL = '[camera]\nwidth = 16\nheight = 8\n[render]\nspp = 4\npasses = 2\n'


def refused(capsys, argv, name):
    """Run ``skyref ARGV``: exit status 2, one line on stderr naming ``name``, no traceback."""
    status = main([str(a) for a in argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2, err
    assert len(err) == 1, err
    assert f"error: {name} = " in err[0], err[0]
    return err[0]


def nothing_written(directory, *keep):
    """Only the inputs ``keep`` (names) are in ``directory``."""
    assert sorted(os.listdir(directory)) == sorted(keep), os.listdir(directory)


@pytest.fixture
def npz_tables(tmp_path):
    path = tmp_path / "tables.npz"
    np.savez(path, transmittance=np.ones((4, 4, 3)), scattering=np.ones((2, 2, 4, 4)),
             irradiance=np.ones((2, 2, 3)), bogus=np.zeros(3))
    return path


def test_a_missing_mesh_is_refused_before_the_render(tmp_path, capsys):
    scene = tmp_path / "scene.toml"
    scene.write_text(SMALL + '[[objects]]\ntype = "obj"\nfilename = "no-such-mesh.obj"\n')
    refused(capsys, ["validate", scene], "objects[0].filename")
    refused(capsys, ["render", scene, "-o", tmp_path / "sky.exr", "-q"], "objects[0].filename")
    nothing_written(tmp_path, "scene.toml")


def test_audit_refuses_unknown_options_and_bad_tables(tmp_path, capsys, npz_tables):
    out = tmp_path / "report"
    line = refused(capsys, ["audit", "--method", "bruneton2017", "--scene", EARTH_CLEAR, "--option", "bogus=1",
                            "-o", out], "--option")
    assert "scattering_orders" in line                      # the valid options are listed
    refused(capsys, ["audit", "--method", "preetham1999", "--scene", EARTH_CLEAR, "--option", "bogus=1",
                     "-o", out], "--option")
    refused(capsys, ["audit", "--method", "bruneton2017", "--scene", EARTH_CLEAR, "--tables", npz_tables,
                     "-o", out], "--tables array")
    refused(capsys, ["audit", "--method", "bruneton2017", "--scene", EARTH_CLEAR, "--tables",
                     tmp_path / "missing.npz", "-o", out], "--tables")
    text = tmp_path / "text.npz"
    text.write_text("not an archive\n")
    refused(capsys, ["audit", "--method", "bruneton2017", "--scene", EARTH_CLEAR, "--tables", text, "-o", out],
            "--tables")
    nothing_written(tmp_path, "tables.npz", "text.npz")


@pytest.mark.parametrize("content", ["{}", '{"entries": [{"method": "x"}]}', "{not json", b"\xff\xfe\x00"])
def test_advise_refuses_a_malformed_map(tmp_path, capsys, content):
    path = tmp_path / "map.json"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    refused(capsys, ["advise", "--scene", EARTH_CLEAR, "--tolerance", "2%", "--map", path], "--map")


@pytest.mark.parametrize("text, name", [
    ('[atmosphere]\ntop_radius_m = 6420000.0\n', "atmosphere"),          # would be a vacuum
    ('name = "' + "x" * 300 + '"\n', "name"),
    ('[spectral]\nwavelengths = { start_nm = 360.0, stop_nm = 830.0, step_nm = 1e-6 }\n', "step_nm"),
    ('[spectral]\nwavelengths = { start_nm = 360.0, stop_nm = 830.0, step_nm = 0.1 }\n', "spectral.wavelengths"),
    ('[camera]\nwidth = 16384\nheight = 16384\n[spectral]\nwavelengths = { start_nm = 360.0, stop_nm = 830.0, '
     'step_nm = 10.0 }\n', "camera"),
])
def test_render_refuses_nonsense_and_unbounded_scenes(tmp_path, capsys, text, name):
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    refused(capsys, ["render", scene, "-o", tmp_path / "out" / "sky.exr", "-q"], name)
    nothing_written(tmp_path, "scene.toml")


def test_a_binary_scene_and_an_output_that_is_a_directory(tmp_path, capsys):
    binary = tmp_path / "scene.toml"
    binary.write_bytes(bytes(range(256)))
    refused(capsys, ["validate", binary], "scene")
    (tmp_path / "sky.exr").mkdir()
    refused(capsys, ["render", EARTH_CLEAR, "-o", tmp_path / "sky.exr", "-q"], "--output")
    nothing_written(tmp_path, "scene.toml", "sky.exr")


def test_echoed_values_are_cut_to_a_readable_length():
    from skyref.atmosphere import preset

    with pytest.raises(ParameterError) as info:
        preset("x" * 10_000_000)
    assert len(str(info.value)) < 500 and "10,000,002 characters" in str(info.value)


def grid_file(tmp_path, axes, output='directory = "out"\nspp = 8\nwidth = 8\nheight = 4\npasses = 2'):
    path = tmp_path / "grid.toml"
    path.write_text(f'[base]\nscene = "{EARTH_CLEAR}"\n[axes]\n{axes}\n[output]\n{output}\n')
    return path


@pytest.mark.parametrize("axes, name", [
    ('"sun.zenith_deg" = [' + ", ".join(str(10 + i * 1e-6) for i in range(20_000)) + "]", "axes.sun.zenith_deg"),
    ("\n".join(f'"{p}" = [{", ".join(str(v) for v in range(1000))}]'
               for p in ("sun.zenith_deg", "sun.azimuth_deg", "observer.altitude_m")), "axes"),
])
def test_batch_refuses_grids_too_large_to_plan(tmp_path, capsys, axes, name):
    refused(capsys, ["batch", grid_file(tmp_path, axes), "-q"], name)
    nothing_written(tmp_path, "grid.toml")


@pytest.mark.parametrize("options, name", [(["--workers", "0"], "workers"),
                                           (["--scheduler", "tcp://127.0.0.1:9"], "scheduler"),
                                           (["--scheduler", "not an address"], "scheduler")])
def test_batch_refuses_bad_workers_and_schedulers_leaving_nothing(tmp_path, capsys, options, name):
    refused(capsys, ["batch", grid_file(tmp_path, '"sun.zenith_deg" = [30.0, 60.0]'), *options, "-q"], name)
    nothing_written(tmp_path, "grid.toml")


@pytest.mark.parametrize("mode, size", [("L", (16, 16)), ("RGB", (3, 200))])
def test_invert_refuses_greyscale_and_tiny_images_leaving_nothing(tmp_path, capsys, mode, size):
    from PIL import Image

    Image.new(mode, size, 128).save(tmp_path / "sky.png")
    refused(capsys, ["invert", tmp_path / "sky.png", "-o", tmp_path / "fit", "--camera", "fisheye",
                     "--sun-zenith", "40", "--sun-azimuth", "120", "-q"], "image")
    nothing_written(tmp_path, "sky.png")


@pytest.mark.parametrize("name", ["../../escape", "/absolute/path", "", "..", "a/b\\c:d*e", "x" * 500])
def test_scene_names_become_file_names_that_stay_put(tmp_path, name):
    from skyref.validation import safe_file_name

    safe = safe_file_name(name)
    assert safe and len(safe) <= 100 and "/" not in safe and not safe.startswith(".")
    target = os.path.realpath(os.path.join(tmp_path, safe))
    assert os.path.dirname(target) == os.path.realpath(tmp_path)


@pytest.mark.parametrize("name", ["../../../escape", "/etc/passwd", ".hidden"])
def test_the_ground_truth_cache_stays_in_its_directory(tmp_path, name):
    """The audit's ground-truth cache is named after the scene: a name with '../' or an
    absolute path still lands inside the cache directory."""
    from skyref.audit.groundtruth import cache_path
    from skyref.scene import Scene

    cache = os.path.realpath(tmp_path / "cache")
    path = os.path.realpath(cache_path(cache, Scene(name=name), 0.01, 1024))
    assert os.path.dirname(path) == cache, path


def test_render_to_an_unwritable_place_is_refused(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    refused(capsys, ["audit", "--method", "preetham1999", "--scene", EARTH_CLEAR, "-o", blocker / "report"],
            "--out")
    assert blocker.read_text() == ""


def test_a_name_only_scene_says_what_it_uses(tmp_path, capsys):
    scene = tmp_path / "scene.toml"
    scene.write_text('name = "only-a-name"\n')
    assert main(["validate", str(scene)]) == 0
    out = capsys.readouterr().out
    assert "defaults used: no [atmosphere]: the bruneton2017 preset; no [sun]: sun at zenith 30 deg" in out
    scene.write_text(EARTH_CLEAR.read_text())
    assert main(["validate", str(scene)]) == 0
    assert "defaults used" not in capsys.readouterr().out


def test_batch_refuses_skies_too_large_to_render_before_starting_workers(tmp_path, capsys):
    """16384x16384 at 48 wavelengths used to pass validation and die inside Dr.Jit (2^32
    entries) as "4 workers died"; the grid is refused up front, naming the camera."""
    grid = grid_file(tmp_path, '"sun.zenith_deg" = [30.0, 60.0]',
                     'directory = "out"\nspp = 16\nwidth = 16384\nheight = 16384\npasses = 16')
    line = refused(capsys, ["batch", grid, "-q"], "base.scene")
    assert "camera" in line and "tiles" in line
    nothing_written(tmp_path, "grid.toml")


@pytest.mark.parametrize("estimator", ["delta_tracking", "line_integral"])
def test_the_same_seed_gives_the_same_bytes(mi, tmp_path, estimator):
    """A render large enough to be split between threads (64x32, 25 samples per pass: a pixel's
    samples straddle the threads' blocks, where atomic sums once differed in the last bit from
    run to run) written twice: the same EXR bytes."""
    from skyref.io.exr import write_sky_exr
    from skyref.render import render_sky
    from skyref.scene import Camera, RenderSettings, Scene, Sun

    scene = Scene(sun=Sun(50.0, 135.0), camera=Camera(width=64, height=32), wavelengths="rgb",
                  render=RenderSettings(spp=100, passes=4, seed=3), name="same-bytes")
    for name in ("a.exr", "b.exr"):
        write_sky_exr(render_sky(scene, estimator=estimator), tmp_path / name)
    assert (tmp_path / "a.exr").read_bytes() == (tmp_path / "b.exr").read_bytes()
