"""Ground truth against DISORT: skyref's path tracer in plane-parallel mode vs. an independent
plane-parallel solver (nanodisort, 64 streams, Nakajima–Tanaka intensity correction; see
tests/references/disort.py, validated by tests/test_disort_reference.py).

Cases at 550 nm (monochromatic), sun zenith 30 and 70 deg:

- ``rayleigh_0.1``: Rayleigh only, vertical optical depth exactly 0.1, black ground;
- ``rayleigh_0.5``: Rayleigh only, vertical optical depth exactly 0.5, black ground;
- ``rayleigh_aerosol``: Rayleigh (bruneton2017 values, tau 0.108) + aerosol (Cornette–Shanks
  g 0.8, Angstrom alpha 0, beta 0.25, i.e. optical depth 0.25, single-scattering albedo 0.9,
  scale height 1.2 km), Lambertian ground of albedo 0.1.

and, under ``slow`` only, a layered atmosphere at 440, 550 and 680 nm and sun zenith 30, 60 and
80 deg (``layered``): bruneton2017's Rayleigh, its Cornette–Shanks aerosol (g 0.8, scale height
1.2 km) at turbidity 3 (optical depth 0.22 at 550 nm), its 300 DU ozone layer (absorbing only,
a piecewise-linear profile 10-40 km), ground albedo 0.3; the sun a 0.05 deg disk (DISORT's sun
is a point: the standard 0.27 deg disk would change the radiance by ~1e-4 at sun zenith 80).
The line-integral estimator must agree with DISORT to 0.1% there (see ``TARGET_LAYERED``).

Views: from the ground, looking up at zenith angles 0–85 deg and relative azimuths 0, 90 (-90 at
sun zenith 70) and 180 deg; with aerosol also four views 10–20 deg from the sun (the aureole) and
two views down at the ground (100, 140 deg). From the top of the atmosphere, looking down at 100 and
140 deg, relative azimuths 0, 90, 180 deg (radiance leaving the atmosphere). The sun's azimuth is
not 0 or 180 deg, so the azimuth convention is exercised.

Statistics: the sky radiance (scattering orders >= 1; DISORT never includes the direct beam) is
estimated in ``BATCHES`` independent batches (distinct seeds); its standard error is the spread of
the batch means / sqrt(BATCHES). Samples are allocated per direction (by repeating a direction in
the wavefront): a separate pilot run sizes the main run, whose own spread then tops up the
directions still short of the target. Each direction must agree within 4 standard errors, and its
relative standard error must be below the target, so a relative bias of 4 x target fails. The mean
of the z-scores over a scene's directions must also be within 4 / sqrt(directions) of 0 (catches
a bias common to all directions, well below 4 x target).

- CI: target relative standard error 0.5% (a 2% bias is >= 4 standard errors in every direction);
- ``-m slow``: 0.25% (so is a 1% bias: the issue's requirement).

Both estimators are checked: ``delta_tracking`` on every scene, ``line_integral`` on the aerosol
scenes and the thick Rayleigh layer at sun zenith 70 in CI and on every scene under ``slow``.
The line integral's 12 scenes at 0.5% took 140 s here (2 cores shared with a test run), all
passing.

Measured at commit e2434aa (llvm_ad_rgb, 2 CPU cores shared with other work), 12 scenes, 144
directions, DISORT ~20 s of the time:

- CI: 75 s; 0.05–0.70 M paths per direction (18 M in all); relative standard errors 0.25–0.44%
  (median 0.35%); |z| <= 2.54, rms z 0.95. Scaling DISORT by 1 +- 1% fails all 12 scenes (16–17
  directions, the rest through the common-bias check); by 1 +- 2%, 135 of 144 directions.
- slow: 2.8–3.2 min (5.8 min when the machine was loaded); 0.11–2.3 M paths per direction
  (59 M in all); relative standard errors 0.14–0.23% (median 0.19%); |z| <= 3.25, rms z 1.06,
  mean z -0.06. Scaling DISORT by 1 +- 1% fails 125–126 of the 144 directions and all 12 scenes;
  by 1 +- 0.5%, all 12 scenes.

Layered, 0.1% (``slow``, ``test_line_integral_matches_layered_disort_to_a_tenth_percent``), measured
at commit c7aa684 (2 cores, shared with a batch render for half the run): 18 scenes in 57 min
(56-466 s each; 736 M paths), 249 directions; relative standard errors 0.009-0.042% (median
0.03%); |z| <= 3.63 (3 directions above 3), RMS z 1.05, mean z +0.17; relative differences
RMS 0.032%, at most 0.14%; noise-corrected RMS per scene 0-0.039%.
"""

from __future__ import annotations

import functools
import math
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("nanodisort")

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # `tests.references` under plain pytest

