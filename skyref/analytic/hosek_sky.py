"""The Hosek–Wilkie sky of a spectral coefficient table on a skyref atmosphere: the published
model (version 1.4a, :func:`skyref.analytic.hosek.published_table`) or a table fitted by
:mod:`skyref.fit`, behind the interface the audit calls (:class:`~skyref.analytic.base.AnalyticModel`).

How an atmosphere becomes the model's configuration:

- turbidity: :func:`skyref.atmosphere.turbidity` of the atmosphere (Linke/Preetham turbidity at
  550 nm), which must lie in the table's range [1, 10] unless ``turbidity=`` is given;
- ground albedo: the atmosphere's albedo at 550 nm (the model has one albedo for every band);
- solar elevation: 90 deg minus the sun's zenith angle, which must be 0..90 deg (the model's
  data stop at the horizon);
- observer: on the ground (the model's skies were seen from sea level); up to 1 km is accepted.

Wavelengths: the spectral table gives 11 bands centred at 320, 360, ..., 720 nm, interpolated
linearly between the centres as the reference code does. Above 720 nm (where CIE luminance
weights are below 1% of their peak) skyref holds the 720 nm value; below 320 nm it refuses.

The sun. The published radiances are those of skies lit by the authors' sun, whose disk radiance
L_HW at the band centres ships with the model (:func:`~skyref.analytic.hosek.published_solar_radiance`:
Preetham et al.'s solar data extended into the UV); skyref's ground truth is lit by ASTM G173 in
10 nm bins (:func:`skyref.atmosphere.spectra.solar_irradiance`, E). With
``solar_spectrum_correction=True`` the published sky is rescaled at each wavelength lambda to
skyref's sun, as in Bruneton 2017's evaluation of the model (the sky's radiance is proportional
to the sun's irradiance):

    L(lambda) = L_published(lambda) E(lambda) / (Omega L_HW(lambda)),

with L_HW interpolated linearly between band centres like the model, Omega the solid angle of
skyref's solar disk (:class:`~skyref.atmosphere.sun.SunDisk`, 6.87e-5 sr) and both spectra taken at the
wavelength the model is evaluated at (720 nm above it). The factor (:func:`solar_spectrum_factor`)
is 1.40 at 320 nm and 1.14 at 360 nm, within 0.95–1.05 at the band centres from 400 to 720 nm:
it matters in the UV. Between band centres it also carries the Fraunhofer structure of skyref's
spectrum, which the ground truth's skies have and the interpolated model lacks (0.90 at 430 nm).
It applies to the published table only: a table fitted to skyref's ground truth has skyref's sun.

References
----------
L. Hosek, A. Wilkie, "An Analytic Model for Full Spectral Sky-Dome Radiance", ACM TOG 31(4), 2012.

E. Bruneton, "A Qualitative and Quantitative Evaluation of 8 Clear Sky Models", IEEE TVCG 23(12),
2017 (the solar-spectrum correction).
"""

from __future__ import annotations

import numpy as np

from skyref.analytic.base import PER_VIEW_IN_LOOKUP, AnalyticModel
from skyref.analytic.hosek import BAND_CENTRES_NM, TURBIDITIES, published_solar_radiance, published_table
from skyref.atmosphere import turbidity as atmosphere_turbidity
from skyref.atmosphere.spectra import solar_irradiance
from skyref.atmosphere.sun import SunDisk
from skyref.sky_method import Operations
from skyref.validation import check_number
from skyref.errors import ParameterError

__all__ = ["ALBEDO_WAVELENGTH_NM", "MAX_OBSERVER_ALTITUDE_M", "HosekWilkie2012", "model_wavelengths",
           "solar_spectrum_factor"]

#: Wavelength at which the atmosphere's ground albedo is read, nm.
ALBEDO_WAVELENGTH_NM = 550.0
#: Highest observer accepted, m.
MAX_OBSERVER_ALTITUDE_M = 1000.0


def model_wavelengths(wavelengths_nm) -> np.ndarray:
    """The wavelengths (nm) at which the model is evaluated for ``wavelengths_nm``: the same,
    held at the last band centre (720 nm) above it."""
    return np.minimum(np.asarray(wavelengths_nm, dtype=np.float64), BAND_CENTRES_NM[-1])


