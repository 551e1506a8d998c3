"""FreeRigidBody: the exact torque-free motion of a rigid body, batched, jit/vmap/grad-compatible."""

from __future__ import annotations

import dataclasses
import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from . import _compiled_motion, _quaternion as quaternion
from ._checks import check_finite, check_nonzero_rows, check_positive, is_concrete, on_host, real_array
from ._frame import angular_velocity, dot as _dot, matrix_product, matrix_times as _apply, to_body, to_principal
from ._fusion import materialise, sum_last, when_any
from ._inertia import InertiaTensor, through_principal_frame, validate_tensor
from ._kernel_path import keyed_by_path
from ._precession import jvp_of_moved, precessing, with_precession_derivatives
from ._regimes import (
    classify,
    constants,
    evaluate,
    evaluate_once,
    orbit_constants,
    reference as regime_reference,
    UNIFORM,
)
from ._uniform import uniform_momentum, uniform_spin


def working_frame(inertia, momentum):
    """Signed permutation P (det +1, columns = working axes in body coordinates) and the working data.

    The working frame sorts the moments (J1 <= J2 <= J3) and uses the body's symmetry under a rotation
    by pi about a principal axis to make l1 >= 0 and l3 >= 0 (docs/theory.md §2,
    "The working frame"): with those signs one formula per regime covers every orbit.
    """
    # Stable ranks (ties keep their order) by comparisons: body i's moment goes to working axis
    # rank_i.  (XLA's sort of the three moments cost 170 ns per body on CPU, these 10 ns.)
    j1, j2, j3 = inertia[..., 0], inertia[..., 1], inertia[..., 2]
    rank = jnp.stack(
        [
            (j2 < j1).astype(jnp.int32) + (j3 < j1),
            (j1 <= j2).astype(jnp.int32) + (j3 < j2),
            (j1 <= j3).astype(jnp.int32) + (j2 <= j3),
        ],
        -1,
    )
    working_axes = jnp.broadcast_to(jnp.arange(3), (*rank.shape, 3))
    permutation = (rank[..., :, None] == working_axes).astype(inertia.dtype)
    # An odd permutation has determinant -1: flip the middle working axis to make it a rotation.
    parity = _permutation_sign(rank).astype(inertia.dtype)
    column_signs = jnp.stack([jnp.ones_like(parity), parity, jnp.ones_like(parity)], -1)
    permutation = permutation * column_signs[..., None, :]
    sorted_inertia = jnp.stack(
        [jnp.where(rank[..., 0] == k, j1, jnp.where(rank[..., 1] == k, j2, j3)) for k in range(3)], -1
    )
    momentum = _apply(jnp.swapaxes(permutation, -1, -2), momentum)
    s1 = jnp.where(momentum[..., 0] < 0, -1.0, 1.0).astype(inertia.dtype)
    s3 = jnp.where(momentum[..., 2] < 0, -1.0, 1.0).astype(inertia.dtype)
    flips = jnp.stack([s1, s1 * s3, s3], -1)
    return permutation * flips[..., None, :], sorted_inertia, momentum * flips


@jax.custom_jvp
def _normalised(vector):
    """vector / |vector| over the last axis."""
    return vector / jnp.sqrt(sum_last(vector * vector))[..., None]


@_normalised.defjvp
def _normalised_jvp(primals, tangents):
    """d(v/|v|) = (dv - u (u . dv)) / |v| with u = v/|v|, component by component.

    Written out so that reverse mode sums the components' contributions as additions: through the
    broadcast 1/|v| of the value, the transpose was a reduction over the trailing axis (an XLA
    reduction at every time).  (Writing the value component by component instead cost 5% of an
    evaluation.)
    """
    (vector,), (tangent,) = primals, tangents
    size = vector.shape[-1]
    inverse_norm = 1 / jnp.sqrt(sum_last(vector * vector))
    unit = jnp.stack([vector[..., k] * inverse_norm for k in range(size)], -1)
    along = _dot(unit, tangent)
    derivative = jnp.stack([(tangent[..., k] - unit[..., k] * along) * inverse_norm for k in range(size)], -1)
    return _normalised(vector), derivative


def _permutation_sign(order):
    """+1 for an even permutation of (0, 1, 2), -1 for an odd one (the same for its inverse)."""
    i, j, k = order[..., 0], order[..., 1], order[..., 2]
    return jnp.where((j - i) * (k - i) * (k - j) > 0, 1, -1)


def _validate(inertia, angular_momentum, attitude):
    """Eager checks of the constructor's inputs; raises ValueError naming the offending argument.

    Shapes are checked always (they are static under jit too).  Values are checked only for concrete
    inputs: a JAX tracer (under jit, vmap, grad) has no value yet, and an invalid body built from
    tracers gives NaN outputs instead (see FreeRigidBody).
    """
    # Strings, objects and complex numbers are refused by name before JAX's conversion.
    for name, value in (("inertia", inertia), ("angular_momentum", angular_momentum), ("attitude", attitude)):
        if value is not None and is_concrete(value):
            real_array(name, value)
    inertia, angular_momentum = jnp.asarray(inertia), jnp.asarray(angular_momentum)
    attitude = None if attitude is None else jnp.asarray(attitude)
    arrays = dict(inertia=inertia, angular_momentum=angular_momentum)
    if attitude is not None:
        arrays["attitude"] = attitude
    shapes = {}
    for name, value in arrays.items():
        shape = tuple(value.shape)
        size = 4 if name == "attitude" else 3
        if len(shape) == 0 or shape[-1] != size:
            raise ValueError(f"{name} must have shape (..., {size}), got shape {shape}")
        shapes[name] = shape
    try:
        np.broadcast_shapes(*(shape[:-1] for shape in shapes.values()))
    except ValueError:
        described = ", ".join(f"{name} {shape}" for name, shape in shapes.items())
        raise ValueError(f"incompatible leading (batch) shapes: {described}") from None

    if is_concrete(inertia):
        check_positive("inertia", inertia)
    if is_concrete(angular_momentum):
        check_finite("angular_momentum", angular_momentum)
    if attitude is not None and is_concrete(attitude):
        check_finite("attitude", attitude)
        check_nonzero_rows("attitude", attitude)


