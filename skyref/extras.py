"""Optional parts of skyref and the pip extras that install them.

The core (rendering, audits, inversion, EXR/PNG files) needs neither extra:

- ``skyref[fit]``: JAX, optimistix and lineax for the Hosek-style fitter (:mod:`skyref.fit`),
  xarray and zarr to read the training skies of a batch dataset;
- ``skyref[batch]``: dask.distributed for ``skyref batch`` and ``skyref report``
  (:mod:`skyref.batch`), xarray and zarr to write the batch dataset.

A code path that needs an extra calls :func:`require` before any work; it looks the modules up
without importing them (``importlib.util.find_spec``), so JAX's and dask's import cost is still
paid only where they are used.
"""

from __future__ import annotations

import importlib.util

from skyref.errors import SkyrefSetupError

__all__ = ["EXTRAS", "require"]

#: Extra -> the top-level modules it installs (pyproject.toml's ``[project.optional-dependencies]``).
EXTRAS = {
    "fit": ("jax", "optimistix", "lineax", "xarray", "zarr"),
    "batch": ("dask", "distributed", "xarray", "zarr"),
}


def require(extra: str) -> None:
    """Raise :class:`~skyref.errors.SkyrefSetupError`, one line naming the missing modules and
    the ``pip install`` that adds them, unless every module of ``extra`` is installed."""
    missing = [module for module in EXTRAS[extra] if importlib.util.find_spec(module) is None]
    if missing:
        raise SkyrefSetupError(f"{', '.join(missing)} not installed (needed by skyref's {extra} tools): "
                               f"pip install 'skyref[{extra}]'")
