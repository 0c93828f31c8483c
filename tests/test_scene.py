"""Scenes: the shipped TOML files, save/load round trips, overrides, the sun from date and
place, and atomic writes."""

import datetime as dt
import math
import os
import tomllib
from pathlib import Path

import numpy as np
import pytest

import skyref.atmosphere as sa
from skyref.io.atomic import atomic_path, atomic_write
from skyref.scene import Camera, Observer, RenderSettings, Scene, Sun, load_scene, save_scene

SCENES = sorted((Path(__file__).resolve().parent.parent / "scenes").glob("*.toml"))
SCENE_IDS = [p.stem for p in SCENES]


def test_scenes_exist():
    assert {"earth-clear", "earth-hazy", "sunset", "from-space", "high-altitude"} <= set(SCENE_IDS)


@pytest.mark.parametrize("path", SCENES, ids=SCENE_IDS)
def test_scene_loads(path):
    scene = load_scene(path)
    raw = tomllib.loads(path.read_text())
    assert scene.name == raw.get("name", path.stem)
    assert scene.sun.zenith_deg == raw["sun"]["zenith_deg"]
    assert scene.observer.altitude_m == raw.get("observer", {}).get("altitude_m", 0.0)
    assert scene.camera.type == raw["camera"]["type"]
    wl = scene.wavelengths_nm
    spec = raw["spectral"]["wavelengths"]
    if spec == "rgb":
        np.testing.assert_array_equal(wl, [680.0, 550.0, 440.0])
    else:
        n = round((spec["stop_nm"] - spec["start_nm"]) / spec["step_nm"]) + 1
        np.testing.assert_allclose(wl, spec["start_nm"] + spec["step_nm"] * np.arange(n))


@pytest.mark.parametrize("path", SCENES, ids=SCENE_IDS)
def test_save_load_round_trip(path, tmp_path):
    scene = load_scene(path)
    out = tmp_path / "again.toml"
    save_scene(scene, out)
    again = load_scene(out)
    assert again == scene
    # A saved scene is fully resolved: no preset, every constituent written out.
    saved = tomllib.loads(out.read_text())
    assert "preset" not in saved["atmosphere"]
    assert set(saved["atmosphere"]["constituents"]) == {c.name for c in scene.atmosphere.constituents}
    # ... and a second save is byte-identical (stable serialisation).
    save_scene(again, tmp_path / "third.toml")
    assert (tmp_path / "third.toml").read_bytes() == out.read_bytes()


def test_earth_hazy_is_turbidity_6():
    scene = load_scene(next(p for p in SCENES if p.stem == "earth-hazy"))
    atm = scene.atmosphere
    tau_m = 1.24062e-6 * 0.55 ** -4 * 8000.0 * (1.0 - math.exp(-60_000.0 / 8000.0))
    tau_a = atm["aerosol"].extinction_coefficient([550.0])[0] * 1200.0  # exponential column
    assert tau_a == pytest.approx(5.0 * tau_m, rel=1e-6)
    assert tau_a == pytest.approx(0.54, abs=0.01)  # the number quoted in the scene file


def test_default_scene_round_trip(tmp_path):
    scene = Scene(name="defaults")
    save_scene(scene, tmp_path / "d.toml")
    assert load_scene(tmp_path / "d.toml") == scene


def test_custom_scene_round_trip(tmp_path):
    atm = sa.Atmosphere(
        constituents=(sa.Rayleigh(profile=sa.TabulatedProfile((0.0, 5e3, 3e4), (1.0, 0.5, 0.0), source="t")),
                      sa.Aerosol(extinction=sa.TabulatedSpectrum((300.0, 900.0), (3e-5, 1e-5)),
                                 angstrom_alpha=None, angstrom_beta=None, phase=sa.HenyeyGreenstein(0.75))),
        ground_albedo=sa.TabulatedSpectrum((300.0, 900.0), (0.1, 0.3)), name="custom")
    scene = Scene(atmosphere=atm, sun=Sun(zenith_deg=85.0, azimuth_deg=300.0, limb_darkening=True),
                  observer=Observer(1500.0), camera=Camera(type="fisheye", width=64, height=64, fov_deg=190.0),
                  wavelengths=[400.0, 450.5, 700.0], render=RenderSettings(spp=16, seed=7, passes=2),
                  name="custom")
    save_scene(scene, tmp_path / "c.toml")
    assert load_scene(tmp_path / "c.toml") == scene


