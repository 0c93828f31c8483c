"""Polarized ground truth against the IPRT intercomparison (phase A/B, MYSTIC's results): I, Q,
U and V of skyref's two polarized estimators (line integral and delta tracking, plane-parallel)
against MYSTIC's, direction by direction, with their combined standard errors (tests/references/iprt.py: the cases, what is
set up and what is not, the conventions).

Per setting (case, depolarization, output level, sun): skyref's relative standard error of I
is sized to ``TARGET`` per direction (64 batches); 99% of the z-scores must be within 3 (on
the CI subset's few dozen z-scores per setting, that count may reach the 99.9th percentile of
its binomial law: 3 of 54, where "at most 1" alone was a 1% false alarm per setting, ~40% over
the 48 settings), the mean z of I within 4 / sqrt(directions) of 0 (a bias common to a setting), and every z-score
within ``max_z``. skyref's standard errors are themselves estimates (63 degrees of freedom) and
dominate the combined error (MYSTIC's is 0.01-0.04% of I), so the z-scores of exact codes follow
Student's t, whose tails are heavier than a normal's: over the 55,000 z-scores of every
direction a bound of 5 would be exceeded in one run of four (a normal's: one in 30). The bounds
are those an exact z-score exceeds with a set probability (:func:`z_bound`): 6% on the CI subset
(~900 z-scores: 4.27), 1% on every direction (5.86). A 1% bias in I is 5 standard errors on the
CI subset, 10 on every direction.

- CI: every setting at view zeniths every 30 deg and azimuths every 60 deg (264 directions),
  target 0.2%, by delta tracking, and by the line integral on the A cases (on the B cases'
  30-layer profile its samples cost ~20 us each, 20x delta tracking's at 1/25 of its variance:
  the quadrature has a panel per layer, 60 with the layers' 1 m steps; measured on B2 0 km,
  2026-12-07, where evaluating the profile by binary search instead of its sum over 60 nodes was
  slower; it runs there under ``slow``);
- ``-m slow``: every direction of the files (17,954), the line integral, target 0.1%
  (``benchmarks/iprt.py`` writes the same comparison to results/iprt.md).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import binom
from scipy.stats import t as student_t

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # `tests.references` under plain pytest

from tests.references import iprt  # noqa: E402

TARGET_CI = 0.002
TARGET_SLOW = 0.001

SETTINGS = [s for case in iprt.CASES for s in iprt.settings(case)]


def _ci_rows(rows):
    return rows[(rows[:, 4] % 30 == 0) & (rows[:, 5] % 60 == 0) & (rows[:, 5] < 360)]


#: Degrees of freedom of skyref's standard errors (its batches), and so of exact codes' z-scores.
DEGREES_OF_FREEDOM = iprt.BATCHES - 1


def _components(setting) -> int:
    """Stokes components compared per direction: V is 0 in both codes except with the Mie matrix (A3)."""
    return 4 if setting.case == "a3" else 3


def z_bound(z_scores: int, false_alarm: float) -> float:
    """The |z| that one of ``z_scores`` exact z-scores (Student's t) exceeds with probability
    ``false_alarm``."""
    return float(student_t.isf(false_alarm / (2 * z_scores), DEGREES_OF_FREEDOM))


MAX_Z_CI = z_bound(sum(len(_ci_rows(s.rows)) * _components(s) for s in SETTINGS), 0.06)
MAX_Z_EVERY_DIRECTION = z_bound(sum(len(s.rows) * _components(s) for s in SETTINGS), 0.01)


def allowed_beyond_3(compared: int) -> int:
    """How many of ``compared`` z-scores may exceed 3 in magnitude: 1% of them (the issue's
    "99% within 3"), or the 99.9th percentile of the count for exact codes (binomial, p the
    share of Student's t beyond 3), whichever is larger."""
    return max(int(0.01 * compared), int(binom.ppf(0.999, compared, 2.0 * student_t.sf(3.0, DEGREES_OF_FREEDOM))))


def _check(setting, rows, target, max_z, estimator="line_integral"):
    mean, se, _ = iprt.estimate(setting, rows, target, estimator=estimator)
    z = iprt.z_scores(mean, se, rows)
    lit = rows[:, 6] > 0.0
    table = "\n".join(f"  va {r[4]:5.1f} phi {r[5]:5.1f}: I {m[0]:.5e}/{r[6]:.5e} Q {m[1]:+.4e}/{r[7]:+.4e} "
                      f"U {m[2]:+.4e}/{r[8]:+.4e} V {m[3]:+.2e}/{r[9]:+.2e} z " + " ".join(f"{x:+.1f}" for x in zz)
                      for r, m, zz in zip(rows, mean, z))
    message = f"{estimator}, {setting.name}:\n{table}"
    assert np.all(mean[~lit] == 0.0), "light where MYSTIC has none\n" + message
    assert np.all(se[lit, 0] <= target * mean[lit, 0]), "standard error above target\n" + message
    assert np.all(np.abs(z) <= max_z), "skyref and MYSTIC disagree\n" + message
    compared = z[lit] != 0.0                     # not the components both codes have exactly 0
    assert np.sum(np.abs(z[lit]) > 3.0) <= allowed_beyond_3(np.sum(compared)), "too many |z| > 3\n" + message
    assert abs(z[lit, 0].mean()) <= 4.0 / math.sqrt(lit.sum()), "common bias in I\n" + message


@pytest.mark.parametrize("setting", [s for s in SETTINGS if s.case.startswith("a")],
                         ids=lambda s: s.name.replace(" ", "_"))
def test_iprt_subset(setting):
    _check(setting, _ci_rows(setting.rows), TARGET_CI, MAX_Z_CI)


@pytest.mark.parametrize("setting", SETTINGS, ids=lambda s: s.name.replace(" ", "_"))
def test_iprt_subset_delta_tracking(setting):
    _check(setting, _ci_rows(setting.rows), TARGET_CI, MAX_Z_CI, "delta_tracking")


@pytest.mark.slow
@pytest.mark.parametrize("setting", [s for s in SETTINGS if s.case.startswith("b")],
                         ids=lambda s: s.name.replace(" ", "_"))
def test_iprt_subset_line_integral_layered(setting):
    _check(setting, _ci_rows(setting.rows), TARGET_CI, MAX_Z_CI)


@pytest.mark.slow
@pytest.mark.parametrize("setting", SETTINGS, ids=lambda s: s.name.replace(" ", "_"))
def test_iprt_every_direction(setting):
    _check(setting, setting.rows, TARGET_SLOW, MAX_Z_EVERY_DIRECTION)
