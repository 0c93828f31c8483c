"""Checks run before any work: each raises :class:`~skyref.errors.ParameterError` naming the
parameter, the value given and the valid range.

- Parameter checks (``check_number``, ``check_array``, ``check_choice``, ...), run when a model
  object is built or an option is read.
- Where skyref may write: an output path is refused when it cannot be written — wrong
  extension, an existing directory where a file should go (or a file where a directory should),
  no writable existing ancestor — and nothing is created by the check: the directories appear
  only when the first file is written (:func:`skyref.io.atomic.atomic_path`), so a run refused
  later leaves nothing behind. Names that become file names go through :func:`safe_file_name`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import tempfile

import numpy as np

from skyref.errors import ParameterError

__all__ = ["check_number", "check_array", "check_fields", "check_int", "check_int_tuple", "check_choice",
           "check_view", "check_output_file", "check_output_directory", "safe_file_name"]

#: Longest file name :func:`safe_file_name` returns, characters.
MAX_FILE_NAME = 100


# --- parameters -----------------------------------------------------------------------------------

def check_number(name: str, value, lo: float = -math.inf, hi: float = math.inf,
                 lo_open: bool = False, hi_open: bool = False) -> float:
    """Return ``value`` as a float if it is a finite real number in the interval, else raise."""
    lo_bracket = "(" if lo_open else "["
    hi_bracket = ")" if hi_open else "]"
    valid = f"{lo_bracket}{lo:g}, {hi:g}{hi_bracket}"
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ParameterError(name, value, valid, "not a number")
    x = float(value)
    if not math.isfinite(x):
        raise ParameterError(name, value, valid, "not finite")
    below = x <= lo if lo_open else x < lo
    above = x >= hi if hi_open else x > hi
    if below or above:
        raise ParameterError(name, value, valid, "out of range")
    return x


def check_array(name: str, values, lo: float = -math.inf, hi: float = math.inf,
                min_length: int = 1, increasing: bool = False) -> np.ndarray:
    """Return ``values`` as a 1D float64 array whose entries are finite and within [lo, hi]."""
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError(name, values, f"a list of numbers in [{lo:g}, {hi:g}]", "not numeric")
    valid = f"{min_length} or more finite numbers in [{lo:g}, {hi:g}]" + (
        ", strictly increasing" if increasing else "")
    if arr.ndim != 1 or arr.size < min_length:
        raise ParameterError(name, values, valid, "wrong shape or length")
    bad = ~np.isfinite(arr) | (arr < lo) | (arr > hi)
    if bad.any():
        i = int(np.argmax(bad))
        raise ParameterError(f"{name}[{i}]", float(arr[i]), valid, "out of range")
    if increasing and np.any(np.diff(arr) <= 0):
        raise ParameterError(name, values, valid, "not strictly increasing")
    return arr


def check_fields(section: str, fields: dict, cls) -> dict:
    """Return ``fields`` if they fit the dataclass ``cls``: every key is one of its init fields
    and every field without a default is present; else raise naming ``section.key``."""
    init = [f for f in dataclasses.fields(cls) if f.init]
    names = [f.name for f in init]
    for key in fields:
        if key not in names:
            raise ParameterError(f"{section}.{key}", fields[key], "one of " + ", ".join(names),
                                 "unknown parameter")
    for f in init:
        if (f.name not in fields and f.default is dataclasses.MISSING
                and f.default_factory is dataclasses.MISSING):
            raise ParameterError(f"{section}.{f.name}", None, "a value", "missing")
    return fields


def check_int(name: str, value, lo: int, hi: int, even: bool = False) -> int:
    """Return ``value`` if it is an integer in [lo, hi] (and even, if asked), else raise."""
    valid = f"an {'even ' if even else ''}integer in [{lo}, {hi}]"
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ParameterError(name, value, valid, "not an integer")
    if not lo <= value <= hi:
        raise ParameterError(name, value, valid, "out of range")
    if even and value % 2:
        raise ParameterError(name, value, valid, "odd")
    return int(value)


def check_int_tuple(name: str, value, count: int, lo: int, hi: int, even_axes=()) -> tuple:
    """Return ``value`` as a tuple of ``count`` integers in [lo, hi] (a table size), those at
    ``even_axes`` even; errors name the entry (``name[i]``)."""
    if not isinstance(value, (tuple, list)) or len(value) != count:
        raise ParameterError(name, value, f"{count} integers in [{lo}, {hi}]", "wrong length")
    return tuple(check_int(f"{name}[{i}]", v, lo, hi, even=i in even_axes) for i, v in enumerate(value))


def check_choice(name: str, value, choices) -> str:
    """Return ``value`` if it is one of ``choices``."""
    if value not in choices:
        raise ParameterError(name, value, "one of " + ", ".join(repr(c) for c in choices),
                             "unknown choice")
    return value


def check_view(directions, sun_direction, observer_altitude_m) -> tuple:
    """The arguments every sky method's ``radiance`` takes, checked: unit view ``directions``
    (M, 3), a non-zero ``sun_direction`` (3,) and ``observer_altitude_m`` in [0, 1e8] m. Returns
    (directions (M, 3), unit sun direction, altitude) as float64."""
    dirs = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    if not np.allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-6):
        raise ParameterError("directions", f"array of shape {dirs.shape}", "unit vectors", "not normalized")
    sun = check_array("sun_direction", sun_direction, min_length=3)
    if sun.size != 3 or not np.linalg.norm(sun) > 0.0:
        raise ParameterError("sun_direction", sun.tolist(), "a non-zero 3-vector", "invalid direction")
    altitude = check_number("observer_altitude_m", observer_altitude_m, 0.0, 1.0e8)
    return dirs, sun / np.linalg.norm(sun), altitude


# --- output paths ---------------------------------------------------------------------------------

def check_output_file(path: str, suffix: str, option: str) -> None:
    """Refuse ``path`` (named ``option`` in the error) unless it ends in ``suffix``, is not a
    directory and lies under a writable directory."""
    path = os.fspath(path)
    if not path.lower().endswith(suffix):
        raise ParameterError(option, path, f"a file name ending in {suffix}", "wrong extension")
    if os.path.isdir(path):
        raise ParameterError(option, path, f"a file name ending in {suffix}", "an existing directory")
    _check_writable(os.path.dirname(os.path.abspath(path)), path, option)


def check_output_directory(path: str, option: str) -> None:
    """Refuse ``path`` (named ``option`` in the error) unless it is a directory, or can become
    one, under a writable directory."""
    path = os.fspath(path)
    if os.path.exists(path) and not os.path.isdir(path):
        raise ParameterError(option, path, "a directory", "an existing file")
    _check_writable(os.path.abspath(path), path, option)


def _check_writable(directory: str, shown: str, option: str) -> None:
    """The nearest existing ancestor of ``directory`` must be a directory where a file can be
    created (probed with a temporary file, removed again)."""
    existing = directory
    while not os.path.exists(existing):
        existing = os.path.dirname(existing)
    if not os.path.isdir(existing):
        raise ParameterError(option, shown, "a path in a writable directory", f"{existing} is a file")
    try:
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as exc:
        raise ParameterError(option, shown, "a path in a writable directory",
                             f"cannot write in {existing} ({exc.strerror})") from None


def safe_file_name(name: str) -> str:
    """``name`` as one file name that stays where it is put: characters other than letters,
    digits, '.', '_' and '-' become '_', leading dots are dropped (no '..', no hidden files),
    at most MAX_FILE_NAME characters; 'unnamed' if nothing is left."""
    safe = re.sub(r"[^A-Za-z0-9._-]", "_", str(name)).lstrip(".")[:MAX_FILE_NAME]
    return safe or "unnamed"
