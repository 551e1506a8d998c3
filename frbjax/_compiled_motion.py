"""The motion as compiled CPU kernels: the working-frame motion at one time per point
(``csrc/motion.hpp``), a body's theta series (``csrc/series.hpp``), the whole free flow of one body at
one time (``csrc/free_flow.hpp``), a ``FreeRigidBody``'s record and its state (``csrc/body.hpp``), and
the flow's partial derivatives (``csrc/flow_jacobian.hpp``).

The first is the compiled form of ``_regimes.orbit_constants`` followed by ``_regimes.evaluate_once``:
the same formulas (docs/theory.md §4, §5, §11), per point in C++ with early exits instead of
elementwise selections, so that XLA compiles one custom call instead of the regimes' hundreds of
fused loops.  It also evaluates the motion on dual numbers, which gives the partial derivatives of
its 11 outputs in its 7 inputs (J1, J2, J3, l1, l2, l3, tau; order 1) and their second ones (order 2)
from the same code: those of the formula taken.  The JAX composite around it (``_body.motion_once``,
with the conventions of ``_uniform`` and ``_precession`` in JAX) is the path of
``FRBJAX_MOTION_KERNEL=jax`` for the rest of the motion and the tests' reference.

On the CPU's default path every derivative of the motion is the flow kernels' (``flow``): the
7 x 11 first and 7 x 11 x 11 second partial derivatives of (L(t), q(t)) in the moments, L0, q0 and t,
with those conventions computed in C++, so that a JVP is a product of a matrix with the tangents
(linear in them: reverse mode transposes it) and no derivative rule of the JAX composite is compiled.
"""

from __future__ import annotations

import functools
import math
import os

import jax
import jax.numpy as jnp
from jax.custom_derivatives import SymbolicZero
from jax.experimental.custom_partitioning import custom_partitioning
from jax.sharding import NamedSharding, PartitionSpec

from .special import _compiled


_SWITCH = "FRBJAX_MOTION_KERNEL"
_INPUTS = 7
_ALL_OUTPUTS = 11  # L (3), q̂(0) (4), q̂(tau) (4)


def _width(order):
    return (1, 1 + _INPUTS, 1 + _INPUTS + _INPUTS * _INPUTS)[order]


def _call(order, attitude, columns, regime):
    """The kernel on broadcast columns (7 arrays of one shape) and the regime: (..., outputs, width)."""
    if _compiled._module() is None:  # registers the handlers on first use
        raise RuntimeError("frbjax's compiled kernels are not available (see frbjax.special._compiled)")
    outputs = _ALL_OUTPUTS if attitude else 3
    shape = columns[0].shape
    result = jax.ShapeDtypeStruct(shape + (outputs * _width(order),), columns[0].dtype)
    name = f"frbjax_{'motion' if attitude else 'momentum'}_{order}"
    out = jax.ffi.ffi_call(name, result, vmap_method="broadcast_all")(*columns, regime)
    return out.reshape(shape + (outputs, _width(order)))


def _direction(primals, tangents):
    """The tangents of (J1, J2, J3, l1, l2, l3, tau) stacked on a last axis (the regime has none)."""
    return jnp.stack([jnp.broadcast_to(t, c.shape) for c, t in zip(primals[:_INPUTS], tangents[:_INPUTS])], axis=-1)


def _kernel(attitude):
    def kernel(order, arguments):
        *columns, regime = arguments
        return _call(order, attitude, columns, regime)

    return _compiled.differentiable(kernel, _INPUTS, _direction)


_motion, _with_jacobian_motion = _kernel(True)
_momentum, _ = _kernel(False)


def working_motion(inertia, unit_momentum, regime, tau, attitude=True):
    """(unit L(tau), q̂(0), q̂(tau)) in the working frame (``_regimes.evaluate_once``'s results), or
    (unit L(tau), None, None) without ``attitude``; sorted ``inertia`` and ``unit_momentum`` (..., 3),
    ``regime`` and ``tau`` (...) broadcast together."""
    batch = jnp.broadcast_shapes(inertia.shape[:-1], unit_momentum.shape[:-1], jnp.shape(regime), jnp.shape(tau))
    columns = [jnp.broadcast_to(inertia[..., k], batch) for k in range(3)]
    columns += [jnp.broadcast_to(unit_momentum[..., k], batch) for k in range(3)]
    columns.append(jnp.broadcast_to(jnp.asarray(tau, inertia.dtype), batch))
    regime = jnp.broadcast_to(regime, batch).astype(jnp.int32)
    if not attitude:
        return _momentum(*columns, regime), None, None
    out = _motion(*columns, regime)
    return out[..., :3], out[..., 3:7], out[..., 7:]


