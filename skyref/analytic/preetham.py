"""Preetham, Shirley & Smits 1999, "A Practical Analytic Model for Daylight" (SIGGRAPH 99).

References below name the paper's parts by content: its skylight section and its appendix
("sunlight" attenuation; "skylight" distribution coefficients and zenith values).

The sky's luminance Y and chromaticity (x, y) each follow Perez et al.'s all-weather formula
(the skylight section), normalised at the zenith:

    F(theta, gamma) = (1 + A exp(B / cos theta)) (1 + C exp(D gamma) + E cos^2 gamma)
    Y(theta, gamma) = Y_z F(theta, gamma) / F(0, theta_s)        (same for x and y)

with theta the view zenith angle, gamma the angle between the view and the sun and theta_s the
sun's zenith angle (F is :func:`skyref.analytic.hosek.perez_f`, shared with the Perez form
skyref fits). The coefficients A..E are linear in the turbidity T, the zenith values are
fits in T and theta_s (appendix, skylight):

    Y_z = (4.0453 T - 4.9710) tan chi - 0.2155 T + 2.4192,  chi = (4/9 - T/120)(pi - 2 theta_s)
    x_z = [T^2 T 1] M_x [theta_s^3 theta_s^2 theta_s 1]^T   (y_z with M_y)

Units: Y_z is in kcd m^-2 (the paper's figures); it is multiplied by 1000 to cd m^-2.

Spectral radiance (skylight section): the chromaticity picks a CIE daylight spectrum
S(lambda) = S0 + M1 S1 + M2 S2 (Judd et al.'s basis, through colour-science) with

    M1 = (-1.3515 - 1.7703 x + 5.9114 y) / (0.0241 + 0.2562 x - 0.7341 y)
    M2 = (0.0300 - 31.4424 x + 30.0717 y) / (0.0241 + 0.2562 x - 0.7341 y)

and the luminance scales it: L(lambda) = Y S(lambda) / (683 lm W^-1 * integral S ybar dlambda), in
W m^-2 sr^-1 nm^-1 when Y is in cd m^-2 (CIE 1931 2-degree ybar). The daylight basis is tabulated
on 300-830 nm, which bounds the model's wavelengths. Far from the daylight locus the combination
is negative in the blue (about 1% of the sky: chiefly the yellow-green horizon of a sun within 10
degrees of it, and around the sun at T = 10); skyref clips it at zero before scaling to Y, so the
luminance stays the paper's.

The sun (appendix, sunlight): :func:`solar_transmittance` is the paper's spectral attenuation of
direct sunlight by Rayleigh scattering, aerosols (Angstrom, alpha 1.3, beta from T), ozone, mixed gases
and water vapour along the relative optical air mass of Kasten (tables of Iqbal 1983, "An
Introduction to Solar Radiation", as the paper's code lists them).

Validity (the paper's fits): turbidity 2-10, sun at or above the horizon, observer on the ground
(below 1 km here). Outside, :class:`~skyref.errors.ParameterError`. The model has no ground:
directions below the horizon return NaN (as LUT methods without a ground model do).

On skyref's atmospheres T comes from :func:`skyref.atmosphere.turbidity` (aerosol + Rayleigh
optical depth over Rayleigh's, at 550 nm); skyref's clear preset has T = 1.05, outside the fit, so
``turbidity=`` may set the value used instead (e.g. 2, the clearest sky the fit covers).

References
----------
A. J. Preetham, P. Shirley, B. Smits, "A Practical Analytic Model for Daylight", SIGGRAPH 99, 1999.

R. Perez, R. Seals, J. Michalsky, "All-weather model for sky luminance distribution — preliminary
configuration and validation", Solar Energy 50(3), 1993.

D. B. Judd, D. L. MacAdam, G. Wyszecki, "Spectral Distribution of Typical Daylight as a Function of
Correlated Color Temperature", JOSA 54(8), 1964 (the daylight basis S0, S1, S2).

F. Kasten, "A new table and approximation formula for the relative optical air mass", Arch. Meteorol.
Geophys. Bioklimatol. B 14, 1966.

M. Iqbal, "An Introduction to Solar Radiation", Academic Press, 1983 (the absorption tables).
"""

from __future__ import annotations

import functools

import numpy as np
from colour.colorimetry import SDS_BASIS_FUNCTIONS_CIE_ILLUMINANT_D_SERIES

from skyref.analytic.base import PER_VIEW_IN_LOOKUP, AnalyticModel
from skyref.analytic.hosek import perez_f
from skyref.sky_method import Operations
from skyref.atmosphere.presets import turbidity as atmosphere_turbidity
from skyref.validation import check_number
from skyref.color import xyz_matrix
from skyref.errors import ParameterError

