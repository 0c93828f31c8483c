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
from skyref.analytic.hosek import skyref_fit_directory
from skyref.atmosphere import PRESETS
from skyref.audit.advise import advice_lines, load_map, parse_tolerance
from skyref.audit.speed_map import (ENTRIES, TRUTH_GRID, entry_summary, evaluate_map, fitted_entries, map_sky_specs,
                                    truth_skies)
from skyref.batch import load_grid, run_batch
from skyref.batch.forecast import coordinates_text, forecast_skies
from skyref.batch.merge import LUT_AUDIT_TRUTH, import_skies
from skyref.batch.store import BatchStore
from skyref.envmap import (DEFAULT_WIDTH, ORIENTATIONS, SUN_MODES, check_width, render_environment_map, snippet_path,
                           write_environment_map)
from skyref.errors import ParameterError, SkyrefSetupError
from skyref.fit.cli import add_fit_parser
from skyref.invert.cli import add_invert_parser
from skyref.io.annotate import check_annotatable
from skyref.io.exr import LAYERS, check_layers, write_sky_exr
from skyref.io.png import exposure_from_ev100, write_png
from skyref.io.polarization import luminance_stokes, preview_paths, write_polarization_pngs
from skyref.lut import METHODS, lut_method, method_class
from skyref.lut import REGISTRY as LUT_REGISTRY
from skyref.render import PILOT_SPP, render_sky
from skyref.scene import ESTIMATORS, load_scene
from skyref.sky import degree_of_linear_polarization
from skyref.timelapse import frame_times, parse_place, render_timelapse, sun_from_options, timelapse_scene
from skyref.validation import check_choice, check_int, check_output_directory, check_output_file, safe_file_name

__all__ = ["build_parser", "cmd_advise", "cmd_audit", "cmd_batch", "cmd_envmap", "cmd_export_lut", "cmd_info",
           "cmd_render", "cmd_report", "cmd_timelapse", "cmd_validate", "main"]


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
        f"render       {scene.render.spp} spp in {scene.render.passes} passes, seed {scene.render.seed}, "
        f"{scene.render.estimator.replace('_', ' ')} estimator"
        + (", polarized (Stokes I, Q, U, V)" if scene.render.polarized else ""),
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


def _polarization_summary(sky) -> str:
    """The luminance-weighted degree of linear polarization of a polarized sky, in words."""
    dolp = degree_of_linear_polarization(luminance_stokes(sky), axis=-1)
    dolp = dolp[np.isfinite(dolp)]
    return (f"degree of linear polarization (luminance) median {np.median(dolp):.2f}, max {dolp.max():.2f}"
            if dolp.size else "no light to polarize")


def cmd_render(args) -> int:
    layers = check_layers(args.layers, "--layers")
    check_output_file(args.output, ".exr", "--output")
    if args.png:
        check_output_file(args.png, ".png", "--png")
    elif args.annotate or args.exposure is not None:
        name, value = ("--annotate", True) if args.annotate else ("--exposure", args.exposure)
        raise ParameterError(name, value, "with --png (it shapes the PNG preview)", "no --png to apply it to")
    exposure = None if args.exposure is None else exposure_from_ev100(args.exposure, "--exposure")
    scene = load_scene(args.scene, report=print)
    scene = scene.replace(sun=sun_from_options(scene.sun, args.time, args.place))
    if args.annotate:
        check_annotatable(scene.camera, "--annotate")
    polarized = scene.render.polarized if args.polarized is None else args.polarized
    if polarized and args.png:
        for path in preview_paths(args.png).values():
            check_output_file(path, ".png", "--png")
    if args.time or args.place:
        print(f"sun at zenith {scene.sun.zenith_deg:.2f} deg, azimuth {scene.sun.azimuth_deg:.2f} deg "
              f"({scene.sun.time.isoformat()} at {scene.sun.latitude_deg:g} N, {scene.sun.longitude_deg:g} E)")
    sky = render_sky(scene, spp=args.spp, passes=args.passes, seed=args.seed, variant=args.variant,
                     geometry=args.geometry, progress=not args.quiet, polarized=polarized, estimator=args.estimator)
    write_sky_exr(sky, args.output, layers=layers, half=args.half, report=print)
    if args.png:
        write_png(sky, args.png, exposure=exposure, annotate=args.annotate)
        if sky.polarized:
            write_polarization_pngs(sky, args.png, annotate=args.annotate)
    meta = sky.metadata
    visible = sky.radiance > 0
    noise = (f"median relative standard error "
             f"{100 * float(np.median(sky.standard_error[visible] / sky.radiance[visible])):.1f}%"
             if visible.any() else "the sky is black (nothing scatters or reflects light towards the camera)")
    print(f"{args.output}: {sky.shape[1]}x{sky.shape[0]} px, {sky.shape[2]} wavelengths, {meta['spp']} spp "
          f"in {meta['render_time_s']:.1f} s ({meta['samples_per_second'] / 1e6:.2f} M samples/s), {noise}"
          + (f"; polarized, {_polarization_summary(sky)}" if sky.polarized else ""))
    return 0


