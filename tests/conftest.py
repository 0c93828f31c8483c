"""Shared fixtures: Mitsuba loaded once, in the RGB variant of :mod:`tests.variants` (the CPU's
unless ``SKYREF_TEST_BACKEND=cuda``), with skyref's plugins; the default scene file rendered by
the baseline estimator."""

import os

# One OpenBLAS thread (NumPy's linear algebra: Gauss-Legendre nodes, DISORT's eigenproblems):
# its threads spin while they wait, and beside Dr.Jit's thread pool and the other test worker
# on a loaded machine a 120-ray check that takes 3 s took 55 s (np.polynomial.legendre.leggauss).
# Set before NumPy is first imported, which reads it once.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import dataclasses  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402
from tests.variants import RGB  # noqa: E402

EARTH_CLEAR = Path(__file__).resolve().parent.parent / "scenes" / "earth-clear.toml"


@pytest.fixture(scope="session")
def mi():
    from skyref.plugins import load_mitsuba

    return load_mitsuba(RGB)


@pytest.fixture(scope="session")
def earth_clear_baseline(tmp_path_factory) -> Path:
    """``scenes/earth-clear.toml`` with ``render.estimator = "delta_tracking"``, for tests whose
    subject is not the estimator (batches, the dataset): the baseline's kernels compile in
    seconds, the default line integral's in about 2 minutes at this scene's 48 wavelengths, and
    each of these tests renders in fresh processes. The estimators are tested apart, both of them."""
    from skyref.scene import load_scene, save_scene

    scene = load_scene(EARTH_CLEAR)
    path = tmp_path_factory.mktemp("scenes") / "earth-clear.toml"
    save_scene(scene.replace(render=dataclasses.replace(scene.render, estimator="delta_tracking")), path)
    return path
