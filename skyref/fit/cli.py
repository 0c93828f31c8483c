"""``skyref fit``: fit Hosek–Wilkie (and Perez baseline) tables to a batch dataset, or report the
errors of a table against one.

    skyref fit --grid out/hosek-training --out coeffs/      # fit; write coeffs/hosek.* and perez.*
    skyref fit --evaluate coeffs/hosek.npz --grid out/hosek-training
    skyref fit --evaluate published --grid out/hosek-training   # the published model
"""

from __future__ import annotations

import os

import numpy as np

from skyref.analytic.hosek import published_table
from skyref.batch.provenance import batch_skies, describe_truth, truth_provenance
from skyref.errors import ParameterError
from skyref.fit.export import read_tables, write_tables
from skyref.fit.fitter import PRIOR_WEIGHT, SHORT_GROUP, fit_table
from skyref.fit.training import load_batch_dataset
from skyref.validation import check_number, check_output_directory

__all__ = ["FORM_NAMES", "KINDS", "add_fit_parser", "cmd_fit", "noise_line", "truth_metadata"]

KINDS = ("spectral", "xyz", "rgb")
FORM_NAMES = {"hosek": "Hosek-Wilkie", "perez": "Perez (Preetham-style baseline)"}


def add_fit_parser(subparsers):
    """Add the ``fit`` subcommand to ``skyref``'s argparse subparsers."""
    p = subparsers.add_parser("fit", help="fit Hosek-Wilkie sky coefficients to a batch dataset, or evaluate a table")
    p.add_argument("--grid", required=True, metavar="DATASET",
                   help="a spectral 'skyref batch' output directory (or its dataset.zarr)")
    p.add_argument("--out", metavar="DIR", help="write the fitted tables here (.npz, .json, C headers)")
    p.add_argument("--evaluate", metavar="COEFFS",
                   help="instead of fitting, report the errors of a table (.npz or .json, or 'published')")
    p.add_argument("--kinds", default=",".join(KINDS), help="comma-separated kinds of tables (default: all the "
                   "dataset supports): spectral, xyz, rgb")
    p.add_argument("--no-perez", action="store_true", help="skip the Perez (Preetham-style) baseline fit")
    p.add_argument("--no-joint", action="store_true", help="skip the joint refinement of the Bezier control points")
    p.add_argument("--joint-prior-weight", type=float, default=PRIOR_WEIGHT, metavar="W",
                   help="the joint refinement's pull towards the start table, per coefficient and sky (default "
                        "%(default)g; 0: the data alone, whose neighbouring configurations then may not blend)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    p.set_defaults(run=cmd_fit)
    return p


def _kinds(text: str, available) -> list[str]:
    kinds = [k.strip() for k in text.split(",") if k.strip()]
    for kind in kinds:
        if kind not in KINDS:
            raise ParameterError("--kinds", text, "a comma-separated subset of " + ", ".join(KINDS), "unknown kind")
    chosen = [k for k in kinds if k in available]
    if not chosen:
        raise ParameterError("--kinds", text, "kinds the dataset supports: " + ", ".join(available),
                             "none available")
    return chosen


def _skies_with_data(training) -> int:
    """How many of the training set's skies have any radiance (an unfinished batch has fewer)."""
    return int(training.rendered.sum())


def _skies_text(training) -> str:
    """``"260 skies"``, or ``"35 of 260 skies"`` where some have no data."""
    total, rendered = len(training.solar_elevation), _skies_with_data(training)
    return f"{total} skies" if rendered == total else f"{rendered} of {total} skies"


def noise_line(training) -> str:
    """The data's noise, and how many of its skies have data where some have none."""
    missing = len(training.solar_elevation) - _skies_with_data(training)
    coverage = (f"; {missing} of the {len(training.solar_elevation)} skies have no data (an unfinished batch?): "
                "their configurations are not fitted" if missing else "")
    noise = training.relative_noise()
    finite = noise[np.isfinite(noise)]
    if finite.size == 0:
        return "noise: none recorded" + coverage
    return (f"noise of the data (standard error / radiance over fitted directions): median "
            f"{100 * np.median(finite):.2f}%, 95th percentile {100 * np.percentile(finite, 95):.2f}%" + coverage)


def _summary_lines(name, table, training, skies: str | None = None) -> list[str]:
    """The error table of ``table`` against ``training``; ``skies`` says which skies it covers
    (default: how many of the training set's have data)."""
    # Lazy: skyref.fit.evaluate imports colour-science (seconds, through skyref.audit.metrics), and
    # ``skyref --help`` imports this module.
    from skyref.fit.evaluate import error_summary

    summary = error_summary(table, training)
    lines = [f"{name} vs {training.kind} ground truth ({skies or _skies_text(training)}): relative error, %",
             f"  {'channel':>8} {'mean':>8} {'rms':>8} {'p95':>8} {'max':>8}   (truth's noise: rms, p95)"]
    for channel, stats in summary["channels"].items():
        if stats is None:
            continue
        lines.append(f"  {channel:>8} {100 * stats['mean']:8.2f} {100 * stats['rms']:8.2f} {100 * stats['p95']:8.2f} "
                     f"{100 * stats['max']:8.2f}   ({100 * stats['noise_rms']:.2f}, {100 * stats['noise_p95']:.2f})")
    by = {}
    for sky in summary["skies"]:
        for key, label in (("solar_elevation_deg", "elevation"), ("turbidity", "turbidity")):
            rms = [s["rms"] for s in sky["channels"].values() if s is not None]
            if rms:
                by.setdefault(label, {}).setdefault(round(sky[key], 3), []).append(np.sqrt(np.mean(np.square(rms))))
    for label, groups in by.items():
        lines.append(f"  rms over channels by {label}: " +
                     ", ".join(f"{value:g}: {100 * np.sqrt(np.mean(np.square(v))):.2f}" for value, v in sorted(groups.items())))
    return lines


def _progress(quiet: bool):
    """A ``progress(stage, done, total)`` callback drawing one tqdm bar per stage."""
    if quiet:
        return None
    from tqdm import tqdm  # lazy: its import cost is paid only with a progress bar

    bars = {}

    def update(stage, done, total):
        bar = bars.get(stage)
        if bar is None:
            bar = bars[stage] = tqdm(total=total, desc=f"fit: {stage}", unit="problem")
        bar.update(done - bar.n)
        if done >= total:
            bar.close()
    return update


def _fit_summary_lines(name, result, training) -> list[str]:
    """:func:`_summary_lines` of a fit over the skies it fitted: a sky it left out keeps the
    start table's values (in an unfinished batch, a rendered sky whose albedo and turbidity
    have too few elevations so far), and its error would be the start table's."""
    used = np.array([s not in result.skipped for s in range(len(training.solar_elevation))], dtype=bool)
    short = sum(why == SHORT_GROUP for why in result.skipped.values())
    skies = f"the {int(used.sum())} skies fitted" + (
        f"; {short} rendered skies left out, their albedo and turbidity still short of elevations" if short else "")
    return _summary_lines(name, result.table, training.select(used), skies)


def _evaluate(args, training_sets) -> int:
    if args.evaluate == "published":
        tables = {kind: published_table(kind) for kind in KINDS}
        name = "published Hosek-Wilkie 1.4a"
    else:
        tables, metadata = read_tables(args.evaluate)
        name = f"{args.evaluate} ({FORM_NAMES.get(metadata.get('form'), metadata.get('form', '?'))})"
    kinds = [k for k in _kinds(args.kinds, list(training_sets)) if k in tables]
    if not kinds:
        raise ParameterError("--evaluate", args.evaluate, "a table of a kind in the dataset: " +
                             ", ".join(training_sets), "no matching table")
    for kind in kinds:
        print(noise_line(training_sets[kind]))
        print("\n".join(_summary_lines(name, tables[kind], training_sets[kind])))
    return 0


def truth_metadata(training) -> dict | None:
    """The provenance of a training set's ground truth (:func:`skyref.batch.provenance.truth_provenance`,
    with its ``description`` in words) from the sky EXRs of the batch directory holding its dataset;
    None where there are none (a dataset copied without them)."""
    skies = batch_skies(os.path.dirname(os.path.abspath(training.source)))
    if not skies:
        return None
    provenance = truth_provenance(skies)
    return {"description": describe_truth(provenance), "skies": len(skies), **provenance}


def _fit(args, training_sets) -> int:
    if not args.out:
        raise ParameterError("--out", None, "a directory for the fitted tables", "missing (or give --evaluate)")
    check_output_directory(args.out, "--out")     # created by the first table written
    kinds = _kinds(args.kinds, list(training_sets))
    progress = _progress(args.quiet)
    truth = truth_metadata(training_sets[kinds[0]])
    written = []
    for form in ("hosek",) if args.no_perez else ("hosek", "perez"):
        tables, runs, notes = {}, {}, {}
        for kind in kinds:
            training = training_sets[kind]
            if form == "hosek":
                print(noise_line(training))
            result = fit_table(training, form=form, joint=not args.no_joint, joint_prior_weight=args.joint_prior_weight,
                               progress=progress)
            tables[kind] = result.table
            unfitted = [f"{channel}" for channel, done in zip(result.table.channels, result.fitted.any(axis=(1, 2)))
                        if not done]
            notes[kind] = "\n".join(
                ([f"Ground truth: skyref's path tracer, {truth['description']} "
                  f"({truth['skies']} {'sky' if truth['skies'] == 1 else 'skies'})."] if truth else [])
                + (["Channels not fitted (start values kept): " + ", ".join(unfitted)] if unfitted else []))
            runs[kind] = {"channels_fitted": [c for c in result.table.channels if c not in unfitted],
                          "fitted_groups": result.fitted.tolist(), "timings_s": result.timings,
                          "unconverged": result.unconverged, "most_steps": result.most_steps,
                          "skipped_skies": {str(k): v for k, v in result.skipped.items()}}
            print(f"{FORM_NAMES[form]} {kind}: fitted in {sum(result.timings.values()):.1f} s "
                  f"({', '.join(f'{k} {v:.1f} s' for k, v in result.timings.items())}); "
                  f"unconverged problems: {result.unconverged}")
            print("\n".join(_fit_summary_lines(f"{FORM_NAMES[form]} fit", result, training)))
        metadata = {"source": f"skyref fit of {os.path.abspath(args.grid)}", "training": args.grid,
                    "joint_refinement": not args.no_joint, "joint_prior_weight": args.joint_prior_weight, "fits": runs,
                    "truth": truth}
        written += write_tables(tables, args.out, form, metadata=metadata, notes=notes)
    print("wrote " + ", ".join(written))
    return 0


def cmd_fit(args) -> int:
    """Run ``skyref fit`` (see the module's documentation)."""
    if args.evaluate and args.out:
        raise ParameterError("--out", args.out, "only when fitting (without --evaluate)", "conflicting options")
    check_number("--joint-prior-weight", args.joint_prior_weight, 0.0, 1e6)
    training_sets = load_batch_dataset(args.grid)
    if args.evaluate:
        return _evaluate(args, training_sets)
    return _fit(args, training_sets)

