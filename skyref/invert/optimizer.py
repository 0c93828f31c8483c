"""The inversion: Levenberg–Marquardt on log pixel values against the ground-truth path tracer,
with an exposure solved in closed form, a final Gauss–Newton step on a high-sample render, and
uncertainties and identifiability from the curvature.

Residuals. For fitted pixel p and channel c, r_pc = log m_pc(theta) + log s - log y_pc: model m
(:class:`~skyref.invert.model.ForwardModel`), observed value y, exposure s (y = s x radiance; 1
for an absolute image). In logarithms the exposure is an additive offset, so for given theta its
best value is closed-form, log s = mean(log y - log m), and it is set so after every render.

Objective. Phi = sum r^2 / (2 sigma^2) + sum_k (theta_k - mu_k)^2 / (2 tau_k^2): the residuals
with variance sigma^2 = RSS / (rows - unknowns) estimated from the current fit, plus the weak prior
of :mod:`skyref.invert.parameters` (mean mu = initial value, tau = bounds / sqrt 12).

Iterations. Each renders the model at a fresh seed and its Jacobian (columns for the free
unknowns and, for a relative image, log s, whose column is 1) twice, J1 and J2, at two other
seeds with half the samples each. The curvature is A = (J1^T J2 + J2^T J1) / (2 sigma^2) + P
(P the prior precision): a product of independent estimates is unbiased for E[J]^T E[J], whereas
J^T J of one noisy J is inflated by its noise and shrinks every step (regression dilution: at 64
samples per pixel the aerosol column's noise nearly doubles J^T J). With J = (J1 + J2) / 2 and
g = J^T r / sigma^2 + P (theta - mu), the step solves (A + lambda D) delta = -g (D = diag(J^T J /
sigma^2 + P), Marquardt's scaling) with theta kept within its bounds (:func:`bounded_step`), and
the trial is rendered at the same seed. Phi is a Monte Carlo estimate and delta tracking
decorrelates renders at different parameter values (the majorants move with them), so the two
values of Phi differ by noise of standard deviation about sqrt(rows) (each row adds r^2 /
(2 sigma^2) of variance 1/2, twice). The step is accepted unless Phi rises by more than twice that
(an overshoot, which far from the optimum is much larger); otherwise lambda grows and the step
shrinks. Samples per pixel double each iteration from ``spp_start`` to ``spp_max``: early steps
are cheap, late ones precise. Converged: at ``spp_max``, the undamped Gauss–Newton step delta has
a length in posterior standard deviations, sqrt(delta^T A delta / unknowns), of at most
``step_tolerance`` (the noise of the residuals alone makes steps of expected length 1; default
1.5).

Jacobian noise. Where unknowns are nearly degenerate (aerosol optical depth, ground albedo and
exposure in a sky-only image), the step -A^-1 J^T r is very sensitive to the Jacobian's Monte
Carlo noise N: N^T r, with r dominated by the image's own noise, moves the estimate along the
degenerate direction. The Jacobians of consecutive iterations are therefore averaged, weighted by
their samples (near the optimum their parameter values differ by a few standard deviations, over
which J hardly changes; the average restarts after a Gauss–Newton step longer than
JACOBIAN_RESTART_STEP), and the remaining noise enters the covariance below.

Final answer. One undamped Gauss–Newton step from the last iterate with the model and a last
Jacobian rendered at ``final_spp`` (fresh seeds), that Jacobian averaged with the previous ones.
The estimate's covariance is the cluster-robust ("sandwich") form A^-1 B A^-1 with B = sum_p (u_p u_p^T + v_p v_p^T) / sigma^4 + P,
u_p = sum_c J_pc r_pc and v_p = sum_c N_pc r_pc, N = (J1 - J2) / 2 estimating the Jacobian's noise:
channels of one pixel share paths (correlated Monte Carlo noise), photon noise varies over the
image, and the Jacobian is noisy, all of which the plain curvature form A^-1 (``std_curvature``,
also reported) ignores.

Identifiability. A free unknown is flagged "not identifiable" when its posterior standard
deviation exceeds ``identifiability_ratio`` (default 1/2) of its prior's (the image does not even
halve what its bounds allowed), or when its estimate sits on a bound. The evidence: the
root-mean-square change of log pixel values that one prior standard deviation of it causes, less
what the exposure absorbs, against the residual noise; and its strongest correlation with
another unknown.

References
----------
K. Levenberg, "A Method for the Solution of Certain Non-Linear Problems in Least Squares", Quarterly of
Applied Mathematics 2(2), 1944.

D. W. Marquardt, "An Algorithm for Least-Squares Estimation of Nonlinear Parameters", Journal of the
Society for Industrial and Applied Mathematics 11(2), 1963 (the damping scaled by diag(J^T J)).

H. White, "A Heteroskedasticity-Consistent Covariance Matrix Estimator and a Direct Test for
Heteroskedasticity", Econometrica 48(4), 1980, and K.-Y. Liang, S. L. Zeger, "Longitudinal Data Analysis
Using Generalized Linear Models", Biometrika 73(1), 1986 (the sandwich covariance, clustered by pixel).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from skyref.validation import check_int, check_number
from skyref.errors import ParameterError
from skyref.invert.model import ForwardModel, stream_seed
from skyref.invert.result import InversionResult
from skyref.projection import solid_angle
from skyref.render import render_sky

__all__ = ["JACOBIAN_RESTART_STEP", "MAP_SAMPLES", "MAP_SPP_RANGE", "InversionSettings", "bounded_step",
           "exposure_offset", "identifiability", "invert", "map_spp", "normal_equations", "sandwich_covariance",
           "select_pixels"]


@dataclass(frozen=True)
class InversionSettings:
    """Budget and controls of an inversion (samples per pixel = spp)."""

    pixels: int = 400             # pixels fitted: a random subsample of the usable ones, by solid angle
    spp_start: int = 64           # spp of the first iteration, doubled each iteration ...
    spp_max: int = 1024           # ... up to this
    final_spp: int = 4096         # spp of the model and Jacobian behind the final step
    map_spp: int = 0              # spp of the full fitted image (residual map, fitted.exr); 0: automatic
    max_iterations: int = 12
    step_tolerance: float = 1.5   # converged: Gauss-Newton step length < this, in posterior std
    identifiability_ratio: float = 0.5
    footprint: int = 0            # sub-directions per pixel side (0: automatic)
    seed: int = 0
    variant: str | None = None    # Mitsuba variant (default: cuda_ad_rgb with a GPU, else llvm_ad_rgb)

    def __post_init__(self):
        check_int("pixels", self.pixels, 8, 1_000_000)
        check_int("spp_start", self.spp_start, 1, 1 << 20)
        check_int("spp_max", self.spp_max, self.spp_start, 1 << 22)
        check_int("final_spp", self.final_spp, 1, 1 << 24)
        if self.map_spp != 0:
            check_int("map_spp", self.map_spp, 2, 1 << 20)
        check_int("max_iterations", self.max_iterations, 1, 1000)
        check_number("step_tolerance", self.step_tolerance, 0.0, 10.0, lo_open=True)
        check_number("identifiability_ratio", self.identifiability_ratio, 0.0, 1.0, lo_open=True)
        check_int("footprint", self.footprint, 0, 16)
        check_int("seed", self.seed, 0, (1 << 31) - 1)


#: A Gauss–Newton step longer than this (in posterior standard deviations) restarts the running
#: average of Jacobians: the fit is still moving, and the Jacobian with it.
JACOBIAN_RESTART_STEP = 3.0

#: Samples spent on the fitted image when ``map_spp`` is automatic, and the range of its spp.
MAP_SAMPLES = 1 << 25
MAP_SPP_RANGE = (16, 1024)


def map_spp(settings, camera) -> int:
    """Samples per pixel of the fitted image: ``settings.map_spp``, or MAP_SAMPLES spread over the
    image within MAP_SPP_RANGE (a small image gets a quiet residual map, a large one stays cheap)."""
    if settings.map_spp:
        return settings.map_spp
    return int(np.clip(MAP_SAMPLES // (camera.width * camera.height), *MAP_SPP_RANGE))


def select_pixels(observation, count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of up to ``count`` usable pixels drawn without replacement with probability
    proportional to their solid angle, so that the fit covers the sky evenly."""
    rows, cols = np.nonzero(observation.mask)
    weights = solid_angle(observation.camera)[rows, cols]
    weights = weights / weights.sum()
    rng = np.random.default_rng(seed)
    chosen = np.sort(rng.choice(rows.size, size=min(count, rows.size), replace=False, p=weights))
    return rows[chosen], cols[chosen]


