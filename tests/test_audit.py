"""The audit machinery, checked with stand-in methods whose error is known: the ground truth
itself rendered independently, scaled by a known factor."""

import json
import math
import os

import numpy as np
import pytest

from skyref.audit.regions import horizon_cosine, region_masks


def test_horizon_cosine_matches_the_tangent_ray():
    R = 6_360_000.0
    assert horizon_cosine(R, 0.0) == 0.0
    for h in (1_000.0, 100_000.0, 1_000_000.0):
        # the tangent ray from radius R + h grazes the sphere: sin(zenith) = R / (R + h)
        assert math.degrees(math.acos(horizon_cosine(R, h))) == pytest.approx(180.0 - math.degrees(math.asin(R / (R + h))))


def test_regions_hold_the_directions_they_name():
    from skyref.scene import direction_from_angles

    sun = direction_from_angles(60.0, 90.0)
    directions = np.stack([sun * 0.0 + direction_from_angles(60.0, 92.0),     # 2 deg from the sun
                           -direction_from_angles(60.0, 90.0) * np.array([1, 1, -1]) * -1 * -1,
                           direction_from_angles(88.0, 0.0),                 # horizon band
                           direction_from_angles(30.0, 0.0),                 # plain sky
                           direction_from_angles(120.0, 0.0)])               # ground
    directions[1] = -sun
    directions[1][2] = abs(directions[1][2])  # anti-solar azimuth, above the horizon: 120 deg from the sun
    directions[1] /= np.linalg.norm(directions[1])
    masks = region_masks(directions, sun, 6_360_000.0, 0.0)
    assert masks["sun"].tolist() == [True, False, False, False, False]
    assert masks["horizon"].tolist() == [False, False, True, False, False]
    assert masks["away"].tolist() == [False, True, False, True, False]
    assert masks["ground"].tolist() == [False, False, False, False, True]
    assert masks["sky"].sum() == 4


