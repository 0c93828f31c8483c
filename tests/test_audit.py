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

        self.integrator = build_integrator(self.scene)
        return 0.0

    def radiance(self, directions, sun_direction, observer_altitude_m):
        orders = np.mean([self.integrator.render_directions(directions, seed=1000 + s, spp=self.spp // 4).numpy()
                          for s in range(4)], axis=0)
        return self.factor * orders[:, 1:].sum(axis=1)  # without the sun_direct layer


@pytest.fixture(scope="module")
def scene(mi):
    from skyref.scene import Camera, RenderSettings, Scene, Sun

    return Scene(sun=Sun(zenith_deg=50.0, azimuth_deg=90.0), camera=Camera(width=16, height=8),
                 wavelengths=[450.0, 550.0, 650.0], render=RenderSettings(passes=4, seed=3), name="tiny")


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
