"""Spectra: functions of wavelength (nm) used by the atmosphere and the sun.

Conventions: wavelengths in nm (vacuum); scattering/absorption coefficients in m^-1; cross
sections in m^2 per molecule; solar spectral irradiance in W m^-2 nm^-1 at the top of the
atmosphere, perpendicular to the beam.

References
----------
ASTM G173-03, "Standard Tables for Reference Solar Spectral Irradiances: Direct Normal and
Hemispherical on 37° Tilted Surface", ASTM International, 2003 (extraterrestrial column, via pvlib).

A. Serdyuchenko, V. Gorshelev, M. Weber, W. Chehade, J. P. Burrows, "High spectral resolution ozone
absorption cross-sections — Part 2: Temperature dependence", Atmos. Meas. Tech. 7, 2014.

E. Bruneton, "Precomputed Atmospheric Scattering: a New Implementation", 2017,
https://ebruneton.github.io/precomputed_atmospheric_scattering/ (the 10 nm bins).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from importlib import resources

import numpy as np

from skyref.validation import check_array, check_fields, check_number
from skyref.errors import ParameterError

__all__ = ["DOBSON_UNIT_PER_M2", "RGB_WAVELENGTHS_NM", "LUMINANCE_WAVELENGTHS_NM", "WAVELENGTH_LIMITS_NM",
           "MAX_GRID_WAVELENGTHS", "Spectrum", "ConstantSpectrum", "PowerLawSpectrum", "TabulatedSpectrum", "power_law",
           "as_spectrum", "ozone_cross_section", "solar_irradiance", "wavelength_grid"]

#: Molecules per m^2 in one Dobson unit (0.01 mm of pure gas at 273.15 K and 1 atm).
DOBSON_UNIT_PER_M2 = 2.6867e20

#: Wavelengths of skyref's "rgb" set, nm (Bruneton 2017, Hillaire 2020).
RGB_WAVELENGTHS_NM = (680.0, 550.0, 440.0)

#: Wavelengths of the "luminance" set: the span of the CIE 1931 2-degree y-bar that matters,
#: every 10 nm (integrate radiance * y-bar * 683 lm/W over it for luminance).
LUMINANCE_WAVELENGTHS_NM = tuple(float(w) for w in range(380, 790, 10))

#: Widest wavelength range any skyref spectrum is defined on (ASTM G173's), nm.
WAVELENGTH_LIMITS_NM = (280.0, 4000.0)

#: Most wavelengths a grid may describe (a scene renders at most ``skyref.scene.MAX_WAVELENGTHS``).
MAX_GRID_WAVELENGTHS = 100_000


class Spectrum:
    """A function of wavelength. ``spectrum(wavelengths_nm)`` returns a float64 array."""

    kind: str = ""
    #: Wavelength range (nm) on which the spectrum is defined.
    valid_range_nm: tuple = WAVELENGTH_LIMITS_NM

    def __call__(self, wavelengths_nm) -> np.ndarray:
        wl = np.asarray(wavelengths_nm, dtype=np.float64)
        lo, hi = self.valid_range_nm
        if np.any((wl < lo) | (wl > hi)):
            bad = float(wl[(wl < lo) | (wl > hi)].flat[0])
            raise ParameterError("wavelengths_nm", bad, f"[{lo:g}, {hi:g}] nm for {self.describe()}",
                                 "outside the spectrum's data")
        return self._evaluate(wl)

    def _evaluate(self, wl: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def describe(self) -> str:
        return self.kind

    def to_dict(self):
        raise NotImplementedError


@dataclass(frozen=True)
class ConstantSpectrum(Spectrum):
    """The same value at every wavelength."""

    value: float
    kind = "constant"

    def __post_init__(self):
        object.__setattr__(self, "value", check_number("value", self.value))

    def _evaluate(self, wl):
        return np.full_like(wl, self.value)

    def to_dict(self):
        return self.value


@dataclass(frozen=True)
class PowerLawSpectrum(Spectrum):
    """value * (lambda / reference_nm) ** exponent, e.g. Rayleigh's lambda^-4."""

    value: float
    exponent: float
    reference_nm: float = 1000.0
    kind = "power_law"

    def __post_init__(self):
        check_number("value", self.value, 0.0, math.inf)
        check_number("exponent", self.exponent, -10.0, 10.0)
        check_number("reference_nm", self.reference_nm, 0.0, math.inf, lo_open=True)

    def _evaluate(self, wl):
        return power_law(wl, self.value, self.exponent, self.reference_nm)

    def to_dict(self):
        return {"type": self.kind, "value": self.value, "exponent": self.exponent,
                "reference_nm": self.reference_nm}


