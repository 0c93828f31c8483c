"""The ``skyref`` command line.

Every subcommand checks its input first; a bad input ends the program with exit status 2 and
one line that names the problem (no traceback).

A few imports stay inside the subcommands that need them, so that ``skyref --help`` and
``skyref validate`` stay fast: Mitsuba and Dr.Jit (``info``; they must also follow
:func:`skyref._llvm.configure_libllvm`) and the audit modules that import colour-science, about
2.5 s (``audit``, ``report``).
"""

from __future__ import annotations

import argparse
import os
import sys
import tomllib
import zipfile

import numpy as np

import skyref
from skyref import _llvm
from skyref.analytic import MODELS, analytic_model
from skyref.analytic import REGISTRY as MODEL_REGISTRY
from skyref.atmosphere import PRESETS
from skyref.audit.advise import advice_lines, load_map, parse_tolerance
from skyref.audit.speed_map import ENTRIES, TRUTH_GRID, entry_summary, evaluate_map, fitted_entries, truth_skies
from skyref.batch import load_grid, run_batch
from skyref.errors import ParameterError, SkyrefSetupError
from skyref.fit.cli import add_fit_parser
from skyref.invert.cli import add_invert_parser
from skyref.io.exr import write_sky_exr
from skyref.io.png import write_png
from skyref.lut import METHODS, lut_method, method_class
from skyref.lut import REGISTRY as LUT_REGISTRY
from skyref.render import render_sky
from skyref.scene import load_scene
from skyref.validation import check_int, check_output_directory, check_output_file, safe_file_name

__all__ = ["build_parser", "cmd_advise", "cmd_audit", "cmd_batch", "cmd_info", "cmd_render", "cmd_report",
           "cmd_validate", "main"]


def _describe_scene(scene) -> str:
    atm = scene.atmosphere
    wl = scene.wavelengths_nm
    probe = np.array([440.0, 550.0, 680.0])
    lines = [
        f"scene        {scene.name or '(unnamed)'}",
        f"atmosphere   {atm.name or '(custom)'}: radii {atm.bottom_radius_m / 1e3:g}–{atm.top_radius_m / 1e3:g} km, "
        f"constituents {', '.join(c.name for c in atm.constituents) or 'none'}",
    ]
    try:
        tau = atm.vertical_optical_depth(probe)
    except ParameterError:  # a spectrum of this atmosphere does not cover the probe wavelengths
        tau = None
    if tau is not None:
        lines.append("             vertical optical depth " +
                     ", ".join(f"{t:.4f} @ {w:g} nm" for t, w in zip(tau, probe)))
    sun = scene.sun
    lines += [
        f"sun          zenith {sun.zenith_deg:.3f} deg, azimuth {sun.azimuth_deg:.3f} deg, "
        f"radius {sun.angular_radius_deg:.4f} deg" + (f" ({sun.time.isoformat()} at {sun.latitude_deg:g} N, "
                                                     f"{sun.longitude_deg:g} E)" if sun.time else ""),
        f"observer     altitude {scene.observer.altitude_m:g} m",
        f"camera       {scene.camera.type} {scene.camera.width}x{scene.camera.height}, fov {scene.camera.fov_deg:g} deg",
        f"wavelengths  {len(wl)}: {wl[0]:g}–{wl[-1]:g} nm",
        f"render       {scene.render.spp} spp in {scene.render.passes} passes, seed {scene.render.seed}",
    ]
    return "\n".join(lines)


def cmd_validate(args) -> int:
    for path in args.scenes:
        scene = load_scene(path, report=None if args.quiet else print)
        print(f"{path}: valid")
        if not args.quiet:
            print(_describe_scene(scene))
    return 0


def cmd_info(args) -> int:
    print(f"skyref       {skyref.__version__}")
    print(f"python       {sys.version.split()[0]}")
    libllvm = _llvm.working_library()
    print(f"libLLVM      {libllvm or 'none that works: ' + _llvm.INSTALL_HINT}")
    if libllvm:
        _llvm.configure_libllvm()
        import drjit  # lazy: see the module docstring
        import mitsuba

        print(f"mitsuba      {mitsuba.__version__}, drjit {drjit.__version__}")
        print(f"variants     {', '.join(v for v in mitsuba.variants() if 'ad_' in v and 'polarized' not in v)}")
        print(f"cuda         {'available' if drjit.has_backend(drjit.JitBackend.CUDA) else 'not available'}")
    print(f"presets      {', '.join(PRESETS)}")
    return 0


def cmd_render(args) -> int:
    check_output_file(args.output, ".exr", "--output")
    if args.png:
        check_output_file(args.png, ".png", "--png")
    scene = load_scene(args.scene, report=print)
    sky = render_sky(scene, spp=args.spp, passes=args.passes, seed=args.seed, variant=args.variant,
                     geometry=args.geometry, progress=not args.quiet)
    write_sky_exr(sky, args.output)
    if args.png:
        write_png(sky, args.png)
    meta = sky.metadata
    visible = sky.radiance > 0
    noise = (f"median relative standard error "
             f"{100 * float(np.median(sky.standard_error[visible] / sky.radiance[visible])):.1f}%"
             if visible.any() else "the sky is black (nothing scatters or reflects light towards the camera)")
    print(f"{args.output}: {sky.shape[1]}x{sky.shape[0]} px, {sky.shape[2]} wavelengths, {meta['spp']} spp "
          f"in {meta['render_time_s']:.1f} s ({meta['samples_per_second'] / 1e6:.2f} M samples/s), {noise}")
    return 0


