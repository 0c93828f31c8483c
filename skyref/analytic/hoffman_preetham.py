"""Hoffman & Preetham 2002, "Rendering Outdoor Light Scattering in Real Time" (GDC 2002 notes).

Light reaching the eye along a path of length s through air of constant density is the light of
the object at its end, attenuated, plus sunlight scattered into the path (the notes' extinction
and in-scattering equations):

    L = L_0 F_ex + L_in,   F_ex = exp(-(b_R + b_M) s),
    L_in = (b_R(theta) + b_M(theta)) / (b_R + b_M) * E_sun * (1 - F_ex),

with b_R, b_M the Rayleigh and Mie coefficients, b(theta) = b p(theta) their angular scattering
coefficients (Rayleigh 3/(16 pi)(1 + cos^2 theta); Mie Henyey–Greenstein, here normalised:
(1 - g^2) / (4 pi (1 + g^2 - 2 g cos theta)^(3/2))), theta the angle between the view and the sun
and E_sun the sun's irradiance, itself attenuated by extinction on its way in. The same equations colour distant objects (aerial perspective) and the sky.

How skyref puts it on a spherical :class:`~skyref.atmosphere.Atmosphere` (what the notes leave open):

- Constant density: each constituent keeps its density at the ground, filling a homogeneous
  layer of the thickness that holds its real vertical column, Z_i = column_i / rho_i(0) (~ its
  scale height H_i; Rayleigh 8 km, aerosol 1.2 km). The optical depth along a path is
  tau_i = k_i * (length of the path inside layer i), so near the ground tau = (b_R + b_M) s exactly
  as in the notes, and straight up it is the real vertical optical depth. Constituents absent at the
  ground (the ozone layer) have no constant-density equivalent and are ignored (listed in
  ``options["ignored_constituents"]``).
- Sky: the view ray runs to the top of the atmosphere (or the ground); the layers bound its optical
  depth, so no arbitrary sky-dome distance enters.
- Unequal path lengths per constituent: with tau = sum_i tau_i the in-scattering becomes
  L_in = E_sun sum_i omega_i p_i(theta) tau_i / tau * (1 - exp(-tau)) (omega_i the single-scattering
  albedo), which is the notes' formula when every constituent sees the same s and does not absorb.
  It is the exact single-scattering integral when the mixture's composition and the sunlight are
  the same all along the path.
- E_sun = E_0 exp(-tau_sun): extinction along the path from the observer to the sun (0 if the planet
  blocks it); the same E_sun lights the whole view ray.
- Ground: a view ray that hits it sees L_0 = albedo / pi * E_sun(ground) * cos(sun zenith there),
  a Lambertian ground lit by the sun alone, with E_sun computed at the ground point.
- Mie phase: Henyey–Greenstein with the asymmetry parameter <cos> of the atmosphere's aerosol phase
  function (0.844 for skyref's Cornette–Shanks g = 0.8).

Validity: meant for observers near the ground (constant density); it stays finite and
non-negative for every observer and sun (the sky is black where the planet shadows the observer).

References
----------
N. Hoffman, A. J. Preetham, "Rendering Outdoor Light Scattering in Real Time", Game Developers
Conference 2002.

L. G. Henyey, J. L. Greenstein, "Diffuse radiation in the Galaxy", ApJ 93, 1941.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from skyref.analytic.base import (PER_VIEW_IN_LOOKUP, AnalyticModel, Component, atmosphere_segment,
                                  components, altitude_along_ray, one_minus_exp_over, phase_values,
                                  sphere_distances, sun_cosine_along_ray, zenith_cosine_along_ray)
from skyref.atmosphere.phase import HenyeyGreenstein
from skyref.sky_method import Operations

__all__ = ["henyey_greenstein_aerosols", "HoffmanPreetham2002"]


def henyey_greenstein_aerosols(items: list[Component]) -> list[Component]:
    """The components with every aerosol's phase function replaced by Henyey–Greenstein of the
    same asymmetry parameter (the notes' Mie phase function)."""
    return [dataclasses.replace(c, phase=HenyeyGreenstein(c.phase.asymmetry)) if c.kind == "aerosol" else c
            for c in items]


class HoffmanPreetham2002(AnalyticModel):
    """The Hoffman–Preetham sky and aerial perspective (see the module's documentation)."""

    name = "hoffman_preetham2002"

    def __init__(self, atmosphere, wavelengths_nm="rgb"):
        super().__init__(atmosphere, wavelengths_nm)
        kept, ignored = self._model_components()
        self.components = henyey_greenstein_aerosols(kept)
        self.ground_albedo = atmosphere.ground_albedo(self.wavelengths_nm)
        self.options = {"henyey_greenstein_g": {c.name: c.phase.g for c in self.components if c.kind == "aerosol"}}
        if ignored:
            self.options["ignored_constituents"] = ignored

    # --- what a subclass changes: which constituents, and the column along a path --------------

    def _model_components(self) -> tuple[list[Component], list[str]]:
        """Constituents present at the ground, and the names of those that are not."""
        kept, ignored = [], []
        for c in components(self.atmosphere, self.wavelengths_nm):
            if float(c.profile.density(0.0)) > 0.0:
                kept.append(c)
            else:
                ignored.append(c.name)
        return kept, ignored

    def layer_thickness(self, component: Component) -> float:
        """Z_i: the thickness of the homogeneous layer at ground density that holds the
        constituent's vertical column through the atmosphere, m."""
        column = component.profile.column(0.0, self.atmosphere.thickness_m)
        return column / float(component.profile.density(0.0))

    def column(self, component: Component, altitude, mu, length) -> np.ndarray:
        """Path integral of the constituent's relative density (m) over ``length`` metres of the
        rays starting at ``altitude`` with zenith cosine ``mu``: here the length of the path inside
        the homogeneous layer (density 1 inside, 0 above)."""
        near, far = sphere_distances(self.bottom_radius + altitude, mu,
                                     self.bottom_radius + self.layer_thickness(component), self.bottom_radius)
        inside = np.minimum(np.nan_to_num(far), length) - np.maximum(np.nan_to_num(near), 0.0)
        return np.maximum(inside, 0.0)

    # --- the model ---------------------------------------------------------------------------

    def _segment_columns(self, r, mu, segment) -> list[np.ndarray]:
        """The columns of every component along each ray's segment inside the atmosphere."""
        altitude = altitude_along_ray(r, mu, segment.start, self.bottom_radius)
        mu_start = zenith_cosine_along_ray(r, mu, segment.start)
        return [self.column(c, altitude, mu_start, segment.end - segment.start) for c in self.components]

    def _optical_depth(self, columns, rays: int) -> np.ndarray:
        """tau (rays, N) = sum_i k_t,i C_i of the columns C_i (rays,) of every component."""
        return sum((c.extinction * column[:, None] for c, column in zip(self.components, columns)),
                   np.zeros((rays, self.wavelengths_nm.size)))

    def sun_irradiance(self, r, mu_s) -> np.ndarray:
        """E_sun at points at radius ``r`` (m) with the sun at zenith cosine ``mu_s`` (arrays of
        shape (K,)): E_0 exp(-tau_sun), 0 where the planet hides the sun; (K, N) W m^-2 nm^-1."""
        r, mu_s = np.broadcast_arrays(np.asarray(r, float), np.asarray(mu_s, float))
        segment = atmosphere_segment(r, mu_s, self.bottom_radius, self.top_radius)
        tau = self._optical_depth(self._segment_columns(r, mu_s, segment), r.size)
        return np.where(segment.ground[:, None], 0.0, self.solar_irradiance * np.exp(-tau))

    def operations(self) -> Operations:
        """Per direction: the path's column of every constituent (:meth:`column`, closed form)
        and one exponential per wavelength; a ground view adds the columns towards the sun from
        the ground point. Per view: the columns towards the sun from the observer."""
        columns = len(self.components)
        return Operations(sky={"constituent columns (closed form)": columns},
                          ground={"constituent columns (closed form)": 2 * columns},
                          per_view={"constituent columns (closed form)": columns}, note=PER_VIEW_IN_LOOKUP)

    def _radiance(self, r, mu, mu_s, nu):
        segment = atmosphere_segment(r, mu, self.bottom_radius, self.top_radius)
        columns = self._segment_columns(r, mu, segment)
        tau = self._optical_depth(columns, mu.size)
        scattered = sum((c.scattering * (phase_values(c, nu) * column)[:, None]
                         for c, column in zip(self.components, columns)), np.zeros_like(tau))
        e_sun = self.sun_irradiance(np.array([r]), np.array([mu_s]))
        # sum_i omega_i p_i tau_i / tau (1 - exp(-tau)) = sum_i k_s,i p_i C_i (1 - exp(-tau)) / tau
        radiance = e_sun * scattered * one_minus_exp_over(tau)
        # Aerial perspective of the ground: L_0 F_ex, L_0 the sunlit Lambertian ground.
        ground = np.flatnonzero(segment.ground)
        if ground.size:
            r_g = np.full(ground.size, self.bottom_radius)
            mu_s_g = sun_cosine_along_ray(r, mu[ground], mu_s, nu[ground], segment.end[ground])
            l_0 = self.ground_albedo / np.pi * self.sun_irradiance(r_g, mu_s_g) * np.maximum(mu_s_g, 0.0)[:, None]
            radiance[ground] += l_0 * np.exp(-tau[ground])
        return radiance
