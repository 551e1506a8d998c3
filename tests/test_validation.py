"""FreeRigidBody input validation: eager ValueErrors naming the argument, NaN outputs under jit.

Concrete inputs are checked when the body is built: moments of inertia finite and > 0, angular
momentum finite, attitude finite and non-zero, trailing shapes (..., 3), (..., 3), (..., 4) and
leading shapes that broadcast.  Under tracing (jit, vmap) only the shapes can be checked; a body with
invalid values then has NaN outputs (all of them, at every time), and the other bodies of the batch
are unaffected.
"""

from __future__ import annotations

import functools

import _reference as ref
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from frbjax import FreeRigidBody


INERTIA = (1.0, 2.0, 3.0)
MOMENTUM = (0.3, -0.5, 0.8)
ATTITUDE = (0.5, -0.5, 0.5, 0.5)
NAN, INF = float("nan"), float("inf")

# --------------------------------------------------------------------------------------------------
# Eager value checks.

INVALID_VALUES = [
    # (argument, inertia, angular momentum, attitude)
    ("inertia", (0.0, 2.0, 3.0), MOMENTUM, ATTITUDE),
    ("inertia", (1.0, -2.0, 3.0), MOMENTUM, ATTITUDE),
    ("inertia", (-1.0, -2.0, -3.0), MOMENTUM, ATTITUDE),
    ("inertia", (-1.0, -1.0, -1.0), MOMENTUM, ATTITUDE),
    ("inertia", (1.0, NAN, 3.0), MOMENTUM, ATTITUDE),
    ("inertia", (1.0, 2.0, INF), MOMENTUM, ATTITUDE),
    ("inertia", (1.0, 2.0, -INF), MOMENTUM, ATTITUDE),
    ("angular_momentum", INERTIA, (0.3, NAN, 0.8), ATTITUDE),
    ("angular_momentum", INERTIA, (INF, 0.0, 0.0), ATTITUDE),
    ("angular_momentum", INERTIA, (0.0, 0.0, -INF), ATTITUDE),
    ("attitude", INERTIA, MOMENTUM, (0.0, 0.0, 0.0, 0.0)),
    ("attitude", INERTIA, MOMENTUM, (NAN, 0.0, 0.0, 0.0)),
    ("attitude", INERTIA, MOMENTUM, (1.0, 0.0, INF, 0.0)),
]


@pytest.mark.parametrize("argument, inertia, momentum, attitude", INVALID_VALUES)
def test_invalid_value_raises(argument, inertia, momentum, attitude):
    with pytest.raises(ValueError, match=argument):
        FreeRigidBody(np.array(inertia), np.array(momentum), np.array(attitude))


@pytest.mark.parametrize("kind", ["list", "numpy", "jax"])
def test_invalid_value_in_a_batch_raises(kind):
    """One bad body among valid ones is enough; inputs as lists, numpy or (concrete) jax arrays."""
    inertia = np.array([INERTIA, INERTIA, (1.0, 0.0, 1.0)])
    convert = dict(list=lambda a: a.tolist(), numpy=lambda a: a, jax=jnp.asarray)[kind]
    with pytest.raises(ValueError, match="inertia"):
        FreeRigidBody(convert(inertia), convert(np.array([MOMENTUM] * 3)))
    attitude = np.array([ATTITUDE, (0.0, 0.0, 0.0, 0.0)])
    with pytest.raises(ValueError, match="attitude"):
        FreeRigidBody(convert(np.array(INERTIA)), convert(np.array(MOMENTUM)), convert(attitude))


def test_zero_attitude_component_is_not_an_error():
    """Only the whole quaternion being zero is an error; any non-zero one is normalised."""
    body = FreeRigidBody(np.array(INERTIA), np.array(MOMENTUM), np.array([0.0, 0.0, 0.0, 1e-3]))
    np.testing.assert_array_equal(np.asarray(body.initial_attitude), [0.0, 0.0, 0.0, 1.0])


def test_valid_edge_values_are_accepted():
    """Zero angular momentum, a sphere, huge and tiny positive moments are all valid."""
    FreeRigidBody(np.array([1.0, 1.0, 1.0]), np.zeros(3))
    FreeRigidBody(np.array([1e-300, 1.0, 1e300]), np.array(MOMENTUM), np.array([2.0, 0.0, 0.0, 0.0]))