def selected(inertia) -> bool:
    """Whether the compiled kernels evaluate the motion of bodies of ``inertia``'s dtype (an array or a
    dtype): wherever the special functions' kernels are selected (``FRBJAX_KERNELS``), unless
    ``FRBJAX_MOTION_KERNEL=jax`` keeps the JAX formulas for the motion alone.

    Where the CPU has FMA instructions the kernel fuses the motion's products and sums as XLA:CPU
    fuses the JAX path's (csrc/motion.hpp): unfused, its long time-reversal error was 3.3 eps |L| t
    against the JAX path's 1.4 (tests/test_body_invariants.py allows 3.0); fused, 1.0.
    """
    choice = os.environ.get(_SWITCH, "compiled")
    if choice not in ("compiled", "jax"):
        raise ValueError(f"{_SWITCH} must be 'compiled' or 'jax', got {choice!r}")
    return choice == "compiled" and _compiled.selected(inertia)


def free_flow(inertia, angular_momentum, attitude, t):
    """(L(t), q(t)) of bodies with principal moments, one kernel for the whole flow (csrc/free_flow.hpp):
    the values of ``_body._motion_once(inertia, angular_momentum, attitude, t)`` (axes None), the
    checks, working frame, regime, uniform rotation and quaternion products included.  ``inertia``,
    ``angular_momentum`` (..., 3), ``attitude`` (..., 4) and ``t`` (...) broadcast together, of one
    float dtype.  Values only: ``frbjax._free_flow`` gives it the composite's derivatives."""
    if _compiled._module() is None:
        raise RuntimeError("frbjax's compiled kernels are not available (see frbjax.special._compiled)")
    batch = jnp.broadcast_shapes(inertia.shape[:-1], angular_momentum.shape[:-1], attitude.shape[:-1], jnp.shape(t))
    dtype = inertia.dtype
    arguments = (
        jnp.broadcast_to(inertia, batch + (3,)),
        jnp.broadcast_to(angular_momentum.astype(dtype), batch + (3,)),
        jnp.broadcast_to(attitude.astype(dtype), batch + (4,)),
        jnp.broadcast_to(jnp.asarray(t, dtype), batch),
    )
    results = (jax.ShapeDtypeStruct(batch + (3,), dtype), jax.ShapeDtypeStruct(batch + (4,), dtype))
    return jax.ffi.ffi_call("frbjax_free_flow", results, vmap_method="broadcast_all")(*arguments)


def flow_direction(tangents, batch, dtype):
    """The tangents of (moments, L0, q0, t) (symbolic zeros allowed) stacked as one (batch, 11) array,
    the order of the flow kernels' partial derivatives."""
    zero = jnp.zeros((), dtype)
    *vectors, time = (zero if isinstance(tangent, SymbolicZero) else tangent for tangent in tangents)
    vectors = [jnp.broadcast_to(vector, batch + (size,)) for vector, size in zip(vectors, (3, 3, 4))]
    return jnp.concatenate(vectors + [jnp.broadcast_to(jnp.asarray(time)[..., None], batch + (1,))], -1)


def _flow_kernel(order, arguments, series=False):
    """The free flow's values (order 0: csrc/free_flow.hpp) or values and partial derivatives (orders 1
    and 2: csrc/flow_jacobian.hpp) of bodies with principal moments, as (..., 7, width).

    ``series``: a FreeRigidBody's evaluations, whose order-1 kernel takes the body's series
    (``series_flow_derivatives``: one record of dual numbers per body, kept over the body's
    consecutive points); orders 0 and 2 are the one-time motion's either way (the same function)."""
    inertia, angular_momentum, attitude, t = arguments
    if order == 0:
        return jnp.concatenate(free_flow(inertia, angular_momentum, attitude, t), -1)[..., None]
    if _compiled._module() is None:
        raise RuntimeError("frbjax's compiled kernels are not available (see frbjax.special._compiled)")
    width = 1 + _FLOW_INPUTS + (_FLOW_INPUTS**2 if order == 2 else 0)
    result = jax.ShapeDtypeStruct(t.shape + (7, width), inertia.dtype)
    name = "frbjax_free_flow_series_1" if series and order == 1 else f"frbjax_free_flow_{order}"
    return jax.ffi.ffi_call(name, result, vmap_method="broadcast_all")(*arguments)


