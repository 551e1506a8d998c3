"""The exact torque-free flow over one time per body: the state after time t, without a per-body series.

``free_flow`` is the one-shot entry point: the state (L(t), q(t)) of bodies each evaluated at one
time, without the per-body series that a ``FreeRigidBody`` prepares; every free flow of the
splitting integrators (``frbjax._splitting``) goes through it.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from . import _compiled_motion
from ._body import _validate, _working_dtype, flow_state, motion_once
from ._checks import check_finite, on_host, real_array
from ._inertia import InertiaTensor, through_principal_frame
from ._kernel_path import keyed_by_path


def _state_in_principal_frame(inertia, angular_momentum, attitude, t, axes):
    """``motion_once`` of a body with principal ``axes``: through the flow kernels where they are
    selected (``_body.flow_state``: one custom call and its derivatives' matrices), else the composite."""
    dtype = _working_dtype(inertia, angular_momentum)
    if _compiled_motion.selected(dtype):
        arguments = (a.astype(dtype) for a in (inertia, axes, angular_momentum, attitude, t))
        return flow_state(*arguments)
    return motion_once(inertia, angular_momentum, attitude, t, True, axes)


@keyed_by_path
def _tensor_free_flow(matrix, moments, axes, angular_momentum, attitude, t):
    batch = jnp.broadcast_shapes(moments.shape[:-1], angular_momentum.shape[:-1], attitude.shape[:-1], t.shape)
    moments = jnp.broadcast_to(moments, batch + (3,))
    axes = jnp.broadcast_to(axes, batch + (3, 3))
    matrix = jnp.broadcast_to(matrix, batch + (3, 3))
    arguments = (
        jnp.broadcast_to(angular_momentum, batch + (3,)),
        jnp.broadcast_to(attitude, batch + (4,)),
        jnp.broadcast_to(t, batch),
    )

    def motion(moments, axes, arguments):
        return _state_in_principal_frame(moments, *arguments, axes)

    def evaluate(prepared, arguments):
        return _state_in_principal_frame(prepared[0], *arguments, prepared[1])

    prepared = jax.lax.stop_gradient((moments, axes))
    return through_principal_frame(motion, evaluate, matrix, prepared, arguments)


def _compiled_state(inertia, angular_momentum, attitude, t):
    """``motion_once``'s (L(t), q(t)) from one compiled kernel (csrc/free_flow.hpp), its derivatives
    those of ``motion_once`` itself.

    On the CPU the composite runs the working-frame kernel and around it some 150 small XLA kernels
    (the checks, the working frame, the classification, the uniform rotation, the quaternion
    products); here the whole flow is one custom call, which is what a splitting method's many
    steps of one body pay for.  The derivatives are the composite's, conventions included (the
    uniform rotation's variational solution, docs/theory.md §6; the regular precession of symmetric
    bodies next to the plane of their equal moments, ``_precession``), from two more kernels
    (csrc/flow_jacobian.hpp): the 7 x 11 partial derivatives in the inputs and their second ones.
    The JVP rule is a product of that matrix with the tangents, linear in them (reverse mode
    transposes it), so that a derivative program compiles a custom call and a contraction instead
    of the composite's derivative program."""
    t = jnp.broadcast_to(t, inertia.shape[:-1])
    state = _compiled_motion.flow(inertia, angular_momentum, attitude, t)
    return state[..., :3], state[..., 3:]


@keyed_by_path
def _free_flow(inertia, angular_momentum, attitude, t):
    batch = jnp.broadcast_shapes(inertia.shape[:-1], angular_momentum.shape[:-1], attitude.shape[:-1], t.shape)
    inertia, angular_momentum = (jnp.broadcast_to(a, batch + (3,)) for a in (inertia, angular_momentum))
    attitude = jnp.broadcast_to(attitude, batch + (4,))
    dtype = _working_dtype(inertia, angular_momentum)
    inertia, angular_momentum, attitude = (a.astype(dtype) for a in (inertia, angular_momentum, attitude))
    if _compiled_motion.selected(inertia):
        return _compiled_state(inertia, angular_momentum, attitude, t)
    return motion_once(inertia, angular_momentum, attitude, t)


def free_flow(inertia, angular_momentum, attitude, t) -> tuple[Float[Array, "... 3"], Float[Array, "... 4"]]:
    r"""$(L(t), q(t))$ of the free bodies with body angular momentum $L$ and attitude $q$ at time 0.

    ``inertia`` (..., 3) (principal moments, any order, > 0) or an `InertiaTensor`
    (then L, q and the results are those of the tensor's body frame), ``angular_momentum`` (..., 3),
    ``attitude`` (..., 4) (w, x, y, z, body to space) and ``t`` (...) broadcast together; every
    element of the broadcast shape is one body at one time.  The values are those of
    ``FreeRigidBody(inertia, angular_momentum, attitude).state(t)`` (to rounding), computed without
    the per-body data that pays off only over many times (docs/theory.md §11): the Jacobi functions at
    the phase $u_0 + B|L|t$ follow from the given $L$ and from sn, cn, dn$(B|L|t)$ by the addition theorem
    (DLMF 22.8.1-22.8.3), and the change of the third-kind integral from one
    $\Pi(n; \mathrm{am}\, v_r|m)$ at the reduced argument and an arctangent (the addition
    theorem of Jacobi's third kind).  Use it for one step of a splitting method or the state at a
    final time; for a body at many times, build a `FreeRigidBody` once.

    Exact in every regime, differentiable in every input (forward and reverse mode, any order),
    jit-compiled once per shape and dtype when called eagerly, and composable with ``jit``, ``vmap``
    and ``grad``.  Invalid inputs raise ValueError as in `FreeRigidBody`, non-finite times ``t``
    too (NaN under tracing).
    """
    if on_host(t):
        check_finite("t", real_array("t", t))
    if isinstance(inertia, InertiaTensor):
        _validate(inertia.principal_moments, angular_momentum, attitude)
        angular_momentum, attitude = jnp.asarray(angular_momentum), jnp.asarray(attitude)
        dtype = _working_dtype(inertia.principal_moments, angular_momentum)
        return _tensor_free_flow(
            inertia.matrix,
            inertia.principal_moments,
            inertia.principal_axes,
            angular_momentum,
            attitude,
            jnp.asarray(t, dtype),
        )
    _validate(inertia, angular_momentum, attitude)
    inertia, angular_momentum, attitude = (jnp.asarray(a) for a in (inertia, angular_momentum, attitude))
    dtype = _working_dtype(inertia, angular_momentum)
    return _free_flow(inertia, angular_momentum, attitude, jnp.asarray(t, dtype))
