"""Regions of the view sphere where errors are reported separately.

Angles are measured from the observer: the geometric horizon of an observer at radius r above a
planet of radius R lies at zenith angle theta_h with cos theta_h = -sqrt(1 - (R / r)^2) (90 deg
on the ground). A view ray hits the ground below it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ANTISOLAR_REGION_DEG", "HORIZON_BAND_DEG", "REGIONS", "SUN_REGION_DEG", "horizon_cosine", "region_masks"]

#: Half-width of the horizon band around the geometric horizon, degrees.
HORIZON_BAND_DEG = 5.0
#: Radius of the region around the sun (the solar disk itself is excluded everywhere), degrees.
SUN_REGION_DEG = 10.0
#: Radius of the anti-solar region (around the direction opposite the sun), degrees.
ANTISOLAR_REGION_DEG = 30.0
#: Regions of the sky in report order; "away" is the sky minus the horizon band and the sun region.
REGIONS = ("sky", "horizon", "sun", "antisolar", "away", "ground")


def horizon_cosine(bottom_radius_m: float, observer_altitude_m: float) -> float:
    """cos of the zenith angle of the geometric horizon (0 on the ground, < 0 above it)."""
    ratio = bottom_radius_m / (bottom_radius_m + observer_altitude_m)
    return -float(np.sqrt(max(0.0, 1.0 - ratio * ratio)))


def region_masks(directions, sun_direction, bottom_radius_m: float, observer_altitude_m: float) -> dict:
    """Boolean masks (shape of ``directions[..., 0]``) for every name in :data:`REGIONS`.
    Directions are unit vectors, east-north-up; NaN directions belong to no region."""
    d = np.asarray(directions, dtype=np.float64)
    valid = np.all(np.isfinite(d), axis=-1)
    d = np.where(valid[..., None], d, 0.0)
    sun = np.asarray(sun_direction, dtype=np.float64) / np.linalg.norm(sun_direction)
    zenith_deg = np.degrees(np.arccos(np.clip(d[..., 2], -1.0, 1.0)))
    horizon_deg = np.degrees(np.arccos(horizon_cosine(bottom_radius_m, observer_altitude_m)))
    to_sun_deg = np.degrees(np.arccos(np.clip(d @ sun, -1.0, 1.0)))
    ground = valid & (zenith_deg > horizon_deg)
    sky = valid & ~ground
    horizon = sky & (zenith_deg > horizon_deg - HORIZON_BAND_DEG)
    near_sun = sky & (to_sun_deg < SUN_REGION_DEG)
    return {"sky": sky, "horizon": horizon, "sun": near_sun,
            "antisolar": sky & (to_sun_deg > 180.0 - ANTISOLAR_REGION_DEG),
            "away": sky & ~horizon & ~near_sun, "ground": ground}
