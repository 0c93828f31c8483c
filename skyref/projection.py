"""Camera projections: film coordinates <-> view directions (plain math, no Mitsuba).

Frame: east-north-up (x east, y north, z up); azimuth clockwise from north towards east, so
zenith theta and azimuth phi give (sin theta sin phi, sin theta cos phi, cos theta).

Film coordinates ``u, v`` run over [0, 1]: ``u`` from the left edge to the right, ``v`` from the
top edge to the bottom; pixel (row i, column j) of an H x W image has its centre at
u = (j + 0.5) / W, v = (i + 0.5) / H.

The per-coordinate functions (``*_direction``) take an array namespace ``xp`` and use only its
``sin, cos, sqrt, atan2, acos, where, minimum, maximum`` plus arithmetic, so the same code runs
on NumPy arrays and, through a small namespace of Dr.Jit functions, inside Mitsuba sensors.

The camera's local frame is Mitsuba's: +z looks along the view direction, +y is image up and +x
is image *left*. For a fisheye looking up (view zenith 0) it coincides with east-north-up: image
up is north and image left is east, the sky-chart convention of a sky seen from below.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["equirectangular_direction", "equirectangular_pixel", "fisheye_direction", "fisheye_pixel",
           "perspective_direction", "camera_to_world", "pixel_directions", "solid_angle"]

#: Sub-samples per pixel side for the fisheye's numerical solid angle.
_FISHEYE_SUBSAMPLES = 8


def equirectangular_direction(u, v, xp=np):
    """Unit direction (x, y, z), east-north-up, of film point (u, v) of an equirectangular map:
    azimuth 2 pi u (clockwise from north), zenith angle pi v."""
    phi = (2.0 * math.pi) * u
    theta = math.pi * v
    sin_theta = xp.sin(theta)
    return sin_theta * xp.sin(phi), sin_theta * xp.cos(phi), xp.cos(theta)


def equirectangular_pixel(direction):
    """Film coordinates (u, v) in [0, 1] of east-north-up direction(s) ``(..., 3)`` (need not be
    unit length); inverse of :func:`equirectangular_direction`."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    phi = np.mod(np.arctan2(d[..., 0], d[..., 1]), 2.0 * np.pi)
    theta = np.arccos(np.clip(d[..., 2], -1.0, 1.0))
    return phi / (2.0 * np.pi), theta / np.pi


def fisheye_direction(u, v, fov_deg, xp=np):
    """Equidistant fisheye, in the camera's local frame (looking along +z, image up +y, image
    left +x): film point (u, v) at radius r from the image centre (r = 1 at the middle of each
    edge) sees zenith angle r * fov/2 from +z.

    Returns (x, y, z, valid); ``valid`` is False outside the image circle (r > 1), where the
    direction continues the same mapping but belongs to no pixel of the image.
    """
    a = 2.0 * u - 1.0                      # image right
    b = 1.0 - 2.0 * v                      # image up
    r = xp.sqrt(a * a + b * b)
    theta = r * (0.5 * math.radians(fov_deg))
    scale = xp.sin(theta) / xp.maximum(r, 1e-30)   # sin(theta) / r; a = b = 0 at r = 0
    return -a * scale, b * scale, xp.cos(theta), r <= 1.0


