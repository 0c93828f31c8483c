"""O'Neil 2005, "Accurate Atmospheric Scattering" (GPU Gems 2, chapter 16): Nishita et al.'s single
scattering evaluated per vertex with a handful of samples, the sun table replaced by a fitted
function.

The scale function (section 16.4, "eliminating one dimension"): the density integral from altitude
h to the top of the atmosphere along a ray at angle theta to the zenith is approximated by

    integral rho ds ~ exp(-h/H) scale(cos theta),
    scale(cos theta) = H exp(c0 + c1 x + c2 x^2 + c3 x^3 + c4 x^4),  x = 1 - cos theta,

i.e. the ground-level integral, scaled by the density at h. O'Neil fitted (c0..c4) = (-0.00287,
0.459, 3.83, -6.80, 5.25) for his atmosphere only: scale height 1/4 of its thickness, thickness
2.5% of the planet's radius ("published"). skyref refits the same form by least squares on
log(integral / H) over x in [0, 1] for each constituent of the atmosphere at hand ("refit", the
procedure the chapter describes for other atmospheres); the fit's largest relative error is kept in
``options["scale_fit_max_error"]`` (Earth: ~17% for Rayleigh, ~45% for the 1.2 km aerosol, both at
the horizon, where the quartic cannot follow a 35-fold (91-fold) rise).

In- and out-scattering (section 16.3 and the chapter's shaders): the view ray inside the
atmosphere is split into n equal steps and sampled at their midpoints P_k (``samples``; the book's
shaders use n = 2). The optical depth of sunlight scattered at P_k towards the camera C is

    sky rays:    t_k = rho(C) scale(cos theta_C) + rho(P_k) (scale(cos theta_sun,k) - scale(cos theta_k))
    ground rays: t_k = rho(P_k) (scale(cos theta_sun,G) + scale(cos theta_G)) - rho(C) scale(cos theta_G)

(theta_k the ray's zenith angle at P_k, C the camera or the ray's entry into the atmosphere; for
rays that end on the ground at G, O'Neil's ground shaders use the angles at G, with the ray reversed
so that scale() sees upward directions). Each constituent i has its own density and scale
function and t_k(lambda) = sum_i k_t,i t_k,i. Then

    L = E_0 sum_i k_s,i p_i(theta) sum_k rho_i(P_k) exp(-t_k) ds,

with the Rayleigh phase function and the Cornette–Shanks-style Mie phase
3 (1 - g^2) / (2 (2 + g^2)) (1 + cos^2) / (1 + g^2 - 2 g cos)^(3/2) / (4 pi) (O'Neil's getMiePhase,
normalised), taken from the atmosphere (skyref's aerosols default to exactly that function, g 0.8).
O'Neil's K_r, K_m and ESun are replaced by the atmosphere's coefficients and the solar spectrum.

Where skyref departs from the shaders: the ground (rays that end on it) is a sunlit Lambertian
reflector attenuated by exp(-t) at G, and its in-scattering keeps the phase functions (O'Neil's
ground shader drops them); optical depths are clamped at >= 0, which the scale differences can
violate where the fit is extrapolated (x > 1: the sun below the local horizon, which O'Neil relies
on as the planet's shadow, and rays below the horizontal from an aircraft).

Constituents: exponential profiles; absorbers with other profiles (the ozone tent) are ignored
(``options["ignored_constituents"]``). Validity: any observer and sun; finite and non-negative.

References
----------
S. O'Neil, "Accurate Atmospheric Scattering", GPU Gems 2, chapter 16, Addison-Wesley, 2005.

T. Nishita, T. Sirai, K. Tadamura, E. Nakamae, "Display of the Earth Taking into Account Atmospheric
Scattering", SIGGRAPH 93, 1993.
"""

from __future__ import annotations

import numpy as np

from skyref.analytic.base import (AnalyticModel, altitude_along_ray, atmosphere_segment,
                                  column_along_rays, exponential_components, per_component,
                                  phase_values, sphere_distances, sun_cosine_along_ray,
                                  zenith_cosine_along_ray)
from skyref.sky_method import Operations
from skyref.validation import check_choice, check_number
from skyref.errors import ParameterError

