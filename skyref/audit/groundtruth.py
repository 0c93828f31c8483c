"""Ground truth for audits: the path tracer's sky for a scene, rendered until its noise is
small enough, and cached on disk (spectral EXR, keyed by the scene and the noise target) so
repeated audits of different methods on one scene render it once."""

from __future__ import annotations

import hashlib
import json
import os

from skyref.io.exr import read_sky_exr, write_sky_exr
from skyref.render import render_to_error
from skyref.validation import safe_file_name

__all__ = ["ROUNDS", "cache_key", "cache_path", "ground_truth"]

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
