"""Smaller EXRs: a choice of layers (radiance, error, orders, rgb) and 16-bit HALF channels;
the reader's answer to files without some layers; ``Sky.save`` by file extension."""

import os

import numpy as np
import OpenEXR
import pytest
from PIL import Image

from skyref import color
from skyref.cli import main
from skyref.errors import ParameterError
from skyref.io.exr import check_layers, read_sky_exr, write_sky_exr
from skyref.scene import Camera, Scene
from skyref.sky import Sky

WAVELENGTHS = (450.0, 550.0, 650.0)
HEIGHT, WIDTH = 3, 5


def make_sky(seed=0, scale=0.3):
    rng = np.random.default_rng(seed)
    shape = (HEIGHT, WIDTH, len(WAVELENGTHS))
    layer = lambda s: (rng.random(shape) * s).astype(np.float32)  # noqa: E731
    scene = Scene(camera=Camera("equirectangular", width=WIDTH, height=HEIGHT), wavelengths=WAVELENGTHS)
    return Sky(radiance=layer(scale), standard_error=layer(1e-3 * scale), wavelengths_nm=np.array(WAVELENGTHS),
               directions=np.zeros(shape), orders={"single": layer(scale), "double": layer(0.1 * scale)},
               scene=scene, metadata={"spp": 16})


def raw_channels(path):
    with OpenEXR.File(str(path), separate_channels=True) as exr:
        return dict(exr.header()), {name: (ch.pixels, ch.type()) for name, ch in exr.channels().items()}


def expected_channels(layers):
    """The channel names of each layer, spelled out from the layout (not from skyref's helpers)."""
    names = {"radiance": ["S0." + f"{w:.6f}".replace(".", ",") + "nm" for w in WAVELENGTHS],
             "rgb": ["R", "G", "B"]}
    names["error"] = ["stderr." + n for n in names["radiance"]]
    names["orders"] = [f"{o}.{n}" for o in ("single", "double") for n in names["radiance"]]
    return {n for layer in layers for n in names[layer]}


@pytest.mark.parametrize("layers", [("radiance",), ("rgb",), ("radiance", "error"), ("radiance", "orders"),
                                    ("error", "orders", "rgb"), ("radiance", "error", "orders", "rgb")])
def test_each_layer_choice_writes_exactly_its_channels(layers, tmp_path):
    sky = make_sky()
    path = tmp_path / "sky.exr"
    write_sky_exr(sky, path, layers=",".join(reversed(layers)))        # order and form do not matter
    header, channels = raw_channels(path)
    assert set(channels) == expected_channels(layers)
    assert "S0.550,000000nm" in channels or "radiance" not in layers
    spectral = layers != ("rgb",)
    assert ("spectralLayoutVersion" in header) == spectral and ("emissiveUnits" in header) == spectral
    if "rgb" in layers:       # the preview is the radiance's, whether or not the radiance is written
        preview = np.stack([channels[c][0] for c in "RGB"], axis=-1)
        assert np.allclose(preview, color.spectral_to_linear_srgb(sky.radiance, WAVELENGTHS), rtol=1e-6)


def test_default_is_the_complete_reference(tmp_path):
    sky = make_sky()
    write_sky_exr(sky, tmp_path / "default.exr")
    write_sky_exr(sky, tmp_path / "all.exr", layers=["radiance", "error", "orders", "rgb"])
    assert (tmp_path / "default.exr").read_bytes() == (tmp_path / "all.exr").read_bytes()
    assert set(raw_channels(tmp_path / "default.exr")[1]) == expected_channels(("radiance", "error", "orders", "rgb"))


def test_reader_without_error_and_orders(tmp_path):
    sky = make_sky()
    write_sky_exr(sky, tmp_path / "sky.exr", layers="radiance,rgb")
    back = read_sky_exr(tmp_path / "sky.exr")
    assert np.array_equal(back.radiance, sky.radiance)
    assert back.standard_error.shape == sky.radiance.shape and np.all(np.isnan(back.standard_error))
    assert back.orders == {}
    assert back.scene.to_dict() == sky.scene.to_dict() and back.metadata == {"spp": 16}


