"""The pieces every LUT method shares (skyref.lut.table, skyref.lut.transmittance), against
independent references:

* ``Table.lookup``: SciPy's RegularGridInterpolator on the texel-centre grid, clamp-to-edge
  outside it, and the storage rounding of float16 (at most 2^-11 relative) and float32 (2^-24).
* The transmittance table's (r, mu) <-> (u, v) parametrization round-trips.
* Transmittance values: the closed form of the vertical optical depth of exponential profiles,
  sigma H (1 - exp(-Z/H)) written here; :meth:`Atmosphere.transmittance` (Gauss-Legendre along
  the ray) for slant rays, with ozone, and for segments (``between``); the path tracer's
  ``sun_direct`` order divided by the sun's disk radiance E / Omega (z-scores); and the
  interpolation error shrinking as the table's resolution doubles. On grazing hazy rays
  (transmittance to the top below float32's range) ``between`` still matches the segment's.
"""

import math

import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

WL = [680.0, 550.0, 440.0]
R_GROUND, Z_TOP = 6_360_000.0, 60_000.0


def optics_of(mi, atmosphere):
    from skyref.lut.base import LutOptics

    return LutOptics(atmosphere, WL)


def exponential_atmosphere():
    """Rayleigh (H 8 km) + aerosol (H 1.2 km, beta 0.1, Angstrom alpha 1, albedo 0.9); no ozone."""
    from skyref.atmosphere import Aerosol, Atmosphere, CornetteShanks, ExponentialProfile, Rayleigh

    return Atmosphere(bottom_radius_m=R_GROUND, top_radius_m=R_GROUND + Z_TOP,
                      constituents=(Rayleigh(profile=ExponentialProfile(8000.0)),
                                    Aerosol(profile=ExponentialProfile(1200.0), angstrom_alpha=1.0,
                                            angstrom_beta=0.1, single_scattering_albedo=0.9,
                                            phase=CornetteShanks(0.8))),
                      ground_albedo=0.0)


def vertical_optical_depth(z0):
    """Closed form from altitude z0 to the top: sum of k H (exp(-z0/H) - exp(-Z/H)); the
    aerosol's k H = beta lambda^-alpha (its column from 0 to infinity)."""
    wl = np.asarray(WL) / 1000.0
    rayleigh = 1.24062e-6 * wl ** -4.0 * 8000.0 * (math.exp(-z0 / 8000.0) - math.exp(-Z_TOP / 8000.0))
    aerosol = 0.1 * wl ** -1.0 * (math.exp(-z0 / 1200.0) - math.exp(-Z_TOP / 1200.0))
    return rayleigh + aerosol


# --- Table --------------------------------------------------------------------------------------

@pytest.mark.parametrize("shape", [(7,), (5, 9), (4, 6, 3), (3, 5, 4, 2)])
def test_table_lookup_matches_scipy(mi, shape):
    """Multilinear lookups at random points between the first and last texel centres equal
    SciPy's linear interpolation on the grid of centres (i + 1/2) / n, for every channel."""
    from skyref.lut.table import Table, cell_centres

    rng = np.random.default_rng(len(shape))
    channels = 3
    values = rng.uniform(-1.0, 2.0, size=shape + (channels,))
    table = Table(values, shape, channels)
    stored = table.numpy()
    grids = [cell_centres(n) for n in shape]
    coords = np.stack([rng.uniform(g[0], g[-1], 200) for g in grids], axis=1)
    result = table.lookup([mi.Float64(coords[:, j]) for j in range(len(shape))])
    for k in range(channels):
        reference = RegularGridInterpolator(grids, stored[..., k])(coords)
        assert np.allclose(result[k].numpy(), reference, rtol=0, atol=1e-12)


def test_table_lookup_clamps_to_edge_and_reads_one_channel(mi):
    """Outside the texel centres (including u < 0 and u > 1) a lookup reads the clamped point;
    ``channel`` per lane reads the same values as the all-channel lookup."""
    from skyref.lut.table import Table, cell_centres

    rng = np.random.default_rng(7)
    shape = (6, 4)
    table = Table(rng.uniform(size=shape + (2,)), shape, 2)
    grids = [cell_centres(n) for n in shape]
    coords = rng.uniform(-0.3, 1.3, size=(300, 2))
    clamped = np.stack([np.clip(coords[:, j], grids[j][0], grids[j][-1]) for j in range(2)], axis=1)
    result = table.lookup([mi.Float64(coords[:, 0]), mi.Float64(coords[:, 1])])
    for k in range(2):
        reference = RegularGridInterpolator(grids, table.numpy()[..., k])(clamped)
        assert np.allclose(result[k].numpy(), reference, rtol=0, atol=1e-12)
    channel = rng.integers(0, 2, 300)
    one = table.lookup([mi.Float64(coords[:, 0]), mi.Float64(coords[:, 1])], mi.UInt32(channel))
    assert np.array_equal(one.numpy(), np.where(channel == 0, result[0].numpy(), result[1].numpy()))


