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

References
----------
L. Hosek, A. Wilkie, "An Analytic Model for Full Spectral Sky-Dome Radiance", ACM TOG 31(4), 2012.
"""

from __future__ import annotations

import numpy as np

from skyref.analytic.base import AnalyticModel
from skyref.analytic.hosek import BAND_CENTRES_NM, TURBIDITIES, published_table
from skyref.atmosphere import turbidity as atmosphere_turbidity
from skyref.validation import check_number
from skyref.errors import ParameterError

__all__ = ["ALBEDO_WAVELENGTH_NM", "MAX_OBSERVER_ALTITUDE_M", "HosekWilkie2012"]

#: Wavelength at which the atmosphere's ground albedo is read, nm.
ALBEDO_WAVELENGTH_NM = 550.0
#: Highest observer accepted, m.
MAX_OBSERVER_ALTITUDE_M = 1000.0


class HosekWilkie2012(AnalyticModel):
    """The Hosek–Wilkie sky of ``table`` (a spectral :class:`~skyref.analytic.hosek.CoefficientTable`;
    default: the published 1.4a coefficients). ``turbidity``: the value the model uses; None
    takes the atmosphere's, which must then lie in [1, 10]."""

    name = "hosek2012"

    def __init__(self, atmosphere, wavelengths_nm="rgb", table=None, turbidity: float | None = None):
        super().__init__(atmosphere, wavelengths_nm)
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
        self.options = {"turbidity": round(self.turbidity, 4), "albedo": self.albedo, "source": self.table.source}

    def _check_validity(self, altitude_m: float, mu_s: float):
        check_number("observer_altitude_m", altitude_m, 0.0, MAX_OBSERVER_ALTITUDE_M)
        check_number("sun zenith angle (deg)", float(np.degrees(np.arccos(mu_s))), 0.0, 90.0)

    def _radiance(self, r: float, mu, mu_s: float, nu) -> np.ndarray:
        theta = np.arccos(np.clip(mu, -1.0, 1.0))
        gamma = np.arccos(np.clip(nu, -1.0, 1.0))
        wavelengths = np.minimum(self.wavelengths_nm, BAND_CENTRES_NM[-1])
        return self.table.spectral_radiance(wavelengths, theta, gamma, float(np.arcsin(np.clip(mu_s, 0.0, 1.0))),
                                            self.turbidity, self.albedo)