@pytest.mark.parametrize("layers, held", [("rgb", "rgb"), ("orders,error", "error, orders")])
def test_reader_needs_the_radiance(layers, held, tmp_path):
    write_sky_exr(make_sky(), tmp_path / "sky.exr", layers=layers)
    with pytest.raises(ParameterError, match=f"no spectral channels \\(it holds {held}") as info:
        read_sky_exr(tmp_path / "sky.exr")
    assert info.value.name == "path" and "radiance layer" in str(info.value)


@pytest.mark.parametrize("layers, problem", [("radiance,spectrum", "unknown layer 'spectrum'"), ("", "no layers"),
                                             (" , ", "no layers"), (["rgb", 3], "unknown layer 3"),
                                             (7, "not a string or a sequence")])
def test_bad_layers_are_refused(layers, problem, tmp_path):
    with pytest.raises(ParameterError, match=problem) as info:
        write_sky_exr(make_sky(), tmp_path / "sky.exr", layers=layers)
    assert info.value.name == "layers"
    assert info.value.valid == "a comma-separated subset of radiance, error, orders, rgb"
    assert os.listdir(tmp_path) == []


def test_layers_come_back_in_file_order():
    assert check_layers(" rgb,radiance ,rgb") == ("radiance", "rgb")
    assert check_layers(["orders"], "--layers") == ("orders",)


def test_half_rounds_to_11_bits(tmp_path):
    sky = make_sky()
    sky.radiance[0, 0] = [1e-6, 3e-5, 6.1e-5]        # half subnormals (below 2^-14 = 6.1035e-5)
    write_sky_exr(sky, tmp_path / "half.exr", half=True)
    _, channels = raw_channels(tmp_path / "half.exr")
    assert {t for _, t in channels.values()} == {OpenEXR.HALF}
    back = read_sky_exr(tmp_path / "half.exr")
    assert back.radiance.dtype == np.float32 and set(back.orders) == {"single", "double"}
    for got, want in ((back.radiance, sky.radiance), (back.standard_error, sky.standard_error),
                      (back.orders["double"], sky.orders["double"])):
        want = want.astype(np.float64)
        normal = want >= 2.0 ** -14
        # IEEE half: 11 significant bits, so round to nearest errs by at most 2^-11 relative;
        # subnormals are spaced 2^-24, so they err by at most 2^-25 absolute.
        assert np.all(np.abs(got[normal] - want[normal]) <= 2.0 ** -11 * want[normal])
        assert np.all(np.abs(got[~normal] - want[~normal]) <= 2.0 ** -25)
        assert not np.array_equal(got, want)          # it really was rounded


def test_half_halves_the_pixel_data(tmp_path):
    rng = np.random.default_rng(1)
    radiance = rng.random((32, 64, len(WAVELENGTHS))).astype(np.float32)     # noise: ZIP gains little
    sky = Sky(radiance=radiance, standard_error=radiance, wavelengths_nm=np.array(WAVELENGTHS),
              directions=np.zeros(radiance.shape))
    write_sky_exr(sky, tmp_path / "float.exr", layers="radiance")
    write_sky_exr(sky, tmp_path / "half.exr", layers="radiance", half=True)
    assert os.path.getsize(tmp_path / "float.exr") > radiance.nbytes * 0.8
    assert os.path.getsize(tmp_path / "half.exr") < 0.6 * os.path.getsize(tmp_path / "float.exr")


