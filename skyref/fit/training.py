"""Training data for the fitter: skies on one shared set of view directions, with the
configuration (solar elevation, turbidity, ground albedo) of each.

:func:`load_batch_dataset` reads the xarray/zarr dataset that ``skyref batch`` writes (see
:mod:`skyref.batch.dataset`; dimensions: the grid's axes, then row, column, wavelength) and turns it
into one :class:`TrainingSet` per kind of table:

- ``"spectral"``: the dataset's wavelengths that fall on the model's band centres (320, 360,
  ..., 720 nm), radiance in W m^-2 sr^-1 nm^-1;
- ``"xyz"`` and ``"rgb"`` (when the wavelengths span 400-700 nm): CIE 1931 XYZ as the integral of
  radiance times the colour-matching functions over the dataset's wavelengths (trapezoidal), and
  linear sRGB of it, in W m^-2 sr^-1 as in the published model (skyref.color's absolute XYZ / 683).

Each sky's configuration comes from its scene, rebuilt from the grid stored with the dataset:
solar elevation = 90 deg - sun zenith, turbidity by :func:`skyref.atmosphere.turbidity`, the grey
ground albedo. View directions are the pixel centres of the scene's camera
(:func:`skyref.projection.pixel_directions`): the training grid renders them exactly
(``pixel_sampling = "centre"``). Only directions at or above the horizon are kept.

:func:`synthesize` builds a training set from a coefficient table instead (tests, benchmarks).

xarray and colour-science (also through :mod:`skyref.color`) are imported inside the functions
that read a dataset: they take about 0.7 s and 2.5 s to import, and ``skyref --help`` imports this
module (through :mod:`skyref.fit.cli`).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, replace

import numpy as np

from skyref.analytic.hosek import BAND_CENTRES_NM, CHANNELS
from skyref.errors import ParameterError
from skyref.atmosphere import ConstantSpectrum, turbidity
from skyref.extras import require
from skyref.atmosphere.sun import SUN_ANGULAR_RADIUS_DEG
from skyref.batch.grid import Grid, OutputSettings
from skyref.projection import pixel_directions, solid_angle
from skyref.scene import Camera, Scene

__all__ = ["SOLAR_DISK_MARGIN", "TRISTIMULUS_SPAN_NM", "TrainingSet", "load_batch_dataset", "synthesize",
           "view_sun_angle"]

#: Directions within this many solar angular radii of the sun's centre are left out of fits and
#: error statistics: the solar disk is not part of the sky model.
SOLAR_DISK_MARGIN = 2.0
#: Tristimulus kinds need the spectrum over at least this range, nm.
TRISTIMULUS_SPAN_NM = (400.0, 700.0)


def view_sun_angle(sun_directions, directions) -> np.ndarray:
    """(S, P) angle (rad) between unit vectors ``sun_directions`` (S, 3) and ``directions``
    (P, 3): atan2 of the cross and dot products, accurate near 0 and pi where arccos is not."""
    dot = sun_directions @ directions.T
    cross = np.linalg.norm(np.cross(sun_directions[:, None, :], directions[None, :, :]), axis=-1)
    return np.arctan2(cross, dot)


@dataclass(frozen=True)
class TrainingSet:
    """S skies of one kind seen along the same P directions.

    ``directions`` ``(P, 3)``: unit view directions, east-north-up (z up), all at or above the
    horizon. ``solid_angle`` ``(P,)``: each direction's pixel solid angle, sr. ``sun_directions``
    ``(S, 3)``: unit vectors towards the sun. ``solar_elevation`` (rad), ``turbidity``, ``albedo``,
    ``sun_angular_radius`` (rad): ``(S,)``. ``radiance`` and ``standard_error`` ``(S, P, C)`` in
    the kind's unit (:data:`skyref.analytic.hosek.UNITS`), NaN where a sky was never rendered;
    ``channels`` names the C channels (a subset of the kind's channels, in storage order).
    """

    kind: str
    channels: tuple[str, ...]
    directions: np.ndarray
    solid_angle: np.ndarray
    sun_directions: np.ndarray
    solar_elevation: np.ndarray
    turbidity: np.ndarray
    albedo: np.ndarray
    sun_angular_radius: np.ndarray
    radiance: np.ndarray
    standard_error: np.ndarray
    source: str = ""

    def __post_init__(self):
        unknown = [c for c in self.channels if c not in CHANNELS[self.kind]]
        if unknown or not self.channels:
            raise ParameterError("channels", list(self.channels), f"a non-empty subset of {CHANNELS[self.kind]}",
                                 "unknown channel")
        s, p, c = len(self.sun_directions), len(self.directions), len(self.channels)
        for name in ("radiance", "standard_error"):
            if np.shape(getattr(self, name)) != (s, p, c):
                raise ParameterError(name, f"array of shape {np.shape(getattr(self, name))}", f"shape {(s, p, c)}",
                                     "wrong shape")

    @property
    def channel_indices(self) -> np.ndarray:
        """Index of each channel among its kind's channels (the table's channel axis)."""
        return np.array([CHANNELS[self.kind].index(c) for c in self.channels])

    @property
    def cos_theta(self) -> np.ndarray:
        """(P,) cosine of each direction's zenith angle."""
        return self.directions[:, 2]

    @property
    def gamma(self) -> np.ndarray:
        """(S, P) angle between each view direction and each sky's sun, rad."""
        return view_sun_angle(self.sun_directions, self.directions)

    def weights(self) -> np.ndarray:
        """(S, P, C) weight of each datum in fits and error statistics: the pixel's solid angle
        (relative to the mean), or 0 where the datum is missing or not positive (a log-radiance
        residual needs radiance > 0) or lies on the solar disk."""
        off_disk = self.gamma > SOLAR_DISK_MARGIN * self.sun_angular_radius[:, None]
        valid = np.isfinite(self.radiance) & (self.radiance > 0.0) & off_disk[..., None]
        relative = self.solid_angle / self.solid_angle.mean()
        return np.where(valid, relative[None, :, None], 0.0)

    @property
    def rendered(self) -> np.ndarray:
        """(S,) True where a sky has any radiance (an unfinished batch has skies with none)."""
        return np.isfinite(self.radiance).any(axis=(1, 2))

    def select(self, mask) -> "TrainingSet":
        """The skies where ``mask`` ``(S,)`` is True."""
        return replace(self, **{name: getattr(self, name)[mask] for name in (
            "sun_directions", "solar_elevation", "turbidity", "albedo", "sun_angular_radius", "radiance",
            "standard_error")})

    def relative_noise(self) -> np.ndarray:
        """(S, P, C) standard error / radiance of the data (NaN where unweighted)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.weights() > 0.0, self.standard_error / self.radiance, np.nan)


# --- the training set of a batch dataset ---------------------------------------------------------

def _dataset_path(path) -> str:
    path = os.fspath(path)
    if os.path.isdir(os.path.join(path, "dataset.zarr")):
        path = os.path.join(path, "dataset.zarr")
    if not os.path.isfile(os.path.join(path, "zarr.json")):
        raise ParameterError("grid", path, "a skyref batch output directory or its dataset.zarr",
                             "no zarr dataset there")
    return path


def _sky_configurations(grid) -> dict:
    """Per sky (C order over the grid's axes): sun direction, elevation, angular radius,
    turbidity and ground albedo of its scene."""
    columns = {name: [] for name in ("sun_directions", "solar_elevation", "sun_angular_radius", "turbidity", "albedo")}
    for index in range(len(grid)):
        scene = Scene.from_dict(grid.sky(index).scene)
        albedo = scene.atmosphere.ground_albedo
        if not isinstance(albedo, ConstantSpectrum):
            raise ParameterError("atmosphere.ground_albedo", albedo.to_dict(), "a grey (constant) albedo",
                                 f"sky {index} has a spectral ground albedo")
        columns["sun_directions"].append(scene.sun.direction)
        columns["solar_elevation"].append(math.radians(90.0 - scene.sun.zenith_deg))
        columns["sun_angular_radius"].append(math.radians(scene.sun.angular_radius_deg))
        columns["turbidity"].append(turbidity(scene.atmosphere))
        columns["albedo"].append(albedo.value)
    return {name: np.asarray(values, dtype=np.float64) for name, values in columns.items()}


def _tristimulus_matrix(wavelengths_nm, kind) -> np.ndarray:
    """(N, 3) matrix from spectral radiance to XYZ or linear sRGB on the published model's scale
    (skyref.color's absolute XYZ divided by 683 lm/W)."""
    import colour

    from skyref.color import xyz_matrix, xyz_to_linear_srgb

    to_xyz = xyz_matrix(wavelengths_nm) / float(colour.constants.CONSTANT_K_M)
    return to_xyz if kind == "xyz" else to_xyz @ xyz_to_linear_srgb(np.eye(3))


def load_batch_dataset(path) -> dict[str, TrainingSet]:
    """Training sets (kind -> :class:`TrainingSet`) of a spectral ``skyref batch`` dataset:
    ``path`` is its output directory or its ``dataset.zarr``. See the module's documentation."""
    require("fit")
    import xarray as xr

    path = _dataset_path(path)
    dataset = xr.open_zarr(path)
    if "radiance" not in dataset:
        raise ParameterError("grid", path, "a spectral batch dataset (output.format = 'spectral')",
                             "it holds RGB images")
    fingerprint = json.loads(dataset.attrs["grid"])
    # The grid's axes, in their original order: each dimension's coordinate names its axis path
    # (datasets written before skyref.batch.dataset named dimensions by the path itself).
    axes_names = [dataset[dim].attrs.get("skyref_axis", dim) for dim in dataset["radiance"].dims[:-3]]
    grid = Grid(base=fingerprint["base"], axes={name: fingerprint["axes"][name] for name in axes_names},
                output=OutputSettings(directory=path, **fingerprint["output"]))
    camera = Camera.from_dict(json.loads(dataset.attrs["camera"]))

    directions = pixel_directions(camera).reshape(-1, 3)
    keep = np.isfinite(directions).all(axis=1) & (directions[:, 2] >= -1e-12)
    directions = directions[keep]
    directions[:, 2] = np.maximum(directions[:, 2], 0.0)
    pixels = solid_angle(camera).reshape(-1)[keep]
    wavelengths = np.asarray(dataset["wavelength"].values, dtype=np.float64)
    count = len(grid)
    radiance = np.asarray(dataset["radiance"].values, dtype=np.float64).reshape(count, -1, wavelengths.size)[:, keep]
    error = np.asarray(dataset["standard_error"].values, dtype=np.float64).reshape(count, -1, wavelengths.size)[:, keep]
    configurations = _sky_configurations(grid)

    def training_set(kind, channels, values, errors):
        return TrainingSet(kind=kind, channels=channels, directions=directions, solid_angle=pixels,
                           radiance=values, standard_error=errors, source=path, **configurations)

    sets = {}
    bands = [i for i, w in enumerate(wavelengths) if np.any(np.isclose(w, BAND_CENTRES_NM, rtol=0.0, atol=1e-6))]
    if bands:
        channels = tuple(f"{wavelengths[i]:g}" for i in bands)
        sets["spectral"] = training_set("spectral", channels, radiance[..., bands], error[..., bands])
    if wavelengths.min() <= TRISTIMULUS_SPAN_NM[0] and wavelengths.max() >= TRISTIMULUS_SPAN_NM[1]:
        for kind in ("xyz", "rgb"):
            matrix = _tristimulus_matrix(wavelengths, kind)
            # All wavelengths of a path share its random numbers, so their errors are almost
            # perfectly correlated: the error of the weighted sum is then |sum of M x error|.
            # Summing |M| x error instead would assume errors of opposite sign never cancel and,
            # for sRGB red (X minus Y and Z), overstate its noise several times.
            sets[kind] = training_set(kind, CHANNELS[kind], radiance @ matrix, np.abs(error @ matrix))
    if not sets:
        raise ParameterError("wavelengths", list(wavelengths), f"band centres {BAND_CENTRES_NM} nm or a span "
                             f"of {TRISTIMULUS_SPAN_NM} nm", "no channel of the model")
    return sets


# --- synthetic training sets -----------------------------------------------------------------------

def synthesize(table, directions, solid_angle, solar_elevation, turbidity, albedo,
               sun_azimuth: float = math.pi, sun_angular_radius: float = math.radians(SUN_ANGULAR_RADIUS_DEG)
               ) -> TrainingSet:
    """The skies a :class:`~skyref.analytic.hosek.CoefficientTable` predicts, as a training set:
    along ``directions`` ``(P, 3)`` (east-north-up, at or above the horizon) with pixel solid
    angles ``solid_angle`` ``(P,)``, for configurations given as arrays ``(S,)`` (solar elevation
    in radians), the sun at azimuth ``sun_azimuth`` (rad, clockwise from north). No noise: the
    standard error is 0."""
    elevation = np.asarray(solar_elevation, dtype=np.float64)
    sun = np.stack([np.cos(elevation) * math.sin(sun_azimuth), np.cos(elevation) * math.cos(sun_azimuth),
                    np.sin(elevation)], axis=-1)
    directions = np.asarray(directions, dtype=np.float64)
    theta = np.arccos(np.clip(directions[:, 2], -1.0, 1.0))
    radiance = table.radiance(theta[None, :], view_sun_angle(sun, directions), elevation[:, None], np.asarray(turbidity, dtype=np.float64)[:, None],
                              np.asarray(albedo, dtype=np.float64)[:, None])
    count = elevation.size
    return TrainingSet(kind=table.kind, channels=table.channels, directions=directions,
                       solid_angle=np.asarray(solid_angle, dtype=np.float64), sun_directions=sun,
                       solar_elevation=elevation, turbidity=np.asarray(turbidity, dtype=np.float64),
                       albedo=np.asarray(albedo, dtype=np.float64),
                       sun_angular_radius=np.full(count, sun_angular_radius), radiance=radiance,
                       standard_error=np.zeros_like(radiance), source=f"synthesized from {table.source or 'a table'}")
