"""``skyref export-lut`` (skyref.lut.export): the exported tables, read back with OpenEXR and
looked up by an engine-side NumPy implementation written here from the papers' parametrizations
(Bruneton 2017's transmittance, 4-D scattering and irradiance textures and its GetSkyRadiance /
GetSkyRadianceToPoint / GetSunAndSkyIrradiance; Hillaire 2020's transmittance, multiple-
scattering and sky-view tables), reproduce the methods' own radiance and transmittance in a few
hundred directions, with GPU texture semantics (texel centres, bilinear, clamp to edge) and the
JSON's constants only.

The files hold exactly the values the methods interpolate (float32 tables as FLOAT pixels,
float16 ones as HALF), so the reproduction is tight for both precisions. Measured: transmittance
to 1e-15 relative; radiance median 5e-10, at most 2.2e-6 relative a few degrees from the sun,
where the methods evaluate the aerosol phase function partly in float32 (its g is a float32
parameter: -2.4e-6 .. -3.1e-6 for nu = 0.99 .. 0.998, the 1 + g^2 - 2 g nu cancellation); asserted
at 1e-5 and 1e-9. float16 storage itself moves the radiance by < 2e-3 (Hillaire 2020, against
the float32 tables).
"""

import itertools
import json
import math
import os

import numpy as np
import pytest

WL = [680.0, 550.0, 440.0]
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "scenes", "earth-clear.toml")
BRUNETON_OPTIONS = dict(r_size=8, mu_size=32, mu_s_size=8, nu_size=4, scattering_orders=2)
HILLAIRE_OPTIONS = dict(sky_view_samples=(8, 8))
#: Relative agreement of the NumPy lookups from the files with the methods' own: radiance (the
#: methods' float32 aerosol phase function), transmittance (float64 round-off).
RADIANCE_RTOL, TRANSMITTANCE_RTOL = 1e-5, 1e-9


