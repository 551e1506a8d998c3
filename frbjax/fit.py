"""Fit a free rigid body (moments of inertia, angular velocity, attitude) to attitude observations.

:func:`fit_attitude` takes observed attitudes q_k (unit quaternions, w x y z, body to space, either
sign) at times t_k, and optionally observed body angular velocities, and returns the torque-free
motion that best explains them (:class:`AttitudeFit`).

What the data can tell
----------------------
The motion depends on the moments only through their ratios: I -> c I together with L -> c L leaves
Omega = L / I and the attitude unchanged.  The fitted (identifiable) parameters are therefore the 8
numbers

    theta = (log(I2/I1), log(I3/I1), Omega_1, Omega_2, Omega_3, delta_1, delta_2, delta_3)

(``inertia="tensor"`` appends psi, the rotation vector of the principal axes in the body frame:
principal_axes = exp(hat(psi)), the tensor R diag(I) R^T, 11 parameters; the body is built from the
moments and axes directly, so the derivatives never meet an eigen-decomposition)

with Omega the body angular velocity at the reference time t_ref (the sample time nearest 0; it is 0
whenever the data contain t = 0) and delta a rotation vector: q(t_ref) = q_ref ⊗ exp(delta / 2), q_ref
the observed attitude at t_ref.  The result reports the moments scaled so that the largest is 1, and
the covariance of theta (``AttitudeFit.covariance``, from the Jacobian: (J^T J)^-1 s^2 with s^2 the
residual variance) and of the scaled moments (``inertia_covariance``).

Residuals
---------
Per sample, r_k = 2 sign(e_w) e_vec with e = conj(q_model(t_k)) ⊗ q_k: the rotation vector (for small
errors) taking the model attitude to the observed one, the same for q_k and -q_k.  Observed angular
velocities add (Omega_model(t_k) - Omega_k) / angular_velocity_sigma (attitude residuals are divided
by attitude_sigma).  A robust loss (``"huber"`` or ``"cauchy"``) replaces each sample's residual vector
r by r sqrt(rho(|r|^2 / c^2) / (|r|^2 / c^2)), so that the sum of squares is c^2 sum rho(|r|^2/c^2):
the Levenberg-Marquardt solver then minimises the robust cost (scale c = ``loss_scale``, by default
2.5 times the median residual norm of the least-squares fit on the previous continuation window).

Optimisation
------------
optimistix's Levenberg-Marquardt (``optx.least_squares``), from a batch of starting points solved in
one compiled program (one after another on CPU, under ``jax.vmap`` elsewhere: ``frbjax._multistart``):
the observed attitude at t_ref, the angular velocity from finite differences of the data around
t_ref, and several inertia ratios (permutations of a few triaxial shapes, then random ones from
``seed``), since the regimes (rotation around the largest or the smallest axis) and the orderings of
the moments are separate basins.  Each start is solved on growing time windows around t_ref
(continuation: the phase of a wrong model drifts with time, so a long record alone has many local
minima) with the squared loss, the last window (all samples) with the chosen loss.  The start with
the lowest cost wins.

Compilation
-----------
Compiling the solver dominates the first call (the Jacobian of the attitude with respect to the
moments is a large program); later calls with the same number of samples, number of starts, dtype,
solver settings (``rtol``, ``atol``, ``max_steps``) and compiler options reuse it, whatever the
data, loss, weights, gyro data or seed.  The compiled program holds one copy of the motion's
forward-mode derivative (a custom JVP hands the solver the Jacobian from one pass, and the same pass
gives the model at the solution, so the motion is not compiled again to report it), and the
continuation windows are one ``lax.scan`` rather than unrolled solves.  The motion's derivatives are
the elliptic formulas' own (``frbjax._body.state_with_elliptic_derivatives``): the rule that
`FreeRigidBody` applies to exactly symmetric bodies next to the plane of their equal moments, which
the iterates of continuous parameters never are, is a conditional branch that the Jacobian would
compile in full (without it the first call takes about a sixth less time).  The model is traced
once although optimistix calls the residuals twice while tracing (``frbjax._trace_once``: a tenth
of the first call).  On the CPU the solver is compiled with ``KERNEL_COMPILER_OPTIONS`` where the
motion runs as compiled kernels (no LLVM optimisation: half the compile time, a fifth more run time),
else ``DEFAULT_COMPILER_OPTIONS`` (XLA:CPU's fusion emitters off: about 25% less compile time, the
same run time; ``frbjax._cpu_options``).  JAX's persistent compilation
cache (``jax_compilation_cache_dir``) keeps the program across processes.
"""

from __future__ import annotations

import functools
import itertools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from . import _checks as checks, _compiled_motion, _quaternion as quaternion
from ._body import FreeRigidBody, state_with_elliptic_derivatives, with_principal_axes
from ._cpu_options import call_with_options, cpu_jit, DEFAULT_COMPILER_OPTIONS
from ._errors import FitError
from ._kernel_path import keyed_by_path
from ._multistart import solve_each
from ._trace_once import traced_once


__all__ = ["AttitudeFit", "FitError", "fit_attitude"]

