"""Camera projections against directions and solid angles worked out by hand."""

import math

import numpy as np
import pytest

from skyref import projection as P
from skyref.scene import Camera

EAST, NORTH, UP = np.eye(3)


def enu(zenith_deg, azimuth_deg):
    t, p = math.radians(zenith_deg), math.radians(azimuth_deg)
    return np.array([math.sin(t) * math.sin(p), math.sin(t) * math.cos(p), math.cos(t)])


def test_equirectangular_known_directions():
    assert np.allclose(P.equirectangular_direction(0.5, 0.0), UP, atol=1e-15)      # top row: zenith
    assert np.allclose(P.equirectangular_direction(0.3, 1.0), -UP, atol=1e-15)     # bottom row: nadir
    assert np.allclose(P.equirectangular_direction(0.0, 0.5), NORTH, atol=1e-15)   # left edge: north
    assert np.allclose(P.equirectangular_direction(0.25, 0.5), EAST, atol=1e-15)   # quarter: east
    assert np.allclose(P.equirectangular_direction(0.5, 0.5), -NORTH, atol=1e-15)  # middle: south
    assert np.allclose(P.equirectangular_direction(0.75, 0.5), -EAST, atol=1e-15)  # west
    # zenith 60 deg, azimuth 135 deg (south-east): u = 135/360, v = 60/180
    assert np.allclose(P.equirectangular_direction(135 / 360, 60 / 180), enu(60, 135), atol=1e-15)


def test_fisheye_known_directions():
    assert np.allclose(P.fisheye_direction(0.5, 0.5, 180)[:3], UP, atol=1e-15)
    assert np.allclose(P.fisheye_direction(0.5, 0.0, 180)[:3], NORTH, atol=1e-15)  # top edge
    assert np.allclose(P.fisheye_direction(0.0, 0.5, 180)[:3], EAST, atol=1e-15)   # left edge
    assert np.allclose(P.fisheye_direction(1.0, 0.5, 180)[:3], -EAST, atol=1e-15)  # right edge
    assert np.allclose(P.fisheye_direction(0.5, 1.0, 180)[:3], -NORTH, atol=1e-15)
    # Half-way from the centre to the left edge: zenith 45 deg towards the east.
    assert np.allclose(P.fisheye_direction(0.25, 0.5, 180)[:3], enu(45, 90), atol=1e-15)
    # A 120-degree fisheye: the top edge sees zenith 60 deg, north.
    assert np.allclose(P.fisheye_direction(0.5, 0.0, 120)[:3], enu(60, 0), atol=1e-15)
    # Corners lie outside the circle.
    assert not P.fisheye_direction(0.0, 0.0, 180)[3]
    assert P.fisheye_direction(0.2, 0.3, 180)[3]


@pytest.mark.parametrize("fov", [90.0, 180.0, 270.0])
def test_fisheye_round_trip(fov):
    rng = np.random.default_rng(1)
    u, v = rng.random((2, 1000))
    inside = (2 * u - 1) ** 2 + (2 * v - 1) ** 2 < 0.999
    x, y, z, valid = P.fisheye_direction(u, v, fov)
    assert np.array_equal(valid[inside], np.ones(inside.sum(), bool))
    d = np.stack([x, y, z], axis=-1)
    assert np.allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-14)
    u2, v2 = P.fisheye_pixel(d[inside], fov)
    assert np.allclose(u2, u[inside], atol=1e-9) and np.allclose(v2, v[inside], atol=1e-9)


def test_equirectangular_round_trip():
    rng = np.random.default_rng(2)
    u, v = rng.random((2, 1000)) * 0.998 + 0.001
    d = np.stack(P.equirectangular_direction(u, v), axis=-1)
    assert np.allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-14)
    u2, v2 = P.equirectangular_pixel(d)
    assert np.allclose(u2, u, atol=1e-12) and np.allclose(v2, v, atol=1e-12)


def test_pixel_directions_equirectangular_grid():
    camera = Camera("equirectangular", width=8, height=4)
    d = P.pixel_directions(camera)
    assert d.shape == (4, 8, 3)
    # Row 1 centre: zenith 180 * 1.5 / 4 = 67.5 deg; column 2 centre: azimuth 360 * 2.5 / 8.
    assert np.allclose(d[1, 2], enu(67.5, 112.5), atol=1e-15)
    u, v = P.equirectangular_pixel(d)
    assert np.allclose(u * 8 - 0.5, np.arange(8)[None, :]) and np.allclose(v * 4 - 0.5, np.arange(4)[:, None])


