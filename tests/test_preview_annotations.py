"""PNG previews: the horizon, compass and sun overlay against closed forms of the fisheye and
equirectangular mappings, the absolute exposure against its formula, and ``skyref render
--annotate --exposure --time --place`` end to end (tiny renders)."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from skyref.cli import main
from skyref.errors import ParameterError
from skyref.io.annotate import COMPASS, draw_overlay, overlay_geometry
from skyref.io.png import exposure_from_ev100, preview_image
from skyref.scene import Camera, Sun, load_scene, save_scene
from skyref.timelapse import sun_from_options
from tests.references.preview import solar_position, srgb8
from tests.variants import RGB

VARIANT = RGB
EARTH_CLEAR = Path(__file__).resolve().parent.parent / "scenes" / "earth-clear.toml"
UP = Camera(type="fisheye", width=128, height=128, fov_deg=180.0)
EQUIRECT = Camera(type="equirectangular", width=128, height=64)
# Looking at the southern horizon: image left is east, image up is the zenith.
SOUTH = Camera(type="fisheye", width=96, height=96, fov_deg=180.0, view_zenith_deg=90.0, view_azimuth_deg=180.0)


def enu(zenith_deg, azimuth_deg):
    t, p = math.radians(zenith_deg), math.radians(azimuth_deg)
    return np.array([math.sin(t) * math.sin(p), math.sin(t) * math.cos(p), math.cos(t)])


# --- independent closed forms of the two projections, in pixels (x right, y down) ----------------

def up_fisheye_xy(camera, zenith_deg, azimuth_deg):
    """Upward equidistant fisheye, north up and east left: radius zenith / (fov / 2)."""
    r = zenith_deg / (camera.fov_deg / 2)
    a = math.radians(azimuth_deg)
    return camera.width / 2 * (1 - r * math.sin(a)), camera.height / 2 * (1 - r * math.cos(a))


def south_fisheye_xy(camera, direction):
    """Equidistant fisheye looking south at the horizon: angle from south over 90 deg is the
    radius; east is image left, the zenith image up."""
    x, y, z = direction
    r = math.degrees(math.acos(-y)) / (camera.fov_deg / 2)
    norm = math.hypot(x, z)
    return camera.width / 2 * (1 - r * x / norm), camera.height / 2 * (1 - r * z / norm)


def equirect_xy(camera, zenith_deg, azimuth_deg):
    return camera.width * (azimuth_deg % 360) / 360, camera.height * zenith_deg / 180


# --- geometry ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("zenith, azimuth", [(0.0, 0.0), (50.0, 135.0), (30.0, 300.0), (89.0, 10.0), (71.4, 75.4)])
def test_sun_marker_where_the_fisheye_maps_the_sun(zenith, azimuth):
    assert overlay_geometry(UP, enu(zenith, azimuth)).sun == pytest.approx(up_fisheye_xy(UP, zenith, azimuth),
                                                                           abs=1e-9)


@pytest.mark.parametrize("zenith, azimuth", [(50.0, 135.0), (80.0, 200.0), (20.0, 260.0), (60.0, 100.0)])
def test_sun_marker_in_a_tilted_fisheye(zenith, azimuth):
    assert overlay_geometry(SOUTH, enu(zenith, azimuth)).sun == pytest.approx(
        south_fisheye_xy(SOUTH, enu(zenith, azimuth)), abs=1e-9)


@pytest.mark.parametrize("zenith, azimuth", [(50.0, 135.0), (95.0, 290.0), (10.0, 0.5)])
def test_sun_marker_in_an_equirectangular_map(zenith, azimuth):
    assert overlay_geometry(EQUIRECT, enu(zenith, azimuth)).sun == pytest.approx(
        equirect_xy(EQUIRECT, zenith, azimuth), abs=1e-9)


def test_sun_out_of_view_has_no_marker():
    assert overlay_geometry(UP, enu(95.0, 90.0)).sun is None          # below an upward 180-degree fisheye
    assert overlay_geometry(SOUTH, enu(60.0, 0.0)).sun is None        # behind a camera facing south


def test_fisheye_compass_and_horizon():
    overlay = overlay_geometry(UP, enu(50.0, 135.0))
    for name, azimuth in COMPASS.items():
        (x, y, _), = overlay.labels[name]
        # invert the closed form: the label's direction has the compass azimuth, a few degrees up
        dx, dy = 1 - 2 * x / UP.width, 1 - 2 * y / UP.height
        assert math.degrees(math.atan2(dx, dy)) % 360 == pytest.approx(azimuth, abs=1e-6)
        assert 2.0 < 90.0 - 90.0 * math.hypot(dx, dy) < 20.0
    # The horizon of an upward 180-degree fisheye is the image circle.
    points = np.concatenate(overlay.horizon)
    assert np.hypot(points[:, 0] - 64, points[:, 1] - 64) == pytest.approx(64.0, abs=1e-9)

    south = overlay_geometry(SOUTH, enu(50.0, 135.0))
    assert set(south.labels) == {"S"}                                # east and west on the rim, north behind
    (x, y, _), = south.labels["S"]
    assert x == pytest.approx(48.0) and 38.0 < y < 48.0             # straight ahead, just above the horizon
    assert np.concatenate(south.horizon)[:, 1] == pytest.approx(48.0, abs=1e-9)   # the middle row


def test_equirectangular_compass_and_horizon():
    overlay = overlay_geometry(EQUIRECT, enu(50.0, 135.0))
    for name, azimuth in (("E", 90), ("S", 180), ("W", 270)):
        (x, y, _), = overlay.labels[name]
        assert x == pytest.approx(equirect_xy(EQUIRECT, 90.0, azimuth)[0]) and 20.0 < y < 31.0
    assert sorted(x for x, _, _ in overlay.labels["N"]) == pytest.approx([1.0, 127.0])  # both edges
    assert overlay.horizon[0][:, 1] == pytest.approx(32.0)


# --- drawing -------------------------------------------------------------------------------------------

def centroid(mask):
    rows, cols = np.nonzero(mask)
    return cols.mean() + 0.5, rows.mean() + 0.5                 # pixel centres, in x, y


def amber(image):
    r, g, b = (image[..., i].astype(int) for i in range(3))
    return (r > 150) & (g > 90) & (b < 60)


@pytest.mark.parametrize("camera, sun, expected", [
    (UP, (50.0, 135.0), up_fisheye_xy(UP, 50.0, 135.0)),
    (UP, (25.0, 250.0), up_fisheye_xy(UP, 25.0, 250.0)),
    (EQUIRECT, (60.0, 200.0), equirect_xy(EQUIRECT, 60.0, 200.0)),
])
def test_drawn_sun_ring_is_centred_on_the_sun(camera, sun, expected):
    image = draw_overlay(np.zeros((camera.height, camera.width, 3), np.uint8), camera, enu(*sun))
    ring = amber(image)
    assert ring.sum() > 10
    assert centroid(ring) == pytest.approx(expected, abs=0.75)
    # and nothing amber elsewhere: no pixel of the ring further than its radius + 2 from the sun
    rows, cols = np.nonzero(ring)
    radius = overlay_geometry(camera, enu(*sun)).sun_radius
    assert np.hypot(cols + 0.5 - expected[0], rows + 0.5 - expected[1]).max() < radius + 2


def test_drawn_letters_sit_at_their_compass_points():
    image = draw_overlay(np.zeros((128, 128, 3), np.uint8), UP, enu(40.0, 135.0))
    rows, cols = np.indices(image.shape[:2]) + 0.5
    inside = np.hypot(rows - 64, cols - 64) < 61                     # leaves out the horizon (the rim)
    white = inside & (image.min(axis=-1) > 100)
    halves = {"N": (slice(0, 40), slice(40, 88)), "S": (slice(88, 128), slice(40, 88)),
              "E": (slice(40, 88), slice(0, 40)), "W": (slice(40, 88), slice(88, 128))}
    for name, (rows, cols) in halves.items():
        part = np.zeros_like(white)
        part[rows, cols] = white[rows, cols]
        (x, y, _), = overlay_geometry(UP, enu(40.0, 135.0)).labels[name]
        assert part.sum() > 5, name
        assert centroid(part) == pytest.approx((x, y), abs=1.5), name


# --- absolute exposure ----------------------------------------------------------------------------

def grey_value(luminance, ev100):
    """The documented mapping: x = L / (1.2 * 2**EV100), Reinhard x / (1 + x), sRGB."""
    x = luminance / (78 / 65 * 2.0 ** ev100)
    return srgb8(x / (1 + x))


def test_absolute_exposure_gives_equal_pixels_for_equal_luminance():
    rng = np.random.default_rng(0)
    dim = rng.uniform(200.0, 2000.0, (8, 8, 3))                     # a dark sky ...
    bright = rng.uniform(5000.0, 40000.0, (8, 8, 3))               # ... and a bright one
    for sky in (dim, bright):
        sky[0, 0] = 3000.0                                           # both hold a D65 grey of 3000 cd/m^2
        sky[0, 1] = 600.0                                            # and one of 600 cd/m^2
    k = exposure_from_ev100(13.0)
    a, b = preview_image(dim, k), preview_image(bright, k)
    assert a[0, 0].tolist() == b[0, 0].tolist() == [grey_value(3000.0, 13.0)] * 3
    assert a[0, 1].tolist() == b[0, 1].tolist() == [grey_value(600.0, 13.0)] * 3
    assert grey_value(600.0, 13.0) < grey_value(3000.0, 13.0)
    # the per-image exposure, by contrast, shows the same luminance differently
    assert preview_image(dim)[0, 0, 0] != preview_image(bright)[0, 0, 0]


def test_ev100_scale():
    assert exposure_from_ev100(0.0) == pytest.approx(65 / 78)
    assert exposure_from_ev100(13.0) / exposure_from_ev100(14.0) == pytest.approx(2.0)
    for bad in (float("nan"), 41.0, -11.0, "13"):
        with pytest.raises(ParameterError, match="ev100"):
            exposure_from_ev100(bad)


# --- the sun from a time and a place -----------------------------------------------------------

@pytest.mark.parametrize("time, place", [("2026-06-21T06:00+02:00", "48.85,2.35"),
                                         ("2026-12-21T13:30-03:00", "-33.9,-70.6"),
                                         ("2027-03-20T12:00+09:00", "35.7,139.7")])
def test_time_and_place_put_the_sun_where_it_stands(time, place):
    from datetime import datetime

    sun = sun_from_options(Sun(zenith_deg=10.0, azimuth_deg=10.0, angular_radius_deg=0.5), time, place)
    zenith, azimuth = solar_position(datetime.fromisoformat(time), *map(float, place.split(",")))
    assert sun.zenith_deg == pytest.approx(zenith, abs=0.03)
    assert sun.azimuth_deg == pytest.approx(azimuth, abs=0.05)
    assert sun.angular_radius_deg == 0.5                            # the scene's disk is kept


# --- the command line ---------------------------------------------------------------------------------

@pytest.fixture
def tiny_scene(tmp_path):
    scene = load_scene(EARTH_CLEAR)
    scene = scene.replace(camera=dataclasses.replace(scene.camera, width=24, height=24), wavelengths="rgb",
                          render=dataclasses.replace(scene.render, passes=2, estimator="delta_tracking"))
    path = tmp_path / "tiny.toml"
    save_scene(scene, path)
    return path


def test_render_time_place_annotate_exposure(mi, tiny_scene, tmp_path, capsys):
    from skyref.io.exr import read_sky_exr

    common = [str(tiny_scene), "--spp", "4", "--variant", VARIANT, "-q"]
    assert main(["render", *common, "-o", str(tmp_path / "a.exr"), "--png", str(tmp_path / "a.png"),
                 "--time", "2026-06-21T09:00+02:00", "--place", "48.85,2.35", "--exposure", "12.5"]) == 0
    sky = read_sky_exr(tmp_path / "a.exr")
    zenith, azimuth = solar_position(sky.scene.sun.time, 48.85, 2.35)
    assert (sky.scene.sun.zenith_deg, sky.scene.sun.azimuth_deg) == pytest.approx((zenith, azimuth), abs=0.05)
    assert "sun at zenith" in capsys.readouterr().out
    # --exposure: every pixel is the documented mapping of its colour (Reinhard on luminance)
    rgb = sky.rgb() * exposure_from_ev100(12.5)
    luminance = rgb @ np.array([0.2126, 0.7152, 0.0722])
    display = np.clip(rgb / (1 + luminance[..., None]), 0, 1)
    expected = np.vectorize(srgb8)(display)
    assert np.abs(np.array(Image.open(tmp_path / "a.png")).astype(int) - expected).max() <= 1

    # --annotate: the same render with the overlay; the sun's ring where the fisheye puts the sun
    assert main(["render", *common, "-o", str(tmp_path / "b.exr"), "--png", str(tmp_path / "b.png"),
                 "--time", "2026-06-21T09:00+02:00", "--place", "48.85,2.35", "--annotate"]) == 0
    annotated = np.array(Image.open(tmp_path / "b.png"))
    camera = Camera(type="fisheye", width=24, height=24, fov_deg=180.0)
    assert centroid(amber(annotated)) == pytest.approx(up_fisheye_xy(camera, zenith, azimuth), abs=1.0)


@pytest.mark.parametrize("options, name", [
    (["--time", "2026-06-21T06:00", "--place", "48.85,2.35"], "--time"),          # no UTC offset
    (["--time", "tomorrow", "--place", "48.85,2.35"], "--time"),
    (["--time", "2026-06-21T06:00+02:00", "--place", "91,2"], "--place"),
    (["--time", "2026-06-21T06:00+02:00", "--place", "48,-181"], "--place"),
    (["--time", "2026-06-21T06:00+02:00", "--place", "48.85"], "--place"),
    (["--time", "2026-06-21T06:00+02:00", "--place", "nan,2"], "--place"),
    (["--time", "2026-06-21T06:00+02:00"], "--place"),                          # the scene has no place
    (["--place", "48.85,2.35"], "--time"),
    (["--exposure", "13"], "--exposure"),                                         # no --png
    (["--annotate"], "--annotate"),
    (["--png", "{tmp}/sky.png", "--exposure", "99"], "--exposure"),
])
def test_render_refuses_bad_options(options, name, tiny_scene, tmp_path, capsys):
    options = [o.replace("{tmp}", str(tmp_path)) for o in options]
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["render", str(tiny_scene), "-o", str(tmp_path / "sky.exr"), "-q", *options]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and name in err[0], err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_annotate_refuses_a_perspective_camera(tiny_scene, tmp_path, capsys):
    scene = load_scene(tiny_scene)
    save_scene(scene.replace(camera=Camera(type="perspective", width=8, height=8, fov_deg=60.0)), tmp_path / "p.toml")
    assert main(["render", str(tmp_path / "p.toml"), "-o", str(tmp_path / "p.exr"), "--png", str(tmp_path / "p.png"),
                 "--annotate", "-q"]) == 2
    assert "--annotate" in capsys.readouterr().err
    assert not (tmp_path / "p.exr").exists() and not (tmp_path / "p.png").exists()
