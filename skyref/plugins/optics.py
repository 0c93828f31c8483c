"""The atmosphere's optics on Dr.Jit arrays: coefficients, majorants and phase functions.

:class:`AtmosphereOptics` turns a :class:`skyref.atmosphere.Atmosphere` into what a kernel
needs, for the wavelengths of a fixed grid (the renderer's wavelength list; RGB = 680/550/440
nm). It is shared by the ``atmosphere`` integrator, medium and phase plugins, so all of them
see the same numbers as the NumPy model, and it holds the differentiable parameters:

=================================  =========================================================
``<name>.density_scale``           multiplies a constituent's coefficients (Rayleigh: pressure)
``<aerosol>.angstrom_alpha/beta``  Angstrom exponent and turbidity coefficient (aerosol)
``<aerosol>.single_scattering_albedo``
``<aerosol>.g``                    Cornette–Shanks (or Henyey–Greenstein) parameter
``<absorber>.column_du``           column amount of an absorber, Dobson units
``ground_albedo``                  Lambertian albedo (a scalar, or one value per grid wavelength)
=================================  =========================================================

Only constituents that the atmosphere contains produce kernel code: an atmosphere without
aerosol has no Mie branch, one without ozone no absorption term.

Coefficients are "at relative density 1" (m^-1) per channel; a channel is an index into the
wavelength grid, and a path carries K channels as an ``ArrayXf``.
"""

from __future__ import annotations

import json
import math

import drjit as dr
import mitsuba as mi
import numpy as np

from skyref.atmosphere import Atmosphere, preset
from skyref.atmosphere.constituents import angstrom_extinction
from skyref.atmosphere.spectra import DOBSON_UNIT_PER_M2, ConstantSpectrum
from skyref.plugins.drjit_namespace import channel_mean, xp

__all__ = ["atmosphere_from_property", "ConstituentOptics", "AtmosphereOptics", "direction_with_cosine", "PathChannels"]


def atmosphere_from_property(value) -> "Atmosphere":
    """An Atmosphere from a preset name, its JSON, an Atmosphere or a dict."""
    if isinstance(value, Atmosphere):
        return value
    if isinstance(value, dict):
        return Atmosphere.from_dict(value)
    text = str(value)
    return Atmosphere.from_dict(json.loads(text)) if text.lstrip().startswith("{") else preset(text)


def _opaque(value) -> mi.Float:
    """A differentiable kernel parameter (opaque: changing it does not recompile kernels)."""
    return dr.opaque(mi.Float, value) if np.ndim(value) == 0 else mi.Float(np.asarray(value, np.float32))