__all__ = ["PUBLISHED_SCALE_COEFFICIENTS", "PUBLISHED_SCALE_DEPTH", "PUBLISHED_THICKNESS_RATIO", "MAX_LOG_SCALE",
           "SCALE_FUNCTIONS", "ONeil2005"]

#: O'Neil's fitted coefficients c0..c4 of log(scale / H) in x = 1 - cos theta.
PUBLISHED_SCALE_COEFFICIENTS = (-0.00287, 0.459, 3.83, -6.80, 5.25)
#: The atmosphere the published fit is for: scale height / thickness, thickness / planet radius.
PUBLISHED_SCALE_DEPTH = 0.25
PUBLISHED_THICKNESS_RATIO = 0.025
#: log(scale / H) is capped here (exp(300) ~ 1e130: no sunlight, and no overflow in differences).
MAX_LOG_SCALE = 300.0
SCALE_FUNCTIONS = ("refit", "published")


class ONeil2005(AnalyticModel):
    """O'Neil's GPU Gems 2 atmospheric scattering (see the module's documentation).

    ``samples``: midpoint samples per view ray (the book's shaders: 2); ``scale_function``:
    "refit" (fit O'Neil's form to this atmosphere in :meth:`precompute`) or "published" (his
    coefficients; only for an atmosphere of his proportions).
    """

    name = "oneil2005"

    def __init__(self, atmosphere, wavelengths_nm="rgb", samples: int = 2, scale_function: str = "refit"):
        super().__init__(atmosphere, wavelengths_nm)
        self.samples = int(check_number("samples", samples, 1, 1024))
        self.scale_function = check_choice("scale_function", scale_function, SCALE_FUNCTIONS)
        self.components, ignored = exponential_components(atmosphere, self.wavelengths_nm, "O'Neil 2005")
        self.ground_albedo = atmosphere.ground_albedo(self.wavelengths_nm)
        self.options = {"samples": self.samples, "scale_function": self.scale_function}
        if ignored:
            self.options["ignored_constituents"] = ignored
        if self.scale_function == "published":
            self._check_published_proportions()
        self.scale_coefficients = None

    def _check_published_proportions(self):
        thickness = self.atmosphere.thickness_m
        ratio = thickness / self.bottom_radius
        if abs(ratio / PUBLISHED_THICKNESS_RATIO - 1.0) > 1e-3:
            raise ParameterError("atmosphere (top - bottom) / bottom radius", ratio,
                                 f"{PUBLISHED_THICKNESS_RATIO:g} for scale_function='published'",
                                 "O'Neil's fit is for another atmosphere; use scale_function='refit'")
        for c in self.components:
            depth = c.scale_height_m / thickness
            if abs(depth / PUBLISHED_SCALE_DEPTH - 1.0) > 1e-3:
                raise ParameterError(f"{c.name} scale height / thickness", depth,
                                     f"{PUBLISHED_SCALE_DEPTH:g} for scale_function='published'",
                                     "O'Neil's fit is for another atmosphere; use scale_function='refit'")

    # --- the scale function ----------------------------------------------------------------

    def _precompute(self):
        """Coefficients (C, 5) of every constituent's scale function (refit or published)."""
        if self.scale_function == "published":
            self.scale_coefficients = np.tile(PUBLISHED_SCALE_COEFFICIENTS, (len(self.components), 1))
            return
        x = np.linspace(0.0, 1.0, 201)
        mu = 1.0 - x
        _, length = sphere_distances(self.bottom_radius, mu, self.top_radius, self.bottom_radius)
        fits, errors = [], {}
        for c in self.components:
            column = column_along_rays(c.profile, self.bottom_radius, 0.0, mu, length, panels=32, nodes=32)
            target = np.log(column / c.scale_height_m)
            coefficients = np.polynomial.polynomial.polyfit(x, target, 4)
            fits.append(coefficients)
            misfit = np.polynomial.polynomial.polyval(x, coefficients) - target
            errors[c.name] = float(np.max(np.abs(np.expm1(misfit))))
        self.scale_coefficients = np.array(fits)
        self.options["scale_fit_max_error"] = errors

    def scale(self, cos_theta) -> np.ndarray:
        """scale_i(cos theta) of every constituent, m: shape (C,) + cos_theta.shape."""
        x = 1.0 - np.asarray(cos_theta, float)
        log_scale = np.array([np.polynomial.polynomial.polyval(x, c) for c in self.scale_coefficients]).reshape(
            (len(self.components),) + x.shape)
        heights = np.array([c.scale_height_m for c in self.components]).reshape((-1,) + (1,) * x.ndim)
        return heights * np.exp(np.minimum(log_scale, MAX_LOG_SCALE))

    def density(self, altitude) -> np.ndarray:
        """rho_i(altitude) of every constituent: shape (C,) + altitude.shape."""
        return per_component(self.components, lambda c: c.profile.density(altitude), np.shape(altitude))

    def operations(self) -> Operations:
        """Per direction, for n ``samples`` and every constituent: the scale function at the
        ray's start and towards the sun and along the ray at each sample (a sky ray, 2 n + 1),
        or towards the sun and back up at the ground point (a ground ray, 2), and one
        exponential per sample and wavelength."""
        n = self.samples
        return Operations(sky={"samples along the ray": n, "scale-function evaluations per constituent": 2 * n + 1},
                          ground={"samples along the ray": n, "scale-function evaluations per constituent": 2})

    # --- per-ray scattering ----------------------------------------------------------------

    def _radiance(self, r, mu, mu_s, nu):
        segment = atmosphere_segment(r, mu, self.bottom_radius, self.top_radius)
        step = (segment.end - segment.start) / self.samples                                      # (M,)
        t = segment.start[:, None] + (np.arange(self.samples) + 0.5) * step[:, None]             # (M, n)
        mu_col, nu_col = mu[:, None], nu[:, None]
        altitude = np.maximum(altitude_along_ray(r, mu_col, t, self.bottom_radius), 0.0)
        mu_t = zenith_cosine_along_ray(r, mu_col, t)
        mu_s_t = sun_cosine_along_ray(r, mu_col, mu_s, nu_col, t)
        start_altitude = altitude_along_ray(r, mu, segment.start, self.bottom_radius)
        mu_start = zenith_cosine_along_ray(r, mu, segment.start)
        mu_end = zenith_cosine_along_ray(r, mu, segment.end)
        mu_s_end = sun_cosine_along_ray(r, mu, mu_s, nu, segment.end)
        ground = segment.ground
        rho, rho_start = self.density(altitude), self.density(start_altitude)                  # (C, M, n), (C, M)

        # Sky rays: the column from C to the top along the ray, minus the part beyond P_k, plus P_k
        # to the sun. Ground rays: P_k to the sun and back up to C, with the angles at G.
        sky = rho_start[..., None] * self.scale(mu_start)[..., None] + rho * (self.scale(mu_s_t) - self.scale(mu_t))
        up_at_ground = self.scale(-mu_end)
        camera_offset = rho_start * up_at_ground
        on_ground = rho * (self.scale(mu_s_end) + up_at_ground)[..., None] - camera_offset[..., None]
        columns = np.where(ground[:, None], on_ground, sky)                                       # (C, M, n)

        extinction = per_component(self.components, lambda c: c.extinction, self.wavelengths_nm.shape)  # (C, N)
        scattering = per_component(self.components, lambda c: c.scattering, self.wavelengths_nm.shape)
        tau = np.maximum(np.einsum("cmk,cn->mkn", columns, extinction), 0.0)                     # (M, n, N)
        front = np.einsum("cmk,mkn->cmn", rho, np.exp(-tau)) * step[None, :, None]               # (C, M, N)
        phases = per_component(self.components, lambda c: phase_values(c, nu), nu.shape)         # (C, M)
        radiance = self.solar_irradiance * np.einsum("cm,cn,cmn->mn", phases, scattering, front)

        if ground.any():
            columns_at_ground = self.density(0.0)[:, None] * (self.scale(mu_s_end) + up_at_ground) - camera_offset
            tau_ground = np.maximum(columns_at_ground.T @ extinction, 0.0)                        # (M, N)
            reflected = (self.ground_albedo / np.pi * self.solar_irradiance
                         * np.maximum(mu_s_end, 0.0)[:, None] * np.exp(-tau_ground))
            radiance[ground] += reflected[ground]
        return radiance