class IndependentRender:
    """A stand-in method: the path tracer with another seed and many samples, times ``factor``."""

    name = "stand-in"

    def __init__(self, scene, factor, spp):
        self.scene, self.factor, self.spp = scene, factor, spp
        self.wavelengths_nm = scene.wavelengths_nm
        self.options = {"factor": factor}

    def precompute(self):
        from skyref.render import build_integrator

        self.integrator = build_integrator(self.scene)        # the scene's estimator, the baseline
        return 0.0

    def radiance(self, directions, sun_direction, observer_altitude_m):
        orders = np.mean([self.integrator.render_directions(directions, seed=1000 + s, spp=self.spp // 4).numpy()
                          for s in range(4)], axis=0)
        return self.factor * orders[:, 1:].sum(axis=1)  # without the sun_direct layer


@pytest.fixture(scope="module")
def scene(mi):
    from skyref.scene import Camera, RenderSettings, Scene, Sun

    # 16 passes: the adaptive ground truth stops each pixel when its standard error looks small
    # enough, and with 4 passes (3 degrees of freedom) the pixels that stopped were those whose
    # error was underestimated (line integral: noise-corrected RMS of a 5% bias 5.5%; 4.96% here).
    # The audit's statistics are the subject: the truth is rendered by the baseline estimator,
    # whose kernels compile in seconds.
    return Scene(sun=Sun(zenith_deg=50.0, azimuth_deg=90.0), camera=Camera(width=16, height=8),
                 wavelengths=[450.0, 550.0, 650.0], render=RenderSettings(passes=16, seed=3, estimator="delta_tracking"),
                 name="tiny")


def test_a_known_bias_is_measured_and_resolved(scene, tmp_path):
    from skyref.audit.audit import audit, write_report

    result = audit(IndependentRender(scene, 1.05, spp=16384), scene, max_spp=16384,
                   cache_dir=str(tmp_path / "cache"), log=lambda *_: None)
    sky = result.statistics["sky"]
    for metric in ("luminance", "spectral"):
        # The stand-in's own noise (16384 spp) is part of its 'error': 5% within 0.5%.
        assert sky[metric]["mean"] == pytest.approx(0.05, abs=0.005)
        assert sky[metric]["rms"] == pytest.approx(0.05, abs=0.005)
    assert sky["luminance"]["resolved_mean"] and sky["luminance"]["resolved_rms"]
    assert sky["delta_e"]["mean"] > 0.5
    # the report and its files
    path = write_report(result, str(tmp_path / "report"))
    text = open(path).read()
    assert "| sky |" in text and "luminance rel. error" in text
    summary = json.load(open(tmp_path / "report" / "summary.json"))
    assert summary["statistics"]["sky"]["luminance"]["mean"] == pytest.approx(sky["luminance"]["mean"])
    import OpenEXR

    with OpenEXR.File(str(tmp_path / "report" / "error_maps.exr")) as exr:
        assert {"luminance", "delta_e", "noise.luminance"} <= set(exr.channels())
    for name in ("images.png", "errors.png"):
        assert os.path.getsize(tmp_path / "report" / name) > 1000


def test_an_unbiased_method_is_flagged_as_noise_limited(scene, tmp_path):
    """Against an independent render of the same sky the only 'error' is noise: the audit
    must not present it as a resolved error."""
    from skyref.audit.audit import audit

    result = audit(IndependentRender(scene, 1.0, spp=256), scene, max_spp=1024,
                   cache_dir=str(tmp_path / "cache"), log=lambda *_: None)
    luminance = result.statistics["sky"]["luminance"]
    assert not luminance["resolved_mean"] and not luminance["resolved_p95"]
    # the noise-corrected RMS of a pure-noise difference is about the method's own noise only
    assert luminance["rms"] < luminance["p95"]


# --- scale and shape, warm timings and the report, on a synthetic sky (no rendering) ----------------

def test_best_scale_is_the_least_squares_factor():
    """s = sum m t / sum m^2, worked by hand: a model exactly twice the truth gives 1/2; m = (1, 2)
    against t = (1, 1) gives 3/5, the minimum of (s - 1)^2 + (2 s - 1)^2; radiance weighs, not
    relative error: m = (1, 10) against t = (2, 10) gives 102/101."""
    from skyref.audit.metrics import best_scale

    truth = np.array([[0.5, 1.0, 2.0], [3.0, 0.1, 7.0]])
    assert best_scale(2.0 * truth, truth) == pytest.approx(0.5, rel=1e-15)
    assert best_scale([1.0, 2.0], [1.0, 1.0]) == pytest.approx(0.6, rel=1e-15)
    assert best_scale([1.0, 10.0], [2.0, 10.0]) == pytest.approx(102.0 / 101.0, rel=1e-15)
    assert math.isnan(best_scale([0.0, 0.0], [1.0, 1.0]))


WAVELENGTHS = np.array([450.0, 550.0, 650.0])
SUN = (50.0, 90.0)  # zenith, azimuth, deg


def synthetic_sky():
    """(truth, scene): a 4 x 8 sky above the horizon, smooth and noisy by 0.1%, as compare reads them."""
    from types import SimpleNamespace

    from skyref.scene import direction_from_angles

    zenith, azimuth = np.meshgrid(np.linspace(10.0, 80.0, 4), np.linspace(0.0, 315.0, 8), indexing="ij")
    directions = direction_from_angles(zenith, azimuth)
    radiance = (1.0 + np.cos(np.radians(zenith)))[..., None] * np.array([1.2, 1.0, 0.7])
    truth = SimpleNamespace(directions=directions, radiance=radiance, standard_error=1e-3 * radiance, orders={},
                            metadata={"spp": 64, "variant": "synthetic"})
    scene = SimpleNamespace(name="synthetic", wavelengths_nm=WAVELENGTHS,
                            sun=SimpleNamespace(direction=direction_from_angles(np.array(SUN[0]), np.array(SUN[1]))),
                            observer=SimpleNamespace(altitude_m=0.0),
                            atmosphere=SimpleNamespace(bottom_radius_m=6_360_000.0))
    return truth, scene


class Clock:
    """A stand-in for time.perf_counter that only the stand-in method advances."""

    def __init__(self):
        self.now = 0.0

    def perf_counter(self):
        return self.now


COMPILE_S, VIEW_S, LOOKUP_S = 1000.0, 0.25, 1e-6


class CompilingMethod:
    """A method whose first per-view build and first lookup each cost COMPILE_S more (a kernel
    compiled), then VIEW_S per view and LOOKUP_S per direction; its radiance is ``factor`` x the
    truth's. It counts one fetch of a 2x3 table per direction."""

    name = "compiling"
    wavelengths_nm = WAVELENGTHS

    def __init__(self, truth, clock, factor=2.0):
        self.values = factor * truth.radiance.reshape(-1, WAVELENGTHS.size)
        self.clock, self.views, self.lookups = clock, [], 0

    def prepare_view(self, sun_direction, observer_altitude_m):
        self.views.append(np.array(sun_direction, dtype=np.float64))
        return (COMPILE_S if len(self.views) == 1 else 0.0) + VIEW_S   # its own wall time, as LutMethod's

    def radiance(self, directions, sun_direction, observer_altitude_m):
        self.clock.now += (COMPILE_S if self.lookups == 0 else 0.0) + LOOKUP_S * len(directions)
        self.lookups += 1
        return self.values

    def operations(self):
        from skyref.sky_method import Operations

        return Operations(tables={"table": (2, 3)}, sky={"table fetches": 1})


def test_per_view_and_lookup_times_exclude_the_first_calls(monkeypatch):
    """compare builds the tables of another view (the sun 1 deg lower) and makes the lookups once
    untimed before it times this view's tables and the same lookups again: a kernel compiled on
    the first call is in neither time."""
    import skyref.audit.audit as audit_module
    from skyref.audit.audit import WARM_UP_SUN_OFFSET_DEG, compare

    truth, scene = synthetic_sky()
    clock = Clock()
    monkeypatch.setattr(audit_module, "time", clock)
    method = CompilingMethod(truth, clock)
    found = compare(method, truth, scene)
    assert len(method.views) == 2 and method.lookups == 2
    warm_up, timed = method.views
    np.testing.assert_allclose(timed, scene.sun.direction, atol=1e-15)
    angle = math.degrees(math.acos(np.clip(warm_up @ timed, -1.0, 1.0)))
    assert angle == pytest.approx(WARM_UP_SUN_OFFSET_DEG) and np.linalg.norm(warm_up) == pytest.approx(1.0)
    assert math.degrees(math.acos(warm_up[2])) == pytest.approx(SUN[0] + WARM_UP_SUN_OFFSET_DEG)   # same azimuth, lower
    assert found["per_view_s"] == VIEW_S
    assert found["lookup_s_per_direction"] == pytest.approx(LOOKUP_S, rel=1e-9)


def test_scale_and_shape_are_reported_apart(monkeypatch, tmp_path):
    """A method exactly twice the truth: its luminance RMS error as it is is 100%, its best scale
    factor 1/2 and its RMS after it 0; the audit's report.md and summary.json carry them, and
    the costs are labelled as this CPU's, with what they count beside them."""
    import skyref.audit.audit as audit_module
    from skyref.audit.audit import AuditResult, compare, write_report

    truth, scene = synthetic_sky()
    clock = Clock()
    monkeypatch.setattr(audit_module, "time", clock)
    found = compare(CompilingMethod(truth, clock), truth, scene)
    scale = found["scale"]
    assert scale["factor"] == pytest.approx(0.5, rel=1e-12)
    assert scale["rms"] == pytest.approx(1.0, rel=1e-5) and scale["resolved_rms"]
    assert scale["rms_scaled"] == pytest.approx(0.0, abs=1e-9) and not scale["resolved_rms_scaled"]

    result = AuditResult(method="compiling", options={}, scene=scene, radiance=found["radiance"], truth=truth,
                         truth_radiance=found["truth_radiance"], maps=found["maps"], statistics=found["statistics"],
                         precompute_s=3.0, per_view_s=found["per_view_s"],
                         lookup_s_per_direction=found["lookup_s_per_direction"], operations=found["operations"],
                         scale=scale)
    text = open(write_report(result, str(tmp_path))).read()
    assert ("| region | luminance RMS as is (noise) | best scale factor s | luminance RMS of s x method (noise) |"
            in text)
    assert "| sky | 100.00% (" in text and "| 0.5 | 0.00% (" in text
    assert "costs of skyref's implementation on this machine's CPU" in text and "per-view tables 250.0 ms" in text
    assert "lookup 1,000 ns per direction" in text and "warm (first-call kernel compilation excluded)" in text
    assert "per sky direction: 1 table fetches; tables: table 2x3" in text
    summary = json.load(open(tmp_path / "summary.json"))
    assert summary["scale"]["factor"] == pytest.approx(0.5)
    assert summary["operations"] == {"tables": {"table": [2, 3]}, "sky": {"table fetches": 1}, "ground": {},
                                     "per_view": {}, "note": ""}
