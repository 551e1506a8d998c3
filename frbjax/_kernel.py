"""One-kernel regions: per-body scalar code that XLA's CPU compiler emits as a single kernel.

XLA:CPU turns a program into a sequence of kernels, one per fused group of operations, and pays
for each one at compile time (about 15 ms) and at every call (a launch).  The exact motion of one
body is a few hundred small kernels: the unrolled AGM, Carlson's duplication and Bulirsch's cel each
leave a kernel per step (docs/performance.md), so that the compile time of a one-body program is
set by their count, not by its arithmetic.  XLA emits a small ``call`` as one kernel, compiled whole, when it
carries the frontend attribute ``xla_cpu_small_call`` (the path XLA takes itself for small while
loops).  :func:`one_kernel` puts a function into such a call: a nested ``jax.jit(...,
inline=False)`` traced under ``jax.experimental.xla_metadata.set_xla_metadata``.  The attribute
rides on the call, so it works inside the caller's own ``jit``; the library uses it for values of
unbatched calls only, and lets ``jax.vmap`` and derivatives trace the ordinary program
(``_primal_region``).

It is an XLA-internal attribute, not an API, and it does not compile everything: XLA:CPU has no
single-kernel emitter for sorts, calls into its runtime (linear algebra, callbacks, FFI) or large
dot products.  So a region is used only where

- the backend is CPU and a probe program, compiled once per process, carries the attribute and
  computes the right value (:func:`available`): a JAX that drops or rejects it gets today's program;
- every array entering the region is small (``MAX_ELEMENTS``): the region is for one body or a few,
  where the kernels' count dominates; over a batch the ordinary fused loops are faster;
- the region's jaxpr holds none of the operations above (:func:`_fits_one_kernel`);
- ``FRBJAX_ONE_KERNEL=0`` is not set in the environment (the switch for comparing both programs; it
  is read when a program is traced, so set it before the process's first call).

Otherwise the function is called as it is.  Both programs compute the same values to rounding
(tests/test_one_kernel.py runs both).
"""

from __future__ import annotations

import functools
import os

import jax
import jax.extend.core
import jax.numpy as jnp
import numpy as np
from jax.custom_batching import custom_vmap
from jax.experimental.xla_metadata import set_xla_metadata

_ATTRIBUTES = dict(xla_cpu_small_call="true", inlineable="false")

# A region's inputs, each at most this many elements (one body's state is 3 + 3 + 4 + 1).
MAX_ELEMENTS = 64
# Dot products with operands up to this size are emitted inside the kernel; larger ones are not.
_MAX_DOT_ELEMENTS = 16
# Operations XLA:CPU cannot emit inside a single kernel: they call its runtime (and every callback).
_RUNTIME_PRIMITIVES = frozenset({
    "sort", "cholesky", "eig", "eigh", "lu", "lu_pivots_to_permutation", "qr", "householder_product",
    "svd", "schur", "hessenberg", "tridiagonal", "tridiagonal_solve", "triangular_solve", "fft",
    "ffi_call", "custom_call", "debug_print", "rng_bit_generator", "random_bits", "all_gather", "psum",
    "ppermute", "all_to_all",
})


def enabled() -> bool:
    """Whether one-kernel regions may be used in this process (``FRBJAX_ONE_KERNEL`` is not ``0``)."""
    return os.environ.get("FRBJAX_ONE_KERNEL", "1") != "0"


@functools.cache
def available() -> bool:
    """Whether the default backend compiles a one-kernel region, checked once per process.

    The probe is a small function of the kind the regions hold (square roots, a quotient and a
    select): it must compile with the attribute in its optimised HLO and give the same value as
    without it.  Any failure means no regions.
    """
    if jax.default_backend() != "cpu":
        return False

    def probe(x):
        root = jnp.sqrt(x + 1)
        return jnp.where(x > 0, root / (1 + root), x)

    try:
        with jax.ensure_compile_time_eval():
            x = np.linspace(-1.0, 2.0, 4, dtype=np.float32)
            compiled = jax.jit(lambda x: _region(probe, x)).lower(x).compile()
            if 'inlineable="false"' not in compiled.as_text():
                return False
            return bool(np.allclose(np.asarray(compiled(x)), np.asarray(jax.jit(probe)(x)), rtol=1e-6))
    except Exception:  # noqa: BLE001 - any failure of an internal attribute: fall back
        return False