_FLOW_INPUTS = 11  # moments (3), L0 (3), q0 (4), t
# (state, with_jacobian) of arguments (inertia, L0, q0 (..., 3, 3, 4), t (...)) of one batch: the state
# (L(t), q(t)) as (..., 7) with the kernels' derivatives (``_compiled.differentiable``: first from the
# order-1 kernel, second from the order-2 one, linear in the tangents), and (values, partials (..., 7, 11)),
# with ``_body.motion_once``'s derivative conventions at uniform rotations and at symmetric bodies next
# to the plane of their equal moments.
flow, flow_with_jacobian = _compiled.differentiable(
    _flow_kernel,
    _FLOW_INPUTS,
    lambda primals, tangents: flow_direction(tangents, primals[3].shape, primals[0].dtype),
)


_series_flow_kernel = functools.partial(_flow_kernel, series=True)


# ``flow`` for a FreeRigidBody's evaluations (``_body._with_flow_jacobian``): its arguments with each
# body's points consecutive, so that a body's series record is built once for all its times.
series_flow, _ = _compiled.differentiable(
    _series_flow_kernel,
    _FLOW_INPUTS,
    lambda primals, tangents: flow_direction(tangents, primals[3].shape, primals[0].dtype),
)


def free_flow_frame(inertia, angular_momentum):
    """The kernel's working frame per body, for the tests: (sorted inertia, unit working L, |L|,
    regime), to compare bit for bit with ``_body._prepare``'s."""
    if _compiled._module() is None:
        raise RuntimeError("frbjax's compiled kernels are not available (see frbjax.special._compiled)")
    batch = jnp.broadcast_shapes(inertia.shape[:-1], angular_momentum.shape[:-1])
    inertia, angular_momentum = (jnp.broadcast_to(a, batch + (3,)) for a in (inertia, angular_momentum))
    result = jax.ShapeDtypeStruct(batch + (8,), inertia.dtype)
    out = jax.ffi.ffi_call("frbjax_free_flow_frame", result, vmap_method="broadcast_all")(inertia, angular_momentum)
    return out[..., 2:5], out[..., 5:8], out[..., 1], out[..., 0].astype(jnp.int32)


# -------------------------------------------------------------------------------------- the series


def series_selected(inertia) -> bool:
    """Whether a ``FreeRigidBody`` of ``inertia``'s dtype builds and evaluates its theta series with the
    compiled kernels (csrc/series.hpp): wherever the special functions' kernels are selected
    (``FRBJAX_KERNELS``).  Its values are the JAX series' to rounding (the same formulas); its
    derivatives are those of the same function (the charts count psi from tau = 0 on both): the
    first ones from the series on dual numbers (``series_flow``), the second ones the one-time
    kernel's."""
    return _compiled.selected(inertia)


def record_size(dtype) -> int:
    """The length of a body's series record (csrc/series.hpp's SeriesLayout): 32 + 4 x terms."""
    return 32 + 4 * (8 if jnp.dtype(dtype) == jnp.float64 else 5)


def series_record(inertia, unit_momentum, regime):
    """Each body's series record (values; its derivatives are taken through ``series_motion``)."""
    if _compiled._module() is None:
        raise RuntimeError("frbjax's compiled kernels are not available (see frbjax.special._compiled)")
    inertia, unit_momentum = jax.lax.stop_gradient((inertia, unit_momentum))
    batch = jnp.broadcast_shapes(inertia.shape[:-1], unit_momentum.shape[:-1], jnp.shape(regime))
    columns = [jnp.broadcast_to(inertia[..., k], batch) for k in range(3)]
    columns += [jnp.broadcast_to(unit_momentum[..., k], batch) for k in range(3)]
    result = jax.ShapeDtypeStruct(batch + (record_size(inertia.dtype),), inertia.dtype)
    regime = jnp.broadcast_to(regime, batch).astype(jnp.int32)
    return jax.ffi.ffi_call("frbjax_series_record", result, vmap_method="broadcast_all")(*columns, regime)