# --- the linear algebra of one step (plain NumPy) ---------------------------------------------------

def exposure_offset(log_model, log_data) -> float:
    """Closed-form log exposure minimising sum (log m + log s - log y)^2: mean(log y - log m)."""
    return float(np.mean(log_data - log_model))


def normal_equations(jacobians, residual, sigma2, prior_precision, prior_offset):
    """(A, g, D) of the objective's Gauss–Newton model from two independent Jacobian estimates
    ``jacobians`` = (J1, J2), each (rows, unknowns): A = sym(J1^T J2) / sigma^2 + P, g = J^T r /
    sigma^2 + P (theta - mu) and D = diag(J^T J / sigma^2 + P) with J = (J1 + J2) / 2. Where noise
    leaves A not positive definite, J^T J / sigma^2 + P replaces it."""
    j1, j2 = jacobians
    mean = 0.5 * (j1 + j2)
    cross = 0.5 * (j1.T @ j2 + j2.T @ j1)
    plain = mean.T @ mean
    precision = np.diag(prior_precision)
    a = cross / sigma2 + precision
    if np.linalg.eigvalsh(a).min() <= 0.0:
        a = plain / sigma2 + precision
    g = mean.T @ residual / sigma2 + prior_precision * prior_offset
    return a, g, np.diag(np.diag(plain / sigma2 + precision))


