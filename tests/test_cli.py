"""The command line: exit statuses, one-line errors, no tracebacks."""

import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from skyref import _llvm
from skyref.cli import main

ROOT = Path(__file__).resolve().parent.parent
EARTH_CLEAR = ROOT / "scenes" / "earth-clear.toml"


def run_cli(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "skyref.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, cwd=ROOT)


def write(tmp_path, text, name="scene.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_validate_in_process(capsys):
    assert main(["validate", str(EARTH_CLEAR)]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    assert f"{EARTH_CLEAR}: valid" in out
    assert "earth-clear" in out and "48: 360–830 nm" in out
    assert "seed 0, line integral estimator" in out              # the default estimator, named
    # The optical depth it prints is Bruneton 2017's, computed here in closed form.
    sigma_o3 = {440.0: 1.582e-26, 550.0: 3.5e-25, 680.0: 1.209e-25}  # the CSV rows of these wavelengths
    pairs = [(float(w), float(t)) for t, w in re.findall(r"([\d.]+) @ (\d+) nm", out)]
    assert sorted(w for w, _ in pairs) == [440.0, 550.0, 680.0]
    for wl, printed in pairs:
        tau = (1.24062e-6 * (wl / 1000.0) ** -4 * 8000.0 * (1 - math.exp(-7.5))
               + 5.328e-3 * (1 - math.exp(-50.0)) + 300 * 2.6867e20 * sigma_o3[wl])
        assert printed == pytest.approx(tau, abs=6e-5)


def test_validate_quiet(capsys):
    assert main(["validate", "-q", str(EARTH_CLEAR), str(ROOT / "scenes" / "sunset.toml")]) == 0
    out, _ = capsys.readouterr()
    assert out.splitlines() == [f"{EARTH_CLEAR}: valid", f"{ROOT / 'scenes' / 'sunset.toml'}: valid"]


def test_validate_subprocess():
    result = run_cli("validate", EARTH_CLEAR)
    assert result.returncode == 0, result.stderr
    assert "valid" in result.stdout and result.stderr == ""


def test_validate_every_shipped_scene():
    scenes = sorted((ROOT / "scenes").glob("*.toml"))
    assert main(["validate", "-q", *map(str, scenes)]) == 0


BAD_SCENES = {
    "sun.zenith_deg": '[sun]\nzenith_deg = 200.0\n',
    "render.spp": '[render]\nspp = 0\n',
    "camera.type": '[camera]\ntype = "orthographic"\n',
    "atmosphere.preset": '[atmosphere]\npreset = "earth"\n',
    "aerosol.angstrom_beta": '[atmosphere]\npreset = "bruneton2017"\n'
                             '[atmosphere.constituents.aerosol]\nangstrom_beta = -0.5\n',
    "phase.gg": '[atmosphere]\npreset = "bruneton2017"\n'
                '[atmosphere.constituents.aerosol.phase]\ntype = "cornette_shanks"\ngg = 0.5\n',
    "wavelengths_nm": '[spectral]\nwavelengths = [300.0]\n',
    "lighting": '[lighting]\nsun = 1\n',
    "scene": '[sun\nzenith_deg = 1\n',
}


@pytest.mark.parametrize("name", sorted(BAD_SCENES))
def test_bad_scene_in_process(name, tmp_path, capsys):
    path = write(tmp_path, BAD_SCENES[name])
    assert main(["validate", str(path)]) == 2
    out, err = capsys.readouterr()
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("skyref validate: error: ")
    assert name in lines[0]
    assert "Traceback" not in err and "valid" not in out


def test_bad_scene_subprocess(tmp_path):
    path = write(tmp_path, '[sun]\nzenith_deg = 200.0\n')
    result = run_cli("validate", path)
    assert result.returncode == 2
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert "sun.zenith_deg" in lines[0] and "200" in lines[0]
    assert "Traceback" not in result.stderr


def test_missing_scene_file(tmp_path, capsys):
    assert main(["validate", str(tmp_path / "nope.toml")]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "nope.toml" in err and "not found" in err


def test_valid_scene_whose_spectra_miss_the_probe_wavelengths(tmp_path, capsys):
    # A tabulated aerosol that covers only the scene's wavelengths: valid, and the summary must not
    # fail on the 440/550/680 nm optical-depth line.
    path = write(tmp_path, '[atmosphere]\npreset = "rayleigh_only"\n[atmosphere.constituents.dust]\n'
                           'kind = "aerosol"\n'
                           'extinction = { type = "tabulated", wavelengths_nm = [500.0, 700.0], values = [1e-5, 1e-5] }\n'
                           '[spectral]\nwavelengths = [550.0, 600.0]\n')
    assert main(["validate", str(path)]) == 0
    out, err = capsys.readouterr()
    assert err == "" and "valid" in out and "dust" in out


def test_info():
    result = run_cli("info")
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    line = next(l for l in result.stdout.splitlines() if l.startswith("libLLVM"))
    value = line.split(None, 1)[1]
    if value.startswith("none"):
        assert "libllvm19" in value
    else:
        version = _llvm.major_version(value)
        assert version is not None and version >= 17 and version not in (15, 16)
        assert Path(value).exists()
        assert "mitsuba      3." in result.stdout
    assert "bruneton2017" in result.stdout


def test_no_command_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as info:
        main([])
    assert info.value.code == 2


# --- render: bad input is refused before any work ------------------------------------------------

@pytest.mark.parametrize("args, name", [
    (["-o", "sky.png"], "--output"),                       # wrong extension
    (["-o", "/proc/no/such/dir/sky.exr"], "--output"),     # cannot be created
    (["-o", "{tmp}/sky.exr", "--png", "{tmp}/sky.jpg"], "--png"),
    (["-o", "{tmp}/sky.exr", "--spp", "0"], "render.spp"),
    (["-o", "{tmp}/sky.exr", "--variant", "no_such_variant"], "variant"),
])
def test_render_refuses_bad_input(args, name, tmp_path, capsys):
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    assert main(["render", str(EARTH_CLEAR), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"skyref render: error: {name} = ")
    assert not list(tmp_path.glob("*.exr")) and not list(tmp_path.glob("*.tmp*"))


def test_render_writes_exr_and_png(tmp_path, capsys):
    from skyref.io.exr import read_sky_exr

    scene = write(tmp_path, '[camera]\nwidth = 16\nheight = 8\n[render]\nspp = 4\npasses = 2\n')
    assert main(["render", str(scene), "-o", str(tmp_path / "sky.exr"), "--png", str(tmp_path / "sky.png"), "-q"]) == 0
    sky = read_sky_exr(tmp_path / "sky.exr")
    assert sky.radiance.shape == (8, 16, 3) and np.all(np.isfinite(sky.radiance))
    assert (tmp_path / "sky.png").stat().st_size > 0
    assert "median relative standard error" in capsys.readouterr().out
    assert sky.metadata["estimator"] == "line_integral"          # the default


def test_render_takes_the_estimator_from_the_scene_or_the_command_line(tmp_path, capsys):
    """``[render] estimator`` picks the path tracer's estimator, ``--estimator`` overrides it, and
    the EXR's metadata says which one rendered (pixel centres, where the line integral pays)."""
    from skyref.io.exr import read_sky_exr

    scene = write(tmp_path, '[camera]\nwidth = 8\nheight = 4\n[render]\nspp = 8\npasses = 2\n'
                            'pixel_sampling = "centre"\nestimator = "delta_tracking"\n')
    for extra, expected in (([], "delta_tracking"), (["--estimator", "line_integral"], "line_integral")):
        exr = tmp_path / f"{expected}.exr"
        assert main(["render", str(scene), "-o", str(exr), "-q", *extra]) == 0
        sky = read_sky_exr(exr)
        assert sky.metadata["estimator"] == expected and np.all(np.isfinite(sky.radiance))
        assert sky.scene.render.estimator == expected


def test_render_refuses_an_unknown_estimator_before_any_work(tmp_path, capsys):
    scene = write(tmp_path, '[render]\nestimator = "path_guiding"\n')
    assert main(["render", str(scene), "-o", str(tmp_path / "sky.exr")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("skyref render: error: render.estimator = 'path_guiding'")
    with pytest.raises(SystemExit) as info:
        main(["render", str(EARTH_CLEAR), "-o", str(tmp_path / "sky.exr"), "--estimator", "path_guiding"])
    assert info.value.code == 2
    assert not list(tmp_path.glob("*.exr"))
