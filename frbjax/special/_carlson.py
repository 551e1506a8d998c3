r"""Carlson's symmetric elliptic integrals $R_F$, $R_D$, $R_J$, $R_C$ for real arguments (DLMF 19.16).

R_F, R_D and R_J: Carlson's duplication algorithm (B. C. Carlson, "Numerical computation of real or
complex elliptic integrals", Numer. Algorithms 10 (1995) 13-26; DLMF 19.36.1-19.36.2), followed by the
Taylor series of DLMF 19.36.1 and 19.36.2 up to seventh order.

Each duplication step is an exact identity that shrinks the relative spread of the arguments by a
factor 4, and the seventh-order series errs by about the eighth power of that spread.  At most a
fixed number of steps per dtype (``_plan``: 12 in float64, enough for argument ratios down to
1e-300) are taken.  Over an array the steps are unrolled, so that XLA fuses them into vectorized
passes over the points, in blocks (``_plan``): the first always, each later one only when some
point of the batch still needs it (Carlson's stopping rule, spread below 2^-8): arguments within a
few per cent of each other, such as the third-kind integral over a short step, need 2 steps,
far-apart ones all 12 (``_duplicate``).  One point or a few use a rolled loop of every step, masked
at each point's own convergence, and the derivative rules a rolled loop of every step (one compiled
step: compile time; ``_common.rolled``).  R_F and R_J of the same x, y, z share one loop
(``_rf_rj``).  In R_J's step, R_C(1, 1 + e_k) (Carlson 1995, eq. (2.19)) costs a square root and a
polynomial; a logarithm only serves the points with 1 + e_k < 1/2.

$R_C$ has closed forms (DLMF 19.2.18-19.2.19): an arctangent for $x < y$, a logarithm for $x > y$, and
its Maclaurin series in $(y - x)/x$ near $x = y$.

Nowhere a quotient by a square root: XLA turns it into rsqrt, whose float64 CPU code is scalar and
de-vectorizes the fused loop around it (``_common.over_sqrt``).

Derivatives (custom JVP rules):

- $R_F$: DLMF 19.18.1, $\partial R_F/\partial z = -R_D(x, y, z)/6$ (and symmetrically).
- $R_C = R_F(x, y, y)$: $\partial R_C/\partial x = -R_D(y, y, x)/6$,
  $\partial R_C/\partial y = -R_D(x, y, y)/3$.
- $R_D$ and $R_J$: the tangent of the duplication recurrence itself.  Every duplication step is an exact
  identity (DLMF 19.26.18-19.26.20), so its derivative is exact, and the derivative of the truncated
  series converges at the same rate as the series.  The partial derivatives in each argument come out
  of one forward pass (``_value_and_partials``), so that the rule is linear in the tangents with no
  loop in its linear part: reverse mode then never transposes a duplication loop.  A partial derivative with
  respect to an argument
  that is exactly zero is infinite; there the tangent of that argument is ignored (documented
  convention), so no NaN reaches the caller.

Every rule is differentiable again (forward or reverse over forward or reverse), with the same
convention at every order: an argument that is exactly zero is frozen (``_frozen_at_zero``, every
derivative with respect to it is 0), a partial derivative that is masked there is evaluated at a
harmless point (``_positive_or_one``), and the square roots of the rules' loops are safe-where square
roots (``_safe_sqrt``), so that no 0 * inf appears in a second derivative.  The second derivatives
come from JAX differentiating the rules themselves: the derivative of the R_D of the R_F rule through
R_D's rule, and the partial derivatives of R_D and R_J from the tangent of their rolled loops.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import Array, lax
from jax.custom_derivatives import SymbolicZero
from jax.typing import ArrayLike

from .._fusion import materialise, when_any
from . import _compiled
from ._common import is_double, over_sqrt, promote, rolled as is_rolled


def _plan(x):
    """(steps, spread threshold, the first blocks of steps over an array) of the duplication, per
    dtype (see the module note).

    float64: 12 steps bring the spread below 2^-8 for argument ratios down to 1e-300, where the
    seventh-order series errs by about 0.1 spread^8 < 1e-17.  float32: 7 steps (spread 2^-5, 1e-13).
    Over an array the steps come in blocks, the first always taken and each later one (the last
    holding the remaining steps) only when some point needs it (``_duplicate``): 2 steps serve
    spreads up to 1/16 (the third-kind integral of a short step), 4 spreads up to 1.
    """
    return (12, 2.0**-8, (2, 2)) if is_double(x) else (7, 2.0**-5, (2, 1))


def _duplicate(step, state, x, rolled=False, deviation=None):
    """Apply duplication ``step(state, q)`` (q = 4^-k at step k) until the spread is small; returns
    (state, 4^-N) with N the steps taken, per point.

    ``deviation(state)`` gives, per point, pairs (Q, A_k) of the relative spread's numerator and
    denominator, one pair per series the loop serves: Q = max |A_0 - x_0| over the arguments, A_k the
    mean after k steps, and the spread 4^-k Q / A_k (Carlson 1995, eq. (2.4)).  Over an array the
    steps are unrolled (fused passes over the points) in ``_plan``'s blocks, each block after the
    first taken only when some point of the batch needs it (a conditional, ``_fusion.when_any``).
    In the first blocks a point takes no further step once its spread is at most ``_plan``'s
    threshold (Carlson's stopping rule), so that in a batch that needs no more, its value depends on
    its own arguments only; the last block (the remaining steps, for batches with far-apart
    arguments) steps every point, unmasked, as a fixed count did: masks in that long fused chain
    made such batches 1.3 times slower.  Further steps are identities of the exact integral, so a
    point's value in such a batch differs by rounding only.  One point or a few: a rolled loop of
    every step, masked.  The derivative rules' loops (``rolled=True``) take every step: a loop JAX
    can transpose, and partial derivatives whose series converge more slowly than the value's.
    """
    steps, threshold, first = _plan(x)

    def converged(carry):
        quarter, state = carry
        done = True
        for spread, mean in deviation(state):
            done = done & (quarter * spread <= threshold * mean)
        return done

    def body(_, carry):
        quarter, state = carry
        done = converged(carry)
        stepped = step(state, quarter)
        state = jax.tree.map(lambda kept, new: jnp.where(done, kept, new), state, stepped)
        return jnp.where(done, quarter, quarter / 4), state

    def unmasked(_, carry):
        quarter, state = carry
        return quarter / 4, step(state, quarter)

    if rolled:
        # The rules' loops: every step, so that the partial derivatives (whose series converge a
        # power of the spread more slowly than the value's) keep the fixed count's accuracy.
        quarter, state = lax.fori_loop(0, steps, unmasked, (jnp.asarray(1.0, x.dtype), state))
        return state, quarter
    carry = (jnp.ones_like(x), state)
    if is_rolled(x):
        # One point or a few: a rolled loop of every step, masked (the same steps, hence the same
        # values, as the unrolled blocks below).
        quarter, state = lax.fori_loop(0, steps, body, carry)
    else:
        # Unrolled in blocks: the first always, each later one only when some point needs it.  The
        # last block takes its steps at every point, unmasked: masks in a long fused chain cost XLA
        # a kernel per step (a batch that needs every step ran 1.3 times slower masked).
        taken = 0
        blocks = [size for size in first + (steps - sum(first),) if size]
        for index, size in enumerate(blocks):
            one_step = unmasked if index == len(blocks) - 1 and index > 0 else body

            def block(carry, start=taken, size=size, one_step=one_step):
                for k in range(start, start + size):
                    carry = one_step(k, carry)
                return carry

            carry = block(carry) if taken == 0 else when_any(~converged(carry), block, lambda c: c, carry)
            taken += size
        quarter, state = carry
    return state, quarter


@jax.custom_jvp
def _safe_sqrt(x):
    """sqrt(x) for the derivative rules' loops: its derivatives of every order at x = 0 are 0 (the
    convention of the module note).  The value is a safe where, so that even differentiated as
    written (which JAX may do in a composition of modes) nothing is infinite; the rule is the same
    derivative with one product per tangent (compile time of the loops' tangents)."""
    positive = x > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, x, 1)), 0)


