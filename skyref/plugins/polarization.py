"""Polarized transport on a backward path: Stokes vectors, reference frames, Mueller matrices.

Conventions (one home for them; tests/test_polarization.py checks them, and the IPRT
comparison, tests/test_iprt.py, fixes the sign of U against MYSTIC's):

* A **Stokes vector** (I, Q, U, V) describes light propagating along a unit vector omega,
  referred to a **frame**: a unit vector ``e_perp`` perpendicular to omega, and
  e_par = omega x e_perp. Q = I_par - I_perp, U = I(+45 deg) - I(-45 deg), +45 deg being
  (e_par + e_perp) / sqrt(2).
* The frame of a **viewing direction** d (light reaching the observer propagates along -d) is
  the *meridian frame*: e_par in the vertical plane through d, e_perp = normalize(d x up)
  horizontal. Looking north at the horizon, e_par points up and e_perp east: U > 0 is light
  polarized along the upper-right diagonal as the observer sees it. This is MYSTIC's sign of U
  (IPRT case A1; azimuths clockwise from north in both). Looking
  straight up or down the meridian plane is undefined; a direction a hair off the vertical
  picks one.
* **Scattering** from propagation direction omega_i into omega_o (cos Theta = omega_i . omega_o)
  maps Stokes vectors referred to the *scattering-plane frames* (e_perp = normalize(omega_i x
  omega_o) for both) through the phase matrix F = [[P11 P12 0 0] [P12 P22 0 0] [0 0 P33 P34]
  [0 0 -P34 P44]] (:meth:`skyref.atmosphere.phase.PhaseFunction.matrix`).
* **Changing frames** of the same direction: if the new e_par is cos(eta) e_par + sin(eta)
  e_perp of the old one, S_new = L(eta) S_old with L(eta) = [[1 0 0 0] [0 c s 0] [0 -s c 0]
  [0 0 0 1]], c = cos 2 eta, s = sin 2 eta.
* A **Lambertian surface** reflects unpolarized light whatever comes in: its Mueller matrix is
  (albedo / pi) cos(theta_i) diag(1, 0, 0, 0).

A path traced from the camera carries the Mueller matrix T that maps the Stokes vector of light
propagating back along its current segment (referred to the segment's frame) to the Stokes
vector the camera sees (referred to its meridian frame). T is written w N: w is the path's
scalar throughput, which the estimators update as in scalar transport (the (0, 0) element of
T: unpolarized light in, radiance out), and N, with N00 = 1, is kept by :class:`StokesPath`.
Every element of a product of phase matrices and rotations is bounded by its (0, 0) element,
so Russian roulette and the tracking's probabilities keep working on w.

References
----------
J. W. Hovenier, C. van der Mee and H. Domke, "Transfer of Polarized Light in Planetary
Atmospheres", Kluwer (2004) (frames, rotations, phase matrices).

A. Fichet, R. Pacanowski and A. Wilkie, "An OpenEXR layout for spectral images", JCGT 10(3)
(2021) (the S0-S3 output layers, :mod:`skyref.exr`).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from skyref.sky import STOKES

__all__ = ["STOKES", "meridian_frame", "StokesPath", "unpolarized", "stokes_times"]


def meridian_frame(d, up):
    """e_perp of the meridian frame of viewing direction ``d`` (unit; light propagating along
    -d) at a point whose local vertical is ``up``: normalize(d x up); for d (anti)parallel to up,
    any unit vector perpendicular to d."""
    e_perp = dr.cross(d, up)
    norm = dr.norm(e_perp)
    return dr.select(norm > 1e-12, e_perp / dr.maximum(norm, 1e-30), mi.coordinate_system(d)[0])


def _rotation(e_perp_from, e_perp_to, omega):
    """(cos 2 eta, sin 2 eta) of the rotation L(eta) from the frame ``e_perp_from`` to the frame
    ``e_perp_to`` of the same propagation direction ``omega``: cos eta = e_par_to . e_par_from =
    e_perp_to . e_perp_from, sin eta = e_par_to . e_perp_from."""
    cos_eta = dr.dot(e_perp_to, e_perp_from)
    sin_eta = dr.dot(dr.cross(omega, e_perp_to), e_perp_from)
    return cos_eta * cos_eta - sin_eta * sin_eta, 2.0 * cos_eta * sin_eta


def unpolarized(intensity):
    """The Stokes vector (I, 0, 0, 0) per channel, packed like :class:`StokesPath`'s outputs:
    an ArrayXf of 4 K values, component-major."""
    return mi.ArrayXf([*intensity, *(mi.Float(0.0) for _ in range(3 * len(intensity)))])


def stokes_times(stokes, scalar):
    """Stokes vectors (4 K packed values) times a per-channel scalar (K values)."""
    k = len(scalar)
    return mi.ArrayXf([stokes[i] * scalar[i % k] for i in range(4 * k)])


class StokesPath:
    """The polarization a backward path carries (module docstring): ``frame``, the e_perp of its
    current segment's frame, and ``matrix``, N per channel (16 K values: element (i, j) of
    channel k at (4 i + j) K + k; N00 = 1)."""

    DRJIT_STRUCT = {"frame": mi.Vector3f, "matrix": mi.ArrayXf}

    def __init__(self, frame=None, matrix=None):
        self.frame, self.matrix = frame, matrix

    @staticmethod
    def camera(d, up, channels: int) -> "StokesPath":
        """A path leaving the camera along ``d``: the meridian frame and N = identity."""
        return StokesPath(meridian_frame(d, up), mi.ArrayXf([mi.Float(1.0 if i // 4 == i % 4 else 0.0)
                                                             for i in range(16) for _ in range(channels)]))

    def _elements(self):
        """N as a 4 x 4 nested list of per-channel lists."""
        k = len(self.matrix) // 16
        return [[[self.matrix[(4 * i + j) * k + c] for c in range(k)] for j in range(4)] for i in range(4)]

    def _scattered_columns(self, towards, d):
        """The columns of N L(eta) for light scattered from propagation direction -towards into
        -d, the path's current direction reversed: the scattering plane's e_perp and the first
        two columns of N L (the last two follow from them, see :meth:`scatter`)."""
        omega_in, omega_out = -towards, -d
        normal = dr.cross(omega_in, omega_out)
        norm = dr.norm(normal)
        # Forward or backward scattering: every frame is a scattering-plane frame; keep ours.
        e_perp = dr.select(norm > 1e-7, normal / dr.maximum(norm, 1e-30), self.frame)
        c, s = _rotation(e_perp, self.frame, omega_out)
        n = self._elements()
        column1 = [[c * a - s * b for a, b in zip(n[i][1], n[i][2])] for i in range(4)]
        column2 = [[s * a + c * b for a, b in zip(n[i][1], n[i][2])] for i in range(4)]
        return e_perp, n, column1, column2

    def scattered_source(self, towards, d, reduced):
        """The Stokes vectors (4 K packed values, component-major) per unit w of an unpolarized
        source along ``towards`` (unit, the direction light comes from) scattered into the path,
        given the phase matrix ``reduced`` = (P12, P22, P33, P34, P44) / P11 per channel at their
        scattering angle: N L(eta) (1, P12 / P11, 0, 0)^T."""
        _, n, column1, _ = self._scattered_columns(towards, d)
        f12 = reduced[0]
        return mi.ArrayXf([n[i][0][c] + f12[c] * column1[i][c] for i in range(4) for c in range(len(f12))])

    def unpolarized_source(self):
        """The Stokes vectors (4 K packed values) per unit w of unpolarized light arriving along
        the current segment (a Lambertian surface's): N (1, 0, 0, 0)^T, the first column."""
        n = self._elements()
        return mi.ArrayXf([n[i][0][c] for i in range(4) for c in range(len(n[0][0]))])

    def scatter(self, towards, d, reduced, active):
        """Where ``active``, the path scatters from direction ``d`` into ``towards``: N becomes
        N L(eta) F / F11, renormalised so that N00 = 1, in the scattering plane's frame.
        Returns that StokesPath and the factor (N L F / F11)_00 per channel by which w must be
        multiplied (1 where not active)."""
        e_perp, n, column1, column2 = self._scattered_columns(towards, d)
        f12, f22, f33, f34, f44 = reduced
        channels = range(len(f12))
        product = [[[n[i][0][c] + f12[c] * column1[i][c] for c in channels],
                    [f12[c] * n[i][0][c] + f22[c] * column1[i][c] for c in channels],
                    [f33[c] * column2[i][c] - f34[c] * n[i][3][c] for c in channels],
                    [f34[c] * column2[i][c] + f44[c] * n[i][3][c] for c in channels]] for i in range(4)]
        factor = [dr.select(active, product[0][0][c], 1.0) for c in channels]
        inverse = [dr.rcp(dr.maximum(x, 1e-30)) for x in factor]
        matrix = mi.ArrayXf([product[i][j][c] * inverse[c] for i in range(4) for j in range(4) for c in channels])
        return (StokesPath(dr.select(active, e_perp, self.frame), dr.select(active, matrix, self.matrix)),
                mi.ArrayXf(factor))

    def reflect(self, active):
        """Where ``active``, a Lambertian reflection: the light leaving the surface is
        unpolarized, so only N's first column survives (w takes the albedo, as in scalar
        transport). Returns the StokesPath after it."""
        k = len(self.matrix) // 16
        keep = mi.ArrayXf([mi.Float(1.0) if (i // k) % 4 == 0 else mi.Float(0.0) for i in range(16 * k)])
        return StokesPath(self.frame, dr.select(active, self.matrix * keep, self.matrix))