# --- overrides ----------------------------------------------------------------------------------

def _scene(tmp_path, atmosphere_toml):
    path = tmp_path / "s.toml"
    path.write_text('[atmosphere]\npreset = "bruneton2017"\n' + atmosphere_toml
                    + '\n[spectral]\nwavelengths = "rgb"\n')
    return load_scene(path)


def test_override_aerosol_beta(tmp_path):
    atm = _scene(tmp_path, "[atmosphere.constituents.aerosol]\nangstrom_beta = 0.1\n").atmosphere
    base = sa.bruneton2017()
    aer = atm["aerosol"]
    assert aer.angstrom_beta == 0.1
    # Everything else about the aerosol and the atmosphere is the preset's.
    assert aer.angstrom_alpha == 0.0 and aer.single_scattering_albedo == 0.9
    assert aer.phase == sa.CornetteShanks(0.8)
    assert atm["rayleigh"] == base["rayleigh"] and atm["ozone"] == base["ozone"]
    assert atm.top_radius_m == base.top_radius_m
    np.testing.assert_allclose(aer.extinction_coefficient([550.0]), 0.1 / 1200.0, rtol=1e-12)


def test_override_removes_ozone(tmp_path):
    atm = _scene(tmp_path, "[atmosphere.constituents]\nozone = false\n").atmosphere
    assert [c.name for c in atm.constituents] == ["rayleigh", "aerosol"]
    assert "ozone" not in atm
    # Without ozone the vertical optical depth is Rayleigh + aerosol only.
    tau_r = 1.24062e-6 * 0.55 ** -4 * 8000.0 * (1.0 - math.exp(-7.5))
    tau_a = 5.328e-3 * (1.0 - math.exp(-60_000.0 / 1200.0))
    assert atm.vertical_optical_depth([550.0])[0] == pytest.approx(tau_r + tau_a, rel=1e-10)


def test_override_turbidity(tmp_path):
    atm = _scene(tmp_path, "turbidity = 3.0\n[atmosphere.constituents.aerosol]\n"
                 "single_scattering_albedo = 0.7\n").atmosphere
    assert sa.turbidity(atm) == pytest.approx(3.0, rel=1e-10)
    assert atm["aerosol"].single_scattering_albedo == 0.7
    assert atm["aerosol"].angstrom_alpha == 1.3
    assert "ozone" in atm


def test_override_geometry_and_albedo(tmp_path):
    atm = _scene(tmp_path, "top_radius_m = 6460000.0\nground_albedo = 0.3\n").atmosphere
    assert atm.top_radius_m == 6_460_000.0
    assert float(atm.ground_albedo(550.0)) == 0.3
    assert atm.constituents == sa.bruneton2017().constituents


def test_scene_without_atmosphere_uses_bruneton2017():
    assert Scene.from_dict({}).atmosphere == sa.bruneton2017()


# --- the sun ------------------------------------------------------------------------------------