@dataclass(frozen=True)
class TabulatedSpectrum(Spectrum):
    """Values at given wavelengths, interpolated linearly; an error outside the table."""

    wavelengths_nm: tuple
    values: tuple
    source: str = ""
    kind = "tabulated"

    def __post_init__(self):
        wl = check_array("wavelengths_nm", self.wavelengths_nm, *WAVELENGTH_LIMITS_NM,
                         min_length=1, increasing=True)
        values = check_array("values", self.values, min_length=1)
        if wl.size != values.size:
            raise ParameterError("values", list(self.values), f"{wl.size} numbers, one per wavelength",
                                 f"{values.size} values for {wl.size} wavelengths")
        object.__setattr__(self, "wavelengths_nm", tuple(float(x) for x in wl))
        object.__setattr__(self, "values", tuple(float(x) for x in values))
        object.__setattr__(self, "valid_range_nm", (wl[0], wl[-1]))

    def _evaluate(self, wl):
        return np.interp(wl, self.wavelengths_nm, self.values)

    def describe(self) -> str:
        return f"tabulated spectrum {self.source}".strip()

    def to_dict(self):
        return {"type": self.kind, "wavelengths_nm": list(self.wavelengths_nm),
                "values": list(self.values), "source": self.source}


def power_law(wavelength_nm, value, exponent, reference_nm=1000.0, xp=np):
    """value * (lambda / reference)^exponent, in any array namespace (parameters may be arrays
    of that namespace too, so gradients flow through them)."""
    return value * xp.exp(exponent * xp.log(wavelength_nm * (1.0 / reference_nm)))


def as_spectrum(value) -> Spectrum:
    """Accept a Spectrum, a number (constant) or a dict as written by ``Spectrum.to_dict``."""
    if isinstance(value, Spectrum):
        return value
    if isinstance(value, dict):
        fields = dict(value)
        kind = fields.pop("type", None)
        if kind in (PowerLawSpectrum.kind, TabulatedSpectrum.kind):
            check_fields("spectrum", fields, {s.kind: s for s in (PowerLawSpectrum, TabulatedSpectrum)}[kind])
        if kind == PowerLawSpectrum.kind:
            return PowerLawSpectrum(**fields)
        if kind == TabulatedSpectrum.kind:
            return TabulatedSpectrum(tuple(fields.pop("wavelengths_nm")), tuple(fields.pop("values")),
                                     **fields)
        raise ParameterError("spectrum.type", kind, "'power_law', 'tabulated' or a number",
                             "unknown spectrum type")
    return ConstantSpectrum(value)


@functools.lru_cache(maxsize=1)
def ozone_cross_section() -> TabulatedSpectrum:
    """Ozone absorption cross-section at 233 K (m^2/molecule), 360–830 nm, Serdyuchenko et al.
    2014 as binned by Bruneton 2017 (see data/SOURCES.md)."""
    path = resources.files("skyref.atmosphere") / "data" / "ozone_cross_section_233K_10nm.csv"
    table = np.loadtxt(str(path), delimiter=",", comments="#", skiprows=4)
    return TabulatedSpectrum(tuple(table[:, 0]), tuple(table[:, 1]),
                             source="Serdyuchenko 2014 O3 233 K (Bruneton 2017 bins)")


