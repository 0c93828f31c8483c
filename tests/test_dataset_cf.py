"""The batch dataset is self-describing (CF-1.10): dimension names without dots, units and
long names, view angles of every pixel that agree with closed forms of the projections and with
where the renderer put the sun, and a netCDF-3 copy equal to the zarr dataset."""

import json
import os
import re

import numpy as np
import pytest

from skyref import __version__
from skyref.batch.grid import load_grid
from skyref.errors import ParameterError

SUN_ZENITH, SUN_AZIMUTH = 56.25, 101.25      # the centre of pixel (row 2, column 4) of a 16x8 map
WIDTH, HEIGHT = 16, 8


def write_grid(tmp_path, axes: str, camera: str = f"{{ width = {WIDTH}, height = {HEIGHT} }}",
               wavelengths: str = "[440.0, 550.0, 680.0]", name: str = "grid"):
    """A grid with an inline base scene in ``tmp_path``; each pixel sees along its centre's
    direction, so the pixel centred on the sun sees the solar disk. The dataset is the subject,
    not the estimator: the baseline's kernels compile in seconds."""
    path = tmp_path / f"{name}.toml"
    path.write_text(f"""
[base.scene]
name = "cf-test"
atmosphere = {{ preset = "bruneton2017" }}
sun = {{ zenith_deg = {SUN_ZENITH}, azimuth_deg = {SUN_AZIMUTH} }}
camera = {camera}
spectral = {{ wavelengths = {wavelengths} }}
render = {{ pixel_sampling = "centre", estimator = "delta_tracking" }}
[axes]
{axes}
[output]
directory = "{name}"
spp = 8
passes = 2
""")
    return load_grid(path)


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    """Two skies rendered by ``skyref batch --netcdf``: the directory and the zarr dataset."""
    import xarray as xr

    from skyref.cli import main

    tmp_path = tmp_path_factory.mktemp("cf")
    grid = write_grid(tmp_path, '"sun.zenith_deg" = [56.25]\n"observer.altitude_m" = [0, 2000]')
    assert main(["batch", grid.source, "--workers", "1", "-q", "--netcdf"]) == 0
    return grid.output.directory, xr.open_zarr(os.path.join(grid.output.directory, "dataset.zarr")).load()


def prepared(grid):
    """The dataset of ``grid`` as a batch creates it (no sky rendered), through the store."""
    import xarray as xr

    from skyref.batch.store import BatchStore

    store = BatchStore(grid)
    store.prepare(grid.validate())
    return store, xr.open_zarr(store.dataset_path).load()


def check_cf_attributes(dataset, axes):
    """Dimensions without dots, the grid's axes first (their paths in ``skyref_axis``); a
    long_name on every variable and coordinate, units on every numeric one."""
    assert all("." not in dim for dim in dataset.dims)
    image = dataset["radiance"] if "radiance" in dataset else dataset["rgb"]
    assert [dataset[dim].attrs["skyref_axis"] for dim in image.dims[:-3]] == list(axes)
    assert image.dims[:-3] == tuple(path.replace(".", "_") for path in axes)
    for name, variable in dataset.variables.items():
        assert variable.attrs.get("long_name"), name
        if variable.dtype.kind in "iuf":
            assert variable.attrs.get("units"), name
        else:  # names, not quantities (CF: units are for quantities)
            assert "units" not in variable.attrs, name
    assert dataset.attrs["Conventions"] == "CF-1.10"
    for attribute in ("title", "source", "history", "references", "coordinate_frame"):
        assert dataset.attrs[attribute], attribute
    assert __version__ in dataset.attrs["source"] and __version__ in dataset.attrs["history"]
    for frame_word in ("east-north-up", "clockwise from north", "90 = east"):
        assert frame_word in dataset.attrs["coordinate_frame"]


