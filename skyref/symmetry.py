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

Polarized light is mirrored too. Each view's Stokes vector is referred to its meridian frame
(:mod:`skyref.plugins.polarization`): e_perp = normalize(d x up), e_par = -d x e_perp. The
reflection maps the frame of d to that of its mirror image d' with e_par kept and e_perp turned
over (a reflection reverses cross products), so the mirror image of the light seen along d,
referred to the frame of d', has the same I and Q and the opposite U and V (the handedness of
circular polarization turns over with the mirror). The phase matrices of Rayleigh scattering,
of spheres and of a Lambertian ground are unchanged by that sign change (their U-V block and
I-Q block do not mix), so the sky's Stokes vector along d' is diag(1, 1, -1, -1) times that
along d (:data:`MIRROR_STOKES_SIGNS`). A rotation about the vertical keeps every frame's
orientation: copies along a row under a zenith sun keep all four components.

An observer standing on the ground (altitude 0) sees the ground at their feet along every view
below the horizon, through no air: a Lambertian ground's radiance there is the same whichever way
it is seen (and unpolarized), so all those views are one group, whatever the sun. On the LUT
audit's grid they are half the directions, and a hazy sky's ground light (its diffuse
irradiance, multiply scattered) had taken 56% of the samples to 0.3%.

Not used where the symmetry does not hold: a scene with objects (they stand anywhere) and pixels
sampled over their area (a footprint's mirror image need not be a footprint).

A copy is the same estimate, not a second one: its noise is the same draw. Statistics over
many pixels that need their noise (the mean of a region, the noise-corrected RMS of an error)
add the noise of a group's pixels coherently (:mod:`skyref.audit.metrics`).
"""

from __future__ import annotations

import numpy as np

from skyref.projection import pixel_directions

__all__ = ["view_groups", "copy_estimates", "KEY_DECIMALS", "FEET_COSINE", "MIRROR_STOKES_SIGNS"]

#: Directions are compared to 1e-9 (unit-vector components): two pixel centres closer than that
#: see the same sky to float32 precision, the precision the integrator traces them in.
KEY_DECIMALS = 9

#: A view at least this far below the horizon (the cosine of its zenith angle below minus this)
#: meets the ground at an observer's feet: well clear of the integrator's grazing threshold
#: (:data:`skyref.plugins.geometry.GRAZING_COSINE`, 1e-6), under which a ray misses the ground.
FEET_COSINE = 1.0e-4

#: What the reflection through the sun's vertical plane does to a Stokes vector (I, Q, U, V),
#: each referred to its own view's meridian frame (module docstring).
MIRROR_STOKES_SIGNS = np.array([1.0, 1.0, -1.0, -1.0])


def view_groups(scene, pixels: np.ndarray) -> tuple:
    """Which estimate each of the scene's ``pixels`` (flat indices, row * width + column) takes:
    (groups, mirrored). ``groups``: for each pixel, the position in ``pixels`` of the first pixel
    of its symmetry group (see the module docstring), itself where no other pixel sees the same
    sky or the symmetry does not apply; ``np.unique(groups)`` are the pixels to trace.
    ``mirrored``: per pixel, whether it sees the mirror image of that first pixel's sky (its U
    and V turned over) rather than the same sky (itself, or a rotation about the vertical)."""
    positions = np.arange(len(pixels))
    unshared = (positions, np.zeros(len(pixels), dtype=bool))
    render = scene.render
    if scene.objects or render.pixel_sampling != "centre" or len(pixels) == 0:
        return unshared
    directions = pixel_directions(scene.camera).reshape(-1, 3)[pixels]
    up_component = directions[:, 2]
    if scene.sun.zenith_deg == 0.0:
        # every rotation about the vertical leaves the sky as it is: the view zenith tells all
        keys, side = up_component[:, None], np.zeros(len(pixels))
    else:
        sun = np.asarray(scene.sun.direction, dtype=np.float64).reshape(3)
        towards_sun = np.array([sun[0], sun[1], 0.0]) / np.hypot(sun[0], sun[1])   # horizontal
        across = np.array([-towards_sun[1], towards_sun[0], 0.0])                   # normal of the sun's vertical plane
        # the reflection turns the component across the plane over and leaves the other two
        across_component = np.round(directions @ across, KEY_DECIMALS)
        keys = np.stack([up_component, directions @ towards_sun, np.abs(across_component)], axis=1)
        side = np.sign(across_component)                       # 0 in the plane: its own mirror image
    keys = np.round(keys, KEY_DECIMALS)
    if scene.observer.altitude_m == 0.0:
        feet = up_component < -FEET_COSINE                    # the ground at the observer's feet
        keys[feet], side[feet] = -2.0, 0.0                     # one key no direction has; unpolarized
    finite = np.all(np.isfinite(keys), axis=1)
    groups = positions.copy()
    _, first, inverse = np.unique(keys[finite], axis=0, return_index=True, return_inverse=True)
    groups[finite] = positions[finite][first][inverse.reshape(-1)]
    return groups, side * side[groups] < 0.0


def copy_estimates(per_view: np.ndarray, estimate_of: np.ndarray, mirrored: np.ndarray,
                   polarized: bool) -> np.ndarray:
    """Per pixel, the estimate of the view it takes (``per_view[estimate_of]``, pixels first);
    if ``polarized`` (an axis of the 4 Stokes components before the last, wavelength axis), with
    U and V turned over where the pixel is ``mirrored`` (:data:`MIRROR_STOKES_SIGNS`). Means
    only: a standard error is the same for a view and its mirror image."""
    copies = per_view[estimate_of]
    if not polarized or not mirrored.any():
        return copies
    signs = np.where(mirrored[:, None], MIRROR_STOKES_SIGNS, 1.0)
    return copies * signs.reshape(len(signs), *(1,) * (copies.ndim - 3), len(MIRROR_STOKES_SIGNS), 1)
