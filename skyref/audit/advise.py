"""``skyref advise``: the cheapest method that meets an error tolerance for a kind of scene,
read from the measured speed-vs-error map (:mod:`skyref.audit.speed_map`).

A scene's kind is decided from what changes the sky most (:func:`scene_kind`): an observer at
5 km or higher is "high altitude", a sun 85 deg or more from the zenith is "sunset", a
turbidity of 3 or more (:func:`skyref.atmosphere.turbidity`) is "hazy", anything else "clear".
Scenes the map has not measured (sun below the horizon, observer above 20 km) are refused
rather than guessed. A method meets the tolerance when its sky luminance RMS error is within it
on every measured sky of that kind and no sky of the kind was refused by the method.
"""

from __future__ import annotations

import json

from skyref.atmosphere import turbidity
from skyref.audit.speed_map import FRAME_DIRECTIONS, KINDS, frame_seconds
from skyref.errors import ParameterError
from skyref.sky_method import describe_operations

__all__ = ["COSTS_MEAN", "ENTRY_KEYS", "MAX_ALTITUDE_M", "MAX_SUN_ZENITH_DEG", "advice_lines", "load_map",
           "parse_tolerance", "rank", "scene_kind"]

#: Highest observer the map's skies represent, m (its high-altitude skies are at 10 km).
MAX_ALTITUDE_M = 20_000.0
#: Highest sun zenith angle the map's skies represent, deg (its sunsets have the sun at 88 deg).
MAX_SUN_ZENITH_DEG = 90.0


def parse_tolerance(text: str) -> float:
    """"2%" or "0.02" -> 0.02; must lie in (0, 100%]."""
    value = str(text).strip()
    try:
        number = float(value[:-1]) / 100.0 if value.endswith("%") else float(value)
    except ValueError:
        raise ParameterError("--tolerance", text, "a relative error such as 2% or 0.02", "not a number") from None
    if not 0.0 < number <= 1.0:
        raise ParameterError("--tolerance", text, "(0%, 100%]", "out of range")
    return number


def scene_kind(scene) -> tuple[str, str]:
    """(kind, reason) of ``scene`` (see the module docstring)."""
    altitude = scene.observer.altitude_m
    zenith = scene.sun.zenith_deg
    if altitude > MAX_ALTITUDE_M:
        raise ParameterError("observer.altitude_m", altitude, f"<= {MAX_ALTITUDE_M:g} m for advice",
                             "the map's high-altitude skies are at 10 km; audit this scene with 'skyref audit'")
    if zenith > MAX_SUN_ZENITH_DEG:
        raise ParameterError("sun.zenith_deg", zenith, f"<= {MAX_SUN_ZENITH_DEG:g} deg for advice",
                             "the map has no twilight skies; audit this scene with 'skyref audit'")
    if altitude >= 5000.0:
        return "high altitude", f"observer at {altitude / 1000:g} km (>= 5 km)"
    if zenith >= 85.0:
        return "sunset", f"sun {zenith:g} deg from the zenith (>= 85 deg)"
    t = turbidity(scene.atmosphere)
    if t >= 3.0:
        return "hazy", f"turbidity {t:.2f} (>= 3)"
    return "clear", f"turbidity {t:.2f} (< 3), sun {zenith:g} deg from the zenith, observer at {altitude:g} m"


def rank(summaries: list[dict], kind: str, tolerance: float, directions: int = FRAME_DIRECTIONS,
         frames: int = 1) -> tuple[list[dict], list[dict]]:
    """(methods meeting ``tolerance`` on ``kind`` skies, cheapest first; the others, most
    accurate first), each a summary of :func:`skyref.audit.speed_map.entry_summary` with
    ``cost_s`` (:func:`skyref.audit.speed_map.frame_seconds` for ``frames`` frames of
    ``directions`` directions) and ``error`` (worst sky luminance RMS on the kind's skies)."""
    if kind not in KINDS:
        raise ParameterError("kind", kind, ", ".join(KINDS), "unknown kind of scene")
    meeting, others = [], []
    for summary in summaries:
        measured = summary["kinds"].get(kind)
        if measured is None:
            continue
        candidate = {**summary, "error": measured["rms"], "error_resolved": measured["resolved"],
                     "cost_s": frame_seconds(summary, directions, frames)}
        (meeting if measured["rms"] <= tolerance and not measured["partial"] else others).append(candidate)
    meeting.sort(key=lambda c: c["cost_s"])
    others.sort(key=lambda c: c["error"])
    return meeting, others