@functools.lru_cache(maxsize=1)
def _astm_g173_extraterrestrial() -> tuple[np.ndarray, np.ndarray]:
    import pvlib  # lazy: pvlib (with pandas) takes ~2 s to import and only the sun needs it

    table = pvlib.spectrum.get_reference_spectra(standard="ASTM G173-03")
    return table.index.to_numpy(dtype=np.float64), table["extraterrestrial"].to_numpy(dtype=np.float64)


def solar_irradiance(wavelengths_nm, bin_width_nm: float = 10.0) -> np.ndarray:
    """Extraterrestrial solar spectral irradiance, W m^-2 nm^-1, from ASTM G173-03 (via pvlib).

    Each value is the mean over [lambda - w/2, lambda + w/2] with w = ``bin_width_nm`` (10 nm by
    default, as Bruneton 2017 bins the same table), which smooths the Fraunhofer lines into what a
    renderer's wavelength bin sees. ``bin_width_nm=0`` interpolates the table point-wise.
    """
    wl = check_array("wavelengths_nm", np.atleast_1d(wavelengths_nm),
                     WAVELENGTH_LIMITS_NM[0] + bin_width_nm / 2, WAVELENGTH_LIMITS_NM[1] - bin_width_nm / 2)
    check_number("bin_width_nm", bin_width_nm, 0.0, 100.0)
    grid, values = _astm_g173_extraterrestrial()
    if bin_width_nm == 0.0:
        return np.interp(wl, grid, values)
    # Exact mean of the piecewise-linear table over each bin via its running integral.
    cumulative = np.concatenate(([0.0], np.cumsum(0.5 * (values[1:] + values[:-1]) * np.diff(grid))))

    def integral(x):
        i = np.clip(np.searchsorted(grid, x) - 1, 0, grid.size - 2)
        t = x - grid[i]
        slope = (values[i + 1] - values[i]) / (grid[i + 1] - grid[i])
        return cumulative[i] + values[i] * t + 0.5 * slope * t * t

    half = bin_width_nm / 2
    return (integral(wl + half) - integral(wl - half)) / bin_width_nm


def wavelength_grid(spec) -> np.ndarray:
    """Wavelengths (nm) from a spectral-sampling description.

    ``"rgb"`` -> 680, 550, 440 nm; ``"luminance"`` -> 380–780 nm every 10 nm; a list of
    numbers; or ``{"start_nm": a, "stop_nm": b, "step_nm": s}`` (b included).
    """
    if isinstance(spec, str):
        named = {"rgb": RGB_WAVELENGTHS_NM, "luminance": LUMINANCE_WAVELENGTHS_NM}
        if spec not in named:
            raise ParameterError("wavelengths", spec, "'rgb', 'luminance', a list of nm, or "
                                 "{start_nm, stop_nm, step_nm}", "unknown wavelength set")
        return np.asarray(named[spec])
    if isinstance(spec, dict):
        start = check_number("start_nm", spec.get("start_nm"), *WAVELENGTH_LIMITS_NM)
        stop = check_number("stop_nm", spec.get("stop_nm"), start, WAVELENGTH_LIMITS_NM[1])
        step = check_number("step_nm", spec.get("step_nm"), 0.0, math.inf, lo_open=True)
        count = math.floor((stop - start) / step + 1e-6) + 1
        if count > MAX_GRID_WAVELENGTHS:
            raise ParameterError("step_nm", step, f">= {(stop - start) / (MAX_GRID_WAVELENGTHS - 1):.3g} nm "
                                 f"(at most {MAX_GRID_WAVELENGTHS:,} wavelengths)", f"gives {count:,} wavelengths")
        return np.arange(start, stop + step * 1e-6, step)
    return check_array("wavelengths", spec, *WAVELENGTH_LIMITS_NM)
