"""The two paths agree: the one-shot path (``frbjax.free_flow``, no per-body setup) and a prebuilt
``FreeRigidBody``'s per-body theta series.

Both paths are also checked on their own against the 30-digit references, diffrax and the gradient
references (``tests/_reference.PATHS`` parametrises those tests); here they are compared with each
other on random bodies and on every family of special bodies, values and derivatives.
"""

from __future__ import annotations

import _reference as ref
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_body_invariants import random_bodies, special_bodies


# Measured over 256 random bodies and the special families at 8 times each, |tau| = |L| t up to 100:
# L (relative to |L|) 6.1e-16 max(1, |tau|), q 1.0e-15 max(1, |tau|) with the JAX series (rounding
# grows with the periods), q 1.53e-15 with the compiled series: on the body spinning 2e-10 off its
# intermediate axis at tau = -0.024, where mpmath puts the compiled series 1.5e-15 off and the
# one-shot path 1.1e-16 (the JAX series is 1.8e-15 off on that body at tau = 0.1).
VALUE_TOLERANCE = 1.6e-15
# Derivatives at 24 random bodies, |tau| up to 30, relative to each column: measured 1.3e-13.
DERIVATIVE_TOLERANCE = 2e-13


def _bodies(seed, count):
    rng = np.random.default_rng(seed)
    inertia, momentum, attitude = random_bodies(rng, count)
    rows = [(np.array(i, float), np.array(l, float)) for items in special_bodies().values() for i, l in items]
    inertia = np.concatenate([inertia, np.stack([r[0] for r in rows])])
    momentum = np.concatenate([momentum, np.stack([r[1] for r in rows])])
    attitude = np.concatenate([attitude, ref.random_attitudes(rng, len(rows))])
    return rng, inertia, momentum, attitude


def test_values_agree():
    from frbjax import free_flow, FreeRigidBody

    rng, inertia, momentum, attitude = _bodies(5, 256)
    tau = 10.0 ** rng.uniform(-3, 2, (len(inertia), 8)) * rng.choice([-1.0, 1.0], (len(inertia), 8))
    norm = np.linalg.norm(momentum, axis=-1)
    times = tau / np.where(norm > 0, norm, 1)[:, None]
    series = jax.jit(lambda i, l, q, t: FreeRigidBody(i[:, None], l[:, None], q[:, None]).state(t))
    L_series, q_series = series(inertia, momentum, attitude, times)
    L_once, q_once = free_flow(inertia[:, None], momentum[:, None], attitude[:, None], times)
    assert L_once.shape == L_series.shape and q_once.shape == q_series.shape
    scale = np.where(norm > 0, norm, 1)[:, None]
    allowed = VALUE_TOLERANCE * np.maximum(1, np.abs(tau))
    error_L = np.abs(np.asarray(L_once - L_series)).max(-1) / scale
    error_q = np.abs(np.asarray(q_once - q_series)).max(-1)
    assert (error_L <= allowed).all(), (error_L / allowed).max()
    assert (error_q <= allowed).all(), (error_q / allowed).max()


def test_prebuilt_bodies_evaluate_through_their_series(monkeypatch):
    """The path follows what is paid for: a FreeRigidBody evaluates through its series at any t.

    At one time per body, at a scalar time and under ``jax.vmap`` over rows of times the one-shot path
    is never traced (it raises here), and the values are those at a times axis to rounding (measured
    5.1e-15 relative: the broadcast shapes differ, and with them XLA's vectorisation).
    """
    import frbjax._body
    from frbjax import FreeRigidBody

    def refuse(*args, **kwargs):
        raise AssertionError("the one-shot path was taken by a prebuilt body")

    monkeypatch.setattr(frbjax._body, "evaluate_once", refuse)
    rng, inertia, momentum, attitude = _bodies(6, 64)
    times = rng.uniform(-20, 20, (5, len(inertia)))
    body = FreeRigidBody(inertia, momentum, attitude)
    # One jitted function for every shape of t (a program per shape, traced under the patch above).
    state = jax.jit(lambda b, t: b.state(t))
    # t of shape (5, N): every body at five times, a times axis in front of the batch.
    L_axis, q_axis = state(body, times)
    rows = [state(body, row) for row in times]
    L_mapped, q_mapped = jax.jit(jax.vmap(lambda b, t: b.state(t), in_axes=(None, 0)))(body, times)
    L_scalar, q_scalar = state(body, times[0, 0])
    L_scalar_axis, q_scalar_axis = state(body, np.full((1, 1), times[0, 0]))
    L_rows, q_rows = np.stack([row[0] for row in rows]), np.stack([row[1] for row in rows])
    scale = np.maximum(np.linalg.norm(momentum, axis=-1), 1)[:, None]
    for L, q, L_want, q_want in (
        (L_rows, q_rows, L_axis, q_axis),
        (L_mapped, q_mapped, L_axis, q_axis),
        (L_scalar, q_scalar, L_scalar_axis[0], q_scalar_axis[0]),
    ):
        assert L.shape == L_want.shape and q.shape == q_want.shape
        assert (np.abs(np.asarray(L - L_want)) / scale).max() <= 1e-14
        assert np.abs(np.asarray(q - q_want)).max() <= 1e-14
    assert body.quaternion(times).shape == times.shape + (4,)