def _working_dtype(inertia, angular_momentum):
    """The floating dtype of a body's computation (that of its moments and L, at least float)."""
    return jnp.result_type(inertia, angular_momentum, float)


# Principal components of L within this many ulp of |L| come from rounding the change of frame.
_FRAME_ROUNDING = 64


def _prepare(inertia, angular_momentum, attitude, axes=None):
    """Broadcast, checked (NaN for invalid bodies) and normalised inputs and the working frame:
    (inertia, angular_momentum, attitude, valid, frame, sorted inertia, unit L, |L|, regime).

    ``axes`` (..., 3, 3): principal axes as columns in body coordinates (a rotation), or None when
    the body axes are principal.  The frame is then the working frame's axes in body coordinates,
    axes @ P (docs/theory.md §12); ``angular_momentum`` and ``attitude`` stay those of the body frame.
    """
    inertia, angular_momentum, attitude, axes, valid = _validated(inertia, angular_momentum, attitude, axes)
    attitude = attitude / jnp.sqrt(sum_last(attitude * attitude))[..., None]

    # Normalised in the working frame (a signed permutation: exact), where the components come in
    # the order of the sorted moments: |L| then rounds the same way for the moments in any order,
    # and a body with its axes relabelled computes bit for bit the same motion.
    if axes is None:
        permutation, sorted_inertia, momentum_working = working_frame(inertia, angular_momentum)
    else:
        principal_momentum = to_principal(axes, angular_momentum)
        # Components left by rounding the change of frame (a tensor's L along a principal axis, or in
        # the plane of two equal moments, gets ~1e-17 across it) are zeros: the body is then exactly
        # a uniform rotation, as given, not a nutation of rounding size whose derivatives cancel.
        # Zeros in value only: x - x keeps the component's tangent (the tilt of the axes moves L off
        # a principal plane or axis at first order).
        size = jnp.sqrt(sum_last(principal_momentum * principal_momentum))[..., None]
        rounding = _FRAME_ROUNDING * jnp.finfo(principal_momentum.dtype).eps * size
        principal_momentum = jnp.where(
            jnp.abs(principal_momentum) <= rounding,
            principal_momentum - jax.lax.stop_gradient(principal_momentum),
            principal_momentum,
        )
        permutation, sorted_inertia, momentum_working = working_frame(inertia, principal_momentum)
        permutation = matrix_product(axes, permutation)
    norm_squared = sum_last(momentum_working**2)
    moving = norm_squared > 0
    norm = jnp.sqrt(jnp.where(moving, norm_squared, 1))
    unit_working = momentum_working / norm[..., None]
    norm = jnp.where(moving, norm, 0)

    regime = classify(sorted_inertia, unit_working, norm)
    return inertia, angular_momentum, attitude, valid, permutation, sorted_inertia, unit_working, norm, regime


def _working_constants(sorted_inertia, unit_working, regime):
    """(per-body data of the motion, q̂(0)): the compiled series' records where the kernels are
    selected (``_compiled_motion.series_selected``), the JAX series of ``_regimes.constants`` elsewhere."""
    if _compiled_motion.series_selected(sorted_inertia):
        record = _compiled_motion.series_record(sorted_inertia, unit_working, regime)
        consts = dict(record=record, inertia=sorted_inertia, unit_momentum=unit_working, regime=regime)
        # q̂(0) (psi counted from tau = 0) with its derivatives: the one-time kernel's chart at tau = 0.
        start = _compiled_motion.working_motion(
            sorted_inertia, unit_working, regime, jnp.zeros_like(regime, record.dtype)
        )
        return consts, start[1]
    consts = constants(sorted_inertia, unit_working, regime)
    return consts, regime_reference(consts, unit_working)


def _evaluate(consts, tau, attitude=True):
    """``_regimes.evaluate`` of the data of ``_working_constants``."""
    if "record" not in consts:
        return evaluate(consts, tau, attitude)
    return _compiled_motion.series_motion(
        consts["record"], consts["inertia"], consts["unit_momentum"], consts["regime"], tau, attitude
    )