def bounded_step(matrix, g, theta, lower, upper) -> np.ndarray:
    """The step delta minimising 1/2 delta^T M delta + g^T delta (M = ``matrix``, positive
    definite) with theta + delta within [lower, upper] for the first len(theta) components (the
    rest, e.g. log exposure, are unbounded). With M = L L^T this is the bounded least-squares
    problem min |L^T delta + L^-1 g|^2, solved exactly by scipy's bounded-variable least squares."""
    # Lazy: scipy.linalg and scipy.optimize take ~0.8 s to import, and ``skyref --help`` imports this
    # module (through skyref.invert).
    from scipy.linalg import cholesky, solve_triangular
    from scipy.optimize import lsq_linear

    factor = cholesky(matrix, lower=True)
    extra = matrix.shape[0] - len(theta)
    lo = np.concatenate([lower - theta, np.full(extra, -np.inf)])
    hi = np.concatenate([upper - theta, np.full(extra, np.inf)])
    target = -solve_triangular(factor, g, lower=True)
    return lsq_linear(factor.T, target, bounds=(lo, hi), method="bvls").x


def sandwich_covariance(jacobians, residual, pixel_of_row, sigma2, prior_precision, a):
    """Cluster-robust covariance A^-1 B A^-1 from the two Jacobian estimates (J1, J2):
    B = sum_p (u_p u_p^T + v_p v_p^T) / sigma^4 + P, with u_p and v_p the sums over pixel p's rows
    of J r and of N r, J = (J1 + J2) / 2 and N = (J1 - J2) / 2 (noise of the same size as J's,
    independent of it). The v term is the spread that the Jacobian's own Monte Carlo noise gives
    the step -A^-1 J^T r (see the module docstring)."""
    b = np.diag(prior_precision).astype(np.float64)
    for combined in (0.5 * (jacobians[0] + jacobians[1]), 0.5 * (jacobians[0] - jacobians[1])):
        scores = np.zeros((pixel_of_row.max() + 1, combined.shape[1]))
        np.add.at(scores, pixel_of_row, combined * residual[:, None])
        b += scores.T @ scores / sigma2 ** 2
    inverse = np.linalg.inv(a)
    return inverse @ b @ inverse


