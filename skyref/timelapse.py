"""The sky through a day: the sun placed by date, time and place, and timelapses of frames.

Times are ISO 8601 with a UTC offset (``2026-06-21T06:00+02:00``); places are ``LAT,LON`` in
degrees north and east. The sun's position comes from :meth:`skyref.scene.Sun.at` (pvlib's
solar position algorithm); sunrise and sunset from pvlib's SPA (upper limb on the horizon,
standard refraction).

A timelapse renders one sky per time, then tone-maps every frame with *one* exposure (the
sweep is there to show how the light changes): ``frame-NNN.png`` (the local time and the sun's
elevation stamped on each), optionally ``frame-NNN.exr``, and ``timelapse.gif`` (and
``timelapse.webp``), every file written atomically.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
import os
import re
import zoneinfo
from time import perf_counter

from tqdm import tqdm

from skyref.errors import ParameterError
from skyref.io.annotate import check_annotatable, draw_caption, draw_overlay
from skyref.io.atomic import atomic_path
from skyref.io.png import ev100_from_exposure, preview_image, save_png
from skyref.render import render_sky
from skyref.scene import Sun
from skyref.validation import check_choice, check_int, check_number, check_output_directory

__all__ = ["MAX_FRAMES", "TIMELAPSE_WAVELENGTHS", "parse_time", "parse_place", "parse_duration", "parse_zone",
           "sun_at", "sun_from_options", "solar_event", "frame_times", "timelapse_scene", "render_timelapse"]

#: Most frames one timelapse renders.
MAX_FRAMES = 2000

#: ``wavelengths`` of :func:`timelapse_scene`: skyref's three RGB wavelengths, or the scene's own.
TIMELAPSE_WAVELENGTHS = ("rgb", "scene")

_TIME_FORMAT = "ISO 8601 with a UTC offset, e.g. 2026-06-21T06:00+02:00"
_DURATION = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)\s*(h|min|s)\s*$")
_DURATION_UNITS = {"h": 3600.0, "min": 60.0, "s": 1.0}
_EVENT = re.compile(r"^\s*(sunrise|sunset|noon)\s*(?:([+-])(.*))?$")
_EVENT_COLUMNS = {"sunrise": "sunrise", "sunset": "sunset", "noon": "transit"}
_OFFSET = re.compile(r"^([+-])(\d{2}):(\d{2})$")


# --- times, places, zones -------------------------------------------------------------------------

def parse_time(text, parameter: str = "--time") -> _dt.datetime:
    """A timezone-aware datetime from ISO 8601 text with a UTC offset (naive times are refused:
    they would silently mean UTC or the machine's zone)."""
    try:
        time = _dt.datetime.fromisoformat(str(text).strip())
    except ValueError:
        raise ParameterError(parameter, text, _TIME_FORMAT, "unreadable time") from None
    if time.tzinfo is None:
        raise ParameterError(parameter, text, _TIME_FORMAT, "no UTC offset")
    return time


def parse_place(text, parameter: str = "--place") -> tuple[float, float]:
    """(latitude, longitude) in degrees from ``LAT,LON``: latitude in [-90, 90] (north),
    longitude in [-180, 180] (east)."""
    valid = "LAT,LON in degrees: latitude in [-90, 90] (north), longitude in [-180, 180] (east), e.g. 48.85,2.35"
    parts = str(text).split(",")
    try:
        latitude, longitude = (float(p) for p in parts)
    except ValueError:
        raise ParameterError(parameter, text, valid, "not two numbers") from None
    for name, value, bound in (("latitude", latitude, 90.0), ("longitude", longitude, 180.0)):
        if not -bound <= value <= bound:                      # also refuses NaN
            raise ParameterError(parameter, text, valid, f"{name} {value:g} out of range")
    return latitude, longitude


def parse_duration(text, parameter: str) -> _dt.timedelta:
    """A duration from ``NUMBER UNIT`` with unit h, min or s (``30min``, ``1.5h``, ``90s``)."""
    match = _DURATION.match(str(text))
    if not match:
        raise ParameterError(parameter, text, "a number and a unit h, min or s, e.g. 30min", "unreadable duration")
    return _dt.timedelta(seconds=float(match.group(1)) * _DURATION_UNITS[match.group(2)])


def parse_zone(text, longitude_deg: float, parameter: str = "--tz") -> _dt.tzinfo:
    """A time zone from ``UTC``, an offset ``+HH:MM`` or an IANA name (``Europe/Paris``); None:
    the nautical zone of the longitude, UTC + round(longitude / 15) hours."""
    if text is None:
        return _dt.timezone(_dt.timedelta(hours=round(longitude_deg / 15.0)))
    text = str(text).strip()
    if text.upper() == "UTC":
        return _dt.timezone.utc
    match = _OFFSET.match(text)
    if match:
        sign, hours, minutes = match.groups()
        offset = _dt.timedelta(hours=int(hours), minutes=int(minutes))
        if offset > _dt.timedelta(hours=14) or int(minutes) >= 60:
            raise ParameterError(parameter, text, "an offset within +-14:00", "out of range")
        return _dt.timezone(-offset if sign == "-" else offset)
    try:
        return zoneinfo.ZoneInfo(text)
    except (zoneinfo.ZoneInfoNotFoundError, ValueError):
        raise ParameterError(parameter, text, "UTC, an offset such as +02:00, or an IANA name such as Europe/Paris",
                             "unknown time zone") from None


# --- the sun ----------------------------------------------------------------------------------------

def sun_at(sun: Sun, time: _dt.datetime, latitude_deg: float, longitude_deg: float) -> Sun:
    """``sun`` (its disk, limb darkening) moved to where it stands at ``time`` seen from the place."""
    return Sun.at(time, latitude_deg, longitude_deg, angular_radius_deg=sun.angular_radius_deg,
                  limb_darkening=sun.limb_darkening)


def sun_from_options(sun: Sun, time_text=None, place_text=None) -> Sun:
    """The sun of ``skyref render --time T --place LAT,LON``: either option may be left out when
    the scene's sun already has a time and place (``sun.time``); ``sun`` itself when both are."""
    if time_text is None and place_text is None:
        return sun
    time = parse_time(time_text) if time_text is not None else sun.time
    place = parse_place(place_text) if place_text is not None else (sun.latitude_deg, sun.longitude_deg)
    if time is None:
        raise ParameterError("--time", None, f"{_TIME_FORMAT}; required with --place (the scene's sun has no time)",
                             "missing")
    if place[0] is None:
        raise ParameterError("--place", None, "LAT,LON; required with --time (the scene's sun has no place)",
                             "missing")
    return sun_at(sun, time, *place)


def solar_event(event: str, date: _dt.date, latitude_deg: float, longitude_deg: float, zone: _dt.tzinfo,
                parameter: str = "--from") -> _dt.datetime:
    """Sunrise, sunset or solar noon (``event``) on the local ``date`` in ``zone``, from pvlib's
    SPA; a ParameterError when there is none (polar day or night)."""
    import pandas as pd  # lazy: pandas and pvlib take ~2 s to import
    import pvlib

    column = _EVENT_COLUMNS[check_choice(parameter, event, tuple(_EVENT_COLUMNS))]
    # pvlib gives the events of each time's UTC day: ask for three days, keep the local date's.
    index = pd.DatetimeIndex([_dt.datetime.combine(date + _dt.timedelta(days=d), _dt.time(12), tzinfo=zone)
                              for d in (-1, 0, 1)])
    events = pvlib.solarposition.sun_rise_set_transit_spa(index, latitude_deg, longitude_deg)[column]
    for time in events.dropna():
        local = time.round("s").to_pydatetime().astimezone(zone)
        if local.date() == date:
            return local
    raise ParameterError(parameter, event, "an explicit time, e.g. 06:00 or 2026-06-21T06:00+02:00",
                         f"no {event} on {date} at {latitude_deg:g}, {longitude_deg:g} (polar day or night)")


def _bound(text, date, latitude_deg, longitude_deg, zone, parameter) -> _dt.datetime:
    """A --from/--to value: ``sunrise``/``sunset``/``noon`` with an optional ``+-DURATION``, a
    local clock time ``HH:MM`` on ``date``, or a full ISO 8601 time with an offset."""
    text = str(text).strip()
    event = _EVENT.match(text)
    clock = re.match(r"^\d{1,2}:\d{2}(:\d{2})?$", text)
    if (event or clock) and date is None:
        raise ParameterError("--date", None, f"YYYY-MM-DD; required with {parameter} {text}", "missing")
    if event:
        time = solar_event(event.group(1), date, latitude_deg, longitude_deg, zone, parameter)
        if event.group(2):
            shift = parse_duration(event.group(3), parameter)
            time = time + shift if event.group(2) == "+" else time - shift
        return time
    if clock:
        try:
            return _dt.datetime.combine(date, _dt.time.fromisoformat(text.zfill(5 if len(text) <= 5 else 8)),
                                        tzinfo=zone)
        except ValueError:
            raise ParameterError(parameter, text, "a clock time HH:MM", "not a time of day") from None
    return parse_time(text, parameter)


def frame_times(date_text, start_text, end_text, step_text, latitude_deg: float, longitude_deg: float,
                zone_text=None) -> list[_dt.datetime]:
    """The times of a timelapse, in the local zone: from ``start_text`` to ``end_text`` (both
    included when the steps land on it) every ``step_text``.

    Bounds: ``sunrise-1h``, ``sunset+30min``, ``noon``, a local clock time ``06:00`` on
    ``date_text`` (YYYY-MM-DD), or an ISO time with an offset. The zone (``zone_text``, see
    :func:`parse_zone`) defaults to the offset of an ISO ``start_text``, else the nautical zone.
    """
    date = None
    if date_text is not None:
        try:
            date = _dt.date.fromisoformat(str(date_text).strip())
        except ValueError:
            raise ParameterError("--date", date_text, "YYYY-MM-DD, e.g. 2026-06-21", "unreadable date") from None
    zone = parse_zone(zone_text, longitude_deg)
    if zone_text is None:
        try:                                                  # an ISO --from: its offset is the local zone
            zone = parse_time(start_text, "--from").tzinfo
        except ParameterError:
            pass                                              # not ISO: _bound reads it below
    step = parse_duration(step_text, "--step")
    if not _dt.timedelta(seconds=1) <= step <= _dt.timedelta(days=1):
        raise ParameterError("--step", step_text, "1 s to 24 h", "out of range")
    start = _bound(start_text, date, latitude_deg, longitude_deg, zone, "--from").astimezone(zone)
    end = _bound(end_text, date, latitude_deg, longitude_deg, zone, "--to").astimezone(zone)
    if end < start:
        raise ParameterError("--to", end_text, f"at or after --from ({start.isoformat(timespec='minutes')})",
                             f"ends before it starts ({end.isoformat(timespec='minutes')})")
    count = math.floor((end - start) / step + 1e-9) + 1
    if count > MAX_FRAMES:
        raise ParameterError("--step", step_text, f"at most {MAX_FRAMES} frames from --from to --to",
                             f"{count} frames")
    return [start + i * step for i in range(count)]


# --- rendering --------------------------------------------------------------------------------------

def timelapse_scene(scene, size: int = 128, wavelengths: str = "rgb"):
    """``scene`` made small for a timelapse: its camera's longer side ``size`` pixels (aspect
    kept), and skyref's RGB wavelengths unless ``wavelengths`` is ``"scene"``."""
    size = check_int("--size", size, 8, 4096)
    check_choice("--wavelengths", wavelengths, TIMELAPSE_WAVELENGTHS)
    camera = scene.camera
    longer = max(camera.width, camera.height)
    width, height = (max(1, round(side * size / longer)) for side in (camera.width, camera.height))
    scene = scene.replace(camera=dataclasses.replace(camera, width=width, height=height))
    return scene.replace(wavelengths="rgb") if wavelengths == "rgb" else scene


def _caption(time: _dt.datetime, sun: Sun) -> str:
    return f"{time:%H:%M} {time:%Z}\nsun {90.0 - sun.zenith_deg:+.1f}\N{DEGREE SIGN}"


def _save_animation(images, path, frame_ms: int) -> None:
    from PIL import Image  # lazy: Pillow's import is paid only when writing images

    frames = [Image.fromarray(image, mode="RGB") for image in images]
    webp = path.endswith(".webp")
    with atomic_path(path) as tmp:
        frames[0].save(tmp, format="WEBP" if webp else "GIF", save_all=True, append_images=frames[1:],
                       duration=frame_ms, loop=0, **({"lossless": True} if webp else {}))


def render_timelapse(scene, times, latitude_deg: float, longitude_deg: float, directory, *, spp: int = 64,
                     exposure: float | None = None, annotate: bool = True, exr: bool = False, webp: bool = False,
                     fps: float = 6.0, variant: str | None = None, progress: bool = True) -> dict:
    """Render ``scene`` with the sun at each of ``times`` (aware datetimes) seen from the place,
    into ``directory``: ``frame-NNN.png`` (and ``.exr`` if ``exr``), ``timelapse.gif`` (and
    ``timelapse.webp`` if ``webp``) at ``fps`` frames per second.

    Every frame is tone-mapped with one ``exposure`` (1 / (cd m^-2), see
    :func:`skyref.io.png.exposure_from_ev100`); by default the per-image exposure of the
    brightest frame (the smallest of :func:`skyref.color.default_exposure` over the frames).
    Frames are annotated (horizon, N/E/S/W, the sun) if ``annotate``, and always stamped with
    the local time and the sun's elevation. Returns a summary: files, exposure, EV100, seconds.
    """
    from PIL import features  # lazy: Pillow's import is paid only when writing images

    from skyref.color import default_exposure  # lazy: colour-science's import cost

    if not times or len(times) > MAX_FRAMES:
        raise ParameterError("times", len(times), f"1 to {MAX_FRAMES} times", "wrong number of frames")
    check_int("--spp", spp, scene.render.passes, 1 << 24)
    if exposure is not None:
        check_number("exposure", exposure, 0.0, math.inf, lo_open=True)
    check_number("--fps", fps, 0.1, 100.0)
    if annotate:
        check_annotatable(scene.camera, "--annotate")
    if webp and not features.check("webp"):
        raise ParameterError("--webp", True, "a Pillow built with WebP", "this Pillow cannot write WebP")
    check_output_directory(directory, "-o")
    directory = os.fspath(directory)
    digits = max(3, len(str(len(times) - 1)))
    name = os.path.join(directory, f"frame-{{:0{digits}d}}")

    frames = []                                               # (linear sRGB, sun, caption)
    start = perf_counter()
    bar = tqdm(times, desc=f"timelapse {scene.name or 'sky'}", unit="frame", disable=not progress)
    for i, time in enumerate(bar):
        bar.set_postfix_str(f"{time:%H:%M}")
        sun = sun_at(scene.sun, time, latitude_deg, longitude_deg)
        sky = render_sky(scene.replace(sun=sun), spp=spp, variant=variant)
        if exr:
            sky.save(name.format(i) + ".exr")
        frames.append((sky.rgb(), sun, _caption(time, sun)))
    render_time = perf_counter() - start
    if exposure is None:
        exposure = min(default_exposure(rgb) for rgb, _, _ in frames)

    images, files = [], []
    for i, (rgb, sun, caption) in enumerate(frames):
        image = preview_image(rgb, exposure)
        if annotate:
            image = draw_overlay(image, scene.camera, sun.direction)
        images.append(draw_caption(image, caption))
        files.append(name.format(i) + ".png")
        save_png(images[-1], files[-1])
    frame_ms = round(1000.0 / fps)
    animations = [os.path.join(directory, "timelapse.gif")] + ([os.path.join(directory, "timelapse.webp")]
                                                              if webp else [])
    for path in animations:
        _save_animation(images, path, frame_ms)
    return {"frames": files, "animations": animations, "exposure": exposure,
            "ev100": ev100_from_exposure(exposure), "times": [t.isoformat() for t in times],
            "sun_zenith_deg": [sun.zenith_deg for _, sun, _ in frames],
            "render_time_s": render_time}