@keyed_by_path
def _construct(inertia, angular_momentum, attitude, axes=None):
    """The fields of a FreeRigidBody (see its docstring) from validated inputs, as one jitted program:
    one compiled kernel (``_construct_compiled``) where the motion's kernels are selected."""
    if _compiled_motion.selected(_working_dtype(inertia, angular_momentum)):
        return _construct_compiled(inertia, angular_momentum, attitude, axes)
    (inertia, angular_momentum, attitude, valid, permutation, sorted_inertia, unit_working, norm, regime) = _prepare(
        inertia, angular_momentum, attitude, axes
    )
    dtype = inertia.dtype
    consts, reference = _working_constants(sorted_inertia, unit_working, regime)

    # q(t) = q0 ⊗ P ⊗ conj(q̂(0)) ⊗ q̂(|L| t) ⊗ conj(P)  (docs/theory.md §8, "Matching the
    # initial state", with the phase folded into q̂; P is the working frame as a quaternion).
    frame_rotation = quaternion.from_matrix(permutation)
    offset = quaternion.multiply(quaternion.multiply(attitude, frame_rotation), quaternion.conjugate(reference))
    # p -> offset ⊗ p ⊗ conj(P) is linear in p: one 4 x 4 matrix per body, columns the images of
    # the unit quaternions, so that each evaluation costs 16 products instead of two Hamilton
    # products.
    unit = jnp.broadcast_to(jnp.eye(4, dtype=dtype), (*offset.shape[:-1], 4, 4))
    columns = quaternion.multiply(
        quaternion.multiply(offset[..., None, :], unit), quaternion.conjugate(frame_rotation)[..., None, :]
    )
    attitude_map = jnp.swapaxes(columns, -1, -2)

    return dict(
        inertia=inertia,
        initial_angular_momentum=angular_momentum,
        initial_attitude=attitude,
        # An invalid body has norm 0 here (its L is NaN), so it is classified UNIFORM and its outputs
        # come from the NaN inputs; its |L| is reported as NaN too.
        momentum_norm=jnp.where(valid, norm, jnp.nan),
        permutation=permutation,
        regime=regime,
        principal_axes=None if axes is None else jnp.where(valid[..., None, None], axes, jnp.nan),
        _constants=consts,
        _attitude_map=attitude_map,
    )


def _validated(inertia, angular_momentum, attitude, axes):
    """The inputs in the working dtype, broadcast and checked: (inertia, L0, q0 (not normalised), axes,
    valid).  Invalid values (possible only under tracing; _validate rejects concrete ones): every
    per-body input becomes NaN, and with it every output of that body (class docstring)."""
    dtype = _working_dtype(inertia, angular_momentum)
    inertia, angular_momentum, attitude = (jnp.asarray(a, dtype) for a in (inertia, angular_momentum, attitude))
    shapes = [inertia.shape[:-1], angular_momentum.shape[:-1], attitude.shape[:-1]]
    if axes is not None:
        axes = axes.astype(dtype)
        shapes.append(axes.shape[:-2])
    batch = jnp.broadcast_shapes(*shapes)
    inertia = jnp.broadcast_to(inertia, batch + (3,))
    angular_momentum = jnp.broadcast_to(angular_momentum, batch + (3,))
    attitude = jnp.broadcast_to(attitude, batch + (4,))
    valid = (
        jnp.all((inertia > 0) & jnp.isfinite(inertia), axis=-1)
        & jnp.all(jnp.isfinite(angular_momentum), axis=-1)
        & jnp.all(jnp.isfinite(attitude), axis=-1)
        & jnp.any(attitude != 0, axis=-1)
    )
    if axes is not None:
        axes = jnp.broadcast_to(axes, batch + (3, 3))
        valid = valid & jnp.all(jnp.isfinite(axes), axis=(-2, -1))
    inertia, angular_momentum, attitude = (
        jnp.where(valid[..., None], a, jnp.nan) for a in (inertia, angular_momentum, attitude)
    )
    return inertia, angular_momentum, attitude, axes, valid


def _construct_compiled(inertia, angular_momentum, attitude, axes):
    """``_construct``'s fields from one compiled kernel (csrc/body.hpp): the checks, the working frame,
    the regime, the series record and the attitude map of each body, whose evaluations are then one
    kernel each (``_compiled_motion.body_state``).  The fields the user sees and differentiates (the
    moments, L0, unit q0, |L|, the axes and the working axes in the body frame) carry their tangents
    here; the record's do not: the evaluations' derivatives are the flow kernels' (``flow_state``)."""
    inertia, angular_momentum, attitude, axes, valid = _validated(inertia, angular_momentum, attitude, axes)
    record = _compiled_motion.body_record(inertia, angular_momentum, attitude, axes)
    at_norm, at_regime, at_permutation, at_map, at_principal = _compiled_motion.body_offsets(record.dtype)
    batch = record.shape[:-1]
    unit_attitude = attitude / jnp.sqrt(sum_last(attitude * attitude))[..., None]
    # |L| as recorded, with the tangent of sqrt(L . L) (safe-where at L = 0).
    squared = sum_last(angular_momentum * angular_momentum)
    moving = squared > 0
    size = jnp.where(moving, jnp.sqrt(jnp.where(moving, squared, 1)), 0)
    norm = record[..., at_norm] + (size - jax.lax.stop_gradient(size))
    permutation = record[..., at_permutation : at_permutation + 9].reshape(batch + (3, 3))
    if axes is not None:
        # R P: the working axes turn with the principal axes.
        principal_permutation = record[..., at_principal : at_principal + 9].reshape(batch + (3, 3))
        turned = matrix_product(axes, principal_permutation)
        permutation = permutation + (turned - jax.lax.stop_gradient(turned))
    return dict(
        inertia=inertia,
        initial_angular_momentum=angular_momentum,
        initial_attitude=unit_attitude,
        momentum_norm=norm,
        permutation=permutation,
        regime=record[..., at_regime].astype(jnp.int32),
        principal_axes=None if axes is None else jnp.where(valid[..., None, None], axes, jnp.nan),
        _constants=dict(body=record),
        _attitude_map=record[..., at_map : at_map + 16].reshape(batch + (4, 4)),
    )


def _uniform_momentum(uniform, inertia, axes, momentum, t):
    """L0 where the body rotates uniformly, with the derivatives of the motion (``_uniform``)."""
    shape = jnp.broadcast_shapes(uniform.shape, jnp.shape(t)) + (3,)

    def with_uniform(momentum):
        return uniform_momentum(inertia, momentum, t, axes)

    # Most batches have no uniformly rotating body: then its derivative rule is not evaluated at all.
    return when_any(uniform, with_uniform, lambda momentum: jnp.broadcast_to(momentum, shape), momentum)


