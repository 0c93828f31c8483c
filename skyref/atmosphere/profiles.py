"""Density profiles: how the amount of a constituent varies with altitude.

A profile returns a *relative* density (dimensionless, usually 1 at its reference altitude);
a constituent multiplies it by its coefficients (m^-1 at relative density 1). Altitudes are in
metres above the planet's surface.

Evaluation (:meth:`DensityProfile.density`, :meth:`DensityProfile.max_density`) is written
against an array namespace ``xp`` (``numpy``, ``jax.numpy`` or skyref's Dr.Jit namespace), so
the path tracer, the LUT methods and the fitter all evaluate the *same* formula. ``xp`` needs
``exp``, ``minimum``, ``maximum`` and ``where``.

Vertical integrals (:meth:`DensityProfile.column`) are analytic; slant paths are integrated
numerically by :class:`skyref.atmosphere.Atmosphere`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from skyref.validation import check_array, check_choice, check_fields, check_number
from skyref.errors import ParameterError

__all__ = ["MAX_ALTITUDE_M", "EXPONENTIAL_PANEL_SCALE_HEIGHTS", "DensityProfile", "ExponentialProfile",
           "PiecewiseLinearProfile", "TabulatedProfile", "PROFILE_TYPES", "profile_from_dict"]

#: Largest altitude any profile accepts, m (well above any atmosphere top we model).
MAX_ALTITUDE_M = 1.0e7

#: Panel boundaries of an exponential profile along a ray, in scale heights (see
#: :meth:`DensityProfile.panel_altitudes`).
EXPONENTIAL_PANEL_SCALE_HEIGHTS = (1.0, 2.0, 3.0, 4.0, 6.0, 8.0)


class DensityProfile:
    """Base class. Subclasses are frozen dataclasses and implement the methods below."""

    kind: str = ""

    def density(self, altitude_m, xp=np):
        """Relative density at ``altitude_m`` (array), evaluated with namespace ``xp``."""
        raise NotImplementedError

    def max_density(self, lower_m, upper_m, xp=np):
        """An upper bound of the density over altitudes in [lower_m, upper_m] (a majorant); tight
        (equal to the maximum) for every profile here."""
        raise NotImplementedError

    def column(self, lower_m: float = 0.0, upper_m: float = math.inf) -> float:
        """Integral of the relative density over altitude from ``lower_m`` to ``upper_m``, m."""
        raise NotImplementedError

    def column_above(self, altitude_m, top_m: float, xp=np):
        """Integral of the relative density from ``altitude_m`` (array, <= ``top_m``) up to
        ``top_m``, m, evaluated with namespace ``xp`` (the vertical column a plane-parallel sun
        ray crosses)."""
        raise NotImplementedError

    def panel_altitudes(self, top_m: float) -> tuple:
        """Altitudes in (0, top_m) that a quadrature along a ray should take as panel
        boundaries: where the density is not smooth, or about every scale height where it
        falls off exponentially (see :mod:`skyref.plugins.line_integral`)."""
        raise NotImplementedError

    def to_dict(self) -> dict:
        raise NotImplementedError


@dataclass(frozen=True)
class ExponentialProfile(DensityProfile):
    """rho(h) = exp(-h / H): the isothermal barometric law with scale height H (m)."""

    scale_height_m: float
    kind = "exponential"

    def __post_init__(self):
        check_number("scale_height_m", self.scale_height_m, 0.0, MAX_ALTITUDE_M, lo_open=True)

    def density(self, altitude_m, xp=np):
        return xp.exp(-altitude_m * (1.0 / self.scale_height_m))

    def max_density(self, lower_m, upper_m, xp=np):
        # Monotonically decreasing: the maximum is at the lowest altitude.
        return self.density(lower_m, xp)

    def column(self, lower_m: float = 0.0, upper_m: float = math.inf) -> float:
        H = self.scale_height_m
        return H * (math.exp(-lower_m / H) - (0.0 if math.isinf(upper_m) else math.exp(-upper_m / H)))

    def column_above(self, altitude_m, top_m: float, xp=np):
        H = self.scale_height_m
        return H * (xp.exp(-altitude_m * (1.0 / H)) - math.exp(-top_m / H))

    def panel_altitudes(self, top_m: float) -> tuple:
        # One panel per scale height near the ground, two higher up, where a profile has fallen
        # by e^-4 and its error weighs that much less.
        levels = [self.scale_height_m * f for f in EXPONENTIAL_PANEL_SCALE_HEIGHTS]
        return tuple(h for h in levels if h < top_m)

    def to_dict(self) -> dict:
        return {"type": self.kind, "scale_height_m": self.scale_height_m}


@dataclass(frozen=True)
class PiecewiseLinearProfile(DensityProfile):
    """Linear interpolation between (altitude, density) nodes, constant beyond the end nodes.

    Written as rho(h) = rho_0 + sum_i s_i (clip(h, h_i, h_{i+1}) - h_i), with s_i the slope of
    segment i, so it evaluates branch-free in every array namespace. The ozone "tent" of Bruneton
    2017 is :meth:`tent`; tabulated profiles (e.g. a standard atmosphere) are
    :class:`TabulatedProfile`.
    """

    altitudes_m: tuple
    densities: tuple
    kind = "piecewise_linear"

    def __post_init__(self):
        h = check_array("altitudes_m", self.altitudes_m, -MAX_ALTITUDE_M, MAX_ALTITUDE_M,
                        min_length=2, increasing=True)
        d = check_array("densities", self.densities, 0.0, math.inf, min_length=2)
        if d.size != h.size:
            raise ParameterError("densities", list(self.densities), f"{h.size} numbers, one per altitude",
                                 f"{d.size} densities for {h.size} altitudes")
        object.__setattr__(self, "altitudes_m", tuple(float(x) for x in h))
        object.__setattr__(self, "densities", tuple(float(x) for x in d))

    @classmethod
    def tent(cls, bottom_m: float, peak_m: float, top_m: float, peak_density: float = 1.0):
        """Zero below ``bottom_m`` and above ``top_m``, rising linearly to ``peak_density`` at
        ``peak_m`` (Bruneton 2017's ozone layer: 10, 25, 40 km)."""
        return cls((bottom_m, peak_m, top_m), (0.0, peak_density, 0.0))

    def _segments(self):
        h = self.altitudes_m
        d = self.densities
        return [(h[i], h[i + 1], (d[i + 1] - d[i]) / (h[i + 1] - h[i])) for i in range(len(h) - 1)]

    def density(self, altitude_m, xp=np):
        rho = self.densities[0] + 0.0 * altitude_m
        for h0, h1, slope in self._segments():
            if slope != 0.0:
                rho = rho + slope * (xp.minimum(xp.maximum(altitude_m, h0), h1) - h0)
        return xp.maximum(rho, 0.0)

    def max_density(self, lower_m, upper_m, xp=np):
        # The maximum of a piecewise-linear function is at an end of the interval or at a node.
        bound = xp.maximum(self.density(lower_m, xp), self.density(upper_m, xp))
        for h, d in zip(self.altitudes_m, self.densities):
            inside = (lower_m <= h) & (upper_m >= h)
            bound = xp.maximum(bound, xp.where(inside, d, 0.0))
        return bound

    def column(self, lower_m: float = 0.0, upper_m: float = math.inf) -> float:
        h = np.asarray(self.altitudes_m)
        d = np.asarray(self.densities)
        if math.isinf(upper_m) and d[-1] > 0.0:
            return math.inf
        upper = min(upper_m, h[-1]) if math.isinf(upper_m) else upper_m
        # Exact: integrate the linear interpolant over the breakpoints inside the interval,
        # plus the constant extensions beyond the end nodes.
        nodes = np.concatenate(([lower_m, upper], h[(h > lower_m) & (h < upper)]))
        nodes = np.unique(nodes)
        values = np.interp(nodes, h, d)
        return float(np.sum(0.5 * (values[1:] + values[:-1]) * np.diff(nodes)))

    def column_above(self, altitude_m, top_m: float, xp=np):
        # Exact for the linear interpolant: each segment contributes the trapezoid from
        # clip(h, h_i, h_{i+1}) to h_{i+1}; the end nodes' constant extensions are added.
        h, d = self.altitudes_m, self.densities
        top = min(top_m, h[-1])
        total = d[-1] * xp.maximum(top_m - xp.maximum(altitude_m, h[-1]), 0.0)
        below = xp.minimum(altitude_m, h[0])
        total = total + d[0] * (h[0] - below)
        for rho0, (h0, h1, slope) in zip(d, self._segments()):
            if h0 >= top:
                break
            h1 = min(h1, top)
            start = xp.minimum(xp.maximum(altitude_m, h0), h1)
            total = total + (rho0 + 0.5 * slope * (start + h1 - 2.0 * h0)) * (h1 - start)
        return total

    def panel_altitudes(self, top_m: float) -> tuple:
        return tuple(h for h in self.altitudes_m if 0.0 < h < top_m)

    def to_dict(self) -> dict:
        return {"type": self.kind, "altitudes_m": list(self.altitudes_m),
                "densities": list(self.densities)}


@dataclass(frozen=True)
class TabulatedProfile(PiecewiseLinearProfile):
    """Measured or modelled (altitude, relative density) pairs, e.g. a standard atmosphere,
    interpolated linearly; ``source`` says where the numbers come from."""

    source: str = ""
    kind = "tabulated"

    @classmethod
    def from_csv(cls, path, source: str = ""):
        """Read a two-column CSV (altitude in m, relative density), '#' lines are comments."""
        table = np.loadtxt(path, delimiter=",", comments="#", ndmin=2)
        return cls(tuple(table[:, 0]), tuple(table[:, 1]), source or str(path))

    def to_dict(self) -> dict:
        return {**super().to_dict(), "source": self.source}


PROFILE_TYPES = {cls.kind: cls for cls in (ExponentialProfile, PiecewiseLinearProfile, TabulatedProfile)}


def profile_from_dict(data: dict) -> DensityProfile:
    """Inverse of ``DensityProfile.to_dict``."""
    fields = dict(data)
    kind = check_choice("profile.type", fields.pop("type", None), tuple(PROFILE_TYPES))
    cls = PROFILE_TYPES[kind]
    check_fields("profile", fields, cls)
    if "altitudes_m" in fields:
        fields["altitudes_m"] = tuple(fields["altitudes_m"])
        fields["densities"] = tuple(fields["densities"])
    try:
        return cls(**fields)
    except TypeError as exc:
        raise ValueError(f"profile of type {kind!r}: {exc}") from None