def directions(count=300, seed=7):
    """Fixed random unit directions, uniform on the sphere (none exactly on the horizon)."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(-1.0, 1.0, count)
    phi = rng.uniform(0.0, 2.0 * math.pi, count)
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def sun_towards(zenith_deg, azimuth_deg=135.0):
    from skyref.scene import direction_from_angles

    return direction_from_angles(zenith_deg, azimuth_deg)


def assert_close(got, want, rtol=RADIANCE_RTOL):
    scale = np.abs(want).max()
    assert np.all(np.isfinite(got))
    assert np.all(np.abs(got - want) <= rtol * np.abs(want) + 1e-9 * scale), np.abs(got - want).max() / scale


# --- reading the files back -------------------------------------------------------------------------

def read_export(directory, name):
    """(JSON, {table: float64 array (..., C) in texel order}) of an export, checking the pixel types."""
    import OpenEXR

    with open(os.path.join(directory, f"{name}.json")) as f:
        meta = json.load(f)
    textures = {}
    for table, entry in meta["tables"].items():
        with OpenEXR.File(os.path.join(directory, entry["file"]), separate_channels=True) as exr:
            channels = exr.channels()
            assert sorted(channels) == sorted(entry["channels"])
            pixels = np.stack([channels[c].pixels for c in entry["channels"]], axis=-1)
        assert pixels.dtype == (np.float16 if entry["pixel_type"] == "float16" else np.float32)
        shape = (entry.get("depth", 1), entry["height"], entry["width"], len(entry["channels"]))
        textures[table] = pixels.reshape(shape if "depth" in entry else shape[1:]).astype(np.float64)
    return meta, textures


def texel(x, n):
    """A unit-range x on the texel centres of an axis of n texels."""
    return 0.5 / n + x * (1.0 - 1.0 / n)


def sample(texture, *coords):
    """A GPU texture(): ``texture`` (..., z, y, x, C), coordinates (u_x, u_y[, u_z]) in [0, 1]
    (arrays of one shape); multilinear between texel centres, clamp to edge. Returns (M, C)."""
    sizes = texture.shape[-2::-1][:len(coords)]
    lower, weights = [], []
    for u, n in zip(coords, sizes):
        t = np.clip(np.asarray(u, dtype=np.float64) * n - 0.5, 0.0, n - 1.0)
        i = np.minimum(np.floor(t).astype(int), max(n - 2, 0))
        lower.append(i)
        weights.append(t - i)
    total = 0.0
    for corner in itertools.product((0, 1), repeat=len(coords)):
        weight = np.prod([w if c else 1.0 - w for w, c in zip(weights, corner)], axis=0)
        index = tuple(np.minimum(i + c, n - 1) for i, c, n in zip(lower, corner, sizes))[::-1]
        total = total + weight[:, None] * texture[index]
    return total


def phase(meta, nu):
    """(Rayleigh, aerosol) phase functions, sr^-1, from the JSON (Cornette–Shanks or Henyey–Greenstein)."""
    rayleigh = 3.0 / (16.0 * math.pi) * (1.0 + nu * nu)
    mie = meta["phase_functions"]["mie"]
    g = mie["g"]
    denominator = (1.0 + g * g - 2.0 * g * nu) ** 1.5
    if mie["type"] == "cornette_shanks":
        return rayleigh, 3.0 / (8.0 * math.pi) * (1 - g * g) / (2 + g * g) * (1 + nu * nu) / denominator
    assert mie["type"] == "henyey_greenstein"
    return rayleigh, (1 - g * g) / (4.0 * math.pi * denominator)


class Planet:
    """Ray geometry from the JSON's radii (Bruneton 2017, section 2.1)."""

    def __init__(self, meta):
        self.R, self.Rt = meta["bottom_radius_m"], meta["top_radius_m"]
        self.H = math.sqrt(self.Rt ** 2 - self.R ** 2)

    def rho(self, r):
        return np.sqrt(np.maximum(r * r - self.R ** 2, 0.0))

    def to_top(self, r, mu):
        return np.maximum(-r * mu + np.sqrt(np.maximum(r * r * (mu * mu - 1.0) + self.Rt ** 2, 0.0)), 0.0)

    def to_ground(self, r, mu):
        return np.maximum(-r * mu - np.sqrt(np.maximum(r * r * (mu * mu - 1.0) + self.R ** 2, 0.0)), 0.0)

    def hits_ground(self, r, mu):
        return (mu < 0.0) & (r * r * (mu * mu - 1.0) + self.R ** 2 >= 0.0)

    @staticmethod
    def along(r, mu, d):
        """(r, mu) at distance d along the ray."""
        r_d = np.sqrt(np.maximum(d * d + 2.0 * r * mu * d + r * r, 0.0))
        return r_d, np.clip((r * mu + d) / np.maximum(r_d, 1e-9), -1.0, 1.0)

    def transmittance_uv(self, r, mu, width, height):
        rho = self.rho(r)
        d_min, d_max = self.Rt - r, rho + self.H
        return texel((self.to_top(r, mu) - d_min) / (d_max - d_min), width), texel(rho / self.H, height)


class Transmittance:
    """T to the top from the transmittance texture, and between two points of a ray from the
    optical depth tau = -ln T, converted from the texture once at load (as the export's
    documentation advises: a ratio of transmittances underflows on grazing hazy rays)."""

    def __init__(self, planet, texture):
        self.planet, self.texture = planet, texture
        self.optical_depth = -np.log(np.maximum(texture, np.finfo(np.float32).tiny))

    def to_top(self, r, mu):
        return self._sample(self.texture, r, mu)

    def _sample(self, texture, r, mu):
        height, width = texture.shape[:2]
        return sample(texture, *self.planet.transmittance_uv(r, mu, width, height))

    def between(self, r, mu, d, hits):
        """exp(-(tau(r, mu) - tau(end))) for rays above the ground; for rays to the ground the
        reversed ray's."""
        r_d, mu_d = self.planet.along(r, mu, d)
        r_d = np.clip(r_d, self.planet.R, self.planet.Rt)
        sign = np.where(hits, -1.0, 1.0)
        start, end = self._sample(self.optical_depth, r, sign * mu), self._sample(self.optical_depth, r_d, sign * mu_d)
        return np.exp(-np.maximum(np.where(hits[:, None], end - start, start - end), 0.0))


# --- Bruneton 2017 as an engine reads it -------------------------------------------------------------

