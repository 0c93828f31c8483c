"""The batch dataset: every sky of a grid in one xarray dataset that follows the CF conventions
(CF-1.10), stored as zarr (``dataset.zarr``, filled sky by sky) and, on request, copied to
netCDF-3 (``dataset.nc``) once every sky is finished.

::

    dimensions   one per grid axis, named by skyref.batch.grid.dimension_name (sun.zenith_deg ->
                 sun_zenith_deg; the axis path stays in the coordinate's ``skyref_axis``
                 attribute), then row, column and wavelength (spectral) or channel (rgb)
    radiance, standard_error  (axes..., row, column, wavelength)  W m-2 sr-1 nm-1  [spectral]
    stokes, stokes_standard_error  (axes..., row, column, stokes_component, wavelength)  W m-2 sr-1 nm-1
                              [polarized grids: I, Q, U, V in each pixel's meridian frame
                              (the coordinate's reference_frame attribute); radiance is I]
    rgb                       (axes..., row, column, channel)     cd m-2           [rgb]
    spp, relative_error_p95   (axes...)                           samples per pixel, 95th
                                                                  percentile of stderr/radiance
    view_zenith_angle, view_azimuth_angle  (row, column)  degree, each pixel centre's direction
    pixel_solid_angle                      (row, column)  sr
    <axis> (<axis>), wavelength (nm, in vacuum), channel (R, G, B), stokes_component (I, Q, U, V)

The frame is :data:`FRAME` (skyref's, see :mod:`skyref.scene`); a sky not rendered yet is NaN.
Global attributes hold the grid (``grid``, JSON: base scene, axes, output settings) and the
camera (``camera``, JSON), from which skyref rebuilds each sky's scene.

netCDF-3 (xarray's built-in scipy engine: no extra dependency) has no 64-bit integers and no
string type: integer labels become 32-bit integers (float64 beyond their range), strings
character arrays and booleans bytes (xarray decodes both back); no variable may exceed 4 GiB
(the 64-bit-offset format), which is checked before any sky is rendered. scipy builds the file
in memory.

dask and xarray are imported inside the functions that use them (see :mod:`skyref.batch.store`).
"""

from __future__ import annotations

import json

import numpy as np

from skyref import __version__
from skyref.batch.grid import dimension_name
from skyref.errors import ParameterError
from skyref.io.atomic import atomic_path
from skyref.io.exr import STOKES_FRAME
from skyref.projection import equirectangular_pixel, pixel_directions, solid_angle
from skyref.sky import STOKES

__all__ = ["CONVENTIONS", "FRAME", "REFERENCES", "NETCDF_FORMAT", "NETCDF_MAX_VARIABLE_BYTES", "axis_attributes",
           "view_coordinates", "layout", "check_netcdf_size", "netcdf3_compatible", "write_netcdf"]

CONVENTIONS = "CF-1.10"
#: skyref's frame (:mod:`skyref.scene`, :mod:`skyref.projection`), in words.
FRAME = ("observer-centred east-north-up frame (x east, y north, z up at the observer); zenith angle "
         "from +z (0 = straight up, 90 = horizon, 180 = straight down); azimuth clockwise from north "
         "towards east (0 = north, 90 = east, 180 = south, 270 = west), in [0, 360)")
REFERENCES = ("skyref README.md (batch, scene and frame conventions); "
              "E. Bruneton, Precomputed Atmospheric Scattering: a New Implementation, 2017, "
              "https://ebruneton.github.io/precomputed_atmospheric_scattering/ (atmosphere presets); "
              "ASTM G173-03 (extraterrestrial solar spectrum); "
              "A. Serdyuchenko et al., Atmos. Meas. Tech. 7, 2014 (ozone cross-sections)")
NETCDF_FORMAT = "NETCDF3_64BIT"
#: Largest variable of netCDF-3's 64-bit-offset format, bytes.
NETCDF_MAX_VARIABLE_BYTES = (1 << 32) - 4

