"""``skyref invert``: the atmosphere behind a sky image.

    skyref invert sky.exr --camera fisheye --sun-zenith 40 --sun-azimuth 120 -o fit/
    skyref invert sky.exr -o fit/          # a skyref EXR: camera and sun from its header
    skyref invert photo.png --camera fisheye --fov 185 --time 2026-06-21T14:00+02:00 \\
        --latitude 45.2 --longitude 5.7 --exclude trees.png -o fit/

Writes fit/result.json, convergence.png, residuals.png, fitted.exr and residual.exr
(:mod:`skyref.invert.result`) and prints the estimates.
"""

from __future__ import annotations

from skyref.atmosphere import PRESETS, preset
from skyref.errors import ParameterError
from skyref.invert import (InversionSettings, ParameterSet, invert, observation, read_exclusion_mask, read_image,
                           sun_from_arguments)
from skyref.invert.inputs import CHANNEL_CHOICES, MAX_WAVELENGTHS
from skyref.invert.parameters import DEFAULT_FREE, UNKNOWNS
from skyref.scene import CAMERA_TYPES, Observer
from skyref.validation import check_output_directory

__all__ = ["add_invert_parser", "cmd_invert"]


def add_invert_parser(subparsers):
    """Add the ``invert`` subcommand to ``skyref``'s argparse subparsers."""
    defaults = InversionSettings()
    p = subparsers.add_parser("invert", help="fit aerosol, ozone and ground albedo to a sky image (differentiable "
                              "ground truth)")
    p.add_argument("image", metavar="IMAGE", help="spectral or RGB OpenEXR, or an 8-bit PNG/JPEG (relative)")
    p.add_argument("-o", "--out", required=True, metavar="DIR", help="output directory")
    g = p.add_argument_group("camera (default: the image's skyref header)")
    g.add_argument("--camera", choices=CAMERA_TYPES, help="projection of the image")
    g.add_argument("--fov", type=float, help="field of view, degrees (fisheye: across the image circle, default "
                   "180; perspective: horizontal, required)")
    g.add_argument("--view-zenith", type=float, default=0.0, help="zenith angle of the view direction, degrees")
    g.add_argument("--view-azimuth", type=float, default=0.0, help="azimuth of the view direction, degrees from north")
    g = p.add_argument_group("sun (one of; default: the image's skyref header)")
    g.add_argument("--sun-zenith", type=float, help="degrees")
    g.add_argument("--sun-azimuth", type=float, help="degrees clockwise from north")
    g.add_argument("--time", help="ISO 8601 date and time (with --latitude and --longitude; pvlib)")
    g.add_argument("--latitude", type=float, help="degrees north")
    g.add_argument("--longitude", type=float, help="degrees east")
    g.add_argument("--sun-from-image", action="store_true", help="locate the visible sun disk in the image")
    g = p.add_argument_group("data")
    g.add_argument("--altitude", type=float, help="observer altitude, m (default: the header's, else 0)")
    g.add_argument("--exclude", metavar="MASK", help="image or .npy of the image's size; non-zero pixels are "
                   "left out (obstacles, clouds, ground)")
    g.add_argument("--channels", choices=CHANNEL_CHOICES, default="auto", help="fit the spectral channels or the "
                   "RGB of an EXR (default: spectral when present)")
    g.add_argument("--absolute", action="store_true", help="the image is absolute radiance (default: relative, "
                   "an exposure scale is fitted)")
    g.add_argument("--wavelengths", help="comma-separated nm: a spectral image's channels to fit, or the grid on "
                   "which RGB is modelled")
    g.add_argument("--max-wavelengths", type=int, default=MAX_WAVELENGTHS,
                   help="most channels of a spectral image to fit, evenly spread (default %(default)s)")
    g.add_argument("--max-view-zenith", type=float, default=90.0, help="leave out pixels farther than this from "
                   "the zenith, degrees (default 90: sky only; 180 fits the model's uniform ground too)")
    g.add_argument("--sun-exclusion", type=float, default=3.0, help="leave out pixels within this of the sun "
                   "(plus half a pixel), degrees")
    g = p.add_argument_group("unknowns")
    g.add_argument("--atmosphere", default="bruneton2017", choices=tuple(PRESETS),
                   help="base atmosphere (profiles, radii, everything not fitted)")
    g.add_argument("--free", default=",".join(DEFAULT_FREE), help="comma-separated unknowns to fit, of: "
                   + ", ".join(UNKNOWNS) + " (default %(default)s)")
    g.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="initial value of a free unknown or value of a fixed one (repeatable)")
    g.add_argument("--bounds", action="append", default=[], metavar="NAME=LO:HI", help="bounds of a free unknown")
    g = p.add_argument_group("budget")
    g.add_argument("--pixels", type=int, default=defaults.pixels, help="pixels fitted (default %(default)s)")
    g.add_argument("--spp", type=int, default=defaults.spp_start, help="samples per pixel of the first iteration")
    g.add_argument("--max-spp", type=int, default=defaults.spp_max, help="samples per pixel of late iterations")
    g.add_argument("--final-spp", type=int, default=defaults.final_spp, help="samples per pixel of the final step")
    g.add_argument("--map-spp", type=int, default=defaults.map_spp, help="samples per pixel of the fitted image (default: 2^25 samples over the image, 16 to 1024 per pixel)")
    g.add_argument("--iterations", type=int, default=defaults.max_iterations, help="most iterations")
    g.add_argument("--seed", type=int, default=defaults.seed)
    g.add_argument("--variant", help="Mitsuba variant (default: cuda_ad_rgb with a GPU, else llvm_ad_rgb)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=cmd_invert)
    return p


def _assignments(option: str, items, parse):
    """``NAME=VALUE`` items -> {NAME: parse(VALUE)}; errors name the option."""
    result = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise ParameterError(option, item, "NAME=VALUE", "not NAME=VALUE")
        try:
            result[name.strip()] = parse(value)
        except ValueError:
            raise ParameterError(option, item, "numbers, e.g. aod_550=0.1 or aod_550=0.01:1", "unreadable") from None
    return result


def _bounds(text: str) -> tuple:
    lo, sep, hi = text.partition(":")
    if not sep:
        raise ValueError(text)
    return float(lo), float(hi)


def _camera(args):
    """The camera fields given on the command line, or None (the image's own)."""
    if args.camera is None:
        for option, value, default in (("--fov", args.fov, None), ("--view-zenith", args.view_zenith, 0.0),
                                       ("--view-azimuth", args.view_azimuth, 0.0)):
            if value != default:
                raise ParameterError(option, value, "only together with --camera", "no camera given")
        return None
    if args.camera == "perspective" and args.fov is None:
        raise ParameterError("--fov", None, "the horizontal field of view of a perspective camera, degrees", "missing")
    camera = {"type": args.camera, "view_zenith_deg": args.view_zenith, "view_azimuth_deg": args.view_azimuth}
    if args.fov is not None:
        camera["fov_deg"] = args.fov
    return camera


def cmd_invert(args) -> int:
    """Run ``skyref invert`` (see the module's documentation)."""
    # Everything is checked before the first render.
    check_output_directory(args.out, "--out")
    atmosphere = preset(args.atmosphere)
    parameters = ParameterSet(atmosphere, free=[n.strip() for n in args.free.split(",") if n.strip()],
                              values=_assignments("--set", args.set, float),
                              bounds=_assignments("--bounds", args.bounds, _bounds))
    settings = InversionSettings(pixels=args.pixels, spp_start=args.spp, spp_max=max(args.max_spp, args.spp),
                                 final_spp=args.final_spp, map_spp=args.map_spp, max_iterations=args.iterations,
                                 seed=args.seed, variant=args.variant)
    camera = _camera(args)
    sun = sun_from_arguments(args.sun_zenith, args.sun_azimuth, args.time, args.latitude, args.longitude)
    if args.sun_from_image:
        if sun is not None:
            raise ParameterError("--sun-from-image", True, "alone, without sun angles or a time and place",
                                 "conflicting sun positions")
        sun = "image"
    image = read_image(args.image, args.channels)
    exclude = read_exclusion_mask(args.exclude, image.shape) if args.exclude else None
    wavelengths = None
    if args.wavelengths:
        try:
            wavelengths = [float(w) for w in args.wavelengths.split(",")]
        except ValueError:
            raise ParameterError("--wavelengths", args.wavelengths, "comma-separated numbers, nm", "unreadable") from None
    obs = observation(image, camera=camera, sun=sun,
                      observer=None if args.altitude is None else Observer(args.altitude), exclude=exclude,
                      absolute=args.absolute, max_view_zenith_deg=args.max_view_zenith,
                      sun_exclusion_deg=args.sun_exclusion, wavelengths=wavelengths,
                      max_wavelengths=args.max_wavelengths, atmosphere=atmosphere)
    result = invert(obs, parameters, settings, progress=not args.quiet)
    paths = result.write(args.out)
    fit = result.to_dict()["fit"]
    print("\n".join(result.summary_lines()))
    print(f"{'converged' if result.converged else 'NOT converged'} after {fit['iterations']} iterations on "
          f"{fit['pixels_fitted']} of {fit['pixels_usable']} usable pixels in {fit['fit_time_s']:.1f} s "
          f"(fitted image {fit['total_time_s'] - fit['fit_time_s']:.1f} s); every number from the ground-truth "
          f"path tracer; wrote {', '.join(paths)}")
    return 0
