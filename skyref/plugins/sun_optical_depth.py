"""The optical depth from any point of the atmosphere to the top along the sun's direction, per
constituent at relative density 1 (metres of "unit-density path"): tau_c(h, mu_s), with mu_s the
cosine of the sun's zenith angle at the point. A kernel multiplies it by each channel's
extinction coefficient of the constituent, so one lookup serves every wavelength and every
differentiable coefficient.

Spherical shell: a table over Bruneton's transmittance parametrisation (Bruneton 2017,
``GetTransmittanceTextureUvFromRMu``: x_r = rho / rho_top with rho = sqrt(r^2 - R^2), and x_mu the
distance to the top between its smallest and largest value), filled in float64 by a 6-node
Gauss–Legendre rule on the panels of :mod:`skyref.plugins.quadrature` (each halved), and read
with bilinear interpolation. Rays towards the sun that hit the ground are in the planet's shadow:
their optical depth is not tabulated (the line integral decides shadow geometrically).

Plane-parallel slab: the vertical column above the point (closed form per profile) / mu_s.

:class:`GreySunDepth`: sum_c k_c tau_c for fixed grey coefficients k_c, from a coarse copy of the
table that stays in cache, for sampling decisions that look the sun up at many points.

References
----------
E. Bruneton, "A Qualitative and Quantitative Evaluation of 8 Clear Sky Models", IEEE TVCG 23
(2017), and its precomputed-scattering code (transmittance texture layout).
"""

from __future__ import annotations

import functools
import math

import drjit as dr
import mitsuba as mi
import numpy as np

from skyref.plugins.drjit_namespace import xp
from skyref.plugins.quadrature import GaussLegendreRule, level_crossings, ordered_breakpoints, panel_levels

__all__ = ["TABLE_SIZE", "TABLE_NODES", "GREY_TABLE_SIZE", "unit_optical_depth", "table_coordinates",
           "SunOpticalDepth", "GreySunDepth"]

#: Table size (x_r, x_mu). Against the direct quadrature at random points and sun directions
#: (``tests/test_line_integral.py``), the transmittance at 440 nm differs by at most 3e-5
#: (bruneton2017) and 6e-5 (turbidity 6).
TABLE_SIZE = (256, 1024)

#: Gauss–Legendre nodes per half panel when the table is filled.
TABLE_NODES = 6

#: Size (x_r, x_mu) of :class:`GreySunDepth`'s table: 32 KB, read from cache. Looking the full
#: table up (3 MB, 4 cache lines per lookup) at the ~15 panel boundaries of every path segment
#: cost 18-45% more CPU per path; this one 8-16%.
GREY_TABLE_SIZE = (64, 128)


def unit_optical_depth(profiles, bottom_radius: float, top_radius: float, levels, h, mu):
    """Optical depth (m at relative density 1) of each profile along the ray from altitude
    ``h`` with zenith cosine ``mu`` (float64 arrays) to the top: shape h.shape + (profiles,).
    A ``TABLE_NODES``-node Gauss–Legendre rule on the panels of ``levels``, each halved."""
    R = bottom_radius
    thickness = top_radius - R
    h, mu = np.broadcast_arrays(np.asarray(h, np.float64), np.asarray(mu, np.float64))
    r = R + h
    r_mu = r * mu
    d = -r_mu + np.sqrt(np.maximum(r_mu * r_mu + (thickness - h) * (2.0 * R + thickness + h), 0.0))
    full = (0.0,) + tuple(levels) + (thickness,)
    fine = tuple(sorted(set(levels) | {0.5 * (a + b) for a, b in zip(full[:-1], full[1:])}))
    crossings = [level_crossings(r_mu, h, level, R, np) for level in fine]
    breakpoints = ordered_breakpoints(crossings, d, rising_only=False, xp=np)
    rule = GaussLegendreRule(TABLE_NODES)
    tau = np.zeros(h.shape + (len(profiles),))
    for a, b in zip(breakpoints[:-1], breakpoints[1:]):
        for u, w in zip(rule.nodes, rule.weights):
            t = a + u * (b - a)
            # altitude without cancellation: (r^2 - R^2 + 2 r mu t + t^2) / (r(t) + R)
            radius = np.sqrt(r * r + 2.0 * r_mu * t + t * t)
            altitude = np.maximum((h * (2.0 * R + h) + 2.0 * r_mu * t + t * t) / (radius + R), 0.0)
            for c, profile in enumerate(profiles):
                tau[..., c] += w * (b - a) * profile.density(altitude)
    return tau


def table_coordinates(bottom_radius: float, top_radius: float):
    """Altitudes and zenith cosines (NR, NM) of the table's grid points (x_r, x_mu)."""
    nr, nm = TABLE_SIZE
    R, top = bottom_radius, top_radius
    rho_top = math.sqrt(top * top - R * R)
    rho = np.linspace(0.0, 1.0, nr)[:, None] * rho_top
    r = np.sqrt(rho * rho + R * R)
    d_min, d_max = top - r, rho + rho_top
    d = d_min + np.linspace(0.0, 1.0, nm)[None, :] * (d_max - d_min)
    with np.errstate(invalid="ignore", divide="ignore"):
        mu = np.where(d > 0.0, (rho_top ** 2 - rho ** 2 - d * d) / (2.0 * r * d), 1.0)
    return rho * rho / (r + R) + 0.0 * mu, np.clip(mu, -1.0, 1.0)


@functools.lru_cache(maxsize=32)
def _table(profiles: tuple, bottom_radius: float, top_radius: float, levels: tuple):
    h, mu = table_coordinates(bottom_radius, top_radius)
    return unit_optical_depth(profiles, bottom_radius, top_radius, levels, h, mu).astype(np.float32).ravel()