def almanac_sun(time_utc, lat_deg, lon_deg):
    """The Astronomical Almanac's low-precision solar position (good to ~0.01 deg in 1950-2050):
    geometric zenith and azimuth (clockwise from north), degrees."""
    j2000 = dt.datetime(2000, 1, 1, 12, tzinfo=dt.timezone.utc)
    n = (time_utc - j2000).total_seconds() / 86400.0  # days since J2000.0
    mean_longitude = math.radians((280.460 + 0.9856474 * n) % 360.0)
    mean_anomaly = math.radians((357.528 + 0.9856003 * n) % 360.0)
    ecliptic_longitude = (mean_longitude + math.radians(1.915) * math.sin(mean_anomaly)
                          + math.radians(0.020) * math.sin(2 * mean_anomaly))
    obliquity = math.radians(23.439 - 4.0e-7 * n)
    right_ascension = math.atan2(math.cos(obliquity) * math.sin(ecliptic_longitude), math.cos(ecliptic_longitude))
    decl = math.asin(math.sin(obliquity) * math.sin(ecliptic_longitude))
    gmst_hours = 18.697374558 + 24.06570982441908 * n
    ha = math.radians((gmst_hours * 15.0 + lon_deg) % 360.0) - right_ascension
    lat = math.radians(lat_deg)
    cos_zen = math.sin(lat) * math.sin(decl) + math.cos(lat) * math.cos(decl) * math.cos(ha)
    zenith = math.degrees(math.acos(cos_zen))
    azimuth = math.degrees(math.atan2(-math.sin(ha) * math.cos(decl),
                                      math.sin(decl) * math.cos(lat) - math.cos(decl) * math.sin(lat) * math.cos(ha)))
    return zenith, azimuth % 360.0


PLACES = [
    ("2024-06-21T10:00:00+00:00", 48.8566, 2.3522),      # Paris, summer solstice morning
    ("2023-12-01T02:30:00+00:00", -33.8688, 151.2093),   # Sydney, early afternoon
    ("2024-03-20T18:00:00+00:00", 40.015, -105.2705),    # Boulder, late morning
    ("2025-09-10T15:45:00+00:00", 64.1466, -21.9426),    # Reykjavik, afternoon
    ("2024-12-21T08:30:00+00:00", 48.8566, 2.3522),      # Paris, just after sunrise (refraction 0.15 deg)
]


@pytest.mark.parametrize("time,lat,lon", PLACES)
def test_sun_at_matches_almanac(time, lat, lon):
    sun = Sun.at(time, lat, lon)
    zenith, azimuth = almanac_sun(dt.datetime.fromisoformat(time).astimezone(dt.timezone.utc), lat, lon)
    # Geometric zenith: skyref does not model refraction, which would add up to 0.15 deg here.
    assert sun.zenith_deg == pytest.approx(zenith, abs=0.01)
    # Azimuth: compare directions (the azimuth itself is ill-conditioned near the zenith).
    t, p = math.radians(zenith), math.radians(azimuth)
    expected = np.array([math.sin(t) * math.sin(p), math.sin(t) * math.cos(p), math.cos(t)])
    angle = math.degrees(math.acos(min(1.0, float(np.dot(sun.direction, expected)))))
    assert angle < 0.02


def test_equinox_noon_at_equator_is_overhead():
    # 2024 March equinox: 20 March 03:06 UTC; the equation of time is about -7.5 min, so the sun
    # crosses the meridian at longitude 0 at about 12:07:30 UTC, within 0.5 deg of the zenith.
    sun = Sun.at("2024-03-20T12:07:30+00:00", 0.0, 0.0)
    assert sun.zenith_deg < 0.5


def test_sun_time_zones_and_naive_utc():
    a = Sun.at("2024-06-21T12:00:00+02:00", 48.8566, 2.3522)
    b = Sun.at(dt.datetime(2024, 6, 21, 10, 0, 0), 48.8566, 2.3522)  # naive: UTC
    assert a.zenith_deg == pytest.approx(b.zenith_deg, abs=1e-9)
    assert a.azimuth_deg == pytest.approx(b.azimuth_deg, abs=1e-9)
    assert b.time.tzinfo is not None


