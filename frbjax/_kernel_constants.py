"""A one-kernel region's constants as values: its jaxpr evaluated with every literal and constant read
from one array per dtype.

XLA:CPU emits a region (``frbjax._kernel``) as one kernel but keeps each distinct constant in it as a
buffer of its own, and its runtime wraps every such buffer anew at each call: about 65 ns a constant,
6 us of a one-body free flow's 19 us.  :func:`lift_constants` evaluates the region's jaxpr again,
binding the same primitives, with each literal and each closed-over array read by a static slice of
a packed array instead; the packed arrays enter the region behind an optimization barrier, so that
XLA cannot fold the slices back into constants.  A few lowerings bring constants of their own, and
are written here without them: ``lax.scan``'s counter (small scans run as while loops whose counter
reads the packed arrays), reductions' initial values (unrolled over their few elements), the index
clamp of ``lax.switch`` (``cond`` is bound directly) and ``exp2``'s log 2.

Calls, checkpoints and custom-derivative or custom-batching wrappers are evaluated in line: this
evaluation gives values only (a region's derivatives and batches are the business of the custom
rules around it in ``frbjax._kernel``).  A jaxpr holding any other higher-order primitive is not
lifted (:func:`lift_constants` returns None).
"""

from __future__ import annotations

import functools
import math

import jax
import jax.extend.core
import jax.numpy as jnp
import numpy as np


# A scan whose scanned and stacked arrays hold at most this many values runs as a while loop.
SMALL_SCAN_ELEMENTS = 64


def _parameter_jaxprs(params):
    for value in params.values():
        for item in value if isinstance(value, (tuple, list)) else (value,):
            if isinstance(item, (jax.extend.core.ClosedJaxpr, jax.extend.core.Jaxpr)):
                yield item


def sub_jaxprs(params):
    """The jaxprs among the parameters of an equation (a call's body, a loop's, a cond's branches)."""
    for item in _parameter_jaxprs(params):
        yield item.jaxpr if isinstance(item, jax.extend.core.ClosedJaxpr) else item


# Higher-order primitives whose values are those of one sub-jaxpr, evaluated in line (the region
# serves values only: custom derivative and batching rules have no part in it).
_CALLS = {
    "jit": "jaxpr",
    "pjit": "jaxpr",
    "closed_call": "call_jaxpr",
    "core_call": "call_jaxpr",
    "remat2": "jaxpr",
    "checkpoint": "jaxpr",
    "custom_jvp_call": "call_jaxpr",
    "custom_vjp_call": "call_jaxpr",
    "custom_vmap_call": "call",
}
_CONTROL_FLOW = frozenset({"cond", "while", "scan"})
# Reductions over a few elements, written as a chain of their binary operation: the reduction's
# initial value would be one more constant.
_REDUCTIONS = {
    "reduce_sum": jax.lax.add,
    "reduce_prod": jax.lax.mul,
    "reduce_max": jax.lax.max,
    "reduce_min": jax.lax.min,
    "reduce_and": jax.lax.bitwise_and,
    "reduce_or": jax.lax.bitwise_or,
}


class _Constants:
    """The literals and constant arrays of a jaxpr, packed into one flat array per dtype.

    :meth:`place` gives a value its segment (equal values share one); the function made by
    :meth:`reader` slices it back out of the packed arrays inside the region, once per jaxpr
    being evaluated.
    """

    def __init__(self):
        self.values = {}  # dtype name -> list of flat arrays
        self.segments = {}  # (dtype name, shape, bytes) -> (start, stop)

    @staticmethod
    def key(value, dtype=None):
        """(dtype name, shape, bytes): equal values, and only they, share a segment."""
        value = np.asarray(value, dtype=dtype)
        return (value.dtype.name, value.shape, value.tobytes()), value

    def place(self, value, dtype=None):
        key, value = self.key(value, dtype)
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
            subs = list(sub_jaxprs(equation.params))
            if subs and name not in _CALLS and name not in _CONTROL_FLOW:
                return False
            for var in equation.invars:
                if isinstance(var, jax.extend.core.Literal):
                    self.place(var.val, var.aval.dtype)
            if name == "scan" and _small_scan(equation.params):  # its counter and zeros (_scan_as_while)
                for value in (0, 1, equation.params["length"]):
                    self.place(value, np.int32)
                for aval in equation.params["jaxpr"].out_avals[equation.params["num_carry"] :]:
                    self.place(0, aval.dtype)
            if name == "exp2":
                self.place(math.log(2), equation.invars[0].aval.dtype)
            for sub in _parameter_jaxprs(equation.params):
                for const in getattr(sub, "consts", ()):
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
            key, _ = self.key(value, dtype)
            if key not in cache:
                start, stop = self.segments[key]
                cache[key] = jax.lax.slice_in_dim(packed[key[0]], start, stop).reshape(key[1])
            return cache[key]

        return read


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
            return _evaluate_closed(branch, flat[len(names) :], constants, dict(zip(names, flat[: len(names)])))

        return evaluate

    flat = [packed[name] for name in names] + list(operands)
    avals = [jax.ShapeDtypeStruct(jnp.shape(x), jnp.result_type(x)) for x in flat]
    branches = tuple(jax.make_jaxpr(branch_function(branch))(*avals) for branch in params["branches"])
    return jax.lax.cond_p.bind(index, *flat, **{**params, "branches": branches})


