"""The physical model of a planetary atmosphere (NumPy only: no Mitsuba, no JAX)."""

from skyref.atmosphere.constituents import (Absorber, Aerosol, Constituent, Rayleigh,
                                            angstrom_extinction)
from skyref.atmosphere.model import Atmosphere
from skyref.atmosphere.phase import (CornetteShanks, HenyeyGreenstein, PhaseFunction,
                                     RayleighPhase, TabulatedPhase, cornette_shanks_phase,
                                     henyey_greenstein_phase, rayleigh_phase)
from skyref.atmosphere.presets import (PRESETS, bruneton2016_measured, bruneton2017,
                                       from_turbidity, hillaire2020, preset, rayleigh_only,
                                       turbidity)
from skyref.atmosphere.profiles import (DensityProfile, ExponentialProfile,
                                        PiecewiseLinearProfile, TabulatedProfile)
from skyref.atmosphere.spectra import (DOBSON_UNIT_PER_M2, RGB_WAVELENGTHS_NM, ConstantSpectrum,
                                       PowerLawSpectrum, Spectrum, TabulatedSpectrum,
                                       ozone_cross_section, solar_irradiance, wavelength_grid)

__all__ = ["Absorber", "Aerosol", "Constituent", "Rayleigh", "angstrom_extinction", "Atmosphere", "CornetteShanks",
           "HenyeyGreenstein", "PhaseFunction", "RayleighPhase", "TabulatedPhase", "cornette_shanks_phase",
           "henyey_greenstein_phase", "rayleigh_phase", "PRESETS", "bruneton2016_measured", "bruneton2017",
           "from_turbidity", "hillaire2020", "preset", "rayleigh_only", "turbidity", "DensityProfile",
           "ExponentialProfile", "PiecewiseLinearProfile", "TabulatedProfile", "DOBSON_UNIT_PER_M2",
           "RGB_WAVELENGTHS_NM", "ConstantSpectrum", "PowerLawSpectrum", "Spectrum", "TabulatedSpectrum",
           "ozone_cross_section", "solar_irradiance", "wavelength_grid"]