__all__ = ["TURBIDITY_RANGE", "MAX_OBSERVER_ALTITUDE_M", "DAYLIGHT_BASIS_RANGE_NM", "PEREZ_LUMINANCE", "PEREZ_X",
           "PEREZ_Y", "ZENITH_X", "ZENITH_Y", "OZONE_K", "MIXED_GAS_K", "WATER_VAPOUR_K", "WATER_VAPOUR_CM",
           "PAPER_OZONE_CM", "perez_coefficients", "zenith_luminance", "zenith_chromaticity", "daylight_weights",
           "daylight_basis", "daylight_basis_grid", "solar_transmittance", "Preetham1999"]

#: Turbidities the paper's fits cover.
TURBIDITY_RANGE = (2.0, 10.0)
#: Highest observer accepted, m: the model's reference skies were seen from the ground.
MAX_OBSERVER_ALTITUDE_M = 1000.0
#: Wavelengths of the CIE daylight basis S0, S1, S2, nm.
DAYLIGHT_BASIS_RANGE_NM = (300.0, 830.0)

# Appendix (skylight): each Perez coefficient is a T + b, rows A..E, columns (a, b).
PEREZ_LUMINANCE = np.array([[0.1787, -1.4630], [-0.3554, 0.4275], [-0.0227, 5.3251],
                            [0.1206, -2.5771], [-0.0670, 0.3703]])
PEREZ_X = np.array([[-0.0193, -0.2592], [-0.0665, 0.0008], [-0.0004, 0.2125],
                    [-0.0641, -0.8989], [-0.0033, 0.0452]])
PEREZ_Y = np.array([[-0.0167, -0.2608], [-0.0950, 0.0092], [-0.0079, 0.2102],
                    [-0.0441, -1.6537], [-0.0109, 0.0529]])
# Appendix (skylight): zenith chromaticity, rows T^2, T, 1; columns theta_s^3, theta_s^2, theta_s, 1.
ZENITH_X = np.array([[0.00166, -0.00375, 0.00209, 0.0], [-0.02903, 0.06377, -0.03202, 0.00394],
                     [0.11693, -0.21196, 0.06052, 0.25886]])
ZENITH_Y = np.array([[0.00275, -0.00610, 0.00317, 0.0], [-0.04214, 0.08970, -0.04153, 0.00516],
                     [0.15346, -0.26756, 0.06670, 0.26688]])

# Appendix (sunlight), from Iqbal 1983: absorption coefficients, wavelength nm -> cm^-1.
OZONE_K = (
    (300, 10.0), (305, 4.8), (310, 2.7), (315, 1.35), (320, 0.8), (325, 0.38), (330, 0.16),
    (335, 0.075), (340, 0.04), (345, 0.019), (350, 0.007), (355, 0.0), (445, 0.003), (450, 0.003),
    (455, 0.004), (460, 0.006), (465, 0.008), (470, 0.009), (475, 0.012), (480, 0.014), (485, 0.017),
    (490, 0.021), (495, 0.025), (500, 0.03), (505, 0.035), (510, 0.04), (515, 0.045), (520, 0.048),
    (525, 0.057), (530, 0.063), (535, 0.07), (540, 0.075), (545, 0.08), (550, 0.085), (555, 0.095),
    (560, 0.103), (565, 0.11), (570, 0.12), (575, 0.122), (580, 0.12), (585, 0.118), (590, 0.115),
    (595, 0.12), (600, 0.125), (605, 0.13), (610, 0.12), (620, 0.105), (630, 0.09), (640, 0.079),
    (650, 0.067), (660, 0.057), (670, 0.048), (680, 0.036), (690, 0.028), (700, 0.023), (710, 0.018),
    (720, 0.014), (730, 0.011), (740, 0.01), (750, 0.009), (760, 0.007), (770, 0.004), (780, 0.0),
    (790, 0.0))
MIXED_GAS_K = ((759, 0.0), (760, 3.0), (770, 0.21), (771, 0.0))
WATER_VAPOUR_K = ((689, 0.0), (690, 0.016), (700, 0.024), (710, 0.0125), (720, 1.0), (730, 0.87),
                  (740, 0.061), (750, 0.001), (760, 1e-5), (770, 1e-5), (780, 6e-4), (790, 0.0175),
                  (800, 0.036))
#: The paper's precipitable water vapour, cm.
WATER_VAPOUR_CM = 2.0
#: The paper's ozone column, cm (NTP); skyref uses the atmosphere's own where it has ozone.
PAPER_OZONE_CM = 0.35


