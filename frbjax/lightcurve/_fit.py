"""Spin state, inertia ratios and convex shape of a tumbling body from relative photometry.

:func:`fit_lightcurve` inverts light curves (brightness at times t_k, with the unit vectors to the Sun
and to the observer) for a torque-free motion and a convex shape, the tumbling generalisation of
convex inversion (Kaasalainen & Torppa 2001; Kaasalainen, Torppa & Muinonen 2001; for tumblers
Kaasalainen 2001, Pravec et al. 2005, and the GPU search of Mashchenko 2019, which integrates Euler's
equations numerically where frbjax evaluates the exact motion).

Parameters
----------
The motion (8 numbers, theta): moments (I1, I2, I3) = (exp theta_0, exp theta_1, 1) (only ratios are
identifiable: I -> c I with L -> c L is the same motion); |L| = exp theta_2 (so that the time scale
is |L| / I); the attitude at the epoch q0 = q_ref ⊗ exp(theta_{3:6} / 2); the body-frame direction of
L at the epoch, l = exp-map of theta_{6:8} on the tangent plane at a reference direction l_ref.  The
inertial direction of L is then R(q0) l, the energy (the mode: short-axis SAM or long-axis LAM) is
sum l_i^2 / I_i, and the two periods follow (:func:`frbjax.lightcurve.tumbler_periods`).  A
principal-axis rotator (``principal_axis=True``) is the same model with l = e3 and fixed moments: 4
free numbers (|L|, the attitude), the period 2 pi / |L|.

The shape: ``"convex"``, log-areas s on fixed normals (the icosphere's facet normals), regularised by
the closure of the Gaussian image (sum A n = 0), the smoothness of s over neighbouring facets and its
mean (the overall size is not observable in relative photometry); or ``"ellipsoid"``, the triaxial
ellipsoid with semi-axes (1, exp s_0, exp s_1) along principal axes 1, 2, 3.

Residuals
---------
Relative photometry: each light curve c has an unknown scale.  The residuals are in log flux,
r_k = (log y_k - log m_k - b_c(k)) / sigma, with m the model flux (:func:`brightness`) and b_c the
mean of log y - log m over the curve's samples (the scale eliminated in closed form, its dependence
on the parameters kept: variable projection), sigma the relative noise.  The Jacobian is formed by
forward mode through the exact motion (8 tangents); the shape's columns are analytic (the flux is
linear in the areas).

Search
------
The two periods make the cost landscape rugged: a model whose period is off by dP drifts in phase by
T dP / P^2 over a record of length T.  Starting points are therefore generated on a grid of the two
periods (log-uniform over the given ranges) times random other states (inertia ratios, mode,
polhode phase, attitude): for given moments the ratio P_psi / P_phi fixes the energy (bisection) and
P_psi then fixes |L|.  The shape of each start is the ellipsoid of the same inertia at uniform
density.  All starts are evaluated on the first continuation window (the samples nearest the epoch)
in one vmapped program (thousands of starts); the best ``n_refine`` are solved by optimistix's
Levenberg-Marquardt (one after another on CPU, under ``vmap`` elsewhere) on growing windows
(continuation) with the ellipsoid shape (the first windows hold fewer samples than a convex shape has
areas), as a population: after each window the better half of the starts (by their cost on it) go on
to the next, down to eight, and before each wider window each start's periods are moved to the best
of their shifts by quarter cycles (up to a cycle) at the new window's edge, costed on it as the search
costs its starts, so that Levenberg-Marquardt starts in the cycle count that fits the new samples
rather than in the nearest basin of a wrong one.  For ``shape="convex"`` the convex shape, started
from the Gaussian image of the fitted ellipsoid, is then solved with the motion on all the data for
the best four.  The lowest cost wins.

Uncertainty
-----------
Periods and moments come with standard errors from two covariances of the winner's parameters: the
model's, (J^T J)^+ s^2 (s^2 the residual variance of the data rows over N less the parameters'
effective number, the data rows' part of the hat matrix's trace: a regularised shape's areas count
for what the data determine of them), right where the model describes the body and the noise is
independent; and the cluster-robust sandwich (J^T J)^+ M (J^T J)^+, M = (G - 1) / G sum_c u_c u_c^T
over the light curves' scores u_c = J_c^T (I - H_cc)^-1 r_c (centred; H_cc the hat matrix's block of
light curve c: the jackknife over the light curves, CR3), which stays right where the residuals of a
light curve are correlated: a shape outside the model's family leaves residuals that repeat with the
rotation through each night (Liang & Zeger 1986; Bell & McCaffrey 2002; MacKinnon, Nielsen & Webb
2023).  Each sigma is the larger of the two (the sandwich needs at least
``_MIN_CLUSTERS`` light curves).  That is the winner's basin's uncertainty (``basin_period_sigma``).
The other starts of the last stage that fit within the noise of the winner's cost at periods more
than three of those sigmas away are competing basins (aliases the data do not rule out): the result
lists them, the fit warns, and the reported ``period_sigma`` and ``inertia_sigma`` are the
root-mean-square distances from the winner of the equal-weight mixture of the winner's and their
basins (each with the winner's basin's spread): the data cannot rank them, so the answer is any of
them.  On the tumbler family
(benchmarks/lightcurve_family.py, docs/lightcurve-search.md) the model's covariance alone put the true
periods within three sigmas for 17 of 24 members; these sigmas, for 22 of the same fits, and for all
24 with every search round (the default).

The shape's resolution
----------------------
Both covariances measure the noise's spread about the model's best fit; neither sees the bias of a
shape that the facets cannot follow (a body that is not a convex polyhedron on the icosphere's
normals), which moves the moments and the periods by more than their sigmas where the body is bumpy.
With ``resolution_error`` (the default for the convex shape) the winner is solved once more on all
the data with each facet split in four (4 F normals, each child starting at its parent's area per
solid angle, the same regularisation weights), and the basin's sigmas become the larger of the two
shapes' (the finer shape's freedom, which the coarser holds fixed, widens them where the moments
or the periods are tied to the shape's detail) with the change of the values between the two shapes
in quadrature (the error estimate of an embedded pair).  The fit reports the coarser solution, whose
predictions of new geometry were as good or better on the family (docs/lightcurve-search.md), and the
finer one's periods and moments beside it (``resolution_periods``, ``resolution_inertia`` and their
sigmas).  The finer solve is one Levenberg-Marquardt solve with four times the shape's parameters.

The search runs in rounds (``search_rounds``, default 4): the first draw of the random states on
the period grid, the same draw on the middles of the grid's cells, a new draw on the grid, then the
first search's next ``3 n_refine`` best starts refined (what a fourfold ``n_refine`` would add), and
so on with further draws (:func:`_round_plan`).  By default all of them run: a wrong basin whose
residuals pass the noise (an alias the data nearly allow) would otherwise stop the search before the
truth's basin is among the refined starts, where it is a competing basin that the warning names and
the sigmas span.  Where the winner's residuals are still well above the stated noise, s^2 / sigma^2
above 1 + 4 sqrt(2 / dof) (the sum of squares of a fit in the data's basin is chi-square with dof
degrees of freedom: four of its standard deviations), the rounds go on until one is within it or
``max_search_rounds`` (default twice ``search_rounds``) have run, taking turns: a round on the
grid over the winner's P_psi times exp(+-cell / 8) (cell: the given grid's, the prior of each start as
fine) and P_phi over its given range, with a new draw, then the plan's next round over the given
ranges.  A wrong basin often shares the truth's P_psi, the period that dominates the light curve, and
the truth's basin is then reached from a start whose P_psi is held to a small fraction of a cell
while the other states are drawn; where the winner's P_psi is itself off, the plan's rounds go on.  On
the tumbler families at the defaults, the five members whose first four rounds leave a wrong basin
(about 6 to 320 standard deviations above; 5 at the former shape weights) reach the truth's in the
fifth round, four of them, and in the seventh (the second focused) an Apophis-like tumbler of large
amplitude that twelve of the plan's rounds missed.  The bound is one standard deviation above the
misfit's warning (three): a finely faceted body, outside the model's family, leaves residuals that no
round removes, up to about 3.2 standard deviations on the truth's own refinement, and with the
warning's bound two such members ran twelve rounds each for nothing, one of them 20 minutes on two
cores (docs/lightcurve-search.md, "Rounds past four that take turns" and "Seed 2 at (100, 4)").
With ``stop_at_noise=True`` the rounds stop at the first whose winner is within the warning's bound
(past ``search_rounds``, the search's), in about a quarter of the time where that is the first.  The
lowest cost of all the rounds' refined starts wins; a winner above the warning's bound after the last
round warns: the search has missed the data's basin, or the model does not follow the body, or sigma
understates the noise (docs/lightcurve-search.md: the rounds on the tumbler family of
benchmarks/lightcurve_family.py).

The pole's mirror image
-----------------------
Light curves observed with the Sun and the observer near one plane (the ecliptic, for most
asteroids) leave the pole ambiguous (Kaasalainen & Lamberg 2006, Inverse Problems 22, 749): with M
the reflection through that plane and D = diag(1, 1, -1) the body's, the attitude R -> M R D and the
body-frame L -> -D L map a torque-free motion to another with the same moments and periods (Euler's
equations keep their form under the body's reflection), its pole at -M L (the longitude 180 degrees
away, the same latitude), and the mirrored convex shape (its areas on the normals D n, the icosphere
being symmetric under D) then gives exactly the same light curves for every direction in the plane.
Off the plane they differ, and the data decide as far as they reach. So the winner's mirror image
(through the plane nearest the observations' directions) is solved on all the data too, the lower
cost wins, and the other pole is reported with its cost above the winner's; within a noise unit and
more than 10 degrees away, the fit warns of two poles. On the tumbler family (docs/lightcurve-search.md)
three of the six members whose later nights were predicted worst had been won by the mirror image
of the truth's pole, within 0.36 noise units of the truth's.

The windows hold the samples within a radius of the epoch, the first a tenth of the data, each next
radius 1.8 times the last: a window's fit predicts the phase a factor 1.8 further out, where its
period error has not yet grown to a cycle.  On every window but the last each start keeps its grid
cell as a Gaussian prior, log P ~ N(log P_start, (cell / 2)^2) for both periods: the first windows
(a few nights) hold the periods so weakly that Levenberg-Marquardt leaves the searched range (by
10% and more in P_psi on the synthetic tumblers of the tests) and the continuation then ends in an
alias of the record.  The last window, all the data, has no prior.
"""

from __future__ import annotations

import functools
import math
import typing
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from .. import _checks as checks, _progress, _quaternion as quaternion
from .._body import FreeRigidBody, quaternion_with_elliptic_derivatives
from .._cpu_options import cpu_jit
from .._errors import FitError
from .._multistart import solve_each, starts_in_sequence
from .._trace_once import traced_once
from ._brightness import brightness as _forward, facet_brightness, LAWS
from ._periods import momentum_from_periods, tumbler_periods
from ._shape import _icosphere_area_vectors, ConvexShape, icosphere


__all__ = ["AmbiguousFitWarning", "CompetingBasins", "LightcurveFit", "MisfitWarning", "fit_lightcurve"]

_MIN_WINDOW = 24
_PRINCIPAL_INERTIA = (0.5, 0.75, 1.0)
_SEARCH_SUBDIVISIONS = 1
_WINDOW_GROWTH = 1.8
# Further solves of a leader that stopped at max_steps before it counts as not converged (FitError).
_CONTINUATIONS = 3
# The cluster-robust covariance estimates each variance from G light curves' scores (G - 1 degrees
# of freedom): below this many it is too noisy to use (Cameron & Miller 2015, J. Human Resources 50,
# 317, on few clusters), and the larger of it and the model's would mostly be the noise of the estimate; the
# model's covariance alone then gives the sigmas.  The family of benchmarks/lightcurve_family.py fits
# 20 nights.
_MIN_CLUSTERS = 12
# A light curve whose rows alone determine a direction of the parameters (leverage 1) has no
# jackknife there; (1 - h)^-1 is capped at 100.
_MAX_LEVERAGE = 0.99
# The refinement's population: the best half of the starts go on to each next window, down to
# _SURVIVORS; the convex stage solves the best _CONVEX_STARTS of the last window.
_SURVIVORS = 8
_CONVEX_STARTS = 4
# Period shifts tried before each wider window: up to _SHIFT_CYCLES cycles at the window's edge in
# steps of 1 / _SHIFTS_PER_CYCLE, for each period.
_SHIFT_CYCLES = 1
_SHIFTS_PER_CYCLE = 4
# The winner's and its mirror image's poles are two answers (``LightcurveFit.pole_ambiguous``) when
# they fit within a noise unit of each other and lie more than this many degrees apart; nearer, the
# mirror image is the winner's pole found again (a pole near the plane's normal is its own image).
_POLE_SEPARATION = 10.0
# Past ``search_rounds``, while the winner misses the noise, every other round zooms on the winner's
# P_psi: its range narrowed to the winner's times exp(+-cell / _FOCUS_NARROWING) (cell: the given
# grid's), so that its grid and each start's prior are 7.5 times finer than the given cell over a
# quarter of it, P_phi over its given range (module docstring, the search's rounds).
_FOCUS_NARROWING = 8
# The rounds past ``search_rounds`` run while the winner's residual variance exceeds this many standard
# deviations of its chi-square (1 + _SEARCH_AGAIN_SIGMAS sqrt(2 / dof)), one more than the misfit's
# warning: a body outside the model's family (the families' finely faceted ones) leaves residuals that
# no round removes, up to about 3.2 standard deviations on the truth's own refinement on the tumbler
# families (seed 2's members 8 and 21), while the winners that further rounds moved to the truth's
# basin were about 5 and more above (docs/lightcurve-search.md, "Seed 2 at (100, 4)").
_SEARCH_AGAIN_SIGMAS = 4.0


# ------------------------------------------------------------------------------------ the model