def fisheye_pixel(direction, fov_deg):
    """Film coordinates (u, v) of local-frame direction(s) ``(..., 3)`` seen by an equidistant
    fisheye of ``fov_deg``; inverse of :func:`fisheye_direction` (u, v fall outside the image
    circle for directions beyond fov/2)."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    r = np.arccos(np.clip(d[..., 2], -1.0, 1.0)) / (0.5 * np.radians(fov_deg))
    psi = np.arctan2(d[..., 1], -d[..., 0])          # angle in the image, from image right
    return 0.5 * (1.0 + r * np.cos(psi)), 0.5 * (1.0 - r * np.sin(psi))


def perspective_direction(u, v, fov_deg, aspect, xp=np):
    """Pinhole camera in the local frame (looking along +z, image up +y, image left +x) with
    horizontal field of view ``fov_deg`` and ``aspect`` = width / height; returns unit (x, y, z)."""
    tan_half = math.tan(0.5 * math.radians(fov_deg))
    x = (1.0 - 2.0 * u) * tan_half
    y = (1.0 - 2.0 * v) * (tan_half / aspect)
    norm = xp.sqrt(x * x + y * y + 1.0)
    return x / norm, y / norm, 1.0 / norm


def camera_to_world(camera) -> np.ndarray:
    """4x4 rotation (float64) from the camera's local frame to east-north-up, as used by
    :func:`pixel_directions` (and fit for a Mitsuba sensor's ``to_world``).

    Columns are image left, image up and the view direction (Mitsuba's ``look_at`` layout). The
    view direction is ``view_zenith_deg``/``view_azimuth_deg``; image up points towards the
    zenith, or towards north when looking straight up or down, so the default fisheye (0, 0) is
    the identity. Equirectangular maps always use the identity: their view angles are ignored.
    """
    matrix = np.eye(4)
    if camera.type == "equirectangular":
        return matrix
    theta = math.radians(camera.view_zenith_deg)
    phi = math.radians(camera.view_azimuth_deg)
    forward = np.array([math.sin(theta) * math.sin(phi), math.sin(theta) * math.cos(phi), math.cos(theta)])
    hint = np.array([0.0, 1.0, 0.0]) if abs(forward[2]) > 1.0 - 1e-12 else np.array([0.0, 0.0, 1.0])
    up = hint - np.dot(hint, forward) * forward
    up /= np.linalg.norm(up)
    matrix[:3, 0] = np.cross(up, forward)
    matrix[:3, 1] = up
    matrix[:3, 2] = forward
    return matrix


def _pixel_centres(camera, xp):
    u = (xp.arange(camera.width) + 0.5) / camera.width
    v = (xp.arange(camera.height) + 0.5) / camera.height
    v, u = xp.meshgrid(v, u, indexing="ij")
    return u, v


def pixel_directions(camera, xp=np):
    """(H, W, 3) unit east-north-up direction of every pixel centre of a
    :class:`skyref.scene.Camera`; NaN for fisheye pixels outside the image circle.

    ``xp`` is a NumPy-compatible namespace (``numpy``, ``jax.numpy``).
    """
    u, v = _pixel_centres(camera, xp)
    if camera.type == "equirectangular":
        return xp.stack(equirectangular_direction(u, v, xp), axis=-1)
    rotation = xp.asarray(camera_to_world(camera)[:3, :3])
    if camera.type == "perspective":
        local = perspective_direction(u, v, camera.fov_deg, camera.width / camera.height, xp)
        return xp.stack(local, axis=-1) @ rotation.T
    x, y, z, valid = fisheye_direction(u, v, camera.fov_deg, xp)
    directions = xp.stack([x, y, z], axis=-1) @ rotation.T
    return xp.where(valid[..., None], directions, xp.nan)


def solid_angle(camera) -> np.ndarray:
    """(H, W) solid angle of each pixel, sr (0 for fisheye pixels wholly outside the circle).

    Equirectangular: exact, 2 pi / W * (cos theta_top - cos theta_bottom). Perspective: exact,
    from the solid angle of a rectangle on the image plane. Fisheye: the equidistant Jacobian
    k sin(k r) / r (k = fov/2 in rad, per unit area of the image square [-1, 1]^2) integrated
    with 8 x 8 midpoint samples per pixel, counting only samples inside the circle.
    """
    width, height = camera.width, camera.height
    if camera.type == "equirectangular":
        cos_edges = np.cos(np.linspace(0.0, np.pi, height + 1))
        return np.repeat(((cos_edges[:-1] - cos_edges[1:]) * (2.0 * np.pi / width))[:, None], width, axis=1)
    if camera.type == "perspective":
        tan_half = math.tan(0.5 * math.radians(camera.fov_deg))
        x = np.linspace(-tan_half, tan_half, width + 1)
        y = np.linspace(-tan_half, tan_half, height + 1) * (height / width)
        yy, xx = np.meshgrid(y, x, indexing="ij")
        # Solid angle of the image-plane rectangle [0, x] x [0, y] at unit distance.
        corner = np.arctan(xx * yy / np.sqrt(1.0 + xx * xx + yy * yy))
        return np.abs(corner[1:, 1:] - corner[1:, :-1] - corner[:-1, 1:] + corner[:-1, :-1])
    k = 0.5 * math.radians(camera.fov_deg)
    m = _FISHEYE_SUBSAMPLES
    total = np.zeros((height, width))
    rows = np.arange(height)[:, None]
    cols = np.arange(width)[None, :]
    for i in range(m):
        b = 1.0 - 2.0 * (rows + (i + 0.5) / m) / height
        for j in range(m):
            a = 2.0 * (cols + (j + 0.5) / m) / width - 1.0
            r = np.sqrt(a * a + b * b)
            density = np.where(r > 0, k * np.sin(k * r) / np.maximum(r, 1e-300), k * k)
            total += np.where(r <= 1.0, density, 0.0)
    return total * (4.0 / (width * height * m * m))
