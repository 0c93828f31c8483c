"""Polarized rendering as users meet it: turned on by the scene file, the keyword or the command
line; Stokes vectors in the Sky, the EXR's S0-S3, DoLP and AoLP layers and the PNG previews;
bad values refused before any work; scalar renders as before."""

import numpy as np
import OpenEXR
import pytest
from PIL import Image

from skyref.cli import main
from skyref.errors import ParameterError
from skyref.io.exr import channel_name, read_sky_exr
from skyref.render import check_image_size, render_sky, render_to_error
from skyref.scene import Camera, RenderSettings, Scene, load_scene
from skyref.sky import STOKES, Sky, angle_of_linear_polarization, degree_of_linear_polarization

WAVELENGTHS = (680.0, 550.0, 440.0)        # "rgb"
#: The output is the subject here, not the estimator (both are tested polarized, below and in
#: test_polarization.py, test_iprt.py): the baseline's kernels compile in seconds.
SCENE = """\
[camera]
type = "equirectangular"
width = 8
height = 4
[render]
spp = 16
passes = 4
seed = 7
estimator = "delta_tracking"
"""


def write_scene(tmp_path, extra="", name="scene.toml"):
    path = tmp_path / name
    path.write_text(SCENE + extra)
    return path


def exr_channels(path):
    with OpenEXR.File(str(path), separate_channels=True) as exr:
        return dict(exr.header()), {name: np.array(ch.pixels) for name, ch in exr.channels().items()}


def stack(channels, layer):
    """(H, W, N) of channels ``layer + <wavelength>nm``, in WAVELENGTHS order."""
    return np.stack([channels[layer + f"{w:.6f}".replace(".", ",") + "nm"] for w in WAVELENGTHS], axis=-1)


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    directory = tmp_path_factory.mktemp("scenes")
    return {"scalar": write_scene(directory, name="scalar.toml"),
            "polarized": write_scene(directory, "polarized = true\n", name="polarized.toml")}


@pytest.fixture(scope="module")
def polarized_sky(mi, scenes):
    """The polarized scene file's sky: the TOML turns polarization on."""
    return render_sky(load_scene(scenes["polarized"]))


# --- turning it on -----------------------------------------------------------------------------

def test_the_scene_file_turns_it_on(polarized_sky):
    sky = polarized_sky
    assert sky.polarized and sky.scene.render.polarized
    assert sky.stokes.shape == (4, 8, 4, 3) and sky.stokes_error.shape == (4, 8, 4, 3)
    assert np.array_equal(sky.radiance, sky.I) and np.array_equal(sky.radiance, sky.stokes[..., 0, :])
    assert np.array_equal(sky.standard_error, sky.stokes_error[..., 0, :])
    # the orders are I per order, and add up to it; their Stokes vectors add up to the sky's
    assert np.allclose(sum(sky.orders.values()), sky.radiance, rtol=1e-5, atol=0.0)
    assert set(sky.order_stokes) == set(sky.orders)
    for name, values in sky.order_stokes.items():
        assert values.shape == (4, 8, 4, 3) and np.array_equal(values[..., 0, :], sky.orders[name])
    scale = np.abs(sky.stokes).max(axis=(0, 1, 2))
    assert np.allclose(sum(sky.order_stokes.values()), sky.stokes, rtol=0.0, atol=1e-5 * scale.max())
    # the sun seen directly is unpolarized; single scattering is polarized more than the whole sky
    assert np.all(sky.order_stokes["sun_direct"][..., 1:, :] == 0.0)
    single = degree_of_linear_polarization(sky.order_stokes["single"])
    assert np.nanmax(single[:2]) > sky.degree_of_linear_polarization()[:2].max()
    assert np.all(np.isfinite(sky.stokes)) and np.all(sky.radiance > 0)
    sky_rows, ground_rows = slice(0, 2), slice(2, 4)
    dolp = sky.degree_of_linear_polarization()
    # The sky is polarized (Rayleigh scattering); the ground under an observer standing on it
    # reflects unpolarized light (Lambertian), and the sky's light scatters in no air on the way.
    assert dolp[sky_rows].max() > 0.3 and np.all(dolp[ground_rows] == 0.0)
    assert np.all(sky.V == 0.0)        # no circular polarization from Rayleigh or P11-only aerosols