def _state(x, series):
    from frbjax import free_flow, FreeRigidBody

    if series:
        momentum, attitude = (v[0] for v in FreeRigidBody(x[:3], x[3:6], x[6:10]).state(x[10:]))
    else:
        momentum, attitude = free_flow(x[:3], x[3:6], x[6:10], x[10])
    return jnp.concatenate([momentum, attitude])


@pytest.fixture(scope="module")
def derivative_points():
    """24 random bodies (|tau| up to 30) and the special families: rows of x = (I, L, q0, t)."""
    rng, inertia, momentum, attitude = _bodies(6, 24)
    tau = 10.0 ** rng.uniform(-2, 1.5, len(inertia)) * rng.choice([-1.0, 1.0], len(inertia))
    norm = np.linalg.norm(momentum, axis=-1)
    return np.concatenate([inertia, momentum, attitude, (tau / np.where(norm > 0, norm, 1))[:, None]], -1)


# Each path's Jacobian is one jitted program (20 to 30 s of compilation on CPU), computed once for the
# module and shared by the tests below, so that no test pays for both.
@pytest.fixture(scope="module")
def jacobian_once(derivative_points):
    return np.asarray(jax.jit(jax.vmap(jax.jacfwd(lambda x: _state(x, False))))(derivative_points))


@pytest.fixture(scope="module")
def jacobian_series(derivative_points):
    return np.asarray(jax.jit(jax.vmap(jax.jacfwd(lambda x: _state(x, True))))(derivative_points))


def test_derivatives_of_the_one_shot_path_are_finite(jacobian_once):
    """Finite at every point, the special bodies (spheres, principal axes, the separatrix) included:
    their one-sided derivatives are conventions (test_gradients_body), so only finiteness is asked."""
    assert np.isfinite(jacobian_once).all()


def test_derivatives_of_the_series_are_finite(jacobian_series):
    """As for the one-shot path, on the prebuilt body's series."""
    assert np.isfinite(jacobian_series).all()


def test_derivatives_agree(jacobian_once, jacobian_series):
    """Generic bodies: the same Jacobian from both paths."""
    once, series = jacobian_once[:24], jacobian_series[:24]
    scale = np.maximum(np.abs(series).max(1, keepdims=True), 1)
    error = np.abs(once - series) / scale
    assert error.max() <= DERIVATIVE_TOLERANCE, error.max()


def test_free_flow_checks_and_broadcasts():
    from frbjax import free_flow

    with pytest.raises(ValueError, match="inertia"):
        free_flow([1.0, -2.0, 3.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], 1.0)
    momentum, attitude = free_flow(
        np.array([1.0, 2.0, 3.0]), np.array([0.3, 0.2, 0.9]), np.array([1.0, 0.0, 0.0, 0.0]), np.linspace(0, 1, 5)
    )
    assert momentum.shape == (5, 3) and attitude.shape == (5, 4)
    # At t = 0 the given state, to rounding (measured 1.2e-16).
    np.testing.assert_allclose(np.asarray(momentum[0]), [0.3, 0.2, 0.9], rtol=0, atol=2.5e-16)
    np.testing.assert_allclose(np.asarray(attitude[0]), [1.0, 0.0, 0.0, 0.0], rtol=0, atol=2.5e-16)
