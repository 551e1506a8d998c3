"""Legendre's elliptic integrals K, E, F, Pi through Carlson's integrals (DLMF 19.25).

Every function takes the parameter m together with its complement ``mc = 1 - m``: near m = 1 the
integrals depend on mc, which a caller (the rigid body) often knows to full relative precision while
``1 - m`` of a rounded m would not.  The tangent along the parameter is ``(dm - dmc)/2``, which is
``dm`` whenever mc = 1 - m holds exactly as functions.

Amplitudes of any size are reduced to ``phi = k pi + phi_r`` with ``|phi_r| <= pi/2``
(quasi-periodicity, DLMF 19.2.10): F(phi) = 2k K + F(phi_r), Pi(phi) = 2k Pi(n) + Pi(phi_r).  Carlson's
forms are used only on the reduced amplitude, where cos(phi_r) >= 0.

JVP rules (analytic, no cancellation at m = 0, n = 0 or m = n):
- dF/dphi = 1/Delta, dPi/dphi = 1/((1 - n sin^2 phi) Delta) (the integrands, DLMF 19.2.4-19.2.7),
- dF/dm = (1/2) int_0^phi sin^2/Delta^3 = (s^3/6) R_D(c^2, 1, Delta^2) and dK/dm = R_D(0, 1, mc)/6,
  dE/dm = -R_D(0, mc, 1)/6 (from DLMF 19.25.1, 19.25.5 and 19.18.1),
- dPi/dm, dPi/dn: the tangent of the Carlson representation at fixed reduced amplitude (the Carlson
  functions carry their own rules).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ._carlson import _rd, _rf, _rj, _rj_parameter_largest
from ._common import complement, promote


def _reduce_amplitude(phi):
    """phi = k pi + phi_r with |phi_r| <= pi/2; returns (k, sin phi_r, cos phi_r >= 0)."""
    turns = jnp.round(phi / jnp.pi)
    reduced = phi - turns * jnp.pi
    return turns, jnp.sin(reduced), jnp.abs(jnp.cos(reduced))


def _delta_squared(sin_phi, cos_phi, mc):
    # 1 - m sin^2 = cos^2 + mc sin^2: no cancellation as m -> 1 and phi -> pi/2.
    return cos_phi * cos_phi + mc * sin_phi * sin_phi


# ------------------------------------------------------------------------------------ complete K, E


@jax.custom_jvp
def _ellipk(m, mc):
    # K(1) = R_F(0, 0, 1) = +inf (scipy's convention); the duplication alone would stop at a finite value.
    value = _rf(jnp.zeros_like(mc), mc, jnp.ones_like(mc))
    return jnp.where(mc == 0, jnp.inf, value)


@_ellipk.defjvp
def _ellipk_jvp(primals, tangents):
    m, mc = primals
    dm, dmc = tangents
    # DLMF 19.25.1 and 19.18.1: dK/dm = R_D(0, 1, mc)/6 (infinite at m = 1 only).
    derivative = _rd(jnp.zeros_like(mc), jnp.ones_like(mc), mc) / 6
    return _ellipk(m, mc), 0.5 * (dm - dmc) * derivative


@jax.custom_jvp
def _ellipe(m, mc):
    zero, one = jnp.zeros_like(mc), jnp.ones_like(mc)
    # DLMF 19.25.1, second form: E = (mc/3) (R_D(0, mc, 1) + R_D(0, 1, mc)), all terms positive (the
    # first form R_F - (m/3) R_D cancels as m -> 1).  E(1) = 1 is the limit of mc R_D(0, 1, mc)/3.
    limit = mc == 0
    safe_mc = jnp.where(limit, 1, mc)
    value = safe_mc * (_rd(zero, safe_mc, one) + _rd(zero, one, safe_mc)) / 3
    return jnp.where(limit, one, value)


@_ellipe.defjvp
def _ellipe_jvp(primals, tangents):
    m, mc = primals
    dm, dmc = tangents
    derivative = -_rd(jnp.zeros_like(mc), mc, jnp.ones_like(mc)) / 6
    return _ellipe(m, mc), 0.5 * (dm - dmc) * derivative


def ellipk(m, *, mc=None):
    r"""Complete elliptic integral of the first kind K(m) (DLMF 19.2.8), parameter m = k^2.

    K(m) = R_F(0, 1 - m, 1) (DLMF 19.25.1).  ``mc`` passes 1 - m directly (see module notes).
    As ``scipy.special.ellipk``; infinite at m = 1.
    """
    m, mc = complement(m, mc)
    return _ellipk(m, mc)


def ellipkm1(p):
    r"""K(1 - p), accurate as p -> 0 (``scipy.special.ellipkm1``); DLMF 19.2.8, 19.25.1."""
    (p,) = promote(p)
    return _ellipk(1 - p, p)


def ellipe(m, *, mc=None):
    r"""Complete elliptic integral of the second kind E(m) (DLMF 19.2.8), via DLMF 19.25.1."""
    m, mc = complement(m, mc)
    return _ellipe(m, mc)


# ------------------------------------------------------------------------------------ incomplete F


@jax.custom_jvp
def _ellipkinc(phi, m, mc):
    turns, s, c = _reduce_amplitude(phi)
    reduced = s * _rf(c * c, _delta_squared(s, c, mc), jnp.ones_like(s))
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
    dk_dm = _rd(jnp.zeros_like(mc), jnp.ones_like(mc), safe_mc) / 6
    dfr_dm = s**3 * _rd(c * c, jnp.ones_like(s), delta2) / 6
    df_dm = jnp.where(turns == 0, 0, 2 * turns * dk_dm) + dfr_dm
    tangent = dphi / jnp.sqrt(delta2) + 0.5 * (dm - dmc) * df_dm
    return value, tangent


def ellipkinc(phi, m, *, mc=None):
    r"""Incomplete elliptic integral of the first kind F(phi|m) (DLMF 19.2.4).

    .. math:: F(\phi|m) = \int_0^\phi \frac{d\theta}{\sqrt{1 - m \sin^2\theta}}
              = \sin\phi\, R_F(\cos^2\phi, 1 - m\sin^2\phi, 1)

    (DLMF 19.25.5) for |phi| <= pi/2, continued to every real phi by F(phi + k pi) = F(phi) + 2k K(m)
    (DLMF 19.2.10).  Argument order as ``scipy.special.ellipkinc``.
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
    one = jnp.ones_like(s)
    x, y = c * c, _delta_squared(s, c, mc)
    transformed = n < _LARGE_NEGATIVE_CHARACTERISTIC
    n_far = jnp.where(transformed, n, 2 * _LARGE_NEGATIVE_CHARACTERISTIC)
    omega = m / n_far
    characteristic = jnp.where(transformed, omega, n)
    p = 1 - characteristic * s * s
    rc_second = (1 - n_far * s * s) * p
    first = _rf(jnp.where(transformed, x * y, x), jnp.where(transformed, rc_second, y),
                jnp.where(transformed, rc_second, one))
    coefficient = jnp.where(transformed, -omega, n)
    return s * first, coefficient * s**3 * _rj(x, y, one, p) / 3


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
    one = jnp.ones_like(s)
    x, y = c * c, _delta_squared(s, c, mc)
    transformed = n < _LARGE_NEGATIVE_CHARACTERISTIC
    n_far = jnp.where(transformed, n, 2 * _LARGE_NEGATIVE_CHARACTERISTIC)
    omega = m / n_far
    characteristic = jnp.where(transformed, omega, n)
    kappa = (1 - n_far) * (1 - omega)
    root_kappa = jnp.sqrt(kappa)
    head = jnp.where(transformed, jnp.arctan2(root_kappa * s, c * jnp.sqrt(y)) / root_kappa, 0)
    tail = characteristic * s**3 * _rj_parameter_largest(x, y, one, 1 - characteristic * s * s) / 3
    return head + jnp.where(transformed, -tail, tail)