class BrunetonEngine:
    def __init__(self, meta, textures):
        self.meta, self.textures = meta, textures
        self.planet = Planet(meta)
        self.transmittance = Transmittance(self.planet, textures["transmittance"])
        size = meta["scattering_size"]
        self.R_SIZE, self.MU, self.MU_S, self.NU = size["r"], size["mu"], size["mu_s"], size["nu"]
        self.A = self.sun_fraction(np.array(meta["mu_s_min"]))
        self.solar = np.array(meta["solar_irradiance"])
        self.albedo = np.array(meta["ground_albedo"])
        self.alpha = meta["sun_angular_radius_rad"]

    def sun_fraction(self, mu_s):
        p = self.planet
        d = p.to_top(p.R + 0.0 * mu_s, mu_s)
        return (d - (p.Rt - p.R)) / (p.H - (p.Rt - p.R))

    def uvwz(self, r, mu, mu_s, nu, hits):
        p = self.planet
        rho = p.rho(r)
        half = self.MU // 2
        discriminant = r * r * (mu * mu - 1.0) + p.R ** 2
        d_ground = -r * mu - np.sqrt(np.maximum(discriminant, 0.0))
        d_min, d_max = r - p.R, rho
        x_ground = np.where(d_max == d_min, 0.0, (d_ground - d_min) / np.maximum(d_max - d_min, 1e-30))
        d_top = -r * mu + np.sqrt(np.maximum(discriminant + p.H ** 2, 0.0))
        x_sky = (d_top - (p.Rt - r)) / (rho + p.H - (p.Rt - r))
        u_mu = np.where(hits, 0.5 - 0.5 * texel(x_ground, half), 0.5 + 0.5 * texel(x_sky, half))
        a = self.sun_fraction(mu_s)
        u_mu_s = texel(np.maximum(1.0 - a / self.A, 0.0) / (1.0 + a), self.MU_S)
        return (nu + 1.0) / 2.0, u_mu_s, u_mu, texel(rho / p.H, self.R_SIZE)

    def lookup4(self, table, coords):
        u_nu, u_mu_s, u_mu, u_r = coords
        x = u_nu * (self.NU - 1)
        lower = np.floor(x)
        w = (x - lower)[:, None]
        a = sample(self.textures[table], (lower + u_mu_s) / self.NU, u_mu, u_r)
        b = sample(self.textures[table], (lower + 1.0 + u_mu_s) / self.NU, u_mu, u_r)
        return a * (1.0 - w) + b * w

    def scattering(self, r, mu, mu_s, nu, hits):
        """(scattering RGB, Mie part: RGB or the alpha channel (M, 1))."""
        coords = self.uvwz(r, mu, mu_s, nu, hits)
        s = self.lookup4("scattering", coords)
        if self.meta["combined_mie"]:
            return s[:, :3], s[:, 3:]
        return s, self.lookup4("single_mie", coords)

    def single_mie(self, s, mie):
        if not self.meta["combined_mie"]:
            return mie
        beta_r, beta_m = np.array(self.meta["rayleigh_scattering_per_m"]), np.array(self.meta["mie_scattering_per_m"])
        factor = beta_r[0] / beta_m[0] * beta_m / beta_r
        ratio = np.where(s[:, :1] <= 0.0, 0.0, mie / np.maximum(s[:, :1], 1e-300))
        return s * ratio * factor

    def enter(self, r, mu, mu_s, nu):
        """A viewer above the atmosphere moved to where the ray enters it."""
        Rt = self.planet.Rt
        discriminant = r * r * mu * mu - r * r + Rt * Rt
        d = -r * mu - np.sqrt(np.maximum(discriminant, 0.0))
        enters = (r > Rt) & (discriminant >= 0.0) & (d > 0.0)
        d = np.where(enters, d, 0.0)
        mu_new = np.clip(np.where(enters, (r * mu + d) / Rt, mu), -1.0, 1.0)
        mu_s_new = np.clip(np.where(enters, (r * mu_s + d * nu) / Rt, mu_s), -1.0, 1.0)
        return np.clip(r, self.planet.R, Rt), mu_new, mu_s_new, d, (r > Rt) & ~enters

    def radiance_of(self, s, mie, nu):
        rayleigh, aerosol = phase(self.meta, nu)
        return s * rayleigh[:, None] + self.single_mie(s, mie) * aerosol[:, None]

    def sky(self, r, mu, mu_s, nu):
        """GetSkyRadiance: (radiance, transmittance) along rays (ground rays: the air up to it)."""
        r, mu, mu_s, _, misses = self.enter(r, mu, mu_s, nu)
        hits = self.planet.hits_ground(r, mu)
        t = np.where(hits[:, None], 0.0, np.where(misses[:, None], 1.0, self.transmittance.to_top(r, mu)))
        s, mie = self.scattering(r, mu, mu_s, nu, hits)
        return np.where(misses[:, None], 0.0, self.radiance_of(s, mie, nu)), t

    def sky_to_point(self, r, mu, mu_s, nu, d):
        """GetSkyRadianceToPoint: scattering at the viewer minus T times that at the point."""
        r, mu, mu_s, entered, _ = self.enter(r, mu, mu_s, nu)
        d = np.maximum(d - entered, 0.0)
        hits = self.planet.hits_ground(r, mu)
        t = self.transmittance.between(r, mu, d, hits)
        s, mie = self.scattering(r, mu, mu_s, nu, hits)
        r_p, mu_p = self.planet.along(r, mu, d)
        r_p = np.clip(r_p, self.planet.R, self.planet.Rt)
        mu_s_p = np.clip((r * mu_s + d * nu) / r_p, -1.0, 1.0)
        s_p, mie_p = self.scattering(r_p, mu_p, mu_s_p, nu, hits)
        s = s - t * s_p
        mie = mie - t[:, :mie.shape[1]] * mie_p
        x = np.clip(mu_s / 0.01, 0.0, 1.0)
        fade = (x * x * (3.0 - 2.0 * x))[:, None]
        rayleigh, aerosol = phase(self.meta, nu)
        return s * rayleigh[:, None] + self.single_mie(s, mie) * fade * aerosol[:, None], t

    def sun_and_sky_irradiance(self, mu_s):
        """At the ground, on a horizontal surface."""
        p = self.planet
        height, width = self.textures["irradiance"].shape[:2]
        sky = sample(self.textures["irradiance"], texel(0.5 * mu_s + 0.5, width), texel(0.0 * mu_s, height))
        # the fraction of the sun's disk above the horizon, whose cosine is 0 at the ground
        x = np.clip((mu_s + self.alpha) / (2.0 * self.alpha), 0.0, 1.0)
        visible = x * x * (3.0 - 2.0 * x)
        sun_t = self.transmittance.to_top(p.R + 0.0 * mu_s, mu_s) * visible[:, None]
        return self.solar * sun_t * np.maximum(mu_s, 0.0)[:, None], sky

    def radiance(self, dirs, sun, altitude):
        p = self.planet
        sun = sun / np.linalg.norm(sun)
        r = np.full(len(dirs), p.R + altitude)
        mu, mu_s, nu = dirs[:, 2], np.full(len(dirs), sun[2]), np.clip(dirs @ sun, -1.0, 1.0)
        sky, _ = self.sky(r, mu, mu_s, nu)
        r_a, mu_a, mu_s_a, entered, misses = self.enter(r, mu, mu_s, nu)
        hits = p.hits_ground(r_a, mu_a) & ~misses
        d = p.to_ground(r_a, mu_a)
        mu_s_ground = np.clip((r_a * mu_s_a + d * nu) / p.R, -1.0, 1.0)
        e_sun, e_sky = self.sun_and_sky_irradiance(mu_s_ground)
        in_scattering, t = self.sky_to_point(r, mu, mu_s, nu, entered + d)
        ground = self.albedo / math.pi * (e_sun + e_sky) * t + in_scattering
        return np.where(hits[:, None], ground, sky)


