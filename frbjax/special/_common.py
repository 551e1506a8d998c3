"""Small helpers shared by the special functions: dtypes, iteration counts, safe branches."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax import lax


def real_array(a):
    """``jnp.asarray(a)``, refusing with ValueError what is not real numbers (strings, complex numbers,
    objects): the functions' domain is real, and values outside it give NaN (as in scipy.special)."""
    try:
        array = jnp.asarray(a)
    except TypeError as error:
        raise ValueError(f"the elliptic functions take real numbers: {error}") from None
    if jnp.issubdtype(array.dtype, jnp.complexfloating):
        raise ValueError(f"the elliptic functions take real numbers, got dtype {array.dtype}")
    return array


def promote(*args):
    """Broadcast the arguments to one floating dtype (float64 only when x64 is on).

    Arguments that are not real numbers raise ValueError (``real_array``).
    """
    arrays = [real_array(a) for a in args]
    dtype = jnp.result_type(*arrays, float)
    arrays = [a.astype(dtype) for a in arrays]
    return jnp.broadcast_arrays(*arrays)


def is_double(x) -> bool:
    """True when ``x`` is float64: iteration counts are chosen per dtype at trace time."""
    return jnp.asarray(x).dtype == jnp.float64


# At most this many points: a fixed iteration runs as a rolled loop rather than unrolled (``rolled``).
ROLLED_MAX_POINTS = 64


def rolled(x) -> bool:
    """Whether a fixed iteration over the points ``x`` runs as a rolled loop (static, from the shape).

    Unrolled for an array of points: XLA fuses the steps into one vectorized pass over them (a rolled
    loop writes the state to memory and back every step, several times slower).  Rolled for one point
    or a few (at most ``ROLLED_MAX_POINTS``): XLA:CPU compiles a loop that touches little memory per
    iteration as one kernel, where the unrolled steps would be a kernel each (a square root or
    quotient feeding several later steps is never fused into them), so that a one-body program
    compiles several times faster for the same arithmetic.
    """
    return jnp.size(x) <= ROLLED_MAX_POINTS


def scan_unroll(x):
    """``lax.scan``'s ``unroll`` for an iteration over the points ``x`` (``rolled``)."""
    return 1 if rolled(x) else True


def iterate(step, state, count, x, roll=False):
    """``state`` after ``count`` applications of ``step(k, state)``, k = 0, 1, ..., over the points ``x``:
    a rolled loop where ``roll`` or ``rolled(x)``, unrolled otherwise."""
    if roll or rolled(x):
        return lax.fori_loop(0, count, step, state)
    for k in range(count):
        state = step(k, state)
    return state


def where_safe(condition, value, substitute):
    """``value`` where ``condition`` holds, ``substitute`` elsewhere (the safe-where pattern).

    Used on *inputs* of a branch, so that the branch not taken is evaluated at a harmless point and
    never produces NaN in values or gradients.
    """
    return jnp.where(condition, value, substitute)


def complement(m, mc):
    """Return ``(m, mc)`` with ``mc = 1 - m`` when the caller did not pass the complement."""
    if mc is None:
        (m,) = promote(m)
        return m, 1 - m
    return tuple(promote(m, mc))


PI_HIGH = np.pi


def over_sqrt(a, b):
    """``a / sqrt(b)`` for b > 0, written as ``a * sqrt(b) / b``.

    XLA rewrites ``a / sqrt(b)`` into ``a * rsqrt(b)``, and its CPU backend evaluates float64 rsqrt with
    scalar code, which stops LLVM from vectorizing the whole fused loop around it (3x slower).  One
    more rounding than the plain quotient.  b = 0 or inf gives NaN (callers select those away).
    """
    return a * jnp.sqrt(b) / b