def test_the_keyword_turns_it_on_and_off(mi, scenes, polarized_sky):
    """The keyword overrides the scene both ways; the same seed gives the same bits."""
    on = render_sky(load_scene(scenes["scalar"]), polarized=True)
    assert on.polarized and np.array_equal(on.stokes, polarized_sky.stokes)
    off = render_sky(load_scene(scenes["polarized"]), polarized=False)
    assert not off.polarized and off.stokes is None and off.stokes_error is None
    assert not off.scene.render.polarized and off.radiance.shape == (4, 8, 3)


def test_the_command_line_turns_it_on_and_writes_s0_to_s3(mi, scenes, polarized_sky, tmp_path, capsys):
    exr, png = tmp_path / "sky.exr", tmp_path / "sky.png"
    assert main(["render", str(scenes["scalar"]), "-o", str(exr), "--png", str(png), "--polarized", "-q"]) == 0
    assert "polarized, degree of linear polarization (luminance) median" in capsys.readouterr().out
    header, channels = exr_channels(exr)
    assert header["polarisationHandedness"] == "right" and "meridian" in header["skyref.stokesFrame"]
    assert 'polarized = true' in header["skyref.scene"]
    spectral = [name for name in channels if name not in ("R", "G", "B")]
    # every Stokes component and its error, the Stokes vector per order, DoLP and AoLP, at every wavelength
    layers = ([f"S{s}." for s in range(4)] + [f"stderr.S{s}." for s in range(4)]
              + [f"{order}.S{s}." for order in polarized_sky.orders for s in range(4)] + ["DoLP.", "AoLP."])
    assert len(spectral) == len(layers) * 3
    stokes = np.stack([stack(channels, f"S{s}.") for s in range(4)], axis=-2)
    # S0 is the render's I (same seed, float32 both): bit for bit, and so is the rest
    assert np.array_equal(stokes[..., 0, :], polarized_sky.I)
    assert np.array_equal(stokes, polarized_sky.stokes)
    assert np.array_equal(np.stack([stack(channels, f"stderr.S{s}.") for s in range(4)], axis=-2),
                          polarized_sky.stokes_error)
    dolp, aolp = stack(channels, "DoLP."), stack(channels, "AoLP.")
    assert np.all((dolp >= 0.0) & (dolp <= 1.0)) and dolp.max() > 0.3
    assert np.all((aolp >= -90.0) & (aolp <= 90.0)) and np.ptp(aolp[:2]) > 45.0
    assert np.allclose(dolp, polarized_sky.degree_of_linear_polarization(), rtol=1e-6, atol=1e-7)
    assert np.allclose(aolp, polarized_sky.angle_of_linear_polarization(), rtol=0.0, atol=1e-4)
    # previews beside the sRGB one
    for name in ("sky.png", "sky.dolp.png", "sky.aolp.png"):
        assert np.asarray(Image.open(tmp_path / name)).shape == (4, 8, 3)
    back = read_sky_exr(exr)
    assert back.polarized and np.array_equal(back.stokes, polarized_sky.stokes)
    assert np.array_equal(back.stokes_error, polarized_sky.stokes_error)
    assert back.order_stokes.keys() == polarized_sky.order_stokes.keys()
    for name, values in back.order_stokes.items():
        assert np.array_equal(values, polarized_sky.order_stokes[name])


def test_previews_show_dolp_on_viridis_and_aolp_as_hue(polarized_sky):
    from matplotlib import colormaps

    from skyref.io.polarization import aolp_image, dolp_image, luminance_stokes

    dolp_png, aolp_png = dolp_image(polarized_sky), aolp_image(polarized_sky)
    dolp = degree_of_linear_polarization(luminance_stokes(polarized_sky), axis=-1)
    want = np.round(colormaps["viridis"](dolp)[..., :3] * 255.0)
    assert np.abs(dolp_png.astype(int) - want).max() <= 1
    # the unpolarized ground is black in the AoLP preview (the angle means nothing there)
    assert np.all(aolp_png[2:] == 0) and aolp_png[:2].max() > 60