def _tangent_basis(direction):
    """Two unit vectors orthogonal to ``direction`` and to each other (numpy, (..., 2, 3))."""
    direction = np.asarray(direction, float)
    helper = np.where(np.abs(direction[..., :1]) < 0.9, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    first = np.cross(direction, helper)
    first /= np.linalg.norm(first, axis=-1, keepdims=True)
    second = np.cross(direction, first)
    return np.stack([first, second], -2)


def _sphere_exp(base, tangent):
    """exp map on the unit sphere: cos|v| base + sin|v| v/|v| (safe at v = 0)."""
    squared = jnp.sum(tangent**2, -1, keepdims=True)
    small = squared < 1e-12
    safe = jnp.where(small, 1.0, squared)
    norm = jnp.sqrt(safe)
    cosine = jnp.where(small, 1 - squared / 2, jnp.cos(norm))
    sinc = jnp.where(small, 1 - squared / 6, jnp.sin(norm) / norm)
    return cosine * base + sinc * tangent


def _initial_state(theta, reference):
    """(moments (I1, I2, 1), body-frame L, attitude q) of motion parameters theta (8,) with the start's
    reference frame."""
    attitude_ref, direction_ref, basis = reference
    inertia = jnp.exp(jnp.concatenate([theta[:2], jnp.zeros(1, theta.dtype)]))
    attitude = quaternion.multiply(attitude_ref, quaternion.exp_pure(theta[3:6]))
    direction = _sphere_exp(direction_ref, theta[6:8] @ basis)
    return inertia, jnp.exp(theta[2]) * direction, attitude


def _body(theta, reference):
    """The FreeRigidBody of motion parameters theta (8,) with the start's reference frame."""
    return FreeRigidBody(*_initial_state(theta, reference))


def _ellipsoid_shape(shape_parameters, subdivisions):
    return ConvexShape.ellipsoid(1.0, jnp.exp(shape_parameters[0]), jnp.exp(shape_parameters[1]), subdivisions)


def _facet_fluxes(theta, reference, normals, data, law, c):
    """S(mu, mu0) per sample and facet (N, F)."""
    times, sun, observer = data["times"], data["sun"], data["observer"]
    # The elliptic formulas' own derivatives (frbjax._body.quaternion_with_elliptic_derivatives): the
    # solver's Jacobian compiles without the rule of exactly symmetric bodies, which its iterates
    # never are.
    matrices = quaternion.as_matrix(quaternion_with_elliptic_derivatives(_body(theta, reference), times))
    sun_body = jnp.einsum("tji,tj->ti", matrices, sun)
    observer_body = jnp.einsum("tji,tj->ti", matrices, observer)
    return facet_brightness(normals, sun_body, observer_body, law, c)


def _safe_log(flux):
    tiny = jnp.finfo(flux.dtype).tiny ** 0.5
    return jnp.log(jnp.maximum(flux, tiny))


def _log_flux_and_jacobian(parameters, reference, data, config):
    """(log m (N,), d log m / d parameters (N, P)) for parameters = (theta (8), shape parameters)."""
    kind, law, c, subdivisions, _ = config
    theta, shape_parameters = parameters[:8], parameters[8:]
    if kind == "convex":
        areas = jnp.exp(shape_parameters)

        def log_flux(theta):
            per_facet = _facet_fluxes(theta, reference, data["normals"], data, law, c)
            flux = per_facet @ areas
            return _safe_log(flux), (per_facet, flux)

        jac_theta, (per_facet, flux) = jax.jacfwd(log_flux, has_aux=True)(theta)
        # The flux is linear in the areas: d log m / d s_f = A_f S_f / m.
        jac_shape = per_facet * areas[None, :] / jnp.maximum(flux, jnp.finfo(flux.dtype).tiny ** 0.5)[:, None]
        return _safe_log(flux), jnp.concatenate([jac_theta, jac_shape], 1)

    def log_flux(parameters):
        shape = _ellipsoid_shape(parameters[8:], subdivisions)
        per_facet = _facet_fluxes(parameters[:8], reference, shape.normals, data, law, c)
        value = _safe_log(per_facet @ shape.areas)
        return value, value

    jacobian, value = jax.jacfwd(log_flux, has_aux=True)(parameters)
    return value, jacobian


def _log_model(parameters, reference, data, config):
    """log m (N,) of parameters = (theta (8), shape parameters), its value alone (the posterior's)."""
    kind, law, c, subdivisions, _ = config
    if kind == "convex":
        normals, areas = data["normals"], jnp.exp(parameters[8:])
    else:
        shape = _ellipsoid_shape(parameters[8:], subdivisions)
        normals, areas = shape.normals, shape.areas
    return _safe_log(_facet_fluxes(parameters[:8], reference, normals, data, law, c) @ areas)


def _regularisation(shape_parameters, data):
    """A convex shape's regularisation rows: the closure of its Gaussian image (3), the smoothness of
    its log-areas (F), their mean (1), the first two weighted by ``data["regularisation"]``."""
    areas = jnp.exp(shape_parameters)
    closure = areas @ data["normals"] / jnp.sum(areas)
    weights = data["regularisation"]
    smooth = data["laplacian"] @ shape_parameters
    return jnp.concatenate([weights[0] * closure, weights[1] * smooth, jnp.mean(shape_parameters, keepdims=True)])


def _curve_mean(values, weights, curves):
    """Weighted mean over each sample's light curve, at every sample: (N,) or (N, P)."""
    expand = (lambda w: w) if values.ndim == 1 else (lambda w: w[:, None])
    totals = curves.T @ (expand(weights) * values)
    counts = curves.T @ weights
    means = totals / expand(jnp.where(counts > 0, counts, 1.0))
    return curves @ means


def _periods(theta, reference, principal_axis):
    """((P_psi, P_phi), LAM) of motion parameters theta.  A principal-axis rotation has one period,
    2 pi I3 / |L| (I3 = 1), reported as P_psi with P_phi infinite: the limit of the tumbler's
    (P_psi, P_phi) at vanishing nutation is not it (1/P = 1/P_psi - 1/P_phi there, for SAM)."""
    # The moments and L alone: building the body (its records) is work the periods do not need.
    inertia, momentum, _ = _initial_state(theta, reference)
    p_psi, p_phi, long_axis = tumbler_periods(inertia, momentum)
    if principal_axis:
        p_psi, p_phi = 2 * jnp.pi / jnp.exp(theta[2]), jnp.asarray(jnp.inf, theta.dtype)
    return jnp.stack([p_psi, p_phi]), long_axis


def _log_periods(theta, reference, principal_axis):
    """log (P_psi, P_phi), the infinite P_phi of a principal-axis rotation as 0 (its prior is off)."""
    periods = _periods(theta, reference, principal_axis)[0]
    return jnp.log(jnp.where(jnp.isfinite(periods), periods, 1.0))


def _rows(parameters, reference, data, window, config):
    """(r (R,), dr/dparameters (R, P)): data rows, the shape's regularisation rows, the period prior's;
    the Jacobian's columns of fixed parameters (``data["free"]`` 0) zero.  Half their sum of squares
    is the fit's cost, and the negative log posterior of :func:`frbjax.posterior.lightcurve_posterior`.

    ``window`` = (weights (N,) of the samples, prior (log centre (2,), inverse widths (2,)), prior
    weight): the continuation window, and the start's period cell as a Gaussian prior in log P; a
    prior of None has no rows (a stage without it does not evaluate the periods at every step)."""
    kind, principal_axis = config[0], config[4]
    weights, prior, prior_weight = window
    log_model, jac = _log_flux_and_jacobian(parameters, reference, data, config)
    difference = data["log_brightness"] - log_model
    offset = _curve_mean(difference, weights, data["curves"])
    scale = weights / data["sigma"]
    residual = scale * (difference - offset)
    jacobian = -scale[:, None] * (jac - _curve_mean(jac, weights, data["curves"]))
    if kind == "convex":
        shape_parameters = parameters[8:]
        areas = jnp.exp(shape_parameters)
        normals, total = data["normals"], jnp.sum(jnp.exp(shape_parameters))
        closure = areas @ normals / total
        d_closure = (areas[:, None] * (normals - closure[None, :]) / total).T  # (3, F)
        weights_reg = data["regularisation"]
        reg = _regularisation(shape_parameters, data)
        d_reg = jnp.concatenate(
            [
                weights_reg[0] * d_closure,
                weights_reg[1] * data["laplacian"],
                jnp.full((1, areas.size), 1.0 / areas.size, areas.dtype),
            ]
        )
        d_reg = jnp.concatenate([jnp.zeros((d_reg.shape[0], 8), d_reg.dtype), d_reg], 1)
        residual = jnp.concatenate([residual, reg])
        jacobian = jnp.concatenate([jacobian, d_reg])
    if prior is not None:
        prior_centre, prior_inverse_width = prior
        log_periods = lambda theta: _log_periods(theta, reference, principal_axis)  # noqa: E731
        prior_scale = prior_weight * prior_inverse_width
        d_prior = prior_scale[:, None] * jax.jacfwd(log_periods)(parameters[:8])
        residual = jnp.concatenate([residual, prior_scale * (log_periods(parameters[:8]) - prior_centre)])
        jacobian = jnp.concatenate([jacobian, jnp.pad(d_prior, ((0, 0), (0, parameters.size - 8)))])
    return residual, jacobian * data["free"][None, :]


@functools.partial(traced_once, static_argnums=4)
def _residuals_and_jacobian(parameters, reference, data, window, config):
    """:func:`_rows` for the solver, a non-finite row (a motion the formulas cannot evaluate) zero
    (traced once for the primal and the JVP of ``_least_squares_fn``: ``frbjax._trace_once``)."""
    residual, jacobian = _rows(parameters, reference, data, window, config)
    finite = jnp.isfinite(residual)
    return jnp.where(finite, residual, 0.0), jnp.where(finite[:, None] & jnp.isfinite(jacobian), jacobian, 0.0)


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def _least_squares_fn(parameters, args, config):
    """(r, (r, J)) for optimistix; its JVP is J @ dp with J from one forward-mode pass."""
    reference, data, window = args
    residual, jacobian = _residuals_and_jacobian(parameters, reference, data, window, config)
    return residual, (residual, jacobian)


@_least_squares_fn.defjvp
def _least_squares_fn_jvp(config, primals, tangents):
    parameters, (reference, data, window) = primals
    residual, jacobian = _residuals_and_jacobian(parameters, reference, data, window, config)
    aux = (residual, jacobian)
    return (residual, aux), (jacobian @ tangents[0], jax.tree.map(jnp.zeros_like, aux))


def _column_scale(jacobian):
    """Marquardt's scaling of the parameters: the Jacobian's column norms (1 for a zero column)."""
    norms = jnp.sqrt(jnp.sum(jacobian**2, 0))
    return jnp.where(jnp.isfinite(norms) & (norms > 0), norms, 1.0)


def _solve_start(parameters, reference, prior, data, masks, prior_weights, config, rtol, atol, max_steps, x_scale):
    """Levenberg-Marquardt on each window of ``masks`` in turn (continuation), the period prior
    weighted by ``prior_weights`` (one per window; ``prior`` and ``prior_weights`` None: no prior,
    an empty pytree that the scan carries as it is).

    ``x_scale="jac"``: each window's solve continued from its end for the parameters times the
    Jacobian's column norms there (Marquardt 1963; Moré 1978, the scaling of MINPACK's lmder;
    scipy's ``least_squares(x_scale="jac")``), so that the damping, a multiple of the identity in
    optimistix's Levenberg-Marquardt, acts alike on every parameter.  Unscaled, a convex shape's
    hundreds of log-areas (columns of norm about 1 to 100) and the motion's (1e3 to 1e5, their lever
    arm the record's length) share one damping, which the steps' failures raise until the motion is
    frozen: the solve fits the shape to the motion it started from, then stops, often well above its
    minimum, its steps below ``rtol``.  Scaled from the start instead, the motion's first steps,
    taken while the shape is still the ellipsoid's, left good basins (docs/lightcurve-search.md,
    "Levenberg-Marquardt's scaling")."""
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    fn = lambda p, args: _least_squares_fn(p, args, config)  # noqa: E731

    def stage(current, window):
        mask, prior_weight = window
        args = (reference, data, (mask, prior, prior_weight))
        solution = optx.least_squares(fn, solver, current, args=args, has_aux=True, max_steps=max_steps, throw=False)
        finite = jnp.all(jnp.isfinite(solution.value))
        value = jnp.where(finite, solution.value, current)
        # The residuals and Jacobian at solution.value, the solver's last accepted point: the aux
        # that optimistix's Gauss-Newton state keeps with it (0.0.10 and 0.1.0 alike; in 0.1.0 the
        # solution's own aux is that of the point before).  The last window's cost and covariance
        # come without another copy of the model in the program: the refinement's compilation
        # 4.6 -> 3.0 s (LAM, one core).  A window whose solution is not finite leaves no valid cost.
        (residual, jacobian), converged = solution.state.aux, solution.result == optx.RESULTS.successful
        if x_scale == "jac":
            # Continued, scaled, from the unscaled solve's end, where the shape has been fitted to the
            # motion it started from (docstring).
            scale = _column_scale(jacobian)
            scaled_fn = lambda scaled, args: _least_squares_fn(scaled / scale, args, config)  # noqa: E731
            continued = optx.least_squares(
                scaled_fn, solver, value * scale, args=args, has_aux=True, max_steps=max_steps, throw=False
            )
            kept = jnp.all(jnp.isfinite(continued.value))
            value = jnp.where(kept, continued.value / scale, value)
            residual, jacobian = (
                jnp.where(kept, new, old) for new, old in zip(continued.state.aux, (residual, jacobian))
            )
            converged = jnp.where(kept, continued.result == optx.RESULTS.successful, converged)
            finite = finite | kept
        residual = jnp.where(finite, residual, jnp.nan)
        # One window of one start done: the refinement's progress bar (``frbjax._progress``).
        jax.debug.callback(_progress.advance, "lightcurve refinement", 1)
        return value, (converged, residual, jacobian)

    parameters, (ok, residuals, jacobians) = jax.lax.scan(stage, parameters, (masks, prior_weights))
    residual, jacobian = residuals[-1], jacobians[-1]
    cost = 0.5 * jnp.sum(residual**2)
    return parameters, jnp.where(jnp.isfinite(cost), cost, jnp.inf), ok[-1], residual, jacobian


def _refine_starts(
    parameters, references, priors, data, masks, prior_weights, config, rtol, atol, max_steps, x_scale=1.0
):
    """Each start (parameters, reference, prior, masks (W, N): its windows) solved by _solve_start,
    one after another or batched (``frbjax._multistart``)."""

    def solve(p, reference, prior, start_masks):
        return _solve_start(
            p, reference, prior, data, start_masks, prior_weights, config, rtol, atol, max_steps, x_scale
        )

    return solve_each(solve, (parameters, references, priors, masks))


# The refinement's programs compiled in 7.8 s instead of 13.8 (the LAM test, one core, 2026-11-29),
# and ran as fast (its second call 16.8 s against 17.2): ``frbjax._cpu_options``.
_refine = cpu_jit(_refine_starts, static_argnames=("config", "rtol", "atol", "max_steps", "x_scale"))


@cpu_jit(static_argnames="config")
def _search_costs(parameters, references, start_areas, data, mask, config):
    """Cost of each start of a chunk on the first window with its own shape (the ellipsoid of its
    inertia)."""
    _, law, c, _, _ = config

    def cost(theta, reference, areas):
        per_facet = _facet_fluxes(theta[:8], reference, data["search_normals"], data, law, c)
        difference = data["log_brightness"] - _safe_log(per_facet @ areas)
        residual = mask * (difference - _curve_mean(difference, mask, data["curves"])) / data["sigma"]
        value = 0.5 * jnp.sum(residual**2)
        return jnp.where(jnp.isfinite(value), value, jnp.inf)

    return jax.vmap(cost)(parameters, references, start_areas)


def _search(parameters, references, start_areas, data, mask, config, chunk, progress):
    """Every start's cost (``_search_costs``), ``chunk`` starts per call of one compiled program (the
    last chunk padded with the first start), each chunk a step of the search's progress bar."""
    count = len(parameters)
    costs = []
    with _progress.bar("lightcurve search", count, "light-curve search", "start", shown=progress) as bar:
        for start in range(0, count, chunk):
            rows = np.arange(start, start + chunk)
            rows = np.where(rows < count, rows, 0)
            take = lambda tree: jax.tree.map(lambda x: x[rows], tree)  # noqa: E731
            costs.append(
                np.asarray(_search_costs(take(parameters), take(references), take(start_areas), data, mask, config))
            )
            if bar is not None:
                _progress.advance("lightcurve search", min(chunk, count - start))
    return np.concatenate(costs)[:count]


_momenta_from_periods = cpu_jit(jax.vmap(momentum_from_periods))


@cpu_jit(static_argnames="principal_axis")
def _fitted_motion(theta, reference, principal_axis):
    """(the body, (P_psi, P_phi), LAM, the periods' Jacobian in theta) of the fitted theta: one
    program (eagerly, each of the body's operations was compiled in turn)."""

    def periods(theta):
        values, long_axis = _periods(theta, reference, principal_axis)
        return values, (values, long_axis)

    jacobian, (values, long_axis) = jax.jacfwd(periods, has_aux=True)(theta)
    return _body(theta, reference), values, long_axis, jacobian


def _plane_normal(sun, observer):
    """The unit normal of the plane nearest the directions (N, 3) to the Sun and to the observer: the
    eigenvector of sum (s s^T + o o^T) with the smallest eigenvalue."""
    _, vectors = np.linalg.eigh(sun.T @ sun + observer.T @ observer)
    return vectors[:, 0]


def _mirrored_normals(normals):
    """The index of each normal's image under the body's reflection D = diag(1, 1, -1): the icosphere
    is symmetric under it, so that a convex shape's mirror image has the same normals, its areas
    permuted."""
    image = normals * np.array([1.0, 1.0, -1.0])
    index = np.argmax(image @ normals.T, -1)
    if not np.allclose(normals[index], image, atol=1e-9):
        raise AssertionError("the shape's normals are not symmetric under z -> -z")
    return index


def _mirror_image(parameters, reference, plane_normal, normal_index):
    """The parameters and reference frame of the motion and shape mirrored through the plane of
    ``plane_normal`` (module docstring, "The pole's mirror image"): the attitude R -> M R D, the
    body-frame L -> -D L, the convex shape's areas moved to the mirrored normals (``normal_index``;
    None: an ellipsoid, its own image)."""
    inertia, momentum, attitude = _initial_state(jnp.asarray(parameters[:8]), tuple(map(jnp.asarray, reference)))
    body_reflection = np.diag([1.0, 1.0, -1.0])
    reflection = np.eye(3) - 2 * np.outer(plane_normal, plane_normal)
    rotation = reflection @ np.asarray(quaternion.as_matrix(attitude)) @ body_reflection
    mirrored_attitude = np.asarray(quaternion.from_matrix(jnp.asarray(rotation)))
    direction = -body_reflection @ np.asarray(momentum)
    direction /= np.linalg.norm(direction)
    mirrored = np.array(parameters, float)
    mirrored[3:8] = 0.0
    if normal_index is not None:
        mirrored[8:] = np.asarray(parameters)[8:][normal_index]
    return mirrored, (mirrored_attitude, direction, _tangent_basis(direction))


# ------------------------------------------------------------------------------------ the result


class CompetingBasins(typing.NamedTuple):
    """Runner-up basins of a light-curve fit (:meth:`LightcurveFit.competing_basins`), best first.

    - ``cost_excess`` (M,): each one's cost above the winner's, in noise units of a cost;
    - ``periods`` (M, 2): its (P_psi, P_phi);
    - ``distance`` (M,): its largest |P - P_winner| in the winner's basin's sigmas
      (``LightcurveFit.basin_period_sigma``).
    """

    cost_excess: np.ndarray
    periods: np.ndarray
    distance: np.ndarray


class AmbiguousFitWarning(UserWarning):
    """:func:`fit_lightcurve` found basins at other periods that fit the data within the noise of the
    winner's (:meth:`LightcurveFit.competing_basins`: the reported sigmas span them all), or a mirror
    pole that does (:attr:`LightcurveFit.pole_ambiguous`)."""


def _warn_if_ambiguous(result, stacklevel=3):
    """An :class:`AmbiguousFitWarning` naming the competing basins of ``result`` and its mirror pole,
    if it has any."""
    basins = result.competing_basins()
    messages = []
    if len(basins.cost_excess):
        winner = np.asarray(result.periods, float)
        listed = "; ".join(
            f"periods {_format_periods(p)} at {e:.2f} noise units of cost ({d:.0f} sigma away)"
            for e, p, d in zip(basins.cost_excess, basins.periods, basins.distance)
        )
        messages.append(
            f"{len(basins.cost_excess)} other basin(s) fit the data within the noise of the winner (periods "
            f"{_format_periods(winner)}): {listed}.  The data do not tell them apart: the reported sigmas are the "
            "root-mean-square distances from the winner of these basins and its own (that alone: "
            "basin_period_sigma; LightcurveFit.competing_basins()).  More nights, or a wider spread of them, decide."
        )
    if result.pole_ambiguous:
        messages.append(
            f"the mirror image of the winner through the plane of the observations, solved on the data, fits them "
            f"within {result.mirror_cost_excess:.2f} noise units of cost, its pole "
            f"{_format_direction(result.mirror_momentum_direction)} {result.pole_separation:.0f} degrees from the "
            f"winner's {_format_direction(result.momentum_direction)}: observations near one plane do not tell the "
            "two poles apart (LightcurveFit.mirror_momentum_direction); nights further from that plane decide."
        )
    if messages:
        warnings.warn("fit_lightcurve: " + "  And ".join(messages), AmbiguousFitWarning, stacklevel=stacklevel)


class MisfitWarning(UserWarning):
    """:func:`fit_lightcurve`'s best fit after its last search round leaves residuals larger than the
    stated noise (``LightcurveFit.noise_ratio`` above its chi-square bound): the search missed the
    data's basin, or ``sigma`` understates the noise, or the model does not describe the body."""


def _warn_of_misfit(result, bound, sigma, within_model_error, stacklevel=3):
    """A :class:`MisfitWarning` for ``result``, whose ``noise_ratio`` exceeds ``bound``; where it is
    ``within_model_error`` (below the search's bound, ``_SEARCH_AGAIN_SIGMAS``) no further round ran."""
    if within_model_error:
        cause = (
            "within what a body outside the model's family leaves, so no further round was searched (they run "
            f"above (s / sigma)^2 = 1 + {_SEARCH_AGAIN_SIGMAS:g} sqrt(2 / dof)): the model may not follow the body's "
            "shape, or sigma understates the noise, or the search missed the data's basin by little"
        )
    else:
        cause = (
            "the search may have missed the data's basin (a larger max_search_rounds, a finer period_grid or "
            "narrower period ranges), or sigma understates the noise"
        )
    warnings.warn(
        f"fit_lightcurve: the best fit's residuals are {result.noise_ratio:.3g} times the stated noise "
        f"sigma={sigma:g} (bound {bound:.3g}) after {result.search_rounds} search round(s), {cause}.  The "
        "reported sigmas assume the residuals' own level.",
        MisfitWarning,
        stacklevel=stacklevel,
    )


def _format_periods(periods):
    return "(" + ", ".join(f"{p:.6g}" for p in np.asarray(periods, float) if np.isfinite(p)) + ")"


def _format_direction(direction):
    return "(" + ", ".join(f"{x:.3f}" for x in np.asarray(direction, float)) + ")"


class LightcurveFit(eqx.Module):
    """Result of :func:`fit_lightcurve`.

    - ``body``: the fitted :class:`frbjax.FreeRigidBody` (time from the epoch), moments (I1, I2, 1);
    - ``shape``: the fitted :class:`ConvexShape` (principal frame; relative size);
    - ``epoch``: the reference time (model time t - epoch);
    - ``periods`` (2,): (P_psi, P_phi), precession and rotation periods (principal axis: (P, inf));
      ``period_sigma`` (2,): their standard errors: the winner's basin's (``basin_period_sigma``, the
      larger of ``covariance``'s, ``robust_covariance``'s and the finer shape's, with the change of
      the value between the two shapes in quadrature: ``resolution_error``), widened to span the
      competing basins where there are any (:meth:`competing_basins`; the module docstring's
      "Uncertainty");
    - ``long_axis_mode``: LAM (True) or SAM; ``energy_ratio``: E / E0 = 2 E I3 / |L|^2 (1 for a
      principal-axis rotation about the largest moment);
    - ``inertia`` (3,): fitted moments scaled to a largest of 1; ``inertia_sigma`` (3,), as
      ``period_sigma``;
    - ``momentum_direction`` (3,): the inertial direction of L (the pole of the angular momentum);
      ``mirror_momentum_direction`` (3,), ``mirror_cost_excess``: the other pole of the winner and its
      mirror image through the plane of the observations (module docstring, "The pole's mirror
      image"), and its cost above the winner's in noise units (NaN and inf with
      ``mirror_pole=False``): within a noise unit and more than 10 degrees away, the data do not
      tell the two poles apart (:attr:`pole_ambiguous`; :func:`fit_lightcurve` warns);
    - ``parameters``: (theta (8), shape parameters) of the module docstring; ``covariance``: their
      covariance (J^T J)^+ s^2 (s^2: the data rows' residual variance over their effective degrees
      of freedom); ``robust_covariance``: the cluster-robust sandwich over the light curves (zeros with
      fewer than ``_MIN_CLUSTERS`` = 12 light curves);
    - ``scales`` (C,): the fitted scale of each light curve (data = scale * model);
    - ``residuals`` (N,): log(data) - log(scale * model) per sample (input order);
    - ``cost``: half the sum of squared (weighted) residuals; ``success``: the solver converged;
    - ``search_periods`` (S, 2), ``search_costs`` (S,): the periods of every start and its cost on the
      first window (the search's landscape; every round's starts, in turn); ``refine_costs`` (K,),
      ``refine_periods`` (K, 2): the cost and the periods of each start solved on all the data (the
      refinement's last stage of every round: the best four for a convex shape; then the best one's
      mirror image, ``mirror_pole``), the winner's among them: runner-ups within the noise of the
      winner's cost (about sqrt(N / 2)) at other periods are basins the data do not tell apart
      (:meth:`competing_basins`, :attr:`ambiguous`; :func:`fit_lightcurve` warns of them);
    - ``noise_ratio``: s / sigma, the residuals' level over the stated noise (1 where the model and
      ``sigma`` hold; where (s / sigma)^2 exceeds 1 + 3 sqrt(2 / dof) after the last round,
      :func:`fit_lightcurve` warns: :class:`MisfitWarning`); ``search_rounds``: the rounds it ran
      (fewer than ``search_rounds`` only with ``stop_at_noise=True``; more, up to
      ``max_search_rounds``, where the winner missed the noise by more than 1 + 4 sqrt(2 / dof));
    - ``resolution_periods`` (2,), ``resolution_inertia`` (3,) and their sigmas
      ``resolution_period_sigma``, ``resolution_inertia_sigma``: the periods and moments of the
      winner solved again with each facet of the convex shape split in four (``resolution_error``;
      NaN without it, for an ellipsoid, or where that solve does not converge): the shape's
      resolution error, the larger of the two shapes' sigmas and the change of the values in
      quadrature, is in ``basin_period_sigma`` and the sigmas built on it;
    - ``shape_model`` (``"convex"`` or ``"ellipsoid"``) and ``regularisation`` (the convex shape's
      closure and smoothness weights): the fit's settings, which the posterior's shape prior reuses.
    """

    body: FreeRigidBody
    shape: ConvexShape
    epoch: float
    law: str = eqx.field(static=True)
    c: float
    periods: Float[Array, 2]
    period_sigma: Float[Array, 2]
    basin_period_sigma: Float[Array, 2]
    long_axis_mode: bool
    energy_ratio: float
    inertia: Float[Array, 3]
    inertia_sigma: Float[Array, 3]
    momentum_direction: Float[Array, 3]
    mirror_momentum_direction: Float[Array, 3]
    mirror_cost_excess: float
    parameters: Float[Array, " P"]
    covariance: Float[Array, "P P"]
    robust_covariance: Float[Array, "P P"]
    scales: Float[Array, " C"]
    residuals: Float[Array, " N"]
    cost: float
    success: bool
    search_periods: Float[Array, "S 2"]
    search_costs: Float[Array, " S"]
    refine_costs: Float[Array, " K"]
    refine_periods: Float[Array, "K 2"]
    noise_ratio: float
    search_rounds: int
    resolution_periods: Float[Array, 2]
    resolution_period_sigma: Float[Array, 2]
    resolution_inertia: Float[Array, 3]
    resolution_inertia_sigma: Float[Array, 3]
    # The frame about which ``parameters`` are counted (the winner's start: its attitude, the inertial
    # direction of L and two unit vectors across it): for the posterior (frbjax.posterior).
    _reference: tuple = ()
    # The shape model ("convex": log-areas on fixed normals; "ellipsoid": two log axis ratios) and the
    # convex shape's regularisation weights (closure, smoothness): the posterior's shape prior.
    shape_model: str = eqx.field(static=True, default="convex")
    regularisation: tuple[float, float] = eqx.field(static=True, default=(100.0, 4.0))

    def competing_basins(self, within: float = 1.0) -> CompetingBasins:
        """The runner-up solutions the data do not tell from this one: the last stage's starts
        (``refine_costs``, ``refine_periods``) whose cost is within ``within`` noise units of the
        winner's and whose periods differ from the winner's by more than 3 of its basin's sigmas
        (``basin_period_sigma``: another basin, not the winner's own found twice).

        The noise unit of a cost is its standard deviation under the fit's own noise level,
        sqrt(N / 2) (s / sigma)^2 with N the samples fitted and (s / sigma)^2 = 2 cost / N (1 when
        ``sigma`` is the data's noise): the cost of the truth's basin varies by that much from one
        draw of the noise to another, so a runner-up within it is as good an answer.  Where there is
        one, the periods are one of these, and more data (nights that resolve the aliases) decide;
        the reported ``period_sigma`` and ``inertia_sigma`` span them (with the default ``within``).

        Returns a :class:`CompetingBasins` sorted by cost (empty arrays when there is none).
        """
        within = checks.scalar("within", within, positive=True, allow_zero=True)
        periods = np.asarray(self.refine_periods, float)
        order, excess, distance = _basins(
            np.asarray(self.refine_costs, float),
            periods,
            np.asarray(self.periods, float),
            np.asarray(self.basin_period_sigma, float),
            int(np.sum(np.isfinite(np.asarray(self.residuals)))),
            self.cost,
            within,
        )
        return CompetingBasins(cost_excess=excess, periods=periods[order], distance=distance)

    def standard_errors(self, covariance=None):
        """(period sigma (2,), inertia sigma (3,)) of the winner's basin, first order in
        ``covariance`` (P, P) of ``parameters``: ``fit.covariance`` (the model's alone, which a
        posterior under the model's likelihood reproduces: :mod:`frbjax.posterior`) or
        ``fit.robust_covariance``; by default the larger of the two per quantity with the shape's
        resolution error (``resolution_periods`` and the rest: the module docstring's "The shape's
        resolution"), as ``basin_period_sigma``.  No competing basins are spanned (``period_sigma`` spans them)."""
        covariances = (self.covariance, self.robust_covariance) if covariance is None else (covariance,)
        covariances = tuple(np.asarray(cov, float) for cov in covariances)
        size = np.asarray(self.parameters).size
        for cov in covariances:
            if cov.shape != (size, size):
                raise ValueError(f"covariance must have shape (P, P) = ({size}, {size}), got {cov.shape}")
        principal_axis = not np.isfinite(float(self.periods[1]))
        reference = tuple(jnp.asarray(r) for r in self._reference)
        _, _, _, period_jacobian = _fitted_motion(jnp.asarray(self.parameters[:8]), reference, principal_axis)
        period_jacobian = np.nan_to_num(np.asarray(period_jacobian), posinf=0.0, neginf=0.0)
        period_sigma, inertia_sigma = _standard_errors(period_jacobian, np.asarray(self.parameters, float), covariances)
        if covariance is None:
            period_sigma = _with_resolution_error(
                period_sigma, np.asarray(self.resolution_period_sigma), self.periods, self.resolution_periods
            )
            inertia_sigma = _with_resolution_error(
                inertia_sigma, np.asarray(self.resolution_inertia_sigma), self.inertia, self.resolution_inertia
            )
        return period_sigma, inertia_sigma

    @property
    def ambiguous(self) -> bool:
        """True when another basin fits the data within the noise of this one (:meth:`competing_basins`)."""
        return len(self.competing_basins().cost_excess) > 0

    @property
    def pole_separation(self) -> float:
        """The angle (degrees) between ``momentum_direction`` and ``mirror_momentum_direction``."""
        cosine = float(np.dot(np.asarray(self.momentum_direction), np.asarray(self.mirror_momentum_direction)))
        return math.degrees(math.acos(min(max(cosine, -1.0), 1.0))) if math.isfinite(cosine) else math.nan

    @property
    def pole_ambiguous(self) -> bool:
        """True when the mirror image's pole fits the data within a noise unit of the winner's and lies
        more than 10 degrees from it: two poles the observations, near one plane, do not tell apart."""
        return bool(self.mirror_cost_excess <= 1.0 and self.pole_separation > _POLE_SEPARATION)

    def predict(self, times, sun, observer):
        """The model brightness (unscaled: multiply by a light curve's scale) at ``times``."""
        times = jnp.asarray(times)
        return _forward(self.body, self.shape, times - self.epoch, sun, observer, self.law, self.c)

    def shape_inertia(self):
        """Principal moments of the fitted shape at uniform density (from its polyhedron, Minkowski's
        problem), in the body's axes (the diagonal of its inertia tensor) scaled to a largest of 1,
        beside ``inertia``; and the whole tensor (same scale)."""
        _, tensor = self.shape.inertia()
        diagonal = np.diag(tensor)
        return diagonal / diagonal.max(), tensor / diagonal.max()


# ------------------------------------------------------------------------------------ starts


def _random_rotations(rng, count):
    q = rng.normal(size=(count, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q * np.where(q[:, :1] < 0, -1, 1)


@cpu_jit  # one program: eagerly, each of its operations was compiled in turn
def _rotate(q, v):
    return jnp.einsum("...ij,...j->...i", quaternion.as_matrix(q), v)


def _ellipsoid_axes(inertia):
    """Semi-axes of the uniform ellipsoid with principal moments ``inertia`` (..., 3) (up to scale):
    I1 ∝ b^2 + c^2, ... => a^2 ∝ I2 + I3 - I1, ..."""
    squares = np.stack(
        [
            inertia[..., 1] + inertia[..., 2] - inertia[..., 0],
            inertia[..., 0] + inertia[..., 2] - inertia[..., 1],
            inertia[..., 0] + inertia[..., 1] - inertia[..., 2],
        ],
        -1,
    )
    return np.sqrt(np.maximum(squares, 1e-6))


def _gaussian_image_areas(axes, normals, solid_angles):
    """Facet areas of the ellipsoid with semi-axes ``axes`` on fixed normals: the area per solid angle
    is 1/K = (abc)^2 / h(n)^4, h(n) = sqrt(sum a_i^2 n_i^2) its support function."""
    support = np.sqrt(np.einsum("...i,fi->...f", axes**2, normals**2))
    return solid_angles * np.prod(axes, -1)[..., None] ** 2 / support**4


def _unit_normals(subdivisions):
    """The icosphere's outward unit normals, solid angles (summing to 4 pi) and faces (numpy)."""
    _, faces = icosphere(subdivisions)
    area_vectors = _icosphere_area_vectors(subdivisions)
    areas = np.linalg.norm(area_vectors, axis=-1)
    return area_vectors / areas[:, None], areas * 4 * np.pi / areas.sum(), faces


def _laplacian(faces):
    """Graph Laplacian (F, F) of the facets sharing an edge: s_f - mean of its neighbours."""
    count = len(faces)
    edges: dict[tuple[int, int], list[int]] = {}
    for index, face in enumerate(faces):
        for i in range(3):
            key = tuple(sorted((int(face[i]), int(face[(i + 1) % 3]))))
            edges.setdefault(key, []).append(index)
    matrix = np.eye(count)
    neighbours = [[] for _ in range(count)]
    for pair in edges.values():
        if len(pair) == 2:
            neighbours[pair[0]].append(pair[1])
            neighbours[pair[1]].append(pair[0])
    for index, around in enumerate(neighbours):
        for other in around:
            matrix[index, other] -= 1.0 / len(around)
    return matrix


# ------------------------------------------------------------------------------------ the fit


def _with_omitted_rows(rows, omitted):
    """``rows`` of the fitted samples placed at their input indices, NaN at the omitted ones."""
    full = np.full(omitted.shape + rows.shape[1:], np.nan)
    full[~omitted] = rows
    return full


def _survivor_counts(starts, windows):
    """How many starts are solved on each window: all on the first, then half as many on each next
    (rounded up), never fewer than ``_SURVIVORS`` (or the starts, if fewer)."""
    counts = [starts]
    for _ in range(windows - 1):
        counts.append(max(-(-counts[-1] // 2), min(_SURVIVORS, starts)))
    return counts


def _period_shifts(parameters, reference, radius, log_ranges, principal_axis):
    """``parameters`` (P,) and copies of them with the periods shifted (first the unshifted).

    A period error dP drifts the phase at time t from the epoch by t dP / P^2 cycles: the shifts of
    log P are k P / (_SHIFTS_PER_CYCLE radius) for |k| <= _SHIFT_CYCLES _SHIFTS_PER_CYCLE, on both
    periods (a grid), each realised as the least-norm change of theta that makes it to first order,
    dtheta = (d log P / dtheta)^+ d log P.  Shifts that leave the searched ranges are not tried."""
    # The fitted motion's program (it builds the body too, unused here): compiled for the result anyway,
    # where a program of the periods' Jacobian alone would be one more to compile.
    _, periods, _, jacobian = _fitted_motion(jnp.asarray(parameters[:8]), reference, principal_axis)
    periods, jacobian = np.asarray(periods, float), np.asarray(jacobian, float)
    finite = np.isfinite(periods) & np.all(np.isfinite(jacobian), -1)
    log_jacobian = np.where(finite[:, None], jacobian / np.where(finite, periods, 1.0)[:, None], 0.0)
    steps = np.arange(-_SHIFT_CYCLES * _SHIFTS_PER_CYCLE, _SHIFT_CYCLES * _SHIFTS_PER_CYCLE + 1) / _SHIFTS_PER_CYCLE
    axes = [steps * periods[k] / radius if finite[k] else np.zeros(1) for k in range(2)]
    shifts = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 2)
    shifts = shifts[np.argsort(np.sum(np.abs(shifts), -1), kind="stable")]  # the unshifted first
    log_periods = np.log(np.where(finite, periods, 1.0)) + shifts
    inside = np.all((log_periods >= log_ranges[:, 0]) & (log_periods <= log_ranges[:, 1]) | ~finite, -1)
    inside[0] = True
    trials = np.repeat(np.asarray(parameters, float)[None], int(inside.sum()), 0)
    trials[:, :8] += shifts[inside] @ np.linalg.pinv(log_jacobian).T
    return trials


class _Misfit(typing.NamedTuple):
    variance: float  # s^2 / sigma^2: the data rows' residual variance over their degrees of freedom
    threshold: float  # its chi-square bound, 1 + 3 sqrt(2 / dof): above it the fit warns
    search_threshold: float  # 1 + _SEARCH_AGAIN_SIGMAS sqrt(2 / dof): above it the rounds go on
    inverse_normal: np.ndarray  # (J^T J)^+ over the free parameters


def _misfit(residual, jacobian, samples, curve_count):
    """The residual variance of a fit in units of sigma^2 (rows already over sigma) and (J^T J)^+.

    The variance is over the data rows' degrees of freedom: N less the light curves' scales and the
    parameters' effective number, the data rows' part of the trace of the hat matrix
    J (J^T J)^+ J^T = U U^T (Hastie, Tibshirani & Friedman 2009, sec. 3.4.1): a regularised convex
    shape's hundreds of areas count for what the data determine of them, not one each.  Where sigma is
    the noise and the model holds, the sum of squares is chi-square with dof degrees of freedom, so the
    variance exceeds 1 + 3 sqrt(2 / dof) (three standard deviations) by chance in a few fits in a
    thousand (the chi-square's tail: 0.33% at 110 degrees of freedom, 0.2% at the family's 850):
    above it, the fit has missed the data's basin (or sigma understates the noise).
    (J^T J)^+ comes from the singular values of J itself: forming J^T J first squares its condition
    number, and the pseudo-inverse's cutoff then depends on rounding (as scipy's curve_fit)."""
    left, singular, right = np.linalg.svd(jacobian, full_matrices=False)
    kept = singular > np.finfo(float).eps * max(jacobian.shape) * singular[0]
    dof = max(samples - curve_count - float(np.sum(left[:samples, kept] ** 2)), 1.0)
    variance = float(np.sum(residual[:samples] ** 2) / dof)
    inverse_normal = (right[kept].T / singular[kept] ** 2) @ right[kept]
    deviation = math.sqrt(2.0 / dof)
    return _Misfit(variance, 1.0 + 3.0 * deviation, 1.0 + _SEARCH_AGAIN_SIGMAS * deviation, inverse_normal)


def _cluster_robust_covariance(residual, jacobian, curves, inverse_normal):
    """The cluster-robust (sandwich) covariance (J^T J)^+ M (J^T J)^+ of the free parameters, the
    light curves the clusters (CR3, the cluster jackknife's), or None with fewer than
    ``_MIN_CLUSTERS`` of them.

    M = (G - 1) / G sum_c (u_c - u_mean)(u_c - u_mean)^T over the light curves' scores
    u_c = J_c^T (I - H_cc)^-1 r_c, H_cc = J_c (J^T J)^+ J_c^T the hat matrix's block of light curve c's
    data rows (the rows after the data, the shape's regularisation, are a prior: in the bread, not the
    meat; centring removes their share of the score).  (J^T J)^+ u_c is, to first order, how far the
    fit moves when light curve c is left out, so this is the jackknife's variance over the light
    curves (Bell & McCaffrey 2002; MacKinnon, Nielsen & Webb 2023, J. Econometrics 232, 272): it holds
    whatever the residuals' correlation within a light curve.  The residuals themselves would not
    do (CR1, u_c = J_c^T r_c): a fit with hundreds of shape parameters pulls each night's residuals
    towards its model (H_cc's eigenvalues reach 0.99 on the tumbler family), and CR1's sigmas came
    out 0.5 to 0.9 times the model's.  Leverages are capped at ``_MAX_LEVERAGE``."""
    samples, clusters = curves.shape
    if clusters < _MIN_CLUSTERS:
        return None
    data_jacobian, data_residual = jacobian[:samples], residual[:samples]
    label = np.argmax(curves, 1)
    scores = np.zeros((clusters, jacobian.shape[1]))
    for curve in range(clusters):
        rows = label == curve
        block = data_jacobian[rows]
        leverage, vectors = np.linalg.eigh(block @ inverse_normal @ block.T)
        lifted = vectors @ ((vectors.T @ data_residual[rows]) / np.maximum(1.0 - leverage, 1.0 - _MAX_LEVERAGE))
        scores[curve] = block.T @ lifted
    scores = scores - scores.mean(0)
    meat = (clusters - 1) / clusters * scores.T @ scores
    return inverse_normal @ meat @ inverse_normal


def _covariances(residual, jacobian, free, curves, misfit):
    """(model covariance, cluster-robust covariance) (P, P) of a solution's parameters from its
    residual and Jacobian rows and its ``misfit`` (:func:`_misfit` over the ``free`` parameters' columns);
    zero rows and columns for the fixed parameters, and a zero robust covariance with too few light
    curves."""
    covariance = np.zeros((free.size, free.size))
    covariance[np.ix_(free > 0, free > 0)] = misfit.inverse_normal * misfit.variance
    robust = _cluster_robust_covariance(residual, jacobian[:, free > 0], curves, misfit.inverse_normal)
    robust_covariance = np.zeros_like(covariance)
    if robust is not None:
        robust_covariance[np.ix_(free > 0, free > 0)] = robust
    return covariance, robust_covariance


def _basins(costs, periods, winner_periods, sigma, samples, cost, within):
    """(indices into ``costs``, cost excess, distance) of the competing basins, best first: the
    starts within ``within`` noise units of the winner's cost at periods more than 3 ``sigma`` away
    (:meth:`LightcurveFit.competing_basins`)."""
    unit = math.sqrt(samples / 2) * max(2 * float(cost) / max(samples, 1), np.finfo(float).tiny)
    excess = (costs - float(cost)) / unit
    # Distance from the winner in its sigmas; a principal-axis rotator's second period is infinite.
    finite = np.isfinite(winner_periods) & np.isfinite(periods)
    difference = np.abs(np.where(finite, periods, 0.0) - np.where(finite, winner_periods, 0.0))
    distance = (difference / np.maximum(sigma, np.finfo(float).tiny)).max(-1)
    competing = np.isfinite(excess) & (excess >= 0) & (excess <= within) & (distance > 3)
    order = np.flatnonzero(competing)[np.argsort(excess[competing], kind="stable")]
    return order, excess[order], distance[order]


def _scaled_moments(parameters):
    """The moments (exp theta_0, exp theta_1, 1) of ``parameters`` scaled to a largest of 1."""
    moments = np.exp(np.concatenate([np.asarray(parameters[:2], float), [0.0]]))
    return moments / moments.max()


def _standard_errors(period_jacobian, parameters, covariances):
    """(periods' (2,), scaled moments' (3,)) standard errors, first order in each of ``covariances``
    (of ``parameters``), the largest over them; ``period_jacobian`` (2, 8) the periods' in theta."""
    moments = _scaled_moments(parameters)
    largest = np.argmax(moments)
    # d log(I_i / I_largest) / d theta: the moments are (exp theta_0, exp theta_1, 1).
    d_log = np.zeros((3, 8))
    for j in range(2):
        d_log[:, j] = (np.arange(3) == j).astype(float) - float(largest == j)

    def sigma(derivative):
        variances = [np.diag(derivative @ np.asarray(cov, float)[:8, :8] @ derivative.T) for cov in covariances]
        return np.sqrt(np.maximum(np.max(variances, 0), 0))

    return sigma(period_jacobian), moments * sigma(d_log)


def _mixture_sigma(sigma, values):
    """Root-mean-square distance from the winner, ``values[0]``, of the equal-weight mixture of
    Gaussians centred at ``values`` (K, D), each of standard deviation ``sigma`` (D,):
    sqrt(sigma^2 + mean_k (values_k - values_0)^2), the error of the reported value if the truth is
    in any of the basins alike (about the winner, not the mixture's mean: the winner is what is
    reported, and an alias at the edge of the basins is as likely to win as one at their centre);
    infinite or non-finite centres (a rotator's second period) leave ``sigma`` as it is."""
    finite = np.all(np.isfinite(values), 0)
    centres = np.where(finite, values, 0.0)
    offsets = centres - centres[:1]
    return np.sqrt(sigma**2 + np.mean(offsets**2, 0))


def _subdivided_log_areas(log_areas, solid_angles, finer_solid_angles):
    """A convex shape's log-areas carried to the icosphere subdivided once more (:func:`icosphere`
    orders the four children of facet f as 4 f .. 4 f + 3): each child keeps its parent's area per
    solid angle (the Gaussian image's density, 1 / K), the mean log-area set to 0 as the
    regularisation's mean row holds it."""
    parents = np.arange(len(finer_solid_angles)) // 4
    finer = np.asarray(log_areas, float)[parents] + np.log(finer_solid_angles / np.asarray(solid_angles)[parents])
    return finer - finer.mean()


def _with_resolution_error(sigma, finer_sigma, values, finer_values):
    """The standard errors of ``values`` (their ``sigma``) with the shape's resolution error: the larger
    of ``sigma`` and the finer shape's ``finer_sigma`` (the finer shape's freedom, which the coarser one
    holds fixed), and the change of the values on the finer shape (``finer_values``: an embedded
    pair's estimate of the coarser one's error), in quadrature; ``sigma`` as it is where the finer
    solution is not finite (an unconverged solve, a rotator's second period)."""
    with np.errstate(invalid="ignore"):  # inf - inf: a rotator's second period
        change = np.asarray(finer_values, float) - np.asarray(values, float)
    finite = np.isfinite(change) & np.isfinite(finer_sigma)
    widened = np.sqrt(np.maximum(sigma, np.where(finite, finer_sigma, 0.0)) ** 2 + np.where(finite, change, 0.0) ** 2)
    return np.where(finite, widened, sigma)


def _round_plan(round_index, n_refine):
    """The search's rounds, four to each two draws of the random states (draws 2c and 2c + 1 of cycle
    c, from ``seed + draw``): the first draw on the period grid, its best ``n_refine`` refined; the same
    draw on the middles of the grid's cells; the second draw on the grid; then the first search
    again, its next ``3 n_refine`` best starts refined (the starts a fourfold ``n_refine`` would have
    refined besides).  Measured on the tumbler family (docs/lightcurve-search.md): member 6 is found on the
    middles, member 13 by the second draw, members 11 and 12 among the first search's next best
    starts (with that round third, member 13 stopped there in a wrong basin whose residuals pass the
    misfit bound).  Returns (draw, middles, how many starts to refine)."""
    cycle, step = divmod(round_index, 4)
    draw = 2 * cycle + (step == 2)
    return draw, step == 1, 3 * n_refine if step == 3 else n_refine


def _focused_ranges(ranges, cell, period_psi):
    """The period ranges of a round that zooms on the winner's ``period_psi``: ``ranges`` (2, 2) with
    P_psi's narrowed to the window of log-width 2 cell / _FOCUS_NARROWING (``cell``: the log-width of
    the given grid's P_psi cell) centred on ``period_psi``, moved inside its range where it would leave
    it (a refined start may end outside the searched ranges), P_phi's unchanged."""
    focused = np.array(ranges, float)
    log_low, log_high = np.log(focused[0])
    half_width = min(cell / _FOCUS_NARROWING, 0.5 * (log_high - log_low))
    # A winner without a finite P_psi (no start converged) leaves the window at the range's middle.
    centre = np.log(period_psi) if np.isfinite(period_psi) else 0.5 * (log_low + log_high)
    centre = np.clip(centre, log_low + half_width, log_high - half_width)
    focused[0] = np.exp([centre - half_width, centre + half_width])
    return focused


def _continuation_windows(distance):
    """Masks (W, N) of the continuation windows: the samples within a radius of the epoch, the first
    radius holding a tenth of them (at least ``_MIN_WINDOW``), each next ``_WINDOW_GROWTH`` times the
    last, the last window all of them."""
    count = distance.size
    ranked = np.sort(distance)
    radii = [ranked[min(count, max(math.ceil(0.1 * count), _MIN_WINDOW)) - 1]]
    while radii[-1] * _WINDOW_GROWTH < ranked[-1]:
        radii.append(radii[-1] * _WINDOW_GROWTH)
    return np.stack([distance <= radius for radius in radii] + [np.ones(count, bool)]).astype(float)


def _validate(times, flux, sun, observer, lightcurve, magnitudes, nan_policy):
    """(times, flux, sun, observer, lightcurve, omitted rows) of the samples to fit, numpy; ValueError
    for data the fit cannot use, naming the argument and the first offending entry."""
    checks.choice("nan_policy", nan_policy, ("raise", "omit"))
    times = checks.real_array("times", times)
    if times.ndim != 1:
        raise ValueError(f"times must be one-dimensional (N,), got shape {times.shape}")
    n = len(times)
    flux = checks.real_array("brightness", flux)
    if flux.shape != (n,):
        raise ValueError(f"brightness must have shape (N,) = ({n},) like times, got {flux.shape}")
    directions = {}
    for name, value in (("sun", sun), ("observer", observer)):
        value = checks.real_array(name, value)
        if value.shape not in ((3,), (n, 3)):
            raise ValueError(f"{name} must have shape (N, 3) = ({n}, 3) like times, or (3,), got {value.shape}")
        directions[name] = np.broadcast_to(value, (n, 3))
    if lightcurve is None:
        lightcurve = np.zeros(n, int)
    lightcurve = np.asarray(lightcurve)
    if lightcurve.shape != (n,):
        raise ValueError(f"lightcurve must have shape (N,) = ({n},) like times, got {lightcurve.shape}")
    omitted = checks.nonfinite_rows(times, flux, directions["sun"], directions["observer"])
    if np.any(omitted) and nan_policy == "raise":
        raise ValueError(
            f"samples {checks.describe_rows(omitted)} have non-finite times, brightness, sun or "
            "observer; pass nan_policy='omit' to leave them out"
        )
    kept = np.flatnonzero(~omitted)
    if len(kept) == 0:
        raise ValueError("times: no sample to fit" + (f" after leaving out {n}" if n else ""))
    for name, value in directions.items():
        # The kept rows under their input indices (rows left out read as valid).
        checks.check_unit_rows(
            name, np.where(omitted[:, None], np.array([1.0, 0.0, 0.0]), value).astype(value.dtype), what="unit vectors"
        )
    if not magnitudes:
        checks.check_positive("brightness", np.where(omitted, 1.0, flux))
    sun, observer = (directions[name][kept].astype(float) for name in ("sun", "observer"))
    opposite = np.sum(sun * observer, -1) <= -1 + 1e-9
    if np.any(opposite):
        raise ValueError(
            f"sun and observer are opposite at sample {kept[np.argmax(opposite)]} (phase angle "
            "180 degrees): no facet is both lit and seen"
        )
    return times[kept].astype(float), flux[kept].astype(float), sun, observer, lightcurve[kept], omitted


def _check_options(
    *,
    periods,
    principal_axis,
    period_grid,
    inertia_range,
    shape,
    convex_subdivisions,
    law,
    c,
    sigma,
    regularisation,
    epoch,
    starts_per_period,
    n_refine,
    search_rounds,
    max_search_rounds,
    stop_at_noise,
    mirror_pole,
    resolution_error,
    seed,
    rtol,
    atol,
    max_steps,
    x_scale,
    search_chunk,
    mode,
    initial,
):
    """The search's options, as (periods, period_grid) arrays; ValueError naming a bad option."""
    if x_scale != "jac" and (isinstance(x_scale, (str, bool)) or x_scale != 1):
        raise ValueError(f"x_scale must be 1.0 (the parameters as they are) or 'jac' (Marquardt's), got {x_scale!r}")
    checks.choice("shape", shape, ("convex", "ellipsoid"))
    checks.choice("law", law, LAWS)
    checks.choice("mode", mode, ("SAM", "LAM", "both"))
    if periods is None:
        raise ValueError(
            "periods: give the search ranges ((P_psi_min, P_psi_max), (P_phi_min, P_phi_max)), "
            "or (P_min, P_max) with principal_axis=True"
        )
    period_array = checks.real_array("periods", periods)
    if principal_axis:
        ranges = [checks.interval("periods", period_array)]
    else:
        if period_array.shape != (2, 2):
            raise ValueError(
                "periods must be the ranges ((P_psi_min, P_psi_max), (P_phi_min, P_phi_max)) "
                f"(shape (2, 2); (P_min, P_max) with principal_axis=True), got shape {period_array.shape}"
            )
        ranges = [checks.interval(f"periods[{k}]", period_array[k]) for k in range(2)]
    grid = np.atleast_1d(np.asarray(period_grid, dtype=object))
    expected = 1 if principal_axis else 2
    if grid.shape not in ((expected,),) + (((2,),) if principal_axis else ()):
        raise ValueError(
            f"period_grid must be {expected} number{'s' if expected > 1 else ''} of grid points, got {period_grid!r}"
        )
    grid = [checks.integer(f"period_grid[{k}]", value, minimum=1) for k, value in enumerate(grid)]
    if not principal_axis:
        checks.interval("inertia_range", inertia_range, upper=1.0)
    checks.integer("convex_subdivisions", convex_subdivisions, minimum=0)
    checks.scalar("c", c, positive=True, allow_zero=True)
    checks.scalar("sigma", sigma, positive=True)
    weights = checks.real_array("regularisation", regularisation)
    if weights.shape != (2,):
        raise ValueError(f"regularisation must be (closure weight, smoothness weight), got shape {weights.shape}")
    checks.check_positive("regularisation", weights, allow_zero=True)
    if epoch is not None:
        checks.scalar("epoch", epoch)
    checks.integer("starts_per_period", starts_per_period, minimum=1)
    checks.integer("n_refine", n_refine, minimum=1)
    checks.integer("search_rounds", search_rounds, minimum=1)
    if max_search_rounds is not None and checks.integer("max_search_rounds", max_search_rounds) < search_rounds:
        raise ValueError(f"max_search_rounds must be >= search_rounds ({search_rounds}), got {max_search_rounds}")
    for name, flag in (
        ("stop_at_noise", stop_at_noise),
        ("mirror_pole", mirror_pole),
        ("resolution_error", resolution_error),
    ):
        if not isinstance(flag, (bool, np.bool_)):
            raise ValueError(f"{name} must be True or False, got {flag!r}")
    checks.integer("seed", seed, minimum=0)
    checks.scalar("rtol", rtol, positive=True)
    checks.scalar("atol", atol, positive=True)
    checks.integer("max_steps", max_steps, minimum=1)
    checks.integer("search_chunk", search_chunk, minimum=1)
    if initial is not None:
        if not isinstance(initial, FreeRigidBody):
            raise ValueError(
                f"initial must be a FreeRigidBody (e.g. an earlier fit's body), got {type(initial).__name__}"
            )
        if initial.inertia.shape != (3,):
            raise ValueError(f"initial must be one body, got a batch of shape {initial.inertia.shape[:-1]}")
    return ranges, grid


def fit_lightcurve(
    times,
    brightness,
    sun,
    observer,
    *,
    lightcurve=None,
    magnitudes: bool = False,
    periods=None,
    principal_axis: bool = False,
    mode: str = "both",
    inertia_range=(0.3, 0.98),
    shape: str = "convex",
    convex_subdivisions: int = 2,
    law: str = "lommel_seeliger_lambert",
    c: float = 0.1,
    sigma: float = 0.01,
    regularisation=(100.0, 4.0),
    epoch: float | None = None,
    period_grid=(16, 16),
    starts_per_period: int = 16,
    n_refine: int = 32,
    search_rounds: int = 4,
    max_search_rounds: int | None = None,
    stop_at_noise: bool = False,
    mirror_pole: bool = True,
    resolution_error: bool = True,
    seed: int = 0,
    rtol: float = 1e-8,
    atol: float = 1e-8,
    max_steps: int = 100,
    x_scale: float | str = 1.0,
    search_chunk: int = 256,
    initial: FreeRigidBody | None = None,
    nan_policy: str = "raise",
    throw: bool = True,
    progress: bool | None = None,
) -> LightcurveFit:
    """Fit a tumbling (or principal-axis) body and its convex shape to light curves.

    Arguments: ``times`` (N,); ``brightness`` (N,) fluxes (> 0), or magnitudes with ``magnitudes=True``
    (flux = 10^(-0.4 m)); ``sun``, ``observer`` (N, 3) unit vectors from the body to the Sun and to the
    observer (inertial frame; light-time corrected ``times`` are the caller's); ``lightcurve`` (N,)
    integer label of each sample's light curve (one unknown scale each; default: one curve).

    Search: ``periods``: ranges ((P_psi_min, P_psi_max), (P_phi_min, P_phi_max)) of the two periods
    (principal axis: (P_min, P_max)), searched on a log-uniform ``period_grid`` (two numbers; one for
    a principal axis) with ``starts_per_period`` random states each (inertia ratios in
    ``inertia_range``, ``mode`` "SAM", "LAM" or "both", polhode phase, attitude); ``n_refine`` of the
    best are refined by Levenberg-Marquardt on growing windows around ``epoch`` (default: the median
    time), each start held to its cell of the period grid by a prior until the last window, the better
    half going on to each next window with its periods moved to their best cycle count there (module
    docstring): choose the grid fine enough that a cell's phase drift over the first nights is well
    under a cycle.  Without prior periods, :func:`tumbler_periodogram` proposes ranked ranges from the
    light curves themselves (``periods=result.proposals[i]``, or ``**result.fit_options(i)``).
    ``search_rounds``: the search's rounds: the first, the same random states on the middles of the
    grid's cells, new random states on the grid, the first search's next ``3 n_refine`` starts
    refined (and so on: four rounds to two draws); the lowest cost over all rounds wins, and a fit
    whose residuals exceed the stated noise (s^2 / sigma^2 above 1 + 3 sqrt(2 / dof), three standard
    deviations of a chi-square: :attr:`LightcurveFit.noise_ratio`) warns (:class:`MisfitWarning`).
    All rounds run by default, so that a wrong basin whose residuals pass the bound (an alias the
    data nearly allow) has the truth's basin among the refined starts, as a competing basin that the
    warning names and the sigmas span; while the winner is above 1 + 4 sqrt(2 / dof) (more than the
    residuals of a body outside the model's family, module docstring), further rounds run, up to
    ``max_search_rounds`` (default ``2 * search_rounds``; the misfit then warns), so that a search
    that missed the data's basin takes longer rather than answering wrong: every other one a new draw
    on a grid over the winner's P_psi +-cell / 8 (the given P_phi range), the others the plan's.
    ``stop_at_noise=True`` stops at the first round whose winner is within the bound, about
    ``search_rounds`` times faster where that is the first, at the risk of a confident answer in such
    an alias (measured on the tumbler family: docs/lightcurve-search.md).
    ``mirror_pole``: the winner's mirror image through the plane of the observations, which fits
    light curves taken near one plane nearly as well (module docstring), is solved too, and the
    lower cost wins; the other pole is reported (:attr:`LightcurveFit.mirror_momentum_direction`)
    and a warning names it where the data do not tell the two apart.  One more Levenberg-Marquardt
    solve on all the data.  ``resolution_error`` (convex shape): the winner solved once more with each
    facet split in four, and the sigmas widened to the larger of the two shapes' with the change of
    the periods and moments between them in quadrature, the bias of a shape the facets cannot follow
    (module docstring, "The shape's resolution"; :attr:`LightcurveFit.resolution_periods`); one more
    solve with four times the shape's parameters (about 50 s on one core on the tumbler family).
    ``shape``: "convex" (log-areas on the facet normals of an icosphere of
    ``convex_subdivisions``, with ``regularisation`` = (closure weight, smoothness weight)) or
    "ellipsoid".  The default weights (100, 4) hold the fitted Gaussian image close to a closed,
    smooth body, which predicts new geometry better at residuals a little higher on the fitted data:
    on the tumbler family the later nights within 1.5% of the truth where the former (10, 1) missed
    them (docs/lightcurve-search.md, "The later nights and the shape's weights").  The defaults
    (``n_refine=32``, 320 normals) are the settings measured on the
    tumbler family of benchmarks/lightcurve_family.py (docs/lightcurve-search.md): fewer normals bias
    the periods where the body is not smooth (3 to 8 sigmas with 80), fewer refined starts find
    the truth's basin less often.  ``initial``: a :class:`frbjax.FreeRigidBody` (time from the epoch), e.g. an earlier
    fit, refined beside the search's best on all the data from the first window (its shape starts as
    the ellipsoid of its inertia).
    ``law``, ``c``: the scattering law (:func:`brightness`); ``sigma``: the relative
    noise (weights the data against the regularisation).

    ``nan_policy``: samples with a non-finite time, brightness, sun or observer direction are
    refused, naming their indices (``"raise"``, default), or left out (``"omit"``: their
    ``residuals`` are NaN).  ``throw``: a fit whose winner did not converge (after up to 3 more
    solves of ``max_steps`` from where it stopped, on all the data) raises
    :class:`frbjax.FitError` (default), whose ``result`` is the unconverged fit; ``throw=False``
    returns it (``success`` False).

    ``x_scale``: ``"jac"`` continues each of the convex shape's Levenberg-Marquardt solves (the last
    stage, the leader's continued solves, the mirror image's and the finer shape's) from where it
    stops, for the parameters times the Jacobian's column norms there (Marquardt 1963; Moré 1978;
    scipy's ``least_squares(x_scale="jac")``); 1.0 (default): the parameters as they are, with which
    those solves can stop well above their minimum, reporting convergence.  Continued, a solve ends
    lower or where it was (the steps are only taken where they lower the cost), at twice the solve's
    time at most; on thirteen measured solves 0.02% to 78% lower.  A fit takes 1.3 to 2.1 times as
    long, and the finer shape's solve (1288 parameters) often ends unconverged, which leaves the
    shape's resolution error out of the sigmas (``resolution_periods`` NaN): six of eight of a tumbler
    family's members.  Hence not the default: docs/lightcurve-search.md, "Levenberg-Marquardt's
    scaling" and "``x_scale="jac"`` on seed 1".

    ``progress``: progress bars (tqdm) for the search (starts costed, a chunk of ``search_chunk`` at a
    time) and the refinement (windows solved); by default shown in a terminal or an IPython/Jupyter
    session and not elsewhere.

    Refused with a ValueError naming the argument and the first offending entry: brightness <= 0
    (without ``magnitudes``), directions that are not unit vectors or are opposite (phase angle 180
    degrees), period ranges that are not finite, positive and increasing (a range given upside down),
    an ``inertia_range`` outside (0, 1], counts below 1, negative weights, non-finite scalars,
    unknown option names, an ``initial`` that is not one body.

    Runs in float64 when JAX has it enabled (recommended).  Module docstring: the parameters, the
    residuals and the search.
    """
    progress = _progress.check_option(progress)
    _check_options(
        periods=periods,
        principal_axis=principal_axis,
        period_grid=period_grid,
        inertia_range=inertia_range,
        shape=shape,
        convex_subdivisions=convex_subdivisions,
        law=law,
        c=c,
        sigma=sigma,
        regularisation=regularisation,
        epoch=epoch,
        starts_per_period=starts_per_period,
        n_refine=n_refine,
        search_rounds=search_rounds,
        max_search_rounds=max_search_rounds,
        stop_at_noise=stop_at_noise,
        mirror_pole=mirror_pole,
        resolution_error=resolution_error,
        seed=seed,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        x_scale=x_scale,
        search_chunk=search_chunk,
        mode=mode,
        initial=initial,
    )
    times, flux, sun, observer, lightcurve, omitted = _validate(
        times, brightness, sun, observer, lightcurve, magnitudes, nan_policy
    )
    log_brightness = -0.4 * np.log(10.0) * flux if magnitudes else np.log(flux)
    n = len(times)
    dtype = jnp.result_type(float)
    epoch = float(np.median(times)) if epoch is None else float(epoch)
    labels, curve_index = np.unique(lightcurve, return_inverse=True)
    curves = np.eye(len(labels))[curve_index]

    masks = _continuation_windows(np.abs(times - epoch))

    # ---- shapes, data and settings (the same for every round of the search)
    search_normals, search_solid, _ = _unit_normals(_SEARCH_SUBDIVISIONS)
    if shape == "convex":
        normals, solid_angles, faces = _unit_normals(convex_subdivisions)
        laplacian = _laplacian(faces)
    else:
        normals = search_normals
        laplacian = np.zeros((1, 1))
    free = np.ones(8 + (len(normals) if shape == "convex" else 2))
    ellipsoid_free = np.ones(10)
    if principal_axis:
        free[[0, 1, 6, 7]] = 0.0
        ellipsoid_free[[0, 1, 6, 7]] = 0.0
    data = dict(
        times=times - epoch,
        sun=sun,
        observer=observer,
        log_brightness=log_brightness,
        curves=curves,
        sigma=np.asarray(sigma),
        normals=normals,
        search_normals=search_normals,
        laplacian=laplacian,
        regularisation=np.asarray(regularisation, float),
        free=free,
    )
    data = {key: jnp.asarray(value, dtype) for key, value in data.items()}
    config = (shape, law, float(c), _SEARCH_SUBDIVISIONS, bool(principal_axis))
    # The continuation windows are solved with the ellipsoid (2 shape parameters): the first windows
    # hold fewer samples than a convex shape has areas.  A convex shape is then fitted on all the data
    # from the Gaussian image of the fitted ellipsoid, on its fixed normals.
    ellipsoid_data = dict(data, free=jnp.asarray(ellipsoid_free, dtype))
    ellipsoid_config = ("ellipsoid",) + config[1:]
    solver_settings = dict(rtol=float(rtol), atol=float(atol), max_steps=int(max_steps))

    def settings(solve_config):
        """The solver's settings for a solve with ``solve_config``: ``x_scale`` for the convex shape's."""
        return dict(solver_settings, x_scale="jac" if x_scale == "jac" and solve_config[0] == "convex" else 1.0)

    radii = [float(np.max(np.abs(times - epoch)[mask > 0])) for mask in masks]
    period_ranges = np.atleast_2d(np.asarray(periods, float))
    grid_sizes = np.atleast_1d(period_grid).astype(int)[: len(period_ranges)]

    def grid_cells(ranges):
        """The log-width of a cell of the period grid over ``ranges`` (one per period)."""
        return np.log(ranges[:, 1] / ranges[:, 0]) / np.maximum(grid_sizes - 1, 1)

    def round_limits(ranges):
        """A round's log-ranges (where its period shifts may go) and its period prior's inverse width:
        each start keeps its grid cell, log P ~ N(log P_start, (cell / 2)^2)."""
        log_ranges = np.array([[-np.inf, np.inf]] * 2)
        log_ranges[: len(ranges)] = np.log(ranges)
        prior_inverse_width = np.zeros(2)
        prior_inverse_width[: len(ranges)] = 2 / np.maximum(grid_cells(ranges), 1e-6)
        return log_ranges, prior_inverse_width

    prior_weights = np.concatenate([np.ones(len(masks) - 1), [0.0]])
    as_jax = lambda tree: jax.tree.map(lambda x: jnp.asarray(x, dtype), tree)  # noqa: E731
    # The search's chunks are taken in numpy (eagerly, JAX would compile each gather).
    as_numpy = lambda tree: jax.tree.map(lambda x: np.asarray(x, dtype), tree)  # noqa: E731
    chunk = None  # the first round's: one chunk size for every search and period shift, one program

    def period_axis(low, high, size, middles):
        """A log-uniform grid of ``size`` points over [low, high], or the middles of its cells, so that
        a round's starts lie between the first's."""
        points = np.linspace(np.log(low), np.log(high), size)
        if middles and size > 1:
            points = 0.5 * (points[1:] + points[:-1])
        return np.exp(points)

    def starts(draw, middles, ranges, on_user_grid):
        """A draw's starts: a grid of the periods over ``ranges`` (or its cells' middles) times random
        states drawn from ``seed + draw``, and the given motion first in the first draw on the user's
        grid (``on_user_grid``; a focused round's grid never holds it).  Returns (theta (S, 8),
        references, the periods (S, 2) of each, valid (S,), the ellipsoid's axes of each start's
        inertia (S, 3), whether it is the given motion (S,))."""
        rng = np.random.default_rng(seed + draw)
        if principal_axis:
            grid = period_axis(*(float(p) for p in ranges[0]), int(grid_sizes[0]), middles)
            period_psi = np.repeat(grid, starts_per_period)
            count = len(period_psi)
            period_phi = np.full(count, np.inf)
            inertia = np.broadcast_to(np.asarray(_PRINCIPAL_INERTIA), (count, 3))
            momentum = np.zeros((count, 3))
            momentum[:, 2] = 2 * np.pi * inertia[:, 2] / period_psi
            valid = np.ones(count, bool)
        else:
            (psi_low, psi_high), (phi_low, phi_high) = ranges
            n_psi, n_phi = grid_sizes
            psi_grid = period_axis(psi_low, psi_high, n_psi, middles)
            phi_grid = period_axis(phi_low, phi_high, n_phi, middles)
            period_psi, period_phi = (
                np.repeat(g.reshape(-1), starts_per_period) for g in np.meshgrid(psi_grid, phi_grid, indexing="ij")
            )
            count = len(period_psi)
            ratios = np.sort(rng.uniform(*inertia_range, size=(count, 2)), -1)
            inertia = np.concatenate([ratios, np.ones((count, 1))], -1)
            if mode == "both":
                long_axis = rng.random(count) < 0.5
            else:
                long_axis = np.full(count, mode == "LAM")
            phase = rng.uniform(0, 2 * np.pi, count)
            momentum, valid = (
                np.array(x)
                for x in _momenta_from_periods(
                    jnp.asarray(inertia, dtype),
                    jnp.asarray(period_psi, dtype),
                    jnp.asarray(period_phi, dtype),
                    jnp.asarray(long_axis),
                    jnp.asarray(phase, dtype),
                )
            )
            valid &= np.all(np.isfinite(momentum), -1)
            momentum = np.where(valid[:, None], momentum, np.array([0.0, 0.0, 1.0]))
        attitudes = _random_rotations(rng, count)
        given = np.zeros(count, bool)
        if initial is not None and draw == 0 and not middles and on_user_grid:
            # The given motion as one more start, placed first; its cost is not searched but refined.
            scale = float(np.max(np.asarray(initial.inertia)))
            inertia = np.concatenate([np.asarray(initial.inertia)[None] / scale, inertia])
            given_momentum = np.asarray(initial.initial_angular_momentum)[None] / scale
            momentum = np.concatenate([given_momentum, momentum])
            attitudes = np.concatenate([np.asarray(initial.initial_attitude)[None], attitudes])
            if principal_axis:
                initial_periods = np.array([2 * np.pi / np.linalg.norm(given_momentum), np.inf])
            else:
                initial_periods = np.asarray(
                    tumbler_periods(initial.inertia, initial.initial_angular_momentum)[:2], float
                )
            period_psi = np.concatenate([initial_periods[:1], period_psi])
            period_phi = np.concatenate([initial_periods[1:], period_phi])
            valid = np.concatenate([[True], valid])
            given = np.concatenate([[True], given])
            count += 1
        momentum_norm = np.linalg.norm(momentum, axis=-1)
        direction = momentum / momentum_norm[:, None]
        if principal_axis:
            direction = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (count, 3)).copy()
            direction[given] = momentum[given] / momentum_norm[given, None]
        theta = np.zeros((count, 8))
        theta[:, 0] = np.log(inertia[:, 0])
        theta[:, 1] = np.log(inertia[:, 1])
        theta[:, 2] = np.log(momentum_norm)
        references = (attitudes, direction, _tangent_basis(direction))
        return theta, references, np.stack([period_psi, period_phi], -1), valid, _ellipsoid_axes(inertia), given

    # (draw, middles, period ranges) -> the starts, their search costs and which have been refined (mask)
    searched = {}

    def search_round(draw, middles, count, focus=None):
        """One round: the random states of ``draw`` on the period grid over the user's ranges (or its
        cells' middles; :func:`_round_plan`), or over ``focus`` (a round on :func:`_focused_ranges`),
        costed on the first window (once a draw), the best ``count`` not yet refined then refined
        through the windows as a population (module docstring).  Returns the last stage's starts (the
        refinement's (parameters, costs, converged, residuals, Jacobians) and their references) and
        the search's periods and costs (empty where the round reuses an earlier round's search)."""
        nonlocal chunk
        ranges = period_ranges if focus is None else focus
        log_ranges, prior_inverse_width = round_limits(ranges)
        key = (draw, middles, tuple(map(tuple, ranges)))
        new_search = key not in searched
        if new_search:
            theta, references, start_periods, valid, axes, given_start = starts(draw, middles, ranges, focus is None)
            if chunk is None:
                chunk = min(int(search_chunk), len(theta))
            costs = _search(
                as_numpy(theta),
                as_numpy(references),
                as_numpy(_gaussian_image_areas(axes, search_normals, search_solid)),
                data,
                jnp.asarray(masks[0], dtype),
                config,
                chunk,
                progress,
            )
            costs = np.where(valid, costs, np.inf)
            refined = np.zeros(len(costs), bool)
            searched[key] = (theta, references, start_periods, axes, given_start, costs, refined)
        theta, references, start_periods, axes, given_start, costs, refined = searched[key]
        ranking = np.argsort(costs, kind="stable")
        best = ranking[~refined[ranking]][:count]
        if new_search and given_start.any() and not given_start[best].any():
            best = np.concatenate([np.flatnonzero(given_start), best[:-1]])
        refined[best] = True

        refs = tuple(r[best] for r in references)
        centres = np.log(start_periods[best])
        centres = np.where(np.isfinite(centres), centres, 0.0)
        priors = (centres, np.broadcast_to(prior_inverse_width, centres.shape))
        # The windows carry a random start's phase outwards from the epoch; a given motion (an earlier
        # fit) has it already and is fitted to all the data from the first window.
        given = given_start[best]
        start_masks = np.where(given[:, None, None], 1.0, masks[None])
        survivors = _survivor_counts(len(best), len(masks))
        convex_starts = min(_CONVEX_STARTS, survivors[-1]) if shape == "convex" else 0

        def refine(rows, parameters, priors, data, masks, prior_weights, config):
            """The starts ``rows`` (of ``best``) solved on ``masks`` (len(rows), W, N).  Where the starts
            are solved one after another anyway (the CPU, ``solve_each``), each is its own call of a
            one-start program, which the leader's continued solves below then reuse: a program over all
            the starts compiled the loop over them too (the LAM benchmark: about 2.5 s of its 12 s of
            compilation when the convex stage had its own)."""
            batches = [slice(k, k + 1) for k in range(len(rows))] if starts_in_sequence() else [slice(None)]
            parts = [
                _refine(
                    as_jax(parameters[part]),
                    as_jax(tuple(r[rows[part]] for r in refs)),
                    None if priors is None else as_jax(tuple(p[rows[part]] for p in priors)),
                    data,
                    jnp.asarray(masks[part], dtype),
                    None if prior_weights is None else jnp.asarray(prior_weights, dtype),
                    config,
                    **settings(config),
                )
                for part in batches
            ]
            return [np.concatenate([np.asarray(piece) for piece in pieces]) for pieces in zip(*parts)]

        def shifted(rows, parameters, window):
            """Each start moved to the best of its period shifts on the window (a costing, as the search's)."""
            trials, owners = [], []
            for row, p in zip(rows, parameters):
                reference = as_jax(tuple(r[row] for r in refs))
                trial = _period_shifts(p, reference, radii[window], log_ranges, principal_axis)
                trials.append(trial)
                owners.append(np.full(len(trial), row))
            trials, owners = np.concatenate(trials), np.concatenate(owners)
            trial_axes = np.concatenate([np.ones((len(trials), 1)), np.exp(trials[:, 8:])], 1)
            trial_costs = _search(
                trials[:, :8],
                tuple(r[owners] for r in refs),
                _gaussian_image_areas(trial_axes, search_normals, search_solid),
                data,
                jnp.asarray(masks[window], dtype),
                config,
                chunk,
                False,
            )
            moved = parameters.copy()
            for k, row in enumerate(rows):
                own = np.flatnonzero(owners == row)
                moved[k] = trials[own[np.argmin(np.where(np.isfinite(trial_costs[own]), trial_costs[own], np.inf))]]
            return moved

        def best_of(rows, row_costs, count):
            """The ``count`` of ``rows`` with the lowest costs (a given motion first, always kept)."""
            ranked = np.argsort(np.where(given[rows], -np.inf, np.nan_to_num(row_costs, nan=np.inf)), kind="stable")
            return rows[ranked[:count]]

        # The refinement's progress bar counts the windows solved (each surviving start's continuation
        # windows, the convex stage, the leader's continued solves).
        windows = sum(survivors) + convex_starts
        ellipsoid_start = np.log(axes[best, 1:] / axes[best, :1])
        parameters = np.concatenate([theta[best], ellipsoid_start], 1)
        alive = np.arange(len(best))
        with _progress.bar("lightcurve refinement", windows, "light-curve refinement", "window", shown=progress) as bar:
            for window in range(len(masks)):
                searching = alive[~given[alive]]
                if window and len(searching):
                    # Before a wider window, each start's periods are moved to the best of their shifts by
                    # fractions of a cycle at the window's edge: Levenberg-Marquardt then starts in the
                    # cycle count that fits the new samples instead of the nearest basin of a wrong one.
                    parameters[searching] = shifted(searching, parameters[searching], window)
                out = refine(
                    alive,
                    parameters[alive],
                    priors,
                    ellipsoid_data,
                    start_masks[alive, window : window + 1],
                    prior_weights[window : window + 1],
                    ellipsoid_config,
                )
                parameters[alive] = out[0]
                if window + 1 < len(masks):
                    # The best half of the starts go on to the next window.
                    alive = best_of(alive, out[1], survivors[window + 1])
            if shape == "convex":
                alive = best_of(alive, out[1], convex_starts)
                fitted = parameters[alive]
                fitted_axes = np.concatenate([np.ones((len(alive), 1)), np.exp(fitted[:, 8:])], 1)
                log_areas = np.log(_gaussian_image_areas(fitted_axes, normals, solid_angles))
                log_areas -= log_areas.mean(-1, keepdims=True)
                # All the data, no prior.
                out = refine(
                    alive,
                    np.concatenate([fitted[:, :8], log_areas], 1),
                    None,
                    data,
                    start_masks[alive, -1:],
                    None,
                    config,
                )
            # A leader that stopped at max_steps still moving is solved on from where it stopped (all the
            # data, no prior), alone: Levenberg-Marquardt on a convex shape's hundreds of areas can take
            # more than max_steps to meet rtol (the LAM test's leader: three more solves).
            final_data, final_config = (data, config) if shape == "convex" else (ellipsoid_data, ellipsoid_config)
            for _ in range(_CONTINUATIONS):
                leader = int(np.argmin(np.where(np.isfinite(out[1]), out[1], np.inf)))
                if out[2][leader] or not np.isfinite(out[1][leader]):
                    break
                if bar is not None:
                    bar.total += 1
                continued = refine(
                    alive[leader : leader + 1],
                    out[0][leader : leader + 1],
                    None,
                    final_data,
                    start_masks[alive[leader : leader + 1], -1:],
                    None,
                    final_config,
                )
                for full, part in zip(out, continued):
                    # The ellipsoid's windows end with the period prior's rows at weight 0 (zeros); the
                    # continued solve has no prior, so its residual and Jacobian rows stop before them.
                    part = part[0]
                    if part.ndim:
                        full[leader] = 0.0
                        full[leader][: len(part)] = part
                    else:
                        full[leader] = part
        if not new_search:
            start_periods, costs = start_periods[:0], costs[:0]
        return out, tuple(r[alive] for r in refs), start_periods, costs

    def solve_on_all_data(start, references, solve_data, solve_config):
        """One start (with its ``references``, each with a leading axis of 1) solved on all the data as
        the last stage solves its starts: continued from where it stops, as the leader is."""
        out = None
        for _ in range(1 + _CONTINUATIONS):
            if out is not None and (out[2][0] or not np.isfinite(out[1][0])):
                break
            out = _refine(
                as_jax(start[None] if out is None else out[0]),
                as_jax(references),
                None,
                solve_data,
                jnp.asarray(masks[-1][None, None], dtype),
                None,
                solve_config,
                **settings(solve_config),
            )
            out = [np.asarray(x) for x in out]
        return out

    def mirror_round(parameters, reference):
        """The start ``parameters`` (with its ``reference``) mirrored through the plane of the
        observations (:func:`_mirror_image`) and solved on all the data: a round of one refined start."""
        final_data, final_config = (data, config) if shape == "convex" else (ellipsoid_data, ellipsoid_config)
        normal_index = _mirrored_normals(normals) if shape == "convex" else None
        mirrored, mirrored_reference = _mirror_image(parameters, reference, _plane_normal(sun, observer), normal_index)
        references = tuple(r[None] for r in mirrored_reference)
        out = solve_on_all_data(mirrored, references, final_data, final_config)
        return out, references, np.zeros((0, 2)), np.zeros(0)

    def finer_solution(parameters, reference):
        """The winner solved again on all the data with each facet of its convex shape split in four
        (module docstring, "The shape's resolution"): ((its periods, its moments), (their sigmas, as the
        winner's: the larger of the model's and the cluster-robust)), NaN where the solve does not
        converge."""
        finer_normals, finer_solid_angles, finer_faces = _unit_normals(convex_subdivisions + 1)
        finer_free = np.ones(8 + len(finer_normals))
        finer_free[:8] = free[:8]
        finer_data = dict(
            data,
            normals=jnp.asarray(finer_normals, dtype),
            laplacian=jnp.asarray(_laplacian(finer_faces), dtype),
            free=jnp.asarray(finer_free, dtype),
        )
        finer_areas = _subdivided_log_areas(parameters[8:], solid_angles, finer_solid_angles)
        start = np.concatenate([parameters[:8], finer_areas])
        out = solve_on_all_data(start, tuple(np.asarray(r)[None] for r in reference), finer_data, config)
        if not (out[2][0] and np.isfinite(out[1][0])):
            return (np.full(2, np.nan), np.full(3, np.nan)), (np.full(2, np.nan), np.full(3, np.nan))
        finer, residual, jacobian = out[0][0], out[3][0], out[4][0]
        _, finer_periods, _, period_derivatives = _fitted_motion(as_jax(finer[:8]), as_jax(reference), principal_axis)
        period_derivatives = np.nan_to_num(np.asarray(period_derivatives), posinf=0.0, neginf=0.0)
        misfit = _misfit(residual, jacobian[:, finer_free > 0], n, curves.shape[1])
        covariances = _covariances(residual, jacobian, finer_free, curves, misfit)
        sigmas = _standard_errors(period_derivatives, finer, covariances)
        return (np.asarray(finer_periods), _scaled_moments(finer)), sigmas

    # ---- the search's rounds: all of them, or (stop_at_noise) while the winner misses the noise
    def best(rounds):
        # The refined starts of all rounds so far, the lowest cost's index, and its misfit.  A round's
        # residuals and Jacobians solved without the period prior have no rows for it (zeros).
        rows = max(r[0][3].shape[1] for r in rounds)
        padded = [
            r[0][:3] + [np.pad(x, [(0, 0), (0, rows - x.shape[1])] + [(0, 0)] * (x.ndim - 2)) for x in r[0][3:]]
            for r in rounds
        ]
        outs = [np.concatenate(parts) for parts in zip(*padded)]
        winner = int(np.argmin(np.where(np.isfinite(outs[1]), outs[1], np.inf)))
        return outs, winner, _misfit(outs[3][winner], outs[4][winner][:, free > 0], n, curves.shape[1])

    # ---- past search_rounds, more rounds while the winner misses the noise by more than a model's
    # error does (_SEARCH_AGAIN_SIGMAS), up to max_search_rounds
    round_limit = 2 * search_rounds if max_search_rounds is None else max_search_rounds

    # The further rounds take turns: one zooms on the winner's P_psi (_FOCUS_NARROWING) with the next
    # draw, one goes on with the plan's rounds over the given ranges (a rotator's all go on with them).
    def winner_reference(rounds, winner):
        """The reference frame (attitude, direction, tangent basis) of the refined start ``winner``."""
        return tuple(np.concatenate(parts)[winner] for parts in zip(*(r[1] for r in rounds)))

    rounds, plan_rounds, focused_draws = [], 0, 0
    outs = winner = None  # best(rounds) after each round from search_rounds on
    for _ in range(round_limit):
        if len(rounds) >= search_rounds and (len(rounds) - search_rounds) % 2 == 0 and not principal_axis:
            reference = as_jax(winner_reference(rounds, winner))
            period_psi = float(_fitted_motion(as_jax(outs[0][winner][:8]), reference, principal_axis)[1][0])
            focus = _focused_ranges(period_ranges, grid_cells(period_ranges)[0], period_psi)
            rounds.append(search_round(focused_draws, False, n_refine, focus))
            focused_draws += 1
        else:
            rounds.append(search_round(*_round_plan(plan_rounds, n_refine)))
            plan_rounds += 1
        if stop_at_noise or len(rounds) >= search_rounds:
            outs, winner, misfit = best(rounds)
            bound = misfit.threshold if len(rounds) < search_rounds else misfit.search_threshold
            if len(rounds) == round_limit or misfit.variance <= bound:
                break
    mirror_row = None
    if mirror_pole:
        rounds.append(mirror_round(outs[0][winner], winner_reference(rounds, winner)))
        # The mirror image's row, and the winner's before it: whichever is not the winner is the other pole.
        mirror_row, searched_winner = len(outs[0]), winner
        outs, winner, misfit = best(rounds)
    fitted, refine_costs, oks, residual_rows, jacobians = outs
    candidate_references = tuple(np.concatenate(parts) for parts in zip(*(r[1] for r in rounds)))
    search_periods = np.concatenate([r[2] for r in rounds])
    search_costs = np.concatenate([r[3] for r in rounds])
    # The motion, periods, mode and periods' Jacobian of each start of the last stage: their periods
    # for the result's runner-ups, the winner's all four.
    motions = [
        _fitted_motion(as_jax(row[:8]), as_jax(tuple(r[k] for r in candidate_references)), principal_axis)
        for k, row in enumerate(fitted)
    ]
    refine_periods = np.stack([np.asarray(motion[1]) for motion in motions])
    p = fitted[winner].astype(float)
    reference = tuple(jnp.asarray(r[winner], dtype) for r in candidate_references)
    covariance, robust_covariance = _covariances(outs[3][winner], outs[4][winner], free, curves, misfit)

    body, period_values, lam, period_jacobian = motions[winner]
    if shape == "convex":
        fitted_shape = ConvexShape(jnp.asarray(normals, dtype), jnp.exp(jnp.asarray(p[8:], dtype)))
    else:
        fitted_shape = _ellipsoid_shape(jnp.asarray(p[8:], dtype), _SEARCH_SUBDIVISIONS)

    # Periods, energy and their uncertainties (first order in the covariance).
    period_values, lam, period_jacobian = (np.asarray(x) for x in (period_values, lam, period_jacobian))
    period_jacobian = np.nan_to_num(period_jacobian, posinf=0.0, neginf=0.0)
    # The larger of the model's and the cluster-robust variances (module docstring, "Uncertainty").
    basin_period_sigma, basin_inertia_sigma = _standard_errors(period_jacobian, p, (covariance, robust_covariance))
    moments = _scaled_moments(p)
    # Another solution's moments are matched to the winner's by rank (its axes may be labelled otherwise).
    rank = np.argsort(np.argsort(moments))
    # The shape's resolution error (module docstring, "The shape's resolution"): the larger of the two
    # shapes' sigmas, and the change of the periods and moments on the finer shape in quadrature.
    resolution_periods, resolution_inertia = np.full(2, np.nan), np.full(3, np.nan)
    resolution_period_sigma, resolution_inertia_sigma = np.full(2, np.nan), np.full(3, np.nan)
    if resolution_error and shape == "convex":
        (resolution_periods, finer_moments), (resolution_period_sigma, finer_inertia_sigma) = finer_solution(
            p, reference
        )
        finer_order = np.argsort(finer_moments)[rank]
        resolution_inertia, resolution_inertia_sigma = finer_moments[finer_order], finer_inertia_sigma[finer_order]
        basin_period_sigma = _with_resolution_error(
            basin_period_sigma, resolution_period_sigma, period_values, resolution_periods
        )
        basin_inertia_sigma = _with_resolution_error(
            basin_inertia_sigma, resolution_inertia_sigma, moments, resolution_inertia
        )
    # Competing basins widen the sigmas to their equal-weight mixture's spread about the winner.
    order, _, _ = _basins(
        refine_costs, refine_periods, period_values, basin_period_sigma, n, refine_costs[winner], within=1.0
    )
    basin_moments = np.stack([moments] + [np.sort(_scaled_moments(fitted[k]))[rank] for k in order])
    period_sigma = _mixture_sigma(basin_period_sigma, np.concatenate([period_values[None], refine_periods[order]]))
    inertia_sigma = _mixture_sigma(basin_inertia_sigma, basin_moments)
    l_body = np.asarray(body.initial_angular_momentum)
    momentum_direction = np.asarray(_rotate(body.initial_attitude, l_body / np.linalg.norm(l_body)))
    energy_ratio = float(np.sum(l_body**2 / moments) / np.sum(l_body**2))
    mirror_direction, mirror_excess = np.full(3, np.nan), math.inf
    if mirror_row is not None:
        other = searched_winner if winner == mirror_row else mirror_row
        other_body = motions[other][0]
        other_l = np.asarray(other_body.initial_angular_momentum)
        mirror_direction = np.asarray(_rotate(other_body.initial_attitude, other_l / np.linalg.norm(other_l)))
        unit = math.sqrt(n / 2) * max(2 * float(refine_costs[winner]) / n, np.finfo(float).tiny)
        excess = (float(refine_costs[other]) - float(refine_costs[winner])) / unit
        mirror_excess = excess if math.isfinite(excess) else math.inf

    # Scales and residuals of the fitted model, per curve.
    log_model = np.log(
        np.maximum(
            np.asarray(_forward(body, fitted_shape, data["times"], data["sun"], data["observer"], law, c)), 1e-300
        )
    )
    difference = log_brightness - log_model
    offsets = (curves.T @ difference) / curves.sum(0)
    residuals = difference - curves @ offsets

    result = LightcurveFit(
        body=body,
        shape=fitted_shape,
        epoch=epoch,
        law=law,
        c=float(c),
        periods=jnp.asarray(period_values),
        period_sigma=jnp.asarray(period_sigma),
        basin_period_sigma=jnp.asarray(basin_period_sigma),
        long_axis_mode=bool(lam) and not principal_axis,
        energy_ratio=energy_ratio,
        inertia=jnp.asarray(moments, dtype),
        inertia_sigma=jnp.asarray(inertia_sigma, dtype),
        momentum_direction=jnp.asarray(momentum_direction, dtype),
        mirror_momentum_direction=jnp.asarray(mirror_direction, dtype),
        mirror_cost_excess=mirror_excess,
        parameters=jnp.asarray(p, dtype),
        covariance=jnp.asarray(covariance, dtype),
        robust_covariance=jnp.asarray(robust_covariance, dtype),
        scales=jnp.asarray(np.exp(offsets), dtype),
        residuals=jnp.asarray(_with_omitted_rows(residuals, omitted), dtype),
        cost=float(refine_costs[winner]),
        success=bool(oks[winner]),
        search_periods=jnp.asarray(search_periods, dtype),
        search_costs=jnp.asarray(search_costs, dtype),
        refine_costs=jnp.asarray(refine_costs, dtype),
        refine_periods=jnp.asarray(refine_periods, dtype),
        noise_ratio=math.sqrt(misfit.variance),
        search_rounds=len(rounds) - (mirror_row is not None),
        resolution_periods=jnp.asarray(resolution_periods, dtype),
        resolution_period_sigma=jnp.asarray(resolution_period_sigma, dtype),
        resolution_inertia=jnp.asarray(resolution_inertia, dtype),
        resolution_inertia_sigma=jnp.asarray(resolution_inertia_sigma, dtype),
        _reference=reference,
        shape_model=shape,
        regularisation=tuple(float(w) for w in regularisation),
    )
    if throw and not (bool(oks[winner]) and np.isfinite(refine_costs[winner])):
        raise FitError(
            f"fit_lightcurve did not converge: the best of the {len(refine_costs)} starts solved on all the "
            f"data stopped at cost {refine_costs[winner]:.6g} without meeting rtol={rtol}, atol={atol} within "
            f"max_steps={max_steps} ({int(np.sum(oks))} converged).  Check the data, widen or refine the period "
            "search, raise max_steps, or pass throw=False for the unconverged result (FitError.result).",
            result,
        )
    if misfit.variance > misfit.threshold:
        _warn_of_misfit(result, math.sqrt(misfit.threshold), sigma, misfit.variance <= misfit.search_threshold)
    _warn_if_ambiguous(result)
    return result