def cmd_batch(args) -> int:
    grid = load_grid(args.grid)
    if args.dry_run:
        grid.validate()
        print(f"{args.grid}: {len(grid)} skies ({' x '.join(f'{k}[{len(v)}]' for k, v in grid.axes.items())}), "
              f"output {grid.output.directory}")
        return 0
    manifest = run_batch(grid, scheduler=args.scheduler, workers=args.workers, variant=args.variant,
                         verify=args.verify, progress=not args.quiet)
    print(f"{grid.output.directory}: {manifest['skies_finished']}/{manifest['skies_total']} skies finished, "
          f"{len(manifest['failed'])} failed, this run {manifest['wall_time_s']:.1f} s")
    return 1 if manifest["failed"] else 0


def _option_value(text: str):
    """``NAME=VALUE`` -> (NAME, VALUE parsed as a TOML value, else the string)."""
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise ParameterError("--option", text, "NAME=VALUE, e.g. scattering_orders=8", "not NAME=VALUE")
    try:
        return name.strip(), tomllib.loads(f"v = {value}")["v"]
    except tomllib.TOMLDecodeError:
        return name.strip(), value


def _load_tables(path: str) -> dict:
    """The arrays of an ``--tables`` .npz file; a ParameterError naming ``--tables`` otherwise."""
    if not os.path.isfile(path):
        raise ParameterError("--tables", path, "an existing .npz file", "file not found")
    try:
        with np.load(path, allow_pickle=False) as archive:
            return dict(archive)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile, AttributeError):
        raise ParameterError("--tables", path, "a NumPy .npz archive of tables (numpy.savez)",
                             "not an .npz archive") from None


def cmd_audit(args) -> int:
    from skyref.audit.audit import audit, summary_table, write_report  # lazy: see the module docstring

    if args.method not in METHODS and args.method not in MODELS:
        raise ParameterError("--method", args.method, ", ".join([*METHODS, *MODELS]), "unknown method")
    if args.tables and args.method not in METHODS:
        raise ParameterError("--tables", args.tables, "a LUT method (" + ", ".join(METHODS) + ")",
                             f"{args.method} has no tables")
    scene = load_scene(args.scene)
    directory = args.out or os.path.join("out", "audit", safe_file_name(f"{args.method}-{scene.name}"))
    check_output_directory(directory, "--out")
    options = dict(_option_value(o) for o in args.option or [])
    if args.tables:
        arrays = _load_tables(args.tables)
        from_tables = method_class(args.method).from_tables
        LUT_REGISTRY.check_options(args.method, arrays, from_tables, "--tables array", required=True)
        LUT_REGISTRY.check_options(args.method, options, from_tables, "--option")
        method = from_tables(scene.atmosphere, scene.wavelengths_nm, **arrays, **options)
    elif args.method in MODELS:
        MODEL_REGISTRY.check_options(args.method, options, parameter="--option")
        method = analytic_model(args.method, scene.atmosphere, scene.wavelengths_nm, **options)
    else:
        LUT_REGISTRY.check_options(args.method, options, parameter="--option")
        method = lut_method(args.method, scene.atmosphere, scene.wavelengths_nm, **options)
    result = audit(method, scene, max_spp=args.max_spp, cache_dir=os.path.join("out", "audit", "ground-truth"),
                   log=(lambda *_: None) if args.quiet else print)
    path = write_report(result, directory)
    print("\n".join(summary_table(result)))
    print(f"precompute {result.precompute_s:.2f} s, lookup {1e9 * result.lookup_s_per_direction:.0f} ns/direction; "
          f"report: {path}")
    return 0


def cmd_report(args) -> int:
    from skyref.audit.map_report import write_map_report  # lazy: see the module docstring

    grid = load_grid(args.truth_grid)
    log = (lambda *_: None) if args.quiet else print
    manifest = run_batch(grid, log=log)
    if manifest["skies_finished"] != len(grid):
        print(f"skyref report: ground truth incomplete ({manifest['skies_finished']}/{len(grid)} skies); "
              "run again to resume", file=sys.stderr)
        return 1
    entries = list(ENTRIES) + fitted_entries(args.coefficients)
    skies = truth_skies(grid)
    rows = evaluate_map(entries, skies, args.cache, log=log)
    path = write_map_report(entries, skies, rows, entry_summary(rows), args.cache, args.results)
    print(f"report: {path}")
    return 0