@_safe_sqrt.defjvp
def _safe_sqrt_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    root = _safe_sqrt(x)
    positive = x > 0
    return root, dx * jnp.where(positive, 0.5 / jnp.where(positive, root, 1), 0)


def _sqrt_for(rolled):
    """The square root of the duplication: plain in the values, ``_safe_sqrt`` in the rules' loops."""
    return _safe_sqrt if rolled else jnp.sqrt


def _rf_polynomial(big_x, big_y):
    """DLMF 19.36.1 through seventh order, X + Y + Z = 0."""
    big_z = -(big_x + big_y)
    e2 = big_x * big_y - big_z * big_z
    e3 = big_x * big_y * big_z
    return (
        1
        - e2 / 10
        + e3 / 14
        + e2 * e2 / 24
        - 3 * e2 * e3 / 44
        - 5 * e2**3 / 208
        + 3 * e3 * e3 / 104
        + e2 * e2 * e3 / 16
    )


def _rj_polynomial(e2, e3, e4, e5):
    """DLMF 19.36.2 (Carlson 1995, eq. (2.7)), terms through seventh order."""
    return (
        1
        - 3 * e2 / 14
        + e3 / 6
        + 9 * e2 * e2 / 88
        - 3 * e4 / 22
        - 9 * e2 * e3 / 52
        + 3 * e5 / 26
        - e2**3 / 16
        + 3 * e3 * e3 / 40
        + 3 * e2 * e4 / 20
        + 45 * e2 * e2 * e3 / 272
        - 9 * (e3 * e4 + e2 * e5) / 68
    )


def _largest_magnitude(*deviations):
    """max |d| over the deviations A_0 - x_0 of the arguments (Carlson's Q)."""
    largest = jnp.abs(deviations[0])
    for deviation in deviations[1:]:
        largest = jnp.maximum(largest, jnp.abs(deviation))
    return largest


def _lambda(x, y, z, sqrt):
    sx, sy, sz = sqrt(x), sqrt(y), sqrt(z)
    return sx * (sy + sz) + sy * sz, (sx, sy, sz)


