r"""Legendre's elliptic integrals K, E, F, Pi through Carlson's integrals (DLMF 19.25).

Every function takes the parameter $m$ together with its complement ``mc`` $= 1 - m$: near $m = 1$
the integrals depend on $m_c$, which a caller (the rigid body) often knows to full relative precision
while ``1 - m`` of a rounded $m$ would not.  The tangent along the parameter is ``(dm - dmc)/2``,
which is ``dm`` whenever $m_c = 1 - m$ holds exactly as functions.

Amplitudes of any size are reduced to $\phi = k\pi + \phi_r$ with $|\phi_r| \le \pi/2$
(quasi-periodicity, DLMF 19.2.10): $F(\phi) = 2kK + F(\phi_r)$, $\Pi(\phi) = 2k\,\Pi(n) + \Pi(\phi_r)$.
Carlson's forms are used only on the reduced amplitude, where $\cos\phi_r \ge 0$.  The complete
$\Pi(n|m)$ of that continuation is $K(m)$ plus $R_J(0, m_c, 1, p)$ by Bulirsch's cel iteration
(``_rj_complete``: one square root and one quotient per step, where a duplication step costs four
square roots), in the values; the JVP rule takes both integrals through the Carlson functions (their
rules give the derivatives).

JVP rules (analytic, no cancellation at $m = 0$, $n = 0$ or $m = n$), with $s = \sin\phi$,
$c = \cos\phi$, $\Delta^2 = 1 - m s^2$:

- $\partial F/\partial\phi = 1/\Delta$, $\partial\Pi/\partial\phi = 1/((1 - n s^2)\Delta)$ (the
  integrands, DLMF 19.2.4-19.2.7),
- $\partial F/\partial m = \tfrac12 \int_0^\phi \sin^2\theta/\Delta^3\,d\theta = (s^3/6)\, R_D(c^2, 1, \Delta^2)$
  and $dK/dm = R_D(0, 1, m_c)/6$, $dE/dm = -R_D(0, m_c, 1)/6$ (from DLMF 19.25.1, 19.25.5 and 19.18.1),
- $\partial\Pi/\partial m$, $\partial\Pi/\partial n$: the tangent of the Carlson representation at
  fixed reduced amplitude (the Carlson functions carry their own rules).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from . import _compiled
from ._carlson import _horner, _rd, _rf, _rf_rj, _rj, _rj_parameter_largest
from ._common import complement, is_double, iterate, over_sqrt, promote


def _reduce_amplitude(phi):
    """phi = k pi + phi_r with |phi_r| <= pi/2; returns (k, sin phi_r, cos phi_r >= 0)."""
    turns = jnp.round(phi / jnp.pi)
    reduced = phi - turns * jnp.pi
    return turns, jnp.sin(reduced), jnp.abs(jnp.cos(reduced))


def _delta_squared(sin_phi, cos_phi, mc):
    # 1 - m sin^2 = cos^2 + mc sin^2: no cancellation as m -> 1 and phi -> pi/2.
    return cos_phi * cos_phi + mc * sin_phi * sin_phi


def _homogeneity(largest):
    """(t, t^(1/2)): powers of two that bring Carlson arguments up to ``largest`` down to moderate size.

    R_F is homogeneous of degree -1/2 and R_D of degree -3/2 (their integrals, DLMF 19.16.1 and
    19.16.5): R_F(x, y, z) = t^(1/2) R_F(tx, ty, tz) and R_D(x, y, z) = t^(3/2) R_D(tx, ty, tz).  For a
    huge argument (1 - m sin^2 phi for m <= -1e306, say) the duplication's last scale 4^-N/A_N falls
    below the smallest normal number, which XLA flushes to zero: the series then loses its first
    terms (relative error 1.9e-6), and R_D's A_N^(3/2) overflows (NaN).  t = 2^-400 (float64) or
    2^-64 (float32) applies only where ``largest`` exceeds 2^500 (2^64), and is exact: the duplication
    of the scaled arguments is the same arithmetic on scaled numbers, so its rounding is unchanged, and
    the smallest argument here (cos^2 phi >= 3e-33, or 0) stays normal.  Elsewhere t = 1.
    """
    big_exponent, t_exponent = (500, -400) if is_double(largest) else (64, -64)
    big = largest > 2.0**big_exponent
    return jnp.where(big, 2.0**t_exponent, 1.0), jnp.where(big, 2.0 ** (t_exponent // 2), 1.0)


def _rd_homogeneous(x, y, z):
    """R_D(x, y, z) for the derivative rules (rolled), with z the largest argument (``_homogeneity``)."""
    t, root = _homogeneity(z)
    return _rd(x * t, y * t, z * t, True) * (root * root * root)


# ------------------------------------------------------------------------------------ complete K, E


# K(m) = P(mc) - log(mc) Q(mc) and E(m) = P(mc) - mc log(mc) Q(mc) on 0 < mc <= 1 (the form of Cephes'
# ellpk and ellpe, whose logarithmic terms are those of DLMF 19.12.1-19.12.2), with degree-10
# polynomials fitted here to relative error 1.7e-18 (K) and 7e-19 (E) against mpmath (Lawson's
# iteration on 570 nodes, denser near mc = 0); highest degree first.  P(0) = ln 4, Q(0) = 1/2 (K) and
# P(0) = 1, Q(0) = 1/4 (E) as in DLMF 19.12.1-19.12.2.  Taking mc itself keeps the accuracy near m = 1.
_K_P = (
    0.00012199461596300885,
    0.0021024603629293606,
    0.00770204240322226,
    0.009983367158858069,
    0.007129239803926991,
    0.006267695510139254,
    0.008798172870398203,
    0.014938254688341316,
    0.03088514797866006,
    0.09657359028256746,
    1.3862943611198906,
)
_K_Q = (
    2.581298904233637e-05,
    0.0008310182798070543,
    0.0055946884717961946,
    0.01504654773623327,
    0.023707330763035973,
    0.030085270466142393,
    0.03737518215400317,
    0.04882798830423169,
    0.07031249945926299,
    0.12499999999971124,
    0.5,
)
_E_P = (
    0.0004658159445461919,
    0.004139984767308233,
    0.009645072330776574,
    0.009259579205601939,
    0.006600125381688035,
    0.007348292367956787,
    0.011553583076406864,
    0.021831499990835144,
    0.05680519316961054,
    0.44314718056016633,
    1.0,
)
_E_Q = (
    -8.388796711600095e-07,
    0.0001189148889893945,
    0.0020338632158478005,
    0.0091497733380019,
    0.01915135739945433,
    0.026910815567490375,
    0.03357527163908704,
    0.04272230510060842,
    0.058593724843368215,
    0.09374999993221704,
    0.24999999999997663,
)


def _complete_first(mc):
    """K(1 - mc) for 0 <= mc <= 1 (+inf at mc = 0, where log(0) = -inf)."""
    return _horner(_K_P, mc) - jnp.log(mc) * _horner(_K_Q, mc)


def _imaginary_modulus(mc):
    """(above, safe_mc, p, log p) for the complete integrals at every mc >= 0 from fits on [0, 1].

    mc > 1 (m < 0) goes through the imaginary-modulus transformation (DLMF 19.7.2, k'^2 = 1/mc):
    ``above`` marks it, ``safe_mc`` is mc there and 1 elsewhere (safe where), p = 1/mc there and mc
    elsewhere (in [0, 1], where the fits hold), and log p = -log(mc) there, which stays exact where
    1/mc is subnormal (flushed to zero).  For mc <= 1: p = mc and log p = log(mc), the operations of
    the fit alone (bit for bit).
    """
    above = mc > 1
    safe_mc = jnp.where(above, mc, 1)
    log_mc = jnp.log(mc)
    return above, safe_mc, jnp.where(above, 1 / safe_mc, mc), jnp.where(above, -log_mc, log_mc)


def _complete_first_any(mc):
    """K(1 - mc) for every mc >= 0: K(m) = mc^(-1/2) K(1 - 1/mc) for mc > 1 (``_imaginary_modulus``).

    Where 1/mc is flushed to zero the polynomials give K ~ ln(4 sqrt(mc))/sqrt(mc) (DLMF 19.12.1).
    """
    above, safe_mc, p, log_p = _imaginary_modulus(mc)
    value = _horner(_K_P, p) - log_p * _horner(_K_Q, p)
    return jnp.where(above, over_sqrt(value, safe_mc), value)


def _complete_second(mc):
    """E(1 - mc) for every mc >= 0 (E = 1 at mc = 0, +inf at mc = +inf).

    The fit holds on 0 <= mc <= 1 only (at mc = 11 it gave E(-10) = 56270 for 3.6391).  mc > 1
    (m < 0) by the imaginary-modulus transformation E(m) = mc^(1/2) E(1 - 1/mc) (DLMF 19.7.2,
    E(ik/k') = E(k)/k'; ``_imaginary_modulus``).  Where p = 1/mc is subnormal (flushed to zero) its
    term p log(p), of size below 1e-305, is lost and the polynomials give E ~ mc^(1/2), the limit of
    DLMF 19.12.2 (relative error p ln(1/p)/4).
    """
    above, safe_mc, p, log_p = _imaginary_modulus(mc)
    # p log(p) is 0 at p = 0 (mc = 0, and mc = +inf), not 0 * inf.
    p_log_p = jnp.where(p > 0, p * log_p, 0)
    value = _horner(_E_P, p) - p_log_p * _horner(_E_Q, p)
    return jnp.where(above, jnp.sqrt(safe_mc) * value, value)


@jax.custom_jvp
def _ellipk(m, mc):
    # K(1) = +inf (scipy's convention).
    return jnp.where(mc == 0, jnp.inf, _complete_first_any(mc))


@_ellipk.defjvp
def _ellipk_jvp(primals, tangents):
    m, mc = primals
    dm, dmc = tangents
    # DLMF 19.25.1 and 19.18.1: dK/dm = R_D(0, 1, mc)/6 (infinite at m = 1 only).
    derivative = _rd_homogeneous(jnp.zeros_like(mc), jnp.ones_like(mc), mc) / 6
    return _ellipk(m, mc), 0.5 * (dm - dmc) * derivative


@jax.custom_jvp
def _ellipe(m, mc):
    return _complete_second(mc)


@_ellipe.defjvp
def _ellipe_jvp(primals, tangents):
    m, mc = primals
    dm, dmc = tangents
    # DLMF 19.25.1 and 19.18.1: dE/dm = -R_D(0, mc, 1)/6.
    derivative = -_rd(jnp.zeros_like(mc), mc, jnp.ones_like(mc), True) / 6
    return _ellipe(m, mc), 0.5 * (dm - dmc) * derivative


@_compiled.one_program
def ellipk(m: ArrayLike, *, mc: ArrayLike | None = None) -> Array:
    r"""Complete elliptic integral of the first kind $K(m)$ (DLMF 19.2.8), parameter $m = k^2$.

    $$K(m) = \int_0^{\pi/2} \frac{d\theta}{\sqrt{1 - m \sin^2\theta}} = R_F(0, 1 - m, 1)$$

    (DLMF 19.25.1).  ``mc`` passes $1 - m$ directly (see the module notes).  As
    ``scipy.special.ellipk``; infinite at $m = 1$.
    """
    m, mc = complement(m, mc)
    return _ellipk(m, mc)


@_compiled.one_program
def ellipkm1(p: ArrayLike) -> Array:
    r"""$K(1 - p)$, accurate as $p \to 0$ (``scipy.special.ellipkm1``); DLMF 19.2.8, 19.25.1."""
    (p,) = promote(p)
    return _ellipk(1 - p, p)


@_compiled.one_program
def ellipe(m: ArrayLike, *, mc: ArrayLike | None = None) -> Array:
    r"""Complete elliptic integral of the second kind $E(m)$ (DLMF 19.2.8), via DLMF 19.25.1.

    $$E(m) = \int_0^{\pi/2} \sqrt{1 - m \sin^2\theta}\, d\theta$$

    As ``scipy.special.ellipe``, for every $m \le 1$: $m < 0$ by DLMF 19.7.2 (``_complete_second``);
    NaN for $m > 1$, where $E$ is complex (scipy gives NaN too).
    """
    m, mc = complement(m, mc)
    return jnp.where(mc >= 0, _ellipe(m, jnp.where(mc >= 0, mc, 0)), jnp.nan)


# ------------------------------------------------------------------------------------ incomplete F


@jax.custom_jvp
def _ellipkinc(phi, m, mc):
    turns, s, c = _reduce_amplitude(phi)
    delta2 = _delta_squared(s, c, mc)
    # R_F of the scaled arguments where 1 - m sin^2 phi is huge (m << 0: ``_homogeneity``).
    t, root = _homogeneity(delta2)
    reduced = s * (root * _rf(c * c * t, delta2 * t, t))
    # K only where a whole half-period is added: K(1) is infinite and must not meet turns = 0.
    complete = jnp.where(turns == 0, 0, 2 * turns * _ellipk(m, jnp.where(turns == 0, 1, mc)))
    return complete + reduced


@_ellipkinc.defjvp
def _ellipkinc_jvp(primals, tangents):
    phi, m, mc = primals
    dphi, dm, dmc = tangents
    value = _ellipkinc(phi, m, mc)
    turns, s, c = _reduce_amplitude(phi)
    delta2 = _delta_squared(s, c, mc)
    safe_mc = jnp.where(turns == 0, 1, mc)
    dk_dm = _rd_homogeneous(jnp.zeros_like(mc), jnp.ones_like(mc), safe_mc) / 6
    dfr_dm = s**3 * _rd_homogeneous(c * c, jnp.ones_like(s), delta2) / 6
    df_dm = jnp.where(turns == 0, 0, 2 * turns * dk_dm) + dfr_dm
    # dF/dphi = 1/Delta (DLMF 19.2.4) as t^(1/2)/sqrt(t Delta^2) (``_homogeneity``): reverse mode
    # divides the cotangent by Delta^2 first, which flushes to zero for Delta^2 > 4.5e307.
    t, root = _homogeneity(delta2)
    tangent = over_sqrt(dphi, delta2 * t) * root + 0.5 * (dm - dmc) * df_dm
    return value, tangent


@_compiled.one_program
def ellipkinc(phi: ArrayLike, m: ArrayLike, *, mc: ArrayLike | None = None) -> Array:
    r"""Incomplete elliptic integral of the first kind $F(\phi|m)$ (DLMF 19.2.4).

    $$F(\phi|m) = \int_0^\phi \frac{d\theta}{\sqrt{1 - m \sin^2\theta}}
                = \sin\phi\, R_F(\cos^2\phi, 1 - m\sin^2\phi, 1)$$

    (DLMF 19.25.5) for $|\phi| \le \pi/2$, continued to every real $\phi$ by
    $F(\phi + k\pi|m) = F(\phi|m) + 2k K(m)$ (DLMF 19.2.10).  Argument order as
    ``scipy.special.ellipkinc``.
    """
    m, mc = complement(m, mc)
    phi, m, mc = promote(phi, m, mc)
    return _ellipkinc(phi, m, mc)


# ----------------------------------------------------------------------------------- third kind Pi

# For n < -1 the parameter of R_J, 1 - n sin^2, would be far above the other arguments and slow the
# duplication; DLMF 19.7.8 (with omega = m/n) trades n for omega in (-1, 0].
_LARGE_NEGATIVE_CHARACTERISTIC = -1.0


def _pi_reduced(n, s, c, m, mc):
    """Pi(n; phi_r|m) for |phi_r| <= pi/2 from s = sin phi_r, c = cos phi_r >= 0 (see _pi_reduced_terms)."""
    head, tail = _pi_reduced_terms(n, s, c, m, mc)
    return head + tail


def _pi_reduced_terms(n, s, c, m, mc):
    """(head, tail) with Pi(n; phi_r|m) = head + tail for |phi_r| <= pi/2, s = sin phi_r, c = cos phi_r >= 0.

    For n >= -1 the head is exactly F(phi_r|m) and the tail is Pi - F (DLMF 19.25.14), which callers
    that know F by other means (the rigid body: F(am u|m) = u) use alone.

    For n >= -1:  Pi = s R_F(c^2, Delta^2, 1) + (n/3) s^3 R_J(c^2, Delta^2, 1, 1 - n s^2).
    For n < -1, DLMF 19.7.8 multiplied through by sin^4, with omega = m/n in (-1, 0]:
        Pi = s R_C(c^2 Delta^2, (1 - n s^2)(1 - omega s^2)) - (omega/3) s^3 R_J(c^2, Delta^2, 1, 1 - omega s^2);
    both terms are >= 0 for n < 0, so nothing cancels.  Both forms are one R_F (R_C(a, b) = R_F(a, b, b))
    plus one R_J, so each is evaluated once with its arguments chosen per point.
    """
    transformed, characteristic, kappa = _moved_characteristic(n, m)
    # One duplication loop gives R_F(x, y, 1) and R_J(x, y, 1, p).  For n < -1 the head
    # s R_C(c^2 Delta^2, (1 - n s^2)(1 - omega s^2)) is elementary (see ``pi_without_first_kind``):
    # arctan(sqrt(kappa) s / (c Delta)) / sqrt(kappa), kappa = (1 - n)(1 - omega); pi/2 at c = 0.
    x, y, one, p = third_kind_arguments(n, s, c, m, mc)
    first, third = _rf_rj(x, y, one, p)
    numerator, denominator = jnp.sqrt(kappa) * s, c * jnp.sqrt(y)
    positive = denominator > 0
    angle = jnp.where(
        positive, jnp.arctan(numerator / jnp.where(positive, denominator, 1)), jnp.copysign(jnp.pi / 2, numerator)
    )
    head = jnp.where(transformed, over_sqrt(angle, kappa), s * first)
    coefficient = jnp.where(transformed, -characteristic, n)
    return head, coefficient * s**3 * third / 3


def _moved_characteristic(n, m):
    """(transformed, characteristic, kappa): n < -1 moves to omega = m/n by DLMF 19.7.8 (see
    ``pi_without_first_kind``), with kappa = (1 - n)(1 - omega); n itself otherwise.

    The move needs omega < 1, i.e. m > n: a parameter m <= n < -1 (both negative) would make kappa
    <= 0 and the result NaN, so such points keep n (their terms K and (n/3) R_J cancel by at most
    the factor sqrt(1 - n) that the move avoids, and only for n far below m's -1 ... 0 range).
    The untaken branch's omega is 0, so that kappa > 0 and its derivatives stay finite."""
    transformed = (n < _LARGE_NEGATIVE_CHARACTERISTIC) & (m > n)
    n_far = jnp.where(transformed, n, 2 * _LARGE_NEGATIVE_CHARACTERISTIC)
    omega = jnp.where(transformed, m / n_far, 0)
    return transformed, jnp.where(transformed, omega, n), (1 - n_far) * (1 - omega)


def third_kind_arguments(n, s, c, m, mc):
    """(x, y, z, p) of the one R_J(x, y, z, p) of ``pi_without_first_kind``: (c^2, Delta^2, 1, 1 - n' s^2),
    n' the characteristic after DLMF 19.7.8.  x, y, z are those of F(phi_r|m) = s R_F(x, y, z)."""
    _, characteristic, _ = _moved_characteristic(n, m)
    x, y = c * c, _delta_squared(s, c, mc)
    return x, y, jnp.ones_like(x), 1 - characteristic * s * s


def pi_without_first_kind_from(n, s, c, m, mc, third):
    """``pi_without_first_kind`` from ``third`` = R_J(*third_kind_arguments(n, s, c, m, mc)), for a
    caller that computes it together with other Carlson integrals (one duplication loop)."""
    transformed, characteristic, kappa = _moved_characteristic(n, m)
    y = _delta_squared(s, c, mc)
    head = jnp.where(transformed, over_sqrt(jnp.arctan2(jnp.sqrt(kappa) * s, c * jnp.sqrt(y)), kappa), 0)
    tail = characteristic * s**3 * third / 3
    return head + jnp.where(transformed, -tail, tail)


def pi_without_first_kind(n, s, c, m, mc):
    """Pi(n; phi_r|m) - F(phi_r|m) for -1 <= n <= 0, Pi(n; phi_r|m) itself for n < -1; |phi_r| <= pi/2.

    For callers that know F(phi_r|m) by other means (the rigid body: F(am u|m) = u): one R_J and no
    R_F.  For -1 <= n <= 0, DLMF 19.25.14: Pi - F = (n/3) s^3 R_J(c^2, Delta^2, 1, 1 - n s^2).  For
    n < -1, the head of DLMF 19.7.8 (see ``_pi_reduced_terms``) is elementary: with
    omega = m/n and kappa = (1 - n)(1 - omega), (1 - n s^2)(1 - omega s^2) - c^2 Delta^2 = kappa s^2,
    so s R_C(c^2 Delta^2, (1 - n s^2)(1 - omega s^2)) = atan2(sqrt(kappa) s, c Delta)/sqrt(kappa)
    (DLMF 19.2.18), and Pi = that - (omega/3) s^3 R_J(c^2, Delta^2, 1, 1 - omega s^2).  In both cases
    the parameter of R_J is the largest argument (n, omega <= 0), which has a cheaper duplication.
    """
    third = _rj_parameter_largest(*third_kind_arguments(n, s, c, m, mc))
    return pi_without_first_kind_from(n, s, c, m, mc, third)


def _pi_complete(n, m, mc):
    head, tail = _pi_reduced_terms(n, jnp.ones_like(m), jnp.zeros_like(m), m, mc)
    # For n >= -1 the head is R_F(0, mc, 1) = K(m): the same polynomial as ellipk, so that
    # Pi(0|m) = K(m) to the last bit (mc = 0 keeps the head: K is infinite there).
    first_kind = (n >= _LARGE_NEGATIVE_CHARACTERISTIC) & (mc > 0)
    head = jnp.where(first_kind, _ellipk(m, jnp.where(first_kind, mc, 1)), head)
    return head + tail


# Iterations of Bulirsch's algorithm (``_rj_complete``) per dtype: it converges quadratically from the
# first step, and 13 (float64) or 8 (float32) steps give full precision for every mc down to the
# smallest subnormal (measured against mpmath for p from 1e-6 to 1e3: 8e-16 and 2e-10 relative).
def _cel_steps(x):
    return 13 if is_double(x) else 8


def _rj_complete(mc, p):
    r"""R_J(0, mc, 1, p) for 0 < mc <= 1 and p > 0, by Bulirsch's algorithm for cel (DLMF 19.2.11).

    .. math:: \mathrm{cel}(k_c, p, a, b) = \int_0^{\pi/2}
              \frac{a \cos^2\theta + b \sin^2\theta}{(\cos^2\theta + p \sin^2\theta)
              \sqrt{\cos^2\theta + k_c^2 \sin^2\theta}}\, d\theta

    With p = 1 - n, cos^2 + p sin^2 = 1 - n sin^2, so n cel(sqrt(mc), p, 0, 1) = Pi(n|m) - K(m)
    = (n/3) R_J(0, mc, 1, p) (DLMF 19.25.2), i.e. R_J(0, mc, 1, p) = 3 cel(sqrt(mc), p, 0, 1).
    R. Bulirsch, Numer. Math. 13 (1969) 305-315 (the AGM-like iteration of DLMF 19.8.6 for the
    general complete integral; its p > 0 case): a fixed number of steps (``_cel_steps``), each one
    square root and one quotient, where the duplication of R_J costs four square roots and an R_C.
    Values only (the derivative rules use the Carlson functions).
    """
    root_p = jnp.sqrt(p)
    a, b = jnp.zeros_like(p), root_p / p  # b / sqrt(p) with b = 1, written without a quotient by a root
    qc = jnp.sqrt(mc)

    def step(_, state):
        a, b, p, e, em, qc = state
        inverse = 1 / p
        f = a
        a = a + b * inverse
        g = e * inverse
        b = 2 * (b + f * g)
        p = p + g
        em = em + qc
        qc = 2 * jnp.sqrt(e)
        return a, b, p, qc * em, em, qc

    a, b, p, _, em, _ = iterate(step, (a, b, root_p, qc, jnp.ones_like(p), qc), _cel_steps(p), p)
    return 1.5 * jnp.pi * (b + a * em) / (em * (em + p))


@jax.custom_jvp
def rj_complete(mc, p):
    """R_J(0, mc, 1, p) for 0 < mc <= 1 and p > 0: the value by Bulirsch's cel iteration
    (``_rj_complete``), the derivatives from R_J's rule (the tangent of its duplication)."""
    return _rj_complete(mc, p)


@rj_complete.defjvp
def _rj_complete_jvp(primals, tangents):
    mc, p = primals
    zero, one = jnp.zeros_like(mc), jnp.ones_like(mc)
    # x = 0 and z = 1 are constants of the closure: R_J's rule then carries the two directions alone.
    _, tangent = jax.jvp(lambda mc, p: _rj(zero, mc, one, p), (mc, p), tangents)
    return rj_complete(mc, p), tangent


def _pi_complete_values(n, m, mc):
    """Pi(n|m) for n <= 1 and 0 <= mc <= 1 (values only; infinite at mc = 0 where n >= -1).

    The terms of ``_pi_reduced_terms`` at phi_r = pi/2 (s = 1, c = 0): K(m) + (n/3) R_J(0, mc, 1, 1 - n)
    for n >= -1, pi/(2 sqrt(kappa)) - (omega/3) R_J(0, mc, 1, 1 - omega) for n < -1 (DLMF 19.7.8), the
    complete R_J by ``_rj_complete`` and K by its polynomial (so that Pi(0|m) = K(m) to the last bit).
    """
    transformed, characteristic, kappa = _moved_characteristic(n, m)
    positive = mc > 0
    safe_mc = jnp.where(positive, mc, 1)
    head = jnp.where(transformed, over_sqrt(jnp.pi / 2, kappa), _ellipk(m, mc))
    third = jnp.where(positive, _rj_complete(safe_mc, 1 - characteristic), jnp.inf)
    coefficient = jnp.where(transformed, -characteristic, n)
    return head + coefficient * third / 3


def _pi_continued(n, turns, s, c, m, mc):
    """2 turns Pi(n|m) + Pi(n; phi_r|m) (DLMF 19.2.10), values only: the complete integral by
    ``_pi_complete_values`` (a fraction of the cost of a second Carlson evaluation)."""
    safe_mc = jnp.where(turns == 0, 1, mc)
    complete = _pi_complete_values(n, m, safe_mc)
    return jnp.where(turns == 0, 0, 2 * turns * complete) + _pi_reduced(n, s, c, m, mc)


def _pi_continued_stacked(n, turns, s, c, m, mc):
    """2 turns Pi(n|m) + Pi(n; phi_r|m) (DLMF 19.2.10) through the Carlson functions, for the JVP rule.

    The complete and the reduced integral go through the Carlson functions together (stacked on a new
    leading axis): one rule and one loop of partial derivatives instead of two, which halves the
    compiled code of the gradient.
    """
    safe_mc = jnp.where(turns == 0, 1, mc)
    stack = lambda reduced, complete: jnp.stack(jnp.broadcast_arrays(reduced, complete))  # noqa: E731
    values = _pi_reduced(
        stack(n, n), stack(s, jnp.ones_like(s)), stack(c, jnp.zeros_like(c)), stack(m, m), stack(mc, safe_mc)
    )
    return jnp.where(turns == 0, 0, 2 * turns * values[1]) + values[0]


@jax.custom_jvp
def _ellippiinc(n, phi, m, mc):
    turns, s, c = _reduce_amplitude(phi)
    return _pi_continued(n, turns, s, c, m, mc)


@_ellippiinc.defjvp
def _ellippiinc_jvp(primals, tangents):
    n, phi, m, mc = primals
    dn, dphi, dm, dmc = tangents
    turns, s, c = _reduce_amplitude(phi)
    delta2 = _delta_squared(s, c, mc)
    dparam = 0.5 * (dm - dmc)

    def at_fixed_amplitude(n_, m_, mc_):
        return _pi_continued_stacked(n_, turns, s, c, m_, mc_)

    value, tangent_nm = jax.jvp(at_fixed_amplitude, (n, m, mc), (dn, dparam, -dparam))
    # DLMF 19.2.7 integrand.
    tangent_phi = dphi / ((1 - n * s * s) * jnp.sqrt(delta2))
    return value, tangent_nm + tangent_phi


@_compiled.one_program
def ellippiinc(n: ArrayLike, phi: ArrayLike, m: ArrayLike, *, mc: ArrayLike | None = None) -> Array:
    r"""Incomplete elliptic integral of the third kind (DLMF 19.2.7, characteristic $n$, parameter $m$).

    $$\Pi(n; \phi|m) = \int_0^\phi \frac{d\theta}{(1 - n\sin^2\theta)\sqrt{1 - m\sin^2\theta}}$$

    for $n \le 1$ ($n > 1$, a principal value, gives NaN) and every real $\phi$, continued by
    $\Pi(n; \phi + k\pi|m) = \Pi(n; \phi|m) + 2k\,\Pi(n|m)$.  On $|\phi| \le \pi/2$, DLMF 19.25.14
    with $s = \sin\phi$, $c = \cos\phi$, $\Delta^2 = 1 - m s^2$:

    $$\Pi(n; \phi|m) = s\, R_F(c^2, \Delta^2, 1) + \tfrac{n}{3} s^3 R_J(c^2, \Delta^2, 1, 1 - n s^2);$$

    for $n < -1$ the characteristic is first moved into $(-1, 0]$ by DLMF 19.7.8.  The argument order
    $(n, \phi, m)$ is that of Mathematica's EllipticPi and Boost's ellint_3.
    """
    m, mc = complement(m, mc)
    n, phi, m, mc = promote(n, phi, m, mc)
    valid = n <= 1
    result = _ellippiinc(jnp.where(valid, n, 0), phi, m, mc)
    return jnp.where(valid, result, jnp.nan)


@jax.custom_jvp
def _ellippi(n, m, mc):
    return _pi_complete(n, m, mc)


@_ellippi.defjvp
def _ellippi_jvp(primals, tangents):
    n, m, mc = primals
    dn, dm, dmc = tangents
    dparam = 0.5 * (dm - dmc)
    return jax.jvp(_pi_complete, (n, m, mc), (dn, dparam, -dparam))


@_compiled.one_program
def ellippi(n: ArrayLike, m: ArrayLike, *, mc: ArrayLike | None = None) -> Array:
    r"""Complete elliptic integral of the third kind $\Pi(n|m) = \Pi(n; \pi/2|m)$ (DLMF 19.2.8), $n < 1$.

    $$\Pi(n|m) = R_F(0, m_c, 1) + \tfrac{n}{3} R_J(0, m_c, 1, 1 - n), \qquad m_c = 1 - m$$

    (DLMF 19.25.2), with DLMF 19.7.8 for $n < -1$.
    """
    m, mc = complement(m, mc)
    n, m, mc = promote(n, m, mc)
    valid = n < 1
    result = _ellippi(jnp.where(valid, n, 0), m, mc)
    return jnp.where(valid, result, jnp.nan)