def identifiability(names, jacobian, covariance, prior_std, sigma2, ratio_limit, relative, at_bound=None):
    """Per free unknown (the first len(prior_std) columns): whether the image constrains it, and
    the evidence (see the module docstring). ``names`` of every column of ``covariance``; an
    unknown ``at_bound`` is not identifiable either (the image pushes it out of its range, and a
    curvature there says nothing)."""
    at_bound = np.zeros(len(prior_std), dtype=bool) if at_bound is None else at_bound
    std = np.sqrt(np.diag(covariance))
    correlation = covariance / np.outer(std, std)
    report = []
    for k, tau in enumerate(prior_std):
        column = jacobian[:, k] - (jacobian[:, k].mean() if relative else 0.0)
        sensitivity = float(np.sqrt(np.mean(column ** 2)) * tau)
        others = [j for j in range(len(names)) if j != k]
        partner = max(others, key=lambda j: abs(correlation[k, j])) if others else None
        ratio = float(std[k] / tau)
        report.append({
            "identifiable": bool(ratio <= ratio_limit and not at_bound[k]),
            "at_bound": bool(at_bound[k]),
            "posterior_to_prior_std": ratio,
            "sensitivity_rms_log_per_prior_std": sensitivity,
            "noise_rms_log": math.sqrt(sigma2),
            "most_correlated_with": None if partner is None else names[partner],
            "correlation": None if partner is None else float(correlation[k, partner]),
        })
    return report


# --- the inversion ------------------------------------------------------------------------------