# ---------------------------------------------------------------------------------------------- R_F


def _rf_series(x, y, z, rolled=False):
    mean0 = (x + y + z) / 3
    dx0, dy0 = mean0 - x, mean0 - y
    spread0 = _largest_magnitude(dx0, dy0, mean0 - z)

    def step(state, _):
        x, y, z, mean = state
        lam, _ = _lambda(x, y, z, _sqrt_for(rolled))
        return (x + lam) / 4, (y + lam) / 4, (z + lam) / 4, (mean + lam) / 4

    (x, y, z, mean), quarter = _duplicate(step, (x, y, z, mean0), x, rolled, lambda state: ((spread0, state[3]),))
    # DLMF 19.36.1 with X = 1 - x_N/A_N computed without cancellation as (A_0 - x_0) / (4^N A_N).
    scale = quarter / mean
    return over_sqrt(_rf_polynomial(dx0 * scale, dy0 * scale), mean)


@jax.custom_jvp
def _rf(x, y, z):
    return _rf_series(x, y, z)


def _rf_tangent(x, y, z, dx, dy, dz):
    # DLMF 19.18.1: dR_F/dz = -R_D(x, y, z)/6, and by symmetry for x and y.  The three R_D go through
    # one duplication loop, stacked on a new leading axis (a third of the compiled code).  R_D(x, y, z)
    # is infinite at z = 0: evaluated at z = 1 there and masked (``_masked``).
    x, y, z = (_frozen_at_zero(a) for a in jnp.broadcast_arrays(x, y, z))
    rd_x, rd_y, rd_z = _rd(
        jnp.stack([y, z, x]),
        jnp.stack([z, x, y]),
        jnp.stack([_positive_or_one(x), _positive_or_one(y), _positive_or_one(z)]),
        True,
    )
    return -(_masked(dx, x, rd_x) + _masked(dy, y, rd_y) + _masked(dz, z, rd_z)) / 6


@_rf.defjvp
def _rf_jvp(primals, tangents):
    return _rf(*primals), _rf_tangent(*primals, *tangents)


def _frozen_at_zero(argument):
    """``argument``, with every derivative taken as 0 where it is zero: the zero-argument convention of
    the module note at every order (a rule's partial derivatives in the other arguments then do not
    depend on it there either, so that second derivatives are symmetric)."""
    return jnp.where(argument > 0, argument, lax.stop_gradient(argument))


def _positive_or_one(argument):
    """``argument`` where it is positive, 1 where it is zero: where a partial derivative is masked
    (``_masked``) it is evaluated at this harmless point, so that its own derivatives are finite there
    too (the safe-where pattern: a where alone would give 0 * inf = NaN one derivative later)."""
    return jnp.where(argument > 0, argument, 1)


def _masked(tangent, argument, partial):
    """``tangent * partial`` with the zero-argument convention of the module note.

    ``partial`` must be finite, with finite derivatives, where ``argument`` is zero (computed at
    ``_positive_or_one`` of it, or in a loop with ``_safe_sqrt``).
    """
    return tangent * jnp.where(argument > 0, partial, 0)


# ---------------------------------------------------------------------------------------------- R_J

# R_C(1, 1 + e) = 2F1(1/2, 1; 3/2; -e) for |e| <= 0.1716: the degree-15 Chebyshev interpolant on that
# interval (mpmath), error 7e-19; highest degree first.
_RC_POLYNOMIAL = (
    -0.035845454157110504,
    0.0382860515301367,
    -0.036861807914879065,
    0.03981424818905601,
    -0.043482670645682224,
    0.04762372192420984,
    -0.052631517733447486,
    0.05882346452803347,
    -0.0666666671270696,
    0.07692307741107116,
    -0.09090909090739277,
    0.11111111110931124,
    -0.14285714285714524,
    0.20000000000000254,
    -0.3333333333333333,
    1.0,
)


def _horner(coefficients, x):
    result = coefficients[0]
    for c in coefficients[1:]:
        result = result * x + c
    return result


def _rc_one_plus(w, logarithm=True, log=None):
    """R_C(1, w) for 0 < w <= 2 (DLMF 19.2.18-19.2.20), w given accurately (w = 1 + e_k in R_J).

    For w >= 1/2 one duplication step of R_C itself: with a = sqrt(w),
    R_C(1, w) = 2/(1 + a) R_C(1, 1 + e') with e' = (w - 1)/(1 + a)^2 = (a - 1)/(a + 1) in
    [-0.1716, 0.1716], where a polynomial takes over (no arctangent; an absolute error of e' of an ulp
    moves R_C by a third of that).  For w < 1/2 (only when ``logarithm``): artanh(r)/r with
    r = sqrt(1 - w), written as log1p(2r(1 + r)/w)/2 so that w -> 0 loses nothing.
    Everything is a function of w alone: XLA then fuses it into the surrounding duplication.  ``log``
    is the logarithm for that branch (default ``_log_above_one``).
    """
    a = jnp.sqrt(w)
    inverse = 1 / (1 + a)
    value = 2 * _horner(_RC_POLYNOMIAL, (a - 1) * inverse) * inverse
    if not logarithm:
        return value
    near = w < 0.5
    minus_e = jnp.where(near, 1 - w, 1)
    # artanh(r)/r = log((1 + r)^2/w)/(2r) with r = sqrt(1 - w); the second square root of 1 - w is
    # written sqrt(4(1 - w))/2 (exact) so that XLA keeps it apart: a value of an expensive operation
    # used twice is not fused, and materializing it every step costs more than a square root.
    root = jnp.sqrt(minus_e)
    argument = (1 + root) * (1 + root) / jnp.where(near, w, 1)  # >= 5.8: no cancellation in the log
    value_near = (log or _log_above_one)(argument) * (jnp.sqrt(4 * minus_e) / 4) / minus_e
    return jnp.where(near, value_near, value)