class ConstituentOptics:
    """One constituent on the grid. ``params`` maps short names to Dr.Jit values."""

    def __init__(self, constituent, wavelengths_nm: np.ndarray):
        self.model = constituent
        self.name = constituent.name
        self.kind = constituent.kind
        self.profile = constituent.profile
        self.wavelengths = mi.Float(wavelengths_nm.astype(np.float32))
        self.params = {}
        self.tables = {}
        if self.kind == "rayleigh":
            self.params["density_scale"] = _opaque(constituent.density_scale)
            self.tables["scattering"] = mi.Float(constituent.scattering(wavelengths_nm).astype(np.float32))
        elif self.kind == "aerosol":
            self.params["density_scale"] = _opaque(constituent.density_scale)
            self.params["single_scattering_albedo"] = _opaque(constituent.single_scattering_albedo)
            if constituent.extinction is None:
                self.params["angstrom_alpha"] = _opaque(constituent.angstrom_alpha)
                self.params["angstrom_beta"] = _opaque(constituent.angstrom_beta)
                self.column_m = constituent.profile.column()
            else:
                self.tables["extinction"] = mi.Float(constituent.extinction(wavelengths_nm).astype(np.float32))
            if hasattr(constituent.phase, "g"):          # a differentiable phase parameter
                self.params["g"] = _opaque(constituent.phase.g)
        elif self.kind == "absorber":
            self.tables["cross_section_per_du"] = mi.Float(
                (constituent.cross_section(wavelengths_nm) * DOBSON_UNIT_PER_M2
                 / constituent.profile.column()).astype(np.float32) if constituent.column_du is not None
                else (constituent.cross_section(wavelengths_nm) * constituent.number_density_per_m3).astype(np.float32))
            if constituent.column_du is not None:
                self.params["column_du"] = _opaque(constituent.column_du)
        if hasattr(constituent.phase, "cosines"):       # a tabulated phase function's device tables
            self.tables["phase_cosines"] = mi.Float(np.asarray(constituent.phase.cosines, np.float32))
            self.tables["phase_values"] = mi.Float(np.asarray(constituent.phase.values, np.float32))
        for element in ("p12", "p33", "p34"):              # a tabulated phase matrix's other elements
            if hasattr(constituent.phase, element):
                self.tables[f"phase_{element}"] = mi.Float(np.asarray(getattr(constituent.phase, element), np.float32))

    # --- coefficients at relative density 1, per channel ----------------------------------------

    def coefficients(self, index: mi.UInt32):
        """(scattering, absorption) coefficients in m^-1 at relative density 1 for grid index
        ``index``; ``None`` stands for an identically zero term."""
        p = self.params
        if self.kind == "rayleigh":
            return p["density_scale"] * dr.gather(mi.Float, self.tables["scattering"], index), None
        if self.kind == "aerosol":
            if "extinction" in self.tables:
                extinction = dr.gather(mi.Float, self.tables["extinction"], index)
            else:
                wl = dr.gather(mi.Float, self.wavelengths, index)
                extinction = angstrom_extinction(wl, p["angstrom_alpha"], p["angstrom_beta"], self.column_m, xp)
            extinction = p["density_scale"] * extinction
            albedo = p["single_scattering_albedo"]
            return albedo * extinction, (1.0 - albedo) * extinction
        amount = p.get("column_du", 1.0)
        return None, amount * dr.gather(mi.Float, self.tables["cross_section_per_du"], index)

    def density(self, altitude):
        return self.profile.density(altitude, xp)

    # --- phase function -------------------------------------------------------------------

    def phase(self, mu):
        """p(mu), sr^-1, mu = cosine between incident and scattered propagation directions."""
        return self.model.phase.evaluate(mu, xp, **self.phase_parameters())

    def phase_matrix(self, mu):
        """The phase matrix's elements (P11, P12, P22, P33, P34, P44), sr^-1
        (:meth:`skyref.atmosphere.phase.PhaseFunction.matrix`)."""
        elements = {name: self.tables[f"phase_{name}"] for name in ("p12", "p33", "p34")
                    if f"phase_{name}" in self.tables}
        return self.model.phase.matrix(mu, xp, **self.phase_parameters(), **elements)

    def sample_cosine(self, u):
        """Sample mu from this component's sampling density; return (mu, pdf(mu) in sr^-1)."""
        mu = self.model.phase.sample_cosine(u, xp, **self.sampling_parameters())
        return mu, self.sampling_pdf(mu)

    def sampling_pdf(self, mu):
        return self.model.phase.pdf(mu, xp, **self.sampling_parameters())

    def phase_parameters(self) -> dict:
        """The phase function's parameters as device values: a differentiable ``g``, or a
        tabulated function's tables; none for Rayleigh."""
        if "g" in self.params:
            return {"g": self.params["g"]}
        if "phase_cosines" in self.tables:
            return {"cosines": self.tables["phase_cosines"], "values": self.tables["phase_values"]}
        return {}

    def sampling_parameters(self) -> dict:
        """The sampling density's parameters: ``g`` detached (sampling decisions carry no
        derivatives); a tabulated function samples with its own fixed ``sampling_g``."""
        return {"g": dr.detach(self.params["g"])} if "g" in self.params else {}


