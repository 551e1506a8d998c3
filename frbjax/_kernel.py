"""One-kernel regions: per-body scalar code that XLA's CPU compiler emits as a single kernel.

XLA:CPU turns a program into a sequence of kernels, one per fused group of operations, and pays
for each one at compile time (about 15 ms) and at every call (a launch).  The exact motion of one
body is a few hundred small kernels: the unrolled AGM, Carlson's duplication and Bulirsch's cel each
leave a kernel per step (docs/performance.md), so that the compile time of a one-body program is
set by their count, not by its arithmetic.  XLA emits a small ``call`` as one kernel, compiled whole, when it
carries the frontend attribute ``xla_cpu_small_call`` (the path XLA takes itself for small while
loops).  :func:`one_kernel` puts a function into such a call: a nested ``jax.jit(...,
inline=False)`` traced under ``jax.experimental.xla_metadata.set_xla_metadata``.  The attribute
rides on the call, so it works inside the caller's own ``jit``; the library uses it for unbatched
calls (their values and derivatives), and lets ``jax.vmap`` trace the ordinary program
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

Three more things keep a region at its floor and XLA:CPU from failing on it:

- its constants are read from one array per dtype (``frbjax._kernel_constants``): XLA keeps each
  distinct constant of a region as a buffer that its runtime handles at every call (about 65 ns
  each; a one-body free flow had 94, 6 of its 19 us);
- arguments known when the call is traced (Python numbers, arrays closed over by the caller) enter
  the region as its constants: XLA:CPU aborts on a region whose argument is a constant once it emits
  an enclosing loop as one kernel;
- derivatives: a ``custom_jvp`` whose rule evaluates the values and their forward-mode Jacobian in
  one more region (the tangent is that Jacobian applied outside it), so that a one-body gradient is
  one region and a small contraction rather than the ordinary reverse pass's hundreds of kernels.  Batches
  (``custom_vmap``) of the values and of the Jacobian trace the ordinary program.
"""

from __future__ import annotations

import functools
import os

import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_batching import custom_vmap
from jax.experimental.xla_metadata import set_xla_metadata

from ._kernel_constants import lift_constants, sub_jaxprs


_ATTRIBUTES = dict(xla_cpu_small_call="true", inlineable="false")

# A region's inputs, each at most this many elements (one body's state is 3 + 3 + 4 + 1).
MAX_ELEMENTS = 64
# Dot products with operands up to this size are emitted inside the kernel; larger ones are not.
_MAX_DOT_ELEMENTS = 16
# Operations XLA:CPU cannot emit inside a single kernel: they call its runtime (and every callback).
_RUNTIME_PRIMITIVES = frozenset(
    {
        "sort",
        "cholesky",
        "eig",
        "eigh",
        "lu",
        "lu_pivots_to_permutation",
        "qr",
        "householder_product",
        "svd",
        "schur",
        "hessenberg",
        "tridiagonal",
        "tridiagonal_solve",
        "triangular_solve",
        "fft",
        "ffi_call",
        "custom_call",
        "debug_print",
        "rng_bit_generator",
        "random_bits",
        "all_gather",
        "psum",
        "ppermute",
        "all_to_all",
    }
)


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


def _fits_one_kernel(jaxpr) -> bool:
    """Whether every operation of ``jaxpr`` (and of its sub-jaxprs) has a single-kernel emitter."""
    for equation in jaxpr.eqns:
        name = equation.primitive.name
        if name in _RUNTIME_PRIMITIVES or "callback" in name:
            return False
        if name == "dot_general" and any(np.prod(v.aval.shape) > _MAX_DOT_ELEMENTS for v in equation.invars):
            return False
        if not all(_fits_one_kernel(sub) for sub in sub_jaxprs(equation.params)):
            return False
    return True


def _batched_everywhere(axis_size, in_batched, args):
    """``args`` with every leaf given the mapped axis in front (broadcast where it was not mapped)."""
    return jax.tree_util.tree_map(
        lambda leaf, batched: leaf if batched else jnp.broadcast_to(leaf, (axis_size,) + jnp.shape(leaf)),
        tuple(args),
        tuple(in_batched),
    )