@pytest.mark.parametrize("precision, bound", [("float16", 2.0 ** -11), ("float32", 2.0 ** -24)])
def test_table_storage_rounding(mi, precision, bound):
    """Stored values are the inputs rounded to the storage precision: relative error at most half
    an ulp, 2^-11 for float16 and 2^-24 for float32 (values within float16's normal range)."""
    from skyref.lut.table import Table

    rng = np.random.default_rng(3)
    # magnitudes across float16's normal range, 6.1e-5 to 65504
    values = rng.choice([-1.0, 1.0], 5000) * 10.0 ** rng.uniform(math.log10(6.2e-5), math.log10(6.0e4), 5000)
    table = Table(values, (5000,), 1, precision)
    stored = table.numpy()[:, 0]
    relative = np.abs(stored / values - 1.0)
    assert relative.max() <= bound
    assert relative.max() > bound / 4.0        # it did round (to this precision, not finer)


def test_texture_coordinate_maps_unit_range_onto_texel_centres():
    from skyref.lut.table import texture_coordinate, unit_range

    x = np.linspace(0.0, 1.0, 11)
    for n in (2, 16, 256):
        u = texture_coordinate(x, n)
        assert u[0] == pytest.approx(0.5 / n) and u[-1] == pytest.approx(1.0 - 0.5 / n)
        assert np.allclose(unit_range(u, n), x, rtol=0, atol=1e-15)


# --- transmittance table -----------------------------------------------------------------------

def test_transmittance_parametrization_round_trips(mi):
    """(u_mu, u_r) -> (r, mu) -> (u_mu, u_r) over the texel-centre range, and (r, mu) -> (u, v) ->
    (r, mu) for rays that reach the top without hitting the ground."""
    from skyref.atmosphere import preset
    from skyref.lut.transmittance import TransmittanceTable

    table = TransmittanceTable(optics_of(mi, preset("bruneton2017")), 256, 64, integration_samples=2)
    rng = np.random.default_rng(11)
    u_mu = rng.uniform(0.5 / 256, 1.0 - 0.5 / 256, 2000)
    u_r = rng.uniform(0.5 / 64, 1.0 - 0.5 / 64, 2000)
    r, mu = table.r_mu_from_uv(mi.Float64(u_mu), mi.Float64(u_r))
    back = table.uv_from_r_mu(r, mu)
    assert np.allclose(back[0].numpy(), u_mu, rtol=0, atol=1e-10)
    assert np.allclose(back[1].numpy(), u_r, rtol=0, atol=1e-10)   # rho^2 = r^2 - R^2 cancels (measured 8e-12)

    r = R_GROUND + rng.uniform(0.0, Z_TOP, 2000)
    horizon = -np.sqrt(1.0 - (R_GROUND / r) ** 2)
    mu = rng.uniform(horizon + 1e-6, 1.0)
    r2, mu2 = table.r_mu_from_uv(*table.uv_from_r_mu(mi.Float64(r), mi.Float64(mu)))
    assert np.allclose(r2.numpy(), r, rtol=1e-12)
    assert np.allclose(mu2.numpy(), mu, rtol=0, atol=1e-9)


