"""The IPRT polarized radiative-transfer intercomparison, phase A/B (Emde et al. 2015), set up
for skyref: the cases' atmospheres, MYSTIC's results and skyref's polarized estimates of them.

Data in ``iprt_phaseA/`` (its README.md: columns, cases, attribution; IPRT, CC BY-SA 3.0). Case
set-ups from the IPRT wiki pages intercomparisons:a1_rayleigh, a2_lambert, a3_aerosol_spherical,
b1_rayleigh, b2_absorption:

- A1: one Rayleigh layer of optical thickness 0.5, black surface; depolarization 0 (sun zenith
  0, azimuth 65), 0.03 (30, 0) and 0.1 (30, 65).
- A2: a Rayleigh layer of optical thickness 0.1 over a Lambertian surface of albedo 0.3,
  depolarization 0.03, sun zenith 50.
- A3: spherical aerosol only (OPAC water-soluble, 50% relative humidity, 500 nm): optical
  thickness 0.2, phase matrix and single-scattering albedo from ``waso.mie.cdf``, black surface,
  sun zenith 40.
- B1: 30 layers of 1 km, Rayleigh optical thicknesses at 450 nm (``tau_rayleigh_450.dat``; the
  value on the row of altitude z is that of the layer from z to z + 1 km), depolarization 0.03,
  black surface, sun zenith 60; outputs at 0, 1 and 30 km.
- B2: as B1 at 325 nm with molecular absorption (``tau_molabs_325.dat``).

Not set up: B3 (spheroidal aerosol: its phase matrix, P22 != P11, is not in the data here) and
B4 (a cloud over an ocean surface with a polarizing reflection matrix; skyref's ground is
Lambertian).

Geometry: plane-parallel. Outputs at the bottom (zout 0, looking up, va < 90) and top (looking
down); MYSTIC's radiances are for a unit beam-normal solar irradiance, without the direct beam,
so skyref's orders >= 1 are divided by its solar irradiance at the case's wavelength. Azimuths
are clockwise from north in both codes, and MYSTIC's phi is the azimuth the sensor looks
towards (phi = saa looks towards the sun: brightest at va = sza in A1). Looking straight up or
down (va 0 or 180) the meridian plane is that of the row's azimuth: skyref looks VERTICAL_OFFSET_DEG
off the vertical towards it.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skyref.atmosphere import Absorber, Aerosol, Atmosphere, Rayleigh, solar_irradiance
from skyref.atmosphere.phase import read_mie_table
from skyref.atmosphere.profiles import ExponentialProfile, PiecewiseLinearProfile
from skyref.atmosphere.spectra import ConstantSpectrum
from tests.variants import RGB

DATA = Path(__file__).with_name("iprt_phaseA")

#: Columns of the result files.
COLUMNS = ("depol", "zout", "sza", "saa", "va", "phi", "I", "Q", "U", "V", "Istd", "Qstd", "Ustd", "Vstd")

#: How far off the vertical skyref looks for va = 0 or 180 (deg): the radiance changes by
#: ~1e-9 relative, and the direction defines the meridian plane.
VERTICAL_OFFSET_DEG = 1e-3

CASES = ("a1", "a2", "a3", "b1", "b2")
WAVELENGTH_NM = {"a1": 550.0, "a2": 550.0, "a3": 500.0, "b1": 450.0, "b2": 325.0}

#: Plane-parallel thickness of the one-layer cases (m; any will do) and the B atmosphere's.
LAYER_THICKNESS_M = 10_000.0
B_THICKNESS_M = 30_000.0


@dataclass(frozen=True)
class Setting:
    """One block of a result file: a case at one depolarization, output level and sun."""

    case: str
    depolarization: float
    zout_km: float
    sun_zenith_deg: float
    sun_azimuth_deg: float
    rows: np.ndarray            # the block's rows, COLUMNS

    @property
    def name(self) -> str:
        depol = f" depol {self.depolarization:g}" if self.case == "a1" else ""
        level = (("bottom" if self.zout_km == 0.0 else "top") if self.case.startswith("a")
                 else f"{self.zout_km:g} km")
        return f"{self.case.upper()}{depol} {level}"


@functools.lru_cache(maxsize=None)
def results(case: str) -> np.ndarray:
    """MYSTIC's rows for ``case`` (COLUMNS)."""
    return np.loadtxt(DATA / f"iprt_case_{case}_mystic.dat", comments="#")


def settings(case: str) -> list:
    """The case's blocks, in file order."""
    rows = results(case)
    keys = [tuple(r) for r in rows[:, :4]]
    out = []
    for key in dict.fromkeys(keys):
        block = rows[np.all(rows[:, :4] == np.asarray(key), axis=1)]
        depol = 0.03 if case in ("b2",) else float(key[0])       # B2's file lists 0; the wiki 0.03
        out.append(Setting(case, depol, float(key[1]), float(key[2]), float(key[3]), block))
    return out