_LOSSES = {"squared": 0, "huber": 1, "cauchy": 2}
_PRINCIPAL_PARAMETERS, _TENSOR_PARAMETERS = 8, 11
_AXES_AT_BODY_AXES = 12  # starts of a tensor fit whose principal axes start at the body axes
# A principal moment gap smaller than this many of its standard deviations leaves the axes in its
# plane undetermined (AttitudeFit.axes_identifiable).
_SIGNIFICANT_GAP = 3.0
# Weight of the triangle-inequality penalty (per unit of (I3 - I1 - I2) / I3) against residuals
# of the order of the attitude noise.
_TRIANGLE_WEIGHT = 1e9
# Weight (per radian, in units of the attitude residuals' weight) of a tensor fit's pull of the
# principal axes' rotation vector towards the body axes.  An axisymmetric body leaves the rotation
# about its symmetry axis undetermined by the data: without the pull, Levenberg-Marquardt wanders
# along that flat valley and may exhaust max_steps; with it, the fit reports the axes nearest the
# body axes.  Against the data's curvature (n samples of weight 1 per radian) it moves determined
# axes by about (weight^2 / n) times their angle: 1e-8 / n rad per radian.
_AXES_PULL = 1e-4
# Fractions of the samples (nearest t_ref first) of the continuation windows; the last is all of them.
_WINDOWS = (0.12, 0.3, 0.6, 1.0)
_MIN_WINDOW = 12  # samples in the smallest window (at least)
_BASE_SHAPES = ((0.6, 0.8, 1.0), (0.85, 0.92, 1.0), (0.4, 0.9, 1.0), (0.5, 0.55, 1.0))


class AttitudeFit(eqx.Module):
    """Result of :func:`fit_attitude`.

    - ``inertia`` (3,): principal moments, scaled so that the largest is 1: in the data's body axes
      (``inertia="principal"``), or ascending along ``principal_axes`` (``inertia="tensor"``);
    - ``inertia_tensor`` (3, 3): the inertia tensor in the data's body frame, scaled so that its
      largest principal moment is 1 (``diag(inertia)`` for a principal fit); ``principal_axes``
      (3, 3): the principal axes as columns in the body frame, a rotation (the identity for a
      principal fit); ``inertia_tensor_covariance`` (3, 3, 3, 3): Cov(T_ij, T_kl);
    - ``axes_identifiable``: False when two fitted principal moments are not significantly different
      (gap below 3 standard deviations): the data cannot show the orientation of the axes about the
      third one, the ``symmetry_axis`` (3,) (zeros when identifiable); the principal axes in that
      plane are then an arbitrary choice, and ``unidentified_direction`` (P,) is the direction of
      the parameters that the residuals do not determine (the null direction of J^T J; zeros when
      identifiable);
    - ``angular_velocity`` (3,): body angular velocity at t = 0;
    - ``attitude`` (4,): attitude (w, x, y, z; w >= 0) at t = 0;
    - ``body``: the fitted :class:`FreeRigidBody` (from ``inertia_tensor``, angular momentum
      ``inertia_tensor @ angular_velocity``, attitude ``attitude``), built when asked for (a
      property: a fit whose caller wants the parameters alone does not compile the constructor);
    - ``parameters`` (P,): theta = (log I2/I1, log I3/I1, Omega(t_ref), delta), and for a tensor fit
      psi, the rotation vector of the principal axes (module docstring); P = 8 or 11;
    - ``covariance`` (P, P): covariance of ``parameters``, (J^T J)^+ s^2, s^2 = 2 cost / (m - P);
    - ``inertia_covariance`` (3, 3): the same propagated to ``inertia`` (rank 2);
    - ``residuals`` (N, 3) attitude residuals (rad, unweighted, least-squares form) and
      ``angular_velocity_residuals`` (N, 3) (zeros without gyro data);
    - ``cost``: half the sum of the squared (weighted, robustified) residuals at the solution;
    - ``success``: the solver converged for the chosen start; ``start_costs``, ``start_success``,
      ``start_parameters`` (S, P): per start, where each ended (the runner-up basins, from which
      :func:`frbjax.posterior.attitude_posterior` starts chains); ``reference_time``: t_ref;
      ``loss_scale``: c of the robust loss.
    """

    inertia: Float[Array, 3]
    inertia_tensor: Float[Array, "3 3"]
    principal_axes: Float[Array, "3 3"]
    inertia_tensor_covariance: Float[Array, "3 3 3 3"]
    axes_identifiable: Array
    symmetry_axis: Float[Array, 3]
    unidentified_direction: Float[Array, " P"]
    angular_velocity: Float[Array, 3]
    attitude: Float[Array, 4]
    parameters: Float[Array, " P"]
    covariance: Float[Array, "P P"]
    inertia_covariance: Float[Array, "3 3"]
    residuals: Float[Array, "N 3"]
    angular_velocity_residuals: Float[Array, "N 3"]
    cost: Float[Array, ""]
    success: Array
    start_costs: Float[Array, " S"]
    start_success: Array
    start_parameters: Float[Array, "S P"]
    reference_time: Float[Array, ""]
    loss_scale: Float[Array, ""]

    @property
    def body(self) -> FreeRigidBody:
        """The fitted FreeRigidBody, built on each access (one dispatch of the cached constructor)."""
        omega, attitude = np.asarray(self.angular_velocity), np.asarray(self.attitude)
        if self.parameters.shape[0] == _PRINCIPAL_PARAMETERS:
            inertia = np.asarray(self.inertia)
            return _fitted_body(inertia, inertia * omega, attitude)
        tensor = np.asarray(self.inertia_tensor)
        return _fitted_body(tensor, tensor @ omega, attitude, tensor=True)


# ------------------------------------------------------------------------------------ the model