# --- Hillaire 2020 as an engine reads it -------------------------------------------------------------

class HillaireEngine:
    def __init__(self, meta, textures):
        self.meta, self.textures = meta, textures
        self.planet = Planet(meta)
        self.transmittance = Transmittance(self.planet, textures["transmittance"])
        self.solar = np.array(meta["solar_irradiance"])
        self.albedo = np.array(meta["ground_albedo"])

    def multiple_scattering(self, r, mu_s):
        p = self.planet
        height, width = self.textures["multiple_scattering"].shape[:2]
        x_r = np.clip((r - p.R) / (p.Rt - p.R), 0.0, 1.0)
        return sample(self.textures["multiple_scattering"], texel(0.5 * mu_s + 0.5, width), texel(x_r, height))

    def sky_view_uv(self, r, mu, cos_azimuth, hits):
        height, width = self.textures["sky_view"].shape[:2]
        beta = np.arccos(np.clip(self.planet.rho(r) / r, -1.0, 1.0))
        horizon = math.pi - beta
        theta = np.arccos(np.clip(mu, -1.0, 1.0))
        above = 0.5 * (1.0 - np.sqrt(np.maximum(1.0 - theta / horizon, 0.0)))
        below = 0.5 * (1.0 + np.sqrt(np.maximum((theta - horizon) / beta, 0.0)))
        x = np.sqrt(np.maximum(0.5 * (1.0 - cos_azimuth), 0.0))
        return texel(x, width), texel(np.where(hits, below, above), height)

    def radiance(self, dirs, sun, altitude):
        p = self.planet
        sun = sun / np.linalg.norm(sun)
        view = self.meta["sky_view"]
        assert altitude == view["observer_altitude_m"] and sun[2] == pytest.approx(view["sun_zenith_cosine"])
        r = np.full(len(dirs), p.R + altitude)
        mu, mu_s, nu = dirs[:, 2], sun[2], np.clip(dirs @ sun, -1.0, 1.0)
        sines = np.sqrt(np.maximum(1.0 - mu * mu, 0.0)) * math.sqrt(max(1.0 - mu_s * mu_s, 0.0))
        cos_azimuth = np.where(sines > 1e-12, np.clip((nu - mu * mu_s) / np.maximum(sines, 1e-12), -1.0, 1.0), 1.0)
        hits = p.hits_ground(r, mu)
        in_scattered = sample(self.textures["sky_view"], *self.sky_view_uv(r, mu, cos_azimuth, hits))
        length = np.where(hits, p.to_ground(r, mu), p.to_top(r, mu))
        r_g, _ = p.along(r, mu, length)
        mu_s_g = np.clip((r * mu_s + length * nu) / np.maximum(r_g, 1.0), -1.0, 1.0)
        ground_r = np.full(len(dirs), p.R)
        ground = self.albedo * (self.transmittance.to_top(ground_r, mu_s_g) * np.maximum(mu_s_g, 0.0)[:, None] / math.pi
                                + self.multiple_scattering(ground_r, mu_s_g))
        t = self.transmittance.between(r, mu, length, hits)
        return (in_scattered + np.where(hits[:, None], t * ground, 0.0)) * self.solar


