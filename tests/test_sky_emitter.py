"""The ``skyref_sky`` emitter and the renderer frames it uses: its radiance against the sky
method it tabulates, its sampling against quadrature, its frames against Mitsuba's ``envmap`` and
Cycles' equirectangular mapping."""

import math

import numpy as np
import pytest

import skyref.atmosphere as A
from skyref.analytic.hosek import published_table
from skyref.analytic.hosek_sky import HosekWilkie2012
from skyref.fit.export import write_npz
from skyref.lut.hillaire import Hillaire2020
from skyref.renderer_frames import WORLD_FROM_ENU, latlong_directions, to_enu, to_world
from skyref.scene import direction_from_angles

WIDTH = 512
SUN = (50.0, 135.0)                     # zenith, azimuth (deg)


def y_up(enu):
    """ENU -> Mitsuba's y-up world, written out: east +x, up +y, north -z."""
    enu = np.asarray(enu, dtype=np.float64)
    return np.stack([enu[..., 0], enu[..., 2], -enu[..., 1]], axis=-1)


def node_directions(width):
    """(H, W, 3) ENU directions of the envmap nodes by the documented layout: zenith angle
    180 j / (H - 1) from row 0 at the zenith, azimuth 360 (i + 0.5) / W clockwise from north."""
    height = width // 2 + 1
    zenith = 180.0 * np.arange(height) / (height - 1)
    azimuth = 360.0 * (np.arange(width) + 0.5) / width
    return direction_from_angles(*np.meshgrid(zenith, azimuth, indexing="ij"))


def evaluate(mi, emitter, world_directions):
    """The emitter's radiance (M, 3) seen along world directions (M, 3)."""
    import drjit as dr  # here: after the mi fixture has pointed Dr.Jit at a working libLLVM

    si = dr.zeros(mi.SurfaceInteraction3f, len(world_directions))
    si.wi = mi.Vector3f(*(-np.asarray(world_directions, dtype=np.float32).T))
    return np.array(emitter.eval(si)).T


def hosek(table=None):
    model = HosekWilkie2012(A.bruneton2017(), "rgb", table=table)
    model.precompute()
    return model


@pytest.fixture(scope="module")
def sky(mi):
    return mi.load_dict({"type": "skyref_sky", "width": WIDTH, "sun_zenith": SUN[0], "sun_azimuth": SUN[1]})