#: Axis path -> (long name, CF standard name or None).
_AXIS_NAMES = {
    "sun.zenith_deg": ("solar zenith angle", "solar_zenith_angle"),
    "sun.azimuth_deg": ("solar azimuth angle, clockwise from north", "solar_azimuth_angle"),
    "sun.angular_radius_deg": ("angular radius of the solar disk", None),
    "sun.time": ("time of the solar position", None),
    "sun.latitude_deg": ("latitude of the solar position's place", "latitude"),
    "sun.longitude_deg": ("longitude of the solar position's place", "longitude"),
    "observer.altitude_m": ("observer altitude above the ground", "height"),
    "atmosphere.preset": ("atmosphere preset", None),
    "atmosphere.turbidity": ("Linke/Preetham turbidity at 550 nm", None),
    "atmosphere.ground_albedo": ("Lambertian ground albedo", "surface_albedo"),
    "atmosphere.bottom_radius_m": ("planet radius", None),
    "atmosphere.top_radius_m": ("radius of the top of the atmosphere", None),
}
#: Units of scene entries by the end of their name, then by name.
_UNIT_SUFFIXES = (("latitude_deg", "degree_north"), ("longitude_deg", "degree_east"), ("_deg", "degree"),
                  ("_m", "m"), ("_nm", "nm"), ("_du", "DU"), ("_per_m3", "m-3"))
_DIMENSIONLESS = ("turbidity", "ground_albedo", "angstrom_alpha", "angstrom_beta", "single_scattering_albedo",
                  "density_scale", "g", "exponent")
#: Parent entries whose spectrum ``value`` is a coefficient in m^-1.
_COEFFICIENT_SPECTRA = ("scattering", "extinction")


def _entry_units(path: str) -> str | None:
    """UDUNITS units of a numeric scene entry, or None where skyref's scene schema names none."""
    *parents, name = path.split(".")
    for suffix, units in _UNIT_SUFFIXES:
        if name.endswith(suffix):
            return units
    parent = parents[-1] if parents else ""
    if name in _DIMENSIONLESS or (name, parent) == ("value", "ground_albedo"):
        return "1"
    if name == "value" and parent in _COEFFICIENT_SPECTRA:
        return "m-1"
    return None


def axis_attributes(path: str, labels: np.ndarray) -> dict:
    """CF attributes of the coordinate of the grid axis at ``path`` with ``labels``
    (:meth:`skyref.batch.grid.Grid.labels`): long_name, units and standard_name where they
    apply (numbers only: strings and tables (labelled by their JSON) are names, not quantities,
    and carry no units), and ``skyref_axis``, the axis path."""
    long_name, standard_name = _AXIS_NAMES.get(path, (f"scene entry {path}", None))
    attrs = {"long_name": long_name, "skyref_axis": path}
    if labels.dtype.kind in "iuf":
        units = _entry_units(path)
        if units is not None:
            attrs["units"] = units
        if standard_name is not None:
            attrs["standard_name"] = standard_name
    elif labels.dtype.kind == "U" and any(label.startswith("{") for label in labels):
        attrs["long_name"] += " (JSON of each table)"
    return attrs


def view_coordinates(camera) -> dict:
    """The (row, column) coordinates of a :class:`skyref.scene.Camera`'s pixels: view zenith
    and azimuth angles of each pixel centre (degrees; NaN outside a fisheye's image circle) and
    the pixel's solid angle (sr), as xarray ``(dims, values, attrs)`` tuples."""
    # An equirectangular map's film coordinates (u, v) of a direction are its azimuth / 360
    # degrees and zenith angle / 180 degrees, whatever camera saw the direction.
    u, v = equirectangular_pixel(pixel_directions(camera))
    frame = {"coordinate_frame": FRAME}
    if camera.type == "fisheye":
        frame["comment"] = "NaN outside the fisheye's image circle"
    dims = ("row", "column")
    return {
        "view_zenith_angle": (dims, 180.0 * v, {"standard_name": "zenith_angle", "units": "degree", "long_name":
                              "zenith angle of the pixel centre's view direction, from the observer", **frame}),
        "view_azimuth_angle": (dims, 360.0 * u, {"units": "degree", "long_name": "azimuth of the pixel centre's "
                               "view direction, from the observer, clockwise from north", **frame}),
        "pixel_solid_angle": (dims, solid_angle(camera), {"units": "sr", "long_name": "solid angle of the pixel"}),
    }