_RC_DERIVATIVE = tuple((len(_RC_POLYNOMIAL) - 1 - k) * c for k, c in enumerate(_RC_POLYNOMIAL[:-1]))


@jax.custom_jvp
def _rc_one_plus_rolled(w):
    """``_rc_one_plus`` for the rules' loops (XLA's logarithm), with the derivative in w as one
    product per tangent: the tangents of the duplication then carry no polynomial (compile time)."""
    return _rc_one_plus(w, log=jnp.log)


@_rc_one_plus_rolled.defjvp
def _rc_one_plus_rolled_jvp(primals, tangents):
    (w,), (dw,) = primals, tangents
    value = _rc_one_plus_rolled(w)
    # w >= 1/2: value = 2 P(u) i, i = 1/(1 + a), u = (a - 1) i, a = sqrt(w); du/da = 2 i^2,
    # di/da = -i^2 and da/dw = a/(2w), so d value/dw = i^2 (2 i P'(u) - P(u)) a / w.
    a = jnp.sqrt(w)
    inverse = 1 / (1 + a)
    u = (a - 1) * inverse
    polynomial = inverse * inverse * (2 * inverse * _horner(_RC_DERIVATIVE, u) - _horner(_RC_POLYNOMIAL, u)) * a / w
    # w < 1/2: R_C(1, w) = artanh(r)/r, r = sqrt(1 - w), whose derivative is (R_C - 1/w)/(2(1 - w))
    # (both terms positive apart, 1 - w > 1/2: no cancellation).
    near = w < 0.5
    minus_e = jnp.where(near, 1 - w, 1)
    logarithmic = (value - 1 / jnp.where(near, w, 1)) / (2 * minus_e)
    return value, dw * jnp.where(near, logarithmic, polynomial)


# log(f) = 2 artanh(u) = 2u sum_k u^(2k)/(2k + 1), u = (f - 1)/(f + 1), |u| <= 0.1716 for
# f in [sqrt(1/2), sqrt(2)): terms through u^22 (error 0.1716^24/25 < 1e-19); highest degree first.
_ARTANH_SERIES = tuple(1 / (2 * k + 1) for k in range(11, -1, -1))
_LOG2_HIGH = 0.693145751953125  # ln 2 to 17 bits: k * _LOG2_HIGH is exact for |k| < 2^36
_LOG2_LOW = 1.4286068203094172e-06


@jax.custom_jvp
def _log_above_one(x):
    """log(x) for finite x >= 1, to about an ulp, in vectorizable arithmetic (derivative 1/x).

    XLA's float64 logarithm costs as much as six square roots on CPU; here x = 2^k f with f in
    [sqrt(1/2), sqrt(2)) from the bits of x (the exponent read as a float through 2^52 + k, no
    integer-to-float conversion), then log f by the artanh series.  float32 uses jnp.log.
    """
    if not is_double(x):
        return jnp.log(x)
    bits = lax.bitcast_convert_type(x, jnp.int64)
    exponent = lax.bitcast_convert_type((bits >> 52) | 0x4330000000000000, jnp.float64) - (2.0**52 + 1023)
    fraction = lax.bitcast_convert_type((bits & 0x000FFFFFFFFFFFFF) | 0x3FF0000000000000, jnp.float64)
    high = fraction > 1.4142135623730951
    fraction = jnp.where(high, 0.5 * fraction, fraction)
    exponent = jnp.where(high, exponent + 1, exponent)
    u = (fraction - 1) * (1 / (fraction + 1))
    return exponent * _LOG2_HIGH + (exponent * _LOG2_LOW + 2 * u * _horner(_ARTANH_SERIES, u * u))


@_log_above_one.defjvp
def _log_above_one_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    return _log_above_one(x), dx / x