# --- fixtures: methods and their exports -------------------------------------------------------------

def scene():
    from skyref.scene import load_scene

    return load_scene(SCENE)


def method(name, precision="float32", **options):
    from skyref.lut.export import build_method

    lut = build_method(name, scene(), "rgb", precision, options)
    lut.precompute()
    return lut


def export(lut, directory):
    from skyref.lut.export import export_lut

    s = scene()
    return export_lut(lut, directory, sun_direction=s.sun.direction, observer_altitude_m=s.observer.altitude_m)


def method_transmittance(lut, r, mu):
    """The method's own T to the top, (M, C)."""
    import mitsuba as mi

    return np.stack([c.numpy() for c in lut.transmittance.to_top(mi.Float64(r), mi.Float64(mu))], axis=1)


# --- Bruneton 2017 ------------------------------------------------------------------------------------

@pytest.mark.parametrize("precision, combined", [("float32", False), ("float16", True)])
def test_bruneton_export_reproduces_the_method(mi, tmp_path, precision, combined):
    """The textures and the JSON alone give the method's radiance (sky, ground from the ground
    and from space, a sun below the horizon) and transmittance; pixel types follow the
    method's storage (float16: scattering HALF, transmittance and irradiance FLOAT as in the
    paper's code); with combined Mie the scattering texture is RGBA."""
    lut = method("bruneton2017", precision, combined_mie=combined, **BRUNETON_OPTIONS)
    export(lut, tmp_path)
    meta, textures = read_export(tmp_path, "bruneton2017")
    assert meta["channels"]["R"]["wavelength_nm"] == 680.0 and meta["wavelengths_nm"] == WL
    assert meta["combined_mie"] == combined and meta["mu_s_min"] == pytest.approx(math.cos(math.radians(
        102.0 if precision == "float16" else 120.0)))
    types = {name: entry["pixel_type"] for name, entry in meta["tables"].items()}
    assert types.pop("scattering") == precision and set(types.values()) == {"float32"}
    assert ("single_mie" in types) == (not combined)
    assert textures["scattering"].shape == (8, 32, 4 * 8, 3 + combined)
    assert textures["transmittance"].shape == (64, 256, 3) and textures["irradiance"].shape == (16, 64, 3)
    # the EXR's scanlines are the paper's 3-D texture: slice i_r, row i_mu, column i_nu * MU_S + i_mu_s
    assert np.array_equal(textures["scattering"], lut.tables()["scattering"])

    engine = BrunetonEngine(meta, textures)
    views = directions()
    for sun_zenith, altitude in ((50.0, 0.0), (85.0, 3000.0), (100.0, 500.0), (30.0, 1.0e6)):
        sun = sun_towards(sun_zenith)
        assert_close(engine.radiance(views, sun, altitude), lut.radiance(views, sun, altitude))
    r = np.full(len(views), engine.planet.R + 3000.0)
    up = views[:, 2] > 0.0
    assert_close(engine.transmittance.to_top(r[up], views[up, 2]), method_transmittance(lut, r[up], views[up, 2]),
                     TRANSMITTANCE_RTOL)


