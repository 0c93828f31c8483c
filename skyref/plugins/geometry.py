"""Where a ray is in the atmosphere: altitudes and boundary distances in float32 without
catastrophic cancellation.

Positions are in the observer-centred east-north-up frame (metres, observer at the origin), so
everything near the observer is small and precise. The planet's centre is at
c = (0, 0, -(R + h0)) for ground radius R and observer altitude h0.

Two geometries share one interface:

- :class:`SphericalShell`: ground sphere of radius R, top of the atmosphere at R + H;
- :class:`PlaneParallelSlab`: flat ground and top (the geometry of DISORT), for validation.

Float32 notes (measured, DESIGN.md): the naive altitude |p - c| - R errs by ~0.8 m and
misclassifies grazing rays, and naive sphere intersection self-intersects at the ground. Here
the altitude is h = (|p|^2 + 2 (R + h0) p_z + h0 (2R + h0)) / (|p - c| + R), with the constant
term from float64; sphere intersections use C = r^2 - rho^2 factored as (h - s)(2R + h + s)
(s = rho - R) and the stable quadratic root.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

#: Distance used for rays that never leave a plane-parallel slab (horizontal rays), m.
UNBOUNDED_DISTANCE_M = 1.0e9


class SphericalShell:
    """Spherical planet (radius ``bottom_radius_m``) under an atmosphere up to ``top_radius_m``,
    seen from an observer at ``observer_altitude_m``."""

    def __init__(self, bottom_radius_m: float, top_radius_m: float, observer_altitude_m: float):
        self.R = float(bottom_radius_m)
        self.H = float(top_radius_m - bottom_radius_m)
        self.h0 = float(observer_altitude_m)
        self.centre_distance = self.R + self.h0          # |c|, float64
        self.altitude_offset = self.h0 * (2.0 * self.R + self.h0)  # |c|^2 - R^2, float64
        # Kernel copies are opaque: a new observer altitude reuses the compiled kernels.
        self._centre = dr.opaque(mi.Float, self.centre_distance)
        self._offset = dr.opaque(mi.Float, self.altitude_offset)

    def altitude(self, p: mi.Point3f) -> mi.Float:
        """Altitude above the ground of point ``p``, m (cancellation-free)."""
        q = dr.squared_norm(p) + (2.0 * self._centre) * p.z + self._offset
        r = dr.sqrt(dr.maximum(dr.squared_norm(mi.Vector3f(p.x, p.y, p.z + self._centre)), 0.0))
        return q / (r + self.R)

    def up(self, p: mi.Point3f) -> mi.Vector3f:
        """Local zenith (outward normal of the ground sphere through ``p``)."""
        return dr.normalize(mi.Vector3f(p.x, p.y, p.z + self._centre))

    def _radial_projection(self, p, d):
        # b = dot(p - c, d): negative while the ray approaches the planet's centre.
        return dr.dot(p, d) + self._centre * d.z

    def _c_term(self, h, shell):
        # r^2 - rho^2 for the sphere of radius rho = R + shell, factored to avoid cancellation.
        return (h - shell) * (2.0 * self.R + h + shell)

    def distance_to_ground(self, p, d, h):
        """Distance along ``d`` to the ground sphere, or +inf if the ray misses it. A ray leaving
        the ground (b >= 0) never hits it again: the sphere is convex."""
        b = self._radial_projection(p, d)
        c = self._c_term(h, 0.0)
        disc = b * b - c
        t = c / (-b + dr.sqrt(dr.maximum(disc, 0.0)))
        return dr.select((b < 0.0) & (disc >= 0.0), dr.maximum(t, 0.0), dr.inf)

    def distance_to_top(self, p, d, h):
        """Distance along ``d`` to where the ray leaves the top sphere (from inside), via the
        stable root: q = -b - sign(b) sqrt(disc), roots q and C/q."""
        b = self._radial_projection(p, d)
        c = self._c_term(h, self.H)
        sqrt_disc = dr.sqrt(dr.maximum(b * b - c, 0.0))
        q = -b - dr.copysign(sqrt_disc, b)
        return dr.maximum(dr.select(b >= 0.0, c / q, q), 0.0)

    def distance_to_entry(self, p, d, h):
        """For a point above the atmosphere: distance to where the ray enters the top sphere,
        or +inf if it misses the atmosphere."""
        b = self._radial_projection(p, d)
        c = self._c_term(h, self.H)
        disc = b * b - c
        t = c / (-b + dr.sqrt(dr.maximum(disc, 0.0)))
        return dr.select((b < 0.0) & (disc >= 0.0), dr.maximum(t, 0.0), dr.inf)

    def lowest_altitude(self, p, d, distance, h_start, h_end):
        """Lowest altitude on the segment p + t d, t in [0, distance] (the closest approach to
        the planet's centre, clamped to the segment)."""
        t = dr.clip(-self._radial_projection(p, d), 0.0, distance)
        return dr.minimum(dr.minimum(self.altitude(p + t * d), h_start), h_end)


class PlaneParallelSlab:
    """Flat ground at altitude 0 and flat top at ``thickness_m``, observer at
    ``observer_altitude_m``: altitude = h0 + z."""

    def __init__(self, thickness_m: float, observer_altitude_m: float):
        self.H = float(thickness_m)
        self.h0 = float(observer_altitude_m)
        self._h0 = dr.opaque(mi.Float, self.h0)

    def altitude(self, p):
        return p.z + self._h0

    def up(self, p):
        return mi.Vector3f(0.0, 0.0, 1.0) + 0.0 * p

    def distance_to_ground(self, p, d, h):
        return dr.select(d.z < 0.0, dr.maximum(h, 0.0) / -d.z, dr.inf)

    def distance_to_top(self, p, d, h):
        t = dr.select(d.z > 0.0, dr.maximum(self.H - h, 0.0) / d.z, UNBOUNDED_DISTANCE_M)
        return dr.minimum(t, UNBOUNDED_DISTANCE_M)

    def distance_to_entry(self, p, d, h):
        return dr.select(d.z < 0.0, dr.maximum(h - self.H, 0.0) / -d.z, dr.inf)

    def lowest_altitude(self, p, d, distance, h_start, h_end):
        return dr.minimum(h_start, h_end)
