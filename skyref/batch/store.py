"""The output directory of a batch, and what makes it safe to kill and rerun.

::

    <directory>/grid.json            the grid's fingerprint: a rerun must use the same grid
    <directory>/skies/<id>.exr       one spectral EXR per sky (skyref.io.exr layout)
    <directory>/markers/<id>.json    completion marker: written last, atomically, with the EXR's
                                     SHA-256 and size, the sky's parameters, samples and timings
                                     (the only place timings are kept: EXRs and the dataset hold
                                     data alone, so a rerun writes the same bytes)
    <directory>/partial/<id>.npz     an adaptive render's checkpoint while the sky is rendered
                                     (skyref.render.AdaptiveProgress), removed once it is marked:
                                     a killed run's next run resumes the sky at its next launch
    <directory>/dataset.zarr         every sky in one CF xarray dataset (skyref.batch.dataset)
    <directory>/dataset.nc           its netCDF-3 copy, written once every sky is finished
                                     (on request: ``skyref batch --netcdf``)
    <directory>/manifest.json        the markers gathered, rewritten at the end of each run

A sky counts as finished only if its marker exists and its EXR has the marker's size (and,
with ``verify``, its SHA-256). EXRs and markers are written to temporary names and renamed, so
a run killed at any moment (even ``kill -9``) leaves either nothing or a complete file under
the final name; the dataset region of a sky is written *before* its marker, so an unmarked
sky's data is simply rewritten by the next run. Leftover temporary files are removed when a
run starts; a lock file stops two runs from sharing a directory. The dataset's layout and
metadata are written once, when it is created.

dask, xarray and zarr are imported inside the methods that use them (seconds of start-up;
:mod:`skyref.batch` is also imported to read and check grids, which needs none of them).
"""

from __future__ import annotations

import contextlib
import fcntl
import glob
import hashlib
import json
import os
import warnings

import numpy as np

from skyref.batch.dataset import layout, write_netcdf
from skyref.errors import ParameterError
from skyref.io.atomic import atomic_write
from skyref.render import AdaptiveProgress
from skyref.validation import check_output_directory

__all__ = ["DATASET", "NETCDF", "sha256_of", "marker_of_exr", "BatchStore"]

DATASET = "dataset.zarr"
NETCDF = "dataset.nc"