from skyref.atmosphere import (Aerosol, Atmosphere, CornetteShanks, Rayleigh,  # noqa: E402
                               from_turbidity, solar_irradiance)
from tests.references.disort import disort_radiance  # noqa: E402
from tests.variants import RGB  # noqa: E402

WAVELENGTH_NM = 550.0

#: Independent batches (seeds) per scene; the standard error has BATCHES - 1 degrees of freedom.
#: Student's t with 63 dof exceeds 4 with probability 1.6e-4, so 144 directions give a ~2%
#: chance of one false alarm for a given set of seeds (the seeds are fixed: the test is
#: deterministic on a given back-end).
BATCHES = 64

#: Samples per direction per batch per repetition of the direction in the wavefront.
SPP = 512

#: Pilot: samples per direction (spp 1, so each is one path's value) to size the allocation.
PILOT_SAMPLES = 16384
PILOT_SEED = 1_000_003

#: Allocation safety factor on the estimated variance (samples = SAFETY x needed).
SAFETY = 1.5

#: Directions whose standard error after the main run exceeds TOPUP_AT x target get more samples.
TOPUP_AT = 0.85

#: Target relative standard error per direction (a bias of 4x this is >= 4 standard errors).
#: CI: 0.5% (2% bias); slow: 0.25% (1% bias, the issue's requirement), ~4x the path-tracing time:
#: 3 min or more on 2 cores, too long for CI (see the module docstring).
TARGET_CI = 0.005
TARGET_SLOW = 0.0025

#: The layered scenes' target relative standard error per direction, and the agreement they must
#: show: the noise-corrected RMS of the relative differences over a scene's directions at most
#: AGREEMENT_LAYERED. A common bias of 0.1% would also put the scene's mean z near 2.5, above the
#: limit 4 / sqrt(directions) (0.85-1.63 for 22-6 directions).
TARGET_LAYERED = 0.0005
AGREEMENT_LAYERED = 0.001
LAYERED_WAVELENGTHS_NM = (440.0, 550.0, 680.0)
LAYERED_SUN_ZENITHS = (30.0, 60.0, 80.0)
LAYERED_SUN_RADIUS_DEG = 0.05

#: Most wavefront lanes per render call (memory).
MAX_LANES = 1 << 21

SUN_AZIMUTH_DEG = {30.0: 135.0, 70.0: 250.0, 60.0: 40.0, 80.0: 300.0}
SUN_ZENITHS = (30.0, 70.0)
CASES = ("rayleigh_0.1", "rayleigh_0.5", "rayleigh_aerosol")
OBSERVERS = ("ground", "top")

UP_ZENITHS = (20.0, 45.0, 60.0, 75.0, 85.0)
DOWN_ZENITHS = (100.0, 140.0)


# --- the scenes ----------------------------------------------------------------------------------

def _rayleigh_with_depth(tau: float) -> Atmosphere:
    """Rayleigh only, black ground, vertical optical depth (over the slab) exactly ``tau``."""
    unit = Atmosphere(constituents=(Rayleigh(),), ground_albedo=0.0)
    scale = tau / float(unit.vertical_optical_depth([WAVELENGTH_NM])[0])
    return Atmosphere(constituents=(Rayleigh(density_scale=scale),), ground_albedo=0.0)


@functools.lru_cache(maxsize=None)
def atmosphere(case: str) -> Atmosphere:
    if case == "rayleigh_0.1":
        return _rayleigh_with_depth(0.1)
    if case == "rayleigh_0.5":
        return _rayleigh_with_depth(0.5)
    if case == "rayleigh_aerosol":
        aerosol = Aerosol(angstrom_alpha=0.0, angstrom_beta=0.25, single_scattering_albedo=0.9,
                          phase=CornetteShanks(0.8))
        return Atmosphere(constituents=(Rayleigh(), aerosol), ground_albedo=0.1)
    if case == "layered":
        return from_turbidity(3.0).replace(ground_albedo=0.3)
    raise KeyError(case)


def _azimuth_for_scattering_angle(sza: float, angle: float) -> float:
    """Relative azimuth at which a view of zenith ``sza`` is ``angle`` deg from the sun."""
    s2 = math.sin(math.radians(sza)) ** 2
    c = (math.cos(math.radians(angle)) - (1.0 - s2)) / s2
    return math.degrees(math.acos(c))


def views(case: str, sza: float, observer: str):
    """(view zenith, relative azimuth) arrays in degrees, skyref's conventions."""
    side = 90.0 if sza == 30.0 else -90.0
    if observer == "top":
        pairs = [(vz, az) for vz in DOWN_ZENITHS for az in (0.0, side, 180.0)]
    else:
        pairs = [(0.0, 0.0)] + [(vz, az) for vz in UP_ZENITHS for az in (0.0, side, 180.0)]
        if case in ("rayleigh_aerosol", "layered"):
            pairs += [(vz, 0.0) for vz in (sza - 10.0, sza + 10.0, sza - 20.0) if vz < 88.0]
            pairs += [(sza, _azimuth_for_scattering_angle(sza, 15.0))]
            pairs += [(vz, 0.0) for vz in DOWN_ZENITHS]
    vza, raz = np.array(pairs, dtype=np.float64).T
    return vza, raz