def test_half_clamps_and_reports_what_does_not_fit(tmp_path):
    sky = make_sky()
    sky.orders = {}
    sky.radiance[1, 2] = 1e5                          # a sun-like pixel, every wavelength above 65504
    reports = []
    write_sky_exr(sky, tmp_path / "sky.exr", layers="radiance,rgb", half=True, report=reports.append)
    rgb = color.spectral_to_linear_srgb(sky.radiance, WAVELENGTHS)[1, 2]
    expected = len(WAVELENGTHS) + int(np.count_nonzero(np.abs(rgb) > 65504.0))
    assert expected > len(WAVELENGTHS)                 # the preview of that pixel overflows too
    assert reports == [f"{tmp_path / 'sky.exr'}: {expected:,} values above 65504, the largest half float, "
                       "clamped to it"]
    _, channels = raw_channels(tmp_path / "sky.exr")
    assert all(np.all(np.isfinite(p)) for p, _ in channels.values())
    assert channels["S0.550,000000nm"][0][1, 2] == 65504.0
    # In float32 nothing is clamped, and nothing reported.
    write_sky_exr(sky, tmp_path / "float.exr", report=reports.append)
    assert len(reports) == 1 and read_sky_exr(tmp_path / "float.exr").radiance[1, 2, 0] == 1e5


def test_half_must_be_a_bool(tmp_path):
    with pytest.raises(ParameterError, match="half"):
        write_sky_exr(make_sky(), tmp_path / "sky.exr", half="yes")


# --- Sky.save ----------------------------------------------------------------------------------

def test_save_by_extension(tmp_path):
    sky = make_sky()
    sky.save(tmp_path / "sky.exr")
    assert np.array_equal(read_sky_exr(tmp_path / "sky.exr").orders["single"], sky.orders["single"])
    sky.save(str(tmp_path / "sky.PNG"))
    image = np.array(Image.open(tmp_path / "sky.PNG"))
    assert np.array_equal(image, color.tonemap_srgb8(sky.rgb()))
    sky.save(tmp_path / "grey.png", exposure=2.0)                        # options go to the writer
    assert np.array_equal(np.array(Image.open(tmp_path / "grey.png")), color.tonemap_srgb8(sky.rgb(), 2.0))
    sky.save(tmp_path / "small.exr", layers="rgb", half=True)
    assert {name: t for name, (_, t) in raw_channels(tmp_path / "small.exr")[1].items()} == \
        {c: OpenEXR.HALF for c in "RGB"}


@pytest.mark.parametrize("name", ["sky.jpg", "sky", "sky.exr.gz"])
def test_save_refuses_other_extensions(name, tmp_path):
    with pytest.raises(ParameterError, match="unknown file extension") as info:
        make_sky().save(tmp_path / name)
    assert info.value.name == "path" and ".exr" in info.value.valid and ".png" in info.value.valid
    assert os.listdir(tmp_path) == []


# --- skyref render --layers / --half ------------------------------------------------------------

def test_cli_refuses_bad_layers_before_any_work(tmp_path, capsys):
    scene = tmp_path / "scene.toml"
    scene.write_text("[camera]\nwidth = 8\nheight = 4\n")
    assert main(["render", str(scene), "-o", str(tmp_path / "sky.exr"), "--layers", "radiance,alpha"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("skyref render: error: --layers = 'radiance,alpha': unknown layer")
    assert "radiance, error, orders, rgb" in err[0]
    assert sorted(os.listdir(tmp_path)) == ["scene.toml"]


def test_cli_writes_the_chosen_layers_in_half(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text("[camera]\nwidth = 16\nheight = 8\n[render]\nspp = 4\npasses = 2\n")
    assert main(["render", str(scene), "-o", str(tmp_path / "sky.exr"), "--layers", "radiance,rgb", "--half",
                 "-q"]) == 0
    _, channels = raw_channels(tmp_path / "sky.exr")
    assert {c for c in channels if not c.startswith("S0.")} == {"R", "G", "B"}
    assert len(channels) == 3 + 3 and {t for _, t in channels.values()} == {OpenEXR.HALF}   # rgb wavelengths
    sky = read_sky_exr(tmp_path / "sky.exr")
    assert sky.radiance.shape == (8, 16, 3) and np.all(np.isfinite(sky.radiance)) and sky.orders == {}
    assert np.all(np.isnan(sky.standard_error))