def _model(theta, reference, times, time_scale):
    """(q(t), Omega(t)) of the motion with parameters theta at times - t_ref (already subtracted).

    8 parameters: principal body axes; 11: principal axes exp(hat(theta[8:11])) in the body frame,
    the body built from moments and axes directly (smooth in both: no eigen-decomposition).
    """
    inertia = jnp.exp(jnp.concatenate([jnp.zeros(1, theta.dtype), theta[:2]]))
    omega = theta[2:5] / time_scale
    attitude = quaternion.multiply(reference, quaternion.exp_pure(theta[5:8]))
    if theta.shape[0] == _PRINCIPAL_PARAMETERS:
        body = FreeRigidBody(inertia, inertia * omega, attitude)
        # One evaluation gives both (``state``): the Jacobi functions behind q(t) give L(t) too.  The
        # elliptic formulas' own derivatives: the solver compiles faster (_body docstring there).
        momentum, attitude_t = state_with_elliptic_derivatives(body, times)
        return attitude_t, momentum / inertia[None, :]
    axes = quaternion.as_matrix(quaternion.exp_pure(theta[8:11]))
    momentum0 = axes @ (inertia * (axes.T @ omega))
    body = with_principal_axes(inertia, momentum0, attitude, axes)
    momentum, attitude_t = state_with_elliptic_derivatives(body, times)
    return attitude_t, (momentum @ axes) / inertia[None, :] @ axes.T


def _attitude_residual(q_model, q_observed):
    """2 sign(e_w) e_vec, e = conj(q_model) ⊗ q_observed: invariant under q_observed -> -q_observed."""
    e = quaternion.multiply(quaternion.conjugate(q_model), q_observed)
    sign = jnp.where(e[..., :1] < 0, -1.0, 1.0).astype(e.dtype)
    return 2 * sign * e[..., 1:]


def _robust_factor(squared, loss):
    """sqrt(rho(s)/s) for s = |r|^2 / c^2: 1 (squared), Huber, Cauchy; finite with its gradient at 0."""
    small = squared < 1e-8
    s = jnp.where(small, 1.0, squared)
    huber = jnp.where(squared <= 1, 1.0, (2 * jnp.sqrt(s) - 1) / s)
    cauchy = jnp.where(small, 1 - squared / 2, jnp.log1p(s) / s)
    ratio = jnp.where(loss == 1, huber, jnp.where(loss == 2, cauchy, 1.0))
    return jnp.sqrt(ratio)


def _residuals(theta, args):
    """(weighted, robustified residuals (M, 6), (q_model (M, 4), Omega_model (M, 3))) at every row."""
    data, mask, loss, scale = args
    times, q_obs, w_obs, reference, time_scale, gyro_weight, attitude_weight, triangle = data
    q_model, w_model = _model(theta, reference, times, time_scale)
    r_att = _attitude_residual(q_model, q_obs) * attitude_weight
    r_gyro = (w_model - w_obs) * gyro_weight
    r = jnp.concatenate([r_att, r_gyro], -1)  # (M, 6): one sample's residual vector
    squared = jnp.sum(r * r, -1) / scale**2
    factor = _robust_factor(squared, loss) * mask
    r = r * factor[:, None]
    # The triangle inequality I1 + I2 >= I3 of physical bodies, when asked for: a penalty on its
    # violation in the last row (the t = 0 row, which holds no sample).
    moments = jnp.exp(jnp.concatenate([jnp.zeros(1, theta.dtype), theta[:2]]))
    excess = (2 * jnp.max(moments) - jnp.sum(moments)) / jnp.max(moments)
    penalty = triangle * _TRIANGLE_WEIGHT * jnp.maximum(excess, 0)
    r = r.at[-1, 0].set(penalty)
    if theta.shape[0] == _TENSOR_PARAMETERS:
        # The axes' pull (_AXES_PULL) in the same row's gyro slots.
        r = r.at[-1, 3:].set(_AXES_PULL * attitude_weight * theta[8:11])
    return r, (q_model, w_model)


# ------------------------------------------------------------------------------------ the solver


@traced_once
def _flat_residuals_and_jacobian(theta, args):
    """(r, dr/dtheta, model), r flattened, by forward mode (8 tangents in one vmapped pass); traced
    once for the primal and the JVP of ``_least_squares_fn`` (``_trace_once``)."""

    def flat(p):
        r, model = _residuals(p, args)
        r = r.reshape(-1)
        return r, (r, model)

    jacobian, (residual, model) = jax.jacfwd(flat, has_aux=True)(theta)
    return residual, jacobian, model


@jax.custom_jvp
def _least_squares_fn(theta, args):
    """(r, aux) for optimistix, aux = (r, J, q_model, Omega_model): the model at every row with its
    residuals and Jacobian.

    The JVP rule is J @ dtheta with J from one forward-mode pass: the compiled solver then holds one
    copy of the body's derivative code (jax.linearize of the plain residuals inside the solver loop
    holds a linearisation and its transpose, and compiles several times slower), and the model values
    at the solution come with it (no separate evaluation of the motion to compile).
    """
    residual, jacobian, model = _flat_residuals_and_jacobian(theta, args)
    return residual, (residual, jacobian) + model


@_least_squares_fn.defjvp
def _least_squares_fn_jvp(primals, tangents):
    theta, args = primals
    dtheta = tangents[0]
    residual, jacobian, model = _flat_residuals_and_jacobian(theta, args)
    aux = (residual, jacobian) + model
    return (residual, aux), (jacobian @ dtheta, jax.tree.map(jnp.zeros_like, aux))