class _Fit:
    """The state shared by the steps of one inversion: data rows, prior, model."""

    def __init__(self, observation, parameters, model, rows, cols):
        self.parameters, self.model = parameters, model
        self.log_data = np.log(observation.values[rows, cols]).reshape(-1)
        channels = observation.values.shape[-1]
        self.pixel_of_row = np.repeat(np.arange(len(rows)), channels)
        self.relative = not observation.absolute
        self.free = len(parameters.free)
        self.exposure_columns = int(self.relative)      # log s, fitted for a relative image
        self.unknowns = self.free + self.exposure_columns
        if self.log_data.size < 4 * (self.unknowns + 1):
            raise ParameterError("pixels", len(rows), f"at least {4 * (self.unknowns + 1)} fitted values for "
                                 f"{self.unknowns} unknowns", "too few usable pixels")
        tau = parameters.prior_std
        self.prior_mean = parameters.vector()
        self.prior_precision = np.concatenate([1.0 / tau ** 2, np.zeros(self.exposure_columns)])
        self.lower, self.upper = parameters.lower, parameters.upper
        self._jacobian_sums, self._jacobian_samples, self._jacobian_count = None, 0, 0

    def residual(self, theta, seed, spp):
        """(residual rows, log exposure) at ``theta`` from a render at ``seed``."""
        log_model = self.model.log(self.model.radiance(self.parameters.with_vector(theta), seed, spp)).reshape(-1)
        log_s = exposure_offset(log_model, self.log_data) if self.relative else 0.0
        return log_model + log_s - self.log_data, log_s

    def jacobians(self, theta, seed, spp):
        """Two independent Jacobian estimates (rows, unknowns) with spp / 2 samples each."""
        values = self.parameters.with_vector(theta)
        estimates = []
        for half in (0, 1):
            j = self.model.log_jacobian(values, stream_seed(seed, half), max(1, spp // 2)).reshape(-1, self.free)
            estimates.append(np.hstack([j, np.ones((j.shape[0], self.exposure_columns))]))
        return estimates

    def averaged_jacobians(self, theta, seed, spp, restart):
        """:meth:`jacobians` at ``theta``, averaged (weighted by samples) with those of the
        previous calls since the last ``restart``: consecutive iterations near the optimum, where
        the Jacobian hardly changes; its noise, which a near-degenerate fit amplifies, falls as
        1 / samples. Returns the two averages and how many estimates they hold."""
        estimates = [spp * j for j in self.jacobians(theta, seed, spp)]
        if restart or self._jacobian_sums is None:
            self._jacobian_sums, self._jacobian_samples, self._jacobian_count = estimates, 0, 0
        else:
            self._jacobian_sums = [total + j for total, j in zip(self._jacobian_sums, estimates)]
        self._jacobian_samples += spp
        self._jacobian_count += 1
        return [total / self._jacobian_samples for total in self._jacobian_sums], self._jacobian_count

    def sigma2(self, residual):
        return float(residual @ residual) / max(residual.size - self.unknowns, 1)

    def objective(self, theta, residual, sigma2):
        offset = theta - self.prior_mean
        return 0.5 * float(residual @ residual) / sigma2 + 0.5 * float(self.prior_precision[:self.free] @ offset ** 2)

    def system(self, theta, jacobians, residual, sigma2):
        offset = np.concatenate([theta - self.prior_mean, np.zeros(self.exposure_columns)])
        return normal_equations(jacobians, residual, sigma2, self.prior_precision, offset)


def invert(observation, parameters, settings: InversionSettings = InversionSettings(), progress: bool = False):
    """Fit the free unknowns of ``parameters`` to ``observation``; returns an
    :class:`~skyref.invert.result.InversionResult` (see the module docstring for the method)."""
    start = time.perf_counter()
    rows, cols = select_pixels(observation, settings.pixels, settings.seed)
    model = ForwardModel(observation, parameters, rows, cols, settings.footprint, settings.variant)
    fit = _Fit(observation, parameters, model, rows, cols)
    bar = None
    if progress:
        from tqdm import tqdm  # lazy: its import cost is paid only with a progress bar

        bar = tqdm(total=settings.max_iterations + 2, desc="invert", unit="step")

    theta = parameters.vector()
    step_length = math.inf
    damping = 1e-3
    history = []
    converged = False
    for iteration in range(settings.max_iterations):
        spp = min(settings.spp_max, settings.spp_start << iteration)
        value_seed = stream_seed(settings.seed, iteration, 0)
        residual, log_s = fit.residual(theta, value_seed, spp)
        sigma2 = fit.sigma2(residual)
        restart = step_length > JACOBIAN_RESTART_STEP
        jacobians, averaged = fit.averaged_jacobians(theta, stream_seed(settings.seed, iteration, 1), spp, restart)
        a, g, scaling = fit.system(theta, jacobians, residual, sigma2)
        cost = fit.objective(theta, residual, sigma2)
        newton = bounded_step(a, g, theta, fit.lower, fit.upper)
        step_length = math.sqrt(max(float(newton @ a @ newton), 0.0) / fit.unknowns)
        accepted = False
        for _ in range(8):
            trial = theta + bounded_step(a + damping * scaling, g, theta, fit.lower, fit.upper)[:fit.free]
            trial_residual, trial_log_s = fit.residual(trial, value_seed, spp)
            if fit.objective(trial, trial_residual, sigma2) <= cost + 2.0 * math.sqrt(residual.size):
                accepted = True
                theta, log_s, residual = trial, trial_log_s, trial_residual
                damping = max(damping / 3.0, 1e-7)
                break
            damping *= 4.0
        history.append({"iteration": iteration, "spp": spp, "model": "ground truth (atmosphere integrator)",
                        "values": parameters.with_vector(theta), "exposure": math.exp(log_s),
                        "rms_log_residual": math.sqrt(float(residual @ residual) / residual.size),
                        "objective": fit.objective(theta, residual, sigma2), "accepted": accepted,
                        "gauss_newton_step_length": step_length, "jacobians_averaged": averaged,
                        "damping": damping, "elapsed_s": time.perf_counter() - start})
        if bar is not None:
            bar.set_postfix_str(", ".join(f"{n} {theta[k]:.4g}" for k, n in enumerate(parameters.free))
                                + f", rms {history[-1]['rms_log_residual']:.4f}", refresh=False)
            bar.update(1)
        if spp == settings.spp_max and step_length <= settings.step_tolerance:
            converged = True
            break

    if bar is not None:
        bar.total = bar.n + 2    # the final step and the fitted image remain
        bar.refresh()

    # -- the final Gauss–Newton step on a high-sample render ---------------------------------------
    final_seed = stream_seed(settings.seed, settings.max_iterations + 1, 0)
    residual, log_s = fit.residual(theta, final_seed, settings.final_spp)
    sigma2 = fit.sigma2(residual)
    jacobians, averaged = fit.averaged_jacobians(theta, stream_seed(settings.seed, settings.max_iterations + 1, 1),
                                                 settings.final_spp, restart=step_length > JACOBIAN_RESTART_STEP)
    a, g, _ = fit.system(theta, jacobians, residual, sigma2)
    delta = bounded_step(a, g, theta, fit.lower, fit.upper)
    theta_final = np.clip(theta + delta[:fit.free], fit.lower, fit.upper)   # (rounding only)
    jacobian = 0.5 * (jacobians[0] + jacobians[1])
    residual = residual + jacobian @ delta              # linearised residuals after the step
    log_s += float(delta[fit.free]) if fit.relative else 0.0
    sigma2 = fit.sigma2(residual)
    a, _, _ = fit.system(theta_final, jacobians, residual, sigma2)
    covariance = sandwich_covariance(jacobians, residual, fit.pixel_of_row, sigma2, fit.prior_precision, a)
    curvature = np.linalg.inv(a)
    names = list(parameters.free) + (["log_exposure"] if fit.relative else [])
    span = fit.upper - fit.lower
    at_bound = np.minimum(theta_final - fit.lower, fit.upper - theta_final) <= 1e-6 * span
    flags = identifiability(names, jacobian, covariance, parameters.prior_std, sigma2,
                            settings.identifiability_ratio, fit.relative, at_bound)
    values = parameters.with_vector(theta_final)
    history.append({"iteration": len(history), "spp": settings.final_spp, "model": "ground truth (atmosphere "
                    "integrator), final Gauss-Newton step", "values": values, "exposure": math.exp(log_s),
                    "rms_log_residual": math.sqrt(float(residual @ residual) / residual.size),
                    "objective": fit.objective(theta_final, residual, sigma2), "accepted": True,
                    "gauss_newton_step_length": math.sqrt(max(float(delta @ a @ delta), 0.0) / fit.unknowns),
                    "damping": 0.0, "elapsed_s": time.perf_counter() - start})
    if bar is not None:
        bar.update(1)
    fit_time = time.perf_counter() - start

    # -- the fitted sky over the whole image, and the residual map --------------------------------
    scene = observation.scene(parameters.atmosphere_at(values), spp=map_spp(settings, observation.camera),
                              seed=stream_seed(settings.seed, settings.max_iterations + 2, 0) & 0xFFFFFF)
    sky = render_sky(scene, variant=settings.variant)
    if bar is not None:
        bar.update(1)
        bar.close()
    return InversionResult(observation=observation, parameters=parameters, settings=settings, values=values,
                           covariance=covariance, covariance_curvature=curvature, names=names,
                           log_exposure=log_s if fit.relative else None, identifiability=flags,
                           history=history, converged=converged, rows=rows, cols=cols,
                           footprint=model.footprint, final_rms_log_residual=math.sqrt(sigma2),
                           fitted_sky=sky, fit_time_s=fit_time, total_time_s=time.perf_counter() - start)