def _uniform_attitude(uniform, inertia, axes, momentum, attitude, t, moving):
    """``moving`` where the body does not rotate uniformly, q0 ⊗ exp(t Omega0 / 2) where it does,
    with the derivatives of the motion (``_uniform``)."""

    def with_uniform(moving):
        time = jnp.broadcast_to(t, uniform.shape)
        spin = uniform_spin(inertia, momentum, time, axes)
        return jnp.where(uniform[..., None], quaternion.multiply(attitude, spin), moving)

    return when_any(uniform, with_uniform, lambda moving: moving, moving)


def _working_motion_once(sorted_inertia, unit_working, regime, tau, with_attitude):
    """(unit L(tau), q̂(0), q̂(tau)) in the working frame: the JAX formulas (``_regimes``), or the
    compiled kernel (``_compiled_motion``) where it is selected (the CPU's default: see its docstring)."""
    if _compiled_motion.selected(sorted_inertia):
        return _compiled_motion.working_motion(sorted_inertia, unit_working, regime, tau, with_attitude)
    orbit = orbit_constants(sorted_inertia, unit_working, regime)
    return evaluate_once(orbit, unit_working, tau, with_attitude)


def _motion_once(inertia, angular_momentum, attitude, t, with_attitude=True, axes=None):
    """(L(t), q(t)) (q None unless ``with_attitude``) of bodies evaluated at one time each.

    The one-time path (``_regimes.evaluate_once``): the per-body constants are elementwise formulas,
    the motion one Jacobi evaluation, one R_J and an arctangent, and no theta series.  ``t`` must
    broadcast to the bodies' batch shape without adding dimensions.  ``axes``: principal axes in the
    body frame (``_prepare``), or None.
    """
    (inertia, angular_momentum, attitude, _, permutation, sorted_inertia, unit_working, norm, regime) = _prepare(
        inertia, angular_momentum, attitude, axes
    )
    # Materialised (see _fusion): the working frame and the regime are cheap elementwise values, so
    # XLA would fuse them into every later loop and recompute there the sort of the moments and the
    # classification's comparisons, once per output element; over a batch that was a quarter of this
    # path's cost.  (The constructor stores them: it needs no such boundary.)
    permutation, sorted_inertia, unit_working, norm, regime = materialise(
        (permutation, sorted_inertia, unit_working, norm, regime)
    )
    t = jnp.asarray(t, inertia.dtype)
    tau = norm * t
    unit_momentum, chart_start, chart_now = _working_motion_once(
        sorted_inertia, unit_working, regime, tau, with_attitude
    )
    uniform = regime == UNIFORM
    moving = norm[..., None] * _apply(permutation, unit_momentum)
    axes = None if axes is None else jnp.broadcast_to(axes, inertia.shape + (3,))
    fixed = _uniform_momentum(uniform, inertia, axes, angular_momentum, t)
    momentum = jnp.where(uniform[..., None], fixed, moving)
    if not with_attitude:
        return momentum, None
    # q = q0 ⊗ P ⊗ conj(q̂(0)) ⊗ q̂(tau) ⊗ conj(P) (docs/theory.md §8), where P ⊗ (w, v) ⊗ conj(P) =
    # (w, P v): the working-frame rotation conj(q̂(0)) ⊗ q̂(tau) with its axis taken to body axes.
    # Materialised: each component of a product would otherwise recompute its factors (see _fusion).
    change = materialise(quaternion.multiply(quaternion.conjugate(chart_start), chart_now))
    change = jnp.concatenate([change[..., :1], _apply(permutation, change[..., 1:])], -1)
    moving = _normalised(materialise(quaternion.multiply(attitude, change)))
    return momentum, _uniform_attitude(uniform, inertia, axes, angular_momentum, attitude, t, moving)


def _once_inputs(inertia, angular_momentum, attitude, t, axes):
    """(inertia, axes, L0, unit q0, t) of ``motion_once``'s bodies, validated and broadcast."""
    inertia, angular_momentum, attitude = _prepare(inertia, angular_momentum, attitude, axes)[:3]
    axes = None if axes is None else jnp.broadcast_to(axes, inertia.shape + (3,))
    return inertia, axes, angular_momentum, attitude, jnp.asarray(t, inertia.dtype)


def _once_precessing(inertia, angular_momentum, attitude, t, axes):
    prepared = _prepare(inertia, angular_momentum, attitude, axes)
    axes = None if axes is None else jnp.broadcast_to(axes, prepared[0].shape + (3,))
    return precessing(prepared[0], axes, prepared[1], prepared[-1] == UNIFORM)


# A symmetric body next to the plane of its equal moments keeps the values of the elliptic formulas and
# takes the derivatives of its regular precession's expansion (frbjax._precession).
_state_at_one_time = with_precession_derivatives(
    lambda inertia, momentum, attitude, t, axes: _motion_once(inertia, momentum, attitude, t, True, axes),
    "state",
    _once_precessing,
    _once_inputs,
)
_momentum_at_one_time = with_precession_derivatives(
    lambda inertia, momentum, attitude, t, axes: _motion_once(inertia, momentum, attitude, t, False, axes),
    "momentum alone",
    _once_precessing,
    _once_inputs,
)


def motion_once(inertia, angular_momentum, attitude, t, with_attitude=True, axes=None):
    """``_motion_once`` with the derivatives of ``_precession`` for the bodies next to the plane of
    their equal moments."""
    motion = _state_at_one_time if with_attitude else _momentum_at_one_time
    return motion(inertia, angular_momentum, attitude, t, axes)


