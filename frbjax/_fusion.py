"""A fusion boundary for XLA: materialise values that several fused loops would otherwise recompute.

XLA fuses elementwise work into loops over the output.  When an expensive value (a theta series, an
arctangent) feeds several outputs, such as the four components of a quaternion built by
``jnp.stack``, the fused loop of each output recomputes it: the quaternion cost four to eight times
its arithmetic.  ``lax.optimization_barrier`` does not prevent this on CPU (XLA removes it before
fusion).  A conditional does: its results are buffers.  ``materialise`` wraps its arguments in a
conditional whose predicate is always true, (a == a) | (a != a) for a data element a (true for NaN
too), which XLA cannot fold away; the other branch is never taken.  Under ``jax.vmap`` the conditional
becomes a select of the two branches, which is still correct.
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
