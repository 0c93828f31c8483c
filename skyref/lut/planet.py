"""Planet-centred ray geometry of the LUT methods (Bruneton 2017, section 2.1 conventions).

A view point is described by its distance ``r`` from the planet's centre (m) and the cosine
``mu`` of the angle between the view ray and the local zenith. With bottom radius R and top
radius R_t:

- the ray hits the ground iff mu < 0 and r^2 (mu^2 - 1) + R^2 >= 0;
- it leaves the top after d_top = -r mu + sqrt(r^2 (mu^2 - 1) + R_t^2);
- it reaches the ground after d_bottom = -r mu - sqrt(r^2 (mu^2 - 1) + R^2);
- after a distance d the point is at r_d = sqrt(d^2 + 2 r mu d + r^2) with
  mu_d = (r mu + d) / r_d.

Functions take Dr.Jit arrays (use Float64: r^2 - R^2 cancels badly in float32).

References
----------
E. Bruneton, "Precomputed Atmospheric Scattering: a New Implementation", 2017,
https://ebruneton.github.io/precomputed_atmospheric_scattering/ (code and documentation).
"""

from __future__ import annotations

import drjit as dr

__all__ = ["distance_to_top", "distance_to_bottom", "intersects_ground", "distance_to_nearest_boundary",
           "point_along_ray"]


def distance_to_top(r, mu, top_radius):
    """Distance from (r, mu) along the ray to the top of the atmosphere, m (>= 0)."""
    discriminant = r * r * (mu * mu - 1.0) + top_radius * top_radius
    return dr.maximum(-r * mu + dr.safe_sqrt(discriminant), 0.0)


def distance_to_bottom(r, mu, bottom_radius):
    """Distance from (r, mu) along the ray to the ground, m (meaningful where it hits it)."""
    discriminant = r * r * (mu * mu - 1.0) + bottom_radius * bottom_radius
    return dr.maximum(-r * mu - dr.safe_sqrt(discriminant), 0.0)


def intersects_ground(r, mu, bottom_radius):
    """True where the ray from (r, mu) hits the ground."""
    return (mu < 0.0) & (r * r * (mu * mu - 1.0) + bottom_radius * bottom_radius >= 0.0)


def distance_to_nearest_boundary(r, mu, bottom_radius, top_radius, ray_hits_ground):
    """Distance to the ground where ``ray_hits_ground``, else to the top of the atmosphere."""
    return dr.select(ray_hits_ground, distance_to_bottom(r, mu, bottom_radius),
                     distance_to_top(r, mu, top_radius))


def point_along_ray(r, mu, d):
    """(r_d, mu_d) of the point at distance ``d`` along the ray from (r, mu)."""
    r_d = dr.safe_sqrt(d * d + 2.0 * r * mu * d + r * r)
    return r_d, dr.clip((r * mu + d) / dr.maximum(r_d, 1e-9), -1.0, 1.0)