def _region(function, *args):
    return _call_region(jax.jit(function, inline=False), *args)


def _call_region(region, *args):
    with set_xla_metadata(**_ATTRIBUTES):
        return region(*args)


def _sub_jaxprs(params):
    for value in params.values():
        for item in value if isinstance(value, (tuple, list)) else (value,):
            if isinstance(item, jax.extend.core.ClosedJaxpr):
                yield item.jaxpr
            elif isinstance(item, jax.extend.core.Jaxpr):
                yield item


def _fits_one_kernel(jaxpr) -> bool:
    """Whether every operation of ``jaxpr`` (and of its sub-jaxprs) has a single-kernel emitter."""
    for equation in jaxpr.eqns:
        name = equation.primitive.name
        if name in _RUNTIME_PRIMITIVES or "callback" in name:
            return False
        if name == "dot_general" and any(np.prod(v.aval.shape) > _MAX_DOT_ELEMENTS for v in equation.invars):
            return False
        if not all(_fits_one_kernel(sub) for sub in _sub_jaxprs(equation.params)):
            return False
    return True


def _batched_everywhere(axis_size, in_batched, args):
    """``args`` with every leaf given the mapped axis in front (broadcast where it was not mapped)."""
    return jax.tree_util.tree_map(
        lambda leaf, batched: leaf if batched else jnp.broadcast_to(leaf, (axis_size,) + jnp.shape(leaf)),
        tuple(args), tuple(in_batched))


def _primal_region(function, region):
    """``function`` as the region for its value; its derivatives and its batches as ``function`` itself.

    Under ``jax.vmap`` the per-body region would become one kernel over the whole batch, which is
    slower than XLA's fused loops and which XLA:CPU cannot always compile (a large loop inside it
    asks for its parallel runtime): ``custom_vmap`` maps ``function`` instead.  ``custom_vmap`` has no
    reverse mode, so the derivatives (``custom_jvp``) are those of ``function``, traced as usual.
    """

    @custom_vmap
    def unbatched(*args):
        return _call_region(region, *args)

    @unbatched.def_vmap
    def _mapped(axis_size, in_batched, *args):
        outputs = jax.vmap(function)(*_batched_everywhere(axis_size, in_batched, args))
        return outputs, jax.tree_util.tree_map(lambda _: True, outputs)

    @jax.custom_jvp
    def evaluate(*args):
        return unbatched(*args)

    @evaluate.defjvp
    def _derivative(primals, tangents):
        return jax.jvp(function, primals, tangents)

    return evaluate


def one_kernel(function):
    """``function`` evaluated as a one-kernel region where possible (module docstring), else as is.

    ``function`` takes and returns pytrees of arrays, and must close over no tracer (pass everything
    it reads as an argument: ``custom_jvp`` and ``custom_vmap`` refuse closed-over tracers).  The
    region serves the value of an unbatched call; under ``jax.vmap`` and in derivatives ``function``
    is traced as usual (``_primal_region``).  The decision is made from the arguments' shapes and
    the jaxpr when the call is traced, so that it costs nothing at run time; the jaxpr is traced once
    (the region's own ``jit`` reuses it).
    """
    region = jax.jit(function, inline=False)
    primal_region = _primal_region(function, region)

    @functools.wraps(function)
    def call(*args):
        leaves = jax.tree_util.tree_leaves(args)
        small = all(np.size(leaf) <= MAX_ELEMENTS for leaf in leaves)
        if not (small and enabled() and available()):
            return function(*args)
        try:
            traced = region.trace(*args)
        except TypeError:  # an argument jit cannot take (a callable inside a pytree, say)
            return function(*args)
        if not _fits_one_kernel(traced.jaxpr.jaxpr):
            return function(*args)
        return primal_region(*args)

    return call