def _rf_rj_series(x, y, z, p, parameter_largest=False, rolled=False, with_rf=True):
    """(R_F(x, y, z), R_J(x, y, z, p)) from one duplication of x, y, z (the same for both); without
    ``with_rf`` the steps stop when R_J's series has converged (R_F's value is then not used)."""
    mean0 = (x + y + z + 2 * p) / 5
    dx0, dy0, dz0 = mean0 - x, mean0 - y, mean0 - z
    px0, py0, pz0 = p - x, p - y, p - z
    spread0 = _largest_magnitude(dx0, dy0, dz0, mean0 - p)
    # e_k < 0 (an odd number of arguments above p) is decided by the inputs alone.
    negative = (px0 < 0) ^ (py0 < 0) ^ (pz0 < 0)
    mean_f0 = (x + y + z) / 3
    fx0, fy0 = mean_f0 - x, mean_f0 - y
    spread_f0 = _largest_magnitude(fx0, fy0, mean_f0 - z)

    def deviation(state):
        pairs = ((spread0, state[4]),)
        return pairs + ((spread_f0, state[5]),) if with_rf else pairs

    def step(state, quarter):
        x, y, z, p, mean, mean_f, correction = state
        lam, (sx, sy, sz) = _lambda(x, y, z, _sqrt_for(rolled))
        sp = _sqrt_for(rolled)(p)
        ix, iy, iz = 1 / (sp + sx), 1 / (sp + sy), 1 / (sp + sz)
        # e_k = 4^{-3k} (p-x)(p-y)(p-z) / d_k^2 (Carlson 1995, eq. (2.19)), d_k = (sp+sx)(sp+sy)(sp+sz),
        # as a product of three ratios (sp - sx)/(sp + sx) in (-1, 1), each from the exact difference
        # 4^-k (p_0 - x_0) = p_k - x_k, so that nothing overflows or cancels.
        ratio_x = quarter * px0 * ix * ix
        ratio_y = quarter * py0 * iy * iy
        ratio_z = quarter * pz0 * iz * iz
        e = ratio_x * ratio_y * ratio_z
        if parameter_largest:
            # p >= x, y, z: every ratio and e are >= 0, and R_C(1, 1 + e) is an arctangent.
            rc = _rc_one_plus_rolled(1 + e) if rolled else _rc_one_plus(1 + e, logarithm=False)
        else:
            # 1 + e without cancellation when e -> -1: each ratio is sign * (1 - t) with
            # t = 1 - |ratio| = 2 min(sqrt p, sqrt x_j)/(sqrt p + sqrt x_j), computed without subtraction.
            tx = 2 * jnp.minimum(sp, sx) * ix
            ty = 2 * jnp.minimum(sp, sy) * iy
            tz = 2 * jnp.minimum(sp, sz) * iz
            one_minus_product = tx + ty + tz - (tx * ty + tx * tz + ty * tz) + tx * ty * tz
            w = jnp.where(negative, one_minus_product, 1 + e)
            if rolled:
                # The accurate value, with the tangent of 1 + e (the same function): the rules' loops
                # then carry no tangents of t_x, t_y, t_z (compile time).
                w = (1 + e) + lax.stop_gradient(w - (1 + e))
            rc = _rc_one_plus_rolled(w) if rolled else _rc_one_plus(w)
        correction = correction + (quarter * rc) * (ix * iy * iz)
        x, y, z, p = (x + lam) / 4, (y + lam) / 4, (z + lam) / 4, (p + lam) / 4
        return x, y, z, p, (mean + lam) / 4, (mean_f + lam) / 4, correction

    state = (x, y, z, p, mean0, mean_f0, jnp.zeros_like(mean0))
    (x, y, z, p, mean, mean_f, correction), quarter = _duplicate(step, state, x, rolled, deviation)
    scale = quarter / mean
    big_x, big_y, big_z = dx0 * scale, dy0 * scale, dz0 * scale
    big_p = -(big_x + big_y + big_z) / 2
    p2 = big_p * big_p
    e2 = big_x * big_y + big_x * big_z + big_y * big_z - 3 * p2
    e3 = big_x * big_y * big_z + 2 * e2 * big_p + 4 * p2 * big_p
    e4 = (2 * big_x * big_y * big_z + e2 * big_p + 3 * p2 * big_p) * big_p
    e5 = big_x * big_y * big_z * p2
    rj = quarter * _rj_polynomial(e2, e3, e4, e5) / (mean * jnp.sqrt(mean)) + 6 * correction
    scale_f = quarter / mean_f
    rf = over_sqrt(_rf_polynomial(fx0 * scale_f, fy0 * scale_f), mean_f)
    return rf, rj


def _rj_series(x, y, z, p, parameter_largest=False, rolled=False):
    return _rf_rj_series(x, y, z, p, parameter_largest, rolled, with_rf=False)[1]


def _rd_series(x, y, z, rolled=False):
    mean0 = (x + y + 3 * z) / 5
    dx0, dy0 = mean0 - x, mean0 - y
    spread0 = _largest_magnitude(dx0, dy0, mean0 - z)

    def step(state, quarter):
        x, y, z, mean, correction = state
        lam, (_, _, sz) = _lambda(x, y, z, _sqrt_for(rolled))
        correction = correction + quarter / (sz * (z + lam))
        return (x + lam) / 4, (y + lam) / 4, (z + lam) / 4, (mean + lam) / 4, correction

    state = (x, y, z, mean0, jnp.zeros_like(mean0))
    (x, y, z, mean, correction), quarter = _duplicate(step, state, x, rolled, lambda state: ((spread0, state[3]),))
    scale = quarter / mean
    big_x, big_y = dx0 * scale, dy0 * scale
    big_z = -(big_x + big_y) / 3
    # R_D = R_J(x, y, z, z): the R_J series with P = Z (DLMF 19.36.2).
    xy, z2 = big_x * big_y, big_z * big_z
    e2 = xy - 6 * z2
    e3 = (3 * xy - 8 * z2) * big_z
    e4 = 3 * (xy - z2) * z2
    e5 = xy * z2 * big_z
    series = _rj_polynomial(e2, e3, e4, e5)
    return quarter * series / (mean * jnp.sqrt(mean)) + 3 * correction


