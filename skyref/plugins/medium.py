"""The ``atmosphere_medium`` medium: skyref's atmosphere as a Mitsuba participating medium,
usable by the stock ``volpath`` integrator (and anything else that drives
``Medium.sample_interaction``).

Plugin name: Mitsuba 3.9.1 keys its plugin registry by (name, variant) only, whatever the
object type, so a medium called ``atmosphere`` would replace (or be replaced by) the
``atmosphere`` integrator. The medium is therefore registered as ``atmosphere_medium``
(:data:`PLUGIN_NAME`).

Properties (all optional):

``atmosphere``
    a preset name or the JSON of ``Atmosphere.to_dict()`` (default ``bruneton2017``);
``observer_altitude``
    m (default 0). The scene frame is the observer-centred east-north-up frame of the
    ``atmosphere`` integrator, in metres: observer at the origin, planet centre at
    (0, 0, -(R + h0));
``wavelengths``
    comma-separated nm. Default: ``680,550,440`` in RGB variants (R, G, B), a 1 nm grid
    360–830 nm in spectral variants (see :class:`skyref.plugins.phase.ChannelMap`);
``majorant``
    ``segment`` (default) or ``global``, see below;
``phase``
    an ``atmosphere_phase`` instance (one is created when absent);
``sample_emitters``
    as for every Mitsuba medium.

From Python, :meth:`AtmosphereMedium.configure` sets the same things from skyref objects.

Coefficients and majorants come from :class:`skyref.plugins.optics.AtmosphereOptics`; the
altitude of a point from :class:`skyref.plugins.geometry.SphericalShell` (cancellation-free in
float32). Below the ground the coefficients are those of the ground (Mitsuba's float32 sphere
may let a point slip a metre under it); above the top of the atmosphere the medium is empty.

**What Mitsuba 3.9.1 calls, and the majorant.** Only ``intersect_aabb``, ``get_majorant`` and
``get_scattering_coefficients`` are called from C++, in that order, by
``Medium::sample_interaction(ray, ...)``. ``get_majorant`` receives a MediumInteraction that
holds only ``wi`` (= -ray.d), ``time`` and ``wavelengths``: *not* the ray's origin. The free
flight is then sampled from the ray's origin up to the box's exit (or the next surface) against
that majorant, and ``get_scattering_coefficients`` gets ``sigma_n = majorant - sigma_t`` at the
sampled point *before* ``combined_extinction`` is stored in the interaction. Hence:

* ``majorant = "segment"``: ``intersect_aabb`` keeps the ray it was given and ``get_majorant``
  bounds sigma_t along that ray's segment inside the box: the extinction at the lowest altitude
  of the segment (its closest approach to the planet's centre, clamped to the ground), up to the
  highest (for non-monotonic profiles such as the ozone tent). ``get_scattering_coefficients``
  then uses that same majorant for sigma_n and drops what was kept. After each null collision
  ``volpath`` restarts from the collision point, so the majorant follows the ray as it climbs,
  as in the ``atmosphere`` integrator. What is kept is a plain Python attribute holding Dr.Jit
  variables of the trace in progress: it relies on that call order (true of every Mitsuba 3.9.1
  integrator, since all go through ``sample_interaction``), and a Python caller that calls
  ``intersect_aabb`` itself must call ``get_majorant`` next.
* ``majorant = "global"`` (or a direct call of ``get_majorant`` that does not follow an
  ``intersect_aabb``): the largest extinction anywhere in the atmosphere. Always valid, slower
  (measured, whole sky, 2 shared cores, llvm_ad_rgb: 0.50 M paths/s against 0.78 M).

Every majorant is *grey* (the largest value over the ray's channels, the same in all channels:
per-channel majorants bias ``prbvolpath`` and inflate ``volpath``'s variance, docs/design.md), and
inflated by ``MAJORANT_SAFETY`` against float32 rounding of altitudes.

Differentiable parameters (``mi.traverse``): those of ``AtmosphereOptics.parameters()`` except
``ground_albedo`` (the ground is a BSDF of the scene, not part of the medium).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from skyref.atmosphere import RGB_WAVELENGTHS_NM
from skyref.plugins.geometry import SphericalShell
from skyref.plugins.optics import AtmosphereOptics, atmosphere_from_property
from skyref.plugins.phase import ChannelMap, is_atmosphere_phase, phase_class
from skyref.plugins.phase import register as register_phase
from skyref.plugins.variant_class import variant_class
from skyref.validation import check_choice, check_number

__all__ = ["PLUGIN_NAME", "MAJORANT_SAFETY", "MAJORANT_FLOOR", "SPECTRAL_GRID_NM", "MAJORANT_MODES",
           "default_wavelengths", "AtmosphereMediumMethods", "medium_class", "register"]

#: Name under which the medium is registered (see the module docstring).
PLUGIN_NAME = "atmosphere_medium"
#: Majorants are inflated by this factor (float32 altitude rounding; as in the integrator).
MAJORANT_SAFETY = 1.001
#: Smallest majorant, m^-1 (a segment entirely above the atmosphere has none).
MAJORANT_FLOOR = 1.0e-12
#: Default wavelength grid of spectral variants, nm (Mitsuba's own spectral range).
SPECTRAL_GRID_NM = (360.0, 830.0, 1.0)
MAJORANT_MODES = ("segment", "global")


def default_wavelengths() -> np.ndarray:
    """The grid the current variant uses by default: RGB 680/550/440 nm, or 360–830 nm by 1 nm."""
    if mi.is_spectral:
        start, stop, step = SPECTRAL_GRID_NM
        return np.arange(start, stop + 0.5 * step, step)
    return np.asarray(RGB_WAVELENGTHS_NM, dtype=np.float64)


class AtmosphereMediumMethods:
    """Mitsuba plugin ``atmosphere_medium`` (see the module docstring): these methods on the
    current variant's ``mi.Medium`` (:func:`medium_class`)."""

    def __init__(self, props=None):
        props = mi.Properties(PLUGIN_NAME) if props is None else props
        phase = None
        for name in props.keys():
            if is_atmosphere_phase(props[name]):
                phase = props[name]
        if phase is None:
            phase = phase_class()()
            props["phase"] = phase
        atmosphere = atmosphere_from_property(props.get("atmosphere", "bruneton2017"))
        observer_altitude = float(props.get("observer_altitude", 0.0))
        text = props.get("wavelengths", "")
        wavelengths = [float(x) for x in text.split(",")] if text else None
        majorant = props.get("majorant", "segment")
        self._mitsuba_base.__init__(self, props)
        self._phase = phase
        self.m_is_homogeneous = False
        self.m_has_spectral_extinction = True
        self.configure(atmosphere, wavelengths, observer_altitude, majorant)

    def configure(self, atmosphere, wavelengths_nm=None, observer_altitude_m: float = 0.0,
                  majorant: str = "segment"):
        """Set the atmosphere (Atmosphere, preset name or JSON), the wavelength grid (nm;
        default :func:`default_wavelengths`), the observer's altitude (m) and the majorant mode."""
        atmosphere = atmosphere_from_property(atmosphere)
        self.majorant_mode = check_choice("majorant", majorant, MAJORANT_MODES)
        h0 = check_number("observer_altitude_m", observer_altitude_m, 0.0, 1.0e8)
        grid = default_wavelengths() if wavelengths_nm is None else np.asarray(wavelengths_nm, np.float64)
        self.atmosphere = atmosphere
        self.optics = AtmosphereOptics(atmosphere, grid)
        self.wavelengths_nm = self.optics.wavelengths_nm
        self.geometry = SphericalShell(atmosphere.bottom_radius_m, atmosphere.top_radius_m, h0)
        self.channel_map = ChannelMap(self.optics)
        self._phase.attach(self.optics, self.geometry, self.channel_map)
        top = atmosphere.top_radius_m
        centre_z = -self.geometry.centre_distance
        # The top sphere's bounding box, as plain floats: mi.BoundingBox3f is shared by variants
        # with the same Float type and its ray_intersect accepts only the Ray3f of the variant
        # that was loaded first (Mitsuba 3.9.1).
        self.box = ((-top, -top, centre_z - top), (top, top, centre_z + top))
        self._pending_ray = None
        self._pending_majorant = None

    # --- what C++ calls -------------------------------------------------------------------------

    def intersect_aabb(self, ray):
        active, mint, maxt = self._box_intersect(ray)
        self._pending_majorant = None
        if self.majorant_mode == "segment":
            # Kept for get_majorant, which Medium::sample_interaction calls next with an
            # interaction that does not hold the ray's origin.
            self._pending_ray = (mi.Point3f(ray.o), mi.Vector3f(ray.d), mi.Float(mint),
                                 dr.minimum(maxt, ray.maxt), mi.Bool(active))
        return active, mint, maxt

    def _box_intersect(self, ray):
        """Slab test against the bounding box: (hit, mint, maxt) as mi.BoundingBox3f does."""
        lower, upper = self.box
        mint, maxt = mi.Float(-dr.inf), mi.Float(dr.inf)
        for axis in range(3):
            inverse = dr.rcp(ray.d[axis])
            t1 = (lower[axis] - ray.o[axis]) * inverse
            t2 = (upper[axis] - ray.o[axis]) * inverse
            mint = dr.maximum(mint, dr.minimum(t1, t2))
            maxt = dr.minimum(maxt, dr.maximum(t1, t2))
        return mint <= maxt, mint, maxt

    def get_majorant(self, mei, active=True):
        channels, _ = self.channel_map.channels(mei.wavelengths)
        majorant = self.global_majorant(channels)
        if self._pending_ray is not None:
            o, d, mint, maxt, hit = self._pending_ray
            self._pending_ray = None
            segment = self.segment_majorant(channels, o, d, dr.maximum(mint, 0.0), maxt)
            majorant = dr.select(hit & dr.isfinite(segment), segment, majorant)
            self._pending_majorant = majorant
        return mi.UnpolarizedSpectrum(majorant)

    def get_scattering_coefficients(self, mei, active=True):
        h = self.geometry.altitude(mei.p)
        inside = h <= self.geometry.H
        channels, fractions = self.channel_map.channels(mei.wavelengths)
        _, sigma_s, sigma_t = self.channel_map.local(channels, fractions, dr.clip(h, 0.0, self.geometry.H))
        sigma_s = dr.select(inside, sigma_s, 0.0)
        sigma_t = dr.select(inside, sigma_t, 0.0)
        if self._pending_majorant is not None:
            majorant = self._pending_majorant
            self._pending_majorant = None
        else:
            # Called on its own: the interaction's own majorant when it has one.
            stored = dr.max(mei.combined_extinction, axis=0)
            majorant = dr.select(stored > 0.0, stored, self.global_majorant(channels))
        sigma_n = dr.maximum(majorant - sigma_t, 0.0)
        spectrum = self.channel_map.to_spectrum
        return spectrum(sigma_s), spectrum(sigma_n), spectrum(sigma_t)

    # --- majorants ------------------------------------------------------------------------------

    def global_majorant(self, channels):
        """The largest extinction anywhere in the atmosphere (grey), m^-1."""
        return MAJORANT_SAFETY * self.optics.majorant(channels, mi.Float(0.0), mi.Float(self.geometry.H)) \
            + MAJORANT_FLOOR

    def segment_majorant(self, channels, o, d, t0, t1):
        """A grey bound of sigma_t on the segment o + t d, t in [t0, t1] (observer frame), m^-1:
        the distance to the planet's centre is convex along a line, so the lowest altitude is at
        the closest approach clamped to the segment and the highest at an end."""
        geometry = self.geometry
        start = o + t0 * d
        h_start = geometry.altitude(start)
        h_end = geometry.altitude(o + t1 * d)
        h_low = geometry.lowest_altitude(start, d, t1 - t0, h_start, h_end)
        h_high = dr.maximum(h_start, h_end)
        h_low = dr.clip(h_low, 0.0, geometry.H)
        h_high = dr.clip(h_high, h_low, geometry.H)
        return MAJORANT_SAFETY * self.optics.majorant(channels, h_low, h_high) + MAJORANT_FLOOR

    # --- Python-side conveniences -------------------------------------------------------------------

    def sigma_t(self, p, wavelengths=None):
        """sigma_t at points ``p`` (observer frame) per channel, as the medium sees it (tests)."""
        h = self.geometry.altitude(p)
        channels, fractions = self.channel_map.channels(wavelengths)
        _, _, sigma_t = self.channel_map.local(channels, fractions, dr.clip(h, 0.0, self.geometry.H))
        return self.channel_map.to_spectrum(dr.select(h <= self.geometry.H, sigma_t, 0.0))

    def phase(self):
        """The ``atmosphere_phase`` instance (also ``phase_function()``)."""
        return self._phase

    def traverse(self, callback):
        for name, value in self.optics.parameters().items():
            if name != "ground_albedo":
                callback.put(name, value, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys=[]):
        pass

    def to_string(self):
        return (f"AtmosphereMedium[atmosphere={self.atmosphere.name!r}, "
                f"observer_altitude={self.geometry.h0} m, majorant={self.majorant_mode!r}, "
                f"wavelengths={len(self.wavelengths_nm)}]")


def medium_class():
    """The ``atmosphere_medium`` class of the current Mitsuba variant."""
    return variant_class(AtmosphereMediumMethods, "AtmosphereMedium", "Medium")


def __getattr__(name):
    if name == "AtmosphereMedium":
        return medium_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def register():
    """Register ``atmosphere_medium`` and ``atmosphere_phase`` for the current variant."""
    register_phase()
    cls = medium_class()
    mi.register_medium(PLUGIN_NAME, lambda props: cls(props))
