"""Views that see the same sky: the symmetry of the atmosphere about the sun's vertical plane.

skyref's atmosphere is spherically symmetric (its profiles depend on altitude alone), its
ground is a uniform Lambertian sphere, the observer stands on a vertical through the planet's
centre, and the sun's disk is round. Such a sky is unchanged by the reflection through the
vertical plane that holds the sun, and, with the sun at the zenith, by every rotation about the
vertical: two view directions that one of them maps onto each other see the same radiance, in
every scattering order and wavelength. The pixel centres of an equirectangular camera whose sun
azimuth falls on a pixel centre or a pixel edge come in such pairs (the LUT audit's grid, the
Hosek training grid), and with the sun at the zenith every pixel of a row sees the same sky.
A render traces one direction of each such group and copies its estimate to the others
(:func:`view_groups`): about half the cost, one row's worth with the sun at the zenith.

Not used where the symmetry does not hold or a copy would not be the same estimand: a scene
with objects (they stand anywhere), pixels sampled over their area (a footprint's mirror image
need not be a footprint), and polarized renders (the reflection turns U and V over; skyref
traces every view there).

A copy is the same estimate, not a second one: its noise is the same draw. Statistics over
many pixels that need their noise (the mean of a region, the noise-corrected RMS of an error)
add the noise of a group's pixels coherently (:mod:`skyref.audit.metrics`).
"""

from __future__ import annotations

import numpy as np

from skyref.projection import pixel_directions

__all__ = ["view_groups", "KEY_DECIMALS"]

#: Directions are compared to 1e-9 (unit-vector components): two pixel centres closer than that
#: see the same sky to float32 precision, the precision the integrator traces them in.
KEY_DECIMALS = 9


def view_groups(scene, pixels: np.ndarray) -> np.ndarray:
    """For each of the scene's ``pixels`` (flat indices, row * width + column), the position in
    ``pixels`` of the one whose estimate it takes: the first pixel of its symmetry group (see the
    module docstring), itself where no other pixel sees the same sky or the symmetry does not
    apply. ``np.unique`` of the result are the pixels to trace."""
    positions = np.arange(len(pixels))
    render = scene.render
    if scene.objects or render.pixel_sampling != "centre" or render.polarized or len(pixels) == 0:
        return positions
    directions = pixel_directions(scene.camera).reshape(-1, 3)[pixels]
    up_component = directions[:, 2]
    if scene.sun.zenith_deg == 0.0:
        # every rotation about the vertical leaves the sky as it is: the view zenith tells all
        keys = up_component[:, None]
    else:
        sun = np.asarray(scene.sun.direction, dtype=np.float64).reshape(3)
        towards_sun = np.array([sun[0], sun[1], 0.0]) / np.hypot(sun[0], sun[1])   # horizontal
        across = np.array([-towards_sun[1], towards_sun[0], 0.0])                   # normal of the sun's vertical plane
        # the reflection turns the component across the plane over and leaves the other two
        keys = np.stack([up_component, directions @ towards_sun, np.abs(directions @ across)], axis=1)
    keys = np.round(keys, KEY_DECIMALS)
    finite = np.all(np.isfinite(keys), axis=1)
    groups = positions.copy()
    _, first, inverse = np.unique(keys[finite], axis=0, return_index=True, return_inverse=True)
    groups[finite] = positions[finite][first][inverse.reshape(-1)]
    return groups