def test_vertical_transmittance_matches_the_closed_form(mi):
    """Straight up (mu = 1 sits on the first texel centre of every row) from the altitudes of
    the rows' centres: tau = -log T against the closed form. The only difference is the bias of
    the trapezoidal rule (500 intervals of h = (Z - z0) / 500): for exp(-z/H) it is (h/H)^2 / 12
    relative, 8e-4 for the aerosol from the ground. So: within 2e-3 of the closed form, and within
    1e-6 (plus float32 storage) of the trapezoidal rule applied here to the exact densities."""
    from skyref.lut.transmittance import TransmittanceTable

    table = TransmittanceTable(optics_of(mi, exponential_atmosphere()), 256, 64)
    rho = table.horizon_distance * np.linspace(0.0, 1.0, 64)[::9]        # row centres
    r = np.sqrt(rho ** 2 + R_GROUND ** 2)
    result = np.stack([t.numpy() for t in table.to_top(mi.Float64(r), mi.Float64(np.ones_like(r)))], axis=1)
    tau_table = -np.log(result)
    z0 = r - R_GROUND
    tau = np.stack([vertical_optical_depth(z) for z in z0])
    assert np.allclose(tau_table, tau, rtol=2e-3, atol=1e-9)

    wl = np.asarray(WL) / 1000.0
    weights = np.ones(501)
    weights[[0, -1]] = 0.5
    trapezoid = []
    for z in z0:
        heights = z + np.linspace(0.0, Z_TOP - z, 501)
        h = (Z_TOP - z) / 500
        density = [weights @ np.exp(-heights / H) * h for H in (8000.0, 1200.0)]
        trapezoid.append(1.24062e-6 * wl ** -4.0 * density[0] + 0.1 * wl ** -1.0 / 1200.0 * density[1])
    assert np.allclose(tau_table, np.array(trapezoid), rtol=1e-6, atol=2e-7)


def slant_reference(atmosphere, r, mu):
    return np.stack([atmosphere.transmittance(WL, ri - R_GROUND, mi_) for ri, mi_ in zip(r, mu)])


def random_rays(rng, count):
    """Rays from 0-60 km with zenith cosines from just above the local horizon to 1."""
    r = R_GROUND + Z_TOP * rng.uniform(0.0, 1.0, count) ** 2
    horizon = -np.sqrt(1.0 - (R_GROUND / r) ** 2)
    mu = horizon + (1.0 - horizon) * rng.uniform(0.02, 1.0, count)
    return r, mu


def test_slant_transmittance_and_its_convergence_with_resolution(mi):
    """Anywhere between the texels (bruneton2017, with ozone; 300 rays from 0-60 km, zenith
    cosines from just above the horizon to 1): the table against Atmosphere.transmittance
    (Gauss-Legendre along the ray). The bilinear interpolation error is second order: its RMS
    falls by ~4.5x per doubling of both sizes (measured RMS 9.0e-4, 2.0e-4, 4.3e-5 and max 9.3e-3,
    1.9e-3, 3.7e-4 for 64 x 16, 128 x 32, 256 x 64)."""
    from skyref.atmosphere import preset
    from skyref.lut.transmittance import TransmittanceTable

    atmosphere = preset("bruneton2017")
    optics = optics_of(mi, atmosphere)
    r, mu = random_rays(np.random.default_rng(5), 300)
    reference = slant_reference(atmosphere, r, mu)
    rms, largest = [], []
    for width, height in ((64, 16), (128, 32), (256, 64)):
        table = TransmittanceTable(optics, width, height)
        error = np.stack([t.numpy() for t in table.to_top(mi.Float64(r), mi.Float64(mu))], axis=1) - reference
        rms.append(np.sqrt(np.mean(error ** 2)))
        largest.append(np.abs(error).max())
    print("RMS and max |T - T_ref| by resolution:", rms, largest)
    assert rms[1] < rms[0] / 3.0 and rms[2] < rms[1] / 3.0
    assert rms[2] < 1e-4 and largest[2] < 1e-3


def test_transmittance_between_two_points(mi):
    """T between a point and another along the ray (the ratio of two table values), for rays to
    the sky and rays that hit the ground (reversed ray), against Atmosphere.transmittance over
    that distance (from 0.1-20 km; measured RMS error 1e-4, max 1.0e-3, near the horizon where
    both table values are interpolated across its steep edge)."""
    from skyref.atmosphere import preset
    from skyref.lut import planet
    from skyref.lut.transmittance import TransmittanceTable

    atmosphere = preset("bruneton2017")
    table = TransmittanceTable(optics_of(mi, atmosphere), 256, 64)
    rng = np.random.default_rng(9)
    r = R_GROUND + rng.uniform(100.0, 20_000.0, 120)
    mu = rng.uniform(-1.0, 1.0, 120)
    r_j, mu_j = mi.Float64(r), mi.Float64(mu)
    hits = planet.intersects_ground(r_j, mu_j, R_GROUND)
    length = planet.distance_to_nearest_boundary(r_j, mu_j, R_GROUND, R_GROUND + Z_TOP, hits).numpy()
    d = length * rng.uniform(0.05, 0.95, 120)
    result = np.stack([t.numpy() for t in table.between(r_j, mu_j, mi.Float64(d), hits)], axis=1)
    reference = np.stack([atmosphere.transmittance(WL, ri - R_GROUND, m, di) for ri, m, di in zip(r, mu, d)])
    assert hits.numpy().any() and not hits.numpy().all()
    error = result - reference
    print(f"T between two points: RMS error {np.sqrt(np.mean(error ** 2)):.2e}, max {np.abs(error).max():.2e}")
    assert np.sqrt(np.mean(error ** 2)) < 2e-4 and np.abs(error).max() < 2e-3


