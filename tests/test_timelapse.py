"""``skyref timelapse``: frame times against a closed-form solar position, three tiny frames and
their GIF, one exposure for every frame, and bad input refused before anything is written."""

import dataclasses
import datetime as dt
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from skyref.cli import main
from skyref.scene import load_scene, save_scene
from skyref.timelapse import frame_times

from tests.references.preview import solar_position, srgb8
from tests.variants import RGB

VARIANT = RGB
EARTH_CLEAR = Path(__file__).resolve().parent.parent / "scenes" / "earth-clear.toml"
PARIS = (48.85, 2.35)
THREE = ["--place", "48.85,2.35", "--from", "2026-06-21T10:00+02:00", "--to", "2026-06-21T11:00+02:00",
         "--step", "30min"]


@pytest.fixture
def scene_path(tmp_path):
    scene = load_scene(EARTH_CLEAR)
    path = tmp_path / "scene.toml"
    # the frames' exposure and timing are the subject, not the estimator: the baseline's kernels
    # compile in seconds (the line integral's for ~2 min at this scene's 48 wavelengths)
    save_scene(scene.replace(render=dataclasses.replace(scene.render, passes=2, estimator="delta_tracking")), path)
    return path


def crossing(date, latitude, longitude, elevation_deg, rising):
    """UTC time at which the closed-form sun crosses ``elevation_deg`` on ``date`` (bisection
    between solar noon and midnight, solar noon taken from the longitude)."""
    noon = dt.datetime.combine(date, dt.time(12), tzinfo=dt.timezone.utc) - dt.timedelta(hours=longitude / 15)
    lo, hi = (noon - dt.timedelta(hours=12), noon) if rising else (noon, noon + dt.timedelta(hours=12))
    above = lambda t: 90.0 - solar_position(t, latitude, longitude)[0] > elevation_deg  # noqa: E731
    for _ in range(40):
        mid = lo + (hi - lo) / 2
        if above(mid) == rising:
            hi = mid
        else:
            lo = mid
    return lo


def test_default_bounds_are_an_hour_around_sunrise_and_sunset():
    times = frame_times("2026-06-21", "sunrise-1h", "sunset+1h", "30min", *PARIS, "Europe/Paris")
    date = dt.date(2026, 6, 21)
    # sunrise and sunset: the upper limb on the horizon under standard refraction, -0.833 deg
    sunrise = crossing(date, *PARIS, -0.8333, rising=True)
    sunset = crossing(date, *PARIS, -0.8333, rising=False)
    assert abs((times[0] - (sunrise - dt.timedelta(hours=1))).total_seconds()) < 60
    assert dt.timedelta(0) <= sunset + dt.timedelta(hours=1) - times[-1] < dt.timedelta(minutes=30)
    assert all(b - a == dt.timedelta(minutes=30) for a, b in zip(times, times[1:]))
    assert {t.utcoffset() for t in times} == {dt.timedelta(hours=2)}               # CEST


def test_zones_and_clock_times():
    # no --tz: the nautical zone of the longitude (-75 deg: UTC-5)
    times = frame_times("2026-01-10", "08:00", "09:00", "1h", 40.7, -75.0)
    assert [t.isoformat() for t in times] == ["2026-01-10T08:00:00-05:00", "2026-01-10T09:00:00-05:00"]
    # an ISO --from gives its offset to the frames
    times = frame_times(None, "2026-06-21T10:00+02:00", "2026-06-21T09:30Z", "15min", *PARIS)
    assert [t.strftime("%H:%M%z") for t in times] == ["10:00+0200", "10:15+0200", "10:30+0200", "10:45+0200",
                                                      "11:00+0200", "11:15+0200", "11:30+0200"]


def read_png(path):
    return np.array(Image.open(path)).astype(int)


def expected_png(rgb, exposure):
    """The documented tone curve: Reinhard on luminance, colours scaled alike, sRGB, 8 bits."""
    rgb = rgb * exposure
    luminance = rgb @ np.array([0.2126, 0.7152, 0.0722])
    return np.vectorize(srgb8)(np.clip(rgb / (1 + luminance[..., None]), 0, 1))