@functools.partial(jax.custom_jvp, nondiff_argnums=(3,))
def _rd(x, y, z, rolled=False):
    """R_D; ``rolled`` (for derivative rules) compiles one duplication step instead of all."""
    return _rd_series(x, y, z, rolled)


def _value_and_partials(function, primals, varying):
    """The value of an elementwise ``function`` and its partial derivatives in the arguments at the
    positions ``varying`` (a leading axis in that order; the other arguments are held fixed).

    One forward-mode pass with a tangent per varying argument (vmapped, so the duplication loop runs
    once).  A JVP rule built on these partials is linear in the tangents with no loop in its linear
    part, so reverse mode does not transpose the duplication loop (which would multiply the compile
    time).  The rules pass only the arguments whose tangents are not symbolic zeros (``_varying``):
    inside ellippiinc's rule, for one, R_J's x and z are fixed, and the loop carries two directions.
    """
    primals = tuple(jnp.broadcast_arrays(*primals))
    basis = jnp.eye(len(varying), dtype=primals[0].dtype)

    def restricted(*moving):
        arguments = list(primals)
        for i, argument in zip(varying, moving):
            arguments[i] = argument
        return function(*arguments)

    def directional(unit):
        tangents = tuple(jnp.full_like(primals[i], unit[k]) for k, i in enumerate(varying))
        return jax.jvp(restricted, tuple(primals[i] for i in varying), tangents)

    values, partials = jax.vmap(directional)(basis)
    # Materialised: each partial feeds its own product with a tangent (and, in reverse mode, with a
    # cotangent), and XLA would otherwise recompute the whole series in each of those fused loops.
    return materialise((jax.tree.map(lambda v: v[0], values), partials))


def _varying(tangents):
    """Positions of the tangents that are not symbolic zeros (rules with ``symbolic_zeros=True``)."""
    return tuple(i for i, tangent in enumerate(tangents) if not isinstance(tangent, SymbolicZero))


def _jvp_from_partials(function, primals, tangents, may_vanish):
    """The JVP of ``function`` (one array or a tuple of them) from its partials; the arguments at the
    positions ``may_vanish`` may be zero, where their tangents are ignored (module note: the partial
    there comes out finite through ``_safe_sqrt``, but is not the derivative)."""
    varying = _varying(tangents)
    primals = tuple(_frozen_at_zero(a) if i in may_vanish else a for i, a in enumerate(primals))
    if not varying:
        value = function(*primals)
        return value, jax.tree.map(jnp.zeros_like, value)
    value, partials = _value_and_partials(function, primals, varying)

    def tangent(partial):
        return sum(
            _masked(tangents[i], primals[i], partial[k]) if i in may_vanish else partial[k] * tangents[i]
            for k, i in enumerate(varying)
        )

    return value, jax.tree.map(tangent, partials)


@functools.partial(_rd.defjvp, symbolic_zeros=True)
def _rd_jvp(rolled, primals, tangents):
    return _jvp_from_partials(lambda a, b, c: _rd_series(a, b, c, True), primals, tangents, (0, 1))


def _rj_rolled(x, y, z, p, parameter_largest=False):
    return _rj_series(x, y, z, p, parameter_largest, True)


@jax.custom_jvp
def _rj(x, y, z, p):
    return _rj_series(x, y, z, p)


@functools.partial(_rj.defjvp, symbolic_zeros=True)
def _rj_jvp(primals, tangents):
    return _jvp_from_partials(_rj_rolled, primals, tangents, (0, 1, 2))


@jax.custom_jvp
def _rf_unrolled(x, y, z):
    """R_F with every duplication step taken and unrolled (one fused pass, the same bits for a point
    in any batch), its JVP rule from the partials of a rolled loop (like ``_rf_rj``'s): for the rigid
    body's several R_F of one stacked call."""
    return _rf_series(x, y, z)


@functools.partial(_rf_unrolled.defjvp, symbolic_zeros=True)
def _rf_unrolled_jvp(primals, tangents):
    return _jvp_from_partials(lambda a, b, c: _rf_series(a, b, c, True), primals, tangents, (0, 1, 2))


@jax.custom_jvp
def _rf_rj(x, y, z, p):
    """(R_F(x, y, z), R_J(x, y, z, p)) from one duplication loop."""
    return _rf_rj_series(x, y, z, p)