# --- Hillaire 2020 ------------------------------------------------------------------------------------

def test_hillaire_export_reproduces_the_method(mi, tmp_path):
    """The transmittance, multiple-scattering and sky-view textures (the sky view for the scene's
    sun and observer) give the method's radiance, sky and ground, and its transmittance; float16
    tables are HALF pixels and reproduce the float16 method as tightly, within 2e-3 of the
    float32 one."""
    s = scene()
    sun, altitude = s.sun.direction, s.observer.altitude_m
    views = directions()
    radiance = {}
    for precision in ("float32", "float16"):
        lut = method("hillaire2020", precision, **HILLAIRE_OPTIONS)
        export(lut, tmp_path / precision)
        meta, textures = read_export(tmp_path / precision, "hillaire2020")
        assert {e["pixel_type"] for e in meta["tables"].values()} == {precision}
        assert set(textures) == {"transmittance", "multiple_scattering", "sky_view"}
        assert textures["sky_view"].shape == (108, 192, 3) and textures["multiple_scattering"].shape == (32, 32, 3)
        assert meta["sky_view"] == {"observer_altitude_m": altitude,
                                    "sun_zenith_cosine": pytest.approx(sun[2], abs=1e-15)}
        assert "aerial-perspective" in meta["not_exported"]
        engine = HillaireEngine(meta, textures)
        radiance[precision] = engine.radiance(views, sun, altitude)
        assert_close(radiance[precision], lut.radiance(views, sun, altitude))
        r = np.full(len(views), engine.planet.R + 1000.0)
        up = views[:, 2] > 0.0
        assert_close(engine.transmittance.to_top(r[up], views[up, 2]), method_transmittance(lut, r[up], views[up, 2]),
                     TRANSMITTANCE_RTOL)
    difference = np.abs(radiance["float16"] / radiance["float32"] - 1.0).max()
    assert 0.0 < difference < 2e-3


def test_hillaire_from_space_has_no_sky_view(mi, tmp_path):
    """Above the atmosphere the method ray marches: no sky-view table, and the JSON says so."""
    from skyref.lut.export import export_lut

    lut = method("hillaire2020", multiple_scattering=False, **HILLAIRE_OPTIONS)
    meta = export_lut(lut, tmp_path / "space", sun_direction=sun_towards(40.0), observer_altitude_m=2.0e5)
    assert set(meta["tables"]) == {"transmittance"} and meta["sky_view"] is None
    assert "sky view" in meta["not_exported"]
    assert sorted(os.listdir(tmp_path / "space")) == ["hillaire2020.glsl", "hillaire2020.json",
                                                      "hillaire2020_transmittance.exr"]


