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

Inside a region XLA keeps every distinct constant as a buffer of its own (it fuses no constant into
the code there), and its CPU runtime wraps each such buffer anew at every call: about 65 ns a
constant, 6 us of a one-body free flow's 19 us (87 constants).  So the region receives the
constants of its jaxpr as arguments (:func:`_lift_constants`): one array per dtype, made once at the
call site, from which the region reads its constants as values.
"""

from __future__ import annotations

import functools
import math
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


# Higher-order primitives whose values are those of one sub-jaxpr, evaluated in line (the region
# serves values only: custom derivative and batching rules have no part in it).
_CALLS = {"jit": "jaxpr", "pjit": "jaxpr", "closed_call": "call_jaxpr", "core_call": "call_jaxpr",
          "remat2": "jaxpr", "checkpoint": "jaxpr", "custom_jvp_call": "call_jaxpr",
          "custom_vjp_call": "call_jaxpr", "custom_vmap_call": "call"}
_CONTROL_FLOW = frozenset({"cond", "while", "scan"})
# Reductions over a few elements, written as a chain of their binary operation: the reduction's
# initial value would be one more constant.
_REDUCTIONS = {"reduce_sum": jax.lax.add, "reduce_prod": jax.lax.mul, "reduce_max": jax.lax.max,
               "reduce_min": jax.lax.min, "reduce_and": jax.lax.bitwise_and, "reduce_or": jax.lax.bitwise_or}


class _Constants:
    """The literals and constant arrays of a jaxpr, packed into one flat array per dtype.

    ``place`` gives a value its segment (equal values share one); :meth:`read` slices it back out
    of the packed arrays inside the region, once per jaxpr being evaluated.
    """

    def __init__(self):
        self.values = {}  # dtype name -> list of flat arrays
        self.segments = {}  # (dtype name, shape, bytes) -> (start, stop)

    def place(self, value, dtype=None):
        value = np.asarray(value, dtype=dtype)
        key = (value.dtype.name, value.shape, value.tobytes())
        if key not in self.segments:
            flat = self.values.setdefault(value.dtype.name, [])
            start = sum(v.size for v in flat)
            flat.append(value.reshape(-1))
            self.segments[key] = (start, start + value.size)
        return key

    def collect(self, jaxpr):
        """Place every literal of ``jaxpr`` and of its sub-jaxprs; False where a higher-order
        primitive is not one that :func:`_evaluate` knows."""
        for equation in jaxpr.eqns:
            name = equation.primitive.name
            subs = list(_sub_jaxprs(equation.params))
            if subs and name not in _CALLS and name not in _CONTROL_FLOW:
                return False
            for var in equation.invars:
                if isinstance(var, jax.extend.core.Literal):
                    self.place(var.val, var.aval.dtype)
            if name == "scan" and _small_scan(equation.params):  # its counter and zeros (_scan_as_while)
                for value in (0, 1, equation.params["length"]):
                    self.place(value, np.int32)
                for aval in equation.params["jaxpr"].out_avals[equation.params["num_carry"]:]:
                    self.place(0, aval.dtype)
            if name == "exp2":
                self.place(math.log(2), equation.invars[0].aval.dtype)
            for sub in _sub_closed_jaxprs(equation.params):
                for const in sub.consts:
                    self.place(const)
            if not all(self.collect(sub) for sub in subs):
                return False
        for var in jaxpr.outvars:
            if isinstance(var, jax.extend.core.Literal):
                self.place(var.val, var.aval.dtype)
        return True

    def packed(self):
        return {dtype: np.concatenate(values) for dtype, values in self.values.items()}

    def reader(self, packed):
        """A function of a value (as placed) giving it from the traced ``packed`` arrays."""
        cache = {}

        def read(value, dtype=None):
            value = np.asarray(value, dtype=dtype)
            key = (value.dtype.name, value.shape, value.tobytes())
            if key not in cache:
                start, stop = self.segments[key]
                cache[key] = jax.lax.slice_in_dim(packed[key[0]], start, stop).reshape(key[1])
            return cache[key]

        return read


def _sub_closed_jaxprs(params):
    for value in params.values():
        for item in value if isinstance(value, (tuple, list)) else (value,):
            if isinstance(item, jax.extend.core.ClosedJaxpr):
                yield item


def _evaluate(jaxpr, consts, args, constants, packed):
    """The outputs of ``jaxpr`` with every literal and constant read from ``packed``."""
    read_constant = constants.reader(packed)
    environment = {}

    def read(var):
        if isinstance(var, jax.extend.core.Literal):
            return read_constant(var.val, var.aval.dtype)
        return environment[var]

    def write(var, value):
        if not isinstance(var, jax.extend.core.DropVar):
            environment[var] = value

    for var, value in zip(jaxpr.constvars, consts):
        write(var, read_constant(value))
    for var, value in zip(jaxpr.invars, args):
        write(var, value)
    for equation in jaxpr.eqns:
        name, params = equation.primitive.name, equation.params
        inputs = [read(var) for var in equation.invars]
        if name in _CALLS:
            outputs = _evaluate_closed(params[_CALLS[name]], inputs, constants, packed)
        elif name == "cond":
            outputs = _cond(params, inputs, constants, packed)
        elif name == "while":
            outputs = _while(params, inputs, constants, packed)
        elif name == "scan" and _small_scan(params):
            outputs = _scan_as_while(params, inputs, constants, packed, read_constant)
        elif name == "scan":
            outputs = _scan(params, inputs, constants, packed)
        elif name in _REDUCTIONS and inputs[0].size and params["axes"]:
            outputs = [_unrolled_reduction(_REDUCTIONS[name], inputs[0], params["axes"])]
        elif name == "optimization_barrier":
            # A nested region's barrier (one_kernel): inside this region it has nothing to keep apart.
            outputs = inputs
        elif name == "exp2":
            outputs = [jax.lax.exp(inputs[0] * read_constant(math.log(2), inputs[0].dtype))]
        else:
            outputs = equation.primitive.bind(*inputs, **params)
            outputs = outputs if equation.primitive.multiple_results else [outputs]
        for var, value in zip(equation.outvars, outputs):
            write(var, value)
    return [read(var) for var in jaxpr.outvars]


def _evaluate_closed(jaxpr, args, constants, packed):
    if isinstance(jaxpr, jax.extend.core.ClosedJaxpr):
        return _evaluate(jaxpr.jaxpr, jaxpr.consts, args, constants, packed)
    return _evaluate(jaxpr, (), args, constants, packed)


def _unrolled_reduction(operation, operand, axes):
    for axis in sorted(axes, reverse=True):
        parts = [jax.lax.index_in_dim(operand, k, axis, keepdims=False) for k in range(operand.shape[axis])]
        operand = functools.reduce(operation, parts)
    return operand


def _cond(params, inputs, constants, packed):
    # cond itself, not lax.switch (which clamps the index with two more constants); the packed
    # arrays enter each branch as operands.
    index, *operands = inputs
    names = sorted(packed)

    def branch_function(branch):
        def evaluate(*flat):
            return _evaluate_closed(branch, flat[len(names):], constants, dict(zip(names, flat[:len(names)])))
        return evaluate

    flat = [packed[name] for name in names] + list(operands)
    avals = [jax.ShapeDtypeStruct(jnp.shape(x), jnp.result_type(x)) for x in flat]
    branches = tuple(jax.make_jaxpr(branch_function(branch))(*avals) for branch in params["branches"])
    return jax.lax.cond_p.bind(index, *flat, **{**params, "branches": branches})


def _while(params, inputs, constants, packed):
    cond_consts = inputs[:params["cond_nconsts"]]
    body_consts = inputs[params["cond_nconsts"]:params["cond_nconsts"] + params["body_nconsts"]]
    initial = inputs[params["cond_nconsts"] + params["body_nconsts"]:]

    def condition(carry):
        return _evaluate_closed(params["cond_jaxpr"], [*cond_consts, *carry], constants, packed)[0]

    def body(carry):
        return _evaluate_closed(params["body_jaxpr"], [*body_consts, *carry], constants, packed)

    return jax.lax.while_loop(condition, body, initial)


def _scan(params, inputs, constants, packed):
    consts = inputs[:params["num_consts"]]
    carry = inputs[params["num_consts"]:params["num_consts"] + params["num_carry"]]
    xs = inputs[params["num_consts"] + params["num_carry"]:]

    def step(carry, x):
        outputs = _evaluate_closed(params["jaxpr"], [*consts, *carry, *x], constants, packed)
        return outputs[:params["num_carry"]], outputs[params["num_carry"]:]

    carry, ys = jax.lax.scan(step, carry, xs, length=params["length"], reverse=params["reverse"],
                             unroll=params["unroll"])
    return [*carry, *ys]


def _holds_loops(jaxpr):
    return any(equation.primitive.name in ("while", "scan")
               or any(_holds_loops(sub) for sub in _sub_jaxprs(equation.params)) for equation in jaxpr.eqns)


def _small_scan(params):
    """Whether a scan runs as :func:`_scan_as_while`: the arrays it runs over and stacks hold at
    most ``MAX_ELEMENTS`` values together, and where it has such arrays its body holds no loop (XLA:CPU
    aborts on emitting such a while loop with loops inside in one kernel: measured with jax 0.10.2 on
    a splitting step, whose stages scan over the method's coefficients around the free flow's loops)."""
    scanned = params["jaxpr"].in_avals[params["num_consts"] + params["num_carry"]:]
    stacked = params["jaxpr"].out_avals[params["num_carry"]:]
    if (scanned or stacked) and _holds_loops(params["jaxpr"].jaxpr):
        return False
    return params["length"] * sum(math.prod(aval.shape) for aval in (*scanned, *stacked)) <= MAX_ELEMENTS


def _scan_as_while(params, inputs, constants, packed, read_constant):
    # A small scan as a while loop whose counter, bound and step are read like the other
    # constants (lax.scan's own loop brings three of its own).  The arrays scanned over ride in the
    # loop's state and turn by one row each step, and so do the stacked outputs (no dynamic slice).
    consts = inputs[:params["num_consts"]]
    carry = inputs[params["num_consts"]:params["num_consts"] + params["num_carry"]]
    xs = inputs[params["num_consts"] + params["num_carry"]:]
    reverse = params["reverse"]
    zero, one, stop = (read_constant(k, np.int32) for k in (0, 1, params["length"]))
    ys = [jax.lax.broadcast(read_constant(0, aval.dtype), (params["length"], *aval.shape))
          for aval in params["jaxpr"].out_avals[params["num_carry"]:]]

    def turn(rows, row=None):
        """The next row to read, and the rows turned by one (``row`` put in where it went out)."""
        if reverse:
            first = rows[-1] if row is None else row
            return rows[-1], jnp.concatenate([first[None], rows[:-1]])
        last = rows[0] if row is None else row
        return rows[0], jnp.concatenate([rows[1:], last[None]])

    def body(state):
        count, carry, xs, ys = state
        x, xs = zip(*(turn(rows) for rows in xs)) if xs else ((), ())
        outputs = _evaluate_closed(params["jaxpr"], [*consts, *carry, *x], constants, packed)
        ys = [turn(rows, row)[1] for rows, row in zip(ys, outputs[params["num_carry"]:])]
        return count + one, outputs[:params["num_carry"]], list(xs), ys

    _, carry, _, ys = jax.lax.while_loop(lambda state: state[0] < stop, body, (zero, list(carry), list(xs), ys))
    return [*carry, *ys]


def _lift_constants(traced):
    """``traced``'s function as ``(lifted, packed)``: ``lifted(packed, *args)`` computes the same
    outputs with every literal and constant of the jaxpr read from ``packed`` (module docstring);
    None where the jaxpr holds a higher-order primitive that :func:`_evaluate` does not know."""
    closed = traced.jaxpr
    constants = _Constants()
    if not constants.collect(closed.jaxpr):
        return None
    for const in closed.consts:
        constants.place(const)

    packed = constants.packed()

    def lifted(*args):
        # The barrier keeps XLA from folding the reads back into constants of their own.
        outputs = _evaluate(closed.jaxpr, closed.consts, jax.tree_util.tree_leaves(args), constants,
                            jax.lax.optimization_barrier(packed))
        return jax.tree_util.tree_unflatten(traced.out_tree, outputs)

    return lifted


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
        outputs = function(*jax.tree_util.tree_unflatten(tree, [next(given) if _inexact(leaf) else leaf
                                                                for leaf in leaves]))
        return outputs, outputs  # the values as jacfwd's auxiliary output: one evaluation for both

    jacobian, outputs = jax.jacfwd(of_variables, argnums=tuple(range(len(variables))), has_aux=True)(*variables)
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
    return tree.unflatten([tangent_of(output, rows)
                           for output, rows in zip(tree.flatten_up_to(outputs), tree.flatten_up_to(jacobian))])


def one_kernel(function):
    """``function`` evaluated as a one-kernel region where possible (module docstring), else as is.

    ``function`` takes and returns pytrees of arrays, and must close over no tracer (pass everything
    it reads as an argument: ``custom_jvp`` and ``custom_vmap`` refuse closed-over tracers).  The
    region serves the value of an unbatched call; under ``jax.vmap`` and in derivatives ``function``
    is traced as usual (``_primal_region``).  The decision is made from the arguments' shapes and
    the jaxpr when the call is traced, so that it costs nothing at run time; the jaxpr is traced once
    (the region's own ``jit`` reuses it).
    """
    @functools.wraps(function)
    def call(*args):
        leaves, tree = jax.tree_util.tree_flatten(args)
        small = all(np.size(leaf) <= MAX_ELEMENTS for leaf in leaves)
        if not (small and enabled() and available()):
            return function(*args)
        # Values known when the call is traced enter the region as its own constants, not as its
        # arguments: XLA:CPU aborts on a region whose argument is a constant once it puts the
        # region into a loop it emits as one kernel itself (a small while loop around it).
        known = [not isinstance(leaf, jax.core.Tracer) for leaf in leaves]

        def of_traced(*traced):
            given = iter(traced)
            return function(*tree.unflatten([leaf if is_known else next(given)
                                             for leaf, is_known in zip(leaves, known)]))

        traced_leaves = [leaf for leaf, is_known in zip(leaves, known) if not is_known]
        region = jax.jit(of_traced, inline=False)
        try:
            traced = region.trace(*traced_leaves)
        except TypeError:  # an argument jit cannot take (a callable inside a pytree, say)
            return function(*args)
        if not _fits_one_kernel(traced.jaxpr.jaxpr):
            return function(*args)
        lifting = _lift_constants(traced)
        try:
            return _primal_region(of_traced, jax.jit(lifting, inline=False) if lifting else region)(*traced_leaves)
        except Exception:  # noqa: BLE001 - a primitive the evaluator binds wrongly: the plain region
            return _primal_region(of_traced, region)(*traced_leaves)

    return call