def test_an_adaptive_render_carries_the_stokes_axis(mi):
    """Rounds pool every Stokes component; pixels outside the region are NaN in all of them."""
    scene = Scene(camera=Camera(width=8, height=4), render=RenderSettings(passes=4, region="above_horizon",
                                                                          polarized=True, estimator="delta_tracking"))
    sky = render_to_error(scene, 0.02, seeds=[1, 2], max_spp=64, initial_spp=16)
    assert sky.polarized and sky.stokes.shape == (4, 8, 4, 3)
    assert np.all(np.isnan(sky.stokes[2:])) and np.all(np.isfinite(sky.stokes[:2]))
    assert np.array_equal(sky.radiance, sky.I, equal_nan=True)
    assert np.all(sky.stokes_error[:2, :, 1:3] > 0.0)      # Q and U vary between passes
    assert sky.metadata["spp_range"][1] > 16                # a second round ran


# --- bad input and what cannot be polarized -----------------------------------------------------------

@pytest.mark.parametrize("value", ['"yes"', "1", "[true]"])
def test_a_scene_file_with_a_bad_value_is_refused(value, tmp_path, capsys):
    scene = write_scene(tmp_path, f"polarized = {value}\n")
    with pytest.raises(ParameterError, match="render.polarized") as info:
        load_scene(scene)
    assert info.value.valid == "true or false" and info.value.problem == "not a boolean"
    assert main(["render", str(scene), "-o", str(tmp_path / "sky.exr"), "--png", str(tmp_path / "sky.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("skyref render: error: render.polarized = ")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.toml"]


def test_the_keyword_refuses_a_bad_value_before_any_work():
    with pytest.raises(ParameterError, match=r"render.polarized = 'yes': not a boolean"):
        render_sky(Scene(camera=Camera(width=8, height=4)), polarized="yes")


def test_the_command_line_refuses_previews_it_cannot_write(scenes, tmp_path, capsys):
    (tmp_path / "sky.dolp.png").mkdir()
    args = ["render", str(scenes["polarized"]), "-o", str(tmp_path / "sky.exr"), "--png", str(tmp_path / "sky.png")]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("skyref render: error: --png = ") and "sky.dolp.png" in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sky.dolp.png"]


def test_both_estimators_render_stokes_vectors(mi):
    """The line integral and delta tracking, polarized, on the same small sky: Stokes axes of
    the same shape, I = the sky's radiance, and their I within their joint noise."""
    scene = Scene(camera=Camera(width=8, height=4))
    skies = {name: render_sky(scene, spp=64, passes=4, polarized=True, estimator=name)
             for name in ("line_integral", "delta_tracking")}
    for sky in skies.values():
        assert sky.stokes.shape == (4, 8, 4, 3) and np.array_equal(sky.I, sky.radiance)
    a, b = skies["line_integral"], skies["delta_tracking"]
    lit = (a.radiance > 0) & (b.radiance > 0) & np.isfinite(a.radiance)
    z = (a.radiance - b.radiance)[lit] / np.hypot(a.standard_error, b.standard_error)[lit]
    assert lit.sum() > 30 and np.median(np.abs(z)) < 2.0


def polarized_grid(tmp_path, output_format="spectral"):
    grid = tmp_path / "grid.toml"
    grid.write_text('[base.scene]\ncamera = { type = "equirectangular", width = 8, height = 4 }\n'
                    'spectral = { wavelengths = "rgb" }\n'
                    'render = { polarized = true, estimator = "delta_tracking" }\n'
                    '[axes]\n"sun.zenith_deg" = [30, 60]\n'
                    f'[output]\ndirectory = "{tmp_path / "out"}"\nformat = "{output_format}"\nspp = 16\npasses = 4\n')
    return grid


def test_a_polarized_batch_holds_the_stokes_vectors_of_its_exrs(mi, tmp_path):
    """A polarized grid's dataset (zarr and its netCDF copy) holds, per sky, the Stokes vectors
    and their standard errors of the sky's EXR, value for value; its radiance is I; the
    stokes_component coordinate names the components and their frame."""
    import xarray as xr

    from skyref.io.exr import STOKES_FRAME

    assert main(["batch", str(polarized_grid(tmp_path)), "--workers", "1", "--netcdf", "-q"]) == 0
    out = tmp_path / "out"
    with xr.open_zarr(out / "dataset.zarr") as zarr_copy, xr.open_dataset(out / "dataset.nc") as netcdf_copy:
        for dataset in (zarr_copy.load(), netcdf_copy.load()):
            assert dataset["stokes"].dims == ("sun_zenith_deg", "row", "column", "stokes_component", "wavelength")
            assert dataset["stokes"].shape == (2, 4, 8, 4, 3)
            assert list(dataset["stokes_component"].values) == list(STOKES)
            assert dataset["stokes_component"].attrs["reference_frame"] == STOKES_FRAME
            exrs = sorted((out / "skies").iterdir())
            assert len(exrs) == 2
            for exr in exrs:
                sky = read_sky_exr(exr)
                row = dataset.sel(sun_zenith_deg=sky.scene.sun.zenith_deg)
                assert np.array_equal(row["stokes"].values, sky.stokes)
                assert np.array_equal(row["stokes_standard_error"].values, sky.stokes_error)
                assert np.array_equal(row["radiance"].values, sky.stokes[..., 0, :])
                assert np.abs(sky.Q).max() > 0.05 * sky.I.max()          # the sky is polarized


def test_a_polarized_batch_needs_the_spectral_format(tmp_path, capsys):
    from skyref.batch.grid import load_grid

    grid = polarized_grid(tmp_path, output_format="rgb")
    with pytest.raises(ParameterError, match="render.polarized = True: output.format = 'rgb' holds radiance only") \
            as info:
        load_grid(grid).validate()
    assert info.value.name == "base.scene"
    assert main(["batch", str(grid), "-q"]) == 2 and not (tmp_path / "out").exists()
    assert "render.polarized = True" in capsys.readouterr().err


def test_the_image_size_check_counts_stokes_components():
    big = Camera(width=2048, height=2048)                   # 4.2 M pixels: 2^30 values allow 5.6 M scalar
    check_image_size(Scene(camera=big), 16)
    with pytest.raises(ParameterError, match=r"polarized: 4 Stokes components"):
        check_image_size(Scene(camera=big, render=RenderSettings(polarized=True)), 16)


# --- the Sky's Stokes API and scalar output -------------------------------------------------------

def test_dolp_and_aolp_of_known_vectors():
    stokes = np.array([[1.0, 0.5, 0.0, 0.0], [1.0, 0.0, 0.5, 0.0], [1.0, -0.5, 0.0, 0.2], [2.0, 0.0, -2.0, 0.0],
                       [0.0, 0.0, 0.0, 0.0]])
    assert np.allclose(degree_of_linear_polarization(stokes, axis=-1)[:4], [0.5, 0.5, 0.5, 1.0])
    assert np.allclose(angle_of_linear_polarization(stokes, axis=-1)[:4], [0.0, 45.0, 90.0, -45.0])
    assert np.isnan(degree_of_linear_polarization(stokes, axis=-1)[4])
    assert np.isnan(angle_of_linear_polarization(stokes, axis=-1)[4])


def test_a_scalar_sky_says_how_to_get_stokes_components():
    sky = Sky(radiance=np.ones((1, 1, 3)), standard_error=np.zeros((1, 1, 3)), wavelengths_nm=np.array(WAVELENGTHS),
              directions=np.zeros((1, 1, 3)))
    assert not sky.polarized
    with pytest.raises(ParameterError, match="rendered without polarization") as info:
        sky.Q
    assert "polarized = true" in info.value.valid
    with pytest.raises(ParameterError, match="not a Stokes component"):
        sky.stokes_component("P")


def test_scalar_scenes_serialise_as_before():
    assert "polarized" not in RenderSettings().to_dict()
    assert RenderSettings(polarized=True).to_dict()["polarized"] is True
    assert Scene.from_dict(Scene(render=RenderSettings(polarized=True)).to_dict()).render.polarized


def test_a_scalar_render_writes_the_layers_it_always_wrote(mi, scenes, tmp_path):
    exr, png = tmp_path / "sky.exr", tmp_path / "sky.png"
    assert main(["render", str(scenes["scalar"]), "-o", str(exr), "--png", str(png), "-q"]) == 0
    header, channels = exr_channels(exr)
    names = [f"{w:.6f}".replace(".", ",") + "nm" for w in WAVELENGTHS]
    want = ({"R", "G", "B"} | {f"S0.{n}" for n in names} | {f"stderr.S0.{n}" for n in names}
            | {f"{o}.S0.{n}" for o in ("sun_direct", "single", "double", "higher") for n in names})
    assert set(channels) == want and channel_name(550.0) == "S0.550,000000nm"
    assert "polarisationHandedness" not in header and "skyref.stokesFrame" not in header
    assert "polarized" not in header["skyref.scene"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sky.exr", "sky.png"]
    assert not read_sky_exr(exr).polarized


def test_a_paired_render_measures_the_polarized_change_of_i_with_its_own_error_bars(mi):
    """Scalar and polarized transport of a hazy sky traced with the same samples (render_paired).
    Each sky is bit for bit the render render_sky gives with that seed (whose accuracy the DISORT
    and IPRT tests check); what is new is the standard error of their difference. Two pairs with
    other seeds agree within it value by value (mean z^2 near 1; an error bar 2x too small gives
    ~4); the change agrees with the one from two independent renders at 4x the samples; and the
    paired standard error is under half of the two renders' errors combined as if independent."""
    from skyref.atmosphere import from_turbidity
    from skyref.render import render_paired
    from skyref.scene import Sun

    scene = Scene(atmosphere=from_turbidity(6.0), sun=Sun(zenith_deg=40.0), camera=Camera(width=8, height=4),
                  wavelengths="rgb", render=RenderSettings(passes=16, pixel_sampling="centre", estimator="line_integral"))
    polarized_scene = scene.replace(render=RenderSettings(passes=16, pixel_sampling="centre",
                                                          estimator="line_integral", polarized=True))
    pairs = [render_paired(scene, polarized_scene, spp=4096, seed=seed) for seed in (5, 6)]
    np.testing.assert_array_equal(pairs[0][0].radiance, render_sky(scene, spp=4096, seed=5, symmetry=False).radiance)
    changes = [polarized.radiance - scalar.radiance for scalar, polarized, _ in pairs]
    z_pairs = (changes[0] - changes[1]) / np.hypot(pairs[0][2], pairs[1][2])
    assert z_pairs.size == 96 and np.all(np.isfinite(z_pairs))
    assert 0.5 < np.mean(z_pairs ** 2) < 1.9, np.mean(z_pairs ** 2)
    independent = [render_sky(scene, spp=16384, seed=7, symmetry=False),
                   render_sky(polarized_scene, spp=16384, seed=8, symmetry=False)]
    reference = independent[1].radiance - independent[0].radiance
    reference_error = np.hypot(independent[0].standard_error, independent[1].standard_error)
    z = (changes[0] - reference) / np.hypot(pairs[0][2], reference_error)
    assert 0.4 < np.mean(z ** 2) < 1.9, np.mean(z ** 2)
    scalar, polarized, paired_error = pairs[0]
    as_if_independent = np.hypot(scalar.standard_error, polarized.standard_error)
    assert np.median(paired_error / as_if_independent) < 0.5, np.median(paired_error / as_if_independent)


def test_a_scalar_truth_plus_the_paired_change_is_the_polarized_truth(mi):
    """The LUT audit's polarized truth (skyref.audit.groundtruth.with_polarization): a scalar
    render plus the paired polarization change of other seeds, against a polarized render of its
    own. Value by value within the combined standard errors (mean z^2 near 1), while the scalar
    render alone is many standard errors off the polarized one (the test can fail)."""
    from skyref.atmosphere import bruneton2017
    from skyref.audit.groundtruth import polarization_change, with_polarization
    from skyref.scene import Sun

    scene = Scene(atmosphere=bruneton2017(), sun=Sun(zenith_deg=40.0), camera=Camera(width=8, height=4),
                  wavelengths="rgb", render=RenderSettings(passes=16, pixel_sampling="centre", estimator="line_integral"))
    polarized_scene = scene.replace(render=RenderSettings(passes=16, pixel_sampling="centre",
                                                          estimator="line_integral", polarized=True))
    truth = render_sky(scene, spp=16384, seed=11, symmetry=False)
    change, change_error, cpu_s = polarization_change(scene, spp=4096, seed=12)
    composed = with_polarization(truth, change, change_error)
    direct = render_sky(polarized_scene, spp=16384, seed=13, symmetry=False)
    lit = truth.radiance > 0.0
    z = ((composed.radiance - direct.radiance) / np.hypot(composed.standard_error, direct.standard_error))[lit]
    z_scalar = ((truth.radiance - direct.radiance) / np.hypot(truth.standard_error, direct.standard_error))[lit]
    assert z.size > 60 and np.all(np.isfinite(z))
    assert 0.4 < np.mean(z ** 2) < 1.9, np.mean(z ** 2)
    assert np.mean(z_scalar ** 2) > 10.0, np.mean(z_scalar ** 2)
    np.testing.assert_allclose(composed.standard_error, np.hypot(truth.standard_error, change_error))
    assert cpu_s > 0.0 and set(composed.orders) <= {"sun_direct"}