# --------------------------------------------------------------------------------------------------
# Shapes (checked eagerly and under jit).

INVALID_SHAPES = [
    # (message fragment, inertia shape, angular momentum shape, attitude shape or None)
    ("inertia", (4,), (3,), None),
    ("inertia", (), (3,), None),
    ("inertia", (3, 2), (3,), None),
    ("angular_momentum", (3,), (4,), None),
    ("angular_momentum", (5, 3), (3, 5), None),
    ("attitude", (3,), (3,), (3,)),
    ("attitude", (2, 3), (2, 3), (2, 3)),
    ("attitude", (3,), (3,), ()),
    # Leading shapes that do not broadcast: the message names every argument with its shape.
    ("inertia \\(2, 3\\), angular_momentum \\(3, 3\\)", (2, 3), (3, 3), None),
    ("attitude \\(4, 4\\)", (5, 3), (5, 3), (4, 4)),
    ("angular_momentum \\(2, 5, 3\\)", (5, 1, 3), (2, 5, 3), (3, 5, 4)),
]


def _arrays(inertia_shape, momentum_shape, attitude_shape):
    inertia = np.ones(inertia_shape) * 2.0
    momentum = np.ones(momentum_shape)
    attitude = None if attitude_shape is None else np.ones(attitude_shape)
    return inertia, momentum, attitude


@pytest.mark.parametrize("message, inertia_shape, momentum_shape, attitude_shape", INVALID_SHAPES)
def test_invalid_shape_raises(message, inertia_shape, momentum_shape, attitude_shape):
    inertia, momentum, attitude = _arrays(inertia_shape, momentum_shape, attitude_shape)
    with pytest.raises(ValueError, match=message):
        FreeRigidBody(inertia, momentum, attitude)


@pytest.mark.parametrize("message, inertia_shape, momentum_shape, attitude_shape", INVALID_SHAPES)
def test_invalid_shape_raises_under_jit(message, inertia_shape, momentum_shape, attitude_shape):
    """The shape errors are raised while tracing (nothing is compiled)."""
    inertia, momentum, attitude = _arrays(inertia_shape, momentum_shape, attitude_shape)
    if attitude is None:
        build = jax.jit(lambda i, l: FreeRigidBody(i, l).momentum_norm)
        arguments = (inertia, momentum)
    else:
        build = jax.jit(lambda i, l, q: FreeRigidBody(i, l, q).momentum_norm)
        arguments = (inertia, momentum, attitude)
    with pytest.raises(ValueError, match=message):
        build(*arguments)


def test_broadcasting_shapes_are_accepted():
    body = FreeRigidBody(np.ones((5, 1, 3)) * 2.0, np.ones((2, 3)), np.ones((1, 4)))
    assert body.momentum_norm.shape == (5, 2)


# --------------------------------------------------------------------------------------------------
# Under tracing: NaN outputs for the invalid bodies, the valid ones untouched.

# Each row: (inertia, angular momentum, attitude).  The first rows are valid bodies of every regime
# (generic, symmetric, sphere, principal axis, L = 0); the rest are invalid.
VALID_ROWS = [
    (INERTIA, MOMENTUM, ATTITUDE),
    ((1.0, 1.0, 2.0), (0.3, -0.5, 0.8), (1.0, 0.0, 0.0, 0.0)),
    ((1.5, 1.5, 1.5), (0.3, -0.5, 0.8), (0.1, 0.2, -0.3, 0.4)),
    ((2.0, 0.8, 1.3), (0.0, -3.0, 0.0), ATTITUDE),
    ((1.0, 3.0, 6.0), (0.0, 0.0, 0.0), ATTITUDE),
]
INVALID_ROWS = [row[1:] for row in INVALID_VALUES] + [
    # Invalid inertia together with L along an axis, or L = 0 (the uniform-rotation path).
    ((-1.0, -2.0, -3.0), (0.0, 0.0, 1.0), ATTITUDE),
    ((0.0, 1.0, 1.0), (0.0, 0.0, 0.0), ATTITUDE),
    ((-2.0, -2.0, -2.0), (1.0, 0.0, 0.0), ATTITUDE),
    ((1.0, 1.0, 1.0), (NAN, 0.0, 0.0), ATTITUDE),
    ((1.0, 2.0, 3.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0)),
]
TIMES = np.array([-3.0, 0.0, 1e-3, 2.5, 100.0])
OUTPUTS = ("angular_momentum", "angular_velocity", "quaternion", "rotation_matrix")


