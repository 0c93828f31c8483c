"""The sun as a light source: a disk of finite angular radius, optionally limb-darkened,
delivering the extraterrestrial solar irradiance. One home for the disk's physics, used by the
path tracer (:mod:`skyref.plugins.integrator`), the stock-volpath scene and the LUT methods;
written against an array namespace ``xp`` (NumPy, or Dr.Jit in kernels).

Units: angles in degrees in the API (radians inside), irradiance in W m^-2 nm^-1 perpendicular
to the beam at the top of the atmosphere, solid angle in sr.

References
----------
E. Bruneton, "A qualitative and quantitative evaluation of 8 clear sky models", IEEE TVCG 23
(2017) (the angular radius 0.00935 / 2 rad).

H. Neckel and D. Labs, "Solar limb darkening 1986-1990", Solar Physics 153 (1994) (the linear
law's coefficient in the visible).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from skyref.atmosphere.spectra import solar_irradiance
from skyref.validation import check_number

__all__ = ["SUN_ANGULAR_RADIUS_DEG", "LIMB_DARKENING_U", "SunDisk"]

#: Bruneton 2017's solar angular radius, 0.00935 / 2 rad, in degrees.
SUN_ANGULAR_RADIUS_DEG = math.degrees(0.00935 / 2.0)

#: Limb-darkening coefficient u of the linear law I(mu)/I(1) = 1 - u (1 - mu), grey (a visible
#: band average; Neckel & Labs 1994 give 0.5–0.7 across 450–700 nm).
LIMB_DARKENING_U = 0.6


@dataclass(frozen=True)
class SunDisk:
    """The solar disk: ``angular_radius_deg`` (0 < r <= 10 deg) and ``limb_darkening`` (the
    linear law with LIMB_DARKENING_U; off: a uniform disk)."""

    angular_radius_deg: float = SUN_ANGULAR_RADIUS_DEG
    limb_darkening: bool = False

    def __post_init__(self):
        check_number("sun.angular_radius_deg", self.angular_radius_deg, 0.0, 10.0, lo_open=True)

    @property
    def cos_radius(self) -> float:
        return math.cos(math.radians(self.angular_radius_deg))

    @property
    def solid_angle_sr(self) -> float:
        return 2.0 * math.pi * (1.0 - self.cos_radius)

    @staticmethod
    def irradiance(wavelengths_nm) -> np.ndarray:
        """Extraterrestrial solar spectral irradiance at ``wavelengths_nm``, W m^-2 nm^-1."""
        return solar_irradiance(wavelengths_nm)

    def limb_darkening_factor(self, cos_angle, xp=np):
        """Radiance at angle acos(cos_angle) from the disk's centre over the disk's mean: the
        linear law in mu = cos of the emission angle on the solar surface, normalised by its disk
        mean 1 - u/3; 1 without limb darkening. Meaningful inside the disk."""
        if not self.limb_darkening:
            return 1.0 + 0.0 * cos_angle
        sin_ratio2 = xp.clip((1.0 - cos_angle * cos_angle) / (1.0 - self.cos_radius ** 2), 0.0, 1.0)
        mu = xp.sqrt(1.0 - sin_ratio2)
        return (1.0 - LIMB_DARKENING_U * (1.0 - mu)) / (1.0 - LIMB_DARKENING_U / 3.0)

    def radiance_factor(self, cos_angle, xp=np):
        """The disk's radiance along a direction at angle acos(cos_angle) from its centre, over
        its mean radiance (0 outside the disk)."""
        return xp.where(cos_angle >= self.cos_radius, self.limb_darkening_factor(cos_angle, xp), 0.0)
