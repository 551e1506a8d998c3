"""One-kernel regions (frbjax._kernel): which program ran, and that both programs agree.

One body's free flow and one body's splitting trajectory are compiled as one kernel where the
backend supports it, and as XLA's ordinary kernels otherwise (``FRBJAX_ONE_KERNEL=0``, a batch, or a
region holding an operation without a single-kernel emitter).  Both give the same values to rounding.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from frbjax import _kernel

INERTIA = np.array([1.0, 2.0, 3.0])
MOMENTUM = np.array([0.3, 1.0, 0.2])
ATTITUDE = np.array([0.9, 0.1, -0.3, 0.2]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2])


def _one_body_program(*args):
    from frbjax._free_flow import _state_once

    return jax.jit(lambda *a: _state_once(*a)).lower(*args).compile()


def _has_region(compiled_text):
    """Whether a program holds a one-kernel region: a call carrying both of frbjax's attributes.

    ``xla_cpu_small_call`` alone is not enough: XLA puts it on the small while loops it hoists itself
    (the rolled iterations of one body)."""
    return 'inlineable="false"' in compiled_text and "xla_cpu_small_call" in compiled_text


def _switch_off(monkeypatch):
    """FRBJAX_ONE_KERNEL=0 is read when a program is traced: JAX's caches of traces are cleared."""
    monkeypatch.setenv("FRBJAX_ONE_KERNEL", "0")
    jax.clear_caches()


@pytest.fixture(autouse=True)
def _fresh_traces():
    yield
    jax.clear_caches()


def _one_body_args(batch=()):
    return tuple(jnp.asarray(np.broadcast_to(a, batch + a.shape)) for a in (INERTIA, MOMENTUM, ATTITUDE)) + (
        jnp.full(batch, 3.7),)


def test_the_backend_says_which_program_runs(monkeypatch):
    """On CPU with this JAX the region is compiled (the probe), and switched off by the environment."""
    if jax.default_backend() != "cpu":
        assert not _kernel.available()
    args = _one_body_args()
    region = _has_region(_one_body_program(*args).as_text())
    assert region == (_kernel.available() and _kernel.enabled())
    if jax.default_backend() == "cpu":
        # jax 0.10.2 on CPU: the probe compiles, so a one-body free flow is one kernel.
        assert _kernel.available() and region
    _switch_off(monkeypatch)
    assert not _kernel.enabled()
    assert not _has_region(_one_body_program(*args).as_text())


def test_a_batch_is_not_a_region():
    args = _one_body_args((_kernel.MAX_ELEMENTS,))
    assert not _has_region(_one_body_program(*args).as_text())


def test_both_programs_agree(monkeypatch):
    """Values to rounding and derivatives of the one-body free flow, with and without the region.

    Measured: 2.2e-16 in the state, 4.4e-16 relative in the Jacobian."""
    from frbjax._free_flow import _state_once

    def state(x):
        momentum, attitude = _state_once(x[:3], x[3:6], x[6:10], x[10])
        return jnp.concatenate([momentum, attitude])

    x = jnp.concatenate([*_one_body_args()[:3], jnp.asarray([3.7])])
    one_kernel = (jax.jit(state)(x), jax.jit(jax.jacrev(state))(x), jax.jit(jax.jacfwd(state))(x))
    _switch_off(monkeypatch)
    ordinary = (jax.jit(state)(x), jax.jit(jax.jacrev(state))(x), jax.jit(jax.jacfwd(state))(x))
    np.testing.assert_allclose(one_kernel[0], ordinary[0], rtol=0, atol=1e-15)
    for got, want in zip(one_kernel[1:], ordinary[1:]):
        assert np.isfinite(got).all()
        np.testing.assert_allclose(got, want, rtol=0, atol=2e-15 * np.abs(want).max())


def test_operations_without_a_single_kernel_emitter_fall_back():
    """A sort (XLA:CPU calls its runtime) inside a region: the ordinary program, the right values."""
    sorted_twice = _kernel.one_kernel(lambda x: 2 * jnp.sort(x))
    x = jnp.asarray([3.0, 1.0, 2.0])
    program = jax.jit(sorted_twice).lower(x).compile()
    assert not _has_region(program.as_text())
    np.testing.assert_array_equal(program(x), [2.0, 4.0, 6.0])
    roots = _kernel.one_kernel(lambda x: jnp.sqrt(x) + jnp.dot(x[:3], x[:3]))
    assert _has_region(jax.jit(roots).lower(x).compile().as_text()) == _kernel.available()


@pytest.mark.parametrize("one_kernel", [True, False])
def test_splitting_trajectory_either_way(monkeypatch, one_kernel):
    """A heavy top's trajectory of one body, with and without the region: the same states.

    Measured: 2.2e-16 after 50 steps between the two programs."""
    from frbjax import RigidBodyTerm, splitting_trajectory

    if not one_kernel:
        _switch_off(monkeypatch)
    term = RigidBodyTerm(INERTIA, potential=lambda t, q, args: q[0] * q[2] + q[1] * q[3])
    y0 = (jnp.asarray(MOMENTUM), jnp.asarray(ATTITUDE))
    run = jax.jit(lambda y0: splitting_trajectory(term, y0, dt=0.05, steps=50)[1])
    text = run.lower(y0).compile().as_text()
    assert _has_region(text) == (one_kernel and _kernel.available())
    momenta, attitudes = run(y0)
    monkeypatch.setenv("FRBJAX_ONE_KERNEL", "1" if not one_kernel else "0")
    jax.clear_caches()
    other = jax.jit(lambda y0: splitting_trajectory(term, y0, dt=0.05, steps=50)[1])(y0)
    np.testing.assert_allclose(momenta, other[0], rtol=0, atol=1e-14)
    np.testing.assert_allclose(attitudes, other[1], rtol=0, atol=1e-14)