def layout(grid, scene):
    """The dataset of ``grid`` (its sky 0 is ``scene``), sky data unwritten: NaN dask arrays
    chunked one sky per chunk, so that each sky's worker writes its own chunk."""
    import dask.array as da  # lazy: see module docstring
    import xarray as xr

    camera = scene.camera
    axes = [dimension_name(path) for path in grid.axes]
    shape, ones = grid.shape, (1,) * len(grid.shape)
    if grid.output.format == "spectral":
        # each image variable's pixel dimensions and their sizes, after the grid's axes
        spectral = {"row": camera.height, "column": camera.width, "wavelength": len(scene.wavelengths_nm)}
        stokes = {"row": camera.height, "column": camera.width, "stokes_component": len(STOKES),
                  "wavelength": len(scene.wavelengths_nm)}                  # as Sky.stokes
        sampled = ("the mean over the pixel's solid angle" if scene.render.pixel_sampling == "area"
                   else "the radiance along the pixel centre's direction")
        radiance = "W m-2 sr-1 nm-1"
        images = {
            "radiance": (spectral, {"units": radiance, "long_name": "spectral radiance reaching the observer from "
                                    "the pixel's view direction", "ancillary_variables": "standard_error",
                                    "comment": f"each value is {sampled}"}),
            "standard_error": (spectral, {"units": radiance, "long_name": "standard error of the spectral radiance "
                                          f"(spread of {grid.output.passes} independent Monte Carlo passes)"}),
        }
        if scene.render.polarized:
            images["radiance"][1]["long_name"] += " (the Stokes vector's I)"
            images["stokes"] = (stokes, {"units": radiance, "long_name": "Stokes vector of the spectral radiance "
                                         "reaching the observer from the pixel's view direction",
                                         "ancillary_variables": "stokes_standard_error",
                                         "comment": f"each value is {sampled}"})
            images["stokes_standard_error"] = (stokes, {"units": radiance, "long_name": "standard error of each "
                                                        f"Stokes component (spread of {grid.output.passes} "
                                                        "independent passes)"})
    else:
        images = {"rgb": ({"row": camera.height, "column": camera.width, "channel": 3},
                          {"units": "cd m-2", "long_name": "linear sRGB of the spectral radiance, absolute: "
                           "R = G = B = luminance for D65 white"})}
    variables = {}
    for name, (pixel_axes, attrs) in images.items():
        pixels = tuple(pixel_axes.values())
        variables[name] = (axes + list(pixel_axes), da.full(shape + pixels, np.nan, dtype=np.float32,
                                                            chunks=ones + pixels), attrs)
    for name, attrs in (("spp", {"units": "1", "long_name": "Monte Carlo samples per rendered pixel (the mean, "
                                                   "where a target error set them per pixel)"}),
                        ("relative_error_p95", {"units": "1", "long_name": "95th percentile over the pixels of "
                                                "standard error / radiance"})):
        variables[name] = (axes, da.full(shape, np.nan, dtype=np.float32, chunks=ones), attrs)
    coords = {}
    for path, name in zip(grid.axes, axes):
        labels = grid.labels(path)
        coords[name] = (name, labels, axis_attributes(path, labels))
    coords.update(view_coordinates(camera))
    if grid.output.format == "spectral":
        coords["wavelength"] = ("wavelength", np.asarray(scene.wavelengths_nm, dtype=np.float64),
                                {"units": "nm", "standard_name": "radiation_wavelength",
                                 "long_name": "wavelength in vacuum"})
    else:
        coords["channel"] = ("channel", np.array(["R", "G", "B"]), {"long_name": "linear sRGB channel"})
    if scene.render.polarized:
        coords["stokes_component"] = ("stokes_component", np.array(STOKES),
                                      {"long_name": "Stokes component", "reference_frame": STOKES_FRAME})
    title = "skyref reference skies" + (f": {scene.name}" if scene.name else "")
    attrs = {"Conventions": CONVENTIONS, "title": title,
             "source": f"skyref {__version__}: spectral Monte Carlo path tracer for a spherical planetary "
                       "atmosphere (Mitsuba 3 / Dr.Jit)",
             "history": f"created by skyref {__version__} (skyref batch); each sky written when rendered",
             "references": REFERENCES,
             "comment": "one sky per point of the grid's axes (the dimensions before row and column); NaN: a sky "
                        "not rendered yet (manifest.json lists the finished ones); view angles are in the frame "
                        "of the coordinate_frame attribute",
             "coordinate_frame": FRAME, "skyref_version": __version__,
             "grid": grid.fingerprint(), "camera": json.dumps(camera.to_dict())}
    dataset = xr.Dataset(variables, coords=coords, attrs=attrs)
    for name, encoding in _coordinate_encoding(dataset).items():
        dataset[name].encoding.update(encoding)
    return dataset