# --- the GLSL snippet ---------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["bruneton2017", "hillaire2020"])
def test_glsl_snippet_has_the_constants(mi, tmp_path, name):
    """Every placeholder filled with the JSON's constants; the functions the JSON names are defined."""
    import re

    lut = method(name, **(BRUNETON_OPTIONS if name == "bruneton2017" else HILLAIRE_OPTIONS))
    meta = export(lut, tmp_path)
    text = (tmp_path / f"{name}.glsl").read_text()
    assert "$" not in text and text.count("{") == text.count("}")
    constants = dict(re.findall(r"const \w+ (\w+) = ([^;]+);", text))
    assert float(constants["BOTTOM_RADIUS"]) == meta["bottom_radius_m"]
    assert float(constants["TOP_RADIUS"]) == meta["top_radius_m"]
    assert int(constants["TRANSMITTANCE_WIDTH"]) == meta["tables"]["transmittance"]["width"]
    if name == "bruneton2017":
        assert float(constants["MU_S_MIN"]) == meta["mu_s_min"]
        assert int(constants["MU_SIZE"]) == meta["scattering_size"]["mu"]
    else:
        assert int(constants["SKY_VIEW_HEIGHT"]) == meta["tables"]["sky_view"]["height"]
    for entry in meta["tables"].values():
        for function in entry["glsl"].split(", "):
            assert re.search(rf"\b\w+ {function}\(", text), function


# --- the command line ---------------------------------------------------------------------------------

def test_cli_export_writes_what_the_method_computes(mi, tmp_path, capsys):
    """``skyref export-lut`` with --option and --precision: the tables equal a method built with
    the same options, and the directory holds just the export."""
    from skyref.cli import main

    out = tmp_path / "lut"
    options = [a for k, v in BRUNETON_OPTIONS.items() for a in ("--option", f"{k}={v}")]
    assert main(["export-lut", "--method", "bruneton2017", "-o", str(out), "--scene", SCENE, "-q", *options]) == 0
    assert "bruneton2017" in capsys.readouterr().out
    assert sorted(os.listdir(out)) == sorted(["bruneton2017.json", "bruneton2017.glsl"] + [
        f"bruneton2017_{t}.exr" for t in ("transmittance", "scattering", "single_mie", "irradiance")])
    assert not [p for p in os.listdir(tmp_path) if p != "lut"]           # no staging directory left
    meta, textures = read_export(out, "bruneton2017")
    assert meta["source"] == {"scene": SCENE} and meta["options"]["scattering_orders"] == 2
    tables = method("bruneton2017", **BRUNETON_OPTIONS).tables()
    for name, values in textures.items():
        assert np.array_equal(values.reshape(tables[name].shape), tables[name]), name
    # again into the existing directory: files replaced, nothing else added
    assert main(["export-lut", "--method", "bruneton2017", "-o", str(out), "--scene", SCENE, "-q", *options]) == 0
    assert len(os.listdir(out)) == 6 and not [p for p in os.listdir(tmp_path) if p != "lut"]


@pytest.mark.parametrize("arguments, parameter", [
    (["--method", "elek2009"], "--method"),
    (["--method", "nishita1993"], "--method"),
    (["--method", "bruneton2017", "--precision", "float64"], "--precision"),
    (["--method", "bruneton2017", "--option", "precision=float16"], "--option"),
    (["--method", "bruneton2017", "--option", "colour=blue"], "--option"),
    (["--method", "bruneton2017", "--option", "r_size=1"], "r_size"),
    (["--method", "hillaire2020", "--wavelengths", "500,600"], "--wavelengths"),
    (["--method", "hillaire2020", "--wavelengths", "red"], "--wavelengths"),
    (["--method", "hillaire2020", "--scene", "no-such-scene.toml"], "scene"),
])
def test_cli_refuses_bad_input_before_any_work(mi, tmp_path, capsys, arguments, parameter):
    from skyref.cli import main

    out = tmp_path / "lut"
    scene_args = [] if "--scene" in arguments else ["--scene", SCENE]
    assert main(["export-lut", "-o", str(out), *scene_args, *arguments]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and parameter in error
    assert os.listdir(tmp_path) == []


def test_cli_refuses_a_file_as_output_directory(tmp_path, capsys):
    from skyref.cli import main

    path = tmp_path / "taken"
    path.write_text("x")
    assert main(["export-lut", "--method", "hillaire2020", "-o", str(path), "--scene", SCENE]) == 2
    assert "-o" in capsys.readouterr().err and path.read_text() == "x"