def test_rendered_dataset_is_self_describing(batch):
    directory, dataset = batch
    check_cf_attributes(dataset, ["sun.zenith_deg", "observer.altitude_m"])
    assert dataset["sun_zenith_deg"].attrs["standard_name"] == "solar_zenith_angle"
    assert dataset["sun_zenith_deg"].attrs["units"] == "degree"
    assert dataset["observer_altitude_m"].attrs["units"] == "m"
    assert dataset["wavelength"].attrs == {"units": "nm", "standard_name": "radiation_wavelength",
                                           "long_name": "wavelength in vacuum"}
    assert dataset["radiance"].attrs["units"] == "W m-2 sr-1 nm-1"
    assert dataset["view_zenith_angle"].dims == dataset["view_azimuth_angle"].dims == ("row", "column")
    assert np.all(np.isfinite(dataset.radiance.values)) and np.all(dataset.spp.values == 8)


def test_view_angles_are_the_equirectangular_closed_form(batch):
    """Row i spans zenith angles [180 i / H, 180 (i + 1) / H], column j azimuths
    [360 j / W, 360 (j + 1) / W] clockwise from north; the coordinates are the centres."""
    _, dataset = batch
    rows, columns = np.mgrid[0:HEIGHT, 0:WIDTH]
    np.testing.assert_allclose(dataset.view_zenith_angle.values, 180.0 * (rows + 0.5) / HEIGHT, atol=1e-9)
    np.testing.assert_allclose(dataset.view_azimuth_angle.values, 360.0 * (columns + 0.5) / WIDTH, atol=1e-9)
    # Equirectangular pixels: solid angle 2 pi / W (cos of the top edge - cos of the bottom edge).
    top, bottom = np.radians(180.0 * rows / HEIGHT), np.radians(180.0 * (rows + 1) / HEIGHT)
    np.testing.assert_allclose(dataset.pixel_solid_angle.values, 2 * np.pi / WIDTH * (np.cos(top) - np.cos(bottom)),
                               rtol=1e-12)


def test_view_angles_point_at_the_rendered_sun(batch):
    """The sun sits at the centre of one pixel and every pixel looks along its centre: that
    pixel, and no other, sees the solar disk (orders of magnitude brighter than the sky), and its
    view angles are the sun's."""
    _, dataset = batch
    assert "centre" in dataset.radiance.attrs["comment"]
    for altitude in dataset.observer_altitude_m.values:
        sky = dataset.radiance.sel(wavelength=550.0, observer_altitude_m=altitude).isel(sun_zenith_deg=0).values
        order = np.argsort(sky.ravel())
        assert sky.ravel()[order[-1]] > 1e3 * sky.ravel()[order[-2]]
        row, column = np.unravel_index(order[-1], sky.shape)
        assert dataset.view_zenith_angle.values[row, column] == pytest.approx(SUN_ZENITH)
        assert dataset.view_azimuth_angle.values[row, column] == pytest.approx(SUN_AZIMUTH)


def test_netcdf_copy_equals_the_zarr_dataset(batch):
    import xarray as xr

    directory, dataset = batch
    path = os.path.join(directory, "dataset.nc")
    with open(path, "rb") as f:
        assert f.read(4) == b"CDF\x02"                       # netCDF-3, 64-bit offset
    assert not [name for name in os.listdir(directory) if name.startswith(".") and "tmp" in name]
    with xr.open_dataset(path, engine="scipy") as copy:
        copy = copy.load()
    xr.testing.assert_identical(copy, dataset)
    assert copy.observer_altitude_m.dtype == np.int32        # netCDF-3 has no 64-bit integers
    assert dataset.observer_altitude_m.dtype == np.int64


