"""Errors of a coefficient table against training skies (the ground truth), beside the truth's
own noise.

The relative error of a direction is (model - truth) / truth; its noise is the truth's standard
error / truth. Statistics are those of the LUT audits (:func:`skyref.audit.metrics._statistics`:
signed mean, noise-corrected RMS, 95th percentile and maximum of |error|, each with the noise's
value) over the directions the fit uses (above the horizon, off the solar disk, truth > 0), per
channel and per sky configuration (solar elevation, turbidity, albedo).

Also: :func:`interpolation_gap`, how a table behaves between the configurations it stores (where
no ground truth was fitted), and :func:`throughput`, its evaluation speed.
"""

from __future__ import annotations

import time

import numpy as np

from skyref.analytic.hosek import ALBEDOS, TURBIDITIES
from skyref.audit.metrics import _statistics, shared_estimates
from skyref.extras import require

__all__ = ["error_summary", "interpolation_gap", "model_radiance", "relative_errors", "throughput"]


def model_radiance(table, training) -> np.ndarray:
    """(S, P, C) radiance of ``table`` along the training directions for each sky's
    configuration, in the training set's channels."""
    theta = np.arccos(np.clip(training.cos_theta, -1.0, 1.0))
    radiance = table.radiance(theta[None, :], training.gamma, training.solar_elevation[:, None],
                              training.turbidity[:, None], training.albedo[:, None])
    return radiance[..., training.channel_indices]


def relative_errors(table, training) -> tuple[np.ndarray, np.ndarray]:
    """(error, noise), both (S, P, C): relative error of ``table`` and relative standard error of
    the truth; NaN where the direction is not used (zero weight)."""
    used = training.weights() > 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        error = np.where(used, model_radiance(table, training) / training.radiance - 1.0, np.nan)
    return error, training.relative_noise()


def error_summary(table, training) -> dict:
    """Statistics of ``table`` against ``training``: ``{"channels": {channel: stats}, "skies":
    [{"solar_elevation_deg", "turbidity", "albedo", "channels": {channel: stats}}, ...]}``
    (stats as :func:`skyref.audit.metrics._statistics`; None where a sky has no used direction)."""
    error, noise = relative_errors(table, training)
    estimates = shared_estimates(training.radiance, training.standard_error)      # (S, P)
    summary = {"channels": {c: _statistics(error[..., i], noise[..., i], estimates)
                            for i, c in enumerate(training.channels)}, "skies": []}
    for s in range(len(training.solar_elevation)):
        summary["skies"].append({
            "solar_elevation_deg": float(np.degrees(training.solar_elevation[s])),
            "turbidity": float(training.turbidity[s]), "albedo": float(training.albedo[s]),
            "channels": {c: _statistics(error[s, :, i], noise[s, :, i], estimates[s])
                         for i, c in enumerate(training.channels)}})
    return summary


def throughput(table, directions: int = 1 << 20, repeats: int = 3) -> dict:
    """Directions per second of ``table.radiance`` for one configuration (every channel), in
    NumPy (float64) and in JAX (jit-compiled, float32 on the default device); the best of
    ``repeats`` timed runs after a warm-up."""
    require("fit")
    import jax  # lazy: JAX's start-up cost, paid only when its speed is measured
    import jax.numpy as jnp

    rng = np.random.default_rng(0)
    theta = rng.uniform(0.0, 0.5 * np.pi, directions)
    gamma = rng.uniform(0.0, np.pi, directions)
    configuration = (0.3, 3.0, 0.1)

    def best(run):
        run()
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            run()
            times.append(time.perf_counter() - start)
        return directions / min(times)

    evaluate = jax.jit(lambda t, g: table.radiance(t, g, *configuration, xp=jnp))
    theta_j, gamma_j = jnp.asarray(theta, dtype=jnp.float32), jnp.asarray(gamma, dtype=jnp.float32)
    return {"numpy": best(lambda: table.radiance(theta, gamma, *configuration)),
            "jax": best(lambda: evaluate(theta_j, gamma_j).block_until_ready()),
            "channels": len(table.channels), "jax_device": str(jax.devices()[0])}


def interpolation_gap(table, elevations_deg=(3.0, 10.0, 30.0, 60.0), steps: int = 24) -> dict:
    """How smoothly ``table`` passes between its stored configurations: the sky halfway between two
    stored turbidities (t + 1/2, each albedo) or at albedo 1/2 (each turbidity), as the model
    evaluates it (by blending coefficients, like the published code), against the mean of the two
    stored skies' radiances. A table whose neighbouring configurations agree on their coefficients
    blends them into a sky between the two (gap ~0); one whose coefficients trade against each other
    differently at each configuration does not, and every sky off the grid inherits that error.

    Returns {"turbidity": stats, "albedo": stats} with "median" and "p95" of |gap| over a grid of
    directions above the horizon (``steps`` x 2 ``steps``), ``elevations_deg`` and every channel
    (directions where both neighbours have zero radiance are left out)."""
    theta, gamma = np.meshgrid(np.radians(np.linspace(0.0, 89.0, steps)), np.radians(np.linspace(2.0, 178.0, 2 * steps)))
    pairs = {"turbidity": [((low, a), (high, a)) for a in ALBEDOS for low, high in zip(TURBIDITIES[:-1], TURBIDITIES[1:])],
             "albedo": [((t, ALBEDOS[0]), (t, ALBEDOS[1])) for t in TURBIDITIES]}
    found = {}
    for axis, neighbours in pairs.items():
        gaps = []
        for elevation in np.radians(elevations_deg):
            for first, second in neighbours:
                sky = [table.radiance(theta, gamma, elevation, *configuration) for configuration in (first, second)]
                halfway = table.radiance(theta, gamma, elevation, *(0.5 * (np.array(first) + np.array(second))))
                with np.errstate(divide="ignore", invalid="ignore"):
                    gaps.append(np.abs(halfway / (0.5 * (sky[0] + sky[1])) - 1.0).ravel())
        gaps = np.concatenate(gaps)
        gaps = gaps[np.isfinite(gaps)]
        found[axis] = {"median": float(np.median(gaps)), "p95": float(np.percentile(gaps, 95.0))}
    return found