def test_transmittance_between_points_on_grazing_hazy_rays(mi):
    """On grazing rays through thick haze (turbidity 10, 10 m - 2 km up, within 0.02 of the
    horizon's cosine, tau to the top 5-150) the transmittance to the top underflows float32, so
    a ratio of two transmittances returns 0 where the truth is 0.4-0.8 (measured: max error
    0.78). ``between`` differences optical depths instead: against Atmosphere.transmittance,
    measured RMS error 4.2e-3, max 2.7e-2 (the table's interpolation across the horizon)."""
    from skyref.atmosphere.presets import from_turbidity
    from skyref.lut import planet
    from skyref.lut.transmittance import TransmittanceTable

    atmosphere = from_turbidity(10.0)
    bottom, top = atmosphere.bottom_radius_m, atmosphere.top_radius_m
    table = TransmittanceTable(optics_of(mi, atmosphere), 256, 64)
    rng = np.random.default_rng(3)
    r = bottom + rng.uniform(10.0, 2000.0, 60)
    mu = -np.sqrt(1.0 - (bottom / r) ** 2) + rng.uniform(-0.02, 0.03, 60)
    r_j, mu_j = mi.Float64(r), mi.Float64(mu)
    hits = planet.intersects_ground(r_j, mu_j, bottom)
    length = planet.distance_to_nearest_boundary(r_j, mu_j, bottom, top, hits).numpy()
    d = np.minimum(rng.uniform(500.0, 20_000.0, 60), 0.9 * length)
    result = np.stack([t.numpy() for t in table.between(r_j, mu_j, mi.Float64(d), hits)], axis=1)
    reference = np.stack([atmosphere.transmittance(WL, ri - bottom, m, di) for ri, m, di in zip(r, mu, d)])
    to_top = np.stack([atmosphere.optical_depth(WL, ri - bottom, -m if h else m)
                       for ri, m, h in zip(r, mu, hits.numpy())])
    assert hits.numpy().any() and not hits.numpy().all() and to_top.max() > 104.0  # below float32's e^-103
    error = result - reference
    print(f"grazing hazy rays: RMS error {np.sqrt(np.mean(error ** 2)):.2e}, max {np.abs(error).max():.2e}")
    assert np.sqrt(np.mean(error ** 2)) < 1e-2 and np.abs(error).max() < 5e-2


@pytest.mark.parametrize("sun_zenith, spp", [(0.0, 20_000), (60.0, 20_000), (85.0, 100_000)])
def test_transmittance_matches_the_path_tracer(mi, sun_zenith, spp):
    """Looking at the sun from the ground: the path tracer's ``sun_direct`` divided by the disk
    radiance E / Omega (ratio tracking, independent of the table) against the table's T.
    Precision (32 seeds x 20k samples, 100k at 85 deg): rel. se < 0.25% (measured 0.05-0.09%, 0.08-0.17%
    at 85 deg) so that a 1% bias fails; |z| < 4 (measured |z| <= 2.1)."""
    from skyref.atmosphere import preset, solar_irradiance
    from skyref.lut.transmittance import TransmittanceTable
    from skyref.render import build_integrator
    from skyref.scene import Observer, RenderSettings, Scene, Sun, direction_from_angles

    atmosphere = preset("bruneton2017")
    scene = Scene(atmosphere=atmosphere, sun=Sun(sun_zenith, 180.0), observer=Observer(0.0), wavelengths=WL,
                  render=RenderSettings(max_depth=1))
    # the LUT method is the subject: the path tracer renders with the baseline estimator,
    # whose kernels compile in seconds (the line integral's in 15 s to minutes per configuration)
    integ = build_integrator(scene, estimator="delta_tracking")
    view = direction_from_angles(sun_zenith, 180.0)[None, :]
    samples = np.stack([integ.render_directions(view, seed=s, spp=spp).numpy()[0, 0] for s in range(32)])
    transmittance = samples / (solar_irradiance(WL) / integ.sun.disk.solid_angle_sr)
    estimate, se = transmittance.mean(axis=0), transmittance.std(axis=0, ddof=1) / math.sqrt(32)
    table = TransmittanceTable(optics_of(mi, atmosphere))
    mu = math.cos(math.radians(sun_zenith))
    lut = np.array([t.numpy()[0] for t in table.to_top(mi.Float64(R_GROUND), mi.Float64(mu))])
    z = (lut - estimate) / se
    print(f"sun zenith {sun_zenith}: T {lut}, path tracer {estimate}, rel. se {se / estimate}, z {z}")
    assert np.all(se / estimate < 2.5e-3)
    assert np.all(np.abs(z) < 4.0)



