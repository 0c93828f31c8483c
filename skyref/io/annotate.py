"""Overlays on sky previews: the horizon, compass labels N/E/S/W and a sun marker, placed by
the camera's own projection (:mod:`skyref.projection`), and a caption line (e.g. a time stamp).

Positions are in Pillow's image coordinates, pixels: x to the right, y down, the centre of
pixel (row i, column j) at (j + 0.5, i + 0.5), i.e. x = u W and y = v H for film coordinates
(u, v). Fisheye and equirectangular cameras are supported; perspective cameras are not.

Pillow is imported inside the drawing functions: ``skyref --help`` imports this module (through
:mod:`skyref.io.png` and :mod:`skyref.cli`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from skyref.errors import ParameterError
from skyref.projection import camera_to_world, equirectangular_pixel, fisheye_pixel

__all__ = ["ANNOTATED_CAMERAS", "COMPASS", "Overlay", "check_annotatable", "font_size", "overlay_geometry",
           "draw_overlay", "draw_caption"]

#: Camera types whose previews can be annotated.
ANNOTATED_CAMERAS = ("fisheye", "equirectangular")

#: Compass labels and their azimuths, degrees clockwise from north.
COMPASS = {"N": 0.0, "E": 90.0, "S": 180.0, "W": 270.0}

_HORIZON_COLOUR = (200, 200, 200)
_LABEL_COLOUR = (255, 255, 255)
_SUN_COLOUR = (255, 200, 0)
_OUTLINE_COLOUR = (0, 0, 0)
_HORIZON_STEP_DEG = 0.5


@dataclass(frozen=True)
class Overlay:
    """Where the overlay goes, in pixels: ``horizon``, polylines (each (K, 2) x, y); ``labels``,
    compass letter -> list of (x, y, Pillow text anchor) (an equirectangular map shows N at both
    edges); ``sun``, (x, y) of the sun's centre, or None when the sun is out of view;
    ``sun_radius`` and ``font`` sizes in pixels."""

    horizon: list
    labels: dict
    sun: tuple | None
    sun_radius: int
    font: int


def check_annotatable(camera, parameter: str = "annotate") -> None:
    """Refuse a camera whose previews cannot be annotated (before any work)."""
    if camera.type not in ANNOTATED_CAMERAS:
        raise ParameterError(parameter, camera.type, "a " + " or ".join(ANNOTATED_CAMERAS) + " camera",
                             "no annotation for this camera type")


def font_size(width: int, height: int) -> int:
    """Text height for an image of ``width`` x ``height`` pixels: 1/12 of the shorter side, at
    least 9."""
    return max(9, round(min(width, height) / 12))


def _compass_direction(azimuth_deg, elevation_deg) -> np.ndarray:
    azimuth, elevation = np.radians(azimuth_deg), np.radians(elevation_deg)
    return np.stack(np.broadcast_arrays(np.cos(elevation) * np.sin(azimuth), np.cos(elevation) * np.cos(azimuth),
                                        np.sin(elevation)), axis=-1)


def _fisheye_points(camera, directions):
    """Pixel (x, y) and image-circle radius r (1 at the circle) of east-north-up directions."""
    local = np.asarray(directions, dtype=np.float64) @ camera_to_world(camera)[:3, :3]
    u, v = fisheye_pixel(local, camera.fov_deg)
    return u * camera.width, v * camera.height, np.hypot(2.0 * u - 1.0, 1.0 - 2.0 * v)


def _runs(mask):
    """(start, stop) of each run of True in a 1-D boolean array."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    return list(zip(edges[::2], edges[1::2]))