def cmd_advise(args) -> int:
    tolerance = parse_tolerance(args.tolerance)
    directions = check_int("--directions", args.directions, 1, 1 << 40)
    frames = check_int("--frames", args.frames, 1, 1 << 30)
    summaries = load_map(args.map)
    scene = load_scene(args.scene)
    print("\n".join(advice_lines(summaries, scene, tolerance, directions, frames)))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="skyref", description="Reference skies: a spectral path tracer "
                                     "for planetary atmospheres and the tools that use it as ground truth.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("validate", help="check scene files and print what they describe")
    p.add_argument("scenes", nargs="+", metavar="SCENE", help="scene TOML file(s)")
    p.add_argument("-q", "--quiet", action="store_true", help="print only whether each scene is valid")
    p.set_defaults(run=cmd_validate)

    p = sub.add_parser("render", help="render a scene to a spectral EXR (and a PNG preview)")
    p.add_argument("scene", metavar="SCENE", help="scene TOML file")
    p.add_argument("-o", "--output", required=True, help="spectral EXR to write")
    p.add_argument("--png", help="also write a tone-mapped sRGB PNG preview")
    p.add_argument("--spp", type=int, help="samples per pixel (default: the scene's)")
    p.add_argument("--passes", type=int, help="independent passes for the standard error (default: the scene's)")
    p.add_argument("--seed", type=int, help="random seed (default: the scene's)")
    p.add_argument("--variant", help="Mitsuba variant (default: cuda_ad_rgb with a GPU, else llvm_ad_rgb)")
    p.add_argument("--geometry", default="spherical", choices=("spherical", "plane_parallel"),
                   help="planet geometry (plane_parallel is for comparisons with DISORT)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=cmd_render)

    p = sub.add_parser("batch", help="render a grid of skies (resumable; local dask cluster or --scheduler)")
    p.add_argument("grid", metavar="GRID", help="grid TOML file (base scene, axes, output)")
    p.add_argument("--scheduler", help="address of a running dask scheduler (default: a local cluster)")
    p.add_argument("--workers", type=int, help="local worker processes (default: one per two cores)")
    p.add_argument("--variant", help="Mitsuba variant (default: cuda_ad_rgb with a GPU, else llvm_ad_rgb)")
    p.add_argument("--verify", action="store_true", help="check finished skies' SHA-256 before skipping them")
    p.add_argument("--dry-run", action="store_true", help="check the grid and print its size; render nothing")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=cmd_batch)

    p = sub.add_parser("audit", help="audit a LUT method or analytic model against the ground truth on a scene")
    p.add_argument("--method", required=True, help="a LUT method (bruneton2017, elek2009, hillaire2020) or an "
                   "analytic model (preetham1999, hoffman_preetham2002, nielsen2003, nishita1993, oneil2005, hosek2012)")
    p.add_argument("--scene", required=True, help="scene TOML file (atmosphere, sun, observer, camera, wavelengths)")
    p.add_argument("--option", action="append", metavar="NAME=VALUE",
                   help="a method option, e.g. scattering_orders=8 or precision=float16 (repeatable)")
    p.add_argument("--tables", help="audit tables computed elsewhere: an .npz of arrays in the method's "
                   "texture layout (bruneton2017)")
    p.add_argument("--max-spp", type=int, default=16384, help="ground-truth sample budget per pixel")
    p.add_argument("-o", "--out", help="report directory (default out/audit/METHOD-SCENE)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress messages")
    p.set_defaults(run=cmd_audit)

    p = sub.add_parser("report", help="the speed-vs-error map of every method: results/README.md, plots, map.json")
    p.add_argument("--truth-grid", default=TRUTH_GRID, help="grid of the ground-truth skies")
    p.add_argument("--coefficients", default=os.path.join("out", "hosek-coefficients"),
                   help="directory of fitted Hosek-Wilkie / Perez tables ('skyref fit --out'), included if present")
    p.add_argument("--cache", default=os.path.join("out", "report", "cache"), help="cache of (method, sky) results")
    p.add_argument("--results", default="results", help="where README.md and report/ are written")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress messages")
    p.set_defaults(run=cmd_report)

    p = sub.add_parser("advise", help="the cheapest method meeting an error tolerance for a scene, from the map")
    p.add_argument("--scene", required=True, help="scene TOML file")
    p.add_argument("--tolerance", required=True, help="sky luminance RMS error, e.g. 2%% or 0.02")
    p.add_argument("--map", default=os.path.join("results", "report", "map.json"), help="map written by 'skyref report'")
    p.add_argument("--directions", type=int, default=1920 * 1080, help="directions per frame (default 1920x1080)")
    p.add_argument("--frames", type=int, default=1, help="frames with the same atmosphere (precompute paid once)")
    p.set_defaults(run=cmd_advise)

    add_fit_parser(sub)
    add_invert_parser(sub)

    p = sub.add_parser("info", help="versions, libLLVM, Mitsuba variants, presets")
    p.set_defaults(run=cmd_info)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.run(args)
    except (ParameterError, SkyrefSetupError, ValueError, OSError) as exc:
        print(f"skyref {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"skyref {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