def test_pixel_directions_fisheye_nan_outside_and_round_trip():
    camera = Camera("fisheye", width=32, height=32, fov_deg=180.0)
    d = P.pixel_directions(camera)
    j, i = np.meshgrid(np.arange(32), np.arange(32))
    r = np.hypot((j + 0.5) / 16 - 1, (i + 0.5) / 16 - 1)
    assert np.all(np.isnan(d[r > 1])) and not np.any(np.isnan(d[r <= 1]))
    assert np.allclose(np.linalg.norm(d[r <= 1], axis=-1), 1.0)
    assert np.all(d[r <= 1][:, 2] >= 0)                      # 180 deg looking up: upper hemisphere
    u, v = P.fisheye_pixel(d[r <= 1], 180.0)
    assert np.allclose(u * 32 - 0.5, j[r <= 1]) and np.allclose(v * 32 - 0.5, i[r <= 1])


def test_camera_to_world_looks_along_view_direction():
    assert np.array_equal(P.camera_to_world(Camera("fisheye")), np.eye(4))
    assert np.array_equal(P.camera_to_world(Camera("equirectangular", view_zenith_deg=50.0)), np.eye(4))
    m = P.camera_to_world(Camera("perspective", width=4, height=4, fov_deg=60.0, view_zenith_deg=90.0))
    # Looking at the north horizon: up is the zenith and east is to the right, west to the left.
    assert np.allclose(m[:3, 2], NORTH) and np.allclose(m[:3, 1], UP) and np.allclose(m[:3, 0], -EAST)
    m = P.camera_to_world(Camera("fisheye", view_zenith_deg=30.0, view_azimuth_deg=200.0))
    assert np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3)) and np.isclose(np.linalg.det(m[:3, :3]), 1.0)
    assert np.allclose(m[:3, 2], enu(30, 200))
    # Looking straight down: image up is north, so east is on the image right (a map).
    m = P.camera_to_world(Camera("fisheye", view_zenith_deg=180.0))
    assert np.allclose(m[:3, 2], -UP) and np.allclose(m[:3, 1], NORTH) and np.allclose(m[:3, 0], -EAST)


def test_tilted_fisheye_centre_is_view_direction():
    camera = Camera("fisheye", width=33, height=33, fov_deg=100.0, view_zenith_deg=70.0, view_azimuth_deg=250.0)
    d = P.pixel_directions(camera)
    assert np.allclose(d[16, 16], enu(70, 250), atol=1e-12)
    # Every valid pixel lies within fov/2 of the view direction.
    cos_angle = d[~np.isnan(d[..., 0])] @ enu(70, 250)
    assert np.all(cos_angle >= math.cos(math.radians(50.0)) - 1e-12)


def test_perspective_directions():
    camera = Camera("perspective", width=4, height=2, fov_deg=90.0, view_zenith_deg=90.0, view_azimuth_deg=90.0)
    d = P.pixel_directions(camera)
    # Looking east at the horizon; pixel (0, 0) centre on the image plane at unit distance:
    # right = -0.75 (leftwards), up = +0.25 (half-height tan(45) * 2/4 = 0.5, centre at half of it).
    # Image left is north, image up the zenith.
    expected = np.array([1.0, 0.75, 0.25]) / math.sqrt(1 + 0.75 ** 2 + 0.25 ** 2)
    assert np.allclose(d[0, 0], expected)


def test_solid_angle_equirectangular_exact():
    camera = Camera("equirectangular", width=16, height=8)
    omega = P.solid_angle(camera)
    assert omega.shape == (8, 16)
    assert math.isclose(omega.sum(), 4 * math.pi, rel_tol=1e-12)
    # Top row: a polar cap of 22.5 deg split into 16 columns.
    assert math.isclose(omega[0, 0], 2 * math.pi * (1 - math.cos(math.pi / 8)) / 16, rel_tol=1e-12)


@pytest.mark.parametrize("fov, total", [(180.0, 2 * math.pi), (360.0, 4 * math.pi),
                                        (90.0, 2 * math.pi * (1 - math.cos(math.pi / 4)))])
def test_solid_angle_fisheye(fov, total):
    omega = P.solid_angle(Camera("fisheye", width=48, height=48, fov_deg=fov))
    assert omega.shape == (48, 48)
    assert abs(omega.sum() / total - 1) < 0.01
    assert omega[0, 0] == 0.0                                 # a corner pixel is all outside


def test_solid_angle_perspective():
    # A 90-deg square view is one face of a cube: 4 pi / 6.
    omega = P.solid_angle(Camera("perspective", width=20, height=20, fov_deg=90.0))
    assert math.isclose(omega.sum(), 4 * math.pi / 6, rel_tol=1e-12)
    # The centre pixels are closest to the flat-field value (pixel side 2/20 at unit distance).
    assert math.isclose(omega[10, 10], 0.1 ** 2, rel_tol=0.02) and omega[0, 0] < omega[10, 10]
