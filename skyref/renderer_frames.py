"""skyref's frame and the world frames and latitude–longitude images of renderers.

skyref works in the observer's east-north-up frame (ENU: x east, y north, z up; azimuth
clockwise from north, :func:`skyref.scene.direction_from_angles`). A renderer's world frame
(``renderer``):

- ``"mitsuba"``: y up, the convention of Mitsuba's ``envmap`` and example scenes. East is +x, up
  is +y and north is -z (right-handed: x east, y up, z south). With this frame, an ``envmap``
  with no ``to_world`` shows azimuth 360° u at image column u (north at the left edge, east a
  quarter in), zenith at the top.
- ``"blender"``: z up, and Blender's Sun Position add-on puts north at +y: the same axes as ENU.

Latitude–longitude images (:func:`latlong_directions`), row 0 at the top of the file:

- Mitsuba's ``envmap`` (3.9.1, measured) reads the rows of an H-row image as *nodes* from the
  zenith (row 0) to the nadir (row H - 1), zenith angle 180° j / (H - 1), and the columns at
  their centres, azimuth 360° (i + 0.5) / W in the frame above; it interpolates bilinearly.
- Blender's Environment Texture (equirectangular, Cycles' ``direction_to_equirectangular``)
  reads pixel centres: zenith angle 180° (j + 0.5) / H, and u = 0.5 - atan2(y, x) / 360° at
  column centre u = (i + 0.5) / W, i.e. azimuth 360° u - 90° (east in the middle of the image).
"""

from __future__ import annotations

import numpy as np

from skyref.projection import equirectangular_direction
from skyref.validation import check_choice, check_int

__all__ = ["RENDERERS", "WORLD_FROM_ENU", "to_world", "to_enu", "latlong_film_coordinates", "latlong_directions"]

RENDERERS = ("mitsuba", "blender")

#: Rotation taking ENU directions to each renderer's world frame (world = R @ enu).
WORLD_FROM_ENU = {"mitsuba": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
                  "blender": np.eye(3)}


def to_world(directions, renderer: str) -> np.ndarray:
    """ENU vectors ``(..., 3)`` in ``renderer``'s world frame."""
    rotation = WORLD_FROM_ENU[check_choice("renderer", renderer, RENDERERS)]
    return np.asarray(directions, dtype=np.float64) @ rotation.T


def to_enu(directions, renderer: str) -> np.ndarray:
    """Vectors ``(..., 3)`` of ``renderer``'s world frame in ENU (inverse of :func:`to_world`)."""
    rotation = WORLD_FROM_ENU[check_choice("renderer", renderer, RENDERERS)]
    return np.asarray(directions, dtype=np.float64) @ rotation


def latlong_film_coordinates(width: int, height: int, renderer: str) -> tuple[np.ndarray, np.ndarray]:
    """Where the texels of a ``width`` x ``height`` latitude–longitude image in ``renderer`` look,
    as film coordinates of :func:`skyref.projection.equirectangular_direction` (azimuth 360° u
    clockwise from north, zenith angle 180° v): u of each column ``(width,)`` (periodic; it may
    fall outside [0, 1)) and v of each row ``(height,)``; see the module's documentation."""
    check_choice("renderer", renderer, RENDERERS)
    width = check_int("width", width, 1, 1 << 16)
    height = check_int("height", height, 2, 1 << 16)
    u = (np.arange(width) + 0.5) / width
    if renderer == "mitsuba":
        return u, np.arange(height) / (height - 1)
    return u - 0.25, (np.arange(height) + 0.5) / height


def latlong_directions(width: int, height: int, renderer: str) -> np.ndarray:
    """Unit ENU directions ``(height, width, 3)`` that the texels of a ``width`` x ``height``
    latitude–longitude image show in ``renderer`` (its environment image with no rotation, in
    the world frame above); see the module's documentation for each layout."""
    u, v = latlong_film_coordinates(width, height, renderer)
    return np.stack(np.broadcast_arrays(*equirectangular_direction(u[None, :], v[:, None])), axis=-1)