def perez_coefficients(turbidity: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A..E) for Y, x and y at turbidity T (appendix, skylight)."""
    t = np.array([turbidity, 1.0])
    return PEREZ_LUMINANCE @ t, PEREZ_X @ t, PEREZ_Y @ t


def zenith_luminance(turbidity: float, sun_zenith: float) -> float:
    """Y_z in kcd m^-2 (appendix, skylight); ``sun_zenith`` in radians."""
    chi = (4.0 / 9.0 - turbidity / 120.0) * (np.pi - 2.0 * sun_zenith)
    return (4.0453 * turbidity - 4.9710) * np.tan(chi) - 0.2155 * turbidity + 2.4192


def zenith_chromaticity(turbidity: float, sun_zenith: float) -> tuple[float, float]:
    """(x_z, y_z) (appendix, skylight); ``sun_zenith`` in radians."""
    t = np.array([turbidity ** 2, turbidity, 1.0])
    theta = np.array([sun_zenith ** 3, sun_zenith ** 2, sun_zenith, 1.0])
    return float(t @ ZENITH_X @ theta), float(t @ ZENITH_Y @ theta)


def daylight_weights(x, y):
    """(M1, M2) of the CIE daylight spectrum with chromaticity (x, y) (Judd et al. 1964)."""
    denominator = 0.0241 + 0.2562 * x - 0.7341 * y
    return ((-1.3515 - 1.7703 * x + 5.9114 * y) / denominator,
            (0.0300 - 31.4424 * x + 30.0717 * y) / denominator)


@functools.lru_cache(maxsize=1)
def _daylight_basis_table() -> tuple[np.ndarray, np.ndarray]:
    basis = SDS_BASIS_FUNCTIONS_CIE_ILLUMINANT_D_SERIES
    wl = np.asarray(basis["S0"].wavelengths, dtype=np.float64)
    return wl, np.stack([np.asarray(basis[k].values, dtype=np.float64) for k in ("S0", "S1", "S2")])


def daylight_basis(wavelengths_nm) -> np.ndarray:
    """S0, S1, S2 at ``wavelengths_nm`` (3, N), interpolated linearly in the CIE table."""
    wl, table = _daylight_basis_table()
    return np.stack([np.interp(wavelengths_nm, wl, row) for row in table])


@functools.lru_cache(maxsize=1)
def daylight_basis_grid() -> tuple[np.ndarray, np.ndarray]:
    """The basis on its own 5 nm grid (3, 107) and the luminance weights w of that grid, so that
    S @ w = 683 lm/W * integral S ybar dlambda (cd m^-2 per unit of S)."""
    wl, table = _daylight_basis_table()
    return table, xyz_matrix(wl)[:, 1]


def solar_transmittance(wavelengths_nm, sun_zenith_deg: float, turbidity: float,
                        ozone_cm: float = PAPER_OZONE_CM, water_vapour_cm: float = WATER_VAPOUR_CM) -> np.ndarray:
    """Spectral transmittance of the atmosphere to direct sunlight (appendix, sunlight), the
    product of

    - Rayleigh: exp(-0.008735 lambda^-4.08 m), lambda in um;
    - aerosol (Angstrom): exp(-beta lambda^-1.3 m), beta = 0.04608365822050 T - 0.04586025928522;
    - ozone: exp(-k_o l m), l the ozone column in cm;
    - mixed gases: exp(-1.41 k_g m / (1 + 118.93 k_g m)^0.45);
    - water vapour: exp(-0.2385 k_wa w m / (1 + 20.07 k_wa w m)^0.45), w in cm;

    with the relative optical mass m = 1 / (cos theta_s + 0.15 (93.885 - theta_s[deg])^-1.253)
    (Kasten 1966). Absorption coefficients outside their tables are those of the nearest entry.
    """
    check_number("sun_zenith_deg", sun_zenith_deg, 0.0, 90.0)
    wl = np.asarray(wavelengths_nm, dtype=np.float64)
    um = wl / 1000.0
    m = 1.0 / (np.cos(np.radians(sun_zenith_deg)) + 0.15 * (93.885 - sun_zenith_deg) ** -1.253)
    beta = 0.04608365822050 * turbidity - 0.04586025928522

    def k(table):
        nodes, values = np.asarray(table, dtype=np.float64).T
        return np.interp(wl, nodes, values)

    k_g, k_wa = k(MIXED_GAS_K), k(WATER_VAPOUR_K)
    tau = (0.008735 * um ** -4.08 * m + beta * um ** -1.3 * m + k(OZONE_K) * ozone_cm * m
           + 1.41 * k_g * m / (1.0 + 118.93 * k_g * m) ** 0.45
           + 0.2385 * k_wa * water_vapour_cm * m / (1.0 + 20.07 * k_wa * water_vapour_cm * m) ** 0.45)
    return np.exp(-tau)


class Preetham1999(AnalyticModel):
    """The Preetham et al. sky on a skyref atmosphere (see the module's documentation).

    ``turbidity``: T used by the fits; None takes :func:`skyref.atmosphere.turbidity` of the
    atmosphere. Either way it must lie in :data:`TURBIDITY_RANGE`.
    """

    name = "preetham1999"

    def __init__(self, atmosphere, wavelengths_nm="rgb", turbidity: float | None = None):
        super().__init__(atmosphere, wavelengths_nm)
        lo, hi = DAYLIGHT_BASIS_RANGE_NM
        outside = (self.wavelengths_nm < lo) | (self.wavelengths_nm > hi)
        if outside.any():
            raise ParameterError("wavelengths_nm", float(self.wavelengths_nm[outside][0]),
                                 f"[{lo:g}, {hi:g}] nm (the CIE daylight basis)", "outside the model's spectrum")
        value = atmosphere_turbidity(atmosphere) if turbidity is None else turbidity
        lo, hi = TURBIDITY_RANGE
        if turbidity is None and not lo <= value <= hi:
            raise ParameterError("turbidity", value, f"[{lo:g}, {hi:g}], the range of the paper's fits",
                                 "the atmosphere's turbidity is outside it; pass turbidity= to choose "
                                 "the value the model uses")
        self.turbidity = check_number("turbidity", value, lo, hi)
        self.options = {"turbidity": self.turbidity}
        self.basis = daylight_basis(self.wavelengths_nm)

    def _check_validity(self, altitude_m: float, mu_s: float):
        check_number("observer_altitude_m", altitude_m, 0.0, MAX_OBSERVER_ALTITUDE_M)
        check_number("sun zenith angle (deg)", float(np.degrees(np.arccos(mu_s))), 0.0, 90.0)

    def sky_xyY(self, mu, mu_s: float, nu) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Chromaticity x, y and luminance Y (cd m^-2) along view zenith cosines ``mu`` (>= 0)
        with view-sun cosines ``nu``, the sun at zenith cosine ``mu_s``."""
        gamma = np.arccos(nu)
        sun_zenith = float(np.arccos(mu_s))
        coefficients_Y, coefficients_x, coefficients_y = perez_coefficients(self.turbidity)
        x_z, y_z = zenith_chromaticity(self.turbidity, sun_zenith)
        Y_z = 1000.0 * zenith_luminance(self.turbidity, sun_zenith)   # kcd m^-2 -> cd m^-2

        def distribute(zenith_value, coefficients):
            return zenith_value * perez_f(coefficients, mu, gamma) / perez_f(coefficients, 1.0, sun_zenith)

        return distribute(x_z, coefficients_x), distribute(y_z, coefficients_y), distribute(Y_z, coefficients_Y)

    def operations(self) -> Operations:
        """Per direction: the Perez function F for Y, x and y, and a CIE daylight spectrum
        (S0 + M1 S1 + M2 S2 at the model's wavelengths, and on the basis's own 107-point grid for
        its luminance: :meth:`_radiance` clips it before scaling it to Y); per view: the zenith
        values and F(0, theta_s) of Y, x and y."""
        return Operations(sky={"Perez F evaluations": 3, "daylight spectra": 1},
                          per_view={"Perez F evaluations": 3, "zenith-value fits": 3}, note=PER_VIEW_IN_LOOKUP)

    def _radiance(self, r, mu, mu_s, nu):
        above = mu >= 0.0
        x, y, Y = self.sky_xyY(np.where(above, mu, 0.0), mu_s, nu)
        weights = np.stack([np.ones_like(x), *daylight_weights(x, y)], axis=1)     # (M, 3): 1, M1, M2
        # Far from the daylight locus (the yellow-green horizon of a low sun) S0 + M1 S1 + M2 S2
        # turns negative in the blue: clip it, then scale the clipped spectrum to luminance Y.
        basis_grid, luminance_weights = daylight_basis_grid()
        luminance_per_unit = np.maximum(weights @ basis_grid, 0.0) @ luminance_weights
        spectrum = np.maximum(weights @ self.basis, 0.0)
        radiance = (Y / luminance_per_unit)[:, None] * spectrum
        return np.where(above[:, None], radiance, np.nan)

    def solar_transmittance(self, sun_zenith_deg: float) -> np.ndarray:
        """:func:`solar_transmittance` at this model's wavelengths and turbidity, with the ozone
        column of the atmosphere's ``ozone`` absorber (0 without one)."""
        ozone_cm = 0.0
        if "ozone" in self.atmosphere and self.atmosphere["ozone"].column_du is not None:
            ozone_cm = self.atmosphere["ozone"].column_du / 1000.0     # 1 DU = 0.001 cm at NTP
        return solar_transmittance(self.wavelengths_nm, sun_zenith_deg, self.turbidity, ozone_cm)
