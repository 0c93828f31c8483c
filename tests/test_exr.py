"""Spectral EXR (Fichet et al. 2021 layout) and PNG previews: round trips, channel names,
header attributes, atomic writes, clear errors."""

import json
import os
import re
import tomllib

import numpy as np
import OpenEXR
import pytest
from PIL import Image

from skyref import color, projection
from skyref.errors import ParameterError
from skyref.io.exr import read_sky_exr, write_sky_exr
from skyref.io.png import write_png
from skyref.scene import Camera, Scene
from skyref.sky import Sky

# The layout's emissive channel pattern, from the paper: S<stokes>.<number with a decimal
# comma, optional exponent><optional SI prefix><m or Hz>.
FICHET_EMISSIVE = re.compile(r"^(S[0-3])\.(\d*,?\d*([Ee][+-]?\d+)?)(Y|Z|E|P|T|G|M|k|h|da|d|c|m|u|n|p)?(m|Hz)$")
WAVELENGTHS = (700.5, 412.25, 550.0, 480.125, 620.0)     # deliberately not sorted
HEIGHT, WIDTH = 4, 6


def random_sky(with_scene=True, seed=0):
    rng = np.random.default_rng(seed)
    shape = (HEIGHT, WIDTH, len(WAVELENGTHS))
    scene = Scene(camera=Camera("equirectangular", width=WIDTH, height=HEIGHT), wavelengths=WAVELENGTHS,
                  name="round-trip") if with_scene else None
    layer = lambda scale: (rng.random(shape) * scale).astype(np.float32)  # noqa: E731
    return Sky(radiance=layer(0.3), standard_error=layer(1e-3), wavelengths_nm=np.array(WAVELENGTHS),
               directions=np.zeros((HEIGHT, WIDTH, 3)), orders={"single": layer(0.2), "higher": layer(0.01)},
               scene=scene, metadata={"spp": np.int64(64), "seconds": 1.5, "tags": ["a", "b"],
                                      "per_pass": np.arange(3.0)})


def read_raw(path):
    with OpenEXR.File(str(path), separate_channels=True) as exr:
        return dict(exr.header()), {name: (ch.pixels, ch.type()) for name, ch in exr.channels().items()}


def comma(w):
    return f"{w:.6f}".replace(".", ",")


def test_round_trip_is_bit_exact(tmp_path):
    sky = random_sky()
    path = tmp_path / "sky.exr"
    write_sky_exr(sky, path)
    back = read_sky_exr(path)
    assert np.array_equal(back.wavelengths_nm, np.array(WAVELENGTHS))      # the scene's order
    for name in ("radiance", "standard_error"):
        assert getattr(back, name).dtype == np.float32
        assert np.array_equal(getattr(back, name), getattr(sky, name))
    assert set(back.orders) == {"single", "higher"}
    for order, values in sky.orders.items():
        assert np.array_equal(back.orders[order], values)
    assert back.scene.to_dict() == sky.scene.to_dict()
    assert back.metadata == {"spp": 64, "seconds": 1.5, "tags": ["a", "b"], "per_pass": [0.0, 1.0, 2.0]}
    assert np.array_equal(back.directions, projection.pixel_directions(sky.scene.camera))


def test_round_trip_without_scene(tmp_path):
    sky = random_sky(with_scene=False)
    sky.orders = {}
    write_sky_exr(sky, tmp_path / "sky.exr")
    back = read_sky_exr(tmp_path / "sky.exr")
    order = np.argsort(WAVELENGTHS)
    assert np.array_equal(back.wavelengths_nm, np.sort(WAVELENGTHS))
    assert np.array_equal(back.radiance, sky.radiance[..., order])
    assert np.array_equal(back.standard_error, sky.standard_error[..., order])
    assert back.scene is None and back.orders == {}
    assert back.directions.shape == (HEIGHT, WIDTH, 3) and np.all(np.isnan(back.directions))


def test_channels_follow_the_spectral_layout(tmp_path):
    sky = random_sky()
    path = tmp_path / "sky.exr"
    write_sky_exr(sky, path)
    header, channels = read_raw(path)
    expected = {"R", "G", "B"}
    for w in WAVELENGTHS:
        expected |= {f"S0.{comma(w)}nm", f"stderr.S0.{comma(w)}nm", f"single.S0.{comma(w)}nm",
                     f"higher.S0.{comma(w)}nm"}
    assert set(channels) == expected
    spectral = [n for n in channels if FICHET_EMISSIVE.match(n)]
    assert sorted(spectral) == sorted(f"S0.{comma(w)}nm" for w in WAVELENGTHS)
    assert "S0.550,000000nm" in channels and "S0.412,250000nm" in channels
    for name in channels:
        layer_free = name.split(".", 1)[1] if name.count(".") == 2 else name
        assert name in "RGB" or FICHET_EMISSIVE.match(layer_free)
        assert channels[name][1] == OpenEXR.FLOAT
    assert np.array_equal(channels["S0.620,000000nm"][0], sky.radiance[..., 4])
    assert np.array_equal(channels["stderr.S0.480,125000nm"][0], sky.standard_error[..., 3])
    # Preview: linear sRGB of the radiance.
    rgb = color.spectral_to_linear_srgb(sky.radiance, WAVELENGTHS)
    preview = np.stack([channels[c][0] for c in "RGB"], axis=-1)
    assert np.allclose(preview, rgb, rtol=1e-6)
    # Header attributes.
    assert header["spectralLayoutVersion"] == "1.0"
    assert header["emissiveUnits"] == "W.m^-2.sr^-1"
    assert tomllib.loads(header["skyref.scene"])["camera"]["type"] == "equirectangular"
    assert json.loads(header["skyref.metadata"])["spp"] == 64