def overlay_geometry(camera, sun_direction) -> Overlay:
    """The :class:`Overlay` of a :class:`skyref.scene.Camera` and the unit direction towards the
    sun (east-north-up).

    Fisheye: the horizon is the projection of elevation 0 over all azimuths (the image circle
    itself for an upward 180-degree fisheye); each compass letter is centred on its azimuth at
    the lowest elevation that keeps the letter above the horizon and inside the image circle
    (its centre 0.8 font sizes from both); the sun is shown when it projects inside the circle.
    Equirectangular: the horizon is the row v = 1/2, the letters stand just above it at their
    columns (u = azimuth / 360 deg; N at both edges), and the sun is always in view.
    """
    check_annotatable(camera)
    width, height = camera.width, camera.height
    font = font_size(width, height)
    sun_radius = max(3, round(min(width, height) / 32))
    sun_direction = np.asarray(sun_direction, dtype=np.float64)
    if camera.type == "equirectangular":
        y = 0.5 * height
        labels = {name: [(azimuth / 360.0 * width, y - 0.6 * font, "mm")] for name, azimuth in COMPASS.items()}
        labels["N"] = [(1.0, y - 0.6 * font, "lm"), (width - 1.0, y - 0.6 * font, "rm")]
        u, v = equirectangular_pixel(sun_direction)
        return Overlay([np.array([[0.0, y], [float(width), y]])], labels, (float(u) * width, float(v) * height),
                       sun_radius, font)

    azimuths = np.arange(0.0, 360.0 + _HORIZON_STEP_DEG / 2, _HORIZON_STEP_DEG)
    x, y, r = _fisheye_points(camera, _compass_direction(azimuths, 0.0))
    visible = r <= 1.0 + 1e-9
    horizon = [np.stack([x[a:b], y[a:b]], axis=-1) for a, b in _runs(visible) if b - a > 1]

    # Letter centres 0.8 font sizes above the horizon and in from the image circle.
    margin = 1.0 - 1.6 * font / min(width, height)
    lowest = 0.8 * font * camera.fov_deg / min(width, height)
    elevations = np.arange(lowest, 90.0, 0.25)
    labels = {}
    for name, azimuth in COMPASS.items():
        x, y, r = _fisheye_points(camera, _compass_direction(azimuth, elevations))
        inside = np.flatnonzero(r <= margin)
        if inside.size:
            i = inside[0]
            labels[name] = [(float(x[i]), float(y[i]), "mm")]
    x, y, r = _fisheye_points(camera, sun_direction)
    sun = (float(x), float(y)) if r <= 1.0 else None
    return Overlay(horizon, labels, sun, sun_radius, font)


def draw_overlay(image, camera, sun_direction) -> np.ndarray:
    """``image`` (H, W, 3) uint8 with the horizon (grey), compass letters (white, black outline)
    and a ring around the sun (amber) of :func:`overlay_geometry` drawn on it; a new array."""
    from PIL import Image, ImageDraw, ImageFont  # lazy: see the module docstring

    overlay = overlay_geometry(camera, sun_direction)
    picture = Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8), mode="RGB")
    draw = ImageDraw.Draw(picture)
    line = max(1, overlay.font // 12)
    for polyline in overlay.horizon:
        draw.line([tuple(p) for p in polyline], fill=_HORIZON_COLOUR, width=line)
    font = ImageFont.load_default(overlay.font)
    for name, places in overlay.labels.items():
        for x, y, anchor in places:
            draw.text((x, y), name, font=font, fill=_LABEL_COLOUR, anchor=anchor,
                      stroke_width=1, stroke_fill=_OUTLINE_COLOUR)
    if overlay.sun is not None:
        x, y = overlay.sun
        radius = overlay.sun_radius
        draw.ellipse((x - radius, y - radius, x + radius, y + radius), outline=_SUN_COLOUR, width=line)
    return np.asarray(picture)


def draw_caption(image, text: str) -> np.ndarray:
    """``image`` (H, W, 3) uint8 with ``text`` (lines split at ``\\n``) in its lower left corner,
    white with a black outline: the overlay's font size, smaller if a line would cross the
    middle of the image; a new array."""
    from PIL import Image, ImageDraw, ImageFont  # lazy: see the module docstring

    height, width = image.shape[:2]
    lines = text.split("\n")
    size = font_size(width, height)
    font = ImageFont.load_default(size)
    while size > 6 and max(font.getlength(line) for line in lines) > 0.5 * width - size / 4:
        size -= 1
        font = ImageFont.load_default(size)
    picture = Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8), mode="RGB")
    draw = ImageDraw.Draw(picture)
    for i, line in enumerate(reversed(lines)):
        draw.text((math.ceil(size / 4), height - math.ceil(size / 4) - i * round(1.2 * size)), line, font=font,
                  fill=_LABEL_COLOUR, anchor="ld", stroke_width=1, stroke_fill=_OUTLINE_COLOUR)
    return np.asarray(picture)
