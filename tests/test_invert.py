"""Differentiable inversion (skyref.invert): input checks, the optimizer's Jacobian against finite
differences, a synthetic round trip, the identifiability flag, and the CLI.

Tiny images and budgets keep the file under two minutes on two CPU cores; results/inversion.md
(benchmarks/inversion.py) measures bias, spread and coverage over many cases. The synthetic
skies are rendered by the estimator the inversion's forward model uses, delta tracking.
"""

import dataclasses
import json
import math
import os

import numpy as np
import pytest

from skyref.errors import ParameterError
from tests.variants import RGB

WL = [440.0, 500.0, 550.0, 610.0, 680.0]
VARIANT = RGB

#: The atmosphere of the round trip (unknowns of skyref.invert.parameters).
TRUTH = dict(aod_550=0.25, angstrom_alpha=1.2, aerosol_g=0.8, ozone_du=320.0, ground_albedo=0.3)


@pytest.fixture(scope="module")
def base():
    from skyref.atmosphere import preset

    return preset("bruneton2017")


@pytest.fixture(scope="module")
def truth_sky(mi, base):
    """A 32x16 equirectangular spectral sky (5 wavelengths, 2048 spp: ~2% noise per pixel) of
    TRUTH, sun at zenith 40, azimuth 120."""
    from skyref.invert import ParameterSet
    from skyref.render import render_sky
    from skyref.scene import Camera, RenderSettings, Scene, Sun

    truth = ParameterSet(base, values=TRUTH)
    scene = Scene(atmosphere=truth.atmosphere_at(truth.values), sun=Sun(40.0, 120.0),
                  camera=Camera("equirectangular", 32, 16), wavelengths=WL,
                  render=RenderSettings(spp=2048, passes=4, seed=7, estimator="delta_tracking"))
    return render_sky(scene, variant=VARIANT)


# --- input checks: one clear error, before any rendering ------------------------------------------

def _image(kind="spectral", shape=(8, 16)):
    from skyref.invert import SkyImage

    channels = 3
    return SkyImage(np.ones(shape + (channels,)), kind, np.array([440.0, 550.0, 680.0]) if kind == "spectral" else None)


def _bad_inputs():
    from skyref.atmosphere import preset
    from skyref.invert import ParameterSet, observation, read_image, sun_from_arguments
    from skyref.invert.inputs import SkyImage
    from skyref.scene import Camera, Sun

    base = preset("bruneton2017")
    cam = {"type": "equirectangular"}
    sun = Sun(40.0, 120.0)
    ldr = SkyImage(np.full((8, 16, 3), 0.5), "rgb", ldr=True, saturated=np.zeros((8, 16), bool))
    return {
        "missing file": (lambda: read_image("/nonexistent/sky.exr"), "image"),
        "unsupported format": (lambda: read_image(__file__), "image"),
        "unknown unknown": (lambda: ParameterSet(base, free=["aod"]), "unknown"),
        "nothing free": (lambda: ParameterSet(base, free=[]), "free"),
        "reversed bounds": (lambda: ParameterSet(base, bounds={"aod_550": (0.5, 0.1)}), "bounds.aod_550"),
        "bounds beyond limits": (lambda: ParameterSet(base, bounds={"ground_albedo": (0.0, 1.5)}),
                                 "bounds.ground_albedo"),
        "bounds of a fixed unknown": (lambda: ParameterSet(base, bounds={"rayleigh_scale": (0.8, 1.0)}),
                                      "bounds.rayleigh_scale"),
        "initial value outside bounds": (lambda: ParameterSet(base, values={"aerosol_g": 0.3}), "aerosol_g"),
        "constituent missing": (lambda: ParameterSet(preset("rayleigh_only"), free=["aod_550"]), "aod_550"),
        "camera size": (lambda: observation(_image(), camera=Camera("equirectangular", 32, 16), sun=sun), "camera"),
        "no camera": (lambda: observation(_image(), sun=sun), "--camera"),
        "no sun": (lambda: observation(_image(), camera=cam), "sun"),
        "sun below horizon": (lambda: observation(_image(), camera=cam, sun=Sun(100.0, 0.0)), "sun.zenith_deg"),
        "sun half given": (lambda: sun_from_arguments(zenith_deg=40.0), "--sun-azimuth"),
        "sun twice": (lambda: sun_from_arguments(40.0, 120.0, "2026-06-21T12:00:00+00:00", 45.0, 5.0),
                      "--sun-zenith/--time"),
        "no visible sun": (lambda: observation(_image(), camera=cam, sun="image"), "sun"),
        "mask size": (lambda: observation(_image(), camera=cam, sun=sun, exclude=np.zeros((4, 4), bool)), "exclude"),
        "everything masked": (lambda: observation(_image(), camera=cam, sun=sun, exclude=np.ones((8, 16), bool)),
                              "pixels"),
        "wavelength not in image": (lambda: observation(_image(), camera=cam, sun=sun, wavelengths=[500.0]),
                                    "wavelengths"),
        "absolute LDR": (lambda: observation(ldr, camera=cam, sun=sun, absolute=True), "--absolute"),
    }