def test_sun_by_time_round_trips(tmp_path):
    sun = Sun.at("2024-06-21T10:00:00+00:00", 48.8566, 2.3522, limb_darkening=True)
    assert Sun.from_dict(sun.to_dict()) == sun
    scene = Scene(sun=sun, name="paris")
    path = tmp_path / "paris.toml"
    save_scene(scene, path)
    saved = tomllib.loads(path.read_text())["sun"]
    assert "zenith_deg" not in saved and isinstance(saved["time"], dt.datetime)
    assert saved["latitude_deg"] == 48.8566
    again = load_scene(path)
    assert again == scene
    assert again.sun.zenith_deg == pytest.approx(sun.zenith_deg, abs=1e-9)


def test_sun_direction_convention():
    np.testing.assert_allclose(Sun(zenith_deg=0.0).direction, [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(Sun(zenith_deg=90.0, azimuth_deg=90.0).direction, [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(Sun(zenith_deg=90.0, azimuth_deg=180.0).direction, [0, -1, 0], atol=1e-15)
    np.testing.assert_allclose(Sun(zenith_deg=60.0, azimuth_deg=0.0).direction,
                               [0, math.sqrt(3) / 2, 0.5], atol=1e-15)


# --- atomic writes --------------------------------------------------------------------------

def test_atomic_write_keeps_old_file_on_error(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text("old contents\n")

    class Boom(Exception):
        pass

    with pytest.raises(Boom):
        with atomic_write(path, "w") as f:
            f.write("half of the new")
            f.flush()
            raise Boom()
    assert path.read_text() == "old contents\n"
    assert sorted(os.listdir(tmp_path)) == ["scene.toml"]


def test_atomic_write_replaces_on_success(tmp_path):
    path = tmp_path / "sub" / "dir" / "data.bin"
    with atomic_write(path, "wb") as f:
        f.write(b"\x00\x01new")
        # Not visible under the final name until the block ends.
        assert not path.exists()
    assert path.read_bytes() == b"\x00\x01new"
    assert os.listdir(path.parent) == ["data.bin"]
    # The permissions of a file made by open(), not mkstemp's owner-only 0600.
    mask = os.umask(0o022)
    try:
        with atomic_write(path, "wb") as f:
            f.write(b"again")
    finally:
        os.umask(mask)
    assert path.stat().st_mode & 0o777 == 0o644


def test_atomic_path_keeps_extension_and_cleans_up(tmp_path):
    path = tmp_path / "image.exr"
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(path) as tmp:
            assert tmp.endswith(".exr") and os.path.dirname(tmp) == str(tmp_path)
            Path(tmp).write_bytes(b"partial")
            raise KeyboardInterrupt
    assert os.listdir(tmp_path) == []


def test_save_scene_failure_keeps_previous_file(tmp_path, monkeypatch):
    import tomli_w

    path = tmp_path / "scene.toml"
    scene = Scene(name="first")
    save_scene(scene, path)
    before = path.read_bytes()

    def broken_dump(obj, f, **kwargs):
        f.write(b"name = ")
        raise OSError("disk full")

    monkeypatch.setattr(tomli_w, "dump", broken_dump)
    with pytest.raises(OSError, match="disk full"):
        save_scene(scene.replace(name="second"), path)
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["scene.toml"]


def test_the_estimator_setting_is_checked_and_round_trips():
    from skyref.errors import ParameterError
    from skyref.scene import DEFAULT_ESTIMATOR, ESTIMATORS

    # always written: a scene written without it was rendered by delta tracking, the default then
    assert RenderSettings().to_dict()["estimator"] == DEFAULT_ESTIMATOR == "line_integral"
    for estimator in ESTIMATORS:
        settings = RenderSettings(estimator=estimator)
        assert RenderSettings.from_dict(settings.to_dict()).estimator == estimator
    with pytest.raises(ParameterError, match=r"render.estimator = 'ratio'.*delta_tracking"):
        RenderSettings(estimator="ratio")