#: What :func:`rank` and :func:`advice_lines` read of each entry of a map.
ENTRY_KEYS = ("method", "label", "kinds", "precompute_s", "per_view_s", "lookup_s")


def load_map(path: str) -> list[dict]:
    """The entry summaries of a map written by ``skyref report``; a ParameterError naming
    ``--map`` for a missing, unreadable or malformed file."""
    valid = "a map.json written by 'skyref report'"
    try:
        with open(path, encoding="utf-8") as f:
            document = json.load(f)
    except FileNotFoundError:
        raise ParameterError("--map", path, valid, "not found; run 'skyref report' first") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ParameterError("--map", path, valid, f"unreadable: {exc}") from None
    except json.JSONDecodeError as exc:
        raise ParameterError("--map", path, valid, f"not JSON (line {exc.lineno}, column {exc.colno}: "
                             f"{exc.msg})") from None
    entries = document.get("entries") if isinstance(document, dict) else None
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise ParameterError("--map", path, valid, "no list of 'entries'")
    for i, entry in enumerate(entries):
        missing = [key for key in ENTRY_KEYS if key not in entry]
        if missing or not isinstance(entry["kinds"], dict):
            raise ParameterError("--map", path, valid, f"entry {i} lacks {', '.join(missing) or 'a kinds table'}")
    return entries


#: What the costs in the advice are (printed with it).
COSTS_MEAN = ("costs: wall seconds of skyref's own implementations on the CPU that measured the map "
              "('skyref report'): a method's precomputation once, its per-view tables once per frame, its "
              "lookups per direction (the last two warm: first-call kernel compilation excluded). An engine on "
              "a GPU pays for what they count instead (table fetches per direction, per-view cells x samples), "
              "in the same proportions only roughly")


def _cost_text(c: dict, directions: int, frames: int) -> str:
    counted = f"; counts: {describe_operations(c['operations'])}" if c.get("operations") else ""
    return (f"{c['cost_s']:.3g} s on the map's CPU for {frames} frame(s) of {directions:,} directions (precompute "
            f"{c['precompute_s']:.3g} s, per view {1e3 * c['per_view_s']:.3g} ms, "
            f"{1e9 * c['lookup_s']:.3g} ns per direction{counted})")


def advice_lines(summaries, scene, tolerance: float, directions: int = FRAME_DIRECTIONS, frames: int = 1) -> list[str]:
    """The advice, as lines of text."""
    kind, reason = scene_kind(scene)
    meeting, others = rank(summaries, kind, tolerance, directions, frames)
    lines = [f"scene '{scene.name}': {kind} ({reason})",
             f"tolerance: sky luminance RMS <= {100 * tolerance:g}% on every measured {kind} sky"]
    if meeting:
        best = meeting[0]
        lines.append(f"cheapest method meeting it: {best['method']} ({best['label']}), worst {kind} sky "
                     f"{100 * best['error']:.2f}%{'' if best['error_resolved'] else ' (not resolved: below the ground truth noise x5)'}; "
                     f"cost {_cost_text(best, directions, frames)}")
        for c in meeting[1:4]:
            lines.append(f"  next: {c['method']} ({c['label']}): {100 * c['error']:.2f}%, {c['cost_s']:.3g} s")
    else:
        lines.append(f"no measured method meets {100 * tolerance:g}% on {kind} skies")
        if others:
            best = others[0]
            why = ("refused some of these skies" if best["error"] <= tolerance
                   else f"{100 * best['error']:.2f}%")
            lines.append(f"most accurate of them: {best['method']} ({best['label']}), {why}; "
                         f"cost {_cost_text(best, directions, frames)}")
    lines.append(COSTS_MEAN)
    return lines
