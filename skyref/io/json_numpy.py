"""JSON for records that hold NumPy values."""

from __future__ import annotations

import numpy as np

__all__ = ["numpy_default"]


def numpy_default(value):
    """``default=`` hook of :func:`json.dump`: NumPy scalars become Python numbers and arrays
    nested lists; anything else is refused with the type's name."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")
