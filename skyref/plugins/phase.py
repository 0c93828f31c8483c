"""The ``atmosphere_phase`` phase function: the atmosphere's local mixture phase function.

At a point of altitude h the light scattered by the air follows

    p(mu; h, lambda) = sum_i sigma_s,i(h, lambda) p_i(mu) / sum_i sigma_s,i(h, lambda),

the constituents' phase functions (Rayleigh, Cornette–Shanks, ...) weighted by their local
scattering coefficients, so it depends on the position and on the wavelength. Coefficients and
phase functions come from :class:`skyref.plugins.optics.AtmosphereOptics` (nothing is computed
twice); the altitude from the medium's geometry (:mod:`skyref.plugins.geometry`, observer-centred
frame). The ``atmosphere_medium`` medium (:mod:`skyref.plugins.medium`) creates one of these,
owns it and hands it its optics and geometry; on its own the plugin has nothing to evaluate.

Conventions (Mitsuba 3.9.1, checked against the built-in ``hg`` plugin): ``mei.wi`` points away
from the interaction, back to where the path came from, and ``wo`` is the direction the path
continues in; forward scattering is ``wo = -wi``, so the scattering-angle cosine between the
propagation directions is mu = -dot(wo, wi). ``eval_pdf`` returns (phase value per channel,
sampling pdf), ``sample`` returns (wo, value / pdf per channel, pdf).

Channels (:class:`ChannelMap`):

* RGB variants: the 3 colour channels are the 3 grid wavelengths (680/550/440 nm by default:
  R, G, B = grid indices 0, 1, 2);
* spectral variants: each of a ray's continuous wavelengths (``mei.wavelengths``, 4 per ray) is
  mapped onto a *uniform* grid (1 nm, 360–830 nm by default) by **linear interpolation** of the
  coefficients between the two neighbouring grid wavelengths (clamped at the ends). Linear
  interpolation keeps the coefficients continuous in lambda: with a 1 nm step the interpolation
  error of the lambda^-4 Rayleigh law is ~2e-5 relative, whereas taking the nearest index would
  err by up to 0.5% per sample. The grid values bound the interpolated ones, so majorants taken
  over the two neighbours stay valid.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from skyref.errors import ParameterError
from skyref.plugins.optics import direction_with_cosine
from skyref.plugins.variant_class import is_instance, variant_class

__all__ = ["ChannelMap", "AtmospherePhaseMethods", "is_atmosphere_phase", "phase_class", "register"]


class ChannelMap:
    """How a Mitsuba ``Spectrum``'s channels map onto an :class:`AtmosphereOptics` grid, and the
    local coefficients per channel (shared by the medium and the phase function)."""

    def __init__(self, optics):
        self.optics = optics
        self.grid = np.asarray(optics.wavelengths_nm, dtype=np.float64)
        self.size = int(dr.size_v(mi.Spectrum))
        self.spectral = mi.is_spectral
        if self.spectral:
            steps = np.diff(self.grid)
            if self.grid.size < 2 or np.any(steps <= 0.0) or np.ptp(steps) > 1e-6 * steps[0]:
                raise ParameterError("wavelengths", self.grid.tolist(),
                                     "a uniform increasing grid of >= 2 values in spectral variants")
            self.start = float(self.grid[0])
            self.step = float(steps[0])
        elif self.grid.size != self.size:
            raise ParameterError("wavelengths", self.grid.tolist(),
                                 f"exactly {self.size} values in RGB variants (one per colour channel)")

    def channels(self, wavelengths):
        """(PathChannels over the grid indices involved, interpolation fractions or None)."""
        if not self.spectral:
            return self.optics.channel_coefficients([mi.UInt32(k) for k in range(self.size)]), None
        n = self.grid.size
        indices, fractions = [], []
        for k in range(self.size):
            x = dr.clip((wavelengths[k] - self.start) * (1.0 / self.step), 0.0, float(n - 1))
            i0 = dr.minimum(mi.UInt32(x), n - 2)
            indices += [i0, i0 + 1]
            fractions.append(x - mi.Float(i0))
        return self.optics.channel_coefficients(indices), fractions

    def _combine(self, array, fractions):
        """Grid-index channels -> Spectrum channels (interpolated in spectral variants)."""
        if array is None or fractions is None:
            return array
        return mi.ArrayXf([dr.lerp(array[2 * k], array[2 * k + 1], fractions[k])
                           for k in range(self.size)])

    def local(self, channels, fractions, altitude):
        """(per-component sigma_s (None for absorbers), sigma_s, sigma_t) per Spectrum channel at
        ``altitude``, m^-1, as ArrayXf."""
        parts, sigma_s, sigma_t = self.optics.local(channels, altitude)
        return ([self._combine(p, fractions) for p in parts], self._combine(sigma_s, fractions),
                self._combine(sigma_t, fractions))

    def to_spectrum(self, array):
        return mi.UnpolarizedSpectrum(*[array[k] for k in range(self.size)])


class AtmospherePhaseMethods:
    """Mitsuba plugin ``atmosphere_phase`` (no properties). :meth:`attach` gives it the optics
    and geometry; the ``atmosphere_medium`` medium does that for the instance it owns.

    The plugin class is these methods on the *current variant's* ``mi.PhaseFunction``
    (:func:`phase_class`): a class bound to one variant's base is rejected by the C++ of another
    (e.g. as a medium's phase function)."""

    def __init__(self, props=None):
        self._mitsuba_base.__init__(self, mi.Properties() if props is None else props)
        self.m_flags = int(mi.PhaseFunctionFlags.Anisotropic)
        self.optics = None
        self.geometry = None
        self.channel_map = None

    def attach(self, optics, geometry, channel_map=None):
        """Use ``optics`` (AtmosphereOptics) and ``geometry`` (SphericalShell or
        PlaneParallelSlab, observer-centred frame)."""
        self.optics = optics
        self.geometry = geometry
        self.channel_map = channel_map if channel_map is not None else ChannelMap(optics)

    def _local(self, mei):
        if self.optics is None:
            raise RuntimeError("atmosphere_phase has no atmosphere: use it through the "
                               "'atmosphere_medium' medium (or call attach(optics, geometry))")
        h = dr.clip(self.geometry.altitude(mei.p), 0.0, self.geometry.H)
        channels, fractions = self.channel_map.channels(mei.wavelengths)
        parts, sigma_s, _ = self.channel_map.local(channels, fractions, h)
        return parts, sigma_s

    def eval_pdf(self, ctx, mei, wo, active=True):
        parts, sigma_s = self._local(mei)
        mu = dr.clip(-dr.dot(wo, mei.wi), -1.0, 1.0)
        value = self.optics.phase(parts, sigma_s, mu)
        pdf = self.optics.phase_pdf(parts, sigma_s, mu)
        return self.channel_map.to_spectrum(value), pdf

    def sample(self, ctx, mei, sample1, sample2, active=True):
        parts, sigma_s = self._local(mei)
        mu, pdf = self.optics.sample_phase(parts, sigma_s, sample1, sample2.x)
        wo = direction_with_cosine(-mei.wi, mu, sample2.y)
        value = self.optics.phase(parts, sigma_s, mu)
        weight = value / dr.maximum(pdf, 1e-30)
        return wo, self.channel_map.to_spectrum(weight), pdf

    def projected_area(self, mei, active=True):
        return mi.Float(1.0)

    def max_projected_area(self):
        return mi.Float(1.0)

    def traverse(self, callback):
        # The parameters live in the shared AtmosphereOptics and are exposed by the medium.
        pass

    def parameters_changed(self, keys=[]):
        pass

    def to_string(self):
        name = self.optics.atmosphere.name if self.optics is not None else "unattached"
        return f"AtmospherePhase[atmosphere={name!r}]"


def is_atmosphere_phase(obj) -> bool:
    """Whether ``obj`` is an ``atmosphere_phase`` instance (of any variant)."""
    return is_instance(obj, "AtmospherePhase")


def phase_class():
    """The ``atmosphere_phase`` class of the current Mitsuba variant."""
    return variant_class(AtmospherePhaseMethods, "AtmospherePhase", "PhaseFunction")


def __getattr__(name):
    if name == "AtmospherePhase":
        return phase_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def register():
    """Register ``atmosphere_phase`` for the current variant (Mitsuba 3.9.1 calls the hook
    ``mi.register_phase``; older releases ``register_phasefunction``)."""
    cls = phase_class()
    mi.register_phase("atmosphere_phase", lambda props: cls(props))
