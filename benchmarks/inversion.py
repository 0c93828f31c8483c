"""Synthetic round trips of ``skyref.invert``: bias, spread and coverage of the recovered
atmosphere parameters, and the time to converge.

Each case draws a realistic atmosphere (aerosol optical depth at 550 nm log-uniform in
0.03-0.6, Angstrom alpha 0.3-2, Cornette–Shanks g 0.65-0.9, ozone 230-450 DU, ground albedo
0.05-0.5, on the bruneton2017 base) and a sun (zenith 20-85 deg, any azimuth), renders it with
the ground truth (4096 spp, on the 8 wavelengths 400-680 nm that RGB images are modelled on),
adds photon-like noise (Poisson, 10,000 photons at the median pixel and channel: 1% there, more
in darker pixels; the render's own Monte Carlo noise, ~1-2%, comes on top) and an unknown
exposure (x 10^U(-2, 2)), and inverts it with the default unknowns (aod_550, angstrom_alpha,
aerosol_g, ozone_du, ground_albedo) plus the exposure, from the default start values.

Cases cycle through four configurations: spectral or RGB (the linear sRGB of the same render,
fitted as XYZ), and a 48x48 fisheye of the upper hemisphere (sky only, the default mask) or a
64x32 equirectangular map with the ground in view (the model's uniform Lambertian ground is the
truth's, so it is fitted too).

Reported per unknown and configuration: bias and spread of the error, the share within the
targets of issue 7 (aod 3%, g 0.02, albedo 0.03, ozone 10% from spectral images), how often the
stated standard deviation covers the truth (1 and 2 std; 68% and 95% expected) for the
cluster-robust uncertainty the inversion reports and for the plain curvature one, and how often
the unknown was flagged "not identifiable". Every number comes from the ground-truth path tracer
(no surrogate).

Usage: ``python benchmarks/inversion.py [--cases 24] [--quick] [--fresh]``; writes
results/inversion.md, results/inversion/*.png and one JSON per case in results/inversion/cases/
(reused by a later run with the same settings, so an interrupted run resumes). ``--quick``:
small images and budgets, to check that the script works (numbers not meaningful).
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from results_files import machine  # noqa: E402

from skyref.plugins import load_mitsuba  # noqa: E402

VARIANT = "llvm_ad_rgb"
mi = load_mitsuba(VARIANT)

from skyref.atmosphere import preset  # noqa: E402
from skyref.invert import InversionSettings, ParameterSet, image_from_sky, invert, observation  # noqa: E402
from skyref.invert.inputs import RGB_MODEL_WAVELENGTHS_NM  # noqa: E402
from skyref.io.atomic import atomic_write  # noqa: E402
from skyref.render import render_sky  # noqa: E402
from skyref.scene import Camera, RenderSettings, Scene, Sun  # noqa: E402

ROOT = os.path.join(os.path.dirname(__file__), "..")
REPORT = os.path.join(ROOT, "results", "inversion.md")
FIGURES = os.path.join(ROOT, "results", "inversion")
CASES = os.path.join(FIGURES, "cases")

CONFIGS = (("spectral", "fisheye"), ("rgb", "fisheye"), ("spectral", "equirectangular"), ("rgb", "equirectangular"))
UNKNOWNS = ("aod_550", "angstrom_alpha", "aerosol_g", "ozone_du", "ground_albedo")

#: Targets of issue 7: (relative or absolute, tolerance, channels it applies to).
TARGETS = {"aod_550": ("relative", 0.03, ("spectral", "rgb")), "aerosol_g": ("absolute", 0.02, ("spectral", "rgb")),
           "ground_albedo": ("absolute", 0.03, ("spectral", "rgb")), "ozone_du": ("relative", 0.10, ("spectral",))}

PHOTONS_AT_MEDIAN = 10_000

#: (image sizes, truth spp, inversion settings) for the full run and for --quick.
MODES = {
    "full": {"fisheye": (48, 48), "equirectangular": (64, 32), "truth_spp": 4096,
             "settings": InversionSettings(variant=VARIANT)},
    "quick": {"fisheye": (24, 24), "equirectangular": (32, 16), "truth_spp": 256,
              "settings": InversionSettings(pixels=150, spp_max=256, final_spp=1024, map_spp=16, max_iterations=5,
                                            variant=VARIANT)},
}


def draw_case(index: int, seed: int) -> dict:
    """The atmosphere, sun, exposure and configuration of case ``index`` (reproducible)."""
    rng = np.random.default_rng([seed, index])
    channels, camera = CONFIGS[index % len(CONFIGS)]
    truth = {"aod_550": float(math.exp(rng.uniform(math.log(0.03), math.log(0.6)))),
             "angstrom_alpha": float(rng.uniform(0.3, 2.0)), "aerosol_g": float(rng.uniform(0.65, 0.9)),
             "ozone_du": float(rng.uniform(230.0, 450.0)), "ground_albedo": float(rng.uniform(0.05, 0.5))}
    return {"index": index, "channels": channels, "camera": camera, "truth": truth,
            "sun_zenith_deg": float(rng.uniform(20.0, 85.0)), "sun_azimuth_deg": float(rng.uniform(0.0, 360.0)),
            "exposure": float(10.0 ** rng.uniform(-2.0, 2.0)), "noise_seed": int(rng.integers(1 << 31))}


def synthetic_image(case: dict, mode: dict, base):
    """The noisy, arbitrarily exposed image of ``case`` (a SkyImage with the scene's geometry)."""
    truth = ParameterSet(base, values=case["truth"])
    width, height = mode[case["camera"]]
    scene = Scene(atmosphere=truth.atmosphere_at(truth.values), sun=Sun(case["sun_zenith_deg"], case["sun_azimuth_deg"]),
                  camera=Camera(case["camera"], width, height), wavelengths=RGB_MODEL_WAVELENGTHS_NM,
                  render=RenderSettings(spp=mode["truth_spp"], passes=4, seed=case["index"] + 1))
    image = image_from_sky(render_sky(scene, variant=VARIANT), case["channels"])
    values = np.nan_to_num(np.maximum(image.values, 0.0))
    # Photon-like noise: Poisson counts, PHOTONS_AT_MEDIAN at the median positive value.
    scale = PHOTONS_AT_MEDIAN / float(np.median(values[values > 0]))
    rng = np.random.default_rng(case["noise_seed"])
    image.values = rng.poisson(values * scale) / scale * case["exposure"]
    return image


def run_case(case: dict, mode_name: str, base) -> dict:
    mode = MODES[mode_name]
    image = synthetic_image(case, mode, base)
    obs = observation(image, max_view_zenith_deg=180.0 if case["camera"] == "equirectangular" else 90.0,
                      atmosphere=base)
    start = time.perf_counter()
    result = invert(obs, ParameterSet(base, free=UNKNOWNS), mode["settings"])
    document = result.to_dict()
    return {**case, "mode": mode_name, "wall_time_s": time.perf_counter() - start,
            "estimates": {n: {k: document["estimates"][n][k] for k in
                              ("value", "std", "std_curvature", "identifiable", "posterior_to_prior_std", "at_bound")}
                          for n in UNKNOWNS},
            "exposure_estimate": document["exposure"]["value"], "exposure_std_log": document["exposure"]["std_log"],
            "fit": document["fit"], "residual_rms_log": document["residuals"]["all_usable_pixels"]["rms_log"]}


# --- statistics and report ---------------------------------------------------------------------------

def error(case, name) -> float:
    """Estimate - truth; relative for aod_550 and ozone_du (the targets are relative)."""
    value, truth = case["estimates"][name]["value"], case["truth"][name]
    return (value - truth) / truth if name in ("aod_550", "ozone_du") else value - truth


def scaled_std(case, name, key) -> float:
    std = case["estimates"][name][key]
    return std / case["truth"][name] if name in ("aod_550", "ozone_du") else std


def summary_rows(cases) -> list[str]:
    rows = []
    groups = [("all", lambda c: True)] + [(f"{ch} {cam}", lambda c, ch=ch, cam=cam: (c["channels"], c["camera"]) == (ch, cam))
                                          for ch, cam in CONFIGS]
    for name in UNKNOWNS:
        relative = name in ("aod_550", "ozone_du")
        unit = "%" if relative else ""
        factor = 100.0 if relative else 1.0
        for label, keep in groups:
            chosen = [c for c in cases if keep(c)]
            if not chosen:
                continue
            errors = np.array([error(c, name) for c in chosen])
            identifiable = np.array([c["estimates"][name]["identifiable"] for c in chosen])
            target = TARGETS.get(name)
            within = "—"
            if target is not None:
                applies = [i for i, c in enumerate(chosen) if c["channels"] in target[2]]
                if applies:
                    within = f"{np.mean(np.abs(errors[applies]) <= target[1]):.0%}"
            coverage = []
            for key in ("std", "std_curvature"):
                z = np.array([abs(error(c, name)) / scaled_std(c, name, key) for c in chosen])[identifiable]
                coverage.append(f"{np.mean(z <= 1):.0%} / {np.mean(z <= 2):.0%}" if z.size else "—")
            rows.append(f"| {name} | {label} | {len(chosen)} | {int((~identifiable).sum())} | "
                        f"{factor * errors.mean():+.3g}{unit} | "
                        f"{f'{factor * errors.std(ddof=1):.3g}{unit}' if len(chosen) > 1 else '—'} | "
                        f"{factor * np.median(np.abs(errors)):.3g}{unit} | {within} | {coverage[0]} | {coverage[1]} |")
    return rows


def timing_rows(cases) -> list[str]:
    rows = []
    for channels, camera in CONFIGS:
        chosen = [c for c in cases if (c["channels"], c["camera"]) == (channels, camera)]
        if not chosen:
            continue
        fit = np.array([c["fit"]["fit_time_s"] for c in chosen])
        total = np.array([c["wall_time_s"] for c in chosen])
        iterations = np.array([c["fit"]["iterations"] for c in chosen])
        converged = np.mean([c["fit"]["converged"] for c in chosen])
        rows.append(f"| {channels} {camera} | {len(chosen)} | {np.median(fit):.0f} | {fit.max():.0f} | "
                    f"{np.median(total):.0f} | {np.median(iterations):.0f} | {converged:.0%} | "
                    f"{np.median([c['residual_rms_log'] for c in chosen]):.3f} |")
    return rows


def plot(cases, directory) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(directory, exist_ok=True)
    markers = {config: m for config, m in zip(CONFIGS, "os^D")}
    fig, axes = plt.subplots(1, len(UNKNOWNS), figsize=(4 * len(UNKNOWNS), 4))
    for ax, name in zip(axes, UNKNOWNS):
        for config, marker in markers.items():
            chosen = [c for c in cases if (c["channels"], c["camera"]) == config]
            for flag, fill in ((True, None), (False, "none")):
                sub = [c for c in chosen if c["estimates"][name]["identifiable"] == flag]
                if not sub:
                    continue
                ax.errorbar([c["truth"][name] for c in sub], [c["estimates"][name]["value"] for c in sub],
                            yerr=[c["estimates"][name]["std"] for c in sub], fmt=marker, ms=4, capsize=2,
                            mfc=fill, color=f"C{CONFIGS.index(config)}",
                            label=f"{config[0]} {config[1]}" + ("" if flag else " (flagged)"))
        lo = min(min(c["truth"][name], c["estimates"][name]["value"]) for c in cases)
        hi = max(max(c["truth"][name], c["estimates"][name]["value"]) for c in cases)
        ax.plot([lo, hi], [lo, hi], "k:", lw=1)
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("truth")
        ax.set_ylabel("estimate ± std")
    axes[0].legend(fontsize=6)
    fig.tight_layout()
    scatter = os.path.join(directory, "estimates.png")
    with atomic_write(scatter, "wb") as f:
        fig.savefig(f, dpi=100, format="png")
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.5), sharey=True)
    grid = np.linspace(-4, 4, 200)
    for ax, key, title in ((axes[0], "std", "cluster-robust std (reported)"), (axes[1], "std_curvature", "plain curvature std")):
        z = [error(c, n) / scaled_std(c, n, key) for c in cases for n in UNKNOWNS if c["estimates"][n]["identifiable"]]
        ax.hist(np.clip(z, -4, 4), bins=24, range=(-4, 4), density=True, alpha=0.6)
        ax.plot(grid, np.exp(-0.5 * grid ** 2) / math.sqrt(2 * math.pi), "k-", lw=1, label="N(0, 1)")
        ax.set_title(f"(estimate - truth) / {title}", fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    zscores = os.path.join(directory, "zscores.png")
    with atomic_write(zscores, "wb") as f:
        fig.savefig(f, dpi=100, format="png")
    plt.close(fig)
    return [scatter, zscores]


def write_report(cases, mode_name, seed, elapsed):
    figures = plot(cases, FIGURES)
    relative = lambda p: os.path.relpath(p, os.path.dirname(REPORT))  # noqa: E731
    settings = MODES[mode_name]["settings"]
    command = "python benchmarks/inversion.py" + (f" --cases {len(cases)}" if len(cases) != 24 else "") + (
        " --quick" if mode_name == "quick" else "")
    lines = [
        "# Inversion: synthetic round trips",
        "",
        f"Generated by `{command}` on {datetime.date.today().isoformat()} ({machine()}"
        f", variant {VARIANT}; this run took {elapsed / 60:.1f} min, cases already in "
        "results/inversion/cases/ were reused).",
        "",
    ]
    if mode_name == "quick" or len(cases) < 20:
        lines += [f"**Preliminary: {len(cases)} case(s)" + (", quick settings (small images and budgets)" if mode_name == "quick" else "")
                  + ". The numbers below only show that the benchmark runs; `python benchmarks/inversion.py` (24 "
                  "cases, default settings) produces the table that counts.**", ""]
    lines += [
        "Method (benchmarks/inversion.py docstring): random realistic atmospheres (aod_550 0.03-0.6 log-uniform, "
        "alpha 0.3-2, g 0.65-0.9, ozone 230-450 DU, albedo 0.05-0.5), sun zenith 20-85 deg; ground-truth render "
        f"({MODES[mode_name]['truth_spp']} spp, 400-680 nm every 40 nm), photon-like noise ({PHOTONS_AT_MEDIAN:,} "
        "photons at the median value) and an unknown exposure x 10^U(-2, 2); inverted from the default start "
        "(aod 0.1, alpha 1, g 0.75, ozone 300, albedo 0.2) with aod_550, angstrom_alpha, aerosol_g, ozone_du, "
        "ground_albedo and the exposure free. Configurations cycle: spectral / RGB x 48x48 fisheye (sky only) / "
        "64x32 equirectangular (ground in view and fitted).",
        "",
        f"Inversion settings: {settings.pixels} pixels, {settings.spp_start}->{settings.spp_max} spp per iteration, "
        f"final step at {settings.final_spp} spp, at most {settings.max_iterations} iterations. **Every estimate, "
        "uncertainty and residual comes from the ground-truth path tracer** (forward-mode AD Jacobians); no "
        "surrogate model is used.",
        "",
        "Errors are estimate - truth, relative (%) for aod_550 and ozone_du. \"Within target\": issue 7's "
        "targets (aod 3%, g 0.02, albedo 0.03, ozone 10% on spectral images only). Coverage: share of the cases "
        "*not flagged* in which |error| <= 1 std / 2 std (68% / 95% expected), for the cluster-robust std the "
        "inversion reports and for the plain curvature std. \"Flagged\": cases where the unknown was reported "
        "not identifiable (posterior std > 1/2 of the prior's).",
        "",
        "| unknown | images | cases | flagged | bias | spread (std) | median abs. error | within target | "
        "coverage 1/2 std (reported) | coverage 1/2 std (curvature) |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
        *summary_rows(cases),
        "",
        "## Time to converge (2-core CPU)",
        "",
        "| images | cases | fit, median (s) | fit, max (s) | with fitted image, median (s) | iterations | converged | "
        "rms log residual |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
        *timing_rows(cases),
        "",
        f"![estimates]({relative(figures[0])})",
        "",
        f"![z-scores]({relative(figures[1])})",
        "",
        f"Per-case results (truth, estimates, std, flags, timings): `results/inversion/cases/` (seed {seed}).",
        "",
    ]
    with atomic_write(REPORT) as f:
        f.write("\n".join(lines))
    return REPORT


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=24, help="number of synthetic cases (default 24)")
    parser.add_argument("--quick", action="store_true", help="small images and budgets (checks that it runs)")
    parser.add_argument("--fresh", action="store_true", help="recompute cases already in results/inversion/cases/")
    parser.add_argument("--seed", type=int, default=2026, help="seed of the case draws")
    args = parser.parse_args()
    mode = "quick" if args.quick else "full"
    base = preset("bruneton2017")
    os.makedirs(CASES, exist_ok=True)
    start = time.perf_counter()
    cases = []
    for index in range(args.cases):
        case = draw_case(index, args.seed)
        path = os.path.join(CASES, f"case-{index:03d}.json")
        if not args.fresh and os.path.exists(path):
            with open(path) as f:
                stored = json.load(f)
            if stored.get("mode") == mode and {k: stored.get(k) for k in case} == case:
                cases.append(stored)
                continue
        result = run_case(case, mode, base)
        with atomic_write(path) as f:
            json.dump(result, f, indent=1)
        cases.append(result)
        errors = ", ".join(f"{n} {result['estimates'][n]['value']:.4g} ({case['truth'][n]:.4g})" for n in UNKNOWNS)
        print(f"case {index} ({case['channels']} {case['camera']}, sun {case['sun_zenith_deg']:.0f} deg): "
              f"{result['fit']['fit_time_s']:.0f} s; estimate (truth): {errors}", flush=True)
    print(f"wrote {write_report(cases, mode, args.seed, time.perf_counter() - start)}")


if __name__ == "__main__":
    main()
