"""Error maps and statistics of a sky method against the ground truth.

Per pixel (all maps share the image's shape):

- ``luminance``: relative luminance error (Y_method - Y_truth) / Y_truth;
- ``spectral``: root mean square over wavelengths of the relative spectral radiance error;
- ``delta_e``: CIEDE2000 on an *absolute* basis: both images' XYZ divided by one white, the
  ground truth's brightest sky pixel (L* = 100 there), D65 white point — so a method that is
  uniformly 10% too dark shows a colour difference, as it would on screen at fixed exposure.

Beside each map, the ground truth's own noise on the same quantity: SE_Y / Y_truth with SE_Y
= sum_k w_k SE_k (the luminance weights w; an upper bound, the wavelengths share paths), the RMS
of SE_k / L_k, and the CIEDE2000 between the truth and the truth raised by one standard error.
A statistic is *resolved* when the noise's statistic is at most 1/5 of the error's.

Statistics per region (:mod:`skyref.audit.regions`): the signed mean, the noise-corrected RMS,
the 95th percentile and the maximum of |error| (see :func:`_statistics`). Region means and
RMS average the truth's noise down over many pixels; p95 and max do not, and are reported as
noise-limited where they are. Pixels that carry one estimate, copied (a truth rendered with its
symmetric views traced once, :mod:`skyref.symmetry`), average nothing down: their noise adds
coherently (:func:`shared_estimates`). Pixels where the truth is black (space seen from orbit) carry no
relative error.

Scale and shape apart (:func:`scale_statistics`): a model can be right in shape and wrong in
overall brightness (a published model whose sun or calibration differs from the ground truth's).
Beside its luminance RMS error as it is, the audit reports the single factor s that best rescales
it (:func:`best_scale`: least squares on radiance over the region's directions and every
wavelength) and the luminance RMS error of s times the method.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skyref.audit.regions import REGIONS
from skyref.color import ciede2000, spectral_to_linear_srgb, xyz_matrix

__all__ = ["DYNAMIC_RANGE", "MAX_PIXEL_NOISE", "METRICS", "NOISE_RATIO", "SCALE_DEFINITION", "STATISTICS", "ErrorMaps",
           "best_scale", "error_maps", "region_statistics", "scale_statistics", "shared_estimates"]

METRICS = ("luminance", "spectral", "delta_e")
STATISTICS = ("mean", "rms", "p95", "max")
#: The ground truth must be this many times less noisy than the error it measures.
NOISE_RATIO = 5.0
#: Pixels darker than this fraction of the image's brightest (solar disk excluded) carry no
#: relative error: no exposure shows them beside the bright sky (space, the night side).
DYNAMIC_RANGE = 1e-4
#: Pixels whose ground-truth luminance is more uncertain than this (SE_Y / Y) are left out of the
#: statistics: a ratio to a noisier truth is biased and its noise estimate unreliable. Their
#: number is reported (``unmeasured``); a region that loses most of its pixels is unresolved.
MAX_PIXEL_NOISE = 0.2
#: What :func:`scale_statistics` reports, in words (for the reports).
SCALE_DEFINITION = ("s minimises sum (s L_method - L_truth)^2 over the sky's measured directions and every "
                    "wavelength, each (direction, wavelength) weighing the same in radiance (W m^-2 sr^-1 nm^-1: "
                    "the brightest directions and wavelengths weigh most); the RMS after it is the luminance RMS "
                    "error of s x the method")


@dataclass
class ErrorMaps:
    """Per-pixel errors and the ground truth's noise on each (see module docstring)."""

    error: dict          # metric -> (H, W)
    noise: dict          # metric -> (H, W)
    valid: np.ndarray    # (H, W) pixels where the truth is lit and measured and the method finite
    lit: np.ndarray      # (H, W) pixels where the truth is lit (DYNAMIC_RANGE)
    estimates: np.ndarray  # (H, W) which estimate of the truth each pixel carries (shared_estimates)


def shared_estimates(truth_radiance, truth_standard_error) -> np.ndarray:
    """Labels (the inputs' shape without the last, wavelength axis) of the ground truth's
    estimates: pixels that carry one estimate, copied to each of them (:mod:`skyref.symmetry`),
    share a label. They are told by their radiance and standard error being equal bit for bit in
    every channel, which independent estimates never are (black pixels, with no noise, may share
    one label too)."""
    t, se = np.asarray(truth_radiance), np.asarray(truth_standard_error)
    rows = np.ascontiguousarray(np.concatenate([t.reshape(-1, t.shape[-1]), se.reshape(-1, se.shape[-1])], axis=1))
    as_bytes = rows.view(np.dtype((np.void, rows.dtype.itemsize * rows.shape[1]))).reshape(-1)
    _, labels = np.unique(as_bytes, return_inverse=True)
    return labels.reshape(t.shape[:-1])