def test_nodes_hold_the_model(mi, sky):
    """At the table's nodes (every 5th, horizon row included) the emitter returns the
    Hosek–Wilkie model's own radiance, in the default y-up world; rows more than one row below
    the horizon are black."""
    nodes = node_directions(WIDTH)
    upper = nodes[: WIDTH // 4 + 1].reshape(-1, 3)[::5]
    expected = hosek().radiance(upper, direction_from_angles(*SUN), 0.0)
    got = evaluate(mi, sky, y_up(upper))
    np.testing.assert_allclose(got, expected, rtol=2e-5)
    below = nodes[WIDTH // 4 + 2:].reshape(-1, 3)[::5]
    assert np.all(evaluate(mi, sky, y_up(below)) == 0.0)


def test_between_nodes_within_interpolation_error(mi, sky):
    """Random directions above 2 deg elevation: bilinear interpolation of a 0.7 deg grid
    (measured: max 0.19%, mean 0.01% at width 512; max 0.08% at 1024); within a degree of the
    horizon the model's horizon term varies faster (4% at 1024)."""
    rng = np.random.default_rng(3)
    z = rng.uniform(math.sin(math.radians(2.0)), 1.0, 20000)
    phi = rng.uniform(0.0, 2.0 * math.pi, z.size)
    enu = np.stack([np.sqrt(1 - z * z) * np.sin(phi), np.sqrt(1 - z * z) * np.cos(phi), z], axis=-1)
    expected = hosek().radiance(enu, direction_from_angles(*SUN), 0.0)
    got = evaluate(mi, sky, y_up(enu))
    relative = np.abs(got / expected - 1.0)
    assert relative.max() < 3e-3, relative.max()
    assert relative.mean() < 3e-4, relative.mean()


def test_to_world(mi):
    """With to_world = identity the world is ENU (z up); with a 90 deg turn about up the sky
    turns with it."""
    enu = node_directions(16)[1:5].reshape(-1, 3)
    expected = hosek().radiance(enu, direction_from_angles(*SUN), 0.0)
    common = {"type": "skyref_sky", "width": 16, "sun_zenith": SUN[0], "sun_azimuth": SUN[1]}
    z_up = mi.load_dict({**common, "to_world": mi.ScalarTransform4f()})
    np.testing.assert_allclose(evaluate(mi, z_up, enu), expected, rtol=2e-5)
    turned = mi.load_dict({**common, "to_world": mi.ScalarTransform4f().rotate([0, 0, 1], 90.0)})
    rotated = np.stack([-enu[:, 1], enu[:, 0], enu[:, 2]], axis=-1)      # +90 deg about z
    np.testing.assert_allclose(evaluate(mi, turned, rotated), expected, rtol=2e-5)


def test_sampling_gives_the_model_irradiance(mi, sky):
    """Irradiance on a horizontal plane: a Monte Carlo estimate with the emitter's
    sample_direction (2^21 samples) equals a midpoint quadrature of the model's radiance x cos
    theta over the sky (512 x 1024 cells), to its error bar (0.05%) plus the table's
    interpolation error (the table's own irradiance is within 7e-5 of the model's);
    pdf_direction agrees with the pdf of each sample and integrates to 1."""
    import drjit as dr  # here: after the mi fixture has pointed Dr.Jit at a working libLLVM

    n = 1 << 21
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(11, n)
    interaction = dr.zeros(mi.Interaction3f, n)
    samples, weight = sky.sample_direction(interaction, sampler.next_2d())
    d, weight, pdf = np.array(samples.d).T, np.array(weight).T, np.array(samples.pdf)
    values = weight * np.maximum(d[:, 1], 0.0)[:, None]                  # cos theta: y is up
    estimate, error = values.mean(0), values.std(0) / math.sqrt(n)

    model, sun = hosek(), direction_from_angles(*SUN)
    cells_mu, cells_phi = 512, 1024                 # within 2e-6 of 2048 x 4096 cells
    phi = (np.arange(cells_phi) + 0.5) * (2.0 * math.pi / cells_phi)
    reference = np.zeros(3)
    for mu in np.array_split((np.arange(cells_mu) + 0.5) / cells_mu, 32):
        m, p = np.meshgrid(mu, phi, indexing="ij")
        s = np.sqrt(1.0 - m * m)
        directions = np.stack([s * np.sin(p), s * np.cos(p), m], axis=-1).reshape(-1, 3)
        reference += (model.radiance(directions, sun, 0.0) * directions[:, 2:]).sum(0)
    reference *= (1.0 / cells_mu) * (2.0 * math.pi / cells_phi)
    assert np.all(error / estimate < 1e-3)
    assert np.all(np.abs(estimate - reference) < 4.0 * error + 3e-4 * reference), (estimate / reference - 1, error / estimate)

    again = np.array(sky.pdf_direction(interaction, samples))
    sampled = pdf > 0.0
    assert sampled.mean() > 0.999
    mismatch = np.abs(again[sampled] / pdf[sampled] - 1.0)
    assert np.median(mismatch) < 1e-5 and np.mean(mismatch > 1e-3) < 1e-4    # float32 at the zenith

    # the pdf over the sphere, by the midpoint rule in (cos theta, phi) of the world's y axis
    mu = (np.arange(512) + 0.5) / 256 - 1.0
    m, p = np.meshgrid(mu, (np.arange(1024) + 0.5) * (2.0 * math.pi / 1024), indexing="ij")
    s = np.sqrt(1.0 - m * m)
    world = np.stack([s * np.sin(p), m, s * np.cos(p)], axis=-1).reshape(-1, 3)
    query = dr.zeros(mi.DirectionSample3f, len(world))
    query.d = mi.Vector3f(*world.T.astype(np.float32))
    total = np.array(sky.pdf_direction(dr.zeros(mi.Interaction3f, len(world)), query)).sum() * (2.0 / 512) * (
        2.0 * math.pi / 1024)
    assert abs(total - 1.0) < 2e-3, total


def test_fitted_coefficients(mi, tmp_path):
    """A coefficient file (the published table with every overall radiance halved, written as
    ``skyref fit`` writes it) gives half the published sky: L = L_M F is linear in L_M."""
    table = published_table("spectral")
    halved = type(table)(table.form, table.kind, table.coefficients, 0.5 * table.radiances, "halved")
    path = str(tmp_path / "halved.npz")
    write_npz({"spectral": halved}, path)
    common = {"type": "skyref_sky", "width": 16, "sun_zenith": SUN[0], "sun_azimuth": SUN[1]}
    enu = node_directions(16)[1:5].reshape(-1, 3)
    published = evaluate(mi, mi.load_dict(common), y_up(enu))
    fitted = evaluate(mi, mi.load_dict({**common, "coefficients": path}), y_up(enu))
    np.testing.assert_allclose(fitted, 0.5 * published, rtol=1e-6)


def test_lut_method(mi):
    """A LUT method (Hillaire 2020) at the nodes: the method's own radiance."""
    atmosphere = A.bruneton2017()
    emitter = mi.load_dict({"type": "skyref_sky", "method": "hillaire2020", "width": 64, "sun_zenith": 70.0,
                            "sun_azimuth": 200.0, "observer_altitude": 500.0})
    method = Hillaire2020(atmosphere, "rgb")
    method.precompute()
    enu = node_directions(64)[: 64 // 4 + 1].reshape(-1, 3)
    expected = method.radiance(enu, direction_from_angles(70.0, 200.0), 500.0)
    np.testing.assert_allclose(evaluate(mi, emitter, y_up(enu)), expected, rtol=2e-5)


@pytest.mark.parametrize("properties, message", [
    ({"width": 30}, "width = 30: the horizon must be a row"),
    ({"method": "bruneton2017", "coefficients": "x.npz"}, "coefficients = 'x.npz': bruneton2017 has no"),
    ({"method": "nishita"}, "method = 'nishita': unknown choice"),
    ({"sun_zenith": 95.0}, "sun zenith angle"),
    ({"wavelengths": "rgb"}, "unreferenced property"),
])
def test_bad_properties(mi, properties, message):
    with pytest.raises(Exception, match=message):
        mi.load_dict({"type": "skyref_sky", "width": 16, **properties})


def test_spectral_variant_refused(mi):
    with mi.util.scoped_set_variant("llvm_ad_spectral"):
        with pytest.raises(Exception, match="variant = 'llvm_ad_spectral'.*RGB variant"):
            mi.load_dict({"type": "skyref_sky", "width": 16})


# --- renderer frames ----------------------------------------------------------------------------

def test_frames_are_rotations():
    for renderer, rotation in WORLD_FROM_ENU.items():
        np.testing.assert_allclose(rotation @ rotation.T, np.eye(3))
        assert np.linalg.det(rotation) == pytest.approx(1.0)       # right-handed, like ENU
        v = np.random.default_rng(0).normal(size=(5, 3))
        np.testing.assert_allclose(to_enu(to_world(v, renderer), renderer), v)
    # Mitsuba: up is +y, north is -z, east is +x
    np.testing.assert_allclose(to_world(np.eye(3), "mitsuba"), [[1, 0, 0], [0, 0, -1], [0, 1, 0]])


def test_mitsuba_latlong_is_what_envmap_shows(mi):
    """A stock envmap whose texels hold (1 + their ENU direction) / 2, looked at along those
    directions in the y-up world, returns them: the layout of latlong_directions is Mitsuba's."""
    width, height = 16, 9
    enu = latlong_directions(width, height, "mitsuba")
    envmap = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(((1.0 + enu) / 2.0).astype(np.float32))})
    rows = enu[1:-1].reshape(-1, 3)                      # the poles are single points
    np.testing.assert_allclose(evaluate(mi, envmap, to_world(rows, "mitsuba")), (1.0 + rows) / 2.0, atol=1e-5)


def test_blender_latlong_is_cycles_mapping():
    """Cycles' direction_to_equirectangular (u = 0.5 - atan2(y, x) / 2 pi, v = 1 - acos(z) / pi,
    v = 1 at the top row) sends each texel's direction to its own centre."""
    width, height = 12, 6
    d = latlong_directions(width, height, "blender")
    u = 0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2.0 * math.pi)
    v = 1.0 - np.arccos(np.clip(d[..., 2], -1.0, 1.0)) / math.pi
    np.testing.assert_allclose(np.mod(u, 1.0), np.broadcast_to((np.arange(width) + 0.5) / width, u.shape), atol=1e-12)
    np.testing.assert_allclose(v, np.broadcast_to(1.0 - (np.arange(height)[:, None] + 0.5) / height, v.shape),
                               atol=1e-12)