def cmd_timelapse(args) -> int:
    latitude, longitude = parse_place(args.place)
    times = frame_times(args.date, args.start, args.end, args.step, latitude, longitude, args.tz)
    exposure = None if args.exposure is None else exposure_from_ev100(args.exposure, "--exposure")
    scene = timelapse_scene(load_scene(args.scene), args.size, args.wavelengths)
    summary = render_timelapse(scene, times, latitude, longitude, args.output, spp=args.spp, exposure=exposure,
                               annotate=args.annotate, exr=args.exr, webp=args.webp, fps=args.fps,
                               variant=args.variant, progress=not args.quiet)
    print(f"{args.output}: {len(times)} frames, {times[0]:%Y-%m-%d %H:%M} to {times[-1]:%H:%M %Z} every {args.step} "
          f"({scene.camera.width}x{scene.camera.height} px, {args.spp} spp, {summary['render_time_s']:.1f} s), "
          f"exposure EV100 {summary['ev100']:.2f}; " + ", ".join(map(os.path.basename, summary["animations"])))
    return 0


def batch_progress_line(grid, indices=None) -> str:
    """What the grid's output directory holds of the skies ``indices`` (default: all): finished
    ones and their CPU time, skies rendered part-way, and how many are still to go."""
    store = BatchStore(grid)
    stored = store.stored_fingerprint()
    if stored is None:
        return "  nothing rendered yet"
    if stored != grid.fingerprint():
        return "  the output directory holds another grid's skies: a run would refuse it"
    indices = range(len(grid)) if indices is None else indices
    progress = store.progress(indices)
    partial = progress["partial"]
    line = (f"  {progress['finished']} of {len(indices)} skies finished ({progress['cpu_s'] / 3600.0:.2f} CPU hours), "
            f"{len(partial)} rendered part-way, {len(indices) - progress['finished'] - len(partial)} not started")
    return line + "".join(f"\n  {sky_id}: {note}" for sky_id, note in partial.items())


def forecast_batch(grid, indices, pilot_spp: int, variant) -> int:
    """``skyref batch --forecast``: each unfinished sky's forecast CPU time
    (:mod:`skyref.batch.forecast`), one line per sky as its pilot ends, then the total."""
    check_int("--pilot-spp", pilot_spp, grid.output.passes, 1 << 20)
    grid.validate()
    forecasts = forecast_skies(grid, indices, pilot_spp, variant)
    print(f"{grid.source or 'grid'}: forecast of the skies still to render, from a pilot of {pilot_spp:,} samples "
          f"per view each (the pilot's CPU is in brackets; compiling is not counted)", flush=True)
    skies, cpu_s, pilot_cpu_s = 0, 0.0, 0.0
    for spec, forecast in forecasts:
        skies, cpu_s, pilot_cpu_s = skies + 1, cpu_s + forecast["cpu_s"], pilot_cpu_s + forecast["pilot_cpu_s"]
        print(f"  {spec.sky_id} ({coordinates_text(spec.coordinates)}): {forecast['cpu_s']:,.0f} CPU s "
              f"[{forecast['pilot_cpu_s']:,.0f}], {forecast['views']:,} views x {forecast['samples_per_view']:,.0f} "
              f"samples, {forecast['views_short']} left above the target", flush=True)
    print(f"{skies} skies to render: {cpu_s / 3600.0:.2f} CPU hours forecast (the pilots took "
          f"{pilot_cpu_s / 3600.0:.2f}); a heavy tail the pilots did not draw makes them dearer")
    return 0