def sha256_of(path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def marker_of_exr(exr_path) -> str:
    """The completion marker of the sky whose EXR is ``exr_path`` (``<directory>/skies/<id>.exr``
    -> ``<directory>/markers/<id>.json``)."""
    directory = os.path.dirname(os.path.dirname(os.fspath(exr_path)))
    return os.path.join(directory, "markers", os.path.splitext(os.path.basename(exr_path))[0] + ".json")


class BatchStore:
    """The output directory of one grid (see module docstring)."""

    def __init__(self, grid, directory=None):
        """The store of ``grid`` in its output directory (or in ``directory``: the same grid's
        output copied from elsewhere)."""
        self.grid = grid
        self.directory = os.path.abspath(directory if directory is not None else grid.output.directory)
        self.dataset_path = os.path.join(self.directory, DATASET)
        self.netcdf_path = os.path.join(self.directory, NETCDF)

    @property
    def fingerprint_path(self) -> str:
        return os.path.join(self.directory, "grid.json")

    def stored_fingerprint(self) -> str | None:
        """The fingerprint of the grid whose output the directory holds (None: none yet)."""
        try:
            with open(self.fingerprint_path) as f:
                return f.read()
        except FileNotFoundError:
            return None

    def exr_path(self, sky_id: str) -> str:
        return os.path.join(self.directory, "skies", f"{sky_id}.exr")

    def marker_path(self, sky_id: str) -> str:
        return marker_of_exr(self.exr_path(sky_id))

    def checkpoint_path(self, sky_id: str) -> str:
        """Where an adaptive render of the sky keeps its state until the sky is marked."""
        return os.path.join(self.directory, "partial", f"{sky_id}.npz")

    # --- opening ----------------------------------------------------------------------------

    def check_writable(self):
        """Fail before any work if the directory cannot be created and written (nothing is
        created yet)."""
        check_output_directory(self.directory, "output.directory")

    @contextlib.contextmanager
    def lock(self):
        """Hold the directory's lock for a run (released by the OS even on ``kill -9``); the
        directory is created here."""
        os.makedirs(self.directory, exist_ok=True)
        with open(os.path.join(self.directory, ".lock"), "w") as handle:
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise ParameterError("output.directory", self.directory, "a directory no other batch "
                                     "is writing", "another skyref batch is running there") from None
            yield

    def prepare(self, first_scene):
        """Check the directory belongs to this grid (or claim it), remove temporary files left
        by a killed run, and create the dataset on first use."""
        for sub in ("skies", "markers"):
            os.makedirs(os.path.join(self.directory, sub), exist_ok=True)
        stored = self.stored_fingerprint()
        if stored is None:
            with atomic_write(self.fingerprint_path) as f:
                f.write(self.grid.fingerprint())
        elif stored != self.grid.fingerprint():
            raise ParameterError("output.directory", self.directory, "an empty directory or one "
                                 "holding this same grid", "it holds the output of a different grid")
        for leftover in glob.glob(os.path.join(self.directory, ".*.tmp*")) + glob.glob(
                os.path.join(self.directory, "*", ".*.tmp*")):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(leftover)
        if not os.path.exists(os.path.join(self.dataset_path, "zarr.json")):
            self._create_dataset(first_scene)

    def _create_dataset(self, scene):
        """The dataset's layout, coordinates and metadata (:func:`skyref.batch.dataset.layout`);
        the sky data stay unwritten (NaN) until each sky's worker fills its chunk."""
        with warnings.catch_warnings():  # consolidated metadata and fixed-length strings: zarr-python
            warnings.simplefilter("ignore")  # extensions to v3, which xarray reads back
            layout(self.grid, scene).to_zarr(self.dataset_path, mode="w", compute=False, zarr_format=3)

    def write_netcdf(self):
        """Copy the dataset to ``dataset.nc`` (netCDF-3), atomically."""
        write_netcdf(self.dataset_path, self.netcdf_path)

    # --- per sky ----------------------------------------------------------------------------

    def is_finished(self, sky_id: str, verify: bool = False) -> bool:
        try:
            with open(self.marker_path(sky_id)) as f:
                marker = json.load(f)
            if os.path.getsize(self.exr_path(sky_id)) != marker["exr_bytes"]:
                return False
            return not verify or sha256_of(self.exr_path(sky_id)) == marker["exr_sha256"]
        except (OSError, ValueError, KeyError):
            return False

    def progress(self, indices) -> dict:
        """How far the run of the sky numbers ``indices`` is, from the directory alone (nothing is
        written): ``finished`` skies and the CPU seconds their markers record (``cpu_s``), and
        ``partial``, sky id -> how far each sky rendered part-way is, from its checkpoint
        (:meth:`skyref.render.AdaptiveProgress.describe`)."""
        finished, cpu_s, partial = 0, 0.0, {}
        for index in indices:
            sky_id = self.grid.sky_id(index)
            if self.is_finished(sky_id):
                with open(self.marker_path(sky_id)) as f:
                    cpu_s += json.load(f).get("task_cpu_s", 0.0)
                finished += 1
            elif (target := self.grid.target_relative_error(self.grid.sky(index).coordinates)) is not None:
                note = AdaptiveProgress.describe(self.checkpoint_path(sky_id), target)
                if note is not None:
                    partial[sky_id] = note
        return {"finished": finished, "cpu_s": cpu_s, "partial": partial}

    def write_sky(self, index: int, sky):
        """Write ``sky`` (a :class:`~skyref.sky.Sky` whose metadata hold ``spp`` and
        ``relative_error_p95``) into its chunk of the dataset, in the grid's output format."""
        meta = sky.metadata
        if self.grid.output.format == "spectral":
            images = {"radiance": sky.radiance, "standard_error": sky.standard_error}
            if sky.polarized:
                images.update(stokes=sky.stokes, stokes_standard_error=sky.stokes_error)
        else:
            images = {"rgb": sky.rgb().astype(np.float32)}
        self.write_region(index, dict(images, spp=np.float32(meta["spp"]),
                                      relative_error_p95=np.float32(meta["relative_error_p95"])))

    def write_region(self, index: int, values: dict):
        """Write one sky's arrays (name -> array) into its chunk of the dataset."""
        import zarr  # lazy: see module docstring

        group = zarr.open_group(self.dataset_path, mode="r+")
        position = tuple(int(i) for i in np.unravel_index(index, self.grid.shape))
        for name, value in values.items():
            group[name][position] = value

    def write_marker(self, sky_id: str, marker: dict):
        with atomic_write(self.marker_path(sky_id)) as f:
            json.dump(marker, f, sort_keys=True)

    def write_manifest(self) -> dict:
        """Gather every marker into ``manifest.json`` (atomically); returns the manifest."""
        markers = []
        for path in sorted(glob.glob(os.path.join(self.directory, "markers", "*.json"))):
            with open(path) as f:
                markers.append(json.load(f))
        manifest = {"grid": json.loads(self.grid.fingerprint()), "axes": list(self.grid.axes),
                    "skies_total": len(self.grid), "skies_finished": len(markers), "skies": markers}
        with atomic_write(os.path.join(self.directory, "manifest.json")) as f:
            json.dump(manifest, f, indent=1, sort_keys=True)
        return manifest