class SunOpticalDepth:
    """Per-constituent optical depth towards the sun (see the module docstring) for the
    constituents of ``atmosphere`` in ``geometry`` (``SphericalShell`` or ``PlaneParallelSlab``)."""

    def __init__(self, atmosphere, geometry):
        self.profiles = tuple(c.profile for c in atmosphere.constituents)
        self.spherical = hasattr(geometry, "R")
        self.geometry = geometry
        if self.spherical:
            R, top = atmosphere.bottom_radius_m, atmosphere.top_radius_m
            #: the table as filled (float32, (x_r, x_mu, constituent) flattened)
            self.values = _table(self.profiles, R, top, panel_levels(atmosphere))
            self.table = mi.Float(self.values)
            self.R = R
            self.H = top - R
            self.rho_top = math.sqrt(top * top - R * R)

    def __call__(self, h, mu_s):
        """[tau_c] per constituent (Float, m at relative density 1) from altitude ``h`` towards
        a sun whose zenith cosine there is ``mu_s``; meaningful only where the sun is above
        the ground's horizon (elsewhere the ray is shadowed)."""
        if not self.spherical:
            inv_mu = dr.rcp(dr.maximum(mu_s, 1e-6))
            return [p.column_above(h, self.geometry.H, xp) * inv_mu for p in self.profiles]
        x_r, x_mu = self.coordinates(h, mu_s)
        return _bilinear(self.table, TABLE_SIZE, len(self.profiles), x_r, x_mu)

    def coordinates(self, h, mu_s):
        """The table coordinates (x_r, x_mu) in [0, 1] of altitude ``h`` and sun zenith cosine
        ``mu_s`` (spherical shell)."""
        R, H = self.R, self.H
        h = dr.clip(h, 0.0, H)
        r = R + h
        rho = dr.sqrt(h * (2.0 * R + h))
        # distance to the top: both terms of the discriminant are >= 0 (no cancellation), and
        # for rising rays the stable root (top^2 - r^2) / (r mu + sqrt(disc)).
        r_mu = r * mu_s
        c_top = (H - h) * (2.0 * R + H + h)
        sqrt_disc = dr.sqrt(c_top + r_mu * r_mu)
        d = dr.select(mu_s >= 0.0, c_top / dr.maximum(r_mu + sqrt_disc, 1e-6), sqrt_disc - r_mu)
        d_min, d_max = H - h, rho + self.rho_top
        x_mu = dr.clip((d - d_min) / dr.maximum(d_max - d_min, 1e-6), 0.0, 1.0)
        x_r = dr.clip(rho / self.rho_top, 0.0, 1.0)
        return x_r, x_mu


def _bilinear(table, size, count, x_r, x_mu):
    """Bilinear interpolation at (x_r, x_mu) in [0, 1]^2 of a table of ``size`` (x_r, x_mu)
    points holding ``count`` interleaved values each: a list of ``count`` Floats."""
    nr, nm = size
    fr, fm = x_r * (nr - 1), x_mu * (nm - 1)
    i = dr.minimum(mi.UInt32(fr), nr - 2)
    j = dr.minimum(mi.UInt32(fm), nm - 2)
    a, b = fr - mi.Float(i), fm - mi.Float(j)
    corners = [((i * nm + j) * count, (1.0 - a) * (1.0 - b)), ((i * nm + j + 1) * count, (1.0 - a) * b),
               (((i + 1) * nm + j) * count, a * (1.0 - b)), (((i + 1) * nm + j + 1) * count, a * b)]
    return [sum(weight * dr.gather(mi.Float, table, index + c) for index, weight in corners) for c in range(count)]


class GreySunDepth:
    """The sun's optical depth sum_c k_c tau_c(h, mu_s) for fixed grey coefficients k_c (m^-1 at
    relative density 1, one per constituent of ``sun_depth``'s atmosphere; None for none): on a
    spherical shell from the full table resampled (bilinearly, in float64) on a
    ``GREY_TABLE_SIZE`` grid of the same coordinates, on a plane-parallel slab in closed form.
    It is coarse (turbidity 6, the most transparent of 360-760 nm, 200,000 random points: 99% within
    0.42 of the full table's optical depth, all within 8% of it, up to 3.5 where rays to the sun
    graze the ground at depths near 67), which only shapes sampling densities."""

    def __init__(self, sun_depth: SunOpticalDepth, coefficients):
        self.sun_depth = sun_depth
        self.coefficients = [0.0 if k is None else float(k) for k in coefficients]
        if sun_depth.spherical:
            nr, nm = TABLE_SIZE
            full = sun_depth.values.reshape(nr, nm, len(self.coefficients)).astype(np.float64) @ self.coefficients
            gr, gm = GREY_TABLE_SIZE
            at_r, at_mu = np.linspace(0.0, nr - 1.0, gr), np.linspace(0.0, nm - 1.0, gm)
            rows = np.stack([np.interp(at_mu, np.arange(nm), full[i]) for i in range(nr)])
            grey = np.stack([np.interp(at_r, np.arange(nr), rows[:, j]) for j in range(gm)], axis=1)
            self.table = mi.Float(grey.astype(np.float32).ravel())

    def __call__(self, h, mu_s):
        """The grey optical depth (Float) from altitude ``h`` towards a sun of zenith cosine ``mu_s``."""
        if not self.sun_depth.spherical:
            return sum(k * tau for k, tau in zip(self.coefficients, self.sun_depth(h, mu_s)) if k != 0.0)
        x_r, x_mu = self.sun_depth.coordinates(h, mu_s)
        return _bilinear(self.table, GREY_TABLE_SIZE, 1, x_r, x_mu)[0]