def cmd_batch(args) -> int:
    grid = load_grid(args.grid)
    indices = grid.sky_numbers(args.skies) if args.skies is not None else None
    if indices is not None and args.import_from:
        raise ParameterError("--skies", args.skies, "without --import-from (an import takes every sky finished there)",
                             "both given")
    if args.pilot_spp is not None and not args.forecast:
        raise ParameterError("--pilot-spp", args.pilot_spp, "only with --forecast", "nothing to pilot")
    if args.forecast and (args.import_from or args.dry_run):
        raise ParameterError("--forecast", "with " + ("--import-from" if args.import_from else "--dry-run"),
                             "--forecast alone, or with --skies, --pilot-spp and --variant", "both given")
    if args.forecast:
        return forecast_batch(grid, indices, PILOT_SPP if args.pilot_spp is None else args.pilot_spp, args.variant)
    if args.dry_run:
        grid.validate()
        print(f"{args.grid}: {len(grid)} skies ({' x '.join(f'{k}[{len(v)}]' for k, v in grid.axes.items())}), "
              f"output {grid.output.directory}")
        print(batch_progress_line(grid, indices))
        return 0
    if args.import_from:
        corrupt = 0
        for source in args.import_from:
            corrupt += len(import_skies(grid, source, parameter="--import-from")["corrupt"])
        return 1 if corrupt else 0
    manifest = run_batch(grid, scheduler=args.scheduler, workers=args.workers, variant=args.variant,
                         verify=args.verify, progress=not args.quiet, netcdf=args.netcdf, indices=indices)
    print(f"{grid.output.directory}: {manifest['skies_finished']}/{manifest['skies_total']} skies finished, "
          f"{len(manifest['failed'])} failed, this run {manifest['wall_time_s']:.1f} s"
          + (f"; netCDF copy {manifest['netcdf']}" if manifest["netcdf"] else ""))
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
    from skyref.audit.audit import audit, scale_table, summary_table, write_report  # lazy: see the module docstring

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
    print("\n".join(summary_table(result) + [""] + scale_table(result)))
    print(f"on this CPU (skyref's implementation, warm): precompute {result.precompute_s:.2f} s, per view "
          f"{1e3 * result.per_view_s:,.1f} ms, lookup {1e9 * result.lookup_s_per_direction:,.0f} ns/direction; "
          f"report: {path}")
    return 0


def cmd_export_lut(args) -> int:
    from skyref.lut import export  # lazy: Dr.Jit and OpenEXR, see the module docstring

    export.check_method(args.method)
    check_output_directory(args.out, "-o")
    options = dict(_option_value(o) for o in args.option or [])
    scene = load_scene(args.scene)
    method = export.build_method(args.method, scene, args.wavelengths, args.precision, options)
    method.precompute(progress=not args.quiet)
    record = export.export_lut(method, args.out, sun_direction=scene.sun.direction,
                               observer_altitude_m=scene.observer.altitude_m, source={"scene": args.scene})
    tables = ", ".join(f"{name} {t['width']}x{t['height']}" + (f"x{t['depth']}" if "depth" in t else "")
                       for name, t in record["tables"].items())
    print(f"{args.out}: {args.method} {tables} ({args.precision}; precompute {method.precompute_seconds:.1f} s), "
          f"{args.method}.json, {args.method}.glsl")
    return 0