class AtmosphereOptics:
    """All constituents plus the ground albedo on a wavelength grid (see module docstring)."""

    def __init__(self, atmosphere, wavelengths_nm):
        self.atmosphere = atmosphere
        self.wavelengths_nm = np.asarray(atmosphere.check_wavelengths(wavelengths_nm), dtype=np.float64)
        self.components = [ConstituentOptics(c, self.wavelengths_nm) for c in atmosphere.constituents]
        albedo = atmosphere.ground_albedo
        if isinstance(albedo, ConstantSpectrum):
            self.ground_albedo = _opaque(albedo.value)
        else:
            self.ground_albedo = mi.Float(albedo(self.wavelengths_nm).astype(np.float32))

    # --- parameters (mi.traverse) ---------------------------------------------------------------

    def parameters(self) -> dict:
        """name -> Dr.Jit value of every differentiable parameter."""
        params = {"ground_albedo": self.ground_albedo}
        for c in self.components:
            for key, value in c.params.items():
                params[f"{c.name}.{key}"] = value
        return params

    def set_parameter(self, name: str, value):
        if name == "ground_albedo":
            self.ground_albedo = value
            return
        constituent, key = name.split(".", 1)
        for c in self.components:
            if c.name == constituent and key in c.params:
                c.params[key] = value
                return
        raise KeyError(name)

    # --- per-path channel data ------------------------------------------------------------------

    def channel_coefficients(self, indices) -> "PathChannels":
        """Everything a path needs for its channels (list of UInt32 grid indices)."""
        coefficients = []
        for c in self.components:
            per_channel = [c.coefficients(i) for i in indices]
            s = None if per_channel[0][0] is None else mi.ArrayXf([x[0] for x in per_channel])
            a = None if per_channel[0][1] is None else mi.ArrayXf([x[1] for x in per_channel])
            coefficients.append((s, a))
        per_wavelength = dr.width(self.ground_albedo) > 1
        albedo = mi.ArrayXf([dr.gather(mi.Float, self.ground_albedo, i if per_wavelength else 0 * i)
                             for i in indices])
        return PathChannels(len(indices), coefficients, albedo)

    def majorant(self, channels: "PathChannels", h_low, h_high):
        """A grey majorant of the extinction over altitudes [h_low, h_high], m^-1: the sum over
        constituents of (largest coefficient over the channels) x (largest density in range)."""
        total = mi.Float(0.0)
        for c, bound in zip(self.components, channels.bounds):
            total += bound * dr.detach(c.profile.max_density(h_low, h_high, xp))
        return total

    def local(self, channels: "PathChannels", altitude):
        """Local coefficients at ``altitude``, per channel, m^-1: (sigma_s of each component
        (ArrayXf, or None for absorbers), total sigma_s, total sigma_t)."""
        sigma_s_parts = []
        sigma_s = channels.zeros()
        sigma_t = channels.zeros()
        for c, (s, a) in zip(self.components, channels.coefficients):
            rho = c.density(altitude)
            part_s = None if s is None else s * rho
            sigma_s_parts.append(part_s)
            if part_s is not None:
                sigma_s = sigma_s + part_s
                sigma_t = sigma_t + part_s
            if a is not None:
                sigma_t = sigma_t + a * rho
        return sigma_s_parts, sigma_s, sigma_t

    def component_phases(self, mu):
        """Each constituent's phase function p_i(mu), sr^-1 (None for an absorber)."""
        return [None if c.model.phase is None else c.phase(mu) for c in self.components]

    def volume_scattering_function(self, sigma_s_parts, phases):
        """beta = sum_i sigma_s,i p_i per channel, m^-1 sr^-1: the light scattered per unit
        length and solid angle, from the local scattering coefficients (:meth:`local`) and the
        constituents' ``phases`` (:meth:`component_phases`). A path's weight multiplies it by
        the transmittance over the sampling densities of the point and direction; no division by
        sigma_s, which :meth:`phase` needs."""
        return sum((part * p for part, p in zip(sigma_s_parts, phases) if part is not None), 0.0)

    def phase(self, sigma_s_parts, sigma_s, mu):
        """The local mixture phase function per channel: sum_i sigma_s,i p_i(mu) / sigma_s."""
        return self.volume_scattering_function(sigma_s_parts, self.component_phases(mu)) / dr.maximum(sigma_s, 1e-30)

    def phase_matrix(self, sigma_s_parts, sigma_s, mu):
        """The local mixture's phase matrix per channel: (p, reduced), p as :meth:`phase` and
        ``reduced`` the elements (P12, P22, P33, P34, P44) of the mixture divided by its P11
        (ArrayXf each; :mod:`skyref.plugins.polarization`)."""
        totals = [0.0 * sigma_s for _ in range(6)]
        for c, part in zip(self.components, sigma_s_parts):
            if part is not None:
                totals = [total + part * element for total, element in zip(totals, c.phase_matrix(mu))]
        inverse = dr.rcp(dr.maximum(totals[0], 1e-30))
        return totals[0] / dr.maximum(sigma_s, 1e-30), [total * inverse for total in totals[1:]]

    def _sampling_mixture(self, sigma_s_parts, sigma_s):
        """The scattering components and their selection probabilities P_i = mean over
        channels of sigma_s,i / sigma_s (detached: sampling decisions carry no derivatives)."""
        comps = [c for c, part in zip(self.components, sigma_s_parts) if part is not None]
        parts = [part for part in sigma_s_parts if part is not None]
        if len(comps) < 2:
            return comps, [mi.Float(1.0)] * len(comps)
        inv = dr.rcp(dr.maximum(dr.detach(sigma_s), 1e-30))
        return comps, [channel_mean(dr.detach(part) * inv) for part in parts]

    def share_without_forward_peak(self, sigma_s_parts, sigma_s):
        """The share of the local scattering (mean over channels, detached, as the probabilities
        of :meth:`sample_phase`) by constituents whose phase function has no forward peak
        (``PhaseFunction.has_forward_peak``: Rayleigh's has none)."""
        comps, probabilities = self._sampling_mixture(sigma_s_parts, sigma_s)
        return sum((p for c, p in zip(comps, probabilities) if not c.model.phase.has_forward_peak), mi.Float(0.0))

    def phase_pdf(self, sigma_s_parts, sigma_s, mu):
        """Density (sr^-1) with which :meth:`sample_phase` produces the cosine ``mu``: the
        mixture sum_i P_i pdf_i(mu)."""
        comps, probabilities = self._sampling_mixture(sigma_s_parts, sigma_s)
        pdf = mi.Float(0.0) if comps else mi.Float(1.0)
        for c, prob in zip(comps, probabilities):
            pdf += prob * c.sampling_pdf(mu)
        return pdf

    def sample_phase(self, sigma_s_parts, sigma_s, u_component, u_mu):
        """Sample a scattering-angle cosine from the mixture of the components' sampling
        densities (component i with probability P_i, see :meth:`phase_pdf`). Returns (mu, pdf)
        — one-sample MIS, so the weight phase / pdf stays bounded whichever component
        produced mu."""
        comps, probabilities = self._sampling_mixture(sigma_s_parts, sigma_s)
        if not comps:  # nothing scatters: never called for a real path, any valid direction will do
            return mi.Float(1.0), mi.Float(1.0)
        # Walk the cumulative probabilities; the last component takes whatever rounding left.
        mu = comps[-1].sample_cosine(u_mu)[0]
        cumulative = mi.Float(0.0)
        for c, prob in zip(comps[:-1], probabilities[:-1]):
            chosen = (u_component >= cumulative) & (u_component < cumulative + prob)
            mu = dr.select(chosen, c.sample_cosine(u_mu)[0], mu)
            cumulative = cumulative + prob
        return mu, self.phase_pdf(sigma_s_parts, sigma_s, mu)