def flow_state(inertia, axes, angular_momentum, attitude, t, series=False):
    """(L(t), q(t)) in the body frame from the flow kernels (``_compiled_motion.flow``), arguments of one
    batch, differentiable (the kernels' first and second derivatives, ``motion_once``'s conventions).

    With principal ``axes`` (columns, a rotation, in the body frame; None: the body axes are principal)
    through the principal frame (docs/theory.md §12): L_p = R^T L0, with components of rounding size
    made zeros in value as ``_prepare`` makes them (so that the kernel sees the same uniform rotations),
    q_p = q0 ⊗ r, and L(t) = R L_p(t), q(t) = q_p(t) ⊗ conj(r) (r: R as a quaternion).  The turn of
    the axes enters the derivatives through these products.

    ``series``: the first derivatives from the body's series (``_compiled_motion.series_flow``), for a
    FreeRigidBody's evaluations, whose arguments come with each body's points consecutive.
    """
    if axes is not None:
        principal = to_principal(axes, angular_momentum)
        size = jax.lax.stop_gradient(jnp.sqrt(sum_last(principal * principal)))[..., None]
        rounding = _FRAME_ROUNDING * jnp.finfo(principal.dtype).eps * size
        angular_momentum = jnp.where(
            jnp.abs(principal) <= rounding, principal - jax.lax.stop_gradient(principal), principal
        )
        rotation = quaternion.from_matrix(axes)
        attitude = quaternion.multiply(attitude, rotation)
    flow = _compiled_motion.series_flow if series else _compiled_motion.flow
    state = flow(inertia, angular_momentum, attitude, t)
    momentum, attitude = state[..., :3], state[..., 3:]
    if axes is None:
        return momentum, attitude
    return to_body(axes, momentum), quaternion.multiply(attitude, quaternion.conjugate(rotation))


def _bodies_first(body_batch, batch):
    """(first, back, times per body) for arrays of ``batch`` (+ trailing axes) whose bodies have the
    batch shape ``body_batch`` (broadcast against ``batch``): ``first(a, trailing)`` broadcasts ``a``
    to the batch and moves the axes along which the bodies differ before those along which they are
    broadcast, so that each body's points are consecutive (the kernel then builds a body's series
    record once for all its times); ``back(a)`` restores the batch's order of a result (..., k)."""
    order, bodies = _compiled_motion.bodies_first(body_batch, batch)
    restore = _compiled_motion.inverse_order(order)
    identity = order == tuple(range(len(batch)))

    def first(a, trailing):
        a = jnp.broadcast_to(a, batch + jnp.shape(a)[jnp.ndim(a) - trailing :])
        return a if identity else jnp.transpose(a, order + tuple(range(len(batch), len(batch) + trailing)))

    def back(a):
        return a if identity else jnp.transpose(a, restore + (len(batch),))

    return first, back, math.prod(batch) // max(bodies, 1)  # the points per body


def _with_flow_jacobian(method, outputs):
    """``method(body, t)`` with the derivatives of the flow kernels (``flow_state``) in the body's
    moments, principal axes, initial L and unit initial attitude and in t: every field of a body is a
    function of those, and its motion at t is ``motion_once``'s, so the JVP is the kernels' matrix of
    partial derivatives times their tangents (the derived fields' tangents are not needed, and JAX
    drops their computation).  The first derivatives come from the body's series on dual numbers (one
    record per body for all its times: ``_compiled_motion.series_flow``), the second ones from the
    one-time kernel."""
    wrapped = jax.custom_jvp(method)

    def rule(primals, tangents):
        body, t = primals
        d_body, d_t = tangents
        # The value through the rule itself, so that derivatives of this rule (second ones) see its
        # derivatives: the method's own values come from kernels without any.
        value = wrapped(body, t)
        batch = jax.tree.leaves(value)[0].shape[:-1]

        first, back, times_per_body = _bodies_first(body.inertia.shape[:-1], batch)

        def state(inertia, axes, momentum, attitude, t):
            axes = None if axes is None else first(axes, 2)
            inertia, momentum, attitude = (first(a, 1) for a in (inertia, momentum, attitude))
            # A body's record pays off from a few times on (measured: a record and one point 6.2 us
            # against the one-time kernel's 4.3 us; 1.6 us a point at ten times).
            series = times_per_body > 1
            momentum, attitude = flow_state(inertia, axes, momentum, attitude, first(t, 0), series=series)
            momentum, attitude = back(momentum), back(attitude)
            return {"momentum": momentum, "attitude": attitude, "state": (momentum, attitude)}[outputs]

        fields = ("inertia", "principal_axes", "initial_angular_momentum", "initial_attitude")
        _, tangent = jvp_of_moved(
            state,
            tuple(getattr(body, name) for name in fields) + (jnp.asarray(t, body.inertia.dtype),),
            tuple(getattr(d_body, name) for name in fields) + (d_t,),
        )
        return value, tangent

    wrapped.defjvp(rule, symbolic_zeros=True)
    return lambda body, t: wrapped(body, t)


def _series_inputs(body, t):
    return (
        body.inertia,
        body.principal_axes,
        body.initial_angular_momentum,
        body.initial_attitude,
        jnp.asarray(t, body.inertia.dtype),
    )


def _series_precessing(body, t):
    return body._precessing()


def _motion_derivatives(outputs):
    """The derivatives of a FreeRigidBody's evaluations through its series: where the compiled kernels
    are selected, those of the flow kernels (``flow_state``); elsewhere the JAX composite's with
    ``with_precession_derivatives`` (the same conventions)."""

    def decorate(method):
        with_precession = with_precession_derivatives(method, outputs, _series_precessing, _series_inputs)
        with_kernel = _with_flow_jacobian(method, outputs)

        @functools.wraps(method)
        def evaluate(body, t):
            if _kernel_derivatives(body):
                return with_kernel(body, t)
            return with_precession(body, t)

        return evaluate

    return decorate