def _layered(boundaries_m, depths):
    """(profile, coefficient): a piecewise-constant density (steps 1 m wide at the boundaries,
    which keep every layer's optical thickness exact) and the coefficient (m^-1 at relative
    density 1) that gives layer i the optical thickness ``depths[i]``."""
    boundaries_m = np.asarray(boundaries_m, np.float64)
    thickness = np.diff(boundaries_m)
    coefficient = float(np.max(np.asarray(depths) / thickness))
    density = np.asarray(depths) / thickness / coefficient
    altitudes, values = [], []
    for i, rho in enumerate(density):
        altitudes += [boundaries_m[i] + 0.5, boundaries_m[i + 1] - 0.5]
        values += [rho, rho]
    return PiecewiseLinearProfile(tuple(altitudes), tuple(values)), coefficient


def _layer_table(name):
    """(boundaries in m, layer optical thicknesses) from a ``tau_*.dat`` file: the value on the
    row of altitude z is the layer from z up to the next boundary."""
    table = np.loadtxt(DATA / name, comments="#")
    order = np.argsort(table[:, 0])
    z, tau = table[order, 0] * 1000.0, table[order, 1]
    return z, tau[:-1]


def atmosphere(setting: Setting) -> Atmosphere:
    """The case's atmosphere (plane-parallel thickness = top radius - bottom radius)."""
    case, bottom = setting.case, 6_360_000.0
    if case in ("a1", "a2"):
        tau = 0.5 if case == "a1" else 0.1
        profile = ExponentialProfile(8000.0)
        column = profile.column(0.0, LAYER_THICKNESS_M)
        rayleigh = Rayleigh(scattering=ConstantSpectrum(tau / column), profile=profile,
                            depolarization=setting.depolarization)
        return Atmosphere(bottom, bottom + LAYER_THICKNESS_M, (rayleigh,), ground_albedo=0.3 if case == "a2" else 0.0)
    if case == "a3":
        phase, albedo = read_mie_table(DATA / "waso.mie.cdf")
        profile = ExponentialProfile(2000.0)
        aerosol = Aerosol(profile=profile, angstrom_alpha=None, angstrom_beta=None,
                          extinction=ConstantSpectrum(0.2 / profile.column(0.0, LAYER_THICKNESS_M)),
                          single_scattering_albedo=albedo, phase=phase)
        return Atmosphere(bottom, bottom + LAYER_THICKNESS_M, (aerosol,), ground_albedo=0.0)
    wavelength = {"b1": 450, "b2": 325}[case]
    z, tau = _layer_table(f"tau_rayleigh_{wavelength}.dat")
    profile, k = _layered(z, tau)
    constituents = [Rayleigh(scattering=ConstantSpectrum(k), profile=profile, depolarization=setting.depolarization)]
    if case == "b2":
        z, tau = _layer_table("tau_molabs_325.dat")
        profile, k = _layered(z, tau)
        constituents.append(Absorber(name="absorption", profile=profile, cross_section=ConstantSpectrum(k),
                                     column_du=None, number_density_per_m3=1.0))
    return Atmosphere(bottom, bottom + B_THICKNESS_M, tuple(constituents), ground_albedo=0.0)


def observer_altitude_m(setting: Setting) -> float:
    """Where the outputs are: the A cases' zout is 0 (bottom) or 1 (top of the layer), the B
    cases' an altitude in km."""
    if setting.case.startswith("a"):
        return LAYER_THICKNESS_M if setting.zout_km > 0.0 else 0.0
    return setting.zout_km * 1000.0


def directions(rows: np.ndarray) -> np.ndarray:
    """skyref's viewing directions (east-north-up) for result rows."""
    from skyref.scene import direction_from_angles

    va = rows[:, 4]
    va = np.where(va <= 0.0, VERTICAL_OFFSET_DEG, np.where(va >= 180.0, 180.0 - VERTICAL_OFFSET_DEG, va))
    return direction_from_angles(va, rows[:, 5])


#: skyref's estimators, both polarized: the line integral (the default here: ~10x faster to a
#: given error on these cases) and delta tracking, independent of each other.
ESTIMATORS = ("line_integral", "delta_tracking")


def integrator(setting: Setting, estimator: str = "line_integral"):
    """skyref's polarized integrator for the setting (plane-parallel; Mitsuba loaded)."""
    from skyref.plugins import load_mitsuba

    load_mitsuba(RGB)
    from skyref.render import build_integrator
    from skyref.scene import Observer, Scene, Sun

    atm = atmosphere(setting)
    scene = Scene(atmosphere=atm, sun=Sun(setting.sun_zenith_deg, setting.sun_azimuth_deg),
                  observer=Observer(observer_altitude_m(setting)), wavelengths=[WAVELENGTH_NM[setting.case]])
    return build_integrator(scene, geometry="plane_parallel", polarized=True, estimator=estimator)