@functools.partial(_rf_rj.defjvp, symbolic_zeros=True)
def _rf_rj_jvp(primals, tangents):
    # Both partial derivatives from one rolled duplication loop (its tangent, as for R_J alone).
    series = lambda a, b, c, d: _rf_rj_series(a, b, c, d, rolled=True)  # noqa: E731
    return _jvp_from_partials(series, primals, tangents, (0, 1, 2))


@jax.custom_jvp
def _rj_parameter_largest(x, y, z, p):
    """R_J(x, y, z, p) for p >= max(x, y, z) (no logarithmic branch: see ``_rf_rj_series``)."""
    return _rj_series(x, y, z, p, True)


@functools.partial(_rj_parameter_largest.defjvp, symbolic_zeros=True)
def _rj_parameter_largest_jvp(primals, tangents):
    return _jvp_from_partials(lambda a, b, c, d: _rj_rolled(a, b, c, d, True), primals, tangents, (0, 1, 2))


# ---------------------------------------------------------------------------------------------- R_C


def _rc_closed(x, y):
    """R_C(x, y) for x >= 0, y > 0 in closed form (DLMF 19.2.18-19.2.19), the series near x = y.

    x < y:  arctan(sqrt((y - x)/x)) / sqrt(y - x)  (x = 0 gives pi/(2 sqrt y));
    x > y:  log1p((sqrt(x - y) + (x - y)/(sqrt x + sqrt y)) / sqrt y) / sqrt(x - y), the argument of
            log1p being (sqrt x + sqrt(x - y))/sqrt y - 1 written without cancellation;
    |y - x| < 2^-10 x:  x^(-1/2) sum_k (-e)^k/(2k + 1), e = (y - x)/x (DLMF 19.2.18 as a series).
    y - x is exact where the series is not used and x, y are within a factor 2 (Sterbenz).
    """
    difference = y - x
    e = difference / jnp.where(x > 0, x, 1)
    small = (jnp.abs(e) < 2.0**-10) & (x > 0)
    magnitude = jnp.abs(jnp.where(small, 1, difference))
    root = jnp.sqrt(magnitude)
    sx, sy = jnp.sqrt(x), jnp.sqrt(y)
    above = jnp.arctan(jnp.sqrt(magnitude / jnp.where(x > 0, x, 0)))
    below = jnp.log1p((root + magnitude / (sx + sy)) / sy)
    series = 1 + e * (-1 / 3 + e * (1 / 5 + e * (-1 / 7 + e * (1 / 9 + e * (-1 / 11 + e * (1 / 13 + e * (-1 / 15)))))))
    # Divisions by square roots as products (see ``over_sqrt``).
    closed = jnp.where(difference > 0, above, below) * root / magnitude
    return jnp.where(small, series * sx / jnp.where(small, x, 1), closed)


@jax.custom_jvp
def _rc_positive(x, y):
    return _rc_closed(x, y)


@_rc_positive.defjvp
def _rc_positive_jvp(primals, tangents):
    x, y = primals
    dx, dy = tangents
    value = _rc_positive(x, y)
    # R_C(x, y) = R_F(x, y, y) and DLMF 19.18.1; both R_D in one loop.
    x, y = jnp.broadcast_arrays(_frozen_at_zero(x), y)
    rd_x, rd_y = _rd(jnp.stack([y, x]), jnp.stack([y, y]), jnp.stack([_positive_or_one(x), y]), True)
    tangent = -_masked(dx, x, rd_x) / 6 - dy * rd_y / 3
    return value, tangent


# ------------------------------------------------------------------------------------- public names


@_compiled.one_program
def elliprf(x: ArrayLike, y: ArrayLike, z: ArrayLike) -> Array:
    r"""Carlson's symmetric integral of the first kind (DLMF 19.16.1).

    $$R_F(x, y, z) = \tfrac12 \int_0^\infty \frac{dt}{\sqrt{(t+x)(t+y)(t+z)}}$$

    for $x, y, z \ge 0$ with at most one of them zero.  Same name and arguments as
    ``scipy.special.elliprf``.  Duplication algorithm, DLMF 19.36.1.
    """
    x, y, z = promote(x, y, z)
    if _compiled.selected(x):
        return _compiled.elliprf(x, y, z)
    return _rf(x, y, z)


@_compiled.one_program
def elliprd(x: ArrayLike, y: ArrayLike, z: ArrayLike) -> Array:
    r"""Carlson's degenerate integral of the second kind (DLMF 19.16.5).

    $$R_D(x, y, z) = \tfrac32 \int_0^\infty \frac{dt}{\sqrt{(t+x)(t+y)}\,(t+z)^{3/2}}$$

    for $x, y \ge 0$ (at most one zero) and $z > 0$.  As ``scipy.special.elliprd``.
    """
    x, y, z = promote(x, y, z)
    if _compiled.selected(x):
        return _compiled.elliprd(x, y, z)
    return _rd(x, y, z)


# Above this ratio p / max(x, y, z) the duplication would need many more steps to bring p down to the
# other arguments (lambda does not involve p); DLMF 19.21.12 then trades p for a parameter q close to
# max(x, y, z).
_LARGE_PARAMETER_RATIO = 16.0