def direction_with_cosine(d, mu, u_phi):
    """A unit vector at angle acos(mu) from ``d``, at azimuth 2 pi u_phi around it."""
    frame = mi.Frame3f(d)
    sin_theta = dr.safe_sqrt(1.0 - mu * mu)
    sin_phi, cos_phi = dr.sincos(2.0 * math.pi * u_phi)
    return frame.to_world(mi.Vector3f(sin_theta * cos_phi, sin_theta * sin_phi, mu))


class PathChannels:
    """A path's K channels: per component (scattering, absorption) coefficients at relative
    density 1 as ArrayXf (None for a zero term), the ground albedo, and per component the largest
    and smallest extinction over the channels (detached; for majorants and sampling proxies)."""

    def __init__(self, count, coefficients, albedo):
        self.count = count
        self.coefficients = coefficients
        self.albedo = albedo
        #: extinction at relative density 1 per component (ArrayXf, or None for a zero term)
        self.extinction = [s if a is None else (a if s is None else s + a) for s, a in coefficients]
        self.bounds = [dr.detach(dr.max(k, axis=0)) for k in self.extinction]
        #: the smallest extinction over the channels per component (detached; None for a zero term)
        self.least = [None if k is None else dr.detach(dr.min(k, axis=0)) for k in self.extinction]

    def zeros(self, components: int = 1):
        """Zeros per channel, ``components`` x K values (e.g. the 4 Stokes components)."""
        return mi.ArrayXf([mi.Float(0.0)] * (components * self.count))

    def optical_depth(self, unit_depths):
        """Optical depth per channel from per-component optical depths at relative density 1
        (m): sum_c k_c tau_c."""
        total = self.zeros()
        for k, tau in zip(self.extinction, unit_depths):
            if k is not None:
                total = total + k * tau
        return total

    def grey(self, throughput):
        """Grey coefficients per component, the channel mean weighted by the path throughput
        (detached; for sampling decisions): ([scattering or None], [extinction or None]) in m^-1
        at relative density 1, and the grey ground albedo."""
        w = dr.detach(throughput)
        inv = dr.rcp(dr.maximum(dr.sum(w, axis=0), 1e-30))

        def mean(k):
            return None if k is None else dr.detach(dr.sum(w * k, axis=0)) * inv

        return ([mean(s) for s, _ in self.coefficients], [mean(k) for k in self.extinction],
                dr.detach(dr.sum(w * self.albedo, axis=0)) * inv)
