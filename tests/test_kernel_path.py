"""A change of ``FRBJAX_KERNELS`` or ``FRBJAX_MOTION_KERNEL`` takes effect at the next call of every
compiled program of the library (frbjax/_kernel_path.py).

The path is chosen when a function is traced; jax.jit caches a program by its arguments' types, so a
program traced under one setting was reused after the variable changed: a body built on the kernels
then built the same way under ``FRBJAX_KERNELS=jax``, and the batched bodies of
test_body_invariants.py evaluated on the JAX path's programs after test_fusion.py had switched it.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from frbjax import _compiled_motion, free_flow, FreeRigidBody
from frbjax._cpu_options import cpu_jit
from frbjax._kernel_path import keyed_by_path
from frbjax._trace_once import traced_once


def _on_kernels(x):
    """1 where the function was traced with the motion's kernels selected, else 0."""
    return jnp.zeros_like(x) + float(_compiled_motion.selected(x))


WRAPPERS = {
    "keyed_by_path": keyed_by_path(_on_kernels),
    "keyed_by_path(filter_jit)": keyed_by_path(_on_kernels, jit=eqx.filter_jit),
    "cpu_jit": cpu_jit(_on_kernels),
    "traced_once": traced_once(_on_kernels),
}


@pytest.mark.parametrize("name", list(WRAPPERS))
def test_each_compiled_program_follows_the_variables(name, monkeypatch):
    program, x = WRAPPERS[name], jnp.ones(2)
    monkeypatch.delenv("FRBJAX_KERNELS", raising=False)
    monkeypatch.delenv("FRBJAX_MOTION_KERNEL", raising=False)
    assert float(program(x)[0]) == 1.0
    monkeypatch.setenv("FRBJAX_KERNELS", "jax")
    assert float(program(x)[0]) == 0.0
    monkeypatch.delenv("FRBJAX_KERNELS")
    monkeypatch.setenv("FRBJAX_MOTION_KERNEL", "jax")
    assert float(program(x)[0]) == 0.0
    monkeypatch.delenv("FRBJAX_MOTION_KERNEL")
    assert float(program(x)[0]) == 1.0


def _kernel_calls(function, *args, name="frbjax_"):
    """How many calls of the library's compiled kernels (``name``: those whose names begin so) the
    program of ``function`` makes.  Traced through a new function object: a caller's own jit of the same
    function would reuse its first trace (a caller's program is traced once, when it is compiled)."""
    return jax.jit(lambda *a: function(*a)).lower(*args).as_text().count(f"custom_call @{name}")


INERTIA, MOMENTUM = jnp.array([1.0, 1.7, 2.9]), jnp.array([0.3, -0.8, 0.5])


def test_a_body_is_built_and_evaluated_on_the_path_of_the_call(monkeypatch):
    """Eager calls, alternating the path: the constructor's record (the kernels' ``body``) and the
    methods' programs follow the variable, bodies of the same shapes as before."""
    monkeypatch.delenv("FRBJAX_KERNELS", raising=False)
    body = FreeRigidBody(INERTIA, MOMENTUM)
    assert "body" in body._constants
    kernel_momentum = body.angular_momentum(3.7)

    monkeypatch.setenv("FRBJAX_KERNELS", "jax")
    body = FreeRigidBody(INERTIA, MOMENTUM)
    assert "body" not in body._constants
    jax_momentum = body.angular_momentum(3.7)
    np.testing.assert_allclose(jax_momentum, kernel_momentum, rtol=0, atol=1e-15)

    # A JAX-built body evaluates its JAX series on either path; its derivatives are the flow kernels'
    # where they are selected (``_body._kernel_derivatives``), decided when the method is traced.
    def derivative(t):
        return jax.jacfwd(body.angular_momentum)(t)

    derivative(3.7)
    assert _kernel_calls(derivative, 3.7) == 0
    monkeypatch.delenv("FRBJAX_KERNELS")
    derivative(3.7)
    assert _kernel_calls(derivative, 3.7) > 0


def test_free_flow_follows_the_variables(monkeypatch):
    monkeypatch.delenv("FRBJAX_KERNELS", raising=False)
    monkeypatch.delenv("FRBJAX_MOTION_KERNEL", raising=False)
    attitude, t = jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.asarray(3.7)
    free_flow(INERTIA, MOMENTUM, attitude, t)
    assert _kernel_calls(free_flow, INERTIA, MOMENTUM, attitude, t) > 0
    monkeypatch.setenv("FRBJAX_MOTION_KERNEL", "jax")
    free_flow(INERTIA, MOMENTUM, attitude, t)
    assert _kernel_calls(free_flow, INERTIA, MOMENTUM, attitude, t, name="frbjax_free_flow") == 0
    monkeypatch.setenv("FRBJAX_KERNELS", "jax")
    assert _kernel_calls(free_flow, INERTIA, MOMENTUM, attitude, t) == 0