def _rj_transform(x, y, z, p):
    """The arguments of DLMF 19.21.12: (low, middle, high, large, p_large, q_minus_high, q)."""
    low = jnp.minimum(jnp.minimum(x, y), z)
    high = jnp.maximum(jnp.maximum(x, y), z)
    middle = jnp.maximum(jnp.minimum(x, y), jnp.minimum(jnp.maximum(x, y), z))
    large = p > _LARGE_PARAMETER_RATIO * high
    p_large = jnp.where(large, p, 2 * high)
    q_minus_high = (low - high) / (p_large - high) * (middle - high)  # no overflow
    return low, middle, high, large, p_large, q_minus_high, high + q_minus_high


def _rj_any_parameter(x, y, z, p):
    low, middle, high, large, p_large, q_minus_high, q = _rj_transform(x, y, z, p)
    direct = _rj(x, y, z, jnp.where(large, high, p))
    # DLMF 19.21.12 with the largest argument as pivot z:
    #   (p - z) R_J(x, y, z, p) + (q - z) R_J(x, y, z, q) = 3 R_F(x, y, z) - 3 R_C(xy/z, pq/z),
    #   (p - z)(q - z) = (x - z)(y - z);  every term is positive, so nothing cancels.
    transformed = (
        3 * _rf(low, middle, high)
        # R_C is homogeneous of degree -1/2: scale by the largest argument so that p q cannot overflow.
        - 3 * over_sqrt(_rc_positive((low / high) * (middle / high), (p_large / high) * (q / high)), high)
        - q_minus_high * _rj(low, middle, high, q)
    ) / (p_large - high)
    return jnp.where(large, transformed, direct)


@jax.custom_jvp
def _rj_general(x, y, z, p):
    """R_J for every p > 0: one duplication loop gives the R_F and R_J of both cases of DLMF 19.21.12."""
    low, middle, high, large, p_large, q_minus_high, q = _rj_transform(x, y, z, p)
    rf, rj = _rf_rj(low, middle, high, jnp.where(large, q, p))
    # R_C(a, b) with b > a here (p q > x y): the arctangent form, no series needed.
    a, b = (low / high) * (middle / high), (p_large / high) * (q / high)
    rc = over_sqrt(jnp.arctan(jnp.sqrt((b - a) / a)), (b - a) * high)
    transformed = (3 * rf - 3 * rc - q_minus_high * rj) / (p_large - high)
    return jnp.where(large, transformed, rj)


@_rj_general.defjvp
def _rj_general_jvp(primals, tangents):
    # A zero x, y or z is frozen (module note): DLMF 19.21.12 would otherwise carry the tangent of a zero
    # argument through q into finite terms of a derivative that is infinite.
    def frozen(x, y, z, p):
        return _rj_any_parameter(_frozen_at_zero(x), _frozen_at_zero(y), _frozen_at_zero(z), p)

    return jax.jvp(frozen, primals, tangents)


@_compiled.one_program
def elliprj(x: ArrayLike, y: ArrayLike, z: ArrayLike, p: ArrayLike) -> Array:
    r"""Carlson's symmetric integral of the third kind (DLMF 19.16.2).

    $$R_J(x, y, z, p) = \tfrac32 \int_0^\infty \frac{dt}{\sqrt{(t+x)(t+y)(t+z)}\,(t+p)}$$

    for $x, y, z \ge 0$ (at most one zero) and $p > 0$; $p \le 0$ (a Cauchy principal value in
    scipy) gives NaN here.  As ``scipy.special.elliprj`` otherwise.  When $p$ is much larger than
    $x$, $y$ and $z$ the change of parameter DLMF 19.21.12 keeps the duplication short.
    """
    x, y, z, p = promote(x, y, z, p)
    if _compiled.selected(x):
        return _compiled.elliprj(x, y, z, p)
    valid = p > 0
    result = _rj_general(x, y, z, jnp.where(valid, p, 1))
    return jnp.where(valid, result, jnp.nan)


@_compiled.one_program
def elliprc(x: ArrayLike, y: ArrayLike) -> Array:
    r"""Carlson's degenerate integral $R_C(x, y) = R_F(x, y, y)$ (DLMF 19.2.17, 19.16.6).

    $$R_C(x, y) = \tfrac12 \int_0^\infty \frac{dt}{\sqrt{t+x}\,(t+y)}$$

    for $x \ge 0$, $y \ne 0$.  For $y < 0$ the Cauchy principal value
    $R_C(x, y) = \sqrt{x/(x - y)}\, R_C(x - y, -y)$ (DLMF 19.6.16), as ``scipy.special.elliprc``;
    NaN for $x < 0$ (as scipy).
    """
    x, y = promote(x, y)
    if _compiled.selected(x):
        return _compiled.elliprc(x, y)
    positive = y > 0
    # One evaluation, its arguments chosen per point.
    factor = jnp.sqrt(jnp.where(positive, 1, x / jnp.where(positive, 1, x - y)))  # safe at x = 0
    value = factor * _rc_positive(jnp.where(positive, x, x - y), jnp.where(positive, y, -y))
    return jnp.where(x >= 0, value, jnp.nan)
