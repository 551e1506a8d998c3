"""A fusion boundary for XLA: materialise values that several fused loops would otherwise recompute.

XLA fuses elementwise work into loops over the output.  When an expensive value (a theta series, an
arctangent) feeds several outputs, such as the four components of a quaternion built by
``jnp.stack``, the fused loop of each output recomputes it: the quaternion cost four to eight times
its arithmetic.  ``lax.optimization_barrier`` does not prevent this on CPU (XLA removes it before
fusion).  A conditional does: its results are buffers.  ``materialise`` wraps its arguments in a
conditional whose predicate is always true, (a == a) | (a != a) for a data element a (true for NaN
too), which XLA cannot fold away; the other branch is never taken.  Under ``jax.vmap`` the conditional
becomes a select of the two branches, which is still correct.

``sum_last`` sums a short last axis by additions rather than a reduction, for a CPU miscompilation.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax


def materialise(values):
    """``values`` (a pytree of arrays), computed once into buffers before any later fused loop."""
    leaves = [leaf for leaf in jax.tree_util.tree_leaves(values) if jnp.size(leaf) > 0]
    if not leaves:
        return values
    anchor = jnp.ravel(leaves[0])[0]
    always = (anchor == anchor) | (anchor != anchor)
    return lax.cond(always, lambda v: v, lambda v: jax.tree_util.tree_map(jnp.zeros_like, v), values)


def sum_last(products):
    """Sum over the last (short) axis of ``products``, written as additions rather than a reduction.

    XLA on CPU (jaxlib 0.10.2) hands float32 reductions fused with broadcasts to its YNNPACK backend,
    which returned the first rows of the result again in place of the later ones (from flat index
    10,000 of a (16, 1000, 3) angular momentum under jit: tests/test_float32.py); additions stay in
    XLA's own elementwise loops.
    """
    total = products[..., 0]
    for k in range(1, products.shape[-1]):
        total = total + products[..., k]
    return total
