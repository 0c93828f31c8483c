"""Ground truth for audits: the path tracer's sky for a scene, rendered until its noise is
small enough, and cached on disk (spectral EXR, keyed by the scene and the noise target) so
repeated audits of different methods on one scene render it once; and the polarized truth's I
made from a scalar one (:func:`polarization_change`, :func:`with_polarization`)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os

import numpy as np

from skyref.io.exr import read_sky_exr, write_sky_exr
from skyref.render import render_paired, render_to_error
from skyref.validation import safe_file_name

__all__ = ["ROUNDS", "cache_key", "cache_path", "ground_truth", "polarization_change", "with_polarization"]

#: Most rendering rounds per ground truth.
ROUNDS = 8


def cache_key(scene, target_relative_error: float, max_spp: int) -> str:
    text = json.dumps({"scene": scene.to_dict(), "target": target_relative_error, "max_spp": max_spp},
                      sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def cache_path(cache_dir: str, scene, target_relative_error: float, max_spp: int) -> str:
    """Where the ground truth of ``scene`` is cached: inside ``cache_dir`` whatever the scene's
    name (made a safe file name), keyed by the scene's content and the sample budget."""
    name = f"{safe_file_name(scene.name or 'scene')}-{cache_key(scene, target_relative_error, max_spp)}"
    return os.path.join(cache_dir, f"{name}.exr")


def ground_truth(scene, target_relative_error: float, max_spp: int, cache_dir: str | None = None,
                 variant: str | None = None):
    """The scene's sky with the 95th percentile of standard error / radiance at most
    ``target_relative_error`` (or ``max_spp`` samples per pixel); read from ``cache_dir`` when
    rendered before."""
    path = None
    if cache_dir is not None:
        path = cache_path(cache_dir, scene, target_relative_error, max_spp)
        if os.path.exists(path):
            return read_sky_exr(path)
    seeds = [scene.render.seed * ROUNDS + r for r in range(ROUNDS)]
    sky = render_to_error(scene, target_relative_error, seeds, max_spp, variant=variant)
    if path is not None:
        write_sky_exr(sky, path)
    return sky


def polarization_change(scene, spp: int, seed: int, variant: str | None = None) -> tuple:
    """What polarized transport changes in the radiance of the scalar ``scene``: I of the
    polarized render minus the scalar radiance, both traced along the same paths
    (:func:`skyref.render.render_paired`, ``spp`` samples per pixel, every pixel), and the
    standard error of that difference (each (H, W, N), W m^-2 sr^-1 nm^-1); and the CPU seconds
    of the pair. The two transports' noise is mostly common and cancels in the difference, so
    the change is known far better than either render."""
    polarized = scene.replace(render=dataclasses.replace(scene.render, polarized=True))
    scalar_sky, polarized_sky, change_error = render_paired(scene, polarized, spp, seed, variant)
    cpu_s = scalar_sky.metadata["render_cpu_s"] + polarized_sky.metadata["render_cpu_s"]
    return polarized_sky.radiance - scalar_sky.radiance, change_error, cpu_s


def with_polarization(truth, change, change_error):
    """The polarized truth's I: the scalar ground truth ``truth`` (a :class:`~skyref.sky.Sky`)
    plus the :func:`polarization_change` of its scene, rendered with seeds of its own. Unbiased
    where both are; the two are independent, so their standard errors add in quadrature. The
    solar disk (``sun_direct``, the same in both transports) is kept; the other orders, which
    no longer sum to the radiance, are dropped."""
    orders = {name: truth.orders[name] for name in ("sun_direct",) if name in truth.orders}
    return dataclasses.replace(truth, radiance=truth.radiance + change,
                               standard_error=np.hypot(truth.standard_error, change_error), orders=orders,
                               metadata=dict(truth.metadata, polarization="I: scalar truth + paired change"))
