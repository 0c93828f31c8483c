"""The fitter: recovery of known coefficients (Hosek–Wilkie and the Perez baseline), what the
joint refinement buys, export/import round trips, the C header against the Python evaluator,
training data from a batch dataset, the CLI, and bad inputs."""

import argparse
import dataclasses
import math
import os
import shutil
import subprocess

import numpy as np
import pytest

from skyref.analytic.hosek import (CHANNELS, CoefficientTable, bezier_weights, elevation_parameter,
                                   published_table)
from skyref.errors import ParameterError
from skyref.fit import forms
from skyref.fit.evaluate import relative_errors
from skyref.fit.export import HEADER_NAMES, read_tables, write_tables
from skyref.fit.fitter import default_start, fit_table
from skyref.fit.training import load_batch_dataset, synthesize
from skyref.projection import pixel_directions, solid_angle
from skyref.scene import Camera

C_EVALUATOR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "skyref", "fit", "c", "hosek_eval.c")
#: One camera for every fit here (168 directions above the horizon), so jit compilations are reused.
CAMERA = Camera(type="equirectangular", width=24, height=13)
CHANNEL, ALBEDO, TURBIDITY = 3, 0, 2           # the group the recovery tests fit: 440 nm, albedo 0, T = 3


def sky_directions():
    directions = pixel_directions(CAMERA).reshape(-1, 3)
    keep = directions[:, 2] >= -1e-12
    return np.maximum(directions[keep], [-1.0, -1.0, 0.0]), solid_angle(CAMERA).reshape(-1)[keep]


def with_group(start, control, radiance_points):
    coefficients, radiances = start.coefficients.copy(), start.radiances.copy()
    coefficients[CHANNEL, ALBEDO, TURBIDITY], radiances[CHANNEL, ALBEDO, TURBIDITY] = control, radiance_points
    return CoefficientTable(start.form, start.kind, coefficients, radiances, source="test truth")


def training_for(table, elevations):
    """The group's skies as the fitter sees them: one channel, turbidity 3, albedo 0."""
    directions, omega = sky_directions()
    count = len(elevations)
    training = synthesize(table, directions, omega, np.asarray(elevations), np.full(count, 3.0), np.zeros(count))
    return dataclasses.replace(training, channels=(table.channels[CHANNEL],),
                               radiance=training.radiance[..., [CHANNEL]],
                               standard_error=training.standard_error[..., [CHANNEL]])


RADIANCE_POINTS = np.array([0.01, 0.02, 0.05, 0.1, 0.12, 0.13])


def hosek_control():
    """A well-conditioned truth inside the bounds: every term of F matters, F > 0 everywhere."""
    k = np.arange(6)[:, None]
    return np.hstack([-1.3 + 0.1 * k, -0.4 + 0.04 * k, 0.3 + 0.05 * k, 3.0 - 0.3 * k, -2.5 + 0.2 * k,
                      0.4 + 0.05 * k, 0.15 + 0.02 * k, 1.2 + 0.1 * k, 0.6 + 0.04 * k])


def normalised_truth(control, elevations):
    """The Hosek–Wilkie form leaves a factor free between L_M and F's scale coefficients; the
    fitter fixes it by making L_M the skies' mean radiance. A truth in that convention: F's scale
    coefficients divided by F's mean at each of six elevations (so the quintic through them is
    exact)."""
    x = elevation_parameter(np.asarray(elevations))
    training = training_for(with_group(published_table(), control, RADIANCE_POINTS), elevations)
    weights = training.weights()[..., 0]
    mean_f = (weights * training.radiance[..., 0]).sum(axis=1) / weights.sum(axis=1) / (bezier_weights(x) @ RADIANCE_POINTS)
    values = bezier_weights(x) @ control
    values[:, forms.scale_mask("hosek")] /= mean_f[:, None]
    return with_group(published_table(), np.linalg.solve(bezier_weights(x), values), RADIANCE_POINTS)


# Six elevations (the fewest a quintic needs), evenly spaced in x but short of the zenith: with the
# sun overhead gamma = theta everywhere, and F's terms cannot be told apart.
ELEVATIONS_6 = 0.5 * math.pi * np.array([0.0, 0.2, 0.4, 0.6, 0.8, 0.95]) ** 3


