"""What the fitter needs to know about a model form beyond its formula: bounds that keep F
finite, the coefficients that carry F's overall scale, and a neutral starting point.

**Bounds.** The optimiser works on unbounded variables u, mapped to bounded coefficients as in
MINUIT (F. James, MINUIT Reference Manual, CERN D506, "parameter limits"; also lmfit):
p = u where a coefficient is free, p = hi + 1 - sqrt(u^2 + 1) under an upper bound only, and
p = lo + (hi - lo) (sin u + 1) / 2 between two bounds. Unlike sigmoid-like maps these reach the
bound at a finite u (where dp/du = 0), so an optimum on a bound converges instead of creeping
towards u = infinity. Bounds are imposed on the Bezier control points too; since every cooked
configuration is a convex combination of control points (see :mod:`skyref.analytic.hosek`), the
whole table then stays within them. For the Hosek–Wilkie form:

- B <= 0: exp(B / (cos theta + 0.01)) <= 1 for every view above the horizon (B > 0 reaches
  exp(100 B) at the horizon and overflows float32 from B = 0.89);
- E <= :data:`MAX_EXPONENT`: exp(E gamma) <= exp(10 pi) ~ 4e13 over gamma in [0, pi];
- |H| <= :data:`MAX_CHI_G`: chi's denominator is at least (1 - |H|)^2, so chi <= 2 / 0.05^3 = 1.6e4.

The Perez form is bounded the same way (B <= 0, D <= :data:`MAX_EXPONENT`).

**Scale.** The Hosek–Wilkie F is linear in C, D, F, G and I, so F and the overall radiance L_M
trade a common factor: the fitter fixes that freedom by keeping L_M the mean radiance of the sky
(:data:`SCALE_COEFFICIENTS`). The Perez form has no such freedom ("1 + ..." fixes its scale), so
its overall radiance is fitted.

References
----------
F. James, "MINUIT: Function Minimization and Error Analysis, Reference Manual", CERN Program Library
Long Writeup D506, 1994 (parameter limits).

L. Hosek, A. Wilkie, "An Analytic Model for Full Spectral Sky-Dome Radiance", ACM TOG 31(4), 2012.

R. Perez, R. Seals, J. Michalsky, "All-weather model for sky luminance distribution — preliminary
configuration and validation", Solar Energy 50(3), 1993.
"""

from __future__ import annotations

import numpy as np

from skyref.analytic.hosek import FORMS

__all__ = ["BOUNDS", "BOUND_MARGIN", "MAX_CHI_G", "MAX_EXPONENT", "NEUTRAL_START", "SCALE_COEFFICIENTS",
           "clip_into_bounds", "coefficient_bounds", "from_unbounded", "neutral_start", "scale_mask", "to_unbounded"]

#: Largest exponent E (Hosek–Wilkie) or D (Perez) of exp(E gamma).
MAX_EXPONENT = 10.0
#: Largest |H|, chi's g.
MAX_CHI_G = 0.95
#: Margin kept from a bound when a starting value is moved inside it (relative to the interval, or
#: absolute for a one-sided bound): on the bound dp/du = 0, and the optimiser could not move it.
BOUND_MARGIN = 1e-2

#: (lower, upper) bound of each coefficient, by form: both, or an upper bound only (None below).
BOUNDS = {
    "hosek": {"B": (None, 0.0), "E": (None, MAX_EXPONENT), "H": (-MAX_CHI_G, MAX_CHI_G)},
    "perez": {"B": (None, 0.0), "D": (None, MAX_EXPONENT)},
}
#: Coefficients in which F is linear and homogeneous, by form: scaling all of them scales F.
SCALE_COEFFICIENTS = {"hosek": ("C", "D", "F", "G", "I"), "perez": ()}
#: Starting coefficients where no table gives better ones: a clear, mid-elevation sky.
NEUTRAL_START = {
    "hosek": {"A": -1.0, "B": -0.3, "C": -1.0, "D": 2.0, "E": -2.0, "F": 0.5, "G": 0.1, "I": 1.5, "H": 0.7},
    "perez": {"A": -1.0, "B": -0.3, "C": 5.0, "D": -2.5, "E": 0.4},
}


def coefficient_bounds(form: str) -> list[tuple[float | None, float | None]]:
    """(lower, upper) per coefficient of ``form``, in storage order."""
    names = FORMS[form][0]
    return [BOUNDS[form].get(name, (None, None)) for name in names]


def scale_mask(form: str) -> np.ndarray:
    """Boolean ``(n,)``: True for the coefficients that carry F's overall scale."""
    return np.array([name in SCALE_COEFFICIENTS[form] for name in FORMS[form][0]])


def neutral_start(form: str) -> np.ndarray:
    """The neutral starting coefficients ``(n,)`` of ``form``."""
    return np.array([NEUTRAL_START[form][name] for name in FORMS[form][0]])


def clip_into_bounds(form: str, coefficients) -> np.ndarray:
    """``coefficients`` ``(..., n)`` moved inside the bounds (by :data:`BOUND_MARGIN`)."""
    p = np.array(coefficients, dtype=np.float64)
    for i, (lo, hi) in enumerate(coefficient_bounds(form)):
        span = (hi - lo) if lo is not None and hi is not None else 1.0
        if lo is not None:
            p[..., i] = np.maximum(p[..., i], lo + BOUND_MARGIN * span)
        if hi is not None:
            p[..., i] = np.minimum(p[..., i], hi - BOUND_MARGIN * span)
    return p


def to_unbounded(form: str, coefficients) -> np.ndarray:
    """Unbounded variables u ``(..., n)`` of coefficients, moved inside the bounds first (NumPy;
    an inverse of :func:`from_unbounded`)."""
    p = clip_into_bounds(form, coefficients)
    u = p.copy()
    for i, (lo, hi) in enumerate(coefficient_bounds(form)):
        if lo is not None and hi is not None:
            u[..., i] = np.arcsin(2.0 * (p[..., i] - lo) / (hi - lo) - 1.0)
        elif hi is not None:
            u[..., i] = np.sqrt((hi + 1.0 - p[..., i]) ** 2 - 1.0)
    return u


def from_unbounded(form: str, u, xp=np):
    """Coefficients ``(..., n)`` of unbounded variables u (see the module's documentation);
    ``xp`` is ``numpy`` or ``jax.numpy`` (the map is smooth, for the optimiser's Jacobians)."""
    columns = []
    for i, (lo, hi) in enumerate(coefficient_bounds(form)):
        v = u[..., i]
        if lo is not None and hi is not None:
            columns.append(lo + 0.5 * (hi - lo) * (xp.sin(v) + 1.0))
        elif hi is not None:
            columns.append(hi + 1.0 - xp.sqrt(v * v + 1.0))
        else:
            columns.append(v)
    return xp.stack(columns, axis=-1)

