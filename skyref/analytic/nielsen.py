"""Nielsen 2003, "Real Time Rendering of Atmospheric Scattering Effects for Flight Simulators"
(M.Sc. thesis, DTU): Hoffman & Preetham's model made altitude-aware.

Hoffman–Preetham assume air of constant density, which fails for an observer in an aircraft.
Nielsen keeps their extinction and in-scattering equations (see
:mod:`skyref.analytic.hoffman_preetham`) but takes the optical depth from the exponential density
integrated along the path. For a straight path of length s from altitude h0 to h1 through
horizontally stratified air (altitude linear along the path), the integral is exact:

    integral_0^s exp(-h/H) ds = s H (exp(-h0/H) - exp(-h1/H)) / (h1 - h0)
                              = s exp(-h0/H) (1 - exp(-x)) / x,   x = (h1 - h0) / H,

so tau_i = k_i s exp(-h0/H_i) (1 - exp(-x_i)) / x_i per constituent (the second form is the one
computed: it has the limit s exp(-h0/H) on horizontal paths).

What skyref derives where the thesis' description is incomplete:

- Sky-dome optical depth: a view ray that misses the ground ends where it leaves the atmosphere
  (the "sky dome" is the top sphere); s and h1 come from the spherical geometry, the density
  integral from the flat-air formula above. This is exact straight up and underestimates
  grazing paths, where altitude grows quadratically along the ray: from the ground at the horizon
  it gives 117 km of sea-level-equivalent air for Rayleigh (H 8 km, top 60 km) where the
  spherical integral is 283 km.
- The sun: E_sun = E_0 exp(-tau_sun) with the same estimate along the path from the observer to
  the top of the atmosphere towards the sun (0 if the planet hides it); one E_sun lights the whole
  view ray, as in Hoffman–Preetham; the ground point of a view ray gets its own.
- In-scattering with constituents of different scale heights: Hoffman–Preetham's weighting by each
  constituent's share of the optical depth (the exact integral if the composition along the path
  were constant); the Mie phase function is Henyey–Greenstein with the atmosphere's aerosol
  asymmetry parameter.
- Constituents: those with exponential profiles; an absorber with another profile (the ozone tent)
  is ignored and listed in ``options["ignored_constituents"]``; a scatterer with another profile is
  refused (ParameterError).

Validity: any observer altitude (aircraft to space) and sun position; finite and non-negative
everywhere.

References
----------
R. S. Nielsen, "Real Time Rendering of Atmospheric Scattering Effects for Flight Simulators", MSc
thesis, Technical University of Denmark, 2003.

N. Hoffman, A. J. Preetham, "Rendering Outdoor Light Scattering in Real Time", Game Developers
Conference 2002.
"""

from __future__ import annotations

from skyref.analytic.base import Component, altitude_along_ray, exponential_components, one_minus_exp_over
from skyref.analytic.hoffman_preetham import HoffmanPreetham2002

__all__ = ["Nielsen2003"]


class Nielsen2003(HoffmanPreetham2002):
    """Hoffman–Preetham with optical depths of exponential density (see the module's
    documentation)."""

    name = "nielsen2003"

    def _model_components(self):
        return exponential_components(self.atmosphere, self.wavelengths_nm, "Nielsen 2003")

    def column(self, component: Component, altitude, mu, length):
        """Flat-air integral of exp(-h/H) over ``length`` metres from ``altitude`` to the
        altitude the ray reaches there (spherical geometry)."""
        end_altitude = altitude_along_ray(self.bottom_radius + altitude, mu, length, self.bottom_radius)
        x = (end_altitude - altitude) / component.scale_height_m
        return length * component.profile.density(altitude) * one_minus_exp_over(x)
