"""Phase functions p(mu), normalised so that the integral over the sphere is 1 (units sr^-1).

mu = cos(theta) is the cosine of the scattering angle between the incident propagation
direction and the scattered direction (mu = 1: forward). Each phase function is one class with
its kernels, written against an array namespace ``xp`` (NumPy, or Dr.Jit in the path tracer,
see :mod:`skyref.atmosphere.profiles`):

- ``evaluate(mu, xp)``: p(mu);
- ``sample_cosine(u, xp)``: mu drawn from the function's *sampling density* for u uniform in
  [0, 1) (Rayleigh and Henyey–Greenstein exactly; Cornette–Shanks and tabulated functions
  through a Henyey–Greenstein density, the difference carried by the weight p / pdf);
- ``pdf(mu, xp)``: that sampling density, sr^-1.

Keyword arguments override the function's own parameters with arrays of the namespace (``g``
as a Dr.Jit value, so that gradients with respect to it flow; a tabulated function's
``cosines`` and ``values`` as device tables).

- ``matrix(mu, xp)``: the elements of its phase matrix, for polarized transport.

References
----------
J. E. Hansen and L. D. Travis, "Light scattering in planetary atmospheres", Space Sci. Rev.
16 (1974) (the Rayleigh phase matrix with depolarization).

L. G. Henyey and J. L. Greenstein, "Diffuse radiation in the Galaxy", ApJ 93 (1941).

W. M. Cornette and J. G. Shanks, "Physically reasonable analytic expression for the
single-scattering phase function", Appl. Opt. 31(16) (1992).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from skyref.validation import check_array, check_choice, check_fields, check_number
from skyref.errors import ParameterError

__all__ = ["rayleigh_phase", "cornette_shanks_phase", "henyey_greenstein_phase", "sample_rayleigh_cosine",
           "sample_henyey_greenstein_cosine", "cornette_shanks_asymmetry", "PhaseFunction", "RayleighPhase", "MiePhase",
           "read_mie_table", "mie_lognormal",
           "CornetteShanks", "HenyeyGreenstein", "TabulatedPhase", "PHASE_TYPES", "phase_from_dict"]

INV_4PI = 1.0 / (4.0 * math.pi)


def rayleigh_phase(mu, xp=np):
    """Rayleigh (unpolarised, scalar): 3/(16 pi) (1 + mu^2)."""
    return (3.0 / (16.0 * math.pi)) * (1.0 + mu * mu)


def cornette_shanks_phase(mu, g, xp=np):
    """Cornette & Shanks 1992: 3/(8 pi) (1-g^2)/(2+g^2) (1+mu^2)/(1+g^2-2 g mu)^(3/2).

    Its ``g`` is *not* the asymmetry parameter <mu>; see :func:`cornette_shanks_asymmetry`.
    """
    g2 = g * g
    denom = 1.0 + g2 - 2.0 * g * mu
    return (3.0 / (8.0 * math.pi)) * (1.0 - g2) / (2.0 + g2) * (1.0 + mu * mu) / (denom * xp.sqrt(denom))


def henyey_greenstein_phase(mu, g, xp=np):
    """Henyey & Greenstein 1941: (1-g^2) / (4 pi (1+g^2-2 g mu)^(3/2)); here g = <mu>."""
    g2 = g * g
    denom = 1.0 + g2 - 2.0 * g * mu
    return INV_4PI * (1.0 - g2) / (denom * xp.sqrt(denom))


def sample_rayleigh_cosine(u, xp=np):
    """Invert the Rayleigh CDF F(mu) = (mu^3 + 3 mu + 4) / 8 exactly (Cardano): with
    v = 4u - 2 and B = cbrt(|v| + sqrt(v^2 + 1)), mu = sign(v) (B - 1/B)."""
    v = 4.0 * u - 2.0
    b = xp.cbrt(xp.abs(v) + xp.sqrt(v * v + 1.0))
    return xp.clip(xp.copysign(b - 1.0 / b, v), -1.0, 1.0)


def sample_henyey_greenstein_cosine(u, g, xp=np):
    """Invert the Henyey–Greenstein CDF: mu = (1 + g^2 - ((1 - g^2) / (1 - g + 2 g u))^2) / (2g),
    and mu = 2u - 1 for |g| < 1e-3."""
    sq = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
    mu = (1.0 + g * g - sq * sq) / (2.0 * g)
    return xp.clip(xp.where(xp.abs(g) < 1e-3, 2.0 * u - 1.0, mu), -1.0, 1.0)


def cornette_shanks_asymmetry(g: float) -> float:
    """Asymmetry parameter <mu> of the Cornette–Shanks function with parameter g:
    3 g (4 + g^2) / (5 (2 + g^2))."""
    return 3.0 * g * (4.0 + g * g) / (5.0 * (2.0 + g * g))


class PhaseFunction:
    """Base class (module docstring). Subclasses sampled through Henyey–Greenstein set
    :attr:`sampling_g`."""

    kind: str = ""

    def evaluate(self, mu, xp=np, **parameters):
        raise NotImplementedError

    @property
    def sampling_g(self) -> float:
        """The Henyey–Greenstein parameter of the sampling density."""
        raise NotImplementedError

    @property
    def has_forward_peak(self) -> bool:
        """Whether the function scatters mostly forwards (asymmetry parameter > 0: aerosols, not
        Rayleigh): the line integral aims its sun lobe at such peaks and guides paths only
        through the scattering without one."""
        return self.asymmetry > 0.0

    def sample_cosine(self, u, xp=np, g=None):
        return sample_henyey_greenstein_cosine(u, self.sampling_g if g is None else g, xp)

    def pdf(self, mu, xp=np, g=None):
        return henyey_greenstein_phase(mu, self.sampling_g if g is None else g, xp)

    def matrix(self, mu, xp=np, **parameters):
        """The phase matrix's independent elements (P11, P12, P22, P33, P34, P44), sr^-1, for
        Stokes vectors referred to the scattering plane (module docstring of
        :mod:`skyref.plugins.polarization`):
        [[P11 P12 0 0] [P12 P22 0 0] [0 0 P33 P34] [0 0 -P34 P44]]. This base version is for
        functions known by P11 alone (Cornette–Shanks, Henyey–Greenstein, a tabulated p): the
        light they scatter is unpolarized, whatever came in."""
        zero = 0.0 * mu
        return self.evaluate(mu, xp, **parameters), zero, zero, zero, zero, zero

    def to_dict(self) -> dict:
        raise NotImplementedError


@dataclass(frozen=True)
class RayleighPhase(PhaseFunction):
    """Rayleigh scattering by air molecules, with the molecules' anisotropy as a depolarization
    factor ``depolarization`` (rho in [0, 1); the King correction's 0.0279 is a common air
    value, 0 the ideal dipole that skyref's presets use as published).

    After Hansen & Travis (1974, eq. 2.15) the phase matrix is Delta x the ideal dipole's plus
    (1 - Delta) x an isotropic, unpolarized part (P11 only), Delta = (1 - rho) / (1 + rho / 2),
    and the circular element P44 carries a further Delta' = (1 - 2 rho) / (1 - rho); so
    p(mu) = Delta 3/(16 pi) (1 + mu^2) + (1 - Delta) / (4 pi). Its sampling is exact: the dipole
    part with probability Delta, a uniform direction otherwise."""

    depolarization: float = 0.0
    kind = "rayleigh"

    def __post_init__(self):
        check_number("depolarization", self.depolarization, 0.0, 1.0, hi_open=True)

    @property
    def dipole_share(self) -> float:
        """Delta: the ideal dipole's share of the phase function."""
        rho = self.depolarization
        return (1.0 - rho) / (1.0 + 0.5 * rho)

    def evaluate(self, mu, xp=np):
        share = self.dipole_share
        if share == 1.0:
            return rayleigh_phase(mu, xp)
        return share * rayleigh_phase(mu, xp) + (1.0 - share) * INV_4PI

    def matrix(self, mu, xp=np):
        rho = self.depolarization
        dipole = (3.0 / (16.0 * math.pi)) * self.dipole_share
        circular = (3.0 / (16.0 * math.pi)) * (1.0 - 2.0 * rho) / (1.0 + 0.5 * rho)    # Delta x Delta'
        return (self.evaluate(mu, xp), dipole * (mu * mu - 1.0), dipole * (1.0 + mu * mu), dipole * 2.0 * mu,
                0.0 * mu, circular * 2.0 * mu)

    def sample_cosine(self, u, xp=np):
        share = self.dipole_share
        if share == 1.0:
            return sample_rayleigh_cosine(u, xp)
        dipole = sample_rayleigh_cosine(xp.minimum(u / share, 1.0), xp)
        return xp.where(u < share, dipole, xp.clip(2.0 * (u - share) / (1.0 - share) - 1.0, -1.0, 1.0))

    def pdf(self, mu, xp=np):
        return self.evaluate(mu, xp)

    @property
    def asymmetry(self) -> float:
        return 0.0

    def to_dict(self):
        return {"type": self.kind, **({"depolarization": self.depolarization} if self.depolarization else {})}


@dataclass(frozen=True)
class CornetteShanks(PhaseFunction):
    """Cornette–Shanks with parameter g in (-1, 1) (not the asymmetry parameter)."""

    g: float = 0.8
    kind = "cornette_shanks"

    def __post_init__(self):
        check_number("g", self.g, -1.0, 1.0, lo_open=True, hi_open=True)

    def evaluate(self, mu, xp=np, g=None):
        return cornette_shanks_phase(mu, self.g if g is None else g, xp)

    @property
    def sampling_g(self) -> float:
        return self.g

    @property
    def asymmetry(self) -> float:
        return cornette_shanks_asymmetry(self.g)

    def to_dict(self):
        return {"type": self.kind, "g": self.g}


@dataclass(frozen=True)
class HenyeyGreenstein(PhaseFunction):
    """Henyey–Greenstein with asymmetry parameter g in (-1, 1)."""

    g: float = 0.8
    kind = "henyey_greenstein"

    def __post_init__(self):
        check_number("g", self.g, -1.0, 1.0, lo_open=True, hi_open=True)

    def evaluate(self, mu, xp=np, g=None):
        return henyey_greenstein_phase(mu, self.g if g is None else g, xp)

    @property
    def sampling_g(self) -> float:
        return self.g

    @property
    def asymmetry(self) -> float:
        return self.g

    def to_dict(self):
        return {"type": self.kind, "g": self.g}


@dataclass(frozen=True)
class TabulatedPhase(PhaseFunction):
    """p(mu) given at increasing mu in [-1, 1], interpolated linearly in mu and renormalised so
    that 2 pi * integral p dmu = 1 (e.g. a Mie computation with miepython)."""

    cosines: tuple
    values: tuple
    kind = "tabulated"

    def __post_init__(self):
        mu = check_array("cosines", self.cosines, -1.0, 1.0, min_length=2, increasing=True)
        p = check_array("values", self.values, 0.0, math.inf, min_length=2)
        if mu[0] != -1.0 or mu[-1] != 1.0 or p.size != mu.size:
            raise ParameterError("cosines", list(self.cosines), "from -1 to 1, one per value",
                                 "does not span [-1, 1] or pair up with values")
        norm = 2.0 * math.pi * float(np.sum(0.5 * (p[1:] + p[:-1]) * np.diff(mu)))
        if norm <= 0.0:
            raise ParameterError("values", list(self.values), "a phase function with a positive integral",
                                 "integrates to zero")
        object.__setattr__(self, "cosines", tuple(float(x) for x in mu))
        object.__setattr__(self, "values", tuple(float(x) / norm for x in p))

    def evaluate(self, mu, xp=np, cosines=None, values=None):
        return xp.interp(mu, self.cosines if cosines is None else cosines, self.values if values is None else values)

    @property
    def sampling_g(self) -> float:
        """Henyey–Greenstein with the table's asymmetry parameter, kept within [-0.95, 0.95]."""
        return float(np.clip(self.asymmetry, -0.95, 0.95))

    @property
    def asymmetry(self) -> float:
        mu = np.asarray(self.cosines)
        p = np.asarray(self.values) * mu
        return 2.0 * math.pi * float(np.sum(0.5 * (p[1:] + p[:-1]) * np.diff(mu)))

    def to_dict(self):
        return {"type": self.kind, "cosines": list(self.cosines), "values": list(self.values)}


@dataclass(frozen=True)
class MiePhase(TabulatedPhase):
    """The phase matrix of spherical particles (Mie theory), tabulated at increasing ``cosines``
    in [-1, 1]: P11 (``values``), P12, P33 and P34 (for spheres P22 = P11 and P44 = P33), in any
    common normalisation (all four are scaled by the factor that normalises P11), interpolated
    linearly in mu and sampled like :class:`TabulatedPhase`. Polarized transport uses the whole
    matrix; scalar transport P11. :func:`read_mie_table` reads one from a libRadtran netCDF file
    (IPRT's ``waso.mie.cdf``)."""

    p12: tuple = ()
    p33: tuple = ()
    p34: tuple = ()
    kind = "mie"

    def __post_init__(self):
        raw = check_array("values", self.values, 0.0, math.inf, min_length=2)
        super().__post_init__()
        scale = float(np.max(self.values)) / float(np.max(raw))
        for name in ("p12", "p33", "p34"):
            element = check_array(name, getattr(self, name), -math.inf, math.inf, min_length=2)
            if element.size != raw.size:
                raise ParameterError(name, list(getattr(self, name))[:4], f"{raw.size} numbers, one per cosine",
                                     f"{element.size} values")
            if np.any(np.abs(element) > raw * (1.0 + 1e-4) + 1e-12 * raw.max()):
                raise ParameterError(name, list(getattr(self, name))[:4], "|P| <= P11 at every angle",
                                     "not a phase matrix of a particle")
            object.__setattr__(self, name, tuple(float(x) * scale for x in element))

    def matrix(self, mu, xp=np, cosines=None, values=None, p12=None, p33=None, p34=None):
        cosines = self.cosines if cosines is None else cosines

        def element(table, own):
            return xp.interp(mu, cosines, own if table is None else table)

        p11 = self.evaluate(mu, xp, cosines, values)
        p33_mu = element(p33, self.p33)
        return p11, element(p12, self.p12), p11, p33_mu, element(p34, self.p34), p33_mu

    def to_dict(self):
        return {**super().to_dict(), "p12": list(self.p12), "p33": list(self.p33), "p34": list(self.p34)}


def read_mie_table(path) -> tuple:
    """A :class:`MiePhase` and the single-scattering albedo from a libRadtran Mie-tool netCDF
    file (variables ``theta`` in degrees and ``phase`` holding P1, P2, P3, P4 of the matrix
    [[P1 P2 0 0] [P2 P1 0 0] [0 0 P3 P4] [0 0 -P4 P3]], each on its own angle grid padded with
    -999, and ``ssa``; the first wavelength and size). The elements are put on the union of
    their grids."""
    from scipy.io import netcdf_file

    try:
        with netcdf_file(path, "r", mmap=False) as data:
            angles = data.variables["theta"].shape[-1]      # (wavelength, size, element, angle)
            theta = np.asarray(data.variables["theta"][:], np.float64).reshape(-1, 4, angles)[0]
            phase = np.asarray(data.variables["phase"][:], np.float64).reshape(-1, 4, angles)[0]
            albedo = float(np.asarray(data.variables["ssa"][:]).ravel()[0])
    except (OSError, KeyError, TypeError, ValueError) as exc:
        raise ParameterError("mie table", str(path), "a libRadtran Mie netCDF file with theta, phase and ssa",
                             f"unreadable: {exc}") from None
    grids = []
    for t, p in zip(theta, phase):
        mu = np.cos(np.radians(t[t > -900.0]))
        order = np.argsort(mu)
        grids.append((mu[order], p[t > -900.0][order]))
    cosines = np.unique(np.clip(np.concatenate([mu for mu, _ in grids]), -1.0, 1.0))
    elements = [np.interp(cosines, mu, p) for mu, p in grids]
    return MiePhase(tuple(cosines), tuple(elements[0]), tuple(elements[1]), tuple(elements[2]),
                    tuple(elements[3])), albedo


def mie_lognormal(wavelength_nm: float, refractive_index: complex, mode_radius_um: float, geometric_std: float,
                  max_radius_um: float = 5.0, radii: int = 400, cosines: int = 721) -> tuple:
    """A :class:`MiePhase` and the single-scattering albedo of spheres whose number density
    follows a lognormal distribution, dN/dln r ~ exp(-(ln r - ln r_mode)^2 / (2 ln^2 sigma)),
    up to ``max_radius_um``, at one wavelength, by Mie theory (miepython; Bohren & Huffman's
    amplitudes S1, S2: P11 = (|S1|^2 + |S2|^2) / 2, P12 = (|S2|^2 - |S1|^2) / 2,
    P33 = Re(S2 S1*), P34 = Im(S2 S1*), each weighted by the particles' scattering cross
    sections). ``refractive_index`` n + i k of the particles relative to the air, k >= 0 for
    absorbing ones (e.g. OPAC's water-soluble aerosol at 50% humidity, 350 nm: 1.422 + 0.00265i,
    mode radius 0.0262 um, sigma 2.24). The matrix is tabulated at ``cosines`` points uniform in
    the scattering angle; the sizes are integrated in ln r with ``radii`` points."""
    import miepython

    index = complex(refractive_index)
    check_number("wavelength_nm", wavelength_nm, 100.0, 100_000.0)
    check_number("refractive_index.real", index.real, 1.0, 5.0, lo_open=True)
    check_number("refractive_index.imag", index.imag, 0.0, 10.0)
    check_number("mode_radius_um", mode_radius_um, 1e-4, 100.0)
    check_number("geometric_std", geometric_std, 1.0, 5.0, lo_open=True)
    check_number("max_radius_um", max_radius_um, mode_radius_um, 1000.0, lo_open=True)
    log_sigma = math.log(geometric_std)
    log_r = np.linspace(math.log(mode_radius_um) - 5.0 * log_sigma, math.log(max_radius_um), int(radii))
    number = np.exp(-0.5 * ((log_r - math.log(mode_radius_um)) / log_sigma) ** 2)
    weights = number * np.gradient(log_r)                          # dN per ln r step
    theta = np.linspace(math.pi, 0.0, int(cosines))
    mu = np.cos(theta)
    mu[0], mu[-1] = -1.0, 1.0
    elements = np.zeros((4, mu.size))
    scattering = extinction = 0.0
    for r, w in zip(np.exp(log_r), weights):
        x = 2.0 * math.pi * r / (wavelength_nm * 1e-3)
        m = complex(index.real, -index.imag)                      # miepython's sign of k
        q_ext, q_sca, _, _ = miepython.efficiencies_mx(m, x)
        s1, s2 = miepython.S1_S2(m, x, mu, norm="qsca")           # integrates to Q_sca over the sphere
        area = w * math.pi * r * r
        elements += area * np.array([0.5 * (abs(s1) ** 2 + abs(s2) ** 2), 0.5 * (abs(s2) ** 2 - abs(s1) ** 2),
                                     (s2 * np.conj(s1)).real, (s2 * np.conj(s1)).imag])
        scattering += area * q_sca
        extinction += area * q_ext
    return MiePhase(tuple(mu), *(tuple(e) for e in elements)), scattering / extinction


PHASE_TYPES = {cls.kind: cls for cls in (RayleighPhase, CornetteShanks, HenyeyGreenstein, TabulatedPhase, MiePhase)}


def phase_from_dict(data: dict) -> PhaseFunction:
    fields = dict(data)
    kind = check_choice("phase.type", fields.pop("type", None), tuple(PHASE_TYPES))
    check_fields("phase", fields, PHASE_TYPES[kind])
    if kind in (TabulatedPhase.kind, MiePhase.kind):
        return PHASE_TYPES[kind](**{key: tuple(value) for key, value in fields.items()})
    return PHASE_TYPES[kind](**fields)