def test_failed_write_leaves_no_file(tmp_path, monkeypatch):
    path = tmp_path / "sky.exr"
    sky = random_sky()

    class FailingFile:
        """Writes half a file, then dies (as a killed writer would)."""

        def __init__(self, *args):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def write(self, target):
            with open(target, "wb") as f:
                f.write(b"v/1\x01partial")
            raise KeyboardInterrupt

    monkeypatch.setattr(OpenEXR, "File", FailingFile)
    with pytest.raises(KeyboardInterrupt):
        write_sky_exr(sky, path)
    assert os.listdir(tmp_path) == []
    # An existing file survives a failed overwrite untouched.
    monkeypatch.undo()
    write_sky_exr(sky, path)
    before = path.read_bytes()
    monkeypatch.setattr(OpenEXR, "File", FailingFile)
    with pytest.raises(KeyboardInterrupt):
        write_sky_exr(random_sky(seed=1), path)
    assert os.listdir(tmp_path) == ["sky.exr"] and path.read_bytes() == before


def test_read_errors(tmp_path):
    with pytest.raises(ParameterError, match="file not found"):
        read_sky_exr(tmp_path / "missing.exr")
    garbage = tmp_path / "garbage.exr"
    garbage.write_bytes(b"not an exr" * 10)
    with pytest.raises(ParameterError, match="unreadable"):
        read_sky_exr(garbage)
    rgb_only = tmp_path / "rgb.exr"
    with OpenEXR.File({}, {c: np.zeros((2, 2), np.float32) for c in "RGB"}) as exr:
        exr.write(str(rgb_only))
    with pytest.raises(ParameterError, match="no spectral channels"):
        read_sky_exr(rgb_only)


def test_write_errors(tmp_path):
    sky = random_sky()
    sky.standard_error = sky.standard_error[:, :-1]
    with pytest.raises(ParameterError, match="sky.standard_error"):
        write_sky_exr(sky, tmp_path / "a.exr")
    sky = random_sky()
    sky.orders["quadruple"] = sky.radiance
    with pytest.raises(ParameterError, match="quadruple"):
        write_sky_exr(sky, tmp_path / "a.exr")
    assert os.listdir(tmp_path) == []


def test_png_preview(tmp_path):
    sky = random_sky()
    write_png(sky, tmp_path / "sky.png")
    image = np.array(Image.open(tmp_path / "sky.png"))
    assert image.shape == (HEIGHT, WIDTH, 3) and image.dtype == np.uint8
    assert np.array_equal(image, color.tonemap_srgb8(sky.rgb()))
    write_png(np.ones((2, 3, 3)), tmp_path / "grey.png", exposure=1.0)
    # Grey 1 -> Reinhard 0.5 -> sRGB 0.7354 -> 188.
    assert np.all(np.array(Image.open(tmp_path / "grey.png")) == 188)
    with pytest.raises(ParameterError):
        write_png(np.ones((2, 3)), tmp_path / "bad.png")


# --- wavelengths survive the channel names exactly --------------------------------------------

from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from skyref.io.exr import channel_name  # noqa: E402

# skyref's default grid ends at 830 nm, read back as 830.0000000000001 before channel names were
# parsed as exact decimals (outside the ozone data, so `skyref invert` refused its own render).
GRID_WAVELENGTHS = st.floats(min_value=360.0, max_value=830.0, allow_nan=False)


@given(st.floats(min_value=1.0, max_value=1.0e6, allow_nan=False))
def test_a_channel_name_reads_back_as_its_decimal(wavelength):
    """A name keeps 6 decimals: it reads back as exactly the float nearest that decimal."""
    from skyref.io.exr import _CHANNEL, _channel_wavelength_nm

    name = channel_name(wavelength)
    assert _channel_wavelength_nm(_CHANNEL.match(name)) == float(f"{wavelength:.6f}")


@settings(max_examples=40, deadline=None)
@given(st.lists(GRID_WAVELENGTHS, min_size=1, max_size=6, unique_by=lambda w: f"{w:.6f}"),
       st.sampled_from([None, 0.1, 1.0, 10.0]))
def test_any_grid_survives_the_round_trip_exactly(tmp_path_factory, wavelengths, step):
    """Any grid — arbitrary floats, or a start/stop/step grid whose values are not short
    decimals — comes back as exactly the scene's wavelengths (from the header), in its order."""
    if step is not None:
        start = min(wavelengths)
        grid = {"start_nm": start, "stop_nm": min(start + 5 * step, 830.0), "step_nm": step}
    else:
        grid = list(wavelengths)
    scene = Scene(camera=Camera("equirectangular", width=2, height=1), wavelengths=grid, name="grid")
    exact = scene.wavelengths_nm
    radiance = np.arange(2 * exact.size, dtype=np.float32).reshape(1, 2, exact.size)
    sky = Sky(radiance=radiance, standard_error=radiance * 0.01, wavelengths_nm=exact,
              directions=np.zeros((1, 2, 3)), orders={}, scene=scene, metadata={})
    path = tmp_path_factory.mktemp("grid") / "sky.exr"
    write_sky_exr(sky, path)
    back = read_sky_exr(path)
    assert back.wavelengths_nm.tolist() == exact.tolist()
    assert np.array_equal(back.radiance, radiance)
    scene.atmosphere.check_wavelengths(back.wavelengths_nm)     # within every spectrum's data
