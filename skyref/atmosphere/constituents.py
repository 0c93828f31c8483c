"""Constituents of the atmosphere: what is in the air, where, and how it interacts with light.

A constituent's local coefficients are ``coefficient(lambda) * profile.density(h)``: the
methods below return the coefficient at relative density 1, in m^-1, with the constituent's
``density_scale`` (or column amount) already applied.

- :class:`Rayleigh`: air molecules, scattering only, Rayleigh phase function.
- :class:`Aerosol`: Mie scattering by particles, extinction from Angstrom's law or a table,
  single-scattering albedo, Cornette–Shanks (default), Henyey–Greenstein or tabulated phase.
- :class:`Absorber`: an absorbing gas such as ozone (cross-section x number density).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from skyref.atmosphere.phase import (CornetteShanks, PhaseFunction, RayleighPhase,
                                     phase_from_dict)
from skyref.atmosphere.profiles import (DensityProfile, ExponentialProfile,
                                        PiecewiseLinearProfile, profile_from_dict)
from skyref.atmosphere.spectra import (DOBSON_UNIT_PER_M2, PowerLawSpectrum, Spectrum,
                                       as_spectrum, ozone_cross_section, power_law)
from skyref.validation import check_choice, check_number
from skyref.errors import ParameterError

__all__ = ["RAYLEIGH_SCATTERING_AT_1UM", "MAX_DENSITY_SCALE", "Constituent", "Rayleigh", "Aerosol",
           "angstrom_extinction", "Absorber", "CONSTITUENT_TYPES", "constituent_from_dict"]

#: Rayleigh scattering coefficient of sea-level air at 1 um (Bruneton 2017), m^-1; it scales
#: as lambda^-4.
RAYLEIGH_SCATTERING_AT_1UM = 1.24062e-6

#: Largest density scale accepted (1000x: "very thick" stress tests).
MAX_DENSITY_SCALE = 1.0e3


def _check_name(name):
    if not isinstance(name, str) or not name.isidentifier():
        raise ParameterError("name", name, "a Python identifier, e.g. 'aerosol'", "invalid name")


class Constituent:
    """Base class: a density profile and coefficients at relative density 1."""

    name: str
    profile: DensityProfile
    kind: str = ""

    def scattering_coefficient(self, wavelengths_nm) -> np.ndarray:
        """Scattering coefficient at relative density 1, m^-1."""
        return np.zeros_like(np.asarray(wavelengths_nm, dtype=np.float64))

    def absorption_coefficient(self, wavelengths_nm) -> np.ndarray:
        """Absorption coefficient at relative density 1, m^-1."""
        return np.zeros_like(np.asarray(wavelengths_nm, dtype=np.float64))

    def extinction_coefficient(self, wavelengths_nm) -> np.ndarray:
        return self.scattering_coefficient(wavelengths_nm) + self.absorption_coefficient(wavelengths_nm)

    #: The phase function of what it scatters; None for a pure absorber.
    phase: PhaseFunction | None = None

    def to_dict(self) -> dict:
        raise NotImplementedError


@dataclass(frozen=True)
class Rayleigh(Constituent):
    """Molecular (Rayleigh) scattering; no absorption. ``scattering`` is the sea-level
    coefficient spectrum (default 1.24062e-6 m^-1 (lambda / 1 um)^-4); ``density_scale``
    multiplies it (surface pressure relative to the standard one). ``depolarization`` is the
    molecules' depolarization factor (:class:`~skyref.atmosphere.phase.RayleighPhase`; 0, the
    presets' published value, or e.g. 0.0279 for air): it shapes the phase function, not the
    coefficient, which is given as a whole."""

    name: str = "rayleigh"
    profile: DensityProfile = ExponentialProfile(8000.0)
    scattering: Spectrum = PowerLawSpectrum(RAYLEIGH_SCATTERING_AT_1UM, -4.0)
    density_scale: float = 1.0
    depolarization: float = 0.0
    phase: PhaseFunction = field(default=RayleighPhase(), init=False)
    kind = "rayleigh"

    def __post_init__(self):
        _check_name(self.name)
        object.__setattr__(self, "scattering", as_spectrum(self.scattering))
        check_number("rayleigh.depolarization", self.depolarization, 0.0, 1.0, hi_open=True)
        object.__setattr__(self, "phase", RayleighPhase(self.depolarization))
        check_number("rayleigh.density_scale", self.density_scale, 0.0, MAX_DENSITY_SCALE)

    def scattering_coefficient(self, wavelengths_nm):
        return self.density_scale * self.scattering(wavelengths_nm)

    def to_dict(self):
        return {"kind": self.kind, "name": self.name, "profile": self.profile.to_dict(),
                "scattering": self.scattering.to_dict(), "density_scale": self.density_scale,
                **({"depolarization": self.depolarization} if self.depolarization else {})}


@dataclass(frozen=True)
class Aerosol(Constituent):
    """Aerosol particles (Mie scattering).

    Extinction either follows Angstrom's law, so that the vertical aerosol optical depth of the
    whole column is ``angstrom_beta * (lambda / 1 um)^(-angstrom_alpha)`` (the coefficient at
    relative density 1 is that divided by the profile's column, i.e. beta/H * lambda^-alpha for an
    exponential profile, as in Bruneton 2017), or is given as a tabulated ``extinction`` spectrum
    (m^-1 at relative density 1). ``single_scattering_albedo`` splits it into scattering and
    absorption. ``phase`` defaults to Cornette–Shanks with g = 0.8 (its g is not the asymmetry
    parameter).
    """

    name: str = "aerosol"
    profile: DensityProfile = ExponentialProfile(1200.0)
    angstrom_alpha: float | None = 0.0
    angstrom_beta: float | None = 5.328e-3
    extinction: Spectrum | None = None
    single_scattering_albedo: float = 0.9
    phase: PhaseFunction = CornetteShanks(0.8)
    density_scale: float = 1.0
    kind = "aerosol"

    def __post_init__(self):
        _check_name(self.name)
        angstrom = self.angstrom_alpha is not None or self.angstrom_beta is not None
        if angstrom == (self.extinction is not None):
            raise ParameterError("aerosol.extinction", self.extinction,
                                 "either angstrom_alpha and angstrom_beta, or a tabulated extinction",
                                 "give exactly one of the two")
        if angstrom:
            check_number("aerosol.angstrom_alpha", self.angstrom_alpha, -1.0, 4.0)
            check_number("aerosol.angstrom_beta", self.angstrom_beta, 0.0, 100.0)
            if not math.isfinite(self.profile.column()):
                raise ParameterError("aerosol.profile", self.profile.to_dict(),
                                     "a profile with a finite column", "Angstrom beta needs a finite column")
        else:
            object.__setattr__(self, "extinction", as_spectrum(self.extinction))
        check_number("aerosol.single_scattering_albedo", self.single_scattering_albedo, 0.0, 1.0)
        check_number("aerosol.density_scale", self.density_scale, 0.0, MAX_DENSITY_SCALE)
        if not isinstance(self.phase, PhaseFunction):
            raise ParameterError("aerosol.phase", self.phase, "a PhaseFunction", "wrong type")

    def extinction_coefficient(self, wavelengths_nm):
        wl = np.asarray(wavelengths_nm, dtype=np.float64)
        if self.extinction is not None:
            return self.density_scale * self.extinction(wl)
        return self.density_scale * angstrom_extinction(wl, self.angstrom_alpha, self.angstrom_beta,
                                                        self.profile.column())

    def scattering_coefficient(self, wavelengths_nm):
        return self.single_scattering_albedo * self.extinction_coefficient(wavelengths_nm)

    def absorption_coefficient(self, wavelengths_nm):
        return (1.0 - self.single_scattering_albedo) * self.extinction_coefficient(wavelengths_nm)

    def optical_depth(self, wavelengths_nm) -> np.ndarray:
        """Vertical aerosol optical depth of the whole column."""
        return self.extinction_coefficient(wavelengths_nm) * self.profile.column()

    def to_dict(self):
        data = {"kind": self.kind, "name": self.name, "profile": self.profile.to_dict(),
                "single_scattering_albedo": self.single_scattering_albedo,
                "phase": self.phase.to_dict(), "density_scale": self.density_scale}
        if self.extinction is not None:
            data["extinction"] = self.extinction.to_dict()
        else:
            data.update(angstrom_alpha=self.angstrom_alpha, angstrom_beta=self.angstrom_beta)
        return data


def angstrom_extinction(wavelength_nm, alpha, beta, column_m, xp=np):
    """Extinction coefficient at relative density 1 (m^-1) whose vertical optical depth over a
    column of ``column_m`` metres is Angstrom's beta (lambda / 1 um)^-alpha."""
    return power_law(wavelength_nm, beta, -alpha, 1000.0, xp) * (1.0 / column_m)