def error_maps(method_radiance, truth_radiance, truth_standard_error, wavelengths_nm) -> ErrorMaps:
    """Maps comparing ``method_radiance`` with ``truth_radiance`` (both (H, W, N), W m^-2 sr^-1
    nm^-1, solar disk excluded from both) given the truth's standard error (H, W, N)."""
    m = np.asarray(method_radiance, dtype=np.float64)
    t = np.asarray(truth_radiance, dtype=np.float64)
    se = np.asarray(truth_standard_error, dtype=np.float64)
    weights = xyz_matrix(wavelengths_nm)[:, 1]
    y_m, y_t, se_y = m @ weights, t @ weights, se @ np.abs(weights)
    brightest = np.nanmax(np.where(np.isfinite(y_t), y_t, 0.0), initial=0.0)
    lit = np.isfinite(y_t) & (y_t > DYNAMIC_RANGE * brightest)
    with np.errstate(divide="ignore", invalid="ignore"):
        measured = se_y <= MAX_PIXEL_NOISE * y_t
    valid = lit & measured & np.all(np.isfinite(m), axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        luminance = np.where(valid, (y_m - y_t) / y_t, np.nan)
        luminance_noise = np.where(valid, se_y / y_t, np.nan)
        positive = t > 0
        relative = np.where(positive, (m - t) / t, 0.0)
        relative_noise = np.where(positive, se / t, 0.0)
        count = np.maximum(positive.sum(axis=-1), 1)
        spectral = np.where(valid, np.sqrt((relative ** 2).sum(axis=-1) / count), np.nan)
        spectral_noise = np.where(valid, np.sqrt((relative_noise ** 2).sum(axis=-1) / count), np.nan)
    rgb_t = spectral_to_linear_srgb(np.where(np.isfinite(t), t, 0.0), wavelengths_nm)
    rgb_m = spectral_to_linear_srgb(np.where(np.isfinite(m), m, 0.0), wavelengths_nm)
    rgb_noisy = spectral_to_linear_srgb(np.where(np.isfinite(t), t + se, 0.0), wavelengths_nm)
    white = float(np.max(np.where(valid, y_t, 0.0), initial=0.0)) or 1.0
    delta_e = np.where(valid, ciede2000(rgb_m, rgb_t, white), np.nan)
    delta_e_noise = np.where(valid, ciede2000(rgb_noisy, rgb_t, white), np.nan)
    return ErrorMaps(error={"luminance": luminance, "spectral": spectral, "delta_e": delta_e},
                     noise={"luminance": luminance_noise, "spectral": spectral_noise, "delta_e": delta_e_noise},
                     valid=valid, lit=lit & np.all(np.isfinite(m), axis=-1),
                     estimates=shared_estimates(t, se))


def _statistics(error, noise, estimates=None) -> dict:
    """Statistics of one metric over a region's pixels, each beside the ground truth's noise on
    it. ``mean`` is the signed mean (its noise: sqrt(sum n_i^2) / n); ``rms`` is the root mean
    square with the truth's noise variance removed, sqrt(max(0, mean(e^2) - mean(n^2))) (its
    noise: the standard error of that estimate, from the delta method, sqrt(sum 4 e_i^2 n_i^2 +
    2 n_i^4) / n); ``p95`` and ``max`` are of |e| per pixel, their noise the same statistic of
    the per-pixel noise n. ``estimates``: labels of the truth's estimates (:func:`shared_estimates`);
    pixels that share one share its noise draw, so in the sums above their terms n_i and 2 e_i n_i
    add before they are squared (and the n_i^2 before the n^4 term's). None: every pixel its own."""
    keep = np.isfinite(error) & np.isfinite(noise)
    e, n = error[keep], noise[keep]
    if e.size == 0:
        return None
    count = e.size
    if estimates is None:
        coherent = np.asarray
    else:
        _, label = np.unique(np.asarray(estimates)[keep], return_inverse=True)

        def coherent(values):
            return np.bincount(label.reshape(-1), weights=values)
    mean_square = float(np.mean(e * e) - np.mean(n * n))
    rms = float(np.sqrt(max(mean_square, 0.0)))
    ms_noise = float(np.sqrt(np.sum(coherent(2.0 * e * n) ** 2 + 2.0 * coherent(n * n) ** 2)) / count)
    a = np.abs(e)
    scale = max(2.0 * rms, float(np.sqrt(ms_noise)))                  # 0 only for exact, noiseless data
    return {"mean": float(e.mean()), "noise_mean": float(np.sqrt(np.sum(coherent(n) ** 2)) / count),
            "rms": rms, "noise_rms": ms_noise / scale if scale > 0.0 else 0.0,
            "p95": float(np.percentile(a, 95.0)), "noise_p95": float(np.percentile(n, 95.0)),
            "max": float(a.max()), "noise_max": float(n.max())}


def region_statistics(maps: ErrorMaps, masks: dict) -> dict:
    """``{region: {"pixels": n, "unmeasured": m, metric: {stat: value, "noise_" + stat: value,
    "resolved_" + stat: bool}}}`` for every region with at least one valid pixel; a statistic is
    resolved when its noise is at most 1/NOISE_RATIO of its magnitude and at most half of the
    region's lit pixels were too noisy to measure. CIEDE2000 is not signed: its ``mean`` is
    the mean difference and its noise the mean of the noise map."""
    table = {}
    for region in REGIONS:
        mask = masks[region] & maps.valid
        if not mask.any():
            continue
        unmeasured = int((masks[region] & maps.lit & ~maps.valid).sum())
        row = {"pixels": int(mask.sum()), "unmeasured": unmeasured}
        covered = unmeasured <= row["pixels"]
        for metric in METRICS:
            entry = _statistics(maps.error[metric][mask], maps.noise[metric][mask], maps.estimates[mask])
            if metric == "delta_e":
                entry["noise_mean"] = float(np.mean(maps.noise[metric][mask]))
            for stat in STATISTICS:
                entry[f"resolved_{stat}"] = covered and bool(entry[f"noise_{stat}"] * NOISE_RATIO <= abs(entry[stat]))
            row[metric] = entry
        table[region] = row
    return table


def best_scale(method_radiance, truth_radiance) -> float:
    """The factor s minimising sum (s m - t)^2 over every value given (directions x wavelengths,
    radiance in W m^-2 sr^-1 nm^-1): s = sum m t / sum m^2. Every (direction, wavelength) value
    weighs the same in radiance, so the brightest directions and wavelengths weigh most. NaN if
    the method is black everywhere."""
    m = np.asarray(method_radiance, dtype=np.float64).ravel()
    t = np.asarray(truth_radiance, dtype=np.float64).ravel()
    power = float(m @ m)
    return float(m @ t) / power if power > 0.0 else float("nan")


def scale_statistics(maps: ErrorMaps, method_radiance, truth_radiance, mask) -> dict | None:
    """Scale and shape apart over the measured pixels of ``mask`` (``maps.valid`` of it; the
    radiances (H, W, N) as given to :func:`error_maps`): ``factor``, the :func:`best_scale` of
    the method over those pixels and every wavelength; ``rms`` and ``rms_scaled``, the
    noise-corrected luminance RMS error (see :func:`_statistics`) of the method as it is and of
    factor x method, whose relative luminance error is s (1 + e) - 1 beside the same truth
    noise; each with its ``noise_`` and ``resolved_`` (the noise at most 1/NOISE_RATIO of the
    value). None without a measured pixel."""
    keep = np.asarray(mask) & maps.valid
    if not keep.any():
        return None
    m, t = np.asarray(method_radiance, dtype=np.float64)[keep], np.asarray(truth_radiance, dtype=np.float64)[keep]
    both = np.isfinite(m) & np.isfinite(t)
    factor = best_scale(m[both], t[both])
    error, noise = maps.error["luminance"][keep], maps.noise["luminance"][keep]
    result = {"factor": factor}
    for key, e in (("rms", error), ("rms_scaled", factor * (1.0 + error) - 1.0)):
        entry = _statistics(e, noise, maps.estimates[keep])
        result.update({key: entry["rms"], f"noise_{key}": entry["noise_rms"],
                       f"resolved_{key}": bool(entry["noise_rms"] * NOISE_RATIO <= entry["rms"])})
    return result
