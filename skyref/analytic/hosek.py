"""The Hosek–Wilkie analytic sky model: evaluators (NumPy and JAX) for any coefficient table of
its form, and the published coefficients (version 1.4a).

L. Hosek and A. Wilkie, "An Analytic Model for Full Spectral Sky-Dome Radiance", ACM TOG 31(4)
(SIGGRAPH 2012). The sky's radiance in a direction at zenith angle theta, at angle gamma from the
sun, is the product of an overall radiance L_M and a shape function of nine coefficients A..I,
an extension of Perez et al.'s all-weather formula::

    L(theta, gamma) = L_M * F(theta, gamma)
    F = (1 + A exp(B / (cos theta + 0.01)))                      # horizon brightening
        * (C + D exp(E gamma) + F cos^2 gamma                    # circumsolar, Rayleigh-like
           + G chi(H, gamma) + I sqrt(cos theta))                # aureole, zenith gradient
    chi(g, gamma) = (1 + cos^2 gamma) / (1 + g^2 - 2 g cos gamma)^(3/2)

chi is a Cornette–Shanks-like peak around the sun (its g is H). L_M is close to the mean radiance
over the sky hemisphere (F averages to 0.95–1.07 over it in the published data).

**Units.** Spectral tables give L in W m^-2 sr^-1 nm^-1 at the centre of each 40 nm band
(320, 360, ..., 720 nm). Tristimulus tables give CIE XYZ as the integral of L times the CIE 1931
2-degree colour-matching functions, W m^-2 sr^-1 (multiply Y by 683 lm/W for luminance in
cd m^-2), or linear sRGB (D65 primaries) of that XYZ.

**Table layout** (that of the published ``ArHosekSkyModelData_*.h``). Per channel, the shape
coefficients form an array ``[albedo 2][turbidity 10][control point 6][coefficient 9]`` and the
overall radiance ``[albedo 2][turbidity 10][control point 6]``, C order. Albedo is the ground
albedo 0 or 1, turbidity 1, 2, ..., 10. The nine coefficients are stored in the order
**A B C D E F G I H** (:data:`COEFFICIENTS`: the reference code reads index 7 as the sqrt(cos theta)
weight and index 8 as chi's g).

**Interpolation** ("cooking" a configuration, as the reference code does): linear in albedo
between 0 and 1, linear in turbidity between the two stored neighbours, and a quintic Bezier curve
over the six control points in the solar-elevation parameter x = (elevation / (pi/2))^(1/3)
(:func:`elevation_parameter`), which crowds the control points near the horizon. All three are
convex combinations, so any coefficient of a cooked configuration lies between the smallest and
largest stored value: bounds on a table hold everywhere it is evaluated.

**Domain.** theta in [0, pi] and gamma in [0, pi] (radians); turbidity in [1, 10]; albedo in
[0, 1]; solar elevation in [-pi/2, pi/2] rad. Outside the model's data skyref extends it by
holding the nearest valid value, where the reference code returns NaN: a sun below the horizon
gives the sky of a sun on it, and a view below the horizon (cos theta < 0) sees the horizon. Inputs
outside these ranges raise :class:`~skyref.errors.ParameterError`. F itself can be negative: the
published coefficients give F < 0 within 1 deg of the horizon, away from a low sun (e.g. 320 nm,
sun on the horizon), so :meth:`CoefficientTable.radiance` returns max(L_M F, 0); :func:`hosek_f`
is the bare formula.

The same layout and interpolation carry the 5-coefficient Perez form (:func:`perez_f`), which
:mod:`skyref.fit` fits as a Preetham-style baseline; :data:`FORMS` names both.

References
----------
L. Hosek, A. Wilkie, "An Analytic Model for Full Spectral Sky-Dome Radiance", ACM TOG 31(4), 2012.

R. Perez, R. Seals, J. Michalsky, "All-weather model for sky luminance distribution — preliminary
configuration and validation", Solar Energy 50(3), 1993.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass
from importlib import resources

import numpy as np

from skyref.errors import ParameterError

__all__ = ["BAND_CENTRES_NM", "TURBIDITIES", "ALBEDOS", "CONTROL_POINTS", "COEFFICIENTS", "PEREZ_COEFFICIENTS",
           "CHANNELS", "UNITS", "HORIZON_OFFSET", "PEREZ_MIN_COS_THETA", "hosek_f", "perez_f", "FORMS",
           "elevation_parameter", "bezier_weights", "configuration_weights", "interpolate_configuration",
           "check_configuration", "check_view", "array_names", "CoefficientTable", "published_arrays",
           "published_table", "published_solar_radiance"]

#: Centres of the published model's 40 nm bands, nm.
BAND_CENTRES_NM = tuple(float(w) for w in range(320, 721, 40))
#: Stored turbidities (Linke/Preetham turbidity).
TURBIDITIES = tuple(float(t) for t in range(1, 11))
#: Stored ground albedos.
ALBEDOS = (0.0, 1.0)
#: Bezier control points per coefficient (a quintic curve).
CONTROL_POINTS = 6
#: Shape coefficients of the Hosek–Wilkie form, in their storage order.
COEFFICIENTS = ("A", "B", "C", "D", "E", "F", "G", "I", "H")
#: Coefficients of the Perez form, in storage order.
PEREZ_COEFFICIENTS = ("A", "B", "C", "D", "E")
#: Channels of each kind of table, in storage order.
CHANNELS = {"spectral": tuple(f"{w:g}" for w in BAND_CENTRES_NM), "xyz": ("X", "Y", "Z"),
            "rgb": ("R", "G", "B")}
#: Unit of the radiance of each kind of table.
UNITS = {"spectral": "W m^-2 sr^-1 nm^-1",
         "xyz": "W m^-2 sr^-1 (CIE 1931 XYZ; Y x 683 lm/W = luminance in cd m^-2)",
         "rgb": "W m^-2 sr^-1 (linear sRGB of that XYZ)"}
#: Offset that keeps the horizon term of the Hosek–Wilkie form finite at cos theta = 0.
HORIZON_OFFSET = 0.01
#: Smallest cos theta the Perez form divides by (its horizon term exp(B / cos theta) is singular).
PEREZ_MIN_COS_THETA = 1e-6

_PUBLISHED = "arhosek_v1.4a.npz"
_PUBLISHED_SUN = "hosek_solar_radiance.csv"
_SKYREF_FIT = "skyref_fit"


# --- the model forms ---------------------------------------------------------------------------

def _components(coefficients, count):
    return [coefficients[..., i] for i in range(count)]


def hosek_f(coefficients, cos_theta, gamma, xp=np):
    """The Hosek–Wilkie shape function F(theta, gamma) (see the module's documentation).

    ``coefficients`` ``(..., 9)`` in storage order A B C D E F G I H; their leading axes broadcast
    against ``cos_theta`` and ``gamma`` (radians). ``cos_theta`` is clamped to [0, 1] (a view
    below the horizon sees the horizon). ``xp`` is ``numpy`` or ``jax.numpy``.

    chi's denominator is computed as (1 - H)^2 + 4 H sin^2(gamma / 2), equal to
    1 + H^2 - 2 H cos gamma but without its cancellation near the pole (H -> 1, gamma -> 0), where
    the textbook form loses all digits in float32.
    """
    a, b, c, d, e, f, g, i, h = _components(coefficients, 9)
    cos_theta = xp.clip(cos_theta, 0.0, 1.0)
    cos_gamma = xp.cos(gamma)
    sin_half = xp.sin(0.5 * gamma)
    chi = (1.0 + cos_gamma * cos_gamma) / ((1.0 - h) ** 2 + 4.0 * h * sin_half * sin_half) ** 1.5
    horizon = 1.0 + a * xp.exp(b / (cos_theta + HORIZON_OFFSET))
    return horizon * (c + d * xp.exp(e * gamma) + f * cos_gamma * cos_gamma + g * chi + i * xp.sqrt(cos_theta))


def perez_f(coefficients, cos_theta, gamma, xp=np):
    """Perez et al.'s all-weather shape function, the 5-coefficient form of Preetham et al.:
    F = (1 + A exp(B / cos theta)) (1 + C exp(D gamma) + E cos^2 gamma).

    ``coefficients`` ``(..., 5)`` (A..E) broadcast against ``cos_theta`` and ``gamma`` (radians).
    cos theta is clamped to [:data:`PEREZ_MIN_COS_THETA`, 1]: at the horizon exp(B / cos theta)
    tends to 0 for the usual B < 0, which the clamp reproduces without dividing by zero.
    """
    a, b, c, d, e = _components(coefficients, 5)
    cos_theta = xp.clip(cos_theta, PEREZ_MIN_COS_THETA, 1.0)
    cos_gamma = xp.cos(gamma)
    return (1.0 + a * xp.exp(b / cos_theta)) * (1.0 + c * xp.exp(d * gamma) + e * cos_gamma * cos_gamma)


#: Model forms carried by a :class:`CoefficientTable`: name -> (coefficient names, F function).
FORMS = {"hosek": (COEFFICIENTS, hosek_f), "perez": (PEREZ_COEFFICIENTS, perez_f)}


# --- interpolation over solar elevation, turbidity and albedo ---------------------------------

def elevation_parameter(solar_elevation, xp=np):
    """x = (elevation / (pi/2))^(1/3) of a solar elevation (radians), the Bezier curve's
    parameter; elevations are clamped to [0, pi/2] (a sun below the horizon counts as on it)."""
    fraction = xp.clip(solar_elevation / (0.5 * math.pi), 0.0, 1.0)
    return fraction ** (1.0 / 3.0)


def bezier_weights(x, xp=np):
    """The quintic Bernstein weights ``(..., 6)`` at ``x`` in [0, 1]:
    (1-x)^5, 5 (1-x)^4 x, 10 (1-x)^3 x^2, 10 (1-x)^2 x^3, 5 (1-x) x^4, x^5."""
    x = xp.asarray(x)[..., None]
    k = np.arange(CONTROL_POINTS)
    binomial = np.array([math.comb(CONTROL_POINTS - 1, int(j)) for j in k], dtype=np.float64)
    return binomial * x ** k * (1.0 - x) ** (CONTROL_POINTS - 1 - k)


def configuration_weights(solar_elevation, turbidity, albedo, xp=np):
    """Weights ``(..., 2, 10, 6)`` of the stored values [albedo][turbidity][control point] in a
    configuration: (1 - a, a) in albedo, hat functions max(0, 1 - |T - T_k|) in turbidity (the
    reference code's linear interpolation between neighbours) and Bezier weights in elevation.
    Inputs broadcast together; they are clamped to the table's range."""
    x = elevation_parameter(xp.asarray(solar_elevation), xp)
    t = xp.clip(xp.asarray(turbidity), TURBIDITIES[0], TURBIDITIES[-1])
    a = xp.clip(xp.asarray(albedo), 0.0, 1.0)
    x, t, a = xp.broadcast_arrays(x, t, a)
    albedo_w = xp.stack([1.0 - a, a], axis=-1)
    turbidity_w = xp.maximum(0.0, 1.0 - xp.abs(t[..., None] - np.asarray(TURBIDITIES)))
    elevation_w = bezier_weights(x, xp)
    return albedo_w[..., :, None, None] * turbidity_w[..., None, :, None] * elevation_w[..., None, None, :]


def interpolate_configuration(coefficients, radiances, solar_elevation, turbidity, albedo, xp=np):
    """Cook a configuration from stored arrays: ``coefficients`` ``(C, 2, 10, 6, n)`` and
    ``radiances`` ``(C, 2, 10, 6)`` give (coefficients ``(..., C, n)``, overall radiance
    ``(..., C)``) for solar elevation (radians), turbidity and albedo broadcast to ``...``."""
    weights = configuration_weights(solar_elevation, turbidity, albedo, xp)
    return (xp.einsum("...atk,catkn->...cn", weights, xp.asarray(coefficients)),
            xp.einsum("...atk,catk->...c", weights, xp.asarray(radiances)))


# --- input checks ------------------------------------------------------------------------------

def _check_range(name: str, value, lo: float, hi: float, unit: str = ""):
    """Raise a ParameterError if any entry of ``value`` is not finite or outside [lo, hi].
    Values that are JAX tracers (inside ``jax.jit``) cannot be inspected and pass: check concrete
    inputs before tracing."""
    try:
        values = np.asarray(value, dtype=np.float64)
    except TypeError:  # a jax tracer refuses conversion (TracerArrayConversionError)
        return
    bad = ~np.isfinite(values) | (values < lo) | (values > hi)
    if bad.any():
        raise ParameterError(name, float(values[bad].flat[0]), f"[{lo:g}, {hi:g}]{unit}", "out of range")


def check_configuration(solar_elevation, turbidity, albedo):
    """Check a configuration's inputs (see the module's "Domain")."""
    _check_range("solar_elevation", solar_elevation, -0.5 * math.pi, 0.5 * math.pi, " rad")
    _check_range("turbidity", turbidity, TURBIDITIES[0], TURBIDITIES[-1])
    _check_range("albedo", albedo, 0.0, 1.0)


def check_view(theta, gamma):
    """Check view angles: ``theta`` (zenith angle) and ``gamma`` (angle to the sun), radians."""
    _check_range("theta", theta, 0.0, math.pi, " rad")
    _check_range("gamma", gamma, 0.0, math.pi, " rad")


# --- tables ------------------------------------------------------------------------------------

def array_names(form: str, kind: str, index: int) -> tuple[str, str]:
    """Names of a channel's (shape, radiance) arrays, as in the published headers:
    ``dataset320``/``datasetRad320``, ``datasetXYZ1``/``datasetXYZRad1``,
    ``datasetRGB1``/``datasetRGBRad1``; a Perez table prefixes ``perez``
    (``perezDataset320``/``perezDatasetRad320``)."""
    prefix = "dataset" if form == "hosek" else f"{form}Dataset"
    if kind == "spectral":
        return f"{prefix}{CHANNELS[kind][index]}", f"{prefix}Rad{CHANNELS[kind][index]}"
    infix = kind.upper()
    return f"{prefix}{infix}{index + 1}", f"{prefix}{infix}Rad{index + 1}"


@dataclass(frozen=True)
class CoefficientTable:
    """The coefficients of one kind of sky ("spectral": the 11 bands; "xyz"; "rgb") for one model
    form ("hosek" or "perez"), in the published layout (see the module's documentation).

    ``coefficients``: ``(channels, 2, 10, 6, n)``; ``radiances``: ``(channels, 2, 10, 6)``, in the
    kind's unit (:data:`UNITS`). ``source`` says where the numbers come from.
    """

    form: str
    kind: str
    coefficients: np.ndarray
    radiances: np.ndarray
    source: str = ""

    def __post_init__(self):
        if self.form not in FORMS:
            raise ParameterError("form", self.form, " or ".join(map(repr, FORMS)), "unknown model form")
        if self.kind not in CHANNELS:
            raise ParameterError("kind", self.kind, " or ".join(map(repr, CHANNELS)), "unknown kind of table")
        shape = (len(self.channels), len(ALBEDOS), len(TURBIDITIES), CONTROL_POINTS)
        for name, expected in (("coefficients", shape + (len(self.coefficient_names),)), ("radiances", shape)):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != expected:
                raise ParameterError(name, f"array of shape {value.shape}", f"shape {expected}", "wrong shape")
            if not np.all(np.isfinite(value)):
                raise ParameterError(name, "array with non-finite entries", "finite numbers", "not finite")
            object.__setattr__(self, name, value)

    @property
    def channels(self) -> tuple[str, ...]:
        return CHANNELS[self.kind]

    @property
    def coefficient_names(self) -> tuple[str, ...]:
        return FORMS[self.form][0]

    @property
    def shape_function(self):
        """F(coefficients, cos_theta, gamma, xp) of the table's form."""
        return FORMS[self.form][1]

    @property
    def unit(self) -> str:
        return UNITS[self.kind]

    def configuration(self, solar_elevation, turbidity, albedo, xp=np):
        """(coefficients ``(..., channels, n)``, overall radiance ``(..., channels)``) of the
        configuration: solar elevation in radians, turbidity, ground albedo (broadcast together)."""
        check_configuration(solar_elevation, turbidity, albedo)
        return interpolate_configuration(self.coefficients, self.radiances, solar_elevation, turbidity, albedo, xp)

    def radiance(self, theta, gamma, solar_elevation, turbidity, albedo, xp=np):
        """Sky radiance ``(..., channels)`` in the kind's unit, solar disk excluded, clamped at 0
        (see the module's "Domain").

        ``theta`` (view zenith angle) and ``gamma`` (angle between view and sun), radians,
        broadcast to ``...``; the configuration is a scalar, or broadcasts against them too.
        """
        check_view(theta, gamma)
        coefficients, scale = self.configuration(solar_elevation, turbidity, albedo, xp)
        theta, gamma = xp.asarray(theta), xp.asarray(gamma)
        radiance = scale * self.shape_function(coefficients, xp.cos(theta)[..., None], gamma[..., None], xp)
        return xp.maximum(radiance, 0.0)

    def spectral_radiance(self, wavelength_nm, theta, gamma, solar_elevation, turbidity, albedo, xp=np):
        """Radiance (W m^-2 sr^-1 nm^-1) at any wavelength in [320, 720] nm, interpolated linearly
        between the band centres as the reference code does; shape of ``theta``/``gamma`` plus the
        shape of ``wavelength_nm``. Spectral tables only."""
        if self.kind != "spectral":
            raise ParameterError("kind", self.kind, "'spectral'", "spectral_radiance needs a spectral table")
        _check_range("wavelength_nm", wavelength_nm, BAND_CENTRES_NM[0], BAND_CENTRES_NM[-1], " nm")
        bands = self.radiance(theta, gamma, solar_elevation, turbidity, albedo, xp)
        centres = np.asarray(BAND_CENTRES_NM)
        wavelength = np.atleast_1d(np.asarray(wavelength_nm, dtype=np.float64))
        # Linear interpolation between band centres as a (bands, wavelengths) matrix.
        interpolation = np.stack([np.interp(wavelength, centres, row) for row in np.eye(centres.size)])
        result = bands @ xp.asarray(interpolation)
        return result.reshape(result.shape[:-1] + np.shape(wavelength_nm))

    def arrays(self) -> dict[str, np.ndarray]:
        """Flat float64 arrays under the published names (:func:`array_names`), in the layout of
        the published headers."""
        result = {}
        for index in range(len(self.channels)):
            shape_name, radiance_name = array_names(self.form, self.kind, index)
            result[shape_name] = self.coefficients[index].ravel()
            result[radiance_name] = self.radiances[index].ravel()
        return result

    @classmethod
    def from_arrays(cls, arrays, form: str, kind: str, source: str = "") -> "CoefficientTable":
        """Inverse of :meth:`arrays`: read a table from a mapping of name -> flat array (an
        ``np.load``-ed ``.npz`` such as the published one)."""
        if form not in FORMS:
            raise ParameterError("form", form, " or ".join(map(repr, FORMS)), "unknown model form")
        if kind not in CHANNELS:
            raise ParameterError("kind", kind, " or ".join(map(repr, CHANNELS)), "unknown kind of table")
        n = len(FORMS[form][0])
        coefficients, radiances = [], []
        for index in range(len(CHANNELS[kind])):
            shape_name, radiance_name = array_names(form, kind, index)
            if shape_name not in arrays or radiance_name not in arrays:
                raise ParameterError("arrays", source or "(mapping)", f"arrays {shape_name} and {radiance_name}",
                                     "missing")
            coefficients.append(np.asarray(arrays[shape_name], dtype=np.float64).reshape(2, 10, CONTROL_POINTS, n))
            radiances.append(np.asarray(arrays[radiance_name], dtype=np.float64).reshape(2, 10, CONTROL_POINTS))
        return cls(form, kind, np.stack(coefficients), np.stack(radiances), source)


# --- the published coefficients ----------------------------------------------------------------

@functools.lru_cache(maxsize=1)
def published_arrays() -> dict[str, np.ndarray]:
    """Every array of the bundled published data (``data/arhosek_v1.4a.npz``): the sky tables
    plus ``solarDataset*`` and ``limbDarkeningDataset*`` of the solar radiance function."""
    with resources.as_file(resources.files("skyref.analytic") / "data" / _PUBLISHED) as path:
        with np.load(path) as data:
            return {name: data[name].copy() for name in data.files}


def published_table(kind: str = "spectral") -> CoefficientTable:
    """The published Hosek–Wilkie coefficients (version 1.4a) of ``kind`` ("spectral", "xyz",
    "rgb")."""
    return CoefficientTable.from_arrays(published_arrays(), "hosek", kind,
                                        source="Hosek & Wilkie 2012, reference implementation 1.4a")


def skyref_fit_directory() -> str:
    """The directory of skyref's own fit of the Hosek–Wilkie model to its ground truth, shipped
    with the package (``data/skyref_fit``): its spectral, CIE XYZ and RGB tables in ``hosek.npz``
    and ``hosek.json``, and as ``ArHosekSkyModelData_{Spectral,CIEXYZ,RGB}.h`` in the published
    layout; what it was fitted to in its ``README.md``. Read it with
    :func:`skyref.fit.export.read_tables`."""
    return os.fspath(resources.files("skyref.analytic") / "data" / _SKYREF_FIT)


@functools.lru_cache(maxsize=1)
def published_solar_radiance() -> np.ndarray:
    """The solar spectrum the published model assumes (``data/hosek_solar_radiance.csv``): the
    radiance of the sun's disk at the top of the atmosphere, W m^-2 sr^-1 nm^-1, at
    :data:`BAND_CENTRES_NM`. The published radiances scale with it: the authors' path tracer lit
    the skies the model was fitted to with this sun."""
    text = (resources.files("skyref.analytic") / "data" / _PUBLISHED_SUN).read_text(encoding="utf-8")
    rows = [line for line in text.splitlines() if line and not line.startswith("#")][1:]   # after the header
    wavelengths, radiance = np.loadtxt(rows, delimiter=",", ndmin=2).T
    if not np.array_equal(wavelengths, BAND_CENTRES_NM):
        raise ValueError(f"{_PUBLISHED_SUN}: wavelengths {wavelengths} are not the band centres {BAND_CENTRES_NM}")
    return radiance
