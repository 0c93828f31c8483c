"""Fit a coefficient table (Hosek–Wilkie or Perez form, published layout) to training skies,
with optimistix's Levenberg–Marquardt in JAX (float64).

Residuals are differences of log radiance, so every direction counts by its *relative* error,
weighted by its pixel's solid angle (:meth:`~skyref.fit.training.TrainingSet.weights`). Three
stages, each jit-compiled and vectorised (``jax.vmap``) over its independent problems:

1. **Per configuration** (each sky and channel): the overall radiance L_M is the sky's mean
   radiance (solid-angle weighted over the fitted directions, Hosek & Wilkie's "expected value
   of radiance"), and the n coefficients of F are fitted to log(L / L_M), starting from the start
   table's configuration and lightly pulled towards it (:data:`PRIOR_WEIGHT`), so that directions
   the data leave undetermined vary smoothly with elevation. A form without scale coefficients (Perez) also fits log L_M's offset.
2. **Bezier curves**: per albedo, turbidity, channel and coefficient, the six control points that
   fit the per-configuration values over x = (elevation / (pi/2))^(1/3) in least squares
   (linear), moved inside the bounds; the same for L_M. Needs at least six distinct elevations.
3. **Joint refinement** (optional, on by default): the control points of F and of L_M together,
   against every direction of every elevation of the (albedo, turbidity, channel), so the table
   minimises the error of the radiance it will actually produce. In the Hosek–Wilkie form F's
   scale coefficients and L_M trade a factor (:mod:`skyref.fit.forms`), and with a handful of
   elevations the product of their two quintic curves is nearly undetermined: a gauge term per
   sky, :data:`GAUGE_WEIGHT` x (log L_M(x) - log mean radiance)^2, picks the solution whose L_M
   stays the mean radiance (Hosek & Wilkie's convention). Like stage 1, the control points are
   pulled lightly towards the start table's (``joint_prior_weight``).

   Both terms serve the same purpose: a table is evaluated between its stored turbidities and
   albedos by blending the neighbours' *coefficients*, which gives a sky between the neighbours'
   skies only if the neighbours settle the form's degenerate directions alike. Fitted
   independently, they do not. skyref's 260-sky fit, measured by
   :func:`skyref.fit.evaluate.interpolation_gap` (the sky halfway between two stored
   configurations against the mean of theirs, 95th percentile):

   - without the pull: 55% halfway in turbidity and 66% at albedo 1/2;
   - with the pull: 6% and 34%. The pull then decided F's scale against L_M, differently at albedo
     0 and 1 (L_M 2.4x the mean radiance at albedo 1, sun 60 deg);
   - with the gauge made strong enough to decide the scale (:data:`GAUGE_WEIGHT`): 8% and 10%.
     The published table has 4% and 4%.

Bounds (:mod:`skyref.fit.forms`) are enforced by a smooth change of variables, on the control
points. log F needs F > 0: F is passed through softplus-like 0.5 (F + sqrt(F^2 + 4 eps^2))
(:data:`POSITIVE_EPSILON`, relative to L_M), equal to F to within eps^2 / F where F >> eps and
smoothly positive where a trial step makes F negative, so the solver is pushed back.

Configurations must lie on the table's grid (albedo 0 or 1, turbidity 1..10); skies with the sun
below the horizon are left out (the layout holds no such data). Albedo/turbidity/channel
groups without training skies keep the start table's values (:attr:`FitResult.fitted`).

JAX, optimistix and lineax are imported inside the functions that use them: their start-up takes
seconds, and ``skyref --help`` imports this module (through :mod:`skyref.fit.cli`).

References
----------
L. Hosek, A. Wilkie, "An Analytic Model for Full Spectral Sky-Dome Radiance", ACM TOG 31(4), 2012.

R. Perez, R. Seals, J. Michalsky, "All-weather model for sky luminance distribution — preliminary
configuration and validation", Solar Energy 50(3), 1993.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from skyref.analytic.hosek import (ALBEDOS, CONTROL_POINTS, FORMS, TURBIDITIES, CoefficientTable,
                                   bezier_weights, elevation_parameter, published_table)
from skyref.validation import check_number
from skyref.errors import ParameterError
from skyref.extras import require
from skyref.fit import forms

__all__ = ["ATOL", "BATCH_SIZE", "GAUGE_WEIGHT", "GRID_TOLERANCE", "MAX_STEPS", "POSITIVE_EPSILON", "PRIOR_WEIGHT",
           "RTOL", "SHORT_GROUP", "FitResult", "default_start", "fit_table"]

#: eps of the positive part of F (see the module's documentation), relative to L_M.
POSITIVE_EPSILON = 1e-6
#: Levenberg–Marquardt tolerances (relative, absolute) on the steps and the residuals.
RTOL, ATOL = 1e-7, 1e-10
#: Most Levenberg–Marquardt steps per problem (per configuration: only a starting point for the
#: curves; joint refinement).
MAX_STEPS = (200, 500)
#: Problems solved together in one vectorised call (per configuration; joint refinement).
BATCH_SIZE = (256, 4)
#: Weight of stage 1's pull of each (unbounded) coefficient towards the start table's value,
#: against about one per direction for the data. The form is degenerate where the data do not
#: decide (e.g. C + D exp(E gamma) with E -> 0 trades C against D); unregularised, such
#: coefficients wander between neighbouring elevations (C from -16 to +1 between 3 and 18 deg on
#: skyref's turbidity-1 skies) and their Bezier curve then describes no sky at all.
PRIOR_WEIGHT = 1.0
#: Weight of the joint refinement's gauge term per sky, log L_M(x) - log(mean radiance), against
#: about one per direction for the sky's radiance (Hosek–Wilkie form). Strong enough to decide F's
#: scale against L_M over the start-table pull (see the module's documentation); the direction it
#: decides is degenerate, so the radiance barely pays (spectral RMS +1 point on skyref's fit).
GAUGE_WEIGHT = 100.0
#: Configurations match the table's turbidities and albedos to this tolerance.
GRID_TOLERANCE = 1e-6
#: Why a rendered sky is not fitted (``FitResult.skipped``) when an unfinished batch has rendered
#: too few elevations of its albedo and turbidity for a Bezier curve: it keeps the start values.
SHORT_GROUP = "too few elevations of its albedo and turbidity rendered (unfinished batch?)"


@dataclass
class FitResult:
    """A fitted table and how the fit went.

    ``fitted`` ``(channels, 2, 10)``: True where the (channel, albedo, turbidity) group was fitted
    (elsewhere the start table's values remain). ``configurations`` ``(S, C, n)`` and
    ``radiance_scale`` ``(S, C)``: the per-configuration fits of stage 1 (NaN for skies left out).
    ``unconverged``: problems per stage that hit the step limit or failed; ``most_steps``: the
    most solver steps a problem took, per stage. ``timings``: seconds per stage. ``skipped``:
    sky index -> why it was left out.
    """

    table: CoefficientTable
    fitted: np.ndarray
    configurations: np.ndarray
    radiance_scale: np.ndarray
    unconverged: dict = field(default_factory=dict)
    most_steps: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    skipped: dict = field(default_factory=dict)


def default_start(form: str, kind: str) -> CoefficientTable:
    """The start table: the published coefficients for the Hosek–Wilkie form, and for the Perez
    form every control point at :func:`skyref.fit.forms.neutral_start` (radiance 0: groups never
    fitted stay visibly empty)."""
    if form == "hosek":
        return published_table(kind)
    channels = len(published_table(kind).channels)
    shape = (channels, len(ALBEDOS), len(TURBIDITIES), CONTROL_POINTS)
    coefficients = np.broadcast_to(forms.neutral_start(form), shape + (len(FORMS[form][0]),))
    return CoefficientTable(form, kind, coefficients.copy(), np.zeros(shape), source="neutral start")


# --- JAX pieces -------------------------------------------------------------------------------

def _levenberg_marquardt():
    """optimistix's Levenberg–Marquardt solving each damped step through the normal equations
    (J^T J + lambda I) delta = J^T r by Cholesky: the problems have far more residuals than
    parameters (joint refinement: ~14,000 x 60), and forming the small normal matrix is ~20x
    faster here than the default QR of the tall augmented Jacobian (measured on 2 CPU cores:
    4 joint problems, 100 steps, 11.6 s -> 0.5 s). Conditioning is squared; in float64 with
    bounded coefficients that costs nothing measurable (tests/test_fit.py recovers known
    tables to 1e-6)."""
    import lineax as lx
    import optimistix as optx

    return optx.LevenbergMarquardt(rtol=RTOL, atol=ATOL, linear_solver=lx.Normal(lx.Cholesky()))


def _positive(f, xp):
    """0.5 (f + sqrt(f^2 + 4 eps^2)): f where f >> eps, smoothly positive everywhere."""
    return 0.5 * (f + xp.sqrt(f * f + 4.0 * POSITIVE_EPSILON ** 2))


@functools.lru_cache(maxsize=None)
def _configuration_solver(form: str, fit_scale: bool):
    """jit(vmap(solve)) for stage 1: u ``(N, n [+1])``, gamma/target/sqrt_weight ``(N, P)``,
    cos_theta ``(P,)`` -> (u, converged)."""
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    n = len(FORMS[form][0])
    shape_function = FORMS[form][1]

    def residuals(u, args):
        gamma, target, sqrt_weight, cos_theta, u_start = args
        coefficients = forms.from_unbounded(form, u[:n], jnp)
        log_f = jnp.log(_positive(shape_function(coefficients, cos_theta, gamma, jnp), jnp))
        offset = u[n] if fit_scale else 0.0
        prior = math.sqrt(PRIOR_WEIGHT) * (u[:n] - u_start[:n])
        return jnp.concatenate([sqrt_weight * (log_f + offset - target), prior])

    solver = _levenberg_marquardt()

    def solve(u, gamma, target, sqrt_weight, cos_theta):
        solution = optx.least_squares(residuals, solver, u, args=(gamma, target, sqrt_weight, cos_theta, u),
                                      max_steps=MAX_STEPS[0], throw=False)
        return solution.value, solution.result == optx.RESULTS.successful, solution.stats["num_steps"]

    return jax.jit(jax.vmap(solve, in_axes=(0, 0, 0, 0, None)))


@functools.lru_cache(maxsize=None)
def _joint_solver(form: str):
    """jit(vmap(solve)) for stage 3, per group: F's control points u ``(6, n)`` (unbounded) and
    L_M's ``(6,)``, x ``(J,)``, gamma/target/sqrt_weight ``(J, P)``, the skies' mean radiances
    ``(J,)`` and the gauge weight ``(J,)`` (0 for padding), cos_theta ``(P,)`` -> ((u, L_M
    control points), converged, steps)."""
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    shape_function = FORMS[form][1]

    n = len(FORMS[form][0])

    def residuals(params, args):
        # One flat vector in and out: optimistix then works on plain matrices (pytrees of
        # parameters or residuals make every step several times slower).
        u, radiance_points = params[:-CONTROL_POINTS].reshape(CONTROL_POINTS, n), params[-CONTROL_POINTS:]
        x, gamma, target, sqrt_weight, mean_radiance, sqrt_gauge, u_start, sqrt_prior, cos_theta = args
        bezier = bezier_weights(x, jnp)                                   # (J, 6)
        coefficients = bezier @ forms.from_unbounded(form, u, jnp)        # (J, n)
        log_scale = jnp.log(_positive(bezier @ radiance_points, jnp))     # (J,)
        f = shape_function(coefficients[:, None, :], cos_theta[None, :], gamma, jnp)
        sky = sqrt_weight * (log_scale[:, None] + jnp.log(_positive(f, jnp)) - target)
        gauge = sqrt_gauge * (log_scale - jnp.log(mean_radiance))
        prior = sqrt_prior * (u - u_start)
        return jnp.concatenate([sky.ravel(), gauge, prior.ravel()])

    solver = _levenberg_marquardt()

    def solve(u, radiance_points, x, gamma, target, sqrt_weight, mean_radiance, sqrt_gauge, u_start, sqrt_prior,
              cos_theta):
        solution = optx.least_squares(residuals, solver, jnp.concatenate([u.ravel(), radiance_points]),
                                      args=(x, gamma, target, sqrt_weight, mean_radiance, sqrt_gauge, u_start,
                                            sqrt_prior, cos_theta),
                                      max_steps=MAX_STEPS[1], throw=False)
        params = solution.value
        return ((params[:-CONTROL_POINTS].reshape(CONTROL_POINTS, n), params[-CONTROL_POINTS:]),
                solution.result == optx.RESULTS.successful, solution.stats["num_steps"])

    return jax.jit(jax.vmap(solve, in_axes=(0, 0, 0, 0, 0, 0, 0, 0, 0, 0, None)))


def _batched(solver, batch_size, per_problem, shared, progress, stage):
    """Run ``solver`` over the leading axis of the arrays in ``per_problem`` in batches of
    ``batch_size`` (fewer problems: the next power of two), the last one padded by repeating its
    first problem, so a few compilations serve every size; returns the concatenated outputs
    (pytrees of arrays)."""
    import jax

    total = len(jax.tree_util.tree_leaves(per_problem)[0])
    size = min(batch_size, 1 << (total - 1).bit_length())
    outputs = []
    for start in range(0, total, size):
        stop = min(start + size, total)

        def take(a):
            chunk = a[start:stop]
            if stop - start < size:
                chunk = np.concatenate([chunk, np.repeat(chunk[:1], size - (stop - start), axis=0)])
            return chunk

        result = solver(*jax.tree_util.tree_map(take, per_problem), *shared)
        outputs.append(jax.tree_util.tree_map(lambda a: np.asarray(a)[:stop - start], result))
        if progress is not None:
            progress(stage, stop, total)
    return jax.tree_util.tree_map(lambda *parts: np.concatenate(parts), *outputs)


# --- the three stages ---------------------------------------------------------------------------

def _grid_indices(values, grid, name) -> np.ndarray:
    index = np.abs(np.asarray(values)[:, None] - np.asarray(grid)[None, :]).argmin(axis=1)
    off = np.abs(np.asarray(values) - np.asarray(grid)[index]) > GRID_TOLERANCE
    if off.any():
        raise ParameterError(name, float(np.asarray(values)[off][0]), f"one of {list(grid)} (the table's grid)",
                             "not a stored configuration")
    return index


def _stage_configurations(form, training, start, skies, weights, progress):
    """Stage 1 for ``skies`` (indices): (coefficients (S', C, n), L_M (S', C), converged)."""
    n = len(FORMS[form][0])
    fit_scale = not forms.scale_mask(form).any()
    radiance = training.radiance[skies]
    w = weights[skies]
    mean_radiance = (w * np.nan_to_num(radiance)).sum(axis=1) / w.sum(axis=1)            # (S', C)
    with np.errstate(divide="ignore", invalid="ignore"):
        target = np.where(w > 0, np.log(radiance / mean_radiance[:, None, :]), 0.0)      # (S', P, C)
    initial, _ = start.configuration(training.solar_elevation[skies].clip(0.0), training.turbidity[skies],
                                     training.albedo[skies])
    initial = forms.to_unbounded(form, initial[:, training.channel_indices])             # (S', C, n)
    if fit_scale:
        initial = np.concatenate([initial, np.zeros(initial.shape[:-1] + (1,))], axis=-1)
    count, channels = mean_radiance.shape
    gamma = np.broadcast_to(training.gamma[skies][:, None, :], (count, channels, len(training.directions)))

    def flat(a):  # (S', C, ...) -> (S' C, ...)
        return np.ascontiguousarray(a).reshape((count * channels,) + a.shape[2:])

    per_problem = (flat(initial), flat(gamma), flat(np.moveaxis(target, 2, 1)), flat(np.sqrt(np.moveaxis(w, 2, 1))))
    u, converged, steps = _batched(_configuration_solver(form, fit_scale), BATCH_SIZE[0], per_problem,
                                   (training.cos_theta,), progress, "per configuration")
    u = u.reshape(count, channels, -1)
    if fit_scale:
        mean_radiance = mean_radiance * np.exp(u[..., n])
    return forms.from_unbounded(form, u[..., :n]), mean_radiance, converged, steps


def _stage_bezier(form, x, coefficients, radiance_scale):
    """Stage 2 for one group: control points (6, n) inside the bounds and L_M's (6,), from values
    at parameters ``x`` (J,); L_M's in relative least squares (L_M spans orders of magnitude
    between the horizon and the zenith)."""
    bezier = bezier_weights(x)
    control, *_ = np.linalg.lstsq(bezier, coefficients, rcond=None)
    radiance_points, *_ = np.linalg.lstsq(bezier / radiance_scale[:, None], np.ones_like(radiance_scale), rcond=None)
    return forms.clip_into_bounds(form, control), radiance_points


def _stage_joint(form, training, groups, control, radiance_points, weights, radiance_scale, start_control,
                 prior_weight, progress):
    """Stage 3 for every group: refined (control points (G, 6, n), L_M control points (G, 6),
    converged (G,), steps (G,)). ``groups``: list of (channel, sky indices); ``radiance_scale``
    (S, C): stage 1's L_M per sky, which the gauge term keeps L_M's curve close to (Hosek–Wilkie
    form)."""
    longest = max(len(skies) for _, skies in groups)
    count, directions = len(groups), len(training.directions)
    x = np.zeros((count, longest))
    gamma = np.zeros((count, longest, directions))
    target = np.zeros((count, longest, directions))
    sqrt_weight = np.zeros((count, longest, directions))
    mean_radiance = np.ones((count, longest))
    sqrt_gauge = np.zeros((count, longest))
    norm = np.empty(count)
    for g, (channel, skies) in enumerate(groups):
        j = len(skies)
        w = weights[skies, :, channel]
        radiance = training.radiance[skies, :, channel]
        norm[g] = np.mean(radiance_scale[skies, channel])
        x[g, :j] = elevation_parameter(training.solar_elevation[skies])
        gamma[g, :j] = training.gamma[skies]
        with np.errstate(divide="ignore", invalid="ignore"):
            target[g, :j] = np.where(w > 0, np.log(radiance / norm[g]), 0.0)
        sqrt_weight[g, :j] = np.sqrt(w)
        mean_radiance[g, :j] = radiance_scale[skies, channel] / norm[g]
        sqrt_gauge[g, :j] = math.sqrt(GAUGE_WEIGHT) if forms.scale_mask(form).any() else 0.0
    # The pull towards the start table per control point, as strong against the group's data as
    # stage 1's is against one sky's (prior_weight per coefficient and sky).
    sqrt_prior = np.sqrt(prior_weight * np.array([len(skies) for _, skies in groups], dtype=float))
    per_problem = (forms.to_unbounded(form, control), radiance_points / norm[:, None], x, gamma, target,
                   sqrt_weight, mean_radiance, sqrt_gauge, forms.to_unbounded(form, start_control), sqrt_prior)
    (u, scaled_points), converged, steps = _batched(_joint_solver(form), BATCH_SIZE[1], per_problem,
                                                    (training.cos_theta,), progress, "joint refinement")
    return forms.from_unbounded(form, u), scaled_points * norm[:, None], converged, steps


def fit_table(training, form: str = "hosek", start: CoefficientTable | None = None, joint: bool = True,
              joint_prior_weight: float = PRIOR_WEIGHT, progress=None) -> FitResult:
    """Fit a table of ``form`` ("hosek" or "perez") to a :class:`~skyref.fit.training.TrainingSet`
    (see the module's documentation). ``start``: table of the same form and kind that gives the
    starting coefficients and the values of groups without data (default :func:`default_start`).
    ``joint_prior_weight``: the joint refinement's pull towards the start table's control points
    (per coefficient and sky; 0: none, the least-squares fit of the data alone).
    ``progress``: optional callable ``(stage, done, total)``."""
    require("fit")
    import jax

    if form not in FORMS:
        raise ParameterError("form", form, " or ".join(map(repr, FORMS)), "unknown model form")
    check_number("joint_prior_weight", joint_prior_weight, 0.0, 1e6)
    start = default_start(form, training.kind) if start is None else start
    if (start.form, start.kind) != (form, training.kind):
        raise ParameterError("start", f"{start.form} {start.kind} table", f"a {form} {training.kind} table",
                             "does not match the fit")
    n = len(FORMS[form][0])
    weights = training.weights()
    skipped, missing = {}, []
    for s in range(len(training.solar_elevation)):
        if training.solar_elevation[s] < 0.0:
            skipped[s] = "sun below the horizon"
        elif not (weights[s] > 0).any(axis=0).all():
            skipped[s] = "no valid radiance in some channel (missing sky?)"
            missing.append(s)
    skies = np.array([s for s in range(len(training.solar_elevation)) if s not in skipped], dtype=int)
    if skies.size == 0:
        raise ParameterError("training", training.source, "at least one sky with the sun above the horizon",
                             "nothing to fit")
    albedo_index = _grid_indices(training.albedo[skies], ALBEDOS, "albedo")
    turbidity_index = _grid_indices(training.turbidity[skies], TURBIDITIES, "turbidity")
    x = elevation_parameter(training.solar_elevation)
    # Each (albedo, turbidity) group's Bezier curve needs CONTROL_POINTS elevations: checked before any
    # work. A group that an unfinished batch leaves short (some of its skies missing) is not fitted.
    short = np.zeros(skies.size, dtype=bool)
    for a in range(len(ALBEDOS)):
        for t in range(len(TURBIDITIES)):
            group = (albedo_index == a) & (turbidity_index == t)
            if group.any() and np.unique(np.round(x[skies[group]], 12)).size < CONTROL_POINTS:
                rendered_later = [s for s in missing if np.isclose(training.albedo[s], ALBEDOS[a])
                                  and np.isclose(training.turbidity[s], TURBIDITIES[t])]
                if not rendered_later:
                    raise ParameterError("solar_elevation", sorted(np.degrees(training.solar_elevation[skies[group]])),
                                         f"at least {CONTROL_POINTS} distinct elevations (deg) per albedo and "
                                         "turbidity", f"too few for albedo {ALBEDOS[a]:g}, turbidity {TURBIDITIES[t]:g}")
                short |= group
                for s in skies[group]:
                    skipped[int(s)] = SHORT_GROUP
    skies, albedo_index, turbidity_index = skies[~short], albedo_index[~short], turbidity_index[~short]
    if skies.size == 0:
        raise ParameterError("training", training.source, f"a group of {CONTROL_POINTS} or more elevations of one "
                             "albedo and turbidity", "nothing to fit")

    timings = {}
    configurations = np.full((len(training.solar_elevation), len(training.channels), n), np.nan)
    radiance_scale = np.full((len(training.solar_elevation), len(training.channels)), np.nan)
    with jax.enable_x64(True):
        begin = time.perf_counter()
        fitted_coefficients, scale, converged, steps = _stage_configurations(form, training, start, skies, weights,
                                                                             progress)
        configurations[skies], radiance_scale[skies] = fitted_coefficients, scale
        timings["per configuration"] = time.perf_counter() - begin
        unconverged = {"per configuration": int((~converged).sum())}
        most_steps = {"per configuration": int(steps.max())}

        begin = time.perf_counter()
        groups, control, points = [], [], []
        for a in range(len(ALBEDOS)):
            for t in range(len(TURBIDITIES)):
                members = skies[(albedo_index == a) & (turbidity_index == t)]
                if members.size == 0:
                    continue
                for c in range(len(training.channels)):
                    groups.append((c, a, t, members))
                    p, r = _stage_bezier(form, x[members], configurations[members, c], radiance_scale[members, c])
                    control.append(p)
                    points.append(r)
        control, points = np.stack(control), np.stack(points)
        timings["bezier"] = time.perf_counter() - begin

        if joint:
            begin = time.perf_counter()
            start_control = np.stack([start.coefficients[training.channel_indices[c], a, t] for c, a, t, _ in groups])
            control, points, converged, steps = _stage_joint(form, training, [(c, m) for c, _, _, m in groups],
                                                             control, points, weights, radiance_scale, start_control,
                                                             joint_prior_weight, progress)
            timings["joint refinement"] = time.perf_counter() - begin
            unconverged["joint refinement"] = int((~converged).sum())
            most_steps["joint refinement"] = int(steps.max())

    coefficients, radiances = start.coefficients.copy(), start.radiances.copy()
    fitted = np.zeros(coefficients.shape[:3], dtype=bool)
    for g, (c, a, t, _) in enumerate(groups):
        channel = training.channel_indices[c]
        coefficients[channel, a, t], radiances[channel, a, t] = control[g], points[g]
        fitted[channel, a, t] = True
    table = CoefficientTable(form, training.kind, coefficients, radiances,
                             source=f"skyref fit ({form}) of {training.source or 'training skies'}")
    return FitResult(table=table, fitted=fitted, configurations=configurations, radiance_scale=radiance_scale,
                     unconverged=unconverged, most_steps=most_steps, timings=timings, skipped=skipped)
