"""Batch generation of reference skies: a parameter grid (:mod:`skyref.batch.grid`) rendered
sky by sky on dask workers (:mod:`skyref.batch.run`), each sky written atomically as a spectral
EXR and into one CF xarray/zarr dataset (:mod:`skyref.batch.dataset`), with completion markers so
a rerun resumes (:mod:`skyref.batch.store`); skies rendered elsewhere are brought in by
:mod:`skyref.batch.merge`."""

from skyref.batch.grid import Grid, load_grid
from skyref.batch.run import run_batch

__all__ = ["Grid", "load_grid", "run_batch"]