def _compiled(method):
    """A method of (body, t) as one jitted program, cached by the shapes and dtypes of both and by the
    kernels' path (``_kernel_path``).

    Called eagerly, an evaluation is one dispatch of a compiled program (as equinox's filter_jit and
    diffrax do); inside the caller's jit, vmap or grad it is traced inline like any other function.
    """
    compiled = keyed_by_path(method)

    @functools.wraps(method)
    def call(self, t):
        if on_host(t):
            check_finite("t", real_array("t", t))
        return compiled(self, jnp.asarray(t))

    return call


class FreeRigidBody(eqx.Module):
    r"""Exact torque-free motion of a rigid body (Euler's equations and the attitude), batched.

    ``FreeRigidBody(inertia, angular_momentum, attitude=None)``

    - ``inertia``: (..., 3) principal moments of inertia, any order, all > 0; or an
      `InertiaTensor` (the tensor in the body frame: see ``from_inertia_tensor``);
    - ``angular_momentum``: (..., 3) body-frame angular momentum $L$ at $t = 0$, any magnitude (0 too);
    - ``attitude``: (..., 4) unit quaternion (w, x, y, z), Hamilton convention, body to space, at
      $t = 0$ (None: the identity); a non-unit quaternion is normalised.

    Leading dimensions of the inputs and of ``t`` broadcast together (numpy rules).  The body solves

    $$\dot L = L \times \Omega, \qquad \dot R = R\,\hat\Omega, \qquad \Omega = I^{-1} L$$

    exactly: $L$ through Jacobi elliptic functions,
    the attitude through the elliptic integral of the third kind (Celledoni, Fassò, Säfström and Zanna,
    "The exact computation of the free rigid body motion and its use in splitting methods", SIAM J. Sci.
    Comput. 30 (2008); derivation in docs/theory.md).

    Which path an evaluation takes follows what has been paid for, not the shape of ``t``: the
    constructor always prepares each body's series (regime, phase, the theta series of the Jacobi
    functions and of the third-kind integral, the particular solution at the phase), and every method
    evaluates through them, at any ``t`` (a scalar for the whole batch, one time per body, a times
    axis, inside ``jax.vmap`` or ``lax.map`` over rows of times).  Bodies that are evaluated once
    and never again (the state at a final time, one step of a splitting method) should not pay for
    the series: `free_flow` is that one-shot entry point (docs/theory.md §11).

    Invalid inputs: wrong trailing shapes or leading shapes that do not broadcast raise ValueError,
    always (shapes are static, under jit too).  With concrete inputs (not JAX tracers) the values are
    checked as well: a moment of inertia that is <= 0 or not finite, a non-finite angular momentum,
    a zero or non-finite attitude, entries that are not real numbers, and non-finite times ``t`` of
    the methods (read where they are on the host) raise ValueError naming the argument and its first
    offending entry.  Under jax.jit, vmap or
    grad the values are unknown at construction and cannot be checked: a body with any such invalid
    value instead has NaN in all its per-body data (the stored inertia, initial angular momentum,
    initial attitude and momentum_norm included), so that every output for that body (angular
    momentum, angular velocity, quaternion, rotation matrix, at every time) is NaN, never a plausible
    finite number.  The other bodies of a batch are not affected.

    Derivatives: every output is differentiable with respect to ``inertia``, ``angular_momentum``,
    ``attitude`` and ``t``, in forward and reverse mode and at any order (``jax.hessian`` too, also
    under ``jax.vmap``), and every derivative is finite.  Where the motion has no derivative, or
    changes formula, the derivatives are those of the formula taken, i.e. one-sided along it:

    - uniform rotation $q_0 \otimes \exp(\Omega t / 2)$ wherever $\Omega$ is parallel to $L$ ($L = 0$,
      $L$ along a principal axis or in the plane of two equal moments, a sphere): the first derivatives
      in every direction are those of the motion, including those that start a nutation (a transverse
      component of $L$, unequal changes of the moments, a tilt of an inertia tensor's axes): the
      uniform formula's derivative rule is the closed-form solution of the variational equations
      (docs/theory.md §6).  Second derivatives there: in $t$ and mixed with $t$ those of the motion,
      in the other directions those of the first-order rule (without the nutation's second-order
      terms; the attitude's are not exactly symmetric there);
    - the separatrix ($2 E I_2 = |L|^2$ exactly, rounding included): derivatives that keep the body on
      it are exact, the others miss the (finite) change of the elliptic parameter;
    - a symmetric body ($I_1 = I_2$ or $I_2 = I_3$ exactly) whose unit $L$ is within $1/8$ of the plane
      of its equal moments but not in it: the values are the elliptic formulas', the derivatives those
      of its regular precession with its first-order neighbours off the symmetric bodies
      (docs/theory.md §6; the elliptic formulas' derivative in an unequal change of the equal moments
      would lose digits as $10^{-16} / (e \cdot n)^2$, in a change of $e \cdot n$ as
      $10^{-16} / (e \cdot n)$).  Every first derivative there is that of the motion; second
      derivatives too, except the one taken twice in the unequal direction of the equal moments (the
      expansion is linear in it).

    tests/test_gradients_body.py checks all of them against 32-digit (60 next to that plane) references.
    """

    inertia: Float[Array, "... 3"]
    initial_angular_momentum: Float[Array, "... 3"]
    initial_attitude: Float[Array, "... 4"]
    momentum_norm: Float[Array, ...]
    permutation: Float[Array, "... 3 3"]
    regime: Int[Array, ...]
    principal_axes: Float[Array, "... 3 3"] | None
    inertia_tensor: Float[Array, "... 3 3"] | None
    _constants: dict
    _attitude_map: Float[Array, "... 4 4"]

    def __init__(self, inertia, angular_momentum, attitude=None):
        tensor = None
        if isinstance(inertia, InertiaTensor):
            # A body in its own body frame: the motion of its principal frame, turned (docs/theory.md
            # §12).  The fields are those of that motion; the tensor is kept for the derivatives.
            tensor, inertia = inertia, inertia.principal_moments
        _validate(inertia, angular_momentum, attitude)
        inertia = jnp.asarray(inertia)
        angular_momentum = jnp.asarray(angular_momentum)
        if attitude is None:
            # The identity as an array (numpy: no eager operation), so that bodies built with and
            # without an attitude share one compiled constructor.
            attitude = np.zeros(inertia.shape[:-1] + (4,), _working_dtype(inertia, angular_momentum))
            attitude[..., 0] = 1
        attitude = jnp.asarray(attitude)
        # One compiled program (cached by shape and dtype): called eagerly, construction is a single
        # dispatch instead of hundreds of eager operations; under the caller's jit it is inlined.
        axes = None if tensor is None else tensor.principal_axes
        for name, value in _construct(inertia, angular_momentum, attitude, axes).items():
            setattr(self, name, value)
        # The matrix alone (one array: each array argument costs a dispatch): the rule of the
        # derivatives needs its tangent, the moments and axes are the fields above.
        self.inertia_tensor = None if tensor is None else tensor.matrix

    @classmethod
    def from_inertia_tensor(cls, inertia_tensor, angular_momentum, attitude=None) -> FreeRigidBody:
        r"""The body with inertia tensor ``inertia_tensor`` $T$ (..., 3, 3) in its own body frame.

        ``FreeRigidBody.from_inertia_tensor(T, L, q)`` is ``FreeRigidBody(InertiaTensor(T), L, q)``:
        ``angular_momentum`` $L$ (..., 3) and ``attitude`` $q$ (..., 4) (body to space) are those of the
        tensor's body frame, and so are every method's outputs ($\Omega = T^{-1} L$).  ``inertia`` is
        then the principal moments (ascending), ``principal_axes`` their directions (columns, body
        coordinates) and ``inertia_tensor`` the (symmetrised) tensor.  Evaluating costs what a body built
        from principal moments costs: the change of frame is folded into the per-body data.
        Derivatives with respect to every tensor entry are finite and correct, repeated moments
        included (`InertiaTensor`; docs/theory.md §12).
        """
        if is_concrete(inertia_tensor):
            real_array("inertia_tensor", inertia_tensor)
        validate_tensor(jnp.asarray(inertia_tensor), "inertia_tensor")
        return cls(InertiaTensor(inertia_tensor), angular_momentum, attitude)

    # ------------------------------------------------------------------------------------ helpers

    def _time(self, t):
        t = jnp.asarray(t, self.inertia.dtype)
        return t, self.momentum_norm * t  # unit-|L| time, shape broadcast(batch, t.shape)

    def _uniform(self):
        return self.regime == UNIFORM

    def _precessing(self):
        return precessing(self.inertia, self.principal_axes, self.initial_angular_momentum, self._uniform())

    def _momentum_from(self, t, unit_working):
        moving = self.momentum_norm[..., None] * _apply(self.permutation, unit_working)
        fixed = _uniform_momentum(self._uniform(), self.inertia, self.principal_axes, self.initial_angular_momentum, t)
        return jnp.where(self._uniform()[..., None], jnp.broadcast_to(fixed, moving.shape), moving)

    def _attitude_from(self, t, tau, particular):
        # q = offset ⊗ q̂ ⊗ conj(P) (docs/theory.md §8), as one matrix product.
        moving = _apply(self._attitude_map, materialise(particular))
        # Three products and the chart leave |q| - 1 at up to ~20 ulp; renormalising costs little and
        # keeps |q| = 1 and rotation_matrix (which assumes it) at the ulp level.
        moving = _normalised(materialise(moving))
        uniform = jnp.broadcast_to(self._uniform(), tau.shape)
        # Uniform rotation about a principal direction (or L = 0): q(t) = q0 ⊗ exp(t Omega0 / 2).
        return _uniform_attitude(
            uniform, self.inertia, self.principal_axes, self.initial_angular_momentum, self.initial_attitude, t, moving
        )

    def _through_tensor(self, method, t):
        """method(self, t); for a body built from an inertia tensor, its derivatives with respect to
        the tensor taken through the principal frame (``_inertia.through_principal_frame``)."""
        body, t = _common_rank(self, t)
        if body.inertia_tensor is None:
            return method(body, t)
        t = jnp.asarray(t, body.inertia.dtype)

        def motion(moments, axes, arguments):
            momentum, attitude, t = arguments
            return method(_body_of(_construct(moments, momentum, attitude, axes)), t)

        def evaluate(prepared, arguments):
            return method(prepared, arguments[2])

        # The series already built: their own derivatives are not needed (the rule rebuilds along
        # the tangent), and cutting them keeps forward mode from computing them.
        prepared = jax.lax.stop_gradient(
            _body_of(dict((name, getattr(body, name)) for name in _FIELDS if name != "inertia_tensor"))
        )
        return through_principal_frame(
            motion, evaluate, body.inertia_tensor, prepared, (body.initial_angular_momentum, body.initial_attitude, t)
        )

    # A body built by the compiled kernel (``_construct_compiled``) evaluates with one kernel call.

    @_motion_derivatives("momentum")
    def _angular_momentum(self, t):
        if "body" in self._constants:
            return _compiled_motion.body_state(self._constants["body"], t, attitude=False)[0]
        t, tau = self._time(t)
        unit_working, _ = _evaluate(self._constants, tau, attitude=False)
        return self._momentum_from(t, unit_working)

    def _elliptic_quaternion(self, t):
        if "body" in self._constants:
            return _compiled_motion.body_state(self._constants["body"], t)[1]
        t, tau = self._time(t)
        particular, _ = _evaluate(self._constants, tau)
        return self._attitude_from(t, tau, particular)

    def _elliptic_state(self, t):
        if "body" in self._constants:
            return _compiled_motion.body_state(self._constants["body"], t)
        t, tau = self._time(t)
        particular, unit_working = _evaluate(self._constants, tau)
        return self._momentum_from(t, unit_working), self._attitude_from(t, tau, particular)

    _quaternion = _motion_derivatives("attitude")(_elliptic_quaternion)
    _state = _motion_derivatives("state")(_elliptic_state)

    # ------------------------------------------------------------------------------------- public

    @_compiled
    def angular_momentum(self, t) -> Float[Array, "... 3"]:
        """Body-frame angular momentum $L(t)$, shape broadcast(batch, t.shape) + (3,).

        Evaluates only the Jacobi functions: no elliptic integral of the third kind.
        """
        return self._through_tensor(FreeRigidBody._angular_momentum, t)

    @_compiled
    def angular_velocity(self, t) -> Float[Array, "... 3"]:
        r"""Body-frame angular velocity $\Omega(t) = I^{-1} L(t)$ ($L / I$ for principal moments)."""
        return self._through_tensor(
            lambda body, t: angular_velocity(body.inertia, body.principal_axes, body._angular_momentum(t)), t
        )

    @_compiled
    def quaternion(self, t) -> Float[Array, "... 4"]:
        """Attitude $q(t)$ (w, x, y, z), body to space, continuous in $t$; $q(0)$ is the given attitude."""
        return self._through_tensor(FreeRigidBody._quaternion, t)

    @_compiled
    def state(self, t) -> tuple[Float[Array, "... 3"], Float[Array, "... 4"]]:
        """(angular_momentum(t), quaternion(t)) from one evaluation of the motion.

        The same values as the two methods (bit for bit), at the cost of ``quaternion`` alone: the
        Jacobi functions that give the attitude give L too.
        """
        return self._through_tensor(FreeRigidBody._state, t)

    @_compiled
    def rotation_matrix(self, t) -> Float[Array, "... 3 3"]:
        r"""Attitude matrix $R(t)$ with $x_\text{space} = R\, x_\text{body}$ ($\dot R = R\,\hat\Omega$)."""
        return quaternion.as_matrix(self.quaternion(t))


