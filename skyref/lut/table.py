"""A look-up table on a Dr.Jit array, read back with GPU-texture semantics.

A table holds ``shape = (n_0, ..., n_{d-1})`` cells per wavelength channel, stored flat with the
channel fastest (index = ((i_0 n_1 + i_1) n_2 + ...) N + k). Lookups take texture coordinates
u_j in [0, 1] per axis, with cell i's centre at u = (i + 1/2) / n_j and clamp-to-edge outside,
and interpolate multilinearly: exactly what ``texture()`` does on a GPU, so a parametrization
written for GPU textures (texel-centre mapping 0.5/n + x (1 - 1/n)) reads the same values here.

Storage precision is a property of the table: ``float16`` rounds every stored value to half
precision (as an engine storing RGBA16F textures would); arithmetic stays in double.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from skyref.validation import check_choice

__all__ = ["PRECISIONS", "texture_coordinate", "unit_range", "cell_centres", "channel_values", "Table"]

PRECISIONS = ("float32", "float16")


def texture_coordinate(x, size: int):
    """Unit-range value x in [0, 1] -> texture coordinate of a table with ``size`` cells whose
    first and last cell centres sit at x = 0 and x = 1 (Bruneton 2017, GetTextureCoordFromUnitRange)."""
    return 0.5 / size + x * (1.0 - 1.0 / size)


def unit_range(u, size: int):
    """Inverse of :func:`texture_coordinate`."""
    return (u - 0.5 / size) / (1.0 - 1.0 / size)


def cell_centres(size: int) -> np.ndarray:
    """Texture coordinates of the cell centres of an axis with ``size`` cells."""
    return (np.arange(size) + 0.5) / size


def channel_values(per_channel) -> np.ndarray:
    """One Dr.Jit array per channel (one lane per cell) as a NumPy array (cells, channels)."""
    return np.stack([np.asarray(x.numpy(), dtype=np.float64) for x in per_channel], axis=-1)


class Table:
    """A ``shape`` x ``channels`` table of float values (see module docstring)."""

    def __init__(self, values, shape: tuple, channels: int, precision: str = "float32"):
        self.shape = tuple(int(n) for n in shape)
        self.channels = int(channels)
        self.precision = check_choice("precision", precision, PRECISIONS)
        values = np.asarray(values, dtype=np.float64).reshape(-1)
        if values.size != int(np.prod(self.shape)) * self.channels:
            raise ValueError(f"table of shape {self.shape} x {self.channels} channels given "
                             f"{values.size} values")
        stored = values.astype(np.float16 if self.precision == "float16" else np.float32)
        self.values = mi.Float64(stored.astype(np.float64))

    @classmethod
    def from_lanes(cls, lanes, shape: tuple, channels: int, precision: str = "float32") -> "Table":
        """A table from a Dr.Jit array with one lane per (cell, channel), channel fastest."""
        return cls(lanes.numpy(), shape, channels, precision)

    @classmethod
    def from_channels(cls, per_channel, shape: tuple, precision: str = "float32", scale: float = 1.0) -> "Table":
        """A table from one Dr.Jit array per channel with one lane per cell, times ``scale``."""
        return cls(channel_values(per_channel) * scale, shape, len(per_channel), precision)

    def numpy(self) -> np.ndarray:
        """The stored values as an array of shape ``shape + (channels,)``."""
        return self.values.numpy().reshape(self.shape + (self.channels,))

    def lookup(self, coords, channel=None):
        """Multilinear lookup at texture coordinates ``coords`` (one Dr.Jit array per axis).
        ``channel``: a UInt32 array (one channel per lane; returns an array) or ``None`` (every
        channel; returns a list of ``channels`` arrays)."""
        if len(coords) != len(self.shape):
            raise ValueError(f"a {len(self.shape)}-D table needs {len(self.shape)} coordinates")
        lower, weights = [], []
        for u, n in zip(coords, self.shape):
            x = dr.clip(mi.Float64(u) * n - 0.5, 0.0, n - 1.0)
            i = dr.minimum(mi.UInt32(dr.floor(x)), max(n - 2, 0))
            lower.append(i)
            weights.append(x - mi.Float64(i) if n > 1 else mi.Float64(0.0))
        strides = [1] * len(self.shape)
        for j in range(len(self.shape) - 2, -1, -1):
            strides[j] = strides[j + 1] * self.shape[j + 1]
        channels = [mi.UInt32(channel)] if channel is not None else [mi.UInt32(k) for k in range(self.channels)]
        results = [mi.Float64(0.0) for _ in channels]
        for corner in range(1 << len(self.shape)):
            weight = mi.Float64(1.0)
            cell = mi.UInt32(0)
            for j, (i, w, n) in enumerate(zip(lower, weights, self.shape)):
                upper = (corner >> j) & 1
                weight *= w if upper else 1.0 - w
                cell += (i + (upper if n > 1 else 0)) * strides[j]
            for r, k in enumerate(channels):
                results[r] += weight * dr.gather(mi.Float64, self.values, cell * self.channels + k)
        return results[0] if channel is not None else results
