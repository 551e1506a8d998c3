"""Carlson's symmetric elliptic integrals R_F, R_D, R_J, R_C for real arguments (DLMF 19.16).

Evaluation is Carlson's duplication algorithm (B. C. Carlson, "Numerical computation of real or complex
elliptic integrals", Numer. Algorithms 10 (1995) 13-26; DLMF 19.36.1-19.36.2) with a *fixed* number of
duplication steps chosen per dtype, followed by the Taylor series of DLMF 19.36.1 and 19.36.2 up to
seventh order.  A fixed count keeps everything a straight-line XLA program (jit, vmap, reverse mode).

Each duplication step shrinks the relative spread of the arguments by a factor 4 and the series error
is the eighth power of that spread, so ``_steps`` steps give full precision whenever the arguments
differ by less than about 4**(_steps - 5) relative to their mean limit; the counts below cover
ratios down to 1e-300 (checked against mpmath in tests/special/test_carlson.py).

Derivatives (custom JVP rules):
- R_F: DLMF 19.18.1, dR_F/dz = -R_D(x, y, z)/6 (and symmetrically).
- R_C = R_F(x, y, y): dR_C/dx = -R_D(y, y, x)/6, dR_C/dy = -R_D(x, y, y)/3.
- R_D and R_J: the tangent of the duplication recurrence itself.  Every duplication step is an exact
  identity (DLMF 19.26.18-19.26.20), so its derivative is exact, and the derivative of the truncated
  series converges at the same rate as the series.  The partial derivatives in each argument come out
  of one forward pass (``_value_and_partials``), so that the rule is linear in the tangents with no
  loop in its linear part: reverse mode then never transposes a duplication loop.  A partial derivative with respect to an argument
  that is exactly zero is infinite; there the tangent of that argument is ignored (documented
  convention), so no NaN reaches the caller.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax

from .._fusion import materialise
from ._common import is_double, promote


def _steps(x) -> int:
    # 12 steps: spread 2 * 4**-12 / (A_N/A_0) <= 1e-2 even when A_N/A_0 is 1e-5 (the worst case, two
    # arguments 1e-300 below the third); the 7th-order series then leaves < 1e-16.
    return 12 if is_double(x) else 7


def _sqrt_for_tangents(x):
    """sqrt whose derivative at 0 is taken as 0 (see the module note on zero arguments)."""
    return _safe_sqrt(x)


@jax.custom_jvp
def _safe_sqrt(x):
    return jnp.sqrt(x)


@_safe_sqrt.defjvp
def _safe_sqrt_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    root = jnp.sqrt(x)
    inverse_twice_root = jnp.where(x > 0, 0.5 / jnp.where(x > 0, root, 1), 0)
    return root, dx * inverse_twice_root


# ---------------------------------------------------------------------------------------------- R_F


def _rf_series(x, y, z, steps):
    mean0 = (x + y + z) / 3
    dx0, dy0 = mean0 - x, mean0 - y

    def duplicate(_, state):
        x, y, z, mean = state
        sx, sy, sz = _sqrt_for_tangents(x), _sqrt_for_tangents(y), _sqrt_for_tangents(z)
        lam = sx * (sy + sz) + sy * sz
        return (x + lam) / 4, (y + lam) / 4, (z + lam) / 4, (mean + lam) / 4

    # A rolled loop: XLA compiles one duplication step instead of `steps` copies (compile time).
    x, y, z, mean = lax.fori_loop(0, steps, duplicate, (x, y, z, mean0))
    # DLMF 19.36.1 with X = 1 - x_N/A_N computed without cancellation as (A_0 - x_0) / (4^N A_N).
    scale = 0.25**steps / mean
    big_x, big_y = dx0 * scale, dy0 * scale
    big_z = -(big_x + big_y)
    e2 = big_x * big_y - big_z * big_z
    e3 = big_x * big_y * big_z
    series = (
        1
        - e2 / 10
        + e3 / 14
        + e2 * e2 / 24
        - 3 * e2 * e3 / 44
        - 5 * e2**3 / 208
        + 3 * e3 * e3 / 104
        + e2 * e2 * e3 / 16
    )
    return series / jnp.sqrt(mean)


@jax.custom_jvp
def _rf(x, y, z):
    return _rf_series(x, y, z, _steps(x))


@_rf.defjvp
def _rf_jvp(primals, tangents):
    x, y, z = primals
    dx, dy, dz = tangents
    value = _rf(x, y, z)
    # DLMF 19.18.1: dR_F/dz = -R_D(x, y, z)/6, and by symmetry for x and y.  The three R_D go through
    # one duplication loop, stacked on a new leading axis (a third of the compiled code).
    x, y, z = jnp.broadcast_arrays(x, y, z)
    rd_x, rd_y, rd_z = _rd(jnp.stack([y, z, x]), jnp.stack([z, x, y]), jnp.stack([x, y, z]))
    tangent = -(_masked(dx, x, rd_x) + _masked(dy, y, rd_y) + _masked(dz, z, rd_z)) / 6
    return value, tangent


def _masked(tangent, argument, partial):
    """``tangent * partial`` with the zero-argument convention of the module note."""
    return tangent * jnp.where(argument > 0, partial, 0)


# ---------------------------------------------------------------------------------------------- R_J


def _rc_one_plus(e, w):
    """R_C(1, w) with w = 1 + e > 0, both given accurately (DLMF 19.2.18-19.2.20).

    arctan(sqrt e)/sqrt e for e > 0; artanh(sqrt -e)/sqrt -e for e < 0, with artanh(r) written as
    log1p(2r(1 + r)/w)/2 so that w -> 0 (e -> -1) loses nothing; the Maclaurin series near e = 0.
    """
    small = jnp.abs(e) < 2.0**-10
    # Series sum_k (-e)^k / (2k + 1), truncated where |e|^8/17 is below float64 precision.
    series = 1 + e * (
        -1 / 3 + e * (1 / 5 + e * (-1 / 7 + e * (1 / 9 + e * (-1 / 11 + e * (1 / 13 + e * (-1 / 15))))))
    )
    root = jnp.sqrt(jnp.abs(jnp.where(small, 1, e)))
    safe_w = jnp.where(small, 1, w)
    atanh = 0.5 * jnp.log1p(2 * root * (1 + root) / safe_w)
    closed = jnp.where(e > 0, jnp.arctan(root), atanh) / root
    return jnp.where(small, series, closed)


def _rc_one_plus_nonnegative(e):
    """R_C(1, 1 + e) = arctan(sqrt e)/sqrt e for e >= 0 (DLMF 19.2.18), the series near e = 0."""
    small = e < 2.0**-10
    series = 1 + e * (
        -1 / 3 + e * (1 / 5 + e * (-1 / 7 + e * (1 / 9 + e * (-1 / 11 + e * (1 / 13 + e * (-1 / 15))))))
    )
    root = jnp.sqrt(jnp.where(small, 1, e))
    return jnp.where(small, series, jnp.arctan(root) / root)


def _rj_series(x, y, z, p, steps, parameter_largest=False):
    mean0 = (x + y + z + 2 * p) / 5
    dx0, dy0, dz0 = mean0 - x, mean0 - y, mean0 - z
    px0, py0, pz0 = p - x, p - y, p - z

    def duplicate(_, state):
        x, y, z, p, mean, correction, quarter_power = state
        sx, sy, sz = _sqrt_for_tangents(x), _sqrt_for_tangents(y), _sqrt_for_tangents(z)
        sp = _sqrt_for_tangents(p)
        lam = sx * (sy + sz) + sy * sz
        d = (sp + sx) * (sp + sy) * (sp + sz)
        # e_k = 4^{-3k} (p-x)(p-y)(p-z) / d_k^2 (Carlson 1995, eq. (2.19)), written as a product of three
        # ratios in (-1, 1) so that nothing overflows; it shrinks about 64-fold per step.
        ratio_x = quarter_power * px0 / ((sp + sx) * (sp + sx))
        ratio_y = quarter_power * py0 / ((sp + sy) * (sp + sy))
        ratio_z = quarter_power * pz0 / ((sp + sz) * (sp + sz))
        e = ratio_x * ratio_y * ratio_z
        # 1 + e without cancellation when e -> -1: write each ratio as sign * (1 - t) with
        # t = 1 - |ratio| = 2 min(sqrt p, sqrt x_j)/(sqrt p + sqrt x_j), computed without subtraction.
        if not parameter_largest:
            tx = 2 * jnp.minimum(sp, sx) / (sp + sx)
            ty = 2 * jnp.minimum(sp, sy) / (sp + sy)
            tz = 2 * jnp.minimum(sp, sz) / (sp + sz)
        if parameter_largest:
            # p >= x, y, z: every ratio and e are >= 0, and R_C(1, 1 + e) is an arctangent.
            correction = correction + quarter_power * _rc_one_plus_nonnegative(e) / d
        else:
            one_minus_product = tx + ty + tz - (tx * ty + tx * tz + ty * tz) + tx * ty * tz
            one_plus_e = jnp.where(e < 0, one_minus_product, 1 + e)
            correction = correction + quarter_power * _rc_one_plus(e, one_plus_e) / d
        x, y, z, p = (x + lam) / 4, (y + lam) / 4, (z + lam) / 4, (p + lam) / 4
        return x, y, z, p, (mean + lam) / 4, correction, quarter_power / 4

    zero = jnp.zeros_like(mean0)
    state = (x, y, z, p, mean0, zero, jnp.ones_like(mean0))
    x, y, z, p, mean, correction, _ = lax.fori_loop(0, steps, duplicate, state)
    scale = 0.25**steps / mean
    big_x, big_y, big_z = dx0 * scale, dy0 * scale, dz0 * scale
    big_p = -(big_x + big_y + big_z) / 2
    p2 = big_p * big_p
    e2 = big_x * big_y + big_x * big_z + big_y * big_z - 3 * p2
    e3 = big_x * big_y * big_z + 2 * e2 * big_p + 4 * p2 * big_p
    e4 = (2 * big_x * big_y * big_z + e2 * big_p + 3 * p2 * big_p) * big_p
    e5 = big_x * big_y * big_z * p2
    # DLMF 19.36.2 (Carlson 1995, eq. (2.7)), terms through seventh order.
    series = (
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
    return (0.25**steps) * series / (mean * jnp.sqrt(mean)) + 6 * correction


def _rd_series(x, y, z, steps):
    mean0 = (x + y + 3 * z) / 5
    dx0, dy0 = mean0 - x, mean0 - y

    def duplicate(_, state):
        x, y, z, mean, correction, quarter_power = state
        sx, sy, sz = _sqrt_for_tangents(x), _sqrt_for_tangents(y), _sqrt_for_tangents(z)
        lam = sx * (sy + sz) + sy * sz
        correction = correction + quarter_power / (sz * (z + lam))
        x, y, z = (x + lam) / 4, (y + lam) / 4, (z + lam) / 4
        return x, y, z, (mean + lam) / 4, correction, quarter_power / 4

    state = (x, y, z, mean0, jnp.zeros_like(mean0), jnp.ones_like(mean0))
    x, y, z, mean, correction, _ = lax.fori_loop(0, steps, duplicate, state)
    scale = 0.25**steps / mean
    big_x, big_y = dx0 * scale, dy0 * scale
    big_z = -(big_x + big_y) / 3
    # R_D = R_J(x, y, z, z): the R_J series with P = Z (DLMF 19.36.2).
    xy, z2 = big_x * big_y, big_z * big_z
    e2 = xy - 6 * z2
    e3 = (3 * xy - 8 * z2) * big_z
    e4 = 3 * (xy - z2) * z2
    e5 = xy * z2 * big_z
    series = (
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
    return (0.25**steps) * series / (mean * jnp.sqrt(mean)) + 3 * correction


@jax.custom_jvp
def _rd(x, y, z):
    return _rd_series(x, y, z, _steps(x))


def _value_and_partials(function, primals):
    """The value of an elementwise ``function`` and its partial derivatives in each argument.

    One forward-mode pass with a tangent per argument (vmapped, so the duplication loop runs once).
    A JVP rule built on these partials is linear in the tangents with no loop in its linear part, so
    reverse mode does not transpose the duplication loop (which would multiply the compile time).
    """
    primals = jnp.broadcast_arrays(*primals)
    basis = jnp.eye(len(primals), dtype=primals[0].dtype)

    def directional(unit):
        tangents = tuple(jnp.full_like(value, unit[i]) for i, value in enumerate(primals))
        return jax.jvp(function, tuple(primals), tangents)

    values, partials = jax.vmap(directional)(basis)
    # Materialised: each partial feeds its own product with a tangent (and, in reverse mode, with a
    # cotangent), and XLA would otherwise recompute the whole series in each of those fused loops.
    return materialise((values[0], partials))


def _jvp_from_partials(function, primals, tangents):
    value, partials = _value_and_partials(function, primals)
    return value, sum(partials[i] * tangent for i, tangent in enumerate(tangents))


@_rd.defjvp
def _rd_jvp(primals, tangents):
    steps = _steps(primals[0])
    return _jvp_from_partials(lambda a, b, c: _rd_series(a, b, c, steps), primals, tangents)


@jax.custom_jvp
def _rj(x, y, z, p):
    return _rj_series(x, y, z, p, _steps(x))


@_rj.defjvp
def _rj_jvp(primals, tangents):
    steps = _steps(primals[0])
    return _jvp_from_partials(lambda a, b, c, d: _rj_series(a, b, c, d, steps), primals, tangents)


@jax.custom_jvp
def _rj_parameter_largest(x, y, z, p):
    """R_J(x, y, z, p) for p >= max(x, y, z) (no logarithmic branch: see ``_rj_series``)."""
    return _rj_series(x, y, z, p, _steps(x), parameter_largest=True)


@_rj_parameter_largest.defjvp
def _rj_parameter_largest_jvp(primals, tangents):
    steps = _steps(primals[0])
    return _jvp_from_partials(lambda a, b, c, d: _rj_series(a, b, c, d, steps, True), primals, tangents)


# ---------------------------------------------------------------------------------------------- R_C


def _rc_series(x, y, steps):
    mean0 = (x + 2 * y) / 3
    dy0 = y - mean0

    def duplicate(_, state):
        x, y, mean = state
        lam = 2 * jnp.sqrt(x) * jnp.sqrt(y) + y
        return (x + lam) / 4, (y + lam) / 4, (mean + lam) / 4

    x, y, mean = lax.fori_loop(0, steps, duplicate, (x, y, mean0))
    s = dy0 * (0.25**steps) / mean
    # DLMF 19.36.8 (Carlson 1995, eq. (2.13)).
    series = 1 + s * s * (
        3 / 10 + s * (1 / 7 + s * (3 / 8 + s * (9 / 22 + s * (159 / 208 + s * (9 / 8)))))
    )
    return series / jnp.sqrt(mean)


@jax.custom_jvp
def _rc_positive(x, y):
    return _rc_series(x, y, _steps(x))


@_rc_positive.defjvp
def _rc_positive_jvp(primals, tangents):
    x, y = primals
    dx, dy = tangents
    value = _rc_positive(x, y)
    # R_C(x, y) = R_F(x, y, y) and DLMF 19.18.1; both R_D in one loop.
    x, y = jnp.broadcast_arrays(x, y)
    rd_x, rd_y = _rd(jnp.stack([y, x]), jnp.stack([y, y]), jnp.stack([x, y]))
    tangent = -_masked(dx, x, rd_x) / 6 - dy * rd_y / 3
    return value, tangent


# ------------------------------------------------------------------------------------- public names


def elliprf(x, y, z):
    r"""Carlson's symmetric integral of the first kind (DLMF 19.16.1).

    .. math:: R_F(x, y, z) = \tfrac12 \int_0^\infty \frac{dt}{\sqrt{(t+x)(t+y)(t+z)}}

    for x, y, z >= 0 with at most one of them zero.  Same name and arguments as
    ``scipy.special.elliprf``.  Duplication algorithm, DLMF 19.36.1.
    """
    x, y, z = promote(x, y, z)
    return _rf(x, y, z)


def elliprd(x, y, z):
    r"""Carlson's degenerate integral of the second kind (DLMF 19.16.5).

    .. math:: R_D(x, y, z) = \tfrac32 \int_0^\infty \frac{dt}{\sqrt{(t+x)(t+y)}\,(t+z)^{3/2}}

    for x, y >= 0 (at most one zero) and z > 0.  As ``scipy.special.elliprd``.
    """
    x, y, z = promote(x, y, z)
    return _rd(x, y, z)


# Above this ratio p / max(x, y, z) the duplication would need many more steps to bring p down to the
# other arguments (lambda does not involve p); DLMF 19.21.12 then trades p for a parameter q close to
# max(x, y, z).
_LARGE_PARAMETER_RATIO = 16.0


def _rj_any_parameter(x, y, z, p):
    low = jnp.minimum(jnp.minimum(x, y), z)
    high = jnp.maximum(jnp.maximum(x, y), z)
    middle = jnp.maximum(jnp.minimum(x, y), jnp.minimum(jnp.maximum(x, y), z))
    large = p > _LARGE_PARAMETER_RATIO * high
    direct = _rj(x, y, z, jnp.where(large, high, p))
    # DLMF 19.21.12 with the largest argument as pivot z:
    #   (p - z) R_J(x, y, z, p) + (q - z) R_J(x, y, z, q) = 3 R_F(x, y, z) - 3 R_C(xy/z, pq/z),
    #   (p - z)(q - z) = (x - z)(y - z);  every term is positive, so nothing cancels.
    p_large = jnp.where(large, p, 2 * high)
    q_minus_high = (low - high) / (p_large - high) * (middle - high)  # no overflow
    q = high + q_minus_high
    transformed = (
        3 * _rf(low, middle, high)
        # R_C is homogeneous of degree -1/2: scale by the largest argument so that p q cannot overflow.
        - 3 * _rc_positive((low / high) * (middle / high), (p_large / high) * (q / high)) / jnp.sqrt(high)
        - q_minus_high * _rj(low, middle, high, q)
    ) / (p_large - high)
    return jnp.where(large, transformed, direct)


def elliprj(x, y, z, p):
    r"""Carlson's symmetric integral of the third kind (DLMF 19.16.2).

    .. math:: R_J(x, y, z, p) = \tfrac32 \int_0^\infty \frac{dt}{\sqrt{(t+x)(t+y)(t+z)}\,(t+p)}

    for x, y, z >= 0 (at most one zero) and p > 0; p <= 0 (a Cauchy principal value in scipy) gives NaN
    here.  As ``scipy.special.elliprj`` otherwise.  When p is much larger than x, y and z the change
    of parameter DLMF 19.21.12 keeps the duplication short.
    """
    x, y, z, p = promote(x, y, z, p)
    valid = p > 0
    result = _rj_any_parameter(x, y, z, jnp.where(valid, p, 1))
    return jnp.where(valid, result, jnp.nan)


def elliprc(x, y):
    r"""Carlson's degenerate integral R_C(x, y) = R_F(x, y, y) (DLMF 19.2.17, 19.16.6).

    For x >= 0, y != 0.  For y < 0 the Cauchy principal value
    R_C(x, y) = sqrt(x/(x - y)) R_C(x - y, -y) (DLMF 19.6.16), as ``scipy.special.elliprc``.
    """
    x, y = promote(x, y)
    positive = y > 0
    # Safe-where: each branch is evaluated at arguments that are valid for it.
    x_pos = jnp.where(positive, x, 1)
    y_pos = jnp.where(positive, y, 1)
    x_neg = jnp.where(positive, 1, x - y)
    y_neg = jnp.where(positive, 1, -y)
    principal = jnp.sqrt(jnp.where(positive, 1, x) / x_neg) * _rc_positive(x_neg, y_neg)
    return jnp.where(positive, _rc_positive(x_pos, y_pos), principal)
