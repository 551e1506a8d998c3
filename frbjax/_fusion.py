"""A fusion boundary for XLA: materialise values that several fused loops would otherwise recompute.

XLA fuses elementwise work into loops over the output.  When an expensive value (a theta series, an
arctangent) feeds several outputs, such as the four components of a quaternion built by
``jnp.stack``, the fused loop of each output recomputes it: the quaternion cost four to eight times
its arithmetic.  ``lax.optimization_barrier`` does not prevent this on CPU (XLA removes it before
fusion).  A conditional does: its results are buffers.  ``materialise`` wraps its arguments in a
conditional whose predicate is always true, (a == a) | (a != a) for a data element a (true for NaN
too), which XLA cannot fold away; the other branch is never taken.

Under ``jax.vmap`` a conditional whose predicate is batched becomes a select of its two branches: no
buffer any more, and every fused loop again recomputes what feeds it.  For ``jax.vmap(jax.hessian(f))``
of a body's motion that made XLA build fusions so large that compiling took 13 GB and three minutes.
So the predicates here come from ``anywhere``, a reduction whose batching rule reduces over the mapped
axis too: its result is never batched, and the conditional stays a conditional under any number of
``jax.vmap``.  ``when_any``, the conditional that skips work nobody in a batch needs (``_body``,
``_series``), uses it for the same reason: under ``jax.vmap`` it skips the work when no body of the
whole mapped batch needs it.

``sum_last`` sums a short last axis by additions rather than a reduction, for a CPU miscompilation.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax
from jax.custom_batching import custom_vmap


@custom_vmap
def anywhere(flags):
    """Whether any element of the boolean ``flags`` is true: one unbatched scalar even under ``jax.vmap``.

    Under ``jax.vmap`` it is true where any element of any mapped instance is: a predicate for
    conditionals that skip work (their branches compute every element and select per element, so
    a predicate true for more instances than need the work changes no value).
    """
    return jnp.any(flags)


@anywhere.def_vmap
def _anywhere_over_the_mapped_axis(axis_size, in_batched, flags):
    del axis_size, in_batched
    return jnp.any(flags), False


def when_any(flags, compute, skip, *operands):
    """``compute(*operands)`` if any of ``flags`` is set (``anywhere``), else ``skip(*operands)``.

    For work that only some elements need: ``compute`` must compute every element and the caller
    select per element, and ``skip`` return placeholders of the same shapes.  ``compute`` is
    checkpointed: in reverse mode JAX gives both branches of a conditional the same residuals, so
    without it the usual branch, ``skip``, would write zeros for every residual of ``compute``, at
    every time of an evaluation.
    """
    return lax.cond(anywhere(flags), jax.checkpoint(compute), skip, *operands)


def materialise(values):
    """``values`` (a pytree of arrays), computed once into buffers before any later fused loop."""
    leaves = [leaf for leaf in jax.tree_util.tree_leaves(values) if jnp.size(leaf) > 0]
    if not leaves:
        return values
    anchor = jnp.ravel(leaves[0])[0]
    always = anywhere((anchor == anchor) | (anchor != anchor))
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