def _evaluate(inertia, momentum, attitude, times):
    body = FreeRigidBody(inertia[:, None], momentum[:, None], attitude[:, None])
    return tuple(getattr(body, name)(times) for name in OUTPUTS) + (body.momentum_norm,)


@functools.cache
def traced_outputs():
    """The batch of VALID_ROWS + INVALID_ROWS evaluated eagerly (valid rows only) and under jit."""
    rows = VALID_ROWS + INVALID_ROWS
    inertia, momentum, attitude = (np.array([r[k] for r in rows], float) for k in range(3))
    jitted = [np.asarray(v) for v in jax.jit(_evaluate)(inertia, momentum, attitude, TIMES)]
    count = len(VALID_ROWS)
    eager = [np.asarray(v) for v in _evaluate(inertia[:count], momentum[:count], attitude[:count], TIMES)]
    return jitted, eager, count


@pytest.mark.parametrize("index", range(len(OUTPUTS) + 1))
def test_invalid_bodies_give_nan_under_jit(index):
    jitted, _, count = traced_outputs()
    invalid = jitted[index][count:]
    name = (OUTPUTS + ("momentum_norm",))[index]
    rows = [i for i in range(len(invalid)) if not np.isnan(invalid[i]).all()]
    assert not rows, f"{name}: not all NaN for invalid rows {[INVALID_ROWS[i] for i in rows]}"


# jit compiles the same operations, fused differently, so the two differ by rounding, which grows with
# the phase: compared with eps (1 + |L| |t| / min I) (times max(1, |L|) for L, max(1, |L|) / min I
# for Omega), the measured worst ratios are 1.0 (L), 0.75 (Omega), 1.0 (q), 2.0 (R); tolerances ~2x.
JIT_RATIO = dict(angular_momentum=2.0, angular_velocity=1.5, quaternion=2.0, rotation_matrix=4.0)


def test_valid_bodies_unaffected_under_jit():
    """The valid bodies of the batch are finite and equal to their eager values (up to JIT_RATIO)."""
    jitted, eager, count = traced_outputs()
    inertia = np.array([r[0] for r in VALID_ROWS], float)
    norm = np.linalg.norm(np.array([r[1] for r in VALID_ROWS], float), axis=-1)[:, None]
    phase = np.finfo(float).eps * (1 + norm * np.abs(TIMES)[None] / inertia.min(-1)[:, None])
    magnitude = dict(
        angular_momentum=np.maximum(1, norm), angular_velocity=np.maximum(1, norm) / inertia.min(-1)[:, None]
    )
    for name, got, want in zip(OUTPUTS, jitted, eager):
        assert np.isfinite(got[:count]).all(), name
        difference = np.abs(got[:count] - want).reshape(count, len(TIMES), -1).max(-1)
        ratio = difference / (phase * magnitude.get(name, 1.0))
        assert ratio.max() <= JIT_RATIO[name], (name, ratio.max())
    # |L| is computed once per body, the same way: bit for bit equal.
    np.testing.assert_array_equal(jitted[-1][:count], eager[-1])


def test_invalid_bodies_give_nan_under_vmap():
    """vmap (op by op, the harness of tests/_reference.py) also traces: NaN, not an error."""
    rows = [VALID_ROWS[0]] + INVALID_ROWS
    inertia, momentum, attitude = (np.array([r[k] for r in rows], float) for k in range(3))
    times = np.tile(TIMES, (len(rows), 1))
    L, q = ref.evaluate(inertia, momentum, attitude, times)
    assert np.isfinite(L[0]).all() and np.isfinite(q[0]).all()
    assert np.isnan(L[1:]).all(axis=-1).all()
    assert np.isnan(q[1:]).all(axis=-1).all()
