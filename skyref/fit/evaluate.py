"""Errors of a coefficient table against training skies (the ground truth), beside the truth's
own noise.

The relative error of a direction is (model - truth) / truth; its noise is the truth's standard
error / truth. Statistics are those of the LUT audits (:func:`skyref.audit.metrics._statistics`:
signed mean, noise-corrected RMS, 95th percentile and maximum of |error|, each with the noise's
value) over the directions the fit uses (above the horizon, off the solar disk, truth > 0), per
channel and per sky configuration (solar elevation, turbidity, albedo).
"""

from __future__ import annotations

import time

import numpy as np

from skyref.audit.metrics import _statistics


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
    summary = {"channels": {c: _statistics(error[..., i], noise[..., i]) for i, c in enumerate(training.channels)},
               "skies": []}
    for s in range(len(training.solar_elevation)):
        summary["skies"].append({
            "solar_elevation_deg": float(np.degrees(training.solar_elevation[s])),
            "turbidity": float(training.turbidity[s]), "albedo": float(training.albedo[s]),
            "channels": {c: _statistics(error[s, :, i], noise[s, :, i]) for i, c in enumerate(training.channels)}})
    return summary


def throughput(table, directions: int = 1 << 20, repeats: int = 3) -> dict:
    """Directions per second of ``table.radiance`` for one configuration (every channel), in
    NumPy (float64) and in JAX (jit-compiled, float32 on the default device); the best of
    ``repeats`` timed runs after a warm-up."""
    import jax
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