def test_three_frames_one_exposure(mi, scene_path, tmp_path, capsys):
    from skyref.io.exr import read_sky_exr

    out = tmp_path / "day"
    common = [str(scene_path), *THREE, "--size", "32", "--spp", "4", "--exr", "--no-annotate",
              "--variant", VARIANT, "-q"]
    assert main(["timelapse", *common, "-o", str(out)]) == 0
    assert "3 frames" in capsys.readouterr().out
    names = sorted(p.name for p in out.iterdir())
    assert names == [f"frame-00{i}.{e}" for i in range(3) for e in ("exr", "png")] + ["timelapse.gif"]
    with Image.open(out / "timelapse.gif") as gif:
        assert gif.n_frames == 3 and gif.size == (32, 32)

    skies = [read_sky_exr(out / f"frame-00{i}.exr") for i in range(3)]
    for i, sky in enumerate(skies):                        # each frame's sun is where it stood
        assert sky.scene.sun.time == dt.datetime(2026, 6, 21, 8, tzinfo=dt.timezone.utc) + i * dt.timedelta(minutes=30)
        zenith, azimuth = solar_position(sky.scene.sun.time, *PARIS)
        assert (sky.scene.sun.zenith_deg, sky.scene.sun.azimuth_deg) == pytest.approx((zenith, azimuth), abs=0.05)
        assert sky.shape == (32, 32, 3)
    # One exposure for all frames, by default the per-image exposure of the brightest one
    # (0.8 / the 99th percentile of luminance). The top half is free of the time stamp.
    rgbs = [sky.rgb() for sky in skies]
    luminances = [rgb @ np.array([0.2126, 0.7152, 0.0722]) for rgb in rgbs]
    exposure = min(0.8 / np.percentile(y[y > 0], 99) for y in luminances)
    for i, rgb in enumerate(rgbs):
        difference = read_png(out / f"frame-00{i}.png")[:16] - expected_png(rgb, exposure)[:16]
        assert np.abs(difference).max() <= 1, i

    # --exposure EV: that exposure instead, the same for every frame
    assert main(["timelapse", *common, "-o", str(tmp_path / "ev"), "--exposure", "12"]) == 0
    for i in range(3):
        rgb = read_sky_exr(tmp_path / "ev" / f"frame-00{i}.exr").rgb()
        expected = expected_png(rgb, 1 / (78 / 65 * 2.0 ** 12))
        assert np.abs(read_png(tmp_path / "ev" / f"frame-00{i}.png")[:16] - expected[:16]).max() <= 1, i


@pytest.mark.parametrize("options, name", [
    (["--place", "48.85,200", "--date", "2026-06-21"], "--place"),
    (["--place", "48.85,2.35", "--date", "2026-13-01"], "--date"),
    (["--place", "48.85,2.35"], "--date"),                                        # sunrise of which day?
    (["--place", "48.85,2.35", "--date", "2026-06-21", "--step", "0min"], "--step"),
    (["--place", "48.85,2.35", "--date", "2026-06-21", "--step", "5 parsecs"], "--step"),
    (["--place", "48.85,2.35", "--date", "2026-06-21", "--step", "1s"], "--step"),   # 70,000 frames
    (["--place", "48.85,2.35", "--date", "2026-06-21", "--from", "12:00", "--to", "11:00"], "--to"),
    (["--place", "85,0", "--date", "2026-06-21"], "--from"),                       # polar day: no sunrise
    (["--place", "48.85,2.35", "--from", "2026-06-21T10:00", "--to", "2026-06-21T11:00+02:00"], "--from"),
    (["--place", "48.85,2.35", "--date", "2026-06-21", "--tz", "Mars/Olympus_Mons"], "--tz"),
    (THREE + ["--size", "4"], "--size"),
    (THREE + ["--spp", "1"], "--spp"),                                             # fewer than the passes
    (THREE + ["--fps", "0"], "--fps"),
    (THREE + ["--exposure", "nan"], "--exposure"),
    (THREE + ["--wavelengths", "xyz"], "--wavelengths"),
])
def test_bad_input_is_refused_before_anything_is_written(options, name, scene_path, tmp_path, capsys):
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["timelapse", str(scene_path), "-o", str(tmp_path / "out"), "-q", *options]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and name in err[0], err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_output_that_is_a_file_is_refused(scene_path, tmp_path, capsys):
    (tmp_path / "out").write_text("a file")
    assert main(["timelapse", str(scene_path), "-o", str(tmp_path / "out"), "-q", *THREE]) == 2
    assert "-o" in capsys.readouterr().err
    assert (tmp_path / "out").read_text() == "a file"