def _pi_complete(n, m, mc):
    return _pi_reduced(n, jnp.ones_like(m), jnp.zeros_like(m), m, mc)


def _pi_continued(n, turns, s, c, m, mc):
    """2 turns Pi(n|m) + Pi(n; phi_r|m) (DLMF 19.2.10).

    The complete and the reduced integral go through the Carlson functions together (stacked on a new
    leading axis): one R_F and one R_J loop instead of two of each, which halves the compiled code
    (the gradient's too).
    """
    safe_mc = jnp.where(turns == 0, 1, mc)
    stack = lambda reduced, complete: jnp.stack(jnp.broadcast_arrays(reduced, complete))  # noqa: E731
    values = _pi_reduced(stack(n, n), stack(s, jnp.ones_like(s)), stack(c, jnp.zeros_like(c)),
                         stack(m, m), stack(mc, safe_mc))
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
        return _pi_continued(n_, turns, s, c, m_, mc_)

    value, tangent_nm = jax.jvp(at_fixed_amplitude, (n, m, mc), (dn, dparam, -dparam))
    # DLMF 19.2.7 integrand.
    tangent_phi = dphi / ((1 - n * s * s) * jnp.sqrt(delta2))
    return value, tangent_nm + tangent_phi


def ellippiinc(n, phi, m, *, mc=None):
    r"""Incomplete elliptic integral of the third kind (DLMF 19.2.7, characteristic n, parameter m).

    .. math:: \Pi(n; \phi|m) = \int_0^\phi \frac{d\theta}{(1 - n\sin^2\theta)\sqrt{1 - m\sin^2\theta}}

    for n <= 1 (n > 1, a principal value, gives NaN) and every real phi, continued by
    Pi(n; phi + k pi|m) = Pi(n; phi|m) + 2k Pi(n|m).  On |phi| <= pi/2 DLMF 19.25.14:
    Pi = s R_F(c^2, Delta^2, 1) + (n/3) s^3 R_J(c^2, Delta^2, 1, 1 - n s^2); for n < -1 the
    characteristic is first moved into (-1, 0] by DLMF 19.7.8.  The argument order (n, phi, m) is that
    of Mathematica's EllipticPi and Boost's ellint_3.
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


def ellippi(n, m, *, mc=None):
    r"""Complete elliptic integral of the third kind Pi(n|m) = Pi(n; pi/2|m) (DLMF 19.2.8), n < 1.

    Pi(n|m) = R_F(0, mc, 1) + (n/3) R_J(0, mc, 1, 1 - n) (DLMF 19.25.2), with DLMF 19.7.8 for n < -1.
    """
    m, mc = complement(m, mc)
    n, m, mc = promote(n, m, mc)
    valid = n < 1
    result = _ellippi(jnp.where(valid, n, 0), m, mc)
    return jnp.where(valid, result, jnp.nan)