def _stokes(integrator_, setting, wavefront, seed, spp, batches):
    """(batches, M, 4) Stokes vectors of the diffuse light per unit irradiance."""
    image = integrator_.render_directions(wavefront, seed=seed, spp=spp, batches=batches).numpy()
    irradiance = float(np.asarray(solar_irradiance([WAVELENGTH_NM[setting.case]]))[0])
    return image.reshape(batches, len(wavefront), 4, 4)[:, :, 1:, :].sum(axis=2) / irradiance


#: Independent batches per estimate: standard errors with BATCHES - 1 degrees of freedom, whose
#: Student t tails matter when thousands of z-scores are checked (with 15, |t| > 4 has
#: probability 1.2e-3 per value: about one per thousand values however exact the estimate; with
#: 63, 1.6e-4).
BATCHES = 64
#: Samples per direction and batch of the pilot run that sizes the main one.
PILOT_SPP = 256
#: Samples per direction and batch of one repetition of a direction in the main run.
SPP = 1024
#: Safety factor on the estimated variance (repetitions = SAFETY x needed).
SAFETY = 1.5
#: Directions whose standard error after the main run exceeds TOPUP_AT x target get more.
TOPUP_AT = 0.9
#: Most repetitions of one direction (2^30 samples).
MAX_REPEATS = 1 << 14
#: Most lanes (directions x spp x batches) per call.
MAX_LANES = 1 << 24


def estimate(setting: Setting, rows: np.ndarray, target: float, seed: int = 0, estimator: str = "line_integral"):
    """skyref's Stokes vectors (I, Q, U, V per unit beam-normal irradiance, sr^-1) for ``rows``
    of ``setting``, with their standard errors from BATCHES batches: (mean (M, 4), se (M, 4),
    samples per direction). A pilot run estimates each direction's variance of I and sizes the
    main run, which repeats each direction so that I's relative standard error is about
    ``target``; directions still above it get more repetitions from the main run's own spread."""
    it = integrator(setting, estimator)
    d = directions(rows)
    pilot = _stokes(it, setting, d, seed + 1_000_003, PILOT_SPP, BATCHES)[..., 0]
    sums = np.zeros((BATCHES, len(d), 4))
    repeats = np.zeros(len(d), dtype=int)

    def trace(extra, call_seed):
        wavefront = np.repeat(np.arange(len(d)), extra)
        per_call = max(1, MAX_LANES // (SPP * BATCHES))
        for start in range(0, wavefront.size, per_call):
            chunk = wavefront[start:start + per_call]
            values = _stokes(it, setting, d[chunk], call_seed + 7919 * (start + 1), SPP, BATCHES)
            np.add.at(sums, (slice(None), chunk), values)
        repeats[:] += extra

    def needed(relative_variance):
        """Repetitions for the target (dark directions, e.g. a black ground seen from above it,
        get one)."""
        return np.clip(np.ceil(SAFETY * relative_variance / target ** 2 / (SPP * BATCHES)), 1, MAX_REPEATS).astype(int)

    def relative_variance(batch_values, samples_per_batch):
        mean = batch_values.mean(axis=0)
        lit = mean > 0.0
        return np.where(lit, batch_values.var(axis=0, ddof=1) * samples_per_batch / np.where(lit, mean, 1.0) ** 2, 0.0)

    trace(needed(relative_variance(pilot, PILOT_SPP)), seed)
    batch_means = sums / repeats[None, :, None]
    short = batch_means[..., 0].std(axis=0, ddof=1) / math.sqrt(BATCHES) > TOPUP_AT * target * batch_means[..., 0].mean(axis=0)
    if np.any(short):
        extra = np.maximum(needed(relative_variance(batch_means[..., 0], repeats * SPP)) - repeats, 1)
        trace(np.where(short, extra, 0), seed + 500_009)
        batch_means = sums / repeats[None, :, None]
    return batch_means.mean(axis=0), batch_means.std(axis=0, ddof=1) / math.sqrt(BATCHES), repeats * SPP * BATCHES


def z_scores(mean, se, rows):
    """(M, 4) z-scores of skyref against MYSTIC with their combined standard errors (0 where
    both are exactly 0, e.g. V of Rayleigh scattering)."""
    reference, reference_se = rows[:, 6:10], rows[:, 10:14]
    combined = np.sqrt(se ** 2 + reference_se ** 2)
    return np.where(combined > 0.0, (mean - reference) / np.where(combined > 0.0, combined, 1.0), 0.0)