def _coordinate_encoding(dataset) -> dict:
    """No _FillValue on the 1-D coordinate variables (CF 2.5.1: they have no missing values)."""
    return {name: {"_FillValue": None} for name in dataset.indexes}


def check_netcdf_size(grid, scene):
    """Raise a ParameterError naming ``--netcdf`` if an image variable of ``grid`` would exceed
    netCDF-3's variable size (:data:`NETCDF_MAX_VARIABLE_BYTES`)."""
    per_pixel = len(scene.wavelengths_nm) if grid.output.format == "spectral" else 3
    if scene.render.polarized:
        per_pixel *= len(STOKES)                     # the stokes variable is the largest
    size = 4 * len(grid) * scene.camera.height * scene.camera.width * per_pixel
    if size > NETCDF_MAX_VARIABLE_BYTES:
        raise ParameterError("--netcdf", f"{size / (1 << 30):.1f} GiB per image variable",
                             "at most 4 GiB per variable (netCDF-3, 64-bit offset)",
                             "too large: use dataset.zarr, or split the grid")


def netcdf3_compatible(dataset):
    """``dataset`` with integers netCDF-3 lacks (64-bit, unsigned) as int32 where their values
    fit, float64 otherwise; strings and booleans are left to xarray's netCDF-3 encoding."""
    wide = {}
    for name, variable in dataset.variables.items():
        if variable.dtype.kind in "iu" and variable.dtype not in (np.int8, np.int16, np.int32):
            info, values = np.iinfo(np.int32), variable.values
            fits = values.size == 0 or (values.min() >= info.min and values.max() <= info.max)
            wide[name] = variable.astype(np.int32 if fits else np.float64)
    coords = {name: value for name, value in wide.items() if name in dataset.coords}
    return dataset.assign_coords(coords).assign({n: v for n, v in wide.items() if n not in coords})


def write_netcdf(zarr_path, path):
    """Copy the zarr dataset at ``zarr_path`` to netCDF-3 at ``path``, atomically."""
    import xarray as xr  # lazy: see module docstring

    # Without dask (chunks=None): xarray's scipy engine refuses dask's distributed scheduler,
    # which a batch's client makes the default.
    with xr.open_zarr(zarr_path, chunks=None) as dataset, atomic_path(path) as tmp:
        copy = netcdf3_compatible(dataset.drop_encoding())
        copy.to_netcdf(tmp, engine="scipy", format=NETCDF_FORMAT, encoding=_coordinate_encoding(copy))