def _while(params, inputs, constants, packed):
    cond_consts = inputs[: params["cond_nconsts"]]
    body_consts = inputs[params["cond_nconsts"] : params["cond_nconsts"] + params["body_nconsts"]]
    initial = inputs[params["cond_nconsts"] + params["body_nconsts"] :]

    def condition(carry):
        return _evaluate_closed(params["cond_jaxpr"], [*cond_consts, *carry], constants, packed)[0]

    def body(carry):
        return _evaluate_closed(params["body_jaxpr"], [*body_consts, *carry], constants, packed)

    return jax.lax.while_loop(condition, body, initial)


def _scan(params, inputs, constants, packed):
    consts = inputs[: params["num_consts"]]
    carry = inputs[params["num_consts"] : params["num_consts"] + params["num_carry"]]
    xs = inputs[params["num_consts"] + params["num_carry"] :]

    def step(carry, x):
        outputs = _evaluate_closed(params["jaxpr"], [*consts, *carry, *x], constants, packed)
        return outputs[: params["num_carry"]], outputs[params["num_carry"] :]

    carry, ys = jax.lax.scan(
        step, carry, xs, length=params["length"], reverse=params["reverse"], unroll=params["unroll"]
    )
    return [*carry, *ys]


def _holds_loops(jaxpr):
    return any(
        equation.primitive.name in ("while", "scan") or any(_holds_loops(sub) for sub in sub_jaxprs(equation.params))
        for equation in jaxpr.eqns
    )


def _small_scan(params):
    """Whether a scan runs as :func:`_scan_as_while`: the arrays it runs over and stacks hold at
    most ``SMALL_SCAN_ELEMENTS`` values together, and where it has such arrays its body holds no
    loop.  XLA:CPU aborted on the one-kernel emission of such a while loop with loops inside
    (jax 0.10.2: a splitting step in diffeqsolve, whose stages scan over the method's coefficients
    around the free flow's loops; "All or none of the slices should have an explicit index")."""
    scanned = params["jaxpr"].in_avals[params["num_consts"] + params["num_carry"] :]
    stacked = params["jaxpr"].out_avals[params["num_carry"] :]
    if (scanned or stacked) and _holds_loops(params["jaxpr"].jaxpr):
        return False
    values = params["length"] * sum(math.prod(aval.shape) for aval in (*scanned, *stacked))
    return values <= SMALL_SCAN_ELEMENTS


def _scan_as_while(params, inputs, constants, packed, read_constant):
    # A small scan as a while loop whose counter, bound and step are read like the other
    # constants (lax.scan's own loop brings three of its own).  The arrays scanned over ride in the
    # loop's state and turn by one row each step, and so do the stacked outputs (no dynamic slice).
    consts = inputs[: params["num_consts"]]
    carry = inputs[params["num_consts"] : params["num_consts"] + params["num_carry"]]
    xs = inputs[params["num_consts"] + params["num_carry"] :]
    reverse = params["reverse"]
    zero, one, stop = (read_constant(k, np.int32) for k in (0, 1, params["length"]))
    ys = [
        jax.lax.broadcast(read_constant(0, aval.dtype), (params["length"], *aval.shape))
        for aval in params["jaxpr"].out_avals[params["num_carry"] :]
    ]

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
        ys = [turn(rows, row)[1] for rows, row in zip(ys, outputs[params["num_carry"] :])]
        return count + one, outputs[: params["num_carry"]], list(xs), ys

    initial = (zero, list(carry), list(xs), ys)
    _, carry, _, ys = jax.lax.while_loop(lambda state: state[0] < stop, body, initial)
    return [*carry, *ys]


def lift_constants(traced):
    """``traced``'s function (a ``jax.stages.Traced``) with every literal and constant of its jaxpr
    read from the packed arrays (module docstring): same arguments, same outputs.  None where the
    jaxpr holds a higher-order primitive that :func:`_evaluate` does not know."""
    closed = traced.jaxpr
    constants = _Constants()
    if not constants.collect(closed.jaxpr):
        return None
    for const in closed.consts:
        constants.place(const)

    packed = constants.packed()

    def lifted(*args):
        # The barrier keeps XLA from folding the reads back into constants of their own.
        outputs = _evaluate(
            closed.jaxpr,
            closed.consts,
            jax.tree_util.tree_leaves(args),
            constants,
            jax.lax.optimization_barrier(packed),
        )
        return jax.tree_util.tree_unflatten(traced.out_tree, outputs)

    return lifted
