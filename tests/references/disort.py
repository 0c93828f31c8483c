"""An independent plane-parallel reference for skyref's path tracer: DISORT (via nanodisort) and a
numerical single-scattering integral.

The atmosphere is used as a PLANE-PARALLEL slab from altitude 0 to ``atmosphere.thickness_m``
(the planet's curvature is ignored), cut into homogeneous layers. Each layer's optical depth is
exact (the constituents' coefficients times the analytic column of their profile over the layer);
its single-scattering albedo is scattering / extinction and its phase function the
scattering-weighted mix of the constituents' phase functions, given to DISORT as Legendre
moments.

Conventions (skyref's, not DISORT's):

- ``view_zenith_deg``: zenith angle of the direction the observer LOOKS (0: straight up, 90: the
  horizon, > 90: down at the ground);
- ``sun_zenith_deg``: zenith angle of the direction TOWARD the sun (< 90);
- ``relative_azimuth_deg``: azimuth of the view direction minus azimuth of the sun direction
  (0: looking at the sun's side of the sky; view zenith = sun zenith with relative azimuth 0 looks
  straight at the sun);
- the cosine of the scattering angle is dot(view direction, sun direction);
- ``solar_irradiance``: top-of-atmosphere irradiance perpendicular to the beam (e.g. W m^-2 nm^-1);
  radiances come out in the same unit per sr (W m^-2 sr^-1 nm^-1), diffuse only (the direct solar
  beam is never included).

Mapping onto DISORT: DISORT's ``umu`` is the cosine of the polar angle of the direction in which
the radiance *propagates* (measured from +z, up), so a view direction of zenith angle vza is
``umu = -cos(vza)``; the beam propagates along (-umu0, phi0) with ``umu0 = cos(sza)``, and
DISORT's cosine of the scattering angle is ``-umu0 umu + sin sin cos(phi - phi0)``, so with
``phi0 = 0`` the DISORT azimuth ``phi`` is skyref's relative azimuth (both directions are
reversed, which leaves their azimuth difference unchanged). :func:`single_scattering_radiance`
checks this mapping independently (tests/test_disort_reference.py).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from skyref.atmosphere.phase import PhaseFunction, RayleighPhase

#: Legendre moments of the Rayleigh phase function (exact).
RAYLEIGH_MOMENTS = (1.0, 0.0, 0.1)

#: Default number of layers of the slab (see :func:`layer_altitudes`; a few more are added at
#: profile nodes and around the observer). Measured on the presets (400-800 nm, sun 30-85 deg,
#: observer 0-15 km): radiance within 7e-5 of a 400-layer run for views more than 2 deg from the
#: horizon; within 1-2 deg of it, from an observer above the ground, up to 2e-3 (the plane-parallel
#: horizon ray runs through the layers next to the observer for a long way).
DEFAULT_N_LAYERS = 100

#: Moments below this are dropped when the number of moments is chosen automatically.
MOMENT_TOLERANCE = 1.0e-9

#: At least this many moments for a peaked (non-Rayleigh) phase function (NT correction).
MIN_PEAKED_MOMENTS = 400

#: Most moments chosen automatically.
MAX_MOMENTS = 2048

#: Largest single-scattering albedo given to DISORT. cdisort replaces ssa = 1 by 1 - 100 eps
#: (2e-14), too close to 1 in double precision: the conservative eigenvalue's square can round to
#: a negative number and the whole solution comes back NaN (e.g. 640 layers, 400 nm, 16 or 32
#: streams). 1 - 1e-8 changes radiances by ~1e-8 x the number of scatterings.
MAX_SSA = 1.0 - 1.0e-8

#: Smallest optical depth of a layer next to an output level (see _solve): cdisort drops the part
#: of the path to the next boundary when it is < 1e-6 (absolute), after delta-M scaling.
MIN_ADJACENT_DTAU = 1.0e-5

#: DISORT's azimuthal-series convergence criterion (0: all nstr components).
ACCUR = 0.0

#: |umu| is kept at least this large (DISORT rejects umu = 0): a view at the horizon gets the
#: limit from the side of the direction given (vza <= 90: the sky side).
MIN_ABS_UMU = 1.0e-6


# --- phase functions ------------------------------------------------------------------------

def legendre_moments(phase, n_moments: int, n_nodes: int | None = None,
                     normalise: bool = True) -> np.ndarray:
    """Legendre moments chi_0..chi_n of a phase function normalised over the sphere (sr^-1):
    chi_l = 2 pi * integral p(mu) P_l(mu) dmu, renormalised so that chi_0 = 1 (DISORT's
    ``pmom`` convention: P(mu) = sum (2l+1) chi_l P_l(mu) with P = 4 pi p; Henyey–Greenstein
    gives chi_l = g^l, Rayleigh 1, 0, 0.1).

    ``phase`` is a :class:`skyref.atmosphere.phase.PhaseFunction` (its ``evaluate(mu)`` is used;
    the Rayleigh one gets its exact moments) or a callable p(mu). Numerical: Gauss–Legendre
    quadrature with ``n_nodes`` nodes (default max(4096, 2 n_moments + 2)), exact for
    polynomials of degree 2 n_nodes - 1 and converging geometrically for Cornette–Shanks and
    Henyey–Greenstein (their nearest singularity is at mu = (1 + g^2) / (2 g) > 1): |error| ~ 1e-11
    (round-off) for g <= 0.9. ``normalise=False`` returns the raw integrals (chi_0 then measures
    the phase function's normalisation)."""
    if n_nodes is None:
        n_nodes = max(4096, 2 * int(n_moments) + 2)
    chi = _legendre_moments(phase, int(n_moments), int(n_nodes))
    return chi / chi[0] if normalise else chi.copy()


@functools.lru_cache(maxsize=8)
def _gauss_legendre(n: int):
    from scipy.special import roots_legendre

    return roots_legendre(n)


@functools.lru_cache(maxsize=128)
def _legendre_moments(phase, n_moments: int, n_nodes: int) -> np.ndarray:
    out = np.zeros(n_moments + 1)
    if isinstance(phase, RayleighPhase):
        k = min(len(RAYLEIGH_MOMENTS), n_moments + 1)
        out[:k] = RAYLEIGH_MOMENTS[:k]
        out[2:k] *= phase.dipole_share           # the depolarized part is isotropic
        return out
    mu, w = _gauss_legendre(n_nodes)
    evaluate = phase.evaluate if isinstance(phase, PhaseFunction) else phase
    wp = w * np.asarray(evaluate(mu), dtype=np.float64)
    p_prev, p_cur = np.zeros_like(mu), np.ones_like(mu)
    out[0] = wp.sum()
    for l in range(1, n_moments + 1):
        p_prev, p_cur = p_cur, ((2 * l - 1) * mu * p_cur - (l - 1) * p_prev) / l
        out[l] = wp @ p_cur
    return 2.0 * math.pi * out


def _scatterers(atmosphere):
    return [c for c in atmosphere.constituents if c.phase is not None]


def default_n_moments(atmosphere, n_streams: int = 64) -> int:
    """Moments given to DISORT by default: at least ``n_streams``; for a peaked phase function at
    least 400 and enough that every dropped moment is below 1e-9 (at most 2048)."""
    n = n_streams
    for c in _scatterers(atmosphere):
        if isinstance(c.phase, RayleighPhase):
            continue
        for trial in (512, MAX_MOMENTS):
            chi = np.abs(legendre_moments(c.phase, trial))
            above = np.nonzero(chi > MOMENT_TOLERANCE)[0]
            if above[-1] < trial - 16:
                break
        n = max(n, MIN_PEAKED_MOMENTS, int(above[-1]) + 1)
    return min(n, MAX_MOMENTS)


# --- the slab -------------------------------------------------------------------------------

def _profile_nodes(profile):
    return tuple(getattr(profile, "altitudes_m", ()))


def layer_altitudes(atmosphere, n_layers: int = DEFAULT_N_LAYERS, extra_altitudes_m=(), refine_m=(),
                    n_refine: int = 5) -> np.ndarray:
    """Layer boundaries (m, increasing from 0 to the top) of the slab.

    Uniform in s(h) = h / Z + sum_i C_i(0, h) / C_i(0, Z), with C_i the column of constituent i's
    profile (Z the thickness): every layer holds at most (K + 1) / n_layers of every constituent's
    column (K constituents with a column) and of the thickness, so thin, dense constituents
    (aerosol near the ground) and thin but tall ones are both resolved. The nodes of piecewise-
    linear profiles and ``extra_altitudes_m`` (e.g. the observer) are added as boundaries, and
    around each altitude in ``refine_m`` ``n_refine`` boundaries on each side at 1/2, 1/4, ... of
    a layer's s-step (near-horizontal radiance there depends on the adjacent layers).
    """
    Z = float(atmosphere.thickness_m)
    forced = {0.0, Z}
    for c in atmosphere.constituents:
        forced.update(h for h in _profile_nodes(c.profile) if 0.0 < h < Z)
    for h in np.atleast_1d(np.asarray(extra_altitudes_m, dtype=np.float64)):
        if not 0.0 <= h <= Z:
            raise ValueError(f"altitude {h} m is outside the slab [0, {Z}] m")
        forced.add(float(h))
    fine = np.union1d(np.linspace(0.0, Z, 20001), np.fromiter(forced, float))
    s = fine / Z
    for c in atmosphere.constituents:
        # The cumulative column by the trapezoid rule on the fine grid is plenty to place
        # boundaries (the layers' optical depths are then computed exactly).
        rho = np.asarray(c.profile.density(fine), dtype=np.float64)
        column = np.concatenate(([0.0], np.cumsum(0.5 * (rho[1:] + rho[:-1]) * np.diff(fine))))
        if column[-1] > 0.0:
            s = s + column / column[-1]
    s = np.maximum.accumulate(s)
    targets = np.linspace(0.0, s[-1], int(n_layers) + 1)
    # Geometric refinement around each altitude in ``refine_m``.
    step = s[-1] / int(n_layers)
    for h in np.atleast_1d(np.asarray(refine_m, dtype=np.float64)):
        s_h = np.interp(h, fine, s)
        ds = step * 0.5 ** np.arange(1, n_refine + 1)
        targets = np.concatenate((targets, np.clip(np.concatenate((s_h - ds, s_h + ds)), 0.0, s[-1])))
    edges = np.interp(targets, s, fine)
    edges = np.union1d(edges, np.fromiter(forced, float))
    # Drop boundaries closer than 1 mm to a neighbour (keep forced ones).
    keep = [edges[0]]
    for h in edges[1:]:
        if h - keep[-1] < 1.0e-3:
            if h in forced and keep[-1] not in forced:
                keep[-1] = h
            continue
        keep.append(h)
    keep[-1] = Z
    return np.asarray(keep)


def layer_optics(atmosphere, wavelength_nm: float, altitudes_m, n_moments: int):
    """Optical properties of the layers between ``altitudes_m`` (increasing), listed from the TOP
    layer down (DISORT's order): (dtau [nlyr], ssa [nlyr], pmom [n_moments + 1, nlyr])."""
    wl = np.atleast_1d(np.asarray(wavelength_nm, dtype=np.float64))
    if wl.size != 1:
        raise ValueError("one wavelength at a time")
    h = np.asarray(altitudes_m, dtype=np.float64)[::-1]  # top first
    n_layers = h.size - 1
    tau_ext = np.zeros(n_layers)
    tau_sca = np.zeros(n_layers)
    pmom = np.zeros((n_moments + 1, n_layers))
    for c in atmosphere.constituents:
        column = np.array([c.profile.column(h[i + 1], h[i]) for i in range(n_layers)])
        tau_ext += float(c.extinction_coefficient(wl)[0]) * column
        if c.phase is None:
            continue
        sca = float(c.scattering_coefficient(wl)[0]) * column
        if np.any(sca > 0.0):
            tau_sca += sca
            pmom += legendre_moments(c.phase, n_moments)[:, None] * sca[None, :]
    scattering = tau_sca > 0.0
    pmom[:, scattering] /= tau_sca[scattering]
    pmom[:, ~scattering] = 0.0
    pmom[0, :] = 1.0
    ssa = np.divide(tau_sca, tau_ext, out=np.zeros(n_layers), where=tau_ext > 0.0)
    return tau_ext, np.clip(ssa, 0.0, MAX_SSA), np.clip(pmom, -1.0, 1.0)


# --- DISORT -----------------------------------------------------------------------------------

def _computational_cosines(nstr: int) -> np.ndarray:
    x, _ = np.polynomial.legendre.leggauss(nstr // 2)
    return 0.5 * (x + 1.0)


def _solve(atmosphere, wavelength_nm, sun_zenith_deg, altitudes_out_m, umu=None, phi=None,
           solar_irradiance=1.0, n_layers=DEFAULT_N_LAYERS, n_streams=64, n_moments=None,
           albedo=None):
    """Run DISORT; returns the solved nanodisort.DisortState (fluxes; radiances if umu given)."""
    import nanodisort as nd

    if not 0.0 <= sun_zenith_deg < 90.0:
        raise ValueError(f"sun_zenith_deg must be in [0, 90) (plane-parallel, sun above the horizon); "
                         f"got {sun_zenith_deg}")
    if n_streams % 2 or n_streams < 4:
        raise ValueError("n_streams must be even and >= 4")
    levels = np.atleast_1d(np.asarray(altitudes_out_m, dtype=np.float64))
    edges = layer_altitudes(atmosphere, n_layers, levels, refine_m=levels)
    if n_moments is None:
        n_moments = default_n_moments(atmosphere, n_streams)
    n_moments = max(int(n_moments), n_streams)
    dtau, ssa, pmom = layer_optics(atmosphere, wavelength_nm, edges, n_moments)
    tau_top = np.concatenate(([0.0], np.cumsum(dtau)))[::-1]  # at edges (increasing altitude)
    # cdisort (c_user_intensities) skips the stretch from an output level to the next layer
    # boundary when it is thinner than 1e-6 in optical depth: with a thin layer next to the
    # level, that whole layer's contribution is lost. Keep the layers next to each output level
    # at least MIN_ADJACENT_DTAU thick (or as thick as everything on that side).
    tau_levels = np.interp(levels, edges, tau_top)
    near = np.zeros(edges.size, dtype=bool)
    for t in tau_levels:
        near |= np.abs(tau_top - t) < MIN_ADJACENT_DTAU
    near &= ~np.isin(edges, levels)
    near[[0, -1]] = False
    if np.any(near):
        edges = edges[~near]
        dtau, ssa, pmom = layer_optics(atmosphere, wavelength_nm, edges, n_moments)
        tau_top = np.concatenate(([0.0], np.cumsum(dtau)))[::-1]
    utau = np.minimum(np.interp(levels, edges, tau_top), tau_top[0])
    if albedo is None:
        albedo = float(np.atleast_1d(atmosphere.ground_albedo(np.atleast_1d(float(wavelength_nm))))[0])

    radiances = umu is not None
    umu0 = math.cos(math.radians(sun_zenith_deg))
    # DISORT stops (and prints to stderr) when the beam is within 1e-4 (relative) of one of its
    # computational angles, the double-Gauss nodes on (0, 1): use two more streams then.
    nstr = n_streams
    while np.min(np.abs(_computational_cosines(nstr) - umu0)) < 2.0e-4 * umu0:
        nstr += 2
    for nstr in (nstr, nstr + 2):
        ds = nd.DisortState()
        ds.nstr = nstr
        ds.nlyr = dtau.size
        ds.nmom = max(n_moments, nstr)
        ds.ntau = utau.size
        ds.numu = len(umu) if radiances else 0
        ds.nphi = len(phi) if radiances else 0
        ds.nphase = 0
        ds.usrtau = True
        ds.usrang = radiances
        ds.onlyfl = not radiances
        ds.lamber = True
        ds.planck = False
        ds.quiet = True
        ds.spher = False
        ds.intensity_correction = True       # Nakajima–Tanaka TMS + IMS ...
        ds.old_intensity_correction = True   # ... with the phase moments (not Buras–Emde)
        ds.allocate()
        ds.dtauc = np.ascontiguousarray(dtau)
        ds.ssalb = np.ascontiguousarray(ssa)
        full = np.zeros((ds.nmom + 1, dtau.size))
        full[: min(pmom.shape[0], ds.nmom + 1)] = pmom[: ds.nmom + 1]
        ds.pmom = np.asfortranarray(full)
        ds.utau = np.ascontiguousarray(utau)
        if radiances:
            ds.umu = np.ascontiguousarray(umu, dtype=np.float64)
            ds.phi = np.ascontiguousarray(phi, dtype=np.float64)
        ds.fbeam = float(solar_irradiance)
        ds.umu0 = umu0
        ds.phi0 = 0.0
        ds.fisot = 0.0
        ds.albedo = float(albedo)
        ds.accur = ACCUR
        try:
            ds.solve()
        except RuntimeError as exc:
            if "computational angle" in str(exc):
                continue
            raise
        if not (np.all(np.isfinite(ds.rfldn)) and np.all(np.isfinite(ds.flup))
                and (not radiances or np.all(np.isfinite(ds.uu)))):
            raise RuntimeError("DISORT returned NaN (try another n_layers or n_streams)")
        return ds
    raise RuntimeError("DISORT: beam angle coincides with a computational angle for every nstr tried")


def disort_radiance(atmosphere, wavelength_nm, sun_zenith_deg, view_zenith_deg, relative_azimuth_deg,
                    observer_altitude_m=0.0, solar_irradiance=1.0, n_layers=DEFAULT_N_LAYERS,
                    n_streams=64, n_moments=None) -> np.ndarray:
    """Diffuse radiance (no direct sun) seen by an observer at ``observer_altitude_m`` in the
    plane-parallel version of ``atmosphere`` at one wavelength (nm), over a Lambertian ground of
    albedo ``atmosphere.ground_albedo(wavelength)``; units of ``solar_irradiance`` per sr.

    ``view_zenith_deg`` and ``relative_azimuth_deg`` broadcast against each other (skyref's
    conventions, see the module docstring); one DISORT run serves them all (on the grid of their
    distinct cosines x distinct azimuths folded into [0, 180]). ``n_moments`` None:
    :func:`default_n_moments`. Nakajima–Tanaka intensity correction (TMS + IMS) is on.
    A view exactly at the horizon (vza = 90) gets the limit from the sky side (umu = -1e-6).
    Cost: ~4 s for 64 streams, 100 layers (2 CPU cores), ~1 s with 32 streams, which agree with
    128 streams to ~2e-5 (64: ~1e-6).
    """
    vza, raz = np.broadcast_arrays(np.asarray(view_zenith_deg, dtype=np.float64),
                                   np.asarray(relative_azimuth_deg, dtype=np.float64))
    if np.any((vza < 0.0) | (vza > 180.0)):
        raise ValueError("view_zenith_deg must be in [0, 180]")
    umu = -np.cos(np.radians(vza))
    umu = np.where(np.abs(umu) < MIN_ABS_UMU, np.where(vza > 90.0, MIN_ABS_UMU, -MIN_ABS_UMU), umu)
    # The plane-parallel field is symmetric about the principal plane: fold azimuths into [0, 180].
    phi = np.abs(np.mod(raz + 180.0, 360.0) - 180.0)
    umu_u, umu_i = np.unique(umu, return_inverse=True)
    phi_u, phi_i = np.unique(phi, return_inverse=True)
    ds = _solve(atmosphere, wavelength_nm, sun_zenith_deg, [observer_altitude_m], umu_u, phi_u,
                solar_irradiance, n_layers, n_streams, n_moments)
    uu = np.asarray(ds.uu)[:, 0, :]  # (numu, nphi)
    return uu[umu_i.reshape(vza.shape), phi_i.reshape(vza.shape)]


def disort_fluxes(atmosphere, wavelength_nm, sun_zenith_deg, altitudes_m, solar_irradiance=1.0,
                  n_layers=DEFAULT_N_LAYERS, n_streams=64, n_moments=None, albedo=None) -> dict:
    """Irradiances (units of ``solar_irradiance``, per unit horizontal area) at ``altitudes_m``:
    ``direct_down``, ``diffuse_down``, ``diffuse_up`` (DISORT's rfldir, rfldn, flup)."""
    ds = _solve(atmosphere, wavelength_nm, sun_zenith_deg, altitudes_m, None, None,
                solar_irradiance, n_layers, n_streams, n_moments, albedo)
    return {"direct_down": np.array(ds.rfldir), "diffuse_down": np.array(ds.rfldn),
            "diffuse_up": np.array(ds.flup)}


# --- single scattering ------------------------------------------------------------------------

def single_scattering_radiance(atmosphere, wavelength_nm, sun_zenith_deg, view_zenith_deg,
                               relative_azimuth_deg, observer_altitude_m=0.0, solar_irradiance=1.0,
                               n_panels=400, n_gauss=8) -> np.ndarray:
    """Singly scattered radiance in the plane-parallel slab, no ground (same conventions and units
    as :func:`disort_radiance`; view zenith angles 90 excluded):

        L = F0 / |mu_v| * integral sigma_s(z) p(cos Theta) exp(-tau(z) / mu0)
                                  exp(-|tau(z) - tau(z_obs)| / |mu_v|) dz

    over z from the observer to the top (looking up) or to the ground (looking down), tau(z) the
    exact vertical optical depth from z to the top, sigma_s p the sum over constituents, and
    cos Theta = dot(view direction, sun direction). Composite Gauss–Legendre quadrature
    (``n_gauss`` nodes on panels from :func:`layer_altitudes` refined geometrically near the
    observer)."""
    vza, raz = np.broadcast_arrays(np.asarray(view_zenith_deg, dtype=np.float64),
                                   np.asarray(relative_azimuth_deg, dtype=np.float64))
    wl = np.atleast_1d(float(wavelength_nm))
    Z = float(atmosphere.thickness_m)
    z_obs = float(observer_altitude_m)
    mu0 = math.cos(math.radians(sun_zenith_deg))
    if mu0 <= 0.0:
        raise ValueError("sun below the horizon")
    mu_v = np.cos(np.radians(vza))
    cos_theta = (mu0 * mu_v + math.sin(math.radians(sun_zenith_deg)) * np.sin(np.radians(vza))
                 * np.cos(np.radians(raz)))
    edges = layer_altitudes(atmosphere, n_panels, [z_obs])
    d = np.geomspace(1.0e-3, Z, 60)
    edges = np.union1d(edges, np.clip(np.concatenate((z_obs - d, z_obs + d)), 0.0, Z))
    x, w = np.polynomial.legendre.leggauss(n_gauss)

    def tau_to_top(z):
        return sum(float(c.extinction_coefficient(wl)[0]) * c.profile.column(z, Z)
                   for c in atmosphere.constituents)

    tau_obs = tau_to_top(z_obs)
    out = np.zeros(vza.shape)
    for up in (True, False):
        sel = (mu_v > 0.0) if up else (mu_v < 0.0)
        if not np.any(sel):
            continue
        e = edges[edges >= z_obs] if up else edges[edges <= z_obs]
        if e.size < 2:
            continue
        a, b = e[:-1, None], e[1:, None]
        z = (0.5 * (b - a) * x + 0.5 * (a + b)).ravel()
        wz = (0.5 * (b - a) * w).ravel()
        tau = np.array([tau_to_top(zz) for zz in z])
        amv = np.abs(mu_v[sel])[:, None]
        attenuation = np.exp(-tau[None, :] / mu0 - np.abs(tau[None, :] - tau_obs) / amv) / amv
        source = np.zeros((amv.shape[0], z.size))
        ct = cos_theta[sel]
        for c in _scatterers(atmosphere):
            sigma = float(c.scattering_coefficient(wl)[0]) * np.asarray(c.profile.density(z))
            source += np.asarray(c.phase.evaluate(ct))[:, None] * sigma[None, :]
        out[sel] = (source * attenuation) @ wz
    return solar_irradiance * out
