"""Cosine, sine and the two-argument arctangent in float64, written so that XLA:CPU vectorises them.

XLA:CPU evaluates a float64 ``cos``, ``sin`` or ``atan2`` by a scalar library call per element (about
9 ns, against well under 1 ns for a vectorised product or square root; its ``exp`` and ``log`` are
vectorised), and the exact motion takes several of them per evaluation.  Here they are products,
sums and one quotient, which the compiler vectorises, within an ulp of the correctly rounded values
(tests/special/test_circular.py, against mpmath):

- :func:`cos_sin`: the argument reduced by the nearest multiple of pi/2 (Cody and Waite's three-part
  pi/2, the first two parts short enough that their products with the multiple are exact, the
  reduced argument carried with its rounding error), then the Taylor series of DLMF 4.19.1 and
  4.19.2 on [-pi/4, pi/4] and the quadrant's signs and swap.  Beyond 2^19 pi/2 the reduction would
  lose digits: a batch holding such an argument takes XLA's own functions (a conditional).
- :func:`arctan2`: the quotient of the smaller and the larger magnitude, a in [0, 1], moved next to
  0 by arctan a = arctan c + arctan((a - c)/(1 + a c)) (DLMF 4.24.15) with c = 0, 1/4, 1/2 or 1 by
  interval (the differences a - c exact), the Taylor series of DLMF 4.24.3 for |t| <= 3/16, and the
  octant's angle (arctan c, pi/2 - arctan c, pi - arctan c or pi/2 + arctan c) as a two-part constant
  to which the small arctan t is added, then the sign of y.  Results that are subnormal flush to
  zero, as all of XLA:CPU's arithmetic does.

float32 arguments take XLA's functions, which are vectorised there.  Derivatives are those of the
functions (a custom JVP), not of the polynomials.
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
_HALF_PI_PARTS = (float.fromhex("0x1.921fb54400000p+0"), float.fromhex("0x1.0b4611a600000p-34"),
                  float.fromhex("0x1.3198a2e037073p-69"))
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


def _two_difference(a, b):
    """(a - b rounded, its exact rounding error)."""
    return _two_sum(a, -b)


_SPLITTER = 2.0**27 + 1  # Veltkamp's constant for float64


def _two_product(a, b):
    """(a b rounded, its exact rounding error) (Dekker's product with Veltkamp's split; |a|, |b| < 2^900)."""
    product = a * b
    a_big, b_big = _SPLITTER * a, _SPLITTER * b
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
    head, error = _two_difference(x - quadrant * first, quadrant * second)
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
    sin_value = jnp.where(quadrant >= 2, -sin_value, sin_value)
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


# The angle of each octant case and centre c = 0, 1/4, 1/2, 1 as (high, low): with r = arctan((a - c)/(1 + a c)),
# the result is high + (low + sign r) for (no swap, x >= 0): arctan c + r; (swap, x >= 0):
# pi/2 - arctan c - r; (no swap, x < 0): pi - arctan c - r; (swap, x < 0): pi/2 + arctan c + r.
_OCTANT_ANGLES = tuple((float.fromhex(high), float.fromhex(low)) for high, low in (
    ("0x0.0p+0", "0x0.0p+0"), ("0x1.f5b75f92c80ddp-3", "0x1.8ab6e3cf7afbdp-57"),
    ("0x1.dac670561bb4fp-2", "0x1.a2b7f222f65e2p-56"), ("0x1.921fb54442d18p-1", "0x1.1a62633145c07p-55"),
    ("0x1.921fb54442d18p+0", "0x1.1a62633145c07p-54"), ("0x1.5368c951e9cfdp+0", "-0x1.96f47948a99f1p-54"),
    ("0x1.1b6e192ebbe44p+0", "0x1.b1b466a88828ep-54"), ("0x1.921fb54442d18p-1", "0x1.1a62633145c07p-55"),
    ("0x1.921fb54442d18p+1", "0x1.1a62633145c07p-53"), ("0x1.72c43f4b1650ap+1", "0x1.c1b6f4f44e10bp-53"),
    ("0x1.56c6e7397f5aep+1", "0x1.660b64ece6f4bp-53"), ("0x1.2d97c7f3321d2p+1", "0x1.a79394c9e8a0ap-54"),
    ("0x1.921fb54442d18p+0", "0x1.1a62633145c07p-54"), ("0x1.d0d6a1369bd34p+0", "-0x1.a23602a65700cp-57"),
    ("0x1.0468a8ace4df6p+1", "0x1.0620bf7406affp-55"), ("0x1.2d97c7f3321d2p+1", "0x1.a79394c9e8a0ap-54")))
# arctan t = t + t^3 A(t^2) through t^25, |t| <= 3/16 (first omitted term below 1e-21 of the value).
_ARCTAN_TAIL = tuple((-1) ** k / (2 * k + 1) for k in range(12, 0, -1))


def _select(index, values):
    """values[index] for a small static table, as a chain of selects (vectorised, unlike a gather)."""
    result = jnp.full(index.shape, values[-1])
    for k in range(len(values) - 2, -1, -1):
        result = jnp.where(index == k, values[k], result)
    return result


def _unit_scale(larger):
    """A power of two that takes ``larger`` > 0 into [1, 4) (exact: the exponent field alone)."""
    exponent = jax.lax.shift_right_logical(jax.lax.bitcast_convert_type(larger, jnp.int64), jnp.int64(52))
    field = jnp.clip(2046 - exponent, 1, 2046)
    return jax.lax.bitcast_convert_type(jax.lax.shift_left(field, jnp.int64(52)), jnp.float64)


def _arctan2_double(y, x):
    near, far = jnp.abs(y), jnp.abs(x)
    swap = near > far
    smaller, larger = jnp.minimum(near, far), jnp.maximum(near, far)
    positive = larger > 0
    scale = jnp.where(positive, _unit_scale(jnp.where(positive, larger, 1)), 1)
    smaller, larger = smaller * scale, jnp.where(positive, larger * scale, 1)
    # c by interval of a = smaller/larger: [0, 3/16), [3/16, 7/16), [7/16, 11/16), [11/16, 1], so that
    # |t| <= 3/16 and smaller - c larger is exact (Sterbenz: smaller lies within a factor 2 of c larger).
    # (0, 0) takes c = 0 and t = 0.
    interval = ((16 * smaller >= 3 * larger).astype(jnp.int32) + (16 * smaller >= 7 * larger)
                + (16 * smaller >= 11 * larger))
    centre = _select(interval, (0.0, 0.25, 0.5, 1.0))
    numerator = smaller - centre * larger
    # t = numerator/(larger + c smaller) with the rounding of the denominator and of the quotient
    # carried in t_low (TwoSum, Dekker's product), so that t is known to far below an ulp.
    denominator, denominator_low = _two_sum(larger, centre * smaller)
    t = numerator / denominator
    product, product_low = _two_product(t, denominator)
    t_low = (((numerator - product) - product_low) - t * denominator_low) / denominator
    reduced_rest = t_low + t * (t * t) * _horner(_ARCTAN_TAIL, t * t)
    negative_x = jnp.signbit(x)
    case = swap.astype(jnp.int32) + 2 * negative_x
    index = 4 * case + interval
    high = _select(index, tuple(angle[0] for angle in _OCTANT_ANGLES))
    low = _select(index, tuple(angle[1] for angle in _OCTANT_ANGLES))
    sign = jnp.where(swap == negative_x, 1.0, -1.0)
    # high + sign t with its rounding error, then the small parts: one rounding at the end.
    head, head_error = _two_sum(high, sign * t)
    angle = head + ((head_error + low) + sign * reduced_rest)
    return jnp.where(jnp.signbit(y), -angle, angle)


@jax.custom_jvp
def arctan2(y, x):
    """The angle of the point (x, y) in [-pi, pi] (DLMF 4.23.34), numpy's ``arctan2``, vectorised for
    finite float64 arguments (module note); signed zeros as IEEE 754 (arctan2(+-0, -0) = +-pi)."""
    dtype = jnp.result_type(y, x)
    y, x = jnp.broadcast_arrays(jnp.asarray(y, dtype), jnp.asarray(x, dtype))
    if not is_double(x):
        return jnp.arctan2(y, x)
    return _arctan2_double(y, x)


@arctan2.defjvp
def _arctan2_jvp(primals, tangents):
    (y, x), (dy, dx) = primals, tangents
    # The derivative JAX gives jnp.arctan2: NaN at the origin, where the angle has none.
    return arctan2(y, x), (x * dy - y * dx) / (x * x + y * y)