def _solve_start(theta0, reference, data, masks, losses, final_loss, loss_scale, rtol, atol, max_steps):
    """Continuation over the windows ``masks`` (all but the last stage use the squared loss).

    Returns theta, cost, success, the robust scale, and the aux of the last stage at theta (residuals,
    Jacobian, model quaternions and angular velocities at every row).
    """
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    data = (data[0], data[1], data[2], reference) + data[3:]
    rows = masks.shape[1]

    def stage(carry, stage_args):
        theta, previous, previous_mask = carry
        mask, loss = stage_args
        # The scale of the robust loss: given, or 2.5 times the median residual norm of the previous
        # stage over the samples it fitted.
        norms = jnp.sqrt(jnp.sum(previous.reshape(rows, 6) ** 2, -1))
        median = jnp.nanmedian(jnp.where(previous_mask > 0, norms, jnp.nan))
        median = jnp.where(jnp.isfinite(median), median, 1.0)
        scale = jnp.where(loss_scale > 0, loss_scale, 2.5 * median + 1e-12)
        solution = optx.least_squares(
            _least_squares_fn,
            solver,
            theta,
            args=(data, mask, loss, scale),
            has_aux=True,
            max_steps=max_steps,
            throw=False,
        )
        # The aux of the solver state belongs to the returned (last accepted) value; solution.aux is
        # that of the step before.
        aux = solution.state.aux
        ok = solution.result == optx.RESULTS.successful
        finite = jnp.all(jnp.isfinite(solution.value)) & jnp.all(jnp.isfinite(aux[0]))
        theta_new = jnp.where(finite, solution.value, theta)
        residual = jnp.where(finite, aux[0], previous)
        return (theta_new, residual, mask), (ok & finite, scale, aux)

    stage_losses = losses.at[-1].set(final_loss)
    initial = (theta0, jnp.zeros(rows * 6, theta0.dtype), jnp.zeros(rows, theta0.dtype))
    (theta, residual, _), (ok, scales, aux) = jax.lax.scan(stage, initial, (masks, stage_losses))
    cost = 0.5 * jnp.sum(residual * residual)
    cost = jnp.where(jnp.isfinite(cost) & ok[-1], cost, jnp.inf)
    return theta, cost, ok[-1], scales[-1], jax.tree.map(lambda a: a[-1], aux)


def _fit(thetas0, references, data, masks, final_loss, loss_scale, rtol, atol, max_steps):
    losses = jnp.zeros(masks.shape[0], jnp.int32)
    solve = lambda theta0, reference: _solve_start(  # noqa: E731
        theta0, reference, data, masks, losses, final_loss, loss_scale, rtol, atol, max_steps
    )
    thetas, costs, oks, scales, aux = solve_each(solve, (thetas0, references))
    # The best start: lowest cost among converged ones (any start if none converged).
    finite_costs = jnp.where(jnp.isfinite(costs), costs, jnp.inf)
    best = jnp.argmin(finite_costs)
    theta, scale = thetas[best], scales[best]
    r, jac, q_model, w_model = (a[best] for a in aux)
    # Residuals that count: 3 per sample, 6 with gyro data (the gyro ones are zeros without).
    m = 3 * jnp.sum(masks[-1] != 0) * jnp.where(data[4] != 0, 2, 1)
    variance = jnp.sum(r * r) / jnp.maximum(m - theta.size, 1)
    covariance = jnp.linalg.pinv(jac.T @ jac) * variance
    # The model at the samples and, in the last row, at t = 0 (unweighted).
    q_obs, w_obs = data[1][:-1], data[2][:-1]
    return dict(
        theta=theta,
        thetas=thetas,
        costs=costs,
        oks=oks,
        best=best,
        covariance=covariance,
        scale=scale,
        jacobian=jac,
        residuals=_attitude_residual(q_model[:-1], q_obs),
        gyro_residuals=w_model[:-1] - w_obs,
        attitude0=q_model[-1],
        omega0=w_model[-1],
    )


def _normalised_inertia(p):
    """Moments scaled to a largest of 1 from theta[:2] = (log I2/I1, log I3/I1), and their Jacobian."""
    logs = np.concatenate([[0.0], np.asarray(p[:2], float)])
    largest = int(np.argmax(logs))
    moments = np.exp(logs - logs[largest])
    # d log(moment_i) / d theta_j = [i == j + 1] - [largest == j + 1]
    jacobian = np.zeros((3, len(p)))
    for j in range(2):
        jacobian[:, j] = moments * ((np.arange(3) == j + 1).astype(float) - float(largest == j + 1))
    return moments, jacobian


def _rotation_matrix(rotation_vector):
    """Rodrigues' formula (numpy): the rotation by |v| about v."""

    def cross(v):  # cross(v) @ x = v x x
        return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])

    angle = np.linalg.norm(rotation_vector)
    if angle < 1e-12:
        return np.eye(3) + cross(rotation_vector)
    generator = cross(rotation_vector / angle)
    return np.eye(3) + np.sin(angle) * generator + (1 - np.cos(angle)) * generator @ generator


def _scaled_tensor(theta):
    """(sorted moments with a largest of 1, their axes (a rotation), the tensor) of parameters theta."""
    moments, _ = _normalised_inertia(theta)
    axes = _rotation_matrix(theta[8:11])
    order = np.argsort(moments, kind="stable")
    moments, axes = moments[order], axes[:, order]
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    return moments, axes, axes @ np.diag(moments) @ axes.T