_FIELDS = tuple(field.name for field in dataclasses.fields(FreeRigidBody))


def _common_rank(body, t):
    """The body and the times with leading unit axes added to whichever has the fewer batch axes: the
    motion then broadcasts the body's batch against ``t`` explicitly, without rank promotion (every
    array of a body has its batch axes first)."""
    extra = jnp.ndim(t) - body.momentum_norm.ndim
    if extra > 0:
        body = jax.tree.map(lambda leaf: jnp.reshape(leaf, (1,) * extra + jnp.shape(leaf)), body)
    elif extra < 0:
        t = jnp.reshape(t, (1,) * -extra + jnp.shape(t))
    return body, t


def _body_of(fields):
    """A FreeRigidBody with the given fields (those of ``_construct``; no inertia tensor unless given),
    without the constructor's checks: for bodies built inside derivative rules and the fit."""
    body = object.__new__(FreeRigidBody)
    for name in _FIELDS:
        object.__setattr__(body, name, fields.get(name))
    return body


def _kernel_derivatives(body) -> bool:
    """Whether a body's evaluations take the flow kernels' derivatives (``_motion_derivatives``)."""
    return _compiled_motion.selected(body.inertia)


def state_with_elliptic_derivatives(body, t):
    """``body.state(t)`` (bodies without an inertia tensor) for the fits: where the flow kernels give
    the derivatives (bodies of principal moments on the CPU), those of ``body.state``, one custom call
    whatever the body; elsewhere those of the elliptic formulas everywhere: a symmetric body next to
    the plane of its equal moments does not take the expansion of its regular precession
    (``_precession``).

    The fits' parameters are continuous, so an iterate is an exactly symmetric body with probability
    zero, and the two derivatives agree everywhere else, bit for bit.  On such a body they are finite
    and differ by 1.3e-13 at unit L 0.02 off that plane, 9e-5 at 1e-6 (entries of order 1;
    tests/test_fit.py), which a Levenberg-Marquardt step does not mind.  In JAX the expansion's rule
    is a conditional that the model's forward-mode Jacobian compiles in full whether or not a body
    takes it: without it ``fit_attitude``'s first call took about a sixth less time.
    """
    body, t = _common_rank(body, jnp.asarray(t, body.inertia.dtype))
    return body._state(t) if _kernel_derivatives(body) else body._elliptic_state(t)


def quaternion_with_elliptic_derivatives(body, t):
    """``body.quaternion(t)`` with the derivatives of ``state_with_elliptic_derivatives``."""
    body, t = _common_rank(body, jnp.asarray(t, body.inertia.dtype))
    return body._quaternion(t) if _kernel_derivatives(body) else body._elliptic_quaternion(t)


def with_principal_axes(inertia, angular_momentum, attitude, axes):
    """The body with principal moments ``inertia`` along ``axes`` (columns, a rotation, in the body
    frame), differentiable in all four directly (the fit's parameterisation; no inertia tensor)."""
    return _body_of(_construct(inertia, angular_momentum, attitude, axes))