# Small tables: the test is about kernels, not accuracy.
SMALL_TABLES = {
    "bruneton2017": dict(scattering_orders=2, r_size=8, mu_size=16, mu_s_size=8, nu_size=4, transmittance_width=32,
                         transmittance_height=8, irradiance_width=16, irradiance_height=4, integration_samples=10),
    "elek2009": dict(scattering_size=(8, 16, 8), scattering_orders=2, gathering_samples=8,
                     aerial_perspective_size=(8, 8, 8), transmittance_size=(32, 8), integration_samples=10),
    "hillaire2020": dict(transmittance_size=(32, 8), transmittance_samples=20, multiple_scattering_size=(8, 8),
                         multiple_scattering_directions=16, multiple_scattering_samples=8, sky_view_size=(16, 12),
                         sky_view_samples=(2, 6)),
}


@pytest.mark.parametrize("name", sorted(SMALL_TABLES))
def test_new_views_reuse_the_compiled_lookup_kernels(mi, name):
    """Four views (other sun, other observer altitude) launch the same kernels, by hash: nothing
    per view is baked into a kernel, and no kernel is specialised on the alignment of its input
    arrays (Dr.Jit emits aligned vector loads when an array happens to be 64-byte aligned, and
    the lookups compiled again on about every call, ~1 s for 2048 directions)."""
    import drjit as dr

    from skyref.atmosphere import preset
    from skyref.lut import lut_method

    method = lut_method(name, preset("bruneton2017"), "rgb", **SMALL_TABLES[name])
    method.precompute()
    rng = np.random.default_rng(5)
    directions = rng.normal(size=(2048, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    hashes = []
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        for zenith, altitude in [(30.0, 0.0), (50.0, 100.0), (70.0, 1000.0), (85.0, 5.0)]:
            sun = np.array([np.sin(np.radians(zenith)), 0.0, np.cos(np.radians(zenith))])
            method.prepare_view(sun, altitude)
            dr.kernel_history()                             # clears the history
            method.radiance(directions, sun, altitude)
            hashes.append(sorted(k["hash"] for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT))
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert hashes[0], "no lookup kernel was launched"
    assert all(h == hashes[0] for h in hashes[1:]), hashes


@pytest.mark.parametrize("name", sorted(SMALL_TABLES))
def test_operations_name_the_tables_the_method_holds(mi, name):
    """The operation counts' tables are the method's tables at their sizes (the per-view ones once
    a view is prepared; Elek's aerial-perspective volume is not among its exported tables), every
    fetch names one of them, and Hillaire's per-view cells are those of its sky view."""
    from skyref.atmosphere import preset
    from skyref.lut import lut_method

    method = lut_method(name, preset("bruneton2017"), "rgb", **SMALL_TABLES[name])
    method.precompute()
    method.prepare_view(np.array([0.5, 0.0, math.sqrt(0.75)]), 0.0)
    tables = method.tables()
    operations = method.operations()
    for table, shape in operations.tables.items():
        if table == "aerial_perspective":
            continue
        held = [array.shape[:-1] for key, array in tables.items() if key == table or key.startswith(table + "(")]
        assert held == [tuple(shape)], (table, shape, {k: v.shape for k, v in tables.items()})
    for what in [*operations.sky, *operations.ground, *operations.per_view]:
        if "fetches" in what:
            assert what.split()[0] in operations.tables, what
    if name == "hillaire2020":
        sky_view = next(array for key, array in tables.items() if key.startswith("sky_view("))
        assert operations.per_view["sky_view cells"] == sky_view.shape[0] * sky_view.shape[1]