def _tensor_result(theta, covariance, jacobian):
    """The tensor, its principal moments and axes, their covariances and identifiability (numpy).

    Derivatives of the tensor and of the moments with respect to theta by central differences of
    these smooth (closed-form) functions; the moments' are exact up to ~1e-10 relative, more than
    enough for a covariance.
    """
    moments, axes, tensor = _scaled_tensor(theta)
    step = 1e-6
    tensor_derivative, moments_derivative = [], []
    for k in range(theta.size):
        shift = np.zeros_like(theta)
        shift[k] = step
        plus, minus = _scaled_tensor(theta + shift), _scaled_tensor(theta - shift)
        tensor_derivative.append((plus[2] - minus[2]) / (2 * step))
        moments_derivative.append((plus[0] - minus[0]) / (2 * step))
    tensor_derivative, moments_derivative = np.asarray(tensor_derivative), np.asarray(moments_derivative).T
    tensor_covariance = np.einsum("kij,kl,lmn->ijmn", tensor_derivative, covariance, tensor_derivative)
    moments_covariance = moments_derivative @ covariance @ moments_derivative.T
    # A pair of moments whose gap is not significant leaves the rotation of the axes in their plane
    # undetermined (an axisymmetric body has no preferred axes about its symmetry axis): the axis of
    # the third moment is then the symmetry axis.
    symmetry_axis = np.zeros(3)
    identifiable = True
    for (i, j), third in (((0, 1), 2), ((1, 2), 0)):
        gap = moments[j] - moments[i]
        spread = np.sqrt(max(moments_covariance[i, i] + moments_covariance[j, j] - 2 * moments_covariance[i, j], 0.0))
        if not gap > _SIGNIFICANT_GAP * spread:
            identifiable = False
            symmetry_axis = axes[:, third]
    unidentified = np.zeros(theta.size)
    if not identifiable:
        # The parameters' direction that changes the residuals least: the null direction of J^T J
        # (columns scaled to unit norm, then back to the parameters' units, normalised).
        norms = np.maximum(np.linalg.norm(jacobian, axis=0), 1e-300)
        _, vectors = np.linalg.eigh((jacobian / norms).T @ (jacobian / norms))
        unidentified = vectors[:, 0] / norms
        unidentified /= np.linalg.norm(unidentified)
    return dict(
        principal_moments=moments,
        principal_axes=axes,
        inertia_tensor=tensor,
        inertia_tensor_covariance=tensor_covariance,
        moments_covariance=moments_covariance,
        axes_identifiable=identifiable,
        symmetry_axis=symmetry_axis,
        unidentified_direction=unidentified,
    )


def _principal_result(moments, moments_covariance):
    """The same fields for a fit whose body axes are principal (diagonal tensor, identity axes)."""
    covariance = np.zeros((3, 3, 3, 3))
    for i in range(3):
        for j in range(3):
            covariance[i, i, j, j] = moments_covariance[i, j]
    return dict(
        principal_moments=moments,
        principal_axes=np.eye(3),
        inertia_tensor=np.diag(moments),
        inertia_tensor_covariance=covariance,
        moments_covariance=moments_covariance,
        axes_identifiable=True,
        symmetry_axis=np.zeros(3),
        unidentified_direction=np.zeros(_PRINCIPAL_PARAMETERS),
    )


_make_body = keyed_by_path(FreeRigidBody, jit=eqx.filter_jit)
_make_tensor_body = keyed_by_path(FreeRigidBody.from_inertia_tensor, jit=eqx.filter_jit)


def _fitted_body(inertia, angular_momentum, attitude, tensor=False):
    """The fitted FreeRigidBody.  Built as any body is (its constructor is one compiled program, cached
    by shapes); a fit that ended non-finite, which the eager constructor rejects, gets the NaN body of
    a construction under jit.  ``inertia``: moments, or the tensor when ``tensor``."""
    build, build_traced = (
        (FreeRigidBody.from_inertia_tensor, _make_tensor_body) if tensor else (FreeRigidBody, _make_body)
    )
    try:
        return build(inertia, angular_momentum, attitude)
    except ValueError:
        return build_traced(inertia, angular_momentum, attitude)


# Where the motion and its derivatives are compiled kernels (the CPU's default), XLA compiles only the
# solver's linear algebra around them, and without LLVM's optimisations it does so in half the time:
# the first call of benchmarks/first_answer.py's fit (200 samples, 12 starts, one core, 2026-11-28)
# 1.58 s against 2.87 s, a later call 0.30 s against 0.25 s.
KERNEL_COMPILER_OPTIONS = {**DEFAULT_COMPILER_OPTIONS, "xla_backend_optimization_level": 0}


_fit_program = cpu_jit(_fit, static_argnames=("rtol", "atol", "max_steps"))


def _solve(options, *args, **static):
    """The solver compiled with ``options``; by default ``DEFAULT_COMPILER_OPTIONS`` on the CPU
    (``cpu_jit``), ``KERNEL_COMPILER_OPTIONS`` where the motion's kernels are selected there."""
    if options is not None:
        return _fit_program.compiled(tuple(sorted(options.items())))(*args, **static)
    if jax.default_backend() == "cpu" and _compiled_motion.selected(args[0].dtype):
        return call_with_options(_fit_program.compiled, KERNEL_COMPILER_OPTIONS, *args, **static)
    return _fit_program(*args, **static)


def _rotation_vector(q):
    """Rotation vector of unit quaternions (..., 4) of either sign (numpy)."""
    q = np.where(q[..., :1] < 0, -q, q)
    vector_norm = np.linalg.norm(q[..., 1:], axis=-1)
    angle = 2 * np.arctan2(vector_norm, q[..., 0])
    safe = np.where(vector_norm > 1e-12, vector_norm, 1.0)
    scale = np.where(vector_norm > 1e-12, angle / safe, 2.0)
    return q[..., 1:] * scale[..., None]