@pytest.mark.parametrize("case", list(_bad_inputs()))
def test_bad_input_is_one_clear_error(case):
    call, name = _bad_inputs()[case]
    with pytest.raises(ParameterError) as info:
        call()
    assert info.value.name == name, str(info.value)
    assert "valid:" in str(info.value)


def test_ldr_image_warns_and_is_relative(tmp_path):
    from PIL import Image

    from skyref.invert import observation, read_image
    from skyref.scene import Sun

    pixels = np.full((8, 16, 3), 120, np.uint8)
    pixels[0, 0] = 255
    Image.fromarray(pixels).save(tmp_path / "sky.png")
    image = read_image(tmp_path / "sky.png")
    assert image.ldr and image.saturated[0, 0] and not image.saturated[1, 1]
    assert image.values[1, 1, 0] == pytest.approx(((120 / 255 + 0.055) / 1.055) ** 2.4)  # sRGB decoding
    with pytest.warns(UserWarning, match="8-bit"):
        obs = observation(image, camera={"type": "equirectangular"}, sun=Sun(40.0, 120.0))
    assert not obs.absolute and not obs.mask[0, 0] and obs.channels == "xyz"


def test_cli_rejects_bad_input_before_work(tmp_path, capsys):
    from skyref.cli import main

    assert main(["invert", str(tmp_path / "missing.exr"), "-o", str(tmp_path / "fit")]) == 2
    assert main(["invert", str(tmp_path / "missing.exr"), "-o", str(tmp_path / "fit"), "--bounds", "aod_550=1"]) == 2
    assert main(["invert", str(tmp_path / "missing.exr"), "-o", str(tmp_path / "fit"), "--fov", "90"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith("skyref invert: error:") for line in err)
    assert "image" in err[0] and "--bounds" in err[1] and "--fov" in err[2]
    assert not (tmp_path / "fit" / "result.json").exists()


# --- the Jacobian the optimizer uses -------------------------------------------------------------

#: Finite-difference steps (5-point stencil) per unknown, at the values of test_jacobian_...
FD_STEPS = dict(aod_550=0.04, angstrom_alpha=0.3, aerosol_g=0.01, ozone_du=100.0, ground_albedo=0.05)


def test_jacobian_matches_finite_differences(mi, base):
    """d log m / d theta from ForwardModel.log_jacobian (forward-mode AD through the path tracer,
    chained to the unknowns: tau_550 and alpha act through Angstrom's beta) against a 5-point
    finite difference of log m at the same seed, per seed; 16 seeds x 512 spp on 13 pixels x 3
    wavelengths of a 16x8 sky (sky and ground). Every element must satisfy |z| < 4.5 (the mean
    difference over its standard error; 195 elements). Measured: max |z| 2.3-3.3 per unknown;
    relative standard error of AD - FD on the best element 2.9% (aod_550), 5.4% (alpha), 6.7% (g),
    12% (ozone), 0.3% (albedo)."""
    from skyref.invert import ParameterSet, SkyImage, observation
    from skyref.invert.model import ForwardModel
    from skyref.scene import Camera, Sun

    image = SkyImage(np.ones((8, 16, 3)), "spectral", np.array([440.0, 550.0, 680.0]))
    obs = observation(image, camera=Camera("equirectangular", 16, 8), sun=Sun(50.0, 90.0), max_view_zenith_deg=180.0)
    params = ParameterSet(base, free=list(FD_STEPS),
                          values=dict(aod_550=0.2, angstrom_alpha=1.0, aerosol_g=0.8, ground_albedo=0.3))
    rows, cols = np.nonzero(obs.mask)
    pick = np.arange(0, rows.size, rows.size // 12)
    model = ForwardModel(obs, params, rows[pick], cols[pick], footprint=1, variant=VARIANT)
    seeds = range(16)
    for k, name in enumerate(params.free):
        ad, fd = [], []
        for seed in seeds:
            ad.append(model.log_jacobian(params.values, seed, 512)[..., k])
            shifted = {}
            for j in (-2, -1, 1, 2):
                values = dict(params.values, **{name: params.values[name] + j * FD_STEPS[name]})
                shifted[j] = model.log(model.radiance(values, seed, 512))
            fd.append((-shifted[2] + 8 * shifted[1] - 8 * shifted[-1] + shifted[-2]) / (12 * FD_STEPS[name]))
        difference = np.array(ad) - np.array(fd)
        se = difference.std(axis=0, ddof=1) / math.sqrt(len(seeds))
        z = difference.mean(axis=0) / se
        significance = np.abs(np.mean(ad, axis=0)) / (np.std(ad, axis=0, ddof=1) / math.sqrt(len(seeds)))
        assert np.max(significance) > 10.0, f"{name}: the AD derivative is not significant"
        assert np.all(np.abs(z) < 4.5), f"{name}: AD and FD disagree, z = {z}"


# --- round trip, identifiability, CLI ------------------------------------------------------------

def test_round_trip_recovers_aod_and_albedo(truth_sky, base, tmp_path):
    """The 32x16 spectral sky of TRUTH, multiplied by an unknown exposure 3.7, with the ground in
    view: aod_550 and ground_albedo free (the rest fixed at the truth). Measured: aod 0.2523 +-
    0.0044, albedo 0.3029 +- 0.0033, exposure 3.68 (0.994 x), fit in 6-18 s. Asserted: aod within
    5%, albedo within 0.02, exposure within 3%, each also within 4 stated standard deviations."""
    from skyref.invert import InversionSettings, ParameterSet, image_from_sky, invert, observation

    image = image_from_sky(truth_sky)
    image.values = image.values * 3.7
    obs = observation(image, max_view_zenith_deg=180.0, atmosphere=base)
    params = ParameterSet(base, free=["aod_550", "ground_albedo"],
                          values={k: v for k, v in TRUTH.items() if k not in ("aod_550", "ground_albedo")})
    settings = InversionSettings(pixels=300, spp_max=512, final_spp=2048, variant=VARIANT)
    result = invert(obs, params, settings)
    std = result.std
    for name, tolerance in (("aod_550", 0.05 * TRUTH["aod_550"]), ("ground_albedo", 0.02)):
        error = result.values[name] - TRUTH[name]
        assert abs(error) < tolerance, f"{name}: {result.values[name]} vs {TRUTH[name]}"
        assert abs(error) < 4.0 * std[name], f"{name}: error {error} vs stated std {std[name]}"
    assert result.exposure == pytest.approx(3.7, rel=0.03)
    assert all(flag["identifiable"] for flag in result.identifiability)

    paths = result.write(tmp_path / "fit")
    document = json.loads((tmp_path / "fit" / "result.json").read_text())
    assert document["estimates"]["aod_550"]["value"] == pytest.approx(result.values["aod_550"])
    assert document["estimates"]["ozone_du"]["free"] is False
    assert "ground-truth" in document["provenance"]["estimates"]
    residuals = document["residuals"]["all_usable_pixels"]
    assert residuals["rms_log"] < 0.06 and abs(residuals["mean_log"]) < 0.01, residuals
    assert all((tmp_path / "fit" / name).stat().st_size > 0 for name in
               ("convergence.png", "residuals.png", "fitted.exr", "residual.exr")) and len(paths) == 5


def test_sun_estimated_from_the_visible_disk(mi, base):
    """The sun at a pixel centre of a 32x16 sky sampled at pixel centres: every sample of that
    pixel sees the disk (with area sampling the disk, 1/360 of an 11.25 x 11.25 deg pixel, is hit
    a Poisson number of times: ~6 in 2048 samples, sometimes none). Its centre comes back within
    half a pixel."""
    from skyref.invert import estimate_sun, image_from_sky
    from skyref.render import render_sky
    from skyref.scene import Camera, RenderSettings, Scene, Sun

    zenith, azimuth = 3.5 * 11.25, 10.5 * 11.25
    sky = render_sky(Scene(atmosphere=base, sun=Sun(zenith, azimuth), camera=Camera("equirectangular", 32, 16),
                           wavelengths=WL, render=RenderSettings(spp=32, passes=2, pixel_sampling="centre",
                                                                        estimator="delta_tracking")),
                     variant=VARIANT)
    sun = estimate_sun(image_from_sky(sky), sky.directions)
    assert abs(sun.zenith_deg - zenith) < 5.7 and abs(sun.azimuth_deg - azimuth) < 5.7


def test_ozone_from_an_rgb_noon_sky_is_flagged(mi, base):
    """An RGB fisheye image of a noon sky (sun zenith 20) with the default unknowns and an
    unknown exposure: ozone barely changes the colour, so it must be flagged "not identifiable",
    with the evidence (measured: posterior std 1.7x the prior's, sensitivity 0.006 against noise
    0.06 in log radiance, correlation +0.97 with aod_550; the other unknowns are recovered: aod
    0.145 +- 0.018 for 0.15, g 0.749 +- 0.007 for 0.75)."""
    from skyref.invert import InversionSettings, ParameterSet, image_from_sky, invert, observation
    from skyref.invert.inputs import RGB_MODEL_WAVELENGTHS_NM
    from skyref.render import render_sky
    from skyref.scene import Camera, RenderSettings, Scene, Sun

    truth = ParameterSet(base, values=dict(aod_550=0.15, angstrom_alpha=1.0, aerosol_g=0.75, ozone_du=300.0))
    scene = Scene(atmosphere=truth.atmosphere_at(truth.values), sun=Sun(20.0, 180.0), camera=Camera("fisheye", 24, 24),
                  wavelengths=RGB_MODEL_WAVELENGTHS_NM,
                  render=RenderSettings(spp=512, passes=4, seed=3, estimator="delta_tracking"))
    obs = observation(image_from_sky(render_sky(scene, variant=VARIANT), "rgb"), atmosphere=base)
    assert obs.channels == "xyz"
    settings = InversionSettings(pixels=150, spp_max=256, final_spp=1024, map_spp=16, max_iterations=4,
                                 variant=VARIANT)
    result = invert(obs, ParameterSet(base), settings)
    ozone = result.identifiability[result.parameters.free.index("ozone_du")]
    assert not ozone["identifiable"]
    assert ozone["posterior_to_prior_std"] > result.settings.identifiability_ratio
    assert ozone["sensitivity_rms_log_per_prior_std"] < ozone["noise_rms_log"]
    assert ozone["most_correlated_with"] in result.names
    assert any("NO:" in line and line.startswith("ozone_du") for line in result.summary_lines())


def test_flag_on_a_degenerate_jacobian():
    """Plain linear algebra: of four columns, one is zero and two are equal; only the first,
    independent one is identifiable."""
    from skyref.invert.optimizer import identifiability, normal_equations, sandwich_covariance

    rng = np.random.default_rng(1)
    rows = 400
    signal = rng.normal(size=rows)
    jacobian = np.stack([rng.normal(size=rows), np.zeros(rows), signal, signal], axis=1)
    residual = 0.01 * rng.normal(size=rows)
    prior_precision = np.ones(4)
    a, _, _ = normal_equations((jacobian, jacobian), residual, 1e-4, prior_precision, np.zeros(4))
    covariance = sandwich_covariance((jacobian, jacobian), residual, np.arange(rows), 1e-4, prior_precision, a)
    flags = identifiability(["a", "zero", "b", "b_twin"], jacobian, covariance, np.ones(4), 1e-4, 0.5, False)
    assert [f["identifiable"] for f in flags] == [True, False, False, False]
    assert flags[2]["most_correlated_with"] == "b_twin" and flags[2]["correlation"] < -0.99
    assert flags[1]["sensitivity_rms_log_per_prior_std"] == 0.0


def test_bounded_step_pins_crossing_unknowns():
    """min 1/2 d^T A d + g^T d with theta + d in bounds: the unknown pushed out stops on its
    bound, the other and the unbounded last component (an exposure) solve the rest exactly."""
    from skyref.invert.optimizer import bounded_step

    a = np.array([[2.0, 0.5, 0.1], [0.5, 1.0, 0.2], [0.1, 0.2, 1.0]])
    g = np.array([-4.0, 0.3, 0.2])
    theta, lower, upper = np.array([0.5, 0.8]), np.array([0.0, 0.0]), np.array([1.0, 1.0])
    delta = bounded_step(a, g, theta, lower, upper)
    assert theta[0] + delta[0] == pytest.approx(1.0)
    rest = np.linalg.solve(a[1:, 1:], -(g[1:] + a[1:, 0] * delta[0]))
    assert delta[1:] == pytest.approx(rest)
    assert np.all(theta + delta[:2] >= lower) and np.all(theta + delta[:2] <= upper)


def test_cli_end_to_end(truth_sky, tmp_path, capsys):
    from skyref.cli import main
    from skyref.io.exr import write_sky_exr

    write_sky_exr(truth_sky, tmp_path / "sky.exr")
    status = main(["invert", str(tmp_path / "sky.exr"), "-o", str(tmp_path / "fit"), "--free", "aod_550",
                   "--set", "ground_albedo=0.3", "--channels", "rgb", "--pixels", "100", "--max-spp", "128",
                   "--final-spp", "256", "--iterations", "3", "--map-spp", "16", "--variant", VARIANT, "-q"])
    out = capsys.readouterr().out
    assert status == 0, out
    assert "aod_550" in out and "ground-truth path tracer" in out
    document = json.loads((tmp_path / "fit" / "result.json").read_text())
    assert document["channels"] == "xyz" and document["sun"]["zenith_deg"] == pytest.approx(40.0)
    assert document["estimates"]["ground_albedo"]["value"] == 0.3


def test_skyrefs_own_default_render_inverts(mi, tmp_path, capsys):
    """The default scene (scenes/earth-clear.toml: 48 wavelengths 360-830 nm), rendered by
    ``skyref render`` (a smaller camera, fewer samples) and given to ``skyref invert``: the
    wavelengths come back exactly from the EXR (830.0, not 830.0000000000001, which is outside
    the ozone data) and the fit runs."""
    from skyref.cli import main
    from skyref.io.exr import read_sky_exr
    from skyref.scene import load_scene, save_scene

    scene = load_scene(os.path.join(os.path.dirname(__file__), "..", "scenes", "earth-clear.toml"))
    small = tmp_path / "earth-clear.toml"
    save_scene(scene.replace(camera=dataclasses.replace(scene.camera, width=32, height=16),
                             render=dataclasses.replace(scene.render, estimator="delta_tracking")), small)
    assert main(["render", str(small), "-o", str(tmp_path / "sky.exr"), "--spp", "32", "--variant", VARIANT, "-q"]) == 0
    assert read_sky_exr(tmp_path / "sky.exr").wavelengths_nm.tolist() == scene.wavelengths_nm.tolist()
    status = main(["invert", str(tmp_path / "sky.exr"), "-o", str(tmp_path / "fit"), "--free", "aod_550",
                   "--channels", "rgb", "--pixels", "64", "--spp", "16", "--max-spp", "32", "--final-spp", "64",
                   "--iterations", "2", "--map-spp", "4", "--variant", VARIANT, "-q"])
    out = capsys.readouterr().out
    assert status == 0, out
    assert json.loads((tmp_path / "fit" / "result.json").read_text())["estimates"]["aod_550"]["value"] > 0.0