@dataclass(frozen=True)
class Absorber(Constituent):
    """An absorbing gas: absorption = cross_section(lambda) [m^2] x number density [m^-3].

    The amount is either ``column_du``, the vertical column in Dobson units (the number density
    at relative density 1 is then column / profile column), or ``number_density_per_m3`` at
    relative density 1. Defaults: ozone, 300 DU, Bruneton 2017's tent 10–25–40 km.
    """

    name: str = "ozone"
    profile: DensityProfile = PiecewiseLinearProfile.tent(10_000.0, 25_000.0, 40_000.0)
    cross_section: Spectrum = field(default_factory=ozone_cross_section)
    column_du: float | None = 300.0
    number_density_per_m3: float | None = None
    kind = "absorber"

    def __post_init__(self):
        _check_name(self.name)
        object.__setattr__(self, "cross_section", as_spectrum(self.cross_section))
        if (self.column_du is None) == (self.number_density_per_m3 is None):
            raise ParameterError(f"{self.name}.column_du", self.column_du,
                                 "either column_du or number_density_per_m3", "give exactly one")
        if self.column_du is not None:
            check_number(f"{self.name}.column_du", self.column_du, 0.0, 1.0e5)
            if not math.isfinite(self.profile.column()) or self.profile.column() <= 0:
                raise ParameterError(f"{self.name}.profile", self.profile.to_dict(),
                                     "a profile with a finite, positive column", "cannot hold a column amount")
        else:
            check_number(f"{self.name}.number_density_per_m3", self.number_density_per_m3, 0.0, 1.0e30)

    @property
    def reference_number_density(self) -> float:
        """Number density at relative density 1, m^-3."""
        if self.column_du is not None:
            return self.column_du * DOBSON_UNIT_PER_M2 / self.profile.column()
        return self.number_density_per_m3

    def absorption_coefficient(self, wavelengths_nm):
        return self.reference_number_density * self.cross_section(wavelengths_nm)

    def to_dict(self):
        cross_section = ("ozone_233K" if self.cross_section == ozone_cross_section()
                         else self.cross_section.to_dict())
        data = {"kind": self.kind, "name": self.name, "profile": self.profile.to_dict(),
                "cross_section": cross_section}
        if self.column_du is not None:
            data["column_du"] = self.column_du
        else:
            data["number_density_per_m3"] = self.number_density_per_m3
        return data