def test_fit_recovers_hosek_coefficients_from_their_skies():
    truth = normalised_truth(hosek_control(), ELEVATIONS_6)
    # The least-squares core, without the pull towards the start (published) table that real fits use.
    result = fit_table(training_for(truth, ELEVATIONS_6), joint_prior_weight=0.0)   # starts from the published table
    assert result.unconverged["joint refinement"] == 0        # stage 1 only starts the curves
    np.testing.assert_allclose(result.table.coefficients[CHANNEL, ALBEDO, TURBIDITY],
                               truth.coefficients[CHANNEL, ALBEDO, TURBIDITY], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(result.table.radiances[CHANNEL, ALBEDO, TURBIDITY], RADIANCE_POINTS, rtol=1e-7)
    assert result.fitted.sum() == 1 and result.fitted[CHANNEL, ALBEDO, TURBIDITY]
    others = np.ones(result.fitted.shape, dtype=bool)
    others[CHANNEL, ALBEDO, TURBIDITY] = False
    assert np.array_equal(result.table.coefficients[others], published_table().coefficients[others])


def test_joint_refinement_fits_the_radiance_better_than_per_configuration_curves():
    """A realistic truth (the published 440 nm curves, in bounds) at nine elevations: the
    Bezier curves through the per-configuration fits are only approximate, the joint refinement
    reduces the error of the radiance the table produces."""
    published = published_table()
    truth = with_group(published, forms.clip_into_bounds("hosek", published.coefficients[CHANNEL, ALBEDO, TURBIDITY]),
                       published.radiances[CHANNEL, ALBEDO, TURBIDITY])
    elevations = 0.5 * math.pi * np.linspace(0.0, 0.96, 9) ** 3
    training = training_for(truth, elevations)
    weights = training.weights()

    def rms(table):
        error, _ = relative_errors(table, training)
        return float(np.sqrt(np.nansum(weights * error ** 2) / weights.sum()))

    curves_only = rms(fit_table(training, joint=False).table)
    joint = rms(fit_table(training, joint_prior_weight=0.0).table)
    assert joint < 0.1 * curves_only and joint < 1e-3, (joint, curves_only)


def test_perez_baseline_recovers_its_coefficients():
    """The Perez form has no free scale: its overall radiance is fitted with F, exactly."""
    k = np.arange(6)[:, None]
    control = np.hstack([-1.1 + 0.05 * k, -0.35 + 0.03 * k, 8.0 - 0.8 * k, -3.0 + 0.2 * k, 0.3 + 0.04 * k])
    truth = with_group(default_start("perez", "spectral"), control, RADIANCE_POINTS)
    elevations = 0.5 * math.pi * np.linspace(0.0, 0.95, 8) ** 3
    result = fit_table(training_for(truth, elevations), form="perez", joint_prior_weight=0.0)
    np.testing.assert_allclose(result.table.coefficients[CHANNEL, ALBEDO, TURBIDITY], control, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(result.table.radiances[CHANNEL, ALBEDO, TURBIDITY], RADIANCE_POINTS, rtol=1e-6)


def test_skies_with_the_sun_below_the_horizon_are_left_out():
    truth = normalised_truth(hosek_control(), ELEVATIONS_6)
    elevations = np.concatenate([ELEVATIONS_6, [-0.05]])
    training = training_for(truth, elevations)
    result = fit_table(training, joint=False)
    assert result.skipped == {6: "sun below the horizon"}
    assert np.all(np.isnan(result.configurations[6]))


def test_a_group_an_unfinished_batch_leaves_short_is_not_fitted():
    """A batch still rendering has (albedo, turbidity) groups with fewer elevations than a Bezier
    curve needs: those are left at the start values (and said so), the complete groups fitted; a
    designed grid with too few elevations is still refused (test_bad_inputs_...)."""
    truth = normalised_truth(hosek_control(), ELEVATIONS_6)
    directions, omega = sky_directions()
    elevations = np.concatenate([ELEVATIONS_6, ELEVATIONS_6])
    albedos = np.repeat([0.0, 1.0], 6)
    training = synthesize(truth, directions, omega, elevations, np.full(12, 3.0), albedos)
    radiance = training.radiance[..., [CHANNEL]].copy()
    radiance[8:] = np.nan                                      # albedo 1: two of six skies rendered so far
    training = dataclasses.replace(training, channels=(truth.channels[CHANNEL],), radiance=radiance,
                                   standard_error=training.standard_error[..., [CHANNEL]])
    result = fit_table(training, joint=False)
    assert {s: why.split(" (")[0] for s, why in result.skipped.items()} == {
        **{s: "no valid radiance in some channel" for s in range(8, 12)},
        6: "too few elevations of its albedo and turbidity rendered", 7: "too few elevations of its albedo and "
        "turbidity rendered"}
    assert result.fitted[training.channel_indices[0], :, TURBIDITY].tolist() == [True, False]
    # What skyref fit prints covers the skies it fitted: the two rendered skies of the short group
    # keep the start table's values, whose error is not the fit's.
    from skyref.fit.cli import _fit_summary_lines, _summary_lines

    printed = _fit_summary_lines("test", result, training)
    assert "(the 6 skies fitted; 2 rendered skies left out" in printed[0]
    assert printed[1:] == _summary_lines("test", result.table, training.select(albedos == 0.0))[1:]
    assert printed[2] != _summary_lines("test", result.table, training)[2]   # the left-out skies differ


def test_an_unfinished_batch_is_said_to_be_one():
    """Skies with no data (a batch still rendering) are counted apart in what skyref fit prints,
    so that its error table does not claim the whole grid."""
    from skyref.fit.cli import _summary_lines, noise_line

    truth = normalised_truth(hosek_control(), ELEVATIONS_6)
    training = training_for(truth, ELEVATIONS_6)
    radiance = training.radiance.copy()
    radiance[[1, 4]] = np.nan
    unfinished = dataclasses.replace(training, radiance=radiance)
    assert noise_line(unfinished).endswith("2 of the 6 skies have no data (an unfinished batch?): "
                                           "their configurations are not fitted")
    assert "ground truth (4 of 6 skies)" in _summary_lines("test", truth, unfinished)[0]
    assert "skies have no data" not in noise_line(training)
    assert "ground truth (6 skies)" in _summary_lines("test", truth, training)[0]


def perturbed(table, seed):
    rng = np.random.default_rng(seed)
    return CoefficientTable(table.form, table.kind, table.coefficients * (1 + 1e-3 * rng.standard_normal(table.coefficients.shape)),
                            table.radiances * (1 + 1e-3 * rng.standard_normal(table.radiances.shape)), source="perturbed")


def test_export_import_round_trip_is_exact(tmp_path):
    hosek = {kind: perturbed(published_table(kind), i) for i, kind in enumerate(CHANNELS)}
    perez = {"spectral": perturbed(default_start("perez", "spectral"), 7)}
    paths = write_tables(hosek, tmp_path, "hosek", metadata={"note": "round trip"})
    paths += write_tables(perez, tmp_path, "perez")
    assert sorted(os.path.basename(p) for p in paths) == sorted(
        ["hosek.npz", "hosek.json", "perez.npz", "perez.json", *HEADER_NAMES.values()])
    for name, tables in (("hosek", hosek), ("perez", perez)):
        for ext in ("npz", "json"):
            back, metadata = read_tables(tmp_path / f"{name}.{ext}")
            assert metadata["form"] == name and set(back) == set(tables)
            for kind, table in tables.items():
                assert back[kind].form == name
                assert np.array_equal(back[kind].coefficients, table.coefficients)
                assert np.array_equal(back[kind].radiances, table.radiances)
    assert read_tables(tmp_path / "hosek.json")[1]["note"] == "round trip"
    header = (tmp_path / "ArHosekSkyModelData_Spectral.h").read_text()
    for name in ("double dataset320[]", "double datasetRad720[]", "double* datasets[]", "double* datasetsRad[]",
                 "double* solarDatasets[]", "limbDarkeningDatasets[]", "Lukas Hosek and Alexander Wilkie"):
        assert name in header
    assert "double* datasetsXYZRad[]" in (tmp_path / "ArHosekSkyModelData_CIEXYZ.h").read_text()


def test_published_npz_reads_as_published_tables():
    from importlib import resources

    with resources.as_file(resources.files("skyref.analytic") / "data" / "arhosek_v1.4a.npz") as path:
        tables, metadata = read_tables(path)
    assert set(tables) == set(CHANNELS) and metadata == {}
    for kind, table in tables.items():
        assert np.array_equal(table.coefficients, published_table(kind).coefficients)


def c_evaluator_radiances(headers, queries) -> np.ndarray:
    """skyref's C evaluator of the published layout (skyref/fit/c/hosek_eval.c), compiled
    against the three headers in the folder ``headers`` and run on ``queries`` (its input
    lines): its radiances."""
    program = os.path.join(headers, "hosek_eval")
    build = subprocess.run(["gcc", "-O2", "-std=c99", "-Wall", "-Wextra", "-Werror", "-I", str(headers),
                            C_EVALUATOR, "-lm", "-o", program], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    run = subprocess.run([program], input="\n".join(queries) + "\n", capture_output=True, text=True, check=True)
    return np.array([float(v) for v in run.stdout.split()])


@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed (run.sh installs it)")
def test_c_header_compiles_and_c_evaluator_matches_python(tmp_path):
    tables = {kind: perturbed(published_table(kind), 10 + i) for i, kind in enumerate(CHANNELS)}
    write_tables(tables, tmp_path, "hosek")
    rng = np.random.default_rng(5)
    queries, expected = [], []
    for i in range(400):
        kind = list(CHANNELS)[i % 3]
        channel = int(rng.integers(len(CHANNELS[kind])))
        elevation, turbidity = rng.uniform(-0.2, math.pi / 2), [1.0, 10.0, rng.uniform(1, 10)][i % 3]
        albedo, theta, gamma = rng.uniform(), rng.uniform(0, math.pi), rng.uniform(0, math.pi)
        queries.append(f"{list(CHANNELS).index(kind)} {channel} {elevation!r} {turbidity!r} {albedo!r} {theta!r} {gamma!r}")
        expected.append(tables[kind].radiance(theta, gamma, elevation, turbidity, albedo)[channel])
    got, expected = c_evaluator_radiances(tmp_path, queries), np.array(expected)
    assert got.shape == expected.shape and (expected > 0).mean() > 0.9
    np.testing.assert_allclose(got, expected, rtol=1e-6, atol=0.0)


# --- training data from a batch dataset -------------------------------------------------------------

WAVELENGTHS = [float(w) for w in range(360, 721, 20)]


def in_bounds(table):
    """``table`` with every control point moved inside the fitter's bounds."""
    return CoefficientTable(table.form, table.kind, forms.clip_into_bounds(table.form, table.coefficients),
                            table.radiances, source=f"{table.source}, in bounds")


def synthetic_batch(tmp_path, truth, turbidities, albedos, zeniths, wavelengths=WAVELENGTHS):
    """A ``skyref batch`` output directory written through the batch store, holding the skies of
    the spectral table ``truth`` instead of renders."""
    from skyref.atmosphere import turbidity as atmosphere_turbidity
    from skyref.batch.grid import load_grid
    from skyref.batch.store import BatchStore
    from skyref.fit.training import view_sun_angle
    from skyref.scene import Scene

    grid_path = tmp_path / "grid.toml"
    grid_path.write_text(f"""
[base.scene]
name = "synthetic"
atmosphere = {{ preset = "bruneton2017" }}
sun = {{ azimuth_deg = 187.5 }}
camera = {{ type = "equirectangular", width = {CAMERA.width}, height = {CAMERA.height} }}
spectral = {{ wavelengths = {list(wavelengths)} }}
render = {{ pixel_sampling = "centre" }}
[axes]
"atmosphere.turbidity" = {turbidities}
"atmosphere.ground_albedo" = {albedos}
"sun.zenith_deg" = {zeniths}
[output]
directory = "batch"
spp = 8
passes = 2
""")
    grid = load_grid(grid_path)
    store = BatchStore(grid)
    store.prepare(grid.validate())
    for index in range(len(grid)):
        scene = Scene.from_dict(grid.sky(index).scene)
        directions = pixel_directions(scene.camera)
        theta = np.arccos(np.clip(directions[..., 2], -1.0, 1.0))
        gamma = view_sun_angle(scene.sun.direction[None], directions.reshape(-1, 3)).reshape(theta.shape)
        radiance = truth.spectral_radiance(np.array(wavelengths), theta, gamma,
                                               math.radians(90.0 - scene.sun.zenith_deg),
                                               atmosphere_turbidity(scene.atmosphere), scene.atmosphere.ground_albedo.value)
        store.write_region(index, {"radiance": radiance.astype(np.float32),
                                   "standard_error": (0.01 * radiance).astype(np.float32),
                                   "spp": np.float32(8), "relative_error_p95": np.float32(0.01)})
    return tmp_path / "batch"


def test_batch_dataset_becomes_training_sets_with_the_right_geometry(tmp_path):
    batch = synthetic_batch(tmp_path, published_table(), [2.0, 7.0], [0.0, 1.0], [80.0, 30.0])
    sets = load_batch_dataset(batch)
    assert set(sets) == {"spectral", "xyz", "rgb"}
    spectral = sets["spectral"]
    assert spectral.channels == ("360", "400", "440", "480", "520", "560", "600", "640", "680", "720")
    assert spectral.radiance.shape == (8, 7 * CAMERA.width, 10)
    np.testing.assert_allclose(spectral.turbidity, np.repeat([2.0, 7.0], 4), rtol=1e-12)
    np.testing.assert_allclose(spectral.albedo, np.tile(np.repeat([0.0, 1.0], 2), 2))
    np.testing.assert_allclose(np.degrees(spectral.solar_elevation), np.tile([10.0, 60.0], 4), rtol=1e-12)
    assert np.all(spectral.cos_theta >= 0.0)
    # The model reproduces its own skies through the loader's geometry (float32 storage).
    error, noise = relative_errors(published_table(), spectral)
    assert np.nanmax(np.abs(error)) < 1e-6 and np.nanmedian(noise) == pytest.approx(0.01, rel=1e-3)
    # Tristimulus channels on the published model's scale: XYZ and sRGB of the published spectral
    # skies (19 wavelengths) agree with the published XYZ and RGB models to a few percent.
    for kind in ("xyz", "rgb"):
        error, noise = relative_errors(published_table(kind), sets[kind])
        assert np.sqrt(np.nanmean(error ** 2)) < 0.05, kind
        # Errors of 1% at every wavelength, fully correlated (one path serves all wavelengths):
        # 1% of every tristimulus channel, also of sRGB red, where X minus Y and Z cancels.
        np.testing.assert_allclose(noise[np.isfinite(noise)], 0.01, rtol=1e-3, err_msg=kind)


def run_cli(argv):
    from skyref.fit.cli import add_fit_parser

    parser = argparse.ArgumentParser(prog="skyref")
    add_fit_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["fit", *argv])
    return args.run(args)


def test_cli_fits_writes_and_evaluates(tmp_path, capsys):
    zeniths = [90.0 - math.degrees(e) for e in ELEVATIONS_6]
    # The published skies with every control point inside the fitter's bounds, so that a table of
    # the fitter's family reproduces them; one band keeps the test short.
    batch = synthetic_batch(tmp_path, in_bounds(published_table()), [3.0], [0.0], zeniths, wavelengths=[440.0])
    out = tmp_path / "coefficients"
    assert run_cli(["--grid", str(batch), "--out", str(out), "--no-perez", "--joint-prior-weight", "0", "-q"]) == 0
    printed = capsys.readouterr().out
    assert "noise of the data" in printed and "Hosek-Wilkie spectral: fitted" in printed
    tables, metadata = read_tables(out / "hosek.npz")
    assert set(tables) == {"spectral"} and metadata["fits"]["spectral"]["channels_fitted"] == ["440"]
    assert "Channels not fitted (start values kept): 320, 360, 400, 480" in (out / "ArHosekSkyModelData_Spectral.h").read_text()
    assert np.array_equal(tables["spectral"].coefficients[0], published_table().coefficients[0])
    # The fitted table reproduces the skies it was fitted to.
    training = load_batch_dataset(batch)["spectral"]
    error, _ = relative_errors(tables["spectral"], training)
    assert np.nanmax(np.abs(error)) < 1e-4, np.nanmax(np.abs(error))
    assert metadata["truth"] is None                       # a dataset without the batch's sky EXRs
    assert run_cli(["--evaluate", str(out / "hosek.npz"), "--grid", str(batch), "--kinds", "spectral"]) == 0
    assert run_cli(["--evaluate", "published", "--grid", str(batch)]) == 0
    report = capsys.readouterr().out
    assert "published Hosek-Wilkie 1.4a vs spectral ground truth" in report and "by elevation" in report


def test_a_fitted_table_names_its_ground_truth(tmp_path):
    """The tables carry the provenance of the skies they were fitted to (estimator, samples, CPU
    time, from the batch's EXRs and markers): in the npz/JSON metadata and the C headers."""
    import json

    from skyref.io.exr import write_sky_exr
    from skyref.scene import Scene
    from skyref.sky import Sky

    zeniths = [90.0 - math.degrees(e) for e in ELEVATIONS_6]
    batch = synthetic_batch(tmp_path, in_bounds(published_table()), [3.0], [0.0], zeniths, wavelengths=[440.0])
    (batch / "skies").mkdir(exist_ok=True)
    truth_scene = Scene(camera=CAMERA, wavelengths=(440.0,))
    values = np.ones((CAMERA.height, CAMERA.width, 1), dtype=np.float32)
    write_sky_exr(Sky(radiance=values, standard_error=0.01 * values, wavelengths_nm=np.array([440.0]),
                      directions=pixel_directions(CAMERA), scene=truth_scene,
                      metadata={"spp": 4096, "estimator": "line_integral"}), batch / "skies" / "sky-0.exr")
    (batch / "markers" / "sky-0.json").write_text(json.dumps({"task_cpu_s": 7200.0}))
    out = tmp_path / "coefficients"
    assert run_cli(["--grid", str(batch), "--out", str(out), "--no-perez", "--no-joint", "-q"]) == 0
    _, metadata = read_tables(out / "hosek.npz")
    truth = metadata["truth"]
    assert truth["estimators"] == ["line_integral"] and truth["skies"] == 1 and truth["cpu_s"] == 7200.0
    assert truth["description"].endswith("4096 samples per direction, 2.00 CPU hours")
    header = (out / "ArHosekSkyModelData_Spectral.h").read_text()
    assert f"Ground truth: skyref's path tracer, {truth['description']} (1 sky)." in header


@pytest.mark.parametrize("call,name", [
    (lambda t: fit_table(dataclasses.replace(t, turbidity=np.full(6, 2.5))), "turbidity"),
    (lambda t: fit_table(dataclasses.replace(t, albedo=np.full(6, 0.3))), "albedo"),
    (lambda t: fit_table(dataclasses.replace(t, solar_elevation=np.r_[ELEVATIONS_6[:5], ELEVATIONS_6[4]])),
     "solar_elevation"),
    (lambda t: fit_table(t, form="preetham"), "form"),
    (lambda t: fit_table(t, joint_prior_weight=-1.0), "joint_prior_weight"),
    (lambda t: run_cli(["--grid", "x", "--out", "y", "--joint-prior-weight", "-1"]), "--joint-prior-weight"),
    (lambda t: fit_table(t, start=published_table("xyz")), "start"),
    (lambda t: dataclasses.replace(t, channels=("321",)), "channels"),
    (lambda t: read_tables("no-such-file.npz"), "coefficients"),
    (lambda t: load_batch_dataset(os.path.dirname(C_EVALUATOR)), "grid"),
    (lambda t: run_cli(["--grid", os.path.dirname(C_EVALUATOR)]), "grid"),
    (lambda t: run_cli(["--grid", "x", "--evaluate", "published", "--out", "y"]), "--out"),
])
def test_bad_inputs_raise_parameter_error_naming_the_parameter(call, name):
    training = training_for(published_table(), ELEVATIONS_6)
    with pytest.raises(ParameterError) as info:
        call(training)
    assert info.value.name == name and "valid:" in str(info.value)


def test_interpolation_gap_finds_coefficients_that_do_not_blend():
    """A table whose albedo-1 skies equal its albedo-0 skies (the published albedo-0 data in both)
    blends them into the same sky at albedo 1/2: gap 0. Stored with the albedo-1 scale traded
    against L_M instead (F's scale coefficients x 3, L_M / 3: the same radiance at albedo 1), the
    blend is (1 + 3)(1 + 1/3) / 4 = 4/3 of it."""
    from skyref.fit.evaluate import interpolation_gap

    published = published_table()
    coefficients, radiances = published.coefficients.copy(), published.radiances.copy()
    coefficients[:, 1], radiances[:, 1] = coefficients[:, 0], radiances[:, 0]
    same = dataclasses.replace(published, coefficients=coefficients.copy(), radiances=radiances.copy())
    assert interpolation_gap(same)["albedo"]["p95"] < 1e-9
    coefficients[:, 1][..., forms.scale_mask("hosek")] *= 3.0
    radiances[:, 1] /= 3.0
    gap = interpolation_gap(dataclasses.replace(published, coefficients=coefficients, radiances=radiances))
    assert gap["albedo"]["median"] == pytest.approx(1.0 / 3.0, rel=1e-6)
    # Turbidity neighbours still agree, as in the published table (a few % where skies differ most).
    assert gap["turbidity"]["p95"] < 0.05 and interpolation_gap(published)["turbidity"]["p95"] < 0.05


@pytest.mark.parametrize("argv, name", [(["--kinds", "bogus"], "--kinds"), (["--out", "{file}/out"], "--out")])
def test_cli_refusals_leave_no_output_directory(tmp_path, argv, name):
    """An unknown kind or an unwritable --out is refused before anything is created."""
    batch = synthetic_batch(tmp_path, published_table(), [3.0], [0.0], [40.0], wavelengths=[440.0])
    (tmp_path / "file").write_text("")
    argv = [a.replace("{file}", str(tmp_path / "file")) for a in argv]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "coefficients")]
    with pytest.raises(ParameterError) as info:
        run_cli(["--grid", str(batch), *argv, "-q"])
    assert info.value.name == name
    assert not (tmp_path / "coefficients").exists() and not (tmp_path / "file" / "out").exists()