def observer_altitude(case: str, observer: str) -> float:
    return 0.0 if observer == "ground" else atmosphere(case).thickness_m


def solar_irradiance_at(wavelength_nm: float) -> float:
    return float(np.asarray(solar_irradiance([wavelength_nm]))[0])


# --- DISORT (cached: ~0.4 s per Rayleigh run, ~4 s with aerosol) ---------------------------------

@functools.lru_cache(maxsize=None)
def reference(case: str, sza: float, observer: str, wavelength_nm: float = WAVELENGTH_NM) -> np.ndarray:
    vza, raz = views(case, sza, observer)
    return disort_radiance(atmosphere(case), wavelength_nm, sza, vza, raz,
                           observer_altitude_m=observer_altitude(case, observer),
                           solar_irradiance=solar_irradiance_at(wavelength_nm), n_streams=64)


# --- the path tracer -----------------------------------------------------------------------------

def _sky(integrator, directions, seed, spp) -> np.ndarray:
    """Diffuse sky radiance (orders >= 1) along each row of ``directions``, in chunks."""
    per_call = max(1, MAX_LANES // spp)
    out = []
    for start in range(0, len(directions), per_call):
        image = integrator.render_directions(directions[start:start + per_call], seed=seed, spp=spp).numpy()
        out.append(image[:, 1:, 0].sum(axis=1))
    return np.concatenate(out)


def _batch_means(integrator, directions, repeats, seed_base) -> np.ndarray:
    """(BATCHES, M) batch means, direction i traced ``repeats[i] * SPP`` times per batch (rows
    of directions with repeats 0 come back as 0)."""
    chosen = np.nonzero(repeats > 0)[0]
    wavefront = np.repeat(directions[chosen], repeats[chosen], axis=0)
    offsets = np.concatenate(([0], np.cumsum(repeats[chosen])[:-1]))
    out = np.zeros((BATCHES, len(directions)))
    for k in range(BATCHES):
        sky = _sky(integrator, wavefront, seed_base + 7919 * (k + 1), SPP)
        out[k, chosen] = np.add.reduceat(sky, offsets) / repeats[chosen]
    return out


@functools.lru_cache(maxsize=None)
def path_traced(case: str, sza: float, observer: str, target: float, estimator: str = "delta_tracking",
                wavelength_nm: float = WAVELENGTH_NM) -> dict:
    """Mean, standard error (from BATCHES seeds), samples per direction and timing.

    Allocation: a pilot (its own seed, discarded) estimates each direction's per-path variance
    and sizes the main run; the main run's batch spread then tops up the directions whose
    standard error came out above TOPUP_AT x target (heavy-tailed paths, e.g. the forward peak,
    make the pilot underestimate), with BATCHES more batches combined batch by batch."""
    from skyref.plugins import load_mitsuba

    load_mitsuba(RGB)
    from skyref.render import build_integrator
    from skyref.scene import Observer, Scene, Sun, direction_from_angles

    saz = SUN_AZIMUTH_DEG[sza]
    sun = Sun(sza, saz, angular_radius_deg=LAYERED_SUN_RADIUS_DEG) if case == "layered" else Sun(sza, saz)
    scene = Scene(atmosphere=atmosphere(case), sun=sun,
                  observer=Observer(observer_altitude(case, observer)), wavelengths=[wavelength_nm])
    integrator = build_integrator(scene, geometry="plane_parallel", estimator=estimator)
    vza, raz = views(case, sza, observer)
    directions = direction_from_angles(vza, raz + saz)
    m = len(vza)
    start = time.perf_counter()
    per_repeat = BATCHES * SPP  # samples per direction per unit of ``repeats``

    pilot = _sky(integrator, np.repeat(directions, PILOT_SAMPLES, axis=0), PILOT_SEED, 1).reshape(m, PILOT_SAMPLES)
    rel_var = pilot.var(axis=1, ddof=1) / np.maximum(pilot.mean(axis=1), 1e-30) ** 2
    repeats = np.maximum(1, np.ceil(SAFETY * rel_var / target ** 2 / per_repeat)).astype(int)
    batches = _batch_means(integrator, directions, repeats, 0)

    def standard_error(b):
        return b.std(axis=0, ddof=1) / math.sqrt(BATCHES)

    rel_se = standard_error(batches) / np.abs(batches.mean(axis=0))
    if np.any(rel_se > TOPUP_AT * target):
        # Per-path relative variance from the main run: rel_se^2 * samples.
        needed = SAFETY * rel_se ** 2 * repeats * per_repeat / target ** 2
        extra = np.where(rel_se > TOPUP_AT * target,
                         np.maximum(1, np.ceil(needed / per_repeat) - repeats), 0).astype(int)
        more = _batch_means(integrator, directions, extra, 1_000_000)
        batches = (batches * repeats + more * extra) / (repeats + extra)
        repeats = repeats + extra
    elapsed = time.perf_counter() - start
    return {"mean": batches.mean(axis=0), "se": standard_error(batches),
            "samples": repeats * per_repeat + PILOT_SAMPLES, "seconds": elapsed}


# --- the tests -----------------------------------------------------------------------------------

def _check(case, sza, observer, target, estimator="delta_tracking", wavelength_nm=WAVELENGTH_NM):
    ref = reference(case, sza, observer, wavelength_nm)
    pt = path_traced(case, sza, observer, target, estimator, wavelength_nm)
    vza, raz = views(case, sza, observer)
    z = (pt["mean"] - ref) / pt["se"]
    rel_se = pt["se"] / ref
    table = "\n".join(f"  vza {v:6.1f} raz {a:7.2f}: disort {r:.6e} pt {p:.6e} rel {p / r - 1:+.5f} "
                      f"se {s:.5f} z {zz:+.2f}"
                      for v, a, r, p, s, zz in zip(vza, raz, ref, pt["mean"], rel_se, z))
    rel = pt["mean"] / ref - 1.0
    rms = math.sqrt(max(np.mean(rel ** 2 - rel_se ** 2), 0.0))
    message = (f"{estimator}: {case} {wavelength_nm:g} nm sza {sza} {observer} ({pt['seconds']:.1f} s, "
               f"{pt['samples'].sum():,} paths; mean z {z.mean():+.2f}, noise-corrected RMS difference "
               f"{100 * rms:.3f}%):\n{table}")
    print(message)
    assert np.all(ref > 0.0), message
    assert np.all(rel_se < target), "standard error above target\n" + message
    assert np.all(np.abs(z) < 4.0), "path tracer and DISORT disagree\n" + message
    assert abs(z.mean()) < 4.0 / math.sqrt(z.size), "common bias\n" + message
    return rms


SCENES = [(c, s, o) for c in CASES for s in SUN_ZENITHS for o in OBSERVERS]


@pytest.mark.parametrize("case,sza,observer", SCENES)
def test_path_tracer_matches_disort(case, sza, observer):
    _check(case, sza, observer, TARGET_CI)


@pytest.mark.slow
@pytest.mark.parametrize("case,sza,observer", SCENES)
def test_path_tracer_matches_disort_to_a_quarter_percent(case, sza, observer):
    _check(case, sza, observer, TARGET_SLOW)


#: The line-integral estimator's scenes in CI: the aerosol and ground case, and the optically
#: thickest Rayleigh layer at the low sun (the most multiple scattering); all 12 under ``slow``.
LINE_INTEGRAL_CI_SCENES = [scene for scene in SCENES if scene[0] == "rayleigh_aerosol"
                           or (scene[0] == "rayleigh_0.5" and scene[1] == 70.0)]


@pytest.mark.parametrize("case,sza,observer", LINE_INTEGRAL_CI_SCENES)
def test_line_integral_matches_disort(case, sza, observer):
    """The line-integral estimator against the same DISORT references, at the same tolerances."""
    _check(case, sza, observer, TARGET_CI, "line_integral")


@pytest.mark.slow
@pytest.mark.parametrize("case,sza,observer", SCENES)
def test_line_integral_matches_disort_to_a_quarter_percent(case, sza, observer):
    _check(case, sza, observer, TARGET_SLOW, "line_integral")


LAYERED_SCENES = [(wl, sza, o) for wl in LAYERED_WAVELENGTHS_NM for sza in LAYERED_SUN_ZENITHS for o in OBSERVERS]


@pytest.mark.slow
@pytest.mark.parametrize("wavelength_nm,sza,observer", LAYERED_SCENES)
def test_line_integral_matches_layered_disort_to_a_tenth_percent(wavelength_nm, sza, observer):
    """The line integral on the layered Rayleigh + aerosol + ozone atmosphere (module docstring)
    at 0.05% per direction: every direction within 4 standard errors, the scene's mean z within
    4 / sqrt(directions), and the noise-corrected RMS relative difference <= 0.1%."""
    rms = _check("layered", sza, observer, TARGET_LAYERED, "line_integral", wavelength_nm)
    assert rms <= AGREEMENT_LAYERED, f"RMS relative difference {100 * rms:.3f}% above 0.1%"