def test_netcdf_file_follows_cf_rules(batch):
    """A few CF-1.10 rules checked on the file itself (scipy's reader, no xarray decoding)."""
    from scipy.io import netcdf_file

    directory, _ = batch
    with netcdf_file(os.path.join(directory, "dataset.nc"), mmap=False) as f:
        assert f._attributes["Conventions"] == b"CF-1.10"
        names = list(f.dimensions) + list(f.variables)
        assert all(re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", name) for name in names), names      # CF 2.3
        for name, variable in f.variables.items():
            if variable.dimensions == (name,):           # a coordinate variable: no missing values (2.5.1)
                assert "_FillValue" not in variable._attributes, name
                values = variable.data
                assert np.all(np.diff(values) > 0) or np.all(np.diff(values) < 0), name    # monotonic (5)
        # Auxiliary coordinates (5.2): the image variables name the view angles.
        listed = f.variables["radiance"]._attributes["coordinates"].decode().split()
        assert {"view_zenith_angle", "view_azimuth_angle", "pixel_solid_angle"} <= set(listed)
        assert f.variables["view_zenith_angle"].dimensions == ("row", "column")


def test_labels_booleans_and_tables_survive_netcdf(tmp_path):
    """String, boolean, table (JSON) and nested-path axes: valid dimension names, long names,
    no units on names, units on numbers, and an identical netCDF-3 copy."""
    import xarray as xr

    axes = ('"atmosphere.preset" = ["bruneton2017", "hillaire2020"]\n"sun.limb_darkening" = [false, true]\n'
            '"atmosphere.constituents.aerosol.phase.g" = [0.7, 0.8]\n'
            '"observer" = [{ altitude_m = 0.0 }, { altitude_m = 500.0 }]')
    grid = write_grid(tmp_path, axes)
    store, dataset = prepared(grid)
    check_cf_attributes(dataset, list(grid.axes))
    assert dataset["atmosphere_constituents_aerosol_phase_g"].attrs["units"] == "1"
    assert json.loads(dataset["observer"].values[1]) == {"altitude_m": 500.0}
    store.write_netcdf()
    with xr.open_dataset(store.netcdf_path, engine="scipy") as copy:
        xr.testing.assert_identical(copy.load(), dataset)


def test_fisheye_view_angles_follow_the_sky_chart(tmp_path):
    """A fisheye looking up (equidistant, 180 deg): a pixel at distance r from the image centre
    (r = 1 at the edge's middle) looks r x 90 deg from the zenith; image up is north, image
    left east (a sky chart seen from below); outside the image circle the angles are NaN."""
    size = 16
    grid = write_grid(tmp_path, '"sun.zenith_deg" = [30.0]',
                      camera=f'{{ type = "fisheye", fov_deg = 180.0, width = {size}, height = {size} }}')
    _, dataset = prepared(grid)
    rows, columns = np.mgrid[0:size, 0:size]
    right, up = 2.0 * (columns + 0.5) / size - 1.0, 1.0 - 2.0 * (rows + 0.5) / size
    r = np.hypot(right, up)
    inside = r <= 1.0
    zenith, azimuth = dataset.view_zenith_angle.values, dataset.view_azimuth_angle.values
    np.testing.assert_allclose(zenith[inside], 90.0 * r[inside], atol=1e-9)
    expected = np.degrees(np.arctan2(-right, up)) % 360.0       # east (90) is image left
    np.testing.assert_allclose(azimuth[inside], expected[inside], atol=1e-9)
    assert np.all(np.isnan(zenith[~inside])) and np.all(np.isnan(azimuth[~inside]))
    assert "NaN" in dataset.view_zenith_angle.attrs["comment"]


def test_axes_whose_dimension_names_collide_are_refused(tmp_path):
    with pytest.raises(ParameterError) as info:
        write_grid(tmp_path, '"atmosphere.constituents.aerosol.angstrom_beta" = [0.01]\n'
                             '"atmosphere.constituents.aerosol_angstrom_beta" = [0.02]')
    assert info.value.name.startswith("axes.atmosphere.constituents.aerosol")
    assert "share" in info.value.problem


def test_too_large_for_netcdf_is_refused_before_any_work(tmp_path):
    """50 skies of 1024 x 512 pixels at 48 wavelengths: 4 bytes x 1.26e9 values = 4.7 GiB per
    image variable, beyond netCDF-3's 4 GiB."""
    from skyref.batch import run_batch

    zeniths = ", ".join(f"{z:.1f}" for z in np.linspace(0.0, 80.0, 50))
    grid = write_grid(tmp_path, f'"sun.zenith_deg" = [{zeniths}]', camera="{ width = 1024, height = 512 }",
                      wavelengths="{ start_nm = 360.0, stop_nm = 830.0, step_nm = 10.0 }")
    with pytest.raises(ParameterError) as info:
        run_batch(grid, workers=1, progress=False, netcdf=True)
    assert info.value.name == "--netcdf" and info.value.value == "4.7 GiB per image variable"
    assert not os.path.exists(grid.output.directory)
