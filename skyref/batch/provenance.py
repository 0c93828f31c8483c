"""What a batch's ground truth is and what it cost, for the reports and tables made from it.

Read from the batch's own files (:mod:`skyref.batch.store`): each sky's EXR names its estimator,
camera, wavelengths and samples per direction; its completion marker holds the CPU seconds the
batch spent on it.
"""

from __future__ import annotations

import glob
import json
import os

from skyref.batch.store import marker_of_exr
from skyref.errors import ParameterError
from skyref.io.exr import read_sky_exr

__all__ = ["batch_skies", "truth_provenance", "describe_truth"]


def batch_skies(directory) -> list[str]:
    """The sky EXRs of the batch output ``directory`` (``<directory>/skies/*.exr``), sorted."""
    return sorted(glob.glob(os.path.join(os.fspath(directory), "skies", "*.exr")))


def truth_provenance(exr_paths) -> dict:
    """What the ground truth in the batch EXRs ``exr_paths`` is, from each EXR's scene and
    metadata and its batch marker (``markers/<id>.json`` beside ``skies/``): ``estimators``
    (sorted names; a sky rendered before the metadata named its estimator was delta tracking's),
    ``camera`` (e.g. "64x32 equirectangular"), ``wavelengths`` (count, first, last, nm), ``spp``
    (the smallest and largest of the skies' mean samples per direction) and ``cpu_s``, the CPU
    seconds the batch spent on them (None if a marker lacks it)."""
    exr_paths = list(exr_paths)
    if not exr_paths:
        raise ParameterError("truth skies", "none", "at least one batch sky EXR", "nothing to describe")
    estimators, spp, cpu = set(), [], 0.0
    for path in exr_paths:
        truth = read_sky_exr(path)
        estimators.add(truth.metadata.get("estimator", "delta_tracking"))
        spp.append(float(truth.metadata["spp"]))
        try:
            with open(marker_of_exr(path)) as f:
                seconds = float(json.load(f)["task_cpu_s"])
        except (OSError, ValueError, KeyError):
            seconds = None
        cpu = None if cpu is None or seconds is None else cpu + seconds
    camera, wavelengths = truth.scene.camera, truth.wavelengths_nm
    return {"estimators": sorted(estimators), "camera": f"{camera.width}x{camera.height} {camera.type}",
            "wavelengths": (len(wavelengths), float(wavelengths.min()), float(wavelengths.max())),
            "spp": (min(spp), max(spp)), "cpu_s": cpu}


def describe_truth(provenance: dict) -> str:
    """:func:`truth_provenance` in words, for reports."""
    low, high = provenance["spp"]
    samples = (f"{low:.0f} samples per direction" if low == high else
               f"{low:.0f}–{high:.0f} samples per direction on average (rendered to an error target)")
    count, first, last = provenance["wavelengths"]
    names = provenance["estimators"]
    text = (" and ".join(name.replace("_", " ") for name in names) + (" estimators" if len(names) > 1 else " estimator")
            + f", {provenance['camera']} pixel-centre directions, {count} wavelengths {first:g}–{last:g} nm, "
            + samples)
    return text if provenance["cpu_s"] is None else text + f", {provenance['cpu_s'] / 3600.0:.2f} CPU hours"
