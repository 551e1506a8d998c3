"""frbjax._fusion (fusion boundaries that survive jax.vmap); the JVP rules of _frame.matrix_times, _body._normalised.

Under jax.vmap a conditional with a batched predicate becomes a select of both branches; the
library's fusion boundaries (``materialise``) and the conditionals that skip unneeded work
(``anywhere``) would then vanish, which made jax.vmap(jax.hessian) of the motion take 13 GB and three
minutes to compile.  These tests check the structure (the conditionals are still there under vmap)
and the values.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.test_util import check_grads

from frbjax import FreeRigidBody
from frbjax._body import _normalised
from frbjax._frame import matrix_times as _apply
from frbjax._fusion import anywhere, materialise


def _conditionals(function, *args):
    return jax.jit(function).lower(*args).as_text().count("stablehlo.case")


def test_anywhere_is_one_unbatched_flag_under_vmap():
    flags = jnp.array([[False, False], [False, True], [False, False]])
    assert bool(anywhere(flags))
    # One flag for the whole mapped batch (vmap's output repeats it), not one per instance: true for
    # the instances whose own flags are all false too.
    np.testing.assert_array_equal(jax.vmap(anywhere)(flags), [True, True, True])
    assert not np.any(jax.vmap(jax.vmap(anywhere))(jnp.zeros((3, 2, 4), bool)))


def test_materialise_stays_a_conditional_under_vmap_and_grad():
    def f(x):
        return jnp.sum(jnp.cos(materialise(jnp.sin(x) * x)))

    x = jnp.linspace(0.1, 1.0, 5)
    batch = jnp.stack([x, 2 * x])
    assert _conditionals(jax.vmap(f), batch) >= 1
    assert _conditionals(jax.vmap(jax.hessian(f)), batch) >= 1
    np.testing.assert_array_equal(jax.vmap(f)(batch), jnp.stack([f(x), f(2 * x)]))
    check_grads(f, (x,), order=2, modes=("fwd", "rev"))


def test_body_keeps_its_conditionals_under_vmap(monkeypatch):
    """The quaternion of one body has the same conditionals alone and under jax.vmap (and jax.grad).

    On the JAX path, whose formulas hold the fusion boundaries (the compiled kernels' programs have
    none of their own)."""
    monkeypatch.setenv("FRBJAX_KERNELS", "jax")

    def quaternion(x):
        return FreeRigidBody(x[:3], x[3:6]).quaternion(x[6])

    point = jnp.array([1.0, 1.7, 2.9, 0.3, -0.8, 0.5, 3.7])
    alone = _conditionals(quaternion, point)
    assert alone >= 5
    assert _conditionals(jax.vmap(quaternion), jnp.stack([point, 1.1 * point])) == alone
    loss = lambda x: jnp.sum(quaternion(x) ** 3)  # noqa: E731
    assert _conditionals(jax.vmap(jax.grad(loss)), jnp.stack([point, 1.1 * point])) == _conditionals(
        jax.grad(loss), point
    )


def test_apply_value_and_derivatives():
    """matrix_times's value is matrix @ vector (bit for bit the sums over j in order) and its custom JVP
    gives the derivatives of the product to all orders, in both arguments, with broadcasting."""
    rng = np.random.default_rng(3)
    matrix = jnp.asarray(rng.normal(size=(5, 4, 4)))
    vector = jnp.asarray(rng.normal(size=(2, 5, 4)))
    expected = jnp.einsum("bij,tbj->tbi", matrix, vector)
    np.testing.assert_allclose(_apply(matrix, vector), expected, rtol=1e-15, atol=1e-15)
    check_grads(_apply, (matrix, vector), order=2, modes=("fwd", "rev"))
    only_vector = jax.jacrev(lambda v: _apply(matrix[0], v))(vector[0, 0])
    np.testing.assert_array_equal(only_vector, matrix[0])


def test_normalised_value_and_derivatives():
    """_normalised is v / |v| and its custom JVP gives that map's derivatives to second order."""
    vector = jnp.asarray(np.random.default_rng(4).normal(size=(3, 5, 4)))
    np.testing.assert_allclose(
        _normalised(vector), vector / np.linalg.norm(vector, axis=-1, keepdims=True), rtol=4e-16, atol=0
    )
    check_grads(_normalised, (vector,), order=2, modes=("fwd", "rev"))