def _hamilton(p, q):
    """Hamilton product of (..., 4) numpy arrays."""
    pw, pv, qw, qv = p[..., :1], p[..., 1:], q[..., :1], q[..., 1:]
    w = pw * qw - np.sum(pv * qv, -1, keepdims=True)
    return np.concatenate([w, pw * qv + qw * pv + np.cross(pv, qv)], -1)


def _finite_difference_rate(times, q, index, span):
    """Mean body rate over [index - span, index + span] (clipped): log(conj(q_a) q_b) / (t_b - t_a)."""
    n = len(times)
    a, b = max(index - span, 0), min(index + span, n - 1)
    if a == b:
        return np.zeros(3)
    # Chain the steps: the rotation per step is below pi for reasonably sampled data.
    conjugate = q[a:b] * np.array([1.0, -1.0, -1.0, -1.0])
    steps = _rotation_vector(_hamilton(conjugate, q[a + 1 : b + 1]))
    return np.sum(steps, 0) / (times[b] - times[a])


def _start_shapes(n_starts, rng):
    """Inertia guesses: permutations of the base triaxial shapes, then random ones."""
    shapes = []
    for base in _BASE_SHAPES:
        for perm in itertools.permutations(range(3)):
            candidate = tuple(base[p] for p in perm)
            if candidate not in shapes:
                shapes.append(candidate)
    shapes = shapes[:n_starts]
    while len(shapes) < n_starts:
        shapes.append(tuple(np.exp(rng.uniform(np.log(0.3), 0.0, size=3))))
    return np.asarray(shapes)


# ------------------------------------------------------------------------------------ arguments


def _checked_data(times, quaternions, angular_velocity_data, nan_policy):
    """(times, quaternions, gyro or None, omitted rows, dtype) of the samples to fit, numpy; ValueError for
    data the fit cannot use, naming the argument and the first offending entry (module ``_checks``)."""
    checks.choice("nan_policy", nan_policy, ("raise", "omit"))
    times_np = checks.real_array("times", times)
    q_np = checks.real_array("quaternions", quaternions)
    if times_np.ndim != 1:
        raise ValueError(f"times must be one-dimensional (N,), got shape {times_np.shape}")
    n = len(times_np)
    if q_np.shape != (n, 4):
        raise ValueError(f"quaternions must have shape (N, 4) = ({n}, 4) like times, got {q_np.shape}")
    arrays = [times_np, q_np]
    gyro_np = None
    if angular_velocity_data is not None:
        gyro_np = checks.real_array("angular_velocity_data", angular_velocity_data)
        if gyro_np.shape != (n, 3):
            raise ValueError(f"angular_velocity_data must have shape (N, 3) = ({n}, 3) like times, got {gyro_np.shape}")
        arrays.append(gyro_np)
    omitted = checks.nonfinite_rows(*arrays)
    if np.any(omitted) and nan_policy == "raise":
        names = "times, quaternions or angular_velocity_data" if gyro_np is not None else "times or quaternions"
        raise ValueError(
            f"samples {checks.describe_rows(omitted)} have non-finite {names}; pass nan_policy='omit' to leave them out"
        )
    kept = np.flatnonzero(~omitted)
    # The checks below see the kept rows under their input indices (rows left out read as valid).
    checked = np.where(omitted[:, None], np.array([1.0, 0.0, 0.0, 0.0]), q_np)
    checks.check_nonzero_rows("quaternions", checked)
    checks.check_unit_rows("quaternions", checked.astype(q_np.dtype))
    checks.check_distinct_times("times", times_np[kept], kept)
    if len(kept) < 4:
        raise ValueError(
            f"times: the fit needs at least 4 samples, got {len(kept)}"
            + (f" after leaving out {n - len(kept)}" if np.any(omitted) else "")
        )
    dtype = jnp.result_type(times_np.dtype, q_np.dtype, float)  # the fit runs in the data's dtype
    gyro_np = None if gyro_np is None else gyro_np[kept].astype(float)
    return times_np[kept].astype(float), q_np[kept].astype(float), gyro_np, omitted, dtype


def _check_options(
    *, loss, loss_scale, attitude_sigma, angular_velocity_sigma, inertia, n_starts, seed, rtol, atol, max_steps
):
    checks.choice("loss", loss, _LOSSES)
    checks.choice("inertia", inertia, ("principal", "tensor"))
    if loss_scale is not None:
        checks.scalar("loss_scale", loss_scale, positive=True)
    checks.scalar("attitude_sigma", attitude_sigma, positive=True)
    checks.scalar("angular_velocity_sigma", angular_velocity_sigma, positive=True)
    checks.integer("n_starts", n_starts, minimum=1)
    checks.integer("seed", seed, minimum=0)
    checks.scalar("rtol", rtol, positive=True)
    checks.scalar("atol", atol, positive=True)
    checks.integer("max_steps", max_steps, minimum=1)


def _with_omitted_rows(rows, omitted):
    """``rows`` of the fitted samples placed at their input indices, NaN at the omitted ones."""
    full = np.full((len(omitted),) + rows.shape[1:], np.nan, dtype=rows.dtype)
    full[~omitted] = rows
    return full


def _reference_sample(times, quaternions):
    """The data sorted by time (unit quaternions) and the reference sample: (order, sorted times,
    sorted quaternions, the index of the time nearest 0, that time t_ref, the observed attitude there
    with w >= 0)."""
    order = np.argsort(times, kind="stable")
    times_sorted, q_sorted = times[order], quaternions[order]
    q_sorted = q_sorted / np.linalg.norm(q_sorted, axis=-1, keepdims=True)
    index = int(np.argmin(np.abs(times_sorted)))
    reference = q_sorted[index] * (1.0 if q_sorted[index, 0] >= 0 else -1.0)
    return order, times_sorted, q_sorted, index, times_sorted[index], reference