CONSTITUENT_TYPES = {cls.kind: cls for cls in (Rayleigh, Aerosol, Absorber)}


def constituent_from_dict(data: dict) -> Constituent:
    """Inverse of ``Constituent.to_dict``; unknown keys are rejected by name."""
    fields = dict(data)
    kind = check_choice("constituent.kind", fields.pop("kind", None), tuple(CONSTITUENT_TYPES))
    if "profile" in fields:
        fields["profile"] = profile_from_dict(fields["profile"])
    if "phase" in fields:
        fields["phase"] = phase_from_dict(fields["phase"])
    if fields.get("cross_section") == "ozone_233K":
        fields["cross_section"] = ozone_cross_section()
    cls = CONSTITUENT_TYPES[kind]
    # to_dict() omits the alternative that is not used (TOML has no null), whose default is not
    # None: a tabulated aerosol has no Angstrom parameters, an absorber given by number density
    # no column amount. Without this, neither could be read back.
    if cls is Aerosol and "extinction" in fields:
        fields.setdefault("angstrom_alpha", None)
        fields.setdefault("angstrom_beta", None)
    if cls is Absorber and "number_density_per_m3" in fields:
        fields.setdefault("column_du", None)
    allowed = {f for f in cls.__dataclass_fields__ if cls.__dataclass_fields__[f].init}
    for key in fields:
        if key not in allowed:
            raise ParameterError(f"{fields.get('name', kind)}.{key}", fields[key],
                                 "one of " + ", ".join(sorted(allowed)), "unknown parameter")
    return cls(**fields)
