"""Where a ray is in the atmosphere: altitudes and boundary distances in float32 without
catastrophic cancellation.

Positions are in the observer-centred east-north-up frame (metres, observer at the origin), so
everything near the observer is small and precise. The planet's centre is at
c = (0, 0, -(R + h0)) for ground radius R and observer altitude h0.

Two geometries share one interface:

- :class:`SphericalShell`: ground sphere of radius R, top of the atmosphere at R + H;
- :class:`PlaneParallelSlab`: flat ground and top (the geometry of DISORT), for validation.

Float32 notes (measured, docs/design.md): the naive altitude |p - c| - R errs by ~0.8 m and
misclassifies grazing rays, and naive sphere intersection self-intersects at the ground. Here
the altitude is h = (|p|^2 + 2 (R + h0) p_z + h0 (2R + h0)) / (|p - c| + R), with the constant
term from float64; sphere intersections use C = r^2 - rho^2 factored as (h - s)(2R + h + s)
(s = rho - R) and the stable quadratic root.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from skyref.plugins import quadrature
from skyref.plugins.drjit_namespace import xp

__all__ = ["UNBOUNDED_DISTANCE_M", "GRAZING_COSINE", "SphericalShell", "PlaneParallelSlab"]

#: Distance used for rays that never leave a plane-parallel slab (horizontal rays), m.
UNBOUNDED_DISTANCE_M = 1.0e9

#: Rays whose cosine with the local zenith is above -GRAZING_COSINE do not descend: a tangent
#: ray from the ground misses it (float32 rounding of a horizontal direction gives -4.4e-8; at
#: 1e-6 the ray's elevation is -0.2 arcsec).
GRAZING_COSINE = 1.0e-6


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
        self._h0 = dr.opaque(mi.Float, self.h0)

    def altitude(self, p: mi.Point3f) -> mi.Float:
        """Altitude above the ground of point ``p``, m (cancellation-free)."""
        q = dr.squared_norm(p) + (2.0 * self._centre) * p.z + self._offset
        r = dr.sqrt(dr.maximum(dr.squared_norm(mi.Vector3f(p.x, p.y, p.z + self._centre)), 0.0))
        return q / (r + self.R)

    def above_observer(self, altitude) -> mi.Point3f:
        """The point at ``altitude`` (m) on the observer's vertical."""
        return mi.Point3f(0.0, 0.0, altitude - self._h0)

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
        the ground (b >= 0) never hits it again: the sphere is convex. A ray tangent to the
        ground at its start (the local zenith cosine above -GRAZING_COSINE: float32 gives
        cos(pi/2) = -4.4e-8) misses it, as a horizontal ray must."""
        b = self._radial_projection(p, d)
        c = self._c_term(h, 0.0)
        disc = b * b - c
        t = c / (-b + dr.sqrt(dr.maximum(disc, 0.0)))
        descends = b < -GRAZING_COSINE * (self.R + h)
        return dr.select(descends & (disc >= 0.0), dr.maximum(t, 0.0), dr.inf)

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

    def level_crossings(self, p, d, h, level):
        """(down, up) distances along ``d`` to the sphere of altitude ``level`` (see
        :func:`skyref.plugins.quadrature.level_crossings`)."""
        return quadrature.level_crossings(self._radial_projection(p, d), h, level, self.R, xp)

    def sun_can_graze(self, sun_zenith_deg: float) -> bool:
        """Whether a ray to the sun (zenith angle ``sun_zenith_deg`` at the observer) from a
        point of a ray from the observer can pass below that point: where the sun is below
        that point's horizon. The points are within arccos(R / (R + h0)) + arccos(R / (R + H))
        of arc of the observer (out to the top over the horizon), or anywhere for an observer
        above the atmosphere."""
        if self.h0 >= self.H:
            return True
        arc = math.acos(self.R / (self.R + max(self.h0, 0.0))) + math.acos(self.R / (self.R + self.H))
        return sun_zenith_deg + math.degrees(arc) > 90.0

    def shadow_interval(self, p, d, length, sun):
        """[t_in, t_out] within [0, length] where p + t d lies in the planet's shadow for the
        sun direction ``sun`` (unit): inside the cylinder of radius R behind the planet. A line
        meets that convex region in one interval; none gives t_in = t_out = length."""
        return self.grazing_interval(p, d, length, sun, 0.0)

    def grazing_interval(self, p, d, length, sun, tangent_altitude):
        """[t_in, t_out] within [0, length] where the ray to the sun from p + t d passes below
        ``tangent_altitude`` (m): inside the cylinder of radius R + tangent_altitude around the
        sun's axis, behind the plane through the planet's centre normal to ``sun`` (in front of
        it the ray to the sun only rises). At 0 this is the planet's shadow. A line meets that
        convex region in one interval; none gives t_in = t_out = length."""
        radius = self.R + tangent_altitude
        e = mi.Vector3f(p.x, p.y, p.z + self._centre)      # from the planet's centre
        e_along, d_along = dr.dot(e, sun), dr.dot(d, sun)
        e_perp, d_perp = e - e_along * sun, d - d_along * sun
        a = dr.squared_norm(d_perp)
        b = dr.dot(e_perp, d_perp)
        c = dr.squared_norm(e_perp) - radius * radius
        disc = b * b - a * c
        root = dr.sqrt(dr.maximum(disc, 0.0))
        inv_a = dr.rcp(dr.maximum(a, 1e-12))
        meets = (disc > 0.0) & (a > 1e-12)
        t_in = dr.select(meets, (-b - root) * inv_a, dr.select(c < 0.0, -dr.inf, dr.inf))
        t_out = dr.select(meets, (-b + root) * inv_a, dr.select(c < 0.0, dr.inf, -dr.inf))
        # ... and behind the planet: e . sun + t d . sun < 0
        t_behind = -e_along / dr.select(d_along == 0.0, 1e-30, d_along)
        t_in = dr.select(d_along < 0.0, dr.maximum(t_in, t_behind), t_in)
        t_out = dr.select(d_along > 0.0, dr.minimum(t_out, t_behind), t_out)
        t_out = dr.select((d_along == 0.0) & (e_along >= 0.0), -dr.inf, t_out)
        t_in, t_out = dr.clip(t_in, 0.0, length), dr.clip(t_out, 0.0, length)
        empty = t_out <= t_in
        return dr.select(empty, length, t_in), dr.select(empty, length, t_out)


class PlaneParallelSlab:
    """Flat ground at altitude 0 and flat top at ``thickness_m``, observer at
    ``observer_altitude_m``: altitude = h0 + z."""

    def __init__(self, thickness_m: float, observer_altitude_m: float):
        self.H = float(thickness_m)
        self.h0 = float(observer_altitude_m)
        self._h0 = dr.opaque(mi.Float, self.h0)

    def altitude(self, p):
        return p.z + self._h0

    def above_observer(self, altitude) -> mi.Point3f:
        """The point at ``altitude`` (m) on the observer's vertical."""
        return mi.Point3f(0.0, 0.0, altitude - self._h0)

    def up(self, p):
        return mi.Vector3f(0.0, 0.0, 1.0) + 0.0 * p

    def distance_to_ground(self, p, d, h):
        return dr.select(d.z < -GRAZING_COSINE, dr.maximum(h, 0.0) / -d.z, dr.inf)

    def distance_to_top(self, p, d, h):
        t = dr.select(d.z > 0.0, dr.maximum(self.H - h, 0.0) / d.z, UNBOUNDED_DISTANCE_M)
        return dr.minimum(t, UNBOUNDED_DISTANCE_M)

    def distance_to_entry(self, p, d, h):
        return dr.select(d.z < 0.0, dr.maximum(h - self.H, 0.0) / -d.z, dr.inf)

    def lowest_altitude(self, p, d, distance, h_start, h_end):
        return dr.minimum(h_start, h_end)

    def level_crossings(self, p, d, h, level):
        t = (level - h) / dr.select(d.z == 0.0, 1e-30, d.z)
        return dr.select(d.z < 0.0, t, -dr.inf), dr.select(d.z > 0.0, t, dr.inf)

    def sun_can_graze(self, sun_zenith_deg: float) -> bool:
        """Rays to the sun never pass below the point they leave from."""
        return False

    def shadow_interval(self, p, d, length, sun):
        """A flat ground casts no shadow in the air, but a sun at or below the horizon lights
        nothing (its optical depth is infinite; the column above a point near the top over a
        clamped cosine was not, and lit the thin air there): then the whole ray is in shadow."""
        below = sun.z <= 0.0
        return dr.select(below, 0.0, mi.Float(length)), mi.Float(length)

    def grazing_interval(self, p, d, length, sun, tangent_altitude):
        """Rays to the sun never pass below the point they leave from: no interval."""
        return mi.Float(length), mi.Float(length)