def solar_spectrum_factor(wavelengths_nm) -> np.ndarray:
    """E / (Omega L_HW) at :func:`model_wavelengths` of ``wavelengths_nm`` (see the module's
    "The sun"): skyref's solar irradiance over the one the published model assumes."""
    wavelengths = model_wavelengths(wavelengths_nm)
    assumed = SunDisk().solid_angle_sr * np.interp(wavelengths, BAND_CENTRES_NM, published_solar_radiance())
    return solar_irradiance(wavelengths) / assumed


class HosekWilkie2012(AnalyticModel):
    """The Hosek–Wilkie sky of ``table`` (a spectral :class:`~skyref.analytic.hosek.CoefficientTable`;
    default: the published 1.4a coefficients). ``turbidity``: the value the model uses; None
    takes the atmosphere's, which must then lie in [1, 10]. ``solar_spectrum_correction``: rescale
    the published sky to skyref's solar spectrum (see the module's "The sun")."""

    name = "hosek2012"

    def __init__(self, atmosphere, wavelengths_nm="rgb", table=None, turbidity: float | None = None,
                 solar_spectrum_correction: bool = False):
        super().__init__(atmosphere, wavelengths_nm)
        if not isinstance(solar_spectrum_correction, bool):
            raise ParameterError("solar_spectrum_correction", solar_spectrum_correction, "true or false",
                                 "not a boolean")
        if solar_spectrum_correction and table is not None:
            raise ParameterError("solar_spectrum_correction", True, "false with a fitted table",
                                 "the correction is for the published coefficients; a table fitted to skyref's "
                                 "ground truth already has skyref's sun")
        self.table = published_table("spectral") if table is None else table
        if self.table.kind != "spectral":
            raise ParameterError("table", f"a {self.table.kind} table", "a spectral coefficient table",
                                 "the sky's spectrum needs the spectral bands")
        low = self.wavelengths_nm < BAND_CENTRES_NM[0]
        if low.any():
            raise ParameterError("wavelengths_nm", float(self.wavelengths_nm[low][0]),
                                 f">= {BAND_CENTRES_NM[0]:g} nm (the model's first band)", "outside the model's spectrum")
        lo, hi = TURBIDITIES[0], TURBIDITIES[-1]
        if turbidity is None:
            value = atmosphere_turbidity(atmosphere)
            if not lo <= value <= hi:
                raise ParameterError("turbidity", value, f"[{lo:g}, {hi:g}], the model's table",
                                     "the atmosphere's turbidity is outside it; pass turbidity= to choose the value "
                                     "the model uses")
            self.turbidity = value
        else:
            self.turbidity = check_number("turbidity", turbidity, lo, hi)
        self.albedo = float(atmosphere.ground_albedo([ALBEDO_WAVELENGTH_NM])[0])
        #: Factor per wavelength applied to the table's radiance (1: the table as it is).
        self.spectrum_factor = (solar_spectrum_factor(self.wavelengths_nm) if solar_spectrum_correction
                                else np.ones(self.wavelengths_nm.size))
        self.options = {"turbidity": round(self.turbidity, 4), "albedo": self.albedo, "source": self.table.source,
                        "solar_spectrum_correction": solar_spectrum_correction}

    def _check_validity(self, altitude_m: float, mu_s: float):
        check_number("observer_altitude_m", altitude_m, 0.0, MAX_OBSERVER_ALTITUDE_M)
        check_number("sun zenith angle (deg)", float(np.degrees(np.arccos(mu_s))), 0.0, 90.0)

    def operations(self) -> Operations:
        """Per direction: the shape function F of every band (the wavelengths interpolate
        between bands); per view: each band's 9 coefficients and overall radiance cooked from
        the 24 stored values around the configuration (2 albedos x 2 turbidities x 6 control
        points)."""
        bands = len(self.table.channels)
        return Operations(sky={"band shape-function (F) evaluations": bands},
                          per_view={"band configurations cooked from 24 stored values each": bands},
                          note=PER_VIEW_IN_LOOKUP)

    def _radiance(self, r: float, mu, mu_s: float, nu) -> np.ndarray:
        theta = np.arccos(np.clip(mu, -1.0, 1.0))
        gamma = np.arccos(np.clip(nu, -1.0, 1.0))
        radiance = self.table.spectral_radiance(model_wavelengths(self.wavelengths_nm), theta, gamma,
                                                float(np.arcsin(np.clip(mu_s, 0.0, 1.0))), self.turbidity, self.albedo)
        return radiance * self.spectrum_factor