def body_record_size(dtype) -> int:
    """The length of a body's record (csrc/body.hpp's BodyLayout): the series record and 52 more."""
    return record_size(dtype) + 52


def body_record(inertia, angular_momentum, attitude, axes=None):
    """Each body's record (csrc/body.hpp; values: the derivatives are the flow kernels'): moments,
    L0 (..., 3) and q0 (..., 4) in the body frame and its principal axes (..., 3, 3) or None, of one
    batch and dtype.  ``body_offsets`` gives where its fields start."""
    if _compiled._module() is None:
        raise RuntimeError("frbjax's compiled kernels are not available (see frbjax.special._compiled)")
    arguments = [inertia, angular_momentum, attitude] + ([] if axes is None else [axes])
    arguments = jax.lax.stop_gradient(arguments)
    result = jax.ShapeDtypeStruct(inertia.shape[:-1] + (body_record_size(inertia.dtype),), inertia.dtype)
    return jax.ffi.ffi_call("frbjax_body_record", result, vmap_method="broadcast_all")(*arguments)


def body_offsets(dtype):
    """Offsets in a body's record (csrc/body.hpp's BodyLayout): |L| (NaN for an invalid body), the
    regime, the working axes in body coordinates (3 x 3), the attitude map (4 x 4) and the working
    axes in principal coordinates (3 x 3)."""
    start = record_size(dtype)
    return start, start + 1, start + 2, start + 11, start + 43


def _body_state_call(records, t):
    return jax.ffi.ffi_call("frbjax_body_state", jax.ShapeDtypeStruct(t.shape + (7,), records.dtype))(records, t)


def _body_momentum_call(records, t):
    return jax.ffi.ffi_call("frbjax_body_momentum", jax.ShapeDtypeStruct(t.shape + (3,), records.dtype))(records, t)


def _over_bodies(mesh, arg_shapes):
    """Shardings of (records, t, result) with the bodies' axis split as ``t``'s leading axis is."""
    spec = tuple(arg_shapes[1].sharding.spec)
    leading = spec[0] if spec else None
    t_spec = (leading,) + (None,) * (len(arg_shapes[1].shape) - 1)
    return (
        NamedSharding(mesh, PartitionSpec(leading, None)),
        NamedSharding(mesh, PartitionSpec(*t_spec)),
        NamedSharding(mesh, PartitionSpec(*t_spec, None)),
    )


def _partitioned(attitude):
    """The evaluation kernel split over devices along the bodies (``shard_bodies``: each device
    evaluates its own bodies), and under ``vmap`` one call over the mapped and the bodies' axes."""
    kernel = _body_state_call if attitude else _body_momentum_call
    call = custom_partitioning(kernel)

    def partition(mesh, arg_shapes, result_shape):
        records, t, result = _over_bodies(mesh, arg_shapes)
        return mesh, kernel, result, (records, t)

    call.def_partition(
        partition=partition,
        infer_sharding_from_operands=lambda mesh, arg_shapes, result_shape: _over_bodies(mesh, arg_shapes)[2],
        sharding_rule="b s, b t -> b t o",
    )

    @jax.custom_batching.custom_vmap
    def evaluate(records, t):
        return call(records, t)

    @evaluate.def_vmap
    def _(axis_size, in_batched, records, t):
        records, t = (
            value if batched else jnp.broadcast_to(value, (axis_size,) + value.shape)
            for value, batched in zip((records, t), in_batched)
        )
        # Each mapped row's bodies after the previous row's: the bodies' axis absorbs the mapped one.
        out = evaluate(records.reshape((-1, records.shape[-1])), t.reshape((-1,) + t.shape[2:]))
        return out.reshape(t.shape + out.shape[-1:]), True

    return evaluate


_body_state_kernels = {True: _partitioned(True), False: _partitioned(False)}