# --- the fit shipped with skyref ---------------------------------------------------------------------

@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed (run.sh installs it)")
def test_shipped_fit_is_one_table_in_three_forms_fitted_to_the_whole_training_grid(tmp_path):
    """skyref/analytic/data/skyref_fit: the npz, the JSON and the C headers hold the same tables
    (spectral, CIE XYZ, RGB), fitted to every sky of grids/hosek_training.toml at its error
    target; the C evaluator compiled against the three headers gives the table's
    radiances."""
    from skyref.analytic.hosek import skyref_fit_directory
    from skyref.batch.grid import load_grid

    directory = skyref_fit_directory()
    tables, metadata = read_tables(os.path.join(directory, "hosek.npz"))
    from_json, json_metadata = read_tables(os.path.join(directory, "hosek.json"))
    assert set(tables) == set(from_json) == {"spectral", "xyz", "rgb"}
    assert metadata["form"] == json_metadata["form"] == "hosek"
    for kind, table in tables.items():
        assert np.array_equal(table.coefficients, from_json[kind].coefficients)
        assert np.array_equal(table.radiances, from_json[kind].radiances)
        assert not np.array_equal(table.coefficients, published_table(kind).coefficients)
    grid = load_grid(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "grids", "hosek_training.toml"))
    assert metadata["truth"]["skies"] == len(grid) == 260
    fitted = np.array(metadata["fits"]["spectral"]["fitted_groups"])
    assert fitted[1:].all() and not fitted[0].any()   # (channel, albedo, turbidity): 360-720 nm everywhere; 320 nm lies outside the truth

    for kind in tables:
        shutil.copy(os.path.join(directory, HEADER_NAMES[kind]), tmp_path)
    rng = np.random.default_rng(11)
    queries, expected = [], []
    for i in range(300):
        kind = ("spectral", "xyz", "rgb")[i % 3]
        channel = int(rng.integers(len(CHANNELS[kind])))
        elevation, turbidity = rng.uniform(0.0, math.pi / 2), rng.uniform(1, 10)
        albedo, theta, gamma = rng.uniform(), rng.uniform(0, math.pi / 2), rng.uniform(0, math.pi)
        queries.append(f"{list(CHANNELS).index(kind)} {channel} {elevation!r} {turbidity!r} {albedo!r} {theta!r} {gamma!r}")
        expected.append(tables[kind].radiance(theta, gamma, elevation, turbidity, albedo)[channel])
    np.testing.assert_allclose(c_evaluator_radiances(tmp_path, queries), expected, rtol=1e-6, atol=0.0)
