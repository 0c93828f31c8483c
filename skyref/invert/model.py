"""The forward model of an inversion: the ground-truth ``atmosphere`` integrator rendering the
fitted pixels, and its Jacobian by forward-mode automatic differentiation through it.

A pixel's value is the mean radiance over its footprint. The model averages ``footprint^2``
directions per pixel: the centres of an even ``footprint x footprint`` split of the pixel's film
square, mapped by the camera (the renderer's box filter is uniform on the film too); each gets
spp / footprint^2 samples, so the cost per pixel does not depend on the split. Sub-directions
outside a fisheye's image circle are left out of the mean. The split is chosen so that each part
spans at most :data:`FOOTPRINT_DEG` (1 for pixels smaller than that).

The fit works with the logarithm of the model's channel values m (spectral radiance, or CIE XYZ
of it). Its Jacobian with respect to the free unknowns theta_k is

    d log m / d theta_k = sum_q (dm/dq) D[q, k] / m,

with dm/dq from :meth:`AtmosphereIntegrator.directional_derivative` (one forward-mode AD render
per integrator parameter q, unbiased) and D the chain matrix of
:meth:`skyref.invert.parameters.ParameterSet.chain`. The m in the denominator comes from the same
render as dm/dq (same seed), so their Monte Carlo errors partly cancel in the ratio; all the
derivative renders of one Jacobian share that seed too (see :meth:`ForwardModel.log_jacobian`).
The value render that gives the residuals uses another seed (:func:`stream_seed`): residuals and
Jacobian carry independent noise, so the gradient J^T r has no bias from their correlation.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from skyref.plugins import load_mitsuba
from skyref.projection import pixel_directions, solid_angle
from skyref.render import build_integrator

__all__ = ["FOOTPRINT_DEG", "MAX_FOOTPRINT", "ForwardModel", "footprint_split", "stream_seed"]

#: Largest angular size (degrees) of one footprint sub-direction's share of a pixel.
FOOTPRINT_DEG = 1.0

#: Most footprint splits per pixel side (16 directions per pixel).
MAX_FOOTPRINT = 4

#: Radiance estimates are clamped to this before taking logarithms (W m^-2 sr^-1 nm^-1, or the
#: same in XYZ units); sky pixels are far above it.
_TINY = 1e-30


def stream_seed(*keys: int) -> int:
    """A 31-bit sampler seed for a tuple of integers (run seed, iteration, stream): distinct
    tuples give statistically independent seeds."""
    return int(np.random.SeedSequence([int(k) for k in keys]).generate_state(1)[0] & 0x7FFFFFFF)


def footprint_split(camera, mask) -> int:
    """Splits per pixel side so that each part spans at most FOOTPRINT_DEG (median pixel of
    ``mask``), between 1 and MAX_FOOTPRINT."""
    size_deg = math.degrees(math.sqrt(float(np.median(solid_angle(camera)[mask]))))
    return int(np.clip(math.ceil(size_deg / FOOTPRINT_DEG - 1e-9), 1, MAX_FOOTPRINT))


class ForwardModel:
    """The fitted pixels (``rows``, ``cols`` of ``observation``) rendered by the ground truth for
    values of the unknowns of ``parameters``. ``footprint``: splits per pixel side (0: chosen
    by :func:`footprint_split`)."""

    def __init__(self, observation, parameters, rows, cols, footprint: int = 0, variant: str | None = None):
        self.mi = load_mitsuba(variant)
        self.observation = observation
        self.parameters = parameters
        camera = observation.camera
        split = footprint or footprint_split(camera, observation.mask)
        self.footprint = split
        fine = pixel_directions(dataclasses.replace(camera, width=camera.width * split, height=camera.height * split))
        sub = fine.reshape(camera.height, split, camera.width, split, 3)[rows, :, cols, :].reshape(len(rows), -1, 3)
        inside = np.all(np.isfinite(sub), axis=-1)
        #: (pixels, split^2) weights of the sub-directions in each pixel's mean.
        self.weights = inside / inside.sum(axis=1, keepdims=True)
        self.directions = np.where(inside[..., None], sub, [0.0, 0.0, 1.0]).reshape(-1, 3)
        scene = observation.scene(parameters.atmosphere_at(parameters.values))
        self.integrator = build_integrator(scene)

    @property
    def pixel_count(self) -> int:
        return self.weights.shape[0]

    def _set(self, values):
        import drjit as dr  # lazy: Dr.Jit only after load_mitsuba (in __init__) has pointed it at a working libLLVM

        for name, value in self.parameters.integrator_values(values).items():
            self.integrator.optics.set_parameter(name, dr.opaque(self.mi.Float, float(value)))

    def _spp_per_direction(self, spp: int) -> int:
        return max(1, round(spp / self.weights.shape[1]))

    def _pixel_channels(self, per_direction) -> np.ndarray:
        """(directions, 4 orders, N) -> (pixels, channels): orders summed, footprint averaged."""
        spectral = np.asarray(per_direction, dtype=np.float64).sum(axis=1)
        spectral = spectral.reshape(self.weights.shape + spectral.shape[-1:])
        return self.observation.to_channels(np.einsum("ps,psn->pn", self.weights, spectral))

    def _chunks(self, spp: int) -> list[int]:
        """The integrator's launch sizes for ``spp`` samples per pixel: each launch (and each AD
        render of the Jacobian) gets its own seed."""
        return self.integrator.launch_sizes(len(self.directions), self._spp_per_direction(spp))

    def radiance(self, values, seed: int, spp: int) -> np.ndarray:
        """(pixels, channels) model values at ``values`` (all unknowns), ``spp`` samples per
        pixel from sampler seed ``seed``."""
        self._set(values)
        chunks = self._chunks(spp)
        total = sum(n * self.integrator.render_directions(self.directions, stream_seed(seed, c), n).numpy()
                    for c, n in enumerate(chunks))
        return self._pixel_channels(total / sum(chunks))

    def log_jacobian(self, values, seed: int, spp: int) -> np.ndarray:
        """(pixels, channels, free) d log m / d theta at ``values``: one AD render per integrator
        parameter moved by a free unknown, all with the same seed (common random numbers), so that
        a combination such as d/dalpha at fixed tau_550 = d/dalpha + beta ln 0.55 d/dbeta, whose
        terms nearly cancel, does not add their noise."""
        self._set(values)
        names, chain = self.parameters.chain(values)
        jacobian = 0.0
        chunks = self._chunks(spp)
        for i, name in enumerate(names):
            value, derivative = 0.0, 0.0
            for c, n in enumerate(chunks):
                v, d = self.integrator.directional_derivative(self.directions, name, stream_seed(seed, c), n)
                value, derivative = value + n * v, derivative + n * d
            ratio = self._pixel_channels(derivative) / np.maximum(self._pixel_channels(value), _TINY)
            jacobian = jacobian + ratio[..., None] * chain[i]
        return jacobian

    @staticmethod
    def log(values) -> np.ndarray:
        return np.log(np.maximum(values, _TINY))