def cmd_report(args) -> int:
    from skyref.audit.map_report import write_map_report  # lazy: see the module docstring

    grid = load_grid(args.truth_grid)
    log = (lambda *_: None) if args.quiet else print
    # the truth that ships with the repository first: its skies cost hours each to render
    source = args.truth_from
    if source is None and args.truth_grid == TRUTH_GRID and os.path.isdir(LUT_AUDIT_TRUTH):
        source = LUT_AUDIT_TRUTH
    if source is not None:
        import_skies(grid, source, log=log, parameter="--truth-from")
    # the map's skies alone: the rest of the truth grid is the LUT audit's (hours more)
    specs = map_sky_specs(grid)
    run_batch(grid, log=log, indices=[spec.index for _, spec in specs])
    store = BatchStore(grid)
    unfinished = [spec.sky_id for _, spec in specs if not store.is_finished(spec.sky_id)]
    if unfinished:
        print(f"skyref report: ground truth incomplete ({len(specs) - len(unfinished)}/{len(specs)} map skies; "
              f"unfinished: {', '.join(unfinished)}); run again to resume", file=sys.stderr)
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


def cmd_envmap(args) -> int:
    check_choice("--orientation", args.orientation, ORIENTATIONS)
    check_choice("--sun", args.sun, SUN_MODES)
    width = check_width(args.width, "--width")
    check_output_file(args.output, ".exr", "--output")
    check_output_file(snippet_path(args.output, args.orientation), "", "--output")
    scene = load_scene(args.scene, report=print)
    envmap = render_environment_map(scene, width, args.orientation, args.sun, spp=args.spp, passes=args.passes,
                                    seed=args.seed, variant=args.variant, progress=not args.quiet)
    exr, snippet = write_environment_map(envmap, args.output)
    sun = ", ".join(f"{c:.4g}" for c in envmap.sun_irradiance)
    print(f"{exr}: {envmap.rgb.shape[1]}x{envmap.rgb.shape[0]} linear sRGB (cd m^-2) for {args.orientation}, "
          f"sun {args.sun} (irradiance RGB {sun} lux); {snippet}")
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
    p.add_argument("--layers", default=",".join(LAYERS), help="what the EXR holds, a comma-separated subset of "
                   f"{', '.join(LAYERS)} (default: all, a complete reference; rgb alone: an environment map)")
    p.add_argument("--half", action="store_true", help="store the EXR's channels as 16-bit half floats "
                   "(about half the size; values above 65504, e.g. the sun's disk in rgb, are clamped)")
    p.add_argument("--png", help="also write a tone-mapped sRGB PNG preview")
    p.add_argument("--spp", type=int, help="samples per pixel (default: the scene's)")
    p.add_argument("--passes", type=int, help="independent passes for the standard error (default: the scene's)")
    p.add_argument("--seed", type=int, help="random seed (default: the scene's)")
    p.add_argument("--variant", help="Mitsuba variant (default: cuda_ad_rgb with a GPU, else llvm_ad_rgb)")
    p.add_argument("--geometry", default="spherical", choices=("spherical", "plane_parallel"),
                   help="planet geometry (plane_parallel is for comparisons with DISORT)")
    p.add_argument("--estimator", choices=ESTIMATORS, help="the path tracer's estimator (default: the scene's "
                   "render.estimator, line_integral): line_integral needs 3-40x less CPU to a given error "
                   "(most along pixel centres, render.pixel_sampling = \"centre\") but compiles for 15 s to minutes "
                   "on a new configuration's first run; delta_tracking is the independent baseline")
    p.add_argument("--polarized", action=argparse.BooleanOptionalAction, default=None,
                   help="transport Stokes vectors (default: the scene's render.polarized): the EXR gets the layout's "
                   "S0-S3 layers (I, Q, U, V in each pixel's meridian frame) and DoLP/AoLP layers, --png also "
                   "NAME.dolp.png and NAME.aolp.png")
    p.add_argument("--annotate", action="store_true", help="draw the horizon, N/E/S/W and a ring around the sun "
                   "on the PNG previews (fisheye and equirectangular cameras)")
    p.add_argument("--exposure", type=float, metavar="EV", help="absolute exposure of the PNG preview, EV at ISO 100 "
                   "(a clear day's sky: about 13): luminance 1.2*2^EV cd/m^2 maps to 1 before the tone curve x/(1+x), "
                   "so equal luminances give equal pixels in every image (default: per image, the 99th percentile "
                   "of luminance becomes 0.8)")
    p.add_argument("--time", help="put the sun where it stands at this time: ISO 8601 with a UTC offset, e.g. "
                   "2026-06-21T06:00+02:00 (with --place, or the scene's sun.latitude_deg/longitude_deg)")
    p.add_argument("--place", metavar="LAT,LON", help="the observer's place for --time, degrees north and east, "
                   "e.g. 48.85,2.35")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=cmd_render)

    p = sub.add_parser("timelapse", help="a day of skies: PNG frames (optionally EXR) and an animated GIF, one "
                       "exposure for all")
    p.add_argument("scene", metavar="SCENE", help="scene TOML file (its camera is resized to --size)")
    p.add_argument("--place", required=True, metavar="LAT,LON", help="degrees north and east, e.g. 48.85,2.35")
    p.add_argument("--date", help="local date YYYY-MM-DD (needed by sunrise/sunset/noon and HH:MM bounds)")
    p.add_argument("--from", dest="start", default="sunrise-1h", help="first frame: sunrise, sunset or noon with an "
                   "optional +-DURATION, a local time HH:MM, or an ISO time with offset (default %(default)s)")
    p.add_argument("--to", dest="end", default="sunset+1h", help="last frame, as --from (default %(default)s)")
    p.add_argument("--step", default="30min", help="time between frames: a number and h, min or s (default "
                   "%(default)s)")
    p.add_argument("--tz", help="local time zone of the bounds and stamps: UTC, +HH:MM or an IANA name such as "
                   "Europe/Paris (default: an ISO --from's offset, else UTC + round(longitude / 15) h)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="directory for frame-NNN.png, timelapse.gif")
    p.add_argument("--size", type=int, default=128, help="longer image side, pixels (default %(default)s)")
    p.add_argument("--spp", type=int, default=64, help="samples per pixel (default %(default)s)")
    p.add_argument("--wavelengths", default="rgb", help="rgb (680, 550, 440 nm; the default) or scene (the "
                   "scene's own)")
    p.add_argument("--exposure", type=float, metavar="EV", help="exposure of every frame, EV at ISO 100 (as for "
                   "render; default: the per-image exposure of the brightest frame)")
    p.add_argument("--annotate", action=argparse.BooleanOptionalAction, default=True,
                   help="horizon, N/E/S/W and the sun on each frame (default: on)")
    p.add_argument("--exr", action="store_true", help="also write each frame's spectral EXR")
    p.add_argument("--webp", action="store_true", help="also write an animated WebP")
    p.add_argument("--fps", type=float, default=6.0, help="frames per second of the animation (default %(default)s)")
    p.add_argument("--variant", help="Mitsuba variant (default: cuda_ad_rgb with a GPU, else llvm_ad_rgb)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=cmd_timelapse)

    p = sub.add_parser("batch", help="render a grid of skies (resumable; local dask cluster or --scheduler)")
    p.add_argument("grid", metavar="GRID", help="grid TOML file (base scene, axes, output)")
    p.add_argument("--scheduler", help="address of a running dask scheduler (default: a local cluster)")
    p.add_argument("--workers", type=int, help="local worker processes (default: one per two cores)")
    p.add_argument("--variant", help="Mitsuba variant (default: cuda_ad_rgb with a GPU, else llvm_ad_rgb)")
    p.add_argument("--verify", action="store_true", help="check finished skies' SHA-256 before skipping them")
    p.add_argument("--netcdf", action="store_true", help="also write dataset.nc (netCDF-3, CF) once every sky "
                   "is finished")
    p.add_argument("--dry-run", action="store_true", help="check the grid, print its size and how far its output "
                   "directory is (skies finished, their CPU hours, skies rendered part-way); render nothing")
    p.add_argument("--skies", metavar="LIST", help="render only these sky numbers, in this order, e.g. 0-9,20 (a "
                   "part of the grid for one machine: the same ids and seeds as the whole grid's run)")
    p.add_argument("--import-from", action="append", metavar="DIR",
                   help="bring in the skies finished in DIR, a copy of this grid's output directory rendered "
                   "elsewhere (checked by SHA-256), then stop; repeatable")
    p.add_argument("--forecast", action="store_true", help="forecast the CPU time of each sky still to render "
                   "(a grid with a target: a pilot render of its views, thrown away) and print it; write nothing")
    p.add_argument("--pilot-spp", type=int, metavar="N", help="samples per view of each --forecast pilot "
                   f"(default {PILOT_SPP}; more see rarer large contributions)")
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
    p.add_argument("--truth-from", help="finished truth skies to import first, rendered elsewhere (default, with the "
                   f"default grid: {LUT_AUDIT_TRUTH}, the truth shipped with the repository, if present)")
    p.add_argument("--coefficients", default=skyref_fit_directory(),
                   help="directory of fitted Hosek-Wilkie / Perez tables ('skyref fit --out'), included if present "
                   "(default: the fit shipped with skyref, skyref/analytic/data/skyref_fit)")
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

    p = sub.add_parser("envmap", help="a scene's sky as a renderer's environment map: an RGB lat-long EXR, the sun "
                       "as a light (Mitsuba XML or Blender script beside it) or in the map")
    p.add_argument("scene", metavar="SCENE", help="scene TOML file (its camera is replaced by the map's)")
    p.add_argument("-o", "--output", required=True, help="RGB EXR to write; sky.exr gets sky.mitsuba.xml or "
                   "sky.blender.py beside it")
    p.add_argument("--orientation", default="mitsuba", help="mitsuba (envmap, y up, north -z) or blender "
                   "(Environment Texture, z up, north +y); default mitsuba")
    p.add_argument("--sun", default="separate", help="separate (a directional / Sun light with the transmitted "
                   "irradiance) or in-map (the sun's texels carry it); default separate")
    p.add_argument("--width", type=int, default=DEFAULT_WIDTH, help=f"map columns, a multiple of 4 (default "
                   f"{DEFAULT_WIDTH}; the sky is rendered at width x width/2)")
    p.add_argument("--spp", type=int, help="samples per pixel (default: the scene's)")
    p.add_argument("--passes", type=int, help="independent passes (default: the scene's)")
    p.add_argument("--seed", type=int, help="random seed (default: the scene's)")
    p.add_argument("--variant", help="Mitsuba variant (default: cuda_ad_rgb with a GPU, else llvm_ad_rgb)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=cmd_envmap)

    p = sub.add_parser("export-lut", help="write a LUT method's tables for an engine: EXR textures in the "
                       "paper's layout, a JSON of the constants and a GLSL snippet")
    p.add_argument("--method", required=True, help="bruneton2017 or hillaire2020")
    p.add_argument("-o", "--out", required=True, help="directory to write the tables into")
    p.add_argument("--scene", default=os.path.join("scenes", "earth-clear.toml"),
                   help="scene TOML file: the atmosphere, and for hillaire2020's sky view the sun and observer "
                   "(default scenes/earth-clear.toml)")
    p.add_argument("--option", action="append", metavar="NAME=VALUE",
                   help="a method option, e.g. scattering_orders=8 or mu_size=256 (repeatable)")
    p.add_argument("--precision", default="float32", help="table storage, float32 or float16 (EXR FLOAT or HALF "
                   "pixels where the method stores the table so; default float32)")
    p.add_argument("--wavelengths", default="rgb", help="the three wavelengths of channels R, G, B: rgb "
                   "(680,550,440 nm, the default) or three numbers in nm, e.g. 700,546,436")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=cmd_export_lut)

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