def fit_attitude(
    times,
    quaternions,
    *,
    angular_velocity_data=None,
    loss: str = "squared",
    loss_scale: float | None = None,
    attitude_sigma: float = 1.0,
    angular_velocity_sigma: float = 1.0,
    inertia: str = "principal",
    triangle_inequality: bool = False,
    n_starts: int = 12,
    seed: int = 0,
    key=None,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    max_steps: int = 200,
    compiler_options: dict | None = None,
    nan_policy: str = "raise",
    throw: bool = True,
) -> AttitudeFit:
    """Fit moments of inertia (ratios), angular velocity and attitude to observed attitudes.

    Arguments: ``times`` (N,), ``quaternions`` (N, 4) observed attitudes (w, x, y, z, body to space;
    the sign of each is irrelevant); ``angular_velocity_data`` (N, 3): observed body angular velocities
    at the same times (optional, e.g. a gyroscope); ``loss``: "squared", "huber" or "cauchy";
    ``loss_scale``: c of the robust loss (in units of the weighted residuals; default: 2.5 times the
    median residual norm of the least-squares fit on the previous continuation window);
    ``attitude_sigma``, ``angular_velocity_sigma``: the residuals are divided by them (their ratio
    weighs gyro against attitude data);
    ``inertia``: "principal" (the data's body axes are principal axes: 8 parameters) or "tensor"
    (the whole inertia tensor up to scale in the data's body frame: the principal axes are fitted
    too, as the rotation vector psi of ``principal_axes``, 11 parameters; their starts are the body
    axes, and random orientations for starts beyond the twelfth); ``triangle_inequality``: make the
    fitted moments obey I1 + I2 >= I3, as those of matter do (a penalty: to about 1e-9 relative);
    ``n_starts``: starting points (solved in one compiled program); ``seed`` or ``key`` (a
    ``jax.random`` key): randomises the starts beyond the deterministic ones and their inertia guesses.

    ``rtol``, ``atol``, ``max_steps``: of each Levenberg-Marquardt solve; ``compiler_options``: XLA
    compiler options of the solver (default on the CPU ``KERNEL_COMPILER_OPTIONS`` where the motion runs
    as compiled kernels, which compiles in half the time and runs a fifth slower, else
    ``DEFAULT_COMPILER_OPTIONS``; ``{}`` for XLA's defaults).

    ``nan_policy``: what to do with samples that have a non-finite time, quaternion or angular
    velocity (a dropped sample): ``"raise"`` (default) refuses them, naming their indices;
    ``"omit"`` leaves them out (their rows of ``residuals`` are NaN).  ``throw``: a fit whose best
    start did not converge raises :class:`frbjax.FitError` (default), whose ``result`` is the
    unconverged fit; with ``throw=False`` that result is returned (``success`` False).

    Refused with a ValueError naming the argument and the first offending entry: times that are not
    one-dimensional or repeat a value, quaternions that are not (N, 4) or not unit (norm 1 to
    1e-6; 1e-3 for float32 data), angular velocity data that are not (N, 3), fewer than 4 samples,
    non-finite or non-positive sigmas, scales and tolerances, counts below 1, unknown option names.

    Only the ratios of the moments are identifiable (I -> c I, L -> c L give the same motion): see the
    module docstring for the fitted parameters.  A tensor fit of a (nearly) axisymmetric body cannot
    determine the principal axes about the symmetry axis: ``AttitudeFit.axes_identifiable`` is then
    False (the tensor itself is still determined).  Runs in the dtype of the inputs (use float64).
    All starts share one compilation for a given (N, n_starts), dtype, solver settings and compiler
    options (module docstring, "Compilation").
    """
    _check_options(
        loss=loss,
        loss_scale=loss_scale,
        attitude_sigma=attitude_sigma,
        angular_velocity_sigma=angular_velocity_sigma,
        inertia=inertia,
        n_starts=n_starts,
        seed=seed if key is None else 0,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
    )
    times_np, q_np, gyro_np, omitted, dtype = _checked_data(times, quaternions, angular_velocity_data, nan_policy)
    tensor = inertia == "tensor"
    n_parameters = _TENSOR_PARAMETERS if tensor else _PRINCIPAL_PARAMETERS
    n = len(times_np)
    if key is not None:
        seed = int(jax.random.randint(key, (), 0, 2**31 - 1))
    rng = np.random.default_rng(seed)

    order, times_sorted, q_sorted, index, t_ref, reference = _reference_sample(times_np, q_np)

    # Angular velocity guesses from finite differences around t_ref (short and longer spans).
    rates = [_finite_difference_rate(times_sorted, q_sorted, index, span) for span in (1, 3)]
    if gyro_np is not None:
        gyro = gyro_np[order]
        rates.insert(0, gyro[index])
    rate_norm = max(float(np.linalg.norm(rates[0])), 1e-300)
    time_scale = 1.0 / rate_norm if rate_norm > 1e-300 else 1.0

    shapes = _start_shapes(n_starts, rng)
    thetas0 = np.zeros((n_starts, n_parameters))
    thetas0[:, 0] = np.log(shapes[:, 1] / shapes[:, 0])
    thetas0[:, 1] = np.log(shapes[:, 2] / shapes[:, 0])
    for s in range(n_starts):
        # Cycle the rate guesses over the inertia guesses (the first shapes get the first guess).
        thetas0[s, 2:5] = rates[(s // 6) % len(rates)] * time_scale
    if tensor:
        # Principal axes start at the body axes (the usual case: products of inertia of a few
        # percent, axes tilted by tens of degrees at most); starts beyond the first
        # _AXES_AT_BODY_AXES try random orientations too.
        turns = rng.normal(size=(n_starts, 3))
        turns *= rng.uniform(0, np.pi, size=(n_starts, 1)) / np.linalg.norm(turns, axis=1, keepdims=True)
        thetas0[:, 8:11] = np.where((np.arange(n_starts) >= _AXES_AT_BODY_AXES)[:, None], turns, 0.0)
    references = np.broadcast_to(reference, (n_starts, 4))

    # Continuation windows: the samples nearest t_ref.  One more row (mask 0) holds t = 0, where the
    # solver's model gives the reported attitude and angular velocity.
    distance = np.abs(times_sorted - t_ref)
    ranked = np.sort(distance)
    masks = np.zeros((len(_WINDOWS), n + 1))
    for k, fraction in enumerate(_WINDOWS):
        count = n if fraction >= 1 else min(n, max(math.ceil(fraction * n), _MIN_WINDOW))
        masks[k, :n] = distance <= ranked[count - 1]

    if gyro_np is None:
        gyro = np.zeros((n, 3))
        gyro_weight = 0.0
    else:
        gyro_weight = 1.0 / angular_velocity_sigma
    data = (
        jnp.asarray(np.append(times_sorted - t_ref, -t_ref), dtype),
        jnp.asarray(np.concatenate([q_sorted, [[1.0, 0.0, 0.0, 0.0]]]), dtype),
        jnp.asarray(np.concatenate([gyro, np.zeros((1, 3))]), dtype),
        jnp.asarray(time_scale, dtype),
        jnp.asarray(gyro_weight, dtype),
        jnp.asarray(1.0 / attitude_sigma, dtype),
        jnp.asarray(1.0 if triangle_inequality else 0.0, dtype),
    )
    scale_in = jnp.asarray(-1.0 if loss_scale is None else loss_scale, dtype)
    out = _solve(
        compiler_options,
        jnp.asarray(thetas0, dtype),
        jnp.asarray(references, dtype),
        data,
        jnp.asarray(masks, dtype),
        jnp.asarray(_LOSSES[loss], jnp.int32),
        scale_in,
        rtol=float(rtol),
        atol=float(atol),
        max_steps=int(max_steps),
    )

    # Back to physical parameters (Omega in 1/time).  The rest is numpy on the solver's outputs (one
    # transfer each): eager JAX operations would each compile a small program on a first call.
    out = {key: np.asarray(value) for key, value in out.items()}
    unscale = np.ones(n_parameters)
    unscale[2:5] = 1.0 / time_scale
    theta_physical = out["theta"].astype(float) * unscale
    covariance = out["covariance"].astype(float) * unscale[:, None] * unscale[None, :]
    moments, d_inertia = _normalised_inertia(theta_physical)
    inertia_covariance = d_inertia @ covariance @ d_inertia.T
    tensor_result = (
        _tensor_result(theta_physical, covariance, out["jacobian"] / unscale)
        if tensor
        else _principal_result(moments, inertia_covariance)
    )
    omega0 = out["omega0"]
    attitude0 = -out["attitude0"] if out["attitude0"][0] < 0 else out["attitude0"]
    moments = tensor_result["principal_moments"]
    inertia_covariance = tensor_result["moments_covariance"]
    unsort = np.argsort(order)
    residuals = _with_omitted_rows(out["residuals"][unsort], omitted)
    if gyro_np is None:
        w_residuals = np.zeros_like(residuals)
    else:
        w_residuals = _with_omitted_rows(out["gyro_residuals"][unsort], omitted)
    costs, oks, best = out["costs"], out["oks"], int(out["best"])
    as_float = functools.partial(jnp.asarray, dtype=dtype)
    result = AttitudeFit(
        inertia=as_float(moments),
        inertia_tensor=as_float(tensor_result["inertia_tensor"]),
        principal_axes=as_float(tensor_result["principal_axes"]),
        inertia_tensor_covariance=as_float(tensor_result["inertia_tensor_covariance"]),
        axes_identifiable=jnp.asarray(tensor_result["axes_identifiable"]),
        symmetry_axis=as_float(tensor_result["symmetry_axis"]),
        unidentified_direction=as_float(tensor_result["unidentified_direction"]),
        angular_velocity=as_float(omega0),
        attitude=as_float(attitude0),
        parameters=as_float(theta_physical),
        covariance=as_float(covariance),
        inertia_covariance=as_float(inertia_covariance),
        residuals=as_float(residuals),
        angular_velocity_residuals=as_float(w_residuals),
        cost=as_float(costs[best]),
        success=jnp.asarray(oks[best]),
        start_costs=as_float(costs),
        start_success=jnp.asarray(oks),
        start_parameters=as_float(out["thetas"].astype(float) * unscale),
        reference_time=as_float(t_ref),
        loss_scale=as_float(out["scale"]),
    )
    if throw and not (bool(oks[best]) and np.isfinite(costs[best])):
        raise FitError(
            f"fit_attitude did not converge: the best of {n_starts} starts stopped at cost {costs[best]:.6g} "
            f"without meeting rtol={rtol}, atol={atol} within max_steps={max_steps} ({int(np.sum(oks))} "
            "starts converged).  Check the data and their units, raise max_steps or n_starts, or pass "
            "throw=False for the unconverged result (FitError.result).",
            result,
        )
    return result
