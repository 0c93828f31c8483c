"""Named atmospheres, each with the source of its numbers.

All presets share the conventions of docs/design.md: planet radius 6360 km, Rayleigh
1.24062e-6 m^-1 (lambda / 1 um)^-4 with an 8 km scale height, aerosol with a 1.2 km scale
height, ozone as a 10–25–40 km tent.

References
----------
E. Bruneton, "Precomputed Atmospheric Scattering: a New Implementation", 2017,
https://ebruneton.github.io/precomputed_atmospheric_scattering/ (the demo's atmosphere).

S. Hillaire, "A Scalable and Production Ready Sky and Atmosphere Rendering Technique", Computer
Graphics Forum 39(4) (Proc. EGSR 2020), 2020.

E. Bruneton, "A Qualitative and Quantitative Evaluation of 8 Clear Sky Models", IEEE TVCG 23(12), 2017
(published online 2016).

A. J. Preetham, P. Shirley, B. Smits, "A Practical Analytic Model for Daylight", SIGGRAPH 99, 1999
(turbidity).
"""

from __future__ import annotations

from skyref.atmosphere.constituents import Absorber, Aerosol, Rayleigh
from skyref.atmosphere.model import Atmosphere
from skyref.atmosphere.phase import CornetteShanks
from skyref.validation import check_choice, check_number

__all__ = ["TURBIDITY_WAVELENGTH_NM", "bruneton2017", "hillaire2020", "bruneton2016_measured", "rayleigh_only",
           "rayleigh_optical_depth", "from_turbidity", "turbidity", "PRESETS", "preset"]

#: Reference wavelength of turbidity, nm.
TURBIDITY_WAVELENGTH_NM = 550.0


def bruneton2017() -> Atmosphere:
    """E. Bruneton, "Precomputed Atmospheric Scattering: a New Implementation" (2017), demo
    values: top of the atmosphere at 6420 km; Rayleigh as above; aerosol Angstrom alpha 0,
    beta 5.328e-3 (extinction 4.44e-6 m^-1 at sea level), single-scattering albedo 0.9,
    Cornette–Shanks g 0.8; ozone 300 DU; ground albedo 0.1."""
    return Atmosphere(
        bottom_radius_m=6_360_000.0, top_radius_m=6_420_000.0, ground_albedo=0.1,
        constituents=(Rayleigh(), Aerosol(), Absorber()), name="bruneton2017")


def hillaire2020() -> Atmosphere:
    """S. Hillaire, "A Scalable and Production Ready Sky and Atmosphere Rendering Technique"
    (EGSR 2020), the values of its paper and demo: top of the atmosphere at 6460 km; Rayleigh
    (5.802, 13.558, 33.1)e-6 m^-1 at 680/550/440 nm (the lambda^-4 law above); aerosol
    scattering 3.996e-6 m^-1 and extinction 4.44e-6 m^-1, grey, Cornette–Shanks g 0.8;
    ozone absorption (0.650, 1.881, 0.085)e-6 m^-1 at the tent's peak (300 DU with the
    Serdyuchenko cross-sections); ground albedo 0."""
    return bruneton2017().replace(top_radius_m=6_460_000.0, ground_albedo=0.0, name="hillaire2020")


def bruneton2016_measured() -> Atmosphere:
    """E. Bruneton, "A Qualitative and Quantitative Evaluation of 8 Clear Sky Models" (IEEE TVCG
    2016): the aerosol that best matched Kider et al.'s measured skies, Angstrom alpha 0.8,
    beta 0.04, Cornette–Shanks g 0.7, single-scattering albedo 0.8. Everything else (ozone,
    ground albedo 0.1, radii) is taken from :func:`bruneton2017`."""
    base = bruneton2017()
    aerosol = Aerosol(angstrom_alpha=0.8, angstrom_beta=0.04, single_scattering_albedo=0.8,
                      phase=CornetteShanks(0.7))
    return base.with_constituent(aerosol).replace(name="bruneton2016_measured")


def rayleigh_only() -> Atmosphere:
    """Molecules only (no aerosol, no ozone), black ground: the textbook Rayleigh sky with the
    geometry of :func:`bruneton2017`."""
    return Atmosphere(constituents=(Rayleigh(),), ground_albedo=0.0, name="rayleigh_only")


def rayleigh_optical_depth(atmosphere: Atmosphere, wavelength_nm: float = TURBIDITY_WAVELENGTH_NM) -> float:
    return float(atmosphere.constituent_optical_depth(atmosphere["rayleigh"], wavelength_nm)[0])


def from_turbidity(turbidity: float, angstrom_alpha: float = 1.3,
                   base: Atmosphere | None = None) -> Atmosphere:
    """An atmosphere with the given Linke/Preetham turbidity T at 550 nm.

    T = (tau_m + tau_a) / tau_m, with tau_m the vertical Rayleigh optical depth and tau_a the
    aerosol optical depth at 550 nm. Hence tau_a(550 nm) = (T - 1) tau_m and, with Angstrom's law
    tau_a(lambda) = beta (lambda / 1 um)^-alpha, beta = (T - 1) tau_m (0.55)^alpha. The aerosol
    keeps the base's profile, single-scattering albedo and phase function (default base:
    :func:`bruneton2017`; alpha 1.3 as in Preetham et al. 1999 and Angstrom's original value).
    """
    check_number("turbidity", turbidity, 1.0, 50.0)
    check_number("angstrom_alpha", angstrom_alpha, -1.0, 4.0)
    base = base or bruneton2017()
    tau_m = rayleigh_optical_depth(base)
    beta = (turbidity - 1.0) * tau_m * (TURBIDITY_WAVELENGTH_NM / 1000.0) ** angstrom_alpha
    old = base["aerosol"] if "aerosol" in base else Aerosol()
    aerosol = Aerosol(name=old.name, profile=old.profile, angstrom_alpha=angstrom_alpha,
                      angstrom_beta=beta, single_scattering_albedo=old.single_scattering_albedo,
                      phase=old.phase)
    return base.with_constituent(aerosol).replace(name=f"turbidity{turbidity:g}")


def turbidity(atmosphere: Atmosphere) -> float:
    """The Linke/Preetham turbidity of an atmosphere at 550 nm (inverse of
    :func:`from_turbidity`); 1 for an atmosphere without aerosol."""
    tau_m = rayleigh_optical_depth(atmosphere)
    tau_a = sum(float(atmosphere.constituent_optical_depth(c, TURBIDITY_WAVELENGTH_NM)[0])
                for c in atmosphere.constituents if c.kind == "aerosol")
    return (tau_m + tau_a) / tau_m


PRESETS = {f.__name__: f for f in (bruneton2017, hillaire2020, bruneton2016_measured, rayleigh_only)}


def preset(name: str) -> Atmosphere:
    """The preset called ``name`` (see :data:`PRESETS`)."""
    return PRESETS[check_choice("atmosphere.preset", name, tuple(PRESETS))]()
