"""Skies of a grid rendered elsewhere, brought into this grid's output directory.

A grid can be rendered in pieces on machines that share no file system (a GPU lent for an hour,
a laptop, a cluster node): each piece is a copy of the same grid's output directory holding the
skies that machine finished (``skyref batch GRID --skies 0-99`` renders a part). :func:`import_skies`
takes every sky finished there and not here: it checks the piece's grid is this grid (the
``grid.json`` fingerprints match), checks each EXR against its marker's SHA-256, copies the EXR,
writes the sky into this directory's dataset from the EXR (the dataset's values of a sky are a
function of its EXR: :meth:`~skyref.batch.store.BatchStore.write_sky`), and writes its marker
last, with ``imported_from`` added, so that an import killed at any moment resumes like a run.
Skies already finished here are kept as they are. :func:`export_skies` makes such a piece of
the skies finished here: their EXRs, markers and ``grid.json``, without the dataset (the
ground truth of the LUT audit ships in the repository that way, results/lut_audit/truth).
"""

from __future__ import annotations

import json
import os
import shutil

from skyref.batch.store import BatchStore
from skyref.errors import ParameterError
from skyref.io.atomic import atomic_path, atomic_write
from skyref.io.exr import read_sky_exr

__all__ = ["LUT_AUDIT_TRUTH", "import_skies", "export_skies"]

#: Where the finished skies of ``grids/lut_audit.toml`` ship, relative to the repository root:
#: a piece :func:`import_skies` takes (written by ``benchmarks/lut_audit.py --part ship``).
LUT_AUDIT_TRUTH = os.path.join("results", "lut_audit", "truth")


def import_skies(grid, source, log=print, parameter: str = "source") -> dict:
    """Import into ``grid``'s output directory the skies finished in ``source`` (another copy of
    the same grid's output directory); returns ``{"imported": [sky ids], "kept": [ids already
    finished here], "corrupt": [ids whose EXR does not match its marker, left out]}``.

    Raises a ParameterError naming ``parameter`` before anything is written if ``source`` is not
    an output directory of this grid (missing, no ``grid.json``, or another grid's)."""
    theirs = BatchStore(grid, directory=source)
    ours = BatchStore(grid)
    expected = "the output directory of a run of this grid"
    if not os.path.isdir(theirs.directory):
        raise ParameterError(parameter, source, expected, "no such directory")
    stored = theirs.stored_fingerprint()
    if stored is None:
        raise ParameterError(parameter, source, expected, "it has no grid.json")
    if stored != grid.fingerprint():
        raise ParameterError(parameter, source, expected, "its grid.json is another grid's")
    if theirs.directory == ours.directory:
        raise ParameterError(parameter, source, "another directory than the grid's own output", "it is the same")
    first_scene = grid.validate()
    ours.check_writable()
    report = {"imported": [], "kept": [], "corrupt": []}
    with ours.lock():
        ours.prepare(first_scene)
        for index in range(len(grid)):
            sky_id = grid.sky_id(index)
            if not os.path.exists(theirs.marker_path(sky_id)):
                continue
            if ours.is_finished(sky_id):
                report["kept"].append(sky_id)
            elif not theirs.is_finished(sky_id, verify=True):
                report["corrupt"].append(sky_id)
                log(f"skyref batch: {sky_id} in {theirs.directory} does not match its marker: not imported")
            else:
                _import(theirs, ours, index, sky_id)
                report["imported"].append(sky_id)
        ours.write_manifest()
    log(f"skyref batch: imported {len(report['imported'])} skies from {theirs.directory} "
        f"({len(report['kept'])} already finished here, kept; {len(report['corrupt'])} corrupt, left out)")
    return report


def _import(theirs: BatchStore, ours: BatchStore, index: int, sky_id: str) -> None:
    """One sky: its EXR, then its dataset chunk, then its marker (the order of a render)."""
    with atomic_path(ours.exr_path(sky_id)) as tmp:
        shutil.copyfile(theirs.exr_path(sky_id), tmp)
    ours.write_sky(index, read_sky_exr(ours.exr_path(sky_id)))
    with open(theirs.marker_path(sky_id)) as f:
        marker = json.load(f)
    ours.write_marker(sky_id, dict(marker, imported_from=theirs.directory))


def export_skies(grid, destination, log=print) -> list[str]:
    """Copy the skies finished in ``grid``'s output directory that ``destination`` lacks into it,
    each EXR checked against its marker's SHA-256 and copied before its marker (atomically), with
    the grid's ``grid.json``: a piece :func:`import_skies` takes. Returns the ids copied. Raises a
    ParameterError naming ``destination`` before anything is written if it holds another grid's
    skies."""
    ours = BatchStore(grid)
    piece = BatchStore(grid, directory=destination)
    stored = piece.stored_fingerprint()
    if stored is not None and stored != grid.fingerprint():
        raise ParameterError("destination", destination, "an empty directory or a piece of this grid",
                             "its grid.json is another grid's")
    if piece.directory == ours.directory:
        raise ParameterError("destination", destination, "another directory than the grid's own output",
                             "it is the same")
    for sub in ("skies", "markers"):
        os.makedirs(os.path.join(piece.directory, sub), exist_ok=True)
    if stored is None:
        with atomic_write(piece.fingerprint_path) as f:
            f.write(grid.fingerprint())
    copied = []
    for index in range(len(grid)):
        sky_id = grid.sky_id(index)
        if piece.is_finished(sky_id) or not ours.is_finished(sky_id, verify=True):
            continue
        with atomic_path(piece.exr_path(sky_id)) as tmp:
            shutil.copyfile(ours.exr_path(sky_id), tmp)
        with atomic_path(piece.marker_path(sky_id)) as tmp:
            shutil.copyfile(ours.marker_path(sky_id), tmp)
        copied.append(sky_id)
    log(f"skyref batch: copied {len(copied)} finished skies to {piece.directory}")
    return copied
