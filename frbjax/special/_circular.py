"""Cosine and sine in float64, written so that XLA:CPU vectorises them.

XLA:CPU evaluates a float64 ``cos`` or ``sin`` by a scalar library call per element (about 9 ns,
against well under 1 ns for a vectorised product or square root; its ``exp`` and ``log`` are
vectorised), and the exact motion takes a cosine and a sine or two per evaluation.  Here they are
products and sums, which the compiler vectorises, within 0.65 ulp of the correctly rounded values
(tests/special/test_circular.py, against mpmath).

:func:`cos_sin` reduces the argument by the nearest multiple of pi/2 (Cody and Waite's three-part
pi/2, the first two parts short enough that their products with the multiple are exact, the
reduced argument carried with its rounding error), then sums the Taylor series of DLMF 4.19.1 and
4.19.2 on [-pi/4, pi/4] and applies the quadrant's signs and swap.  Beyond 2^19 pi/2 the reduction
would lose digits: a batch holding such an argument takes XLA's own functions (a conditional).
float32 arguments take XLA's functions, which are vectorised there.  Derivatives are those of the
functions (a custom JVP), not of the polynomials.

XLA's float64 ``atan2`` is a scalar call too.  A vectorised one written the same way (correctly
rounded to 0.001 ulp) left the series evaluation as fast as before, made the one-time path 7%
faster, and made the programs that hold it about a fifth slower to compile; the motion keeps XLA's.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from .._fusion import when_any
from ._carlson import _horner
from ._common import is_double


# pi/2 as three parts: the first two with 33 significant bits, so that k times each is exact for
# |k| < 2^20, and the rest rounded (pi/2 - the three parts is 1e-37).
_HALF_PI_PARTS = (
    float.fromhex("0x1.921fb54400000p+0"),
    float.fromhex("0x1.0b4611a600000p-34"),
    float.fromhex("0x1.3198a2e037073p-69"),
)
_TWO_OVER_PI = float.fromhex("0x1.45f306dc9c883p-1")
_REDUCTION_LIMIT = 2.0**19 * math.pi / 2

# Taylor tails, highest coefficient first: sin r = r + r^3 S(r^2) through r^19 and
# cos r = 1 - r^2/2 + r^4 C(r^2) through r^20 (|r| <= pi/4: first omitted terms below 1e-21).
_SIN_TAIL = tuple((-1) ** k / math.factorial(2 * k + 1) for k in range(9, 0, -1))
_COS_TAIL = tuple((-1) ** k / math.factorial(2 * k) for k in range(10, 1, -1))


def _two_sum(a, b):
    """(a + b rounded, its exact rounding error) (Knuth's TwoSum)."""
    total = a + b
    b_virtual = total - a
    a_virtual = total - b_virtual
    return total, (a - a_virtual) + (b - b_virtual)


def _two_product(a, b):
    """(a b rounded, its exact rounding error) (Dekker's product with Veltkamp's split, 2^27 + 1 in
    float64 and 2^12 + 1 in float32; |a|, |b| far below the overflow threshold)."""
    splitter = 2.0**27 + 1 if is_double(a) else 2.0**12 + 1
    product = a * b
    a_big, b_big = splitter * a, splitter * b
    a_high, b_high = a_big - (a_big - a), b_big - (b_big - b)
    a_low, b_low = a - a_high, b - b_high
    return product, ((a_high * b_high - product) + a_high * b_low + a_low * b_high) + a_low * b_low


def cos_sin_near_zero(r, tail=None):
    """(cos, sin)(r + tail) for |r| <= pi/4 (a little beyond too), ``tail`` a correction of an ulp of r
    or None: the Taylor polynomials, 1 - r^2/2 with the roundings of r^2 and of the difference added
    back (Dekker's product, then w = 1 - h and (1 - w) - h exactly), and the tail at first order."""
    square, square_error = _two_product(r, r)
    sine_rest = r * square * _horner(_SIN_TAIL, square)
    half = square / 2
    lead = 1 - half
    cosine_rest = (((1 - lead) - half) - square_error / 2) + square * square * _horner(_COS_TAIL, square)
    if tail is not None:
        # sin(r + d) = sin r + d cos r and cos(r + d) = cos r - d sin r to first order in d ~ ulp(r).
        sine_rest = sine_rest + tail * (lead + cosine_rest)
        cosine_rest = cosine_rest - tail * r
    return lead + cosine_rest, r + sine_rest


def _reduced(x):
    """(quadrant k mod 4, r, tail) with x = k pi/2 + r + tail, |r| <= pi/4 (about), for |x| <= 2^19 pi/2."""
    quadrant = jnp.round(x * _TWO_OVER_PI)
    first, second, third = _HALF_PI_PARTS
    # x - k P1 and k P2 are exact; the difference of those two is carried with its error.
    head, error = _two_sum(x - quadrant * first, -(quadrant * second))
    third_part = quadrant * third
    r = head - third_part
    tail = ((head - r) - third_part) + error
    return jnp.mod(quadrant, 4), r, tail


def _cos_sin_reduced(x):
    quadrant, r, tail = _reduced(x)
    cosine, sine = cos_sin_near_zero(r, tail)
    # Quadrant k: (cos, sin)(k pi/2 + r) = (c, s), (-s, c), (-c, -s), (s, -c) for k = 0, 1, 2, 3.
    swap = (quadrant == 1) | (quadrant == 3)
    cos_value = jnp.where(swap, sine, cosine)
    sin_value = jnp.where(swap, cosine, sine)
    cos_value = jnp.where((quadrant == 1) | (quadrant == 2), -cos_value, cos_value)
    # sin(+-0) = +-0 (the polynomial's sum would give +0 for both).
    sin_value = jnp.where(x == 0, x, jnp.where(quadrant >= 2, -sin_value, sin_value))
    return cos_value, sin_value


@jax.custom_jvp
def cos_sin(x):
    """(cos x, sin x) (DLMF 4.14), vectorised for float64 (module note); XLA's functions for float32
    and for a batch holding an |x| above 2^19 pi/2."""
    if not is_double(x):
        return jnp.cos(x), jnp.sin(x)
    far = ~(jnp.abs(x) <= _REDUCTION_LIMIT)  # NaN and infinities too
    return when_any(far, lambda x: (jnp.cos(x), jnp.sin(x)), _cos_sin_reduced, x)


@cos_sin.defjvp
def _cos_sin_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    cosine, sine = cos_sin(x)
    return (cosine, sine), (-sine * dx, cosine * dx)
