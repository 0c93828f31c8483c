"""Randomised quasi-Monte Carlo samples for paths: Owen-scrambled Sobol points, padded per use.

Each call of :meth:`ScrambledSobolSampler.next_1d` / ``next_2d`` is one *decision* of a path
(where the forced collision falls, which direction the phase function sends it, ...). The k-th
call of every sample of one target (a pixel or a direction) is the same decision, so the
samples' values for it can be stratified against each other: they are the first one or two
dimensions of the Sobol sequence at the sample's index, shuffled and scrambled with seeds of
(target, batch, k) — Burley's "padding by shuffling". Points of different decisions are
independent of each other; the points of one decision over 2^m samples form a (0, m, 2)-net, so
the error of a smooth one- or two-dimensional integrand falls much faster than 1/sqrt(N).

Calls are counted by a per-lane counter that is loop state, so a call inside a symbolic loop is a
new decision on every iteration (Mitsuba's ``ldsampler`` reuses its dimensions across the
iterations of one symbolic loop, which correlates the bounces of a path and biased the double
scattering, see ``docs/design.md``). Batches are independent scrambles: their means are
independent, unbiased estimates, and their spread is an honest error bar.

References
----------
I. M. Sobol', "On the distribution of points in a cube and the approximate evaluation of
integrals", USSR Comput. Math. Math. Phys. 7(4) (1967).

S. Joe and F. Y. Kuo, "Constructing Sobol sequences with better two-dimensional projections",
SIAM J. Sci. Comput. 30 (2008) (the second dimension's primitive polynomial x + 1).

B. Burley, "Practical Hash-based Owen Scrambling", JCGT 9(4) (2020) (nested uniform scrambling
by a Laine–Karras-style hash, index shuffling, padding).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

__all__ = ["ScrambledSobolSampler", "hash_combine"]

#: 2^-32 as the largest float32 below 1 allows: a 32-bit integer times this is in [0, 1).
_INV_2_32 = 2.0 ** -32
_ONE_MINUS_EPSILON = 1.0 - 2.0 ** -24


#: Sobol dimensions 2-4 as (degree s, coefficients a, initial m_1..m_s) of their primitive
#: polynomials (Joe & Kuo 2008); dimension 1 is the van der Corput sequence.
_POLYNOMIALS = ((1, 0, (1,)), (2, 1, (1, 3)), (3, 1, (1, 3, 1)))


def _direction_numbers(degree, coefficients, initial):
    """Direction numbers v_1..v_32 of one Sobol dimension as 32-bit integers (bit b of the
    sample index contributes v_{b+1}), by the recurrence
    m_k = 2 a_1 m_{k-1} ^ 4 a_2 m_{k-2} ^ ... ^ 2^s m_{k-s} ^ m_{k-s}."""
    m = list(initial)
    for k in range(degree, 32):
        value = m[k - degree] ^ (m[k - degree] << degree)
        for j in range(1, degree):
            if (coefficients >> (degree - 1 - j)) & 1:
                value ^= m[k - j] << j
        m.append(value)
    return [m_k << (31 - k) for k, m_k in enumerate(m)]


_DIRECTIONS = [_direction_numbers(*polynomial) for polynomial in _POLYNOMIALS]


def _hash(x):
    """A 32-bit integer hash with good avalanche (Wellons' "lowbias32")."""
    x = x ^ (x >> 16)
    x = x * 0x7FEB352D
    x = x ^ (x >> 15)
    x = x * 0x846CA68B
    return x ^ (x >> 16)


def hash_combine(seed, value):
    """A seed derived from ``seed`` and ``value`` (UInt32 arrays or ints)."""
    return _hash(mi.UInt32(seed) ^ (_hash(mi.UInt32(value)) + 0x9E3779B9 + (mi.UInt32(seed) << 6)
                                    + (mi.UInt32(seed) >> 2)))


def _nested_uniform_scramble(x, seed):
    """Owen's nested uniform scramble of the bits of ``x`` (most significant first), by a
    Laine–Karras-style hash applied to the reversed bits (Burley 2020)."""
    x = dr.brev(x)
    x = x + seed
    x = x ^ (x * 0x6C50B47C)
    x = x ^ (x * 0xB82F1E52)
    x = x ^ (x * 0xC7AFE638)
    x = x ^ (x * 0x8D22F6E6)
    return dr.brev(x)


def _to_unit(x):
    return dr.minimum(mi.Float(x) * _INV_2_32, _ONE_MINUS_EPSILON)


class ScrambledSobolSampler:
    """Samples for ``index`` (the sample's number within its target and batch, UInt32) with the
    scrambling ``seed`` of its target and batch (UInt32); ``decision`` counts the calls so far.
    Offers what the path tracer asks of a Mitsuba sampler, ``next_1d`` and ``next_2d``, and
    ``next_3d`` (three dimensions of one decision, stratified jointly)."""

    DRJIT_STRUCT = {"index": mi.UInt32, "seed": mi.UInt32, "decision": mi.UInt32}

    def __init__(self, index=None, seed=None, decision=None):
        self.index = mi.UInt32(0) if index is None else mi.UInt32(index)
        self.seed = mi.UInt32(0) if seed is None else mi.UInt32(seed)
        self.decision = mi.UInt32(0) if decision is None else mi.UInt32(decision)

    def _shuffled_index(self):
        """The sample's index, shuffled for the current decision; returns (index, decision seed)."""
        seed = hash_combine(self.seed, self.decision)
        self.decision = self.decision + 1
        return _nested_uniform_scramble(self.index, seed), seed

    def _point(self, dimensions):
        """The current decision's point in ``dimensions`` (1-4) Sobol dimensions, scrambled."""
        index, seed = self._shuffled_index()
        values = [dr.brev(index)]
        for directions in _DIRECTIONS[:dimensions - 1]:
            value = mi.UInt32(0)
            for bit, v in enumerate(directions):
                value = value ^ dr.select((index & (1 << bit)) != 0, mi.UInt32(v), mi.UInt32(0))
            values.append(value)
        return [_to_unit(_nested_uniform_scramble(x, _hash(seed ^ (k + 1)))) for k, x in enumerate(values)]

    def next_1d(self, active=True):
        return self._point(1)[0]

    def next_2d(self, active=True):
        return mi.Point2f(*self._point(2))

    def next_3d(self, active=True):
        return mi.Point3f(*self._point(3))