def body_state(record, t, attitude=True):
    """(L(t), q(t)) in the body frame from the bodies' records at times ``t`` (values), or (L(t), None)
    without ``attitude``; ``t`` broadcasts against the records' batch."""
    batch = jnp.broadcast_shapes(record.shape[:-1], jnp.shape(t))
    t = jax.lax.stop_gradient(jnp.broadcast_to(jnp.asarray(t, record.dtype), batch))
    records, order = _records_by_body(jax.lax.stop_gradient(record), batch)
    # (bodies, times per body): the kernel's layout (each body's times contiguous).
    t = jnp.transpose(t, order)
    times = t.reshape((records.shape[0], -1)) if t.size else t.reshape((0, 1))
    out = _body_state_kernels[attitude](records, times).reshape(t.shape + ((7 if attitude else 3),))
    out = jnp.transpose(out, inverse_order(order) + (len(batch),))
    return (out[..., :3], out[..., 3:]) if attitude else (out, None)


def _series_kernel(attitude):
    outputs = 7 if attitude else 3
    rows = list(range(3)) + (list(range(7, 11)) if attitude else [])

    @jax.custom_jvp
    def motion(record, *arguments):
        # record: (bodies, size), each body's points contiguous in the batch (``_records_by_body``).
        *columns, regime = arguments
        shape = columns[0].shape
        result = jax.ShapeDtypeStruct(shape + (outputs,), columns[0].dtype)
        name = "frbjax_series_motion" if attitude else "frbjax_series_momentum"
        return jax.ffi.ffi_call(name, result, vmap_method="broadcast_all")(record, columns[-1])

    @motion.defjvp
    def motion_jvp(primals, tangents):
        # The series and the one-time kernel compute one function (the charts count psi from tau = 0):
        # its derivatives are the one-time kernel's, in (J, l, tau); the record is a function of (J, l).
        record, *arguments = primals
        value = motion(record, *arguments)
        _, jacobian = _with_jacobian_motion(*arguments)
        direction = _direction(arguments, tangents[1:])
        return value, jnp.sum(jacobian[..., rows, :] * direction[..., None, :], axis=-1)

    return motion


_series_motion = _series_kernel(True)
_series_momentum = _series_kernel(False)


def bodies_first(body_batch, batch):
    """(order, bodies): the order of ``batch``'s axes that puts the axes along which bodies of batch
    shape ``body_batch`` (broadcast against ``batch``) differ before those along which they are
    broadcast, and the number of bodies.  The kernels take each body's points contiguous, so that
    bodies (N,) at times (K, N) are N bodies of K points each (not K x N bodies of one point)."""
    shape = (1,) * (len(batch) - len(body_batch)) + tuple(body_batch)
    bodies = tuple(k for k, n in enumerate(shape) if n != 1)
    order = bodies + tuple(k for k in range(len(batch)) if k not in bodies)
    return order, math.prod(batch[k] for k in bodies)


def inverse_order(order):
    """The permutation that undoes ``order`` (a transpose's axes)."""
    return tuple(sorted(range(len(order)), key=order.__getitem__))


def _records_by_body(record, batch):
    """The records as (bodies, size), each body's points contiguous in ``batch`` transposed to the
    order of ``bodies_first`` (returned with them)."""
    order, bodies = bodies_first(record.shape[:-1], batch)
    shape = (1,) * (len(batch) - (record.ndim - 1)) + record.shape[:-1]
    record = jnp.transpose(record.reshape(shape + record.shape[-1:]), order + (len(batch),))
    return record.reshape((bodies, record.shape[-1])), order


def series_motion(record, inertia, unit_momentum, regime, tau, attitude=True):
    """(q̂(tau), unit L(tau)) from the bodies' records, or (unit L(tau), None) without ``attitude``."""
    batch = jnp.broadcast_shapes(record.shape[:-1], inertia.shape[:-1], jnp.shape(regime), jnp.shape(tau))
    columns = [jnp.broadcast_to(inertia[..., k], batch) for k in range(3)]
    columns += [jnp.broadcast_to(unit_momentum[..., k], batch) for k in range(3)]
    columns.append(jnp.broadcast_to(jnp.asarray(tau, inertia.dtype), batch))
    regime = jnp.broadcast_to(regime, batch).astype(jnp.int32)
    record, order = _records_by_body(jax.lax.stop_gradient(record), batch)
    columns, regime = [jnp.transpose(column, order) for column in columns], jnp.transpose(regime, order)
    back = inverse_order(order) + (len(batch),)
    if not attitude:
        return jnp.transpose(_series_momentum(record, *columns, regime), back), None
    out = jnp.transpose(_series_motion(record, *columns, regime), back)
    return out[..., 3:], out[..., :3]
