"""Theta-function series of one body's motion: coefficients once per body, cheap evaluation at any time.

Two expansions of the same functions, chosen per body: one in the nome q of the parameter m, for m
up to about 0.9999, and one in the complementary nome q' (Jacobi's imaginary transformation) for m
beyond, up to and including the separatrix m = 1.

Direct series.  With the nome q = exp(-pi K'/K) (DLMF 22.2.1) and v = pi u / (2K), the Jacobi
functions are quotients of theta functions (DLMF 22.2.4-22.2.6, with theta_2(0)/theta_3(0) = m^(1/4)
and theta_4(0)/theta_3(0) = mc^(1/4), DLMF 22.2.2):

    sn = theta_1(v) / (m^(1/4) theta_4(v)),  cn = (mc/m)^(1/4) theta_2(v)/theta_4(v),
    dn = mc^(1/4) theta_3(v)/theta_4(v),

with theta_1..4 the q-series of DLMF 20.2.1-20.2.4, whose terms fall like q^(n^2).

The third-kind integral along the orbit, for a characteristic chi = m sn^2(a) <= 0 (an imaginary shift
a = i a'), follows from Jacobi's form Pi(u, a) = u Z(a) + (1/2) ln(Theta(u - a)/Theta(u + a))
(Whittaker and Watson, A Course of Modern Analysis, 22.74), Theta(u) = theta_4(v):

    Pi(chi; am u | m) = u Pi(chi|m)/K + A arg theta_4(v + i alpha'),
    A = sqrt(-chi) / sqrt((1 - chi)(m - chi)),  alpha' = pi a' / (2K),
    a' = F(arctan sqrt(-chi/m) | mc)

(A = sn cn / dn at a' and parameter mc, by Jacobi's imaginary transformation DLMF 22.6.12).  With
rho = q exp(2 alpha') = exp(-pi b/K), b = F(arccot sqrt(-chi) | mc) = K' - a', the coefficients of
theta_4(v + i alpha') = 1 + 2 sum (-1)^n q^(n^2) (cos 2nv cosh 2n alpha' - i sin 2nv sinh 2n alpha') are
    q^(n^2) cosh(2n alpha') = (q^(n(n-1)) rho^n + q^(n(n+1)) rho^(-n)) / 2,
    q^(n^2) sinh(2n alpha') = q^(n(n-1)) rho^n (-expm1(-4n alpha')) / 2,
so nothing overflows as m -> 0 (q -> 0, alpha' -> infinity) and nothing cancels as chi -> 0.  The
terms fall like q^(n(n-1)) rho^n with rho < 1 for every chi < 0, so no characteristic needs a
transformation.  theta_4(v + i alpha') stays in the right half-plane (its zero, at v = 0 and
alpha' = pi K'/(2K), is only reached as chi -> -infinity, where Re theta_4(i alpha') -> 0+), so
atan2 gives the continuous argument.  Only the ratio sn : cn = theta_1 : mc^(1/4) theta_2 is used
(theta_4 and its cancellation, 1 - 2q + 2q^4 - ..., drop out).

Complementary series.  With q' = exp(-pi K/K') (the nome of mc) and w = pi u / (2K'), Jacobi's
imaginary transformation (DLMF 22.6.12: sn(u|m) = -i sc(iu|mc), cn(u|m) = nc(iu|mc)) and the theta
quotients of parameter mc at the imaginary argument i w give

    sn : cn = S(w) : (mc/q')^(1/4) T4(w) / 2,
    S(w) = sum_{n>=0} (-1)^n q'^(n(n+1)) sinh((2n+1) w),  T4(w) = theta_4(iw|q') = 1 + 2 sum_{n>=1} (-1)^n
    q'^(n^2) cosh(2nw).

The third kind follows from the direct form by the theta transformation DLMF 20.7.32,
theta_4(z|tau) = (-i tau)^(-1/2) exp(-i z^2/(pi tau)) theta_2(z/tau | -1/tau): the Gaussian factor
only adds a term linear in u, and for |u| <= K

    Pi(chi; am u | m) = u slope' + A arg theta_2(iw - beta' | q'),  beta' = pi a'/(2K'),
    arg theta_2(iw - beta') = atan2(sum q'^(n(n+1)) sinh((2n+1)w) sin((2n+1)beta'),
                                    sum q'^(n(n+1)) cosh((2n+1)w) cos((2n+1)beta')),
    slope' = Pi(chi|m)/K - A pi a'/(2 K K') = m/(m - chi) + A Z(a'|mc),

the last form from Jacobi's imaginary transformation of his zeta function (i Z(ia|m) = -Z(a|mc) +
dn sc(a|mc) - pi a/(2KK'), with Jacobi's Pi(u, a) = u Z(a) + ... above; checked against mpmath), and
Z(a'|mc) = (pi/(2K')) theta_4'(beta'|q')/theta_4(beta'|q'), the logarithmic derivative of theta_4
with nome q' (DLMF section 22.16(iii)): both terms are >= 0, so nothing cancels as chi -> -infinity, where
slope' ~ 1/(-chi) while Pi(chi|m)/K ~ 1/sqrt(-chi).  Without F (chi >= -1, see ``coefficients``) the
slope is slope' - 1 = chi/(m - chi) + A Z(a'|mc), again without cancellation as chi -> 0.
Relative to the leading term the n-th terms of S and of the third kind are at most q'^(n^2) for
|w| <= pi K/(2K') (|u| <= K), those of T4 at most q'^(n(n-1)): with q' < 1e-4 wherever the direct
series stops, two and three terms reach the dtype's rounding.  Every term is written through
E = exp(-2|w|) <= 1 and F = q' exp(2|w|) = exp(-pi (K - |u|)/K') <= 1, so nothing overflows on the
separatrix (q' = 0, K' = pi/2, K infinite), where the series are exact: sn = tanh u, cn = dn = sech u
and arg theta_2(iu - beta') = arctan(tan beta' tanh u); 1 - E and 1 - F (the zeros of sn and cn)
come from expm1.

All forms were checked against mpmath at 40 digits (tests/test_series.py checks the evaluation).
``_terms`` terms of the direct series reach the dtype's rounding for q <= ``_largest_nome`` (m below
about 0.99993 in float64, 0.9987 in float32); the complementary series serves the bodies beyond.

Evaluation (``evaluate_series``): the half-period reduction u = 2jK + u_r, then for the direct series
one sine and cosine of v_r = pi u_r/(2K), their multiples by the rotation recurrence and short dot
products, for the complementary series two exp and two expm1; both are evaluated and selected per
body (elementwise and cheap), then one normalisation and one atan2 for the third kind.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ._fusion import materialise, when_any
from .special import elliprf
from .special._circular import cos_sin
from .special._common import is_double
from .special._legendre import _LARGE_NEGATIVE_CHARACTERISTIC, pi_without_first_kind


# Terms of the complementary series (n = 0, 1 of S and of the third kind, n = 1, 2 of T4): the next
# omitted ones are 5 q'^4 and q'^6 relative, below 1e-20 for q' <= 8.3e-5 (q = 0.35, float32's limit).
_COMPLEMENTARY_TERMS = 2


def _terms(x) -> int:
    # Next omitted terms at q = 0.45: q^81 (theta_3,4), q^72.25 (theta_1,2), q^72 rho^9 (third kind).
    return 8 if is_double(x) else 5


def _largest_nome(x) -> float:
    return 0.45 if is_double(x) else 0.35


def _landen_nome(m, mc):
    """Nome q of parameter m <= 1/2 from DLMF 19.5.5, q = lambda + 2 lambda^5 + 15 lambda^9 + ...

    with lambda = (1 - mc^(1/4)) / (2 (1 + mc^(1/4))) = m / (2 (1 + sqrt mc)(1 + mc^(1/4))^2) (no
    cancellation as m -> 0).  Returns (q, q/m) with q/m finite at m = 0 (the limit is 1/16).
    """
    root = jnp.sqrt(mc)
    fourth = jnp.sqrt(root)
    lam_over_m = 1 / (2 * (1 + root) * (1 + fourth) ** 2)
    lam = m * lam_over_m
    lam4 = lam**4
    # DLMF 19.5.5 through lambda^21 (lambda <= 0.0432 for m <= 1/2: the next term is below 1e-27).
    series = 1 + lam4 * (2 + lam4 * (15 + lam4 * (150 + lam4 * (1707 + lam4 * 20910))))
    return lam * series, lam_over_m * series


def nome(m, mc):
    """(q, q/m) for 0 <= m < 1; q/m is finite at m = 0 (limit 1/16).

    For m <= 1/2 from the Landen series; for m > 1/2 from the complementary nome q' of mc, through
    ln q ln q' = pi^2 (DLMF 22.2.1: q = exp(-pi K'/K), q' = exp(-pi K/K')).
    """
    small = m <= 0.5
    q_direct, q_over_m = _landen_nome(jnp.where(small, m, 0.25), jnp.where(small, mc, 0.75))
    q_complement, _ = _landen_nome(jnp.where(small, 0.25, mc), jnp.where(small, 0.75, m))
    q_reflected = jnp.exp(np.pi**2 / jnp.log(q_complement))
    q = jnp.where(small, q_direct, q_reflected)
    return q, jnp.where(small, q_over_m, q_reflected / jnp.where(small, 1, m))


class SeriesData(NamedTuple):
    """Per-body data of the series (``coefficients``), the leading (body) shape first in every field."""

    rows: Float[Array, "... 4 terms"]
    amplitude: Float[Array, ...]
    origin: Float[Array, ...]
    quarter: Float[Array, ...]
    nome: Float[Array, ...]
    slope: Float[Array, ...]
    complementary: Bool[Array, ...]
    periodic: Bool[Array, ...]
    complementary_rows: Float[Array, "... 4 2"]
    complementary_log_nome: Float[Array, ...]
    complementary_scale: Float[Array, ...]
    complementary_cn_factor: Float[Array, ...]


def _characteristic_terms(m, characteristic):
    # chi = 0 (no third-kind term) only through harmless stand-ins; the square roots of -chi are taken
    # safely there so that no gradient is NaN.
    moving = characteristic < 0
    minus_chi = jnp.where(moving, -characteristic, 1)
    return moving, minus_chi, m + minus_chi


def _complementary_candidate(m):
    # Bodies whose complementary series is computed from their own m (q' < 0.0433); the others get
    # stand-ins there (their K' = K(mc) is infinite at m = 0).
    return m > 0.5


def integral_arguments(m, mc, characteristic):
    """(x, y, z) of the four R_F(x, y, z) the series data need, stacked on a new leading axis.

    K(m) = R_F(0, mc, 1) (DLMF 19.25.1), then a' and b by DLMF 19.25.5 with parameter mc: for a',
    sin^2 = -chi/(m - chi), cos^2 = m/(m - chi), 1 - mc sin^2 = m (1 - chi)/(m - chi); for b,
    sin^2 = 1/(1 - chi), cos^2 = -chi/(1 - chi), 1 - mc sin^2 = (m - chi)/(1 - chi); and
    K' = K(mc) = R_F(0, m, 1) for the complementary series (a stand-in for m <= 1/2).  A caller passes
    elliprf of these to ``coefficients``, possibly computed in one call with other R_F of its own.
    """
    _, minus_chi, gap = _characteristic_terms(m, characteristic)
    zero, one = jnp.zeros_like(gap), jnp.ones_like(gap)
    complement_parameter = jnp.where(_complementary_candidate(m), m, 0.5)
    x = jnp.stack(jnp.broadcast_arrays(zero, m / gap, minus_chi / (1 + minus_chi), zero))
    y = jnp.stack(jnp.broadcast_arrays(mc, m * (1 + minus_chi) / gap, gap / (1 + minus_chi), complement_parameter))
    return x, y, jnp.stack(jnp.broadcast_arrays(one, one, one, one))


def coefficients(m, mc, characteristic, integrals=None, complete=None) -> SeriesData:
    """Per-body series data (``SeriesData``) for Pi(chi; am u|m) - u (chi >= -1) or Pi(chi; am u|m).

    The first kind is left out for -1 <= chi <= 0, as ``special._legendre.pi_without_first_kind`` does
    (the rigid body adds it back where it needs it).  ``rows`` (..., 4, terms) of the direct series
    hold, for n = 0 .. terms - 1,
    2 (q/m)^(1/4) (-1)^n q^(n(n+1))          (sin((2n+1) v): sn times theta_4)
    2 (q/m)^(1/4) mc^(1/4) q^(n(n+1))        (cos((2n+1) v): cn times theta_4)
    2 (-1)^(n+1) q^((n+1)^2) cosh(2(n+1) alpha'),  2 (-1)^(n+1) q^((n+1)^2) sinh(2(n+1) alpha')
                                             (theta_4(v + i alpha'), real and imaginary parts);
    ``origin`` = theta_4(i alpha') (see ``evaluate_series``) without cancellation, ``amplitude`` = A,
    ``quarter`` = K(m), ``nome`` = q, ``slope`` = complete/K (direct) or slope' (complementary).
    ``complementary_rows`` (..., 4, 2) hold, for n = 0, 1, q'^(n^2) cos((2n+1) beta'),
    q'^(n^2) sin((2n+1) beta'), (-1)^n q'^(n^2) and (q', q'^2) (see ``_evaluate_complementary``);
    ``complementary_log_nome`` = ln q' = -pi K/K', ``complementary_scale`` = pi/K',
    ``complementary_cn_factor`` = (mc/q')^(1/4).  ``complementary`` picks the series (q beyond
    ``_largest_nome``), ``periodic`` is true except in the separatrix limit (``at_separatrix``).
    ``characteristic`` chi <= 0 is the one whose integral is expanded; ``integrals`` =
    elliprf(*integral_arguments(m, mc, chi)) and ``complete`` = the same integral at u = K (computed
    here if None).
    """
    if integrals is None:
        integrals = elliprf(*integral_arguments(m, mc, characteristic))
    if complete is None:
        one = jnp.ones_like(m)
        complete = pi_without_first_kind(characteristic, one, jnp.zeros_like(m), m, mc)
    quarter, shift_integral, distance_integral, complement_quarter = (integrals[k] for k in range(4))
    terms = _terms(m)
    q, q_over_m = nome(m, mc)
    moving, minus_chi, gap = _characteristic_terms(m, characteristic)
    shift = jnp.sqrt(minus_chi / gap) * shift_integral
    distance = distance_integral / jnp.sqrt(1 + minus_chi)
    rho = jnp.exp(-np.pi * distance / quarter)
    amplitude = jnp.where(moving, jnp.sqrt(minus_chi) / jnp.sqrt((1 + minus_chi) * gap), 0)
    odd_scale = 2 * jnp.sqrt(jnp.sqrt(q_over_m))
    mc_fourth = jnp.sqrt(jnp.sqrt(mc))
    rows = [[] for _ in range(4)]
    # theta_4(i alpha') -> 0 as chi -> -infinity (rho -> 1), where its series 1 - rho - q^2/rho + ...
    # cancels.  With beta = pi b/(2K) = pi K'/(2K) - alpha' and theta_4(z + pi tau/2) = i q^(-1/4)
    # exp(-iz) theta_1(z) (DLMF 20.2.13), theta_4(i alpha') = 2 exp(-beta) sum (-1)^n q^(n(n+1))
    # sinh((2n+1) beta) = sum (-1)^n q^(n^2) (q/rho)^n (-expm1(-2 (2n+1) beta)): no cancellation.
    two_beta = np.pi * distance / quarter
    origin = -jnp.expm1(-two_beta)
    # Every power by a recurrence over n (a product or two per term instead of an integer power or an
    # exponential: a fraction of the compiled code, and rounding of a few ulp in terms that are at most
    # q^2 of the first), and every 1 - x^k as (1 - x^(k-1)) + x^(k-1) (1 - x), a sum of non-negative
    # terms, so that nothing cancels as the exponent -> 0 (chi -> 0 or chi -> -infinity).
    shift_decay = jnp.exp(-np.pi * shift / quarter)  # q/rho = exp(-2 alpha')
    shift_gap = -jnp.expm1(-2 * np.pi * shift / quarter)  # 1 - (q/rho)^2
    beta_decay = jnp.exp(-two_beta)
    beta_gap = -jnp.expm1(-2 * two_beta)  # 1 - exp(-4 beta)
    # Materialised: every coefficient below is a product chain of these, and each output's fused
    # loop would otherwise recompute their exponentials (and the nome's) for itself.
    q, q_over_m, rho, origin, shift_decay, shift_gap, beta_decay, beta_gap, amplitude = materialise(
        (q, q_over_m, rho, origin, shift_decay, shift_gap, beta_decay, beta_gap, amplitude)
    )
    q_squared = q * q
    shift_decay_squared = shift_decay * shift_decay
    beta_decay_squared = beta_decay * beta_decay
    q_odd = jnp.ones_like(q)  # q^(n(n-1)) = q^(j(j+1))
    q_power, q_even_power = jnp.ones_like(q), jnp.ones_like(q)  # q^(n-1), q^(2(n-1))
    rho_power, shift_power = jnp.ones_like(rho), jnp.ones_like(shift_decay)  # rho^(n-1), (q/rho)^(n-1)
    shift_square_power, shift_complement = jnp.ones_like(shift_decay), jnp.zeros_like(shift_decay)
    beta_power, beta_complement = beta_decay, origin  # exp(-2(2n-1) beta), 1 - exp(-2(2n-1) beta)
    for j in range(terms):
        n = j + 1
        q_power, rho_power, shift_power = q_power * q, rho_power * rho, shift_power * shift_decay
        rows[0].append(odd_scale * (-1) ** j * q_odd)
        rows[1].append(odd_scale * mc_fourth * q_odd)
        growing = q_odd * rho_power
        # q^(n(n+1)) rho^(-n) = q^(n^2) (q/rho)^n with q/rho = exp(-2 alpha') <= 1.
        decaying = q_odd * q_power * shift_power
        # 1 - (q/rho)^(2n) = 1 - exp(-4 n alpha').
        shift_complement = shift_complement + shift_square_power * shift_gap
        shift_square_power = shift_square_power * shift_decay_squared
        sign = (-1) ** n
        rows[2].append(sign * (growing + decaying))
        rows[3].append(jnp.where(moving, sign * growing * shift_complement, 0))
        if n < terms:
            # 1 - exp(-2 (2n + 1) beta).
            beta_complement = beta_complement + beta_power * beta_gap
            beta_power = beta_power * beta_decay_squared
            origin = origin + sign * decaying * beta_complement
        q_even_power = q_even_power * q_squared
        q_odd = q_odd * q_even_power
    stacked = jnp.stack([jnp.stack(jnp.broadcast_arrays(*row), -1) for row in rows], -2)
    without_first_kind = characteristic >= _LARGE_NEGATIVE_CHARACTERISTIC

    # Complementary series, from the nome q' of mc (stand-ins where m <= 1/2, see integral_arguments).
    candidate = _complementary_candidate(m)
    q_c, q_c_over_mc = nome(jnp.where(candidate, mc, 0.5), jnp.where(candidate, m, 0.5))
    # beta' = pi a'/(2K') and pi/2 - beta' = pi b/(2K'): each sine from the smaller angle, so that
    # sin beta' keeps its digits as chi -> 0 and cos beta' as chi -> -infinity (one call for both).
    sin_shift, cos_shift = cos_sin(np.pi / 2 * jnp.stack([shift, distance]) / complement_quarter[None])[1]
    # cos 3x = cos x (4 cos^2 x - 3), sin 3x = sin x (3 - 4 sin^2 x): relative precision kept.
    cos_triple = cos_shift * (4 * cos_shift * cos_shift - 3)
    sin_triple = sin_shift * (3 - 4 * sin_shift * sin_shift)
    # Z(a'|mc) = (pi/(2K')) theta_4'(beta')/theta_4(beta') with nome q' (DLMF 20.2.4, two terms each).
    sin_double = 2 * sin_shift * cos_shift
    cos_double = (cos_shift - sin_shift) * (cos_shift + sin_shift)
    q_c4 = q_c**4
    theta_derivative = 4 * sin_double * (q_c - 4 * q_c4 * cos_double)
    theta = 1 - 2 * q_c * cos_double + 2 * q_c4 * (2 * cos_double * cos_double - 1)
    zeta = (np.pi / 2) / complement_quarter * theta_derivative / theta
    slope_complementary = jnp.where(moving, jnp.where(without_first_kind, -minus_chi, m) / gap + amplitude * zeta, 0)
    complementary_rows = jnp.stack(
        [
            jnp.stack(jnp.broadcast_arrays(cos_shift, q_c * cos_triple), -1),
            jnp.stack(jnp.broadcast_arrays(sin_shift, q_c * sin_triple), -1),
            jnp.stack(jnp.broadcast_arrays(jnp.ones_like(q_c), -q_c), -1),
            jnp.stack(jnp.broadcast_arrays(q_c, q_c * q_c), -1),
        ],
        -2,
    )
    complementary = q > _largest_nome(m)
    slope = jnp.where(complementary, slope_complementary, complete / quarter)
    return SeriesData(
        rows=stacked,
        amplitude=amplitude,
        origin=origin,
        quarter=quarter,
        nome=q,
        slope=slope,
        complementary=complementary,
        periodic=jnp.ones_like(complementary),
        complementary_rows=complementary_rows,
        complementary_log_nome=-np.pi * quarter / complement_quarter,
        complementary_scale=np.pi / complement_quarter,
        complementary_cn_factor=1 / jnp.sqrt(jnp.sqrt(q_c_over_mc)),
    )


def at_separatrix(data: SeriesData, separatrix, sin_shift, cos_shift, amplitude, slope) -> SeriesData:
    """``data`` with the bodies where ``separatrix`` replaced by the limit m = 1 of the complementary series.

    There q' = 0, K' = pi/2 (w = u), K is infinite (no reduction: ``periodic`` false; ``quarter``
    becomes a finite stand-in for the direct series, whose result is not used), (mc/q')^(1/4) = 2
    (q'/mc -> 1/16), and the third kind is slope u + A arctan(tan beta' tanh u) with sin beta' =
    ``sin_shift``, cos beta' = ``cos_shift``, A = ``amplitude`` and ``slope`` given by the caller (for
    Pi(chi; gd u|1) = (u + sqrt(-chi) arctan(sqrt(-chi) tanh u))/(1 - chi): sin beta' =
    sqrt(-chi/(1 - chi)), A = sqrt(-chi)/(1 - chi), slope 1/(1 - chi)).
    """

    def put(limit, value):
        mask = separatrix.reshape(separatrix.shape + (1,) * (jnp.ndim(value) - separatrix.ndim))
        return jnp.where(mask, jnp.asarray(limit, value.dtype), value)

    zero = jnp.zeros_like(sin_shift)
    rows = jnp.stack(
        [
            jnp.stack([cos_shift, zero], -1),
            jnp.stack([sin_shift, zero], -1),
            jnp.stack([jnp.ones_like(zero), zero], -1),
            jnp.stack([zero, zero], -1),
        ],
        -2,
    )
    return data._replace(
        quarter=put(1.0, data.quarter),
        amplitude=put(amplitude, data.amplitude),
        slope=put(slope, data.slope),
        complementary=separatrix | data.complementary,
        periodic=~separatrix & data.periodic,
        complementary_rows=put(rows, data.complementary_rows),
        complementary_log_nome=put(-np.inf, data.complementary_log_nome),
        complementary_scale=put(2.0, data.complementary_scale),
        complementary_cn_factor=put(2.0, data.complementary_cn_factor),
    )


def _complementary_part(data: SeriesData, reduced):
    """``_evaluate_complementary`` at u = ``reduced``, its exponentials materialised (each feeds
    several outputs, whose fused loops would otherwise recompute it)."""
    return _evaluate_complementary(data, reduced, materialise(_complementary_exponentials(data, reduced)))


def _no_complementary_part(data: SeriesData, reduced):
    zero = jnp.zeros_like(reduced)
    return zero, zero, zero, zero


def _complementary_exponentials(data: SeriesData, reduced):
    """(h, D, F, G) of ``_evaluate_complementary`` at u = ``reduced``."""
    distance = jnp.abs(reduced) * data.complementary_scale  # 2|w|
    # -pi (K - |u|)/K' <= 0; the clip only absorbs the rounding of the reduction (and keeps the
    # stand-ins of the other bodies finite).
    gap = jnp.minimum(data.complementary_log_nome + distance, 0)
    return jnp.exp(-distance / 2), -jnp.expm1(-distance), jnp.exp(gap), -jnp.expm1(gap)


def _evaluate_complementary(data: SeriesData, reduced, exponentials):
    """(sn, cn) up to a common positive factor and theta_2(iw - beta'|q') up to one, at u = ``reduced``.

    With E = exp(-2|w|), D = 1 - E, F = q' exp(2|w|), G = 1 - F, h = exp(-|w|) and P_k = (1 - E^k)/(1 - E):
    2 exp(-|w|) S(w) = sign(w) D sum (-1)^n q'^(n^2) F^n P_(2n+1),
    T4(w) = G - q' E + q'^2 F^2 (1 + E^4) - ...,
    2 exp(-|w|) theta_2(iw - beta') / (2 q'^(1/4)) = sum q'^(n^2) F^n ((1 + E^(2n+1)) cos((2n+1) beta')
                                                      + i sign(w) D P_(2n+1) sin((2n+1) beta')).
    """
    rows = jnp.moveaxis(data.complementary_rows, (-2, -1), (0, 1))
    cos_rows, sin_rows, odd_rows, even_rows = rows
    sign = jnp.where(reduced < 0, -1, 1).astype(reduced.dtype)
    half, d, f, g = exponentials
    e = half * half
    e2 = e * e
    triple = 1 + e + e2  # P_3
    sn_scaled = sign * d * (odd_rows[0] + odd_rows[1] * f * triple)
    cn_scaled = data.complementary_cn_factor * half * (g - even_rows[0] * e + even_rows[1] * (f * f) * (1 + e2 * e2))
    real = cos_rows[0] * (1 + e) + cos_rows[1] * f * (1 + e * e2)
    imaginary = sign * d * (sin_rows[0] + sin_rows[1] * f * triple)
    return sn_scaled, cn_scaled, real, imaginary


def _multiples(sin_v, cos_v, count):
    """(cos(k v), sin(k v)) for k = 1 .. count by the rotation recurrence."""
    cosines, sines = [cos_v], [sin_v]
    for _ in range(count - 1):
        c, s = cosines[-1], sines[-1]
        cosines.append(c * cos_v - s * sin_v)
        sines.append(s * cos_v + c * sin_v)
    return cosines, sines


def _reduced_third_kind(data: SeriesData, reduced, sines, complementary_parts):
    """The expanded integral from 0 to ``reduced`` (|u_r| <= K): u_r slope + A arg theta(...)."""
    terms = data.rows.shape[-1]
    _, _, third_cos, third_sin = jnp.moveaxis(data.rows, (-2, -1), (0, 1))
    # Re theta_4(v + i alpha') = theta_4(i alpha') - 2 sum c_n sin^2(n v) (1 - cos 2nv = 2 sin^2 nv):
    # the form 1 + sum c_n cos 2nv loses all digits where both are small (chi -> -infinity, v -> 0).
    real = data.origin - 2 * sum(third_cos[j] * (sines[j] * sines[j]) for j in range(terms))
    imaginary = -sum(third_sin[j] * sines[2 * j + 1] for j in range(terms))
    _, _, real_c, imaginary_c = complementary_parts
    real = jnp.where(data.complementary, real_c, real)
    imaginary = jnp.where(data.complementary, imaginary_c, imaginary)
    return reduced * data.slope + data.amplitude * jnp.arctan2(imaginary, real)


def _angle(data: SeriesData, reduced):
    half_angle = reduced * (np.pi / 2) / data.quarter
    # Materialised: each is used by several outputs, whose fused loops would otherwise recompute it.
    half_cos, half_sin = cos_sin(half_angle)
    return materialise((reduced, half_sin, half_cos))


def third_kind_at(data: SeriesData, u):
    """The expanded integral (``evaluate_series``' fourth output) at |u| <= K, alone: no Jacobi
    functions (the attitude at the phase u0, where the body's own L gives them)."""
    reduced, sin_v, cos_v = _angle(data, u)
    _, sines = _multiples(sin_v, cos_v, 2 * data.rows.shape[-1])
    parts = when_any(data.complementary, _complementary_part, _no_complementary_part, data, reduced)
    return materialise(_reduced_third_kind(data, reduced, sines, parts))


def evaluate_series(data: SeriesData, mc, u, third_kind=True):
    """(sn_r, cn_r, dn, third_kind_reduced, turns) at u from the per-body ``coefficients``.

    u = 2 turns K + u_r with |u_r| <= K (turns = 0 where not ``periodic``); sn_r = sn(u_r), cn_r =
    cn(u_r) >= 0 (so sn(u) = (-1)^turns sn_r, cn(u) = (-1)^turns cn_r), dn = dn(u), and the expanded
    integral (see ``coefficients``) from 0 to u_r: u_r slope + the periodic part.  The integral to u
    adds 2 turns times the complete one.
    """
    rows, quarter = data.rows, data.quarter
    terms = rows.shape[-1]
    turns = jnp.where(data.periodic, jnp.round(u / (2 * quarter)), 0)
    reduced, sin_v, cos_v = _angle(data, u - 2 * quarter * turns)
    cosines, sines = _multiples(sin_v, cos_v, 2 * terms)
    # Term axis first, so that each term's coefficients are contiguous over the bodies.
    odd_sin, odd_cos, _, _ = jnp.moveaxis(rows, (-2, -1), (0, 1))
    # sn : cn = theta_1 : mc^(1/4) theta_2 (theta_4 cancels), or S : (mc/q')^(1/4) T4/2.
    sn_scaled = sum(odd_sin[j] * sines[2 * j] for j in range(terms))
    cn_scaled = sum(odd_cos[j] * cosines[2 * j] for j in range(terms))
    # The complementary series serves only the bodies next to the separatrix (about 1 in 20,000 random
    # ones): skipped for a batch that has none (``_fusion.when_any``).
    parts = when_any(data.complementary, _complementary_part, _no_complementary_part, data, reduced)
    sn_c, cn_c, _, _ = parts
    complementary = data.complementary
    sn_scaled = jnp.where(complementary, sn_c, sn_scaled)
    cn_scaled = jnp.where(complementary, cn_c, cn_scaled)
    # Normalised so that sn^2 + cn^2 = 1 to an ulp, and dn = sqrt(cn^2 + mc sn^2) = sqrt(1 - m sn^2)
    # without cancellation: L then keeps |L| and the energy to an ulp.
    norm = jnp.sqrt(sn_scaled * sn_scaled + cn_scaled * cn_scaled)
    sn_reduced = sn_scaled / norm
    cn_reduced = cn_scaled / norm
    dn = jnp.sqrt(cn_reduced * cn_reduced + mc * (sn_reduced * sn_reduced))
    if not third_kind:
        return (*materialise((sn_reduced, cn_reduced, dn)), None, turns)
    reduced_integral = _reduced_third_kind(data, reduced, sines, parts)
    # Materialised: each output feeds several later fused loops, which would otherwise recompute it.
    return (*materialise((sn_reduced, cn_reduced, dn, reduced_integral)), turns)