def _primal_region(function, region):
    """``function`` as the region for its value, with derivatives through a region of its Jacobian.

    Under ``jax.vmap`` the per-body region would become one kernel over the whole batch, which is
    slower than XLA's fused loops and which XLA:CPU cannot always compile (a large loop inside it
    asks for its parallel runtime): ``custom_vmap`` maps ``function`` instead.  ``custom_vmap`` has no
    reverse mode, so the tangent rule (``custom_jvp``) takes the values and the Jacobian from a
    region that depends on the primal inputs alone (JAX's linearisation evaluates it as a known
    value) and applies the Jacobian outside it, a linear map that reverse mode transposes.
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
        outputs, jacobian = one_kernel(functools.partial(_values_and_jacobian, function))(*primals)
        return outputs, _apply_jacobian(jacobian, outputs, primals, tangents)

    return evaluate


def _inexact(leaf):
    return jnp.issubdtype(jnp.result_type(leaf), jnp.inexact)


def _values_and_jacobian(function, *args):
    """``function(*args)`` and its Jacobian in the inexact leaves of ``args`` (forward mode)."""
    leaves, tree = jax.tree_util.tree_flatten(args)
    variables = [leaf for leaf in leaves if _inexact(leaf)]

    def of_variables(*variables):
        given = iter(variables)
        outputs = function(
            *jax.tree_util.tree_unflatten(tree, [next(given) if _inexact(leaf) else leaf for leaf in leaves])
        )
        return outputs, outputs  # the values as jacfwd's auxiliary output: one evaluation for both

    every_variable = tuple(range(len(variables)))
    jacobian, outputs = jax.jacfwd(of_variables, argnums=every_variable, has_aux=True)(*variables)
    return outputs, jacobian


def _apply_jacobian(jacobian, outputs, primals, tangents):
    """The tangent of the outputs: the Jacobian (one entry per inexact input leaf) applied to the tangents."""
    leaves = jax.tree_util.tree_leaves(primals)
    directions = [tangent for leaf, tangent in zip(leaves, jax.tree_util.tree_leaves(tangents)) if _inexact(leaf)]

    def tangent_of(output, rows):
        total = jnp.zeros_like(output)
        for row, direction in zip(rows, directions):
            total = total + jnp.tensordot(row, direction, axes=jnp.ndim(direction))
        return total

    tree = jax.tree_util.tree_structure(outputs)
    rows_of_outputs = zip(tree.flatten_up_to(outputs), tree.flatten_up_to(jacobian))
    return tree.unflatten([tangent_of(output, rows) for output, rows in rows_of_outputs])


def _region_call(function, tree, leaves, known, traced_leaves):
    """A callable of ``traced_leaves`` (the leaves not ``known``): ``function`` as a one-kernel region
    (its constants lifted) or, where the region does not apply, ``function`` itself."""

    def of_traced(*traced):
        given = iter(traced)
        return function(*tree.unflatten([leaf if is_known else next(given) for leaf, is_known in zip(leaves, known)]))

    region = jax.jit(of_traced, inline=False)
    try:
        traced = region.trace(*traced_leaves)
    except TypeError:  # an argument jit cannot take (a callable inside a pytree, say)
        return of_traced
    if not _fits_one_kernel(traced.jaxpr.jaxpr):
        return of_traced
    lifting = lift_constants(traced)
    try:
        lifted = _primal_region(of_traced, jax.jit(lifting, inline=False) if lifting else region)
        # Traced here (abstractly, once: JAX keeps the trace for the call that follows) so that a
        # primitive the evaluator binds wrongly falls back to the plain region, not to an error.
        jax.eval_shape(lifted, *traced_leaves)
        return lifted
    except Exception:  # noqa: BLE001 - see above
        return _primal_region(of_traced, region)


def one_kernel(function):
    """``function`` evaluated as a one-kernel region where possible (module docstring), else as is.

    ``function`` takes and returns pytrees of arrays, and must close over no tracer (pass everything
    it reads as an argument: ``custom_jvp`` and ``custom_vmap`` refuse closed-over tracers).  The
    region serves the value of an unbatched call and, through a second region, its derivatives;
    under ``jax.vmap`` ``function`` is traced as usual (``_primal_region``).  The decision is made
    from the arguments' shapes and the jaxpr when the call is traced, so that it costs nothing at
    run time.
    """
    # The regions of eager calls, by the arguments' structure and types (a call under a trace is
    # traced once with the caller's program, which the caller's jit caches).
    eager_regions = {}

    @functools.wraps(function)
    def call(*args):
        leaves, tree = jax.tree_util.tree_flatten(args)
        small = all(np.size(leaf) <= MAX_ELEMENTS for leaf in leaves)
        if not (small and enabled() and available()):
            return function(*args)
        # Under a trace, values known when the call is traced enter the region as its own constants,
        # not as its arguments: XLA:CPU aborts on a region whose argument is a constant once it puts
        # the region into a loop it emits as one kernel itself (a small while loop around it).
        tracing = any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)
        known = [tracing and not isinstance(leaf, jax.core.Tracer) for leaf in leaves]
        traced_leaves = [leaf for leaf, is_known in zip(leaves, known) if not is_known]
        if tracing:
            return _region_call(function, tree, leaves, known, traced_leaves)(*traced_leaves)
        try:
            key = (tree, tuple(jax.typeof(leaf) for leaf in leaves))
            hash(key)
        except TypeError:  # a leaf that is not an array (jit refuses it too): no cache
            return _region_call(function, tree, leaves, known, traced_leaves)(*traced_leaves)
        if key not in eager_regions:
            eager_regions[key] = _region_call(function, tree, leaves, known, traced_leaves)
        return eager_regions[key](*traced_leaves)

    return call
