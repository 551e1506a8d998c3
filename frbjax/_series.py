"""Theta-function series of one body's motion: coefficients once per body, cheap evaluation at any time.

For a fixed parameter m, with the nome q = exp(-pi K'/K) (DLMF 22.2.1) and v = pi u / (2K), the Jacobi
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
atan2 gives the continuous argument.

All forms were checked against mpmath at 40 digits (tests/test_series.py checks the evaluation).
``_terms`` terms reach the dtype's rounding for q <= ``_largest_nome``, that is m below about 0.9995;
the few bodies beyond (next to the separatrix) are evaluated by the Carlson/Landen path of
``_regimes`` instead.  Only the ratio sn : cn = theta_1 : mc^(1/4) theta_2 is used (theta_4 and its
cancellation, 1 - 2q + 2q^4 - ..., drop out); sn and cn are then normalised and dn = sqrt(cn^2 +
mc sn^2).

Evaluation (``evaluate_series``): the half-period reduction u = 2jK + u_r, one sine and cosine of
v_r = pi u_r/(2K), their multiples by the rotation recurrence, and short dot products; one atan2 for
the third kind.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._fusion import materialise
from .special import elliprf
from .special._common import is_double

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
    amplitude: Float[Array, "..."]
    origin: Float[Array, "..."]
    quarter: Float[Array, "..."]
    nome: Float[Array, "..."]


def _characteristic_terms(m, characteristic):
    # chi = 0 (no third-kind term) only through harmless stand-ins; the square roots of -chi are taken
    # safely there so that no gradient is NaN.
    moving = characteristic < 0
    minus_chi = jnp.where(moving, -characteristic, 1)
    return moving, minus_chi, m + minus_chi


def integral_arguments(m, mc, characteristic):
    """(x, y, z) of the three R_F(x, y, z) the series data need, stacked on a new leading axis.

    K(m) = R_F(0, mc, 1) (DLMF 19.25.1), then a' and b by DLMF 19.25.5 with parameter mc: for a',
    sin^2 = -chi/(m - chi), cos^2 = m/(m - chi), 1 - mc sin^2 = m (1 - chi)/(m - chi); for b,
    sin^2 = 1/(1 - chi), cos^2 = -chi/(1 - chi), 1 - mc sin^2 = (m - chi)/(1 - chi).  A caller passes
    elliprf of these to ``coefficients``, possibly computed in one call with other R_F of its own.
    """
    _, minus_chi, gap = _characteristic_terms(m, characteristic)
    zero, one = jnp.zeros_like(gap), jnp.ones_like(gap)
    x = jnp.stack(jnp.broadcast_arrays(zero, m / gap, minus_chi / (1 + minus_chi)))
    y = jnp.stack(jnp.broadcast_arrays(mc, m * (1 + minus_chi) / gap, gap / (1 + minus_chi)))
    return x, y, jnp.stack(jnp.broadcast_arrays(one, one, one))


def coefficients(m, mc, characteristic, integrals=None) -> SeriesData:
    """Per-body series data (``SeriesData``).

    ``rows`` (..., 4, terms) hold, for n = 0 .. terms - 1,
    2 (q/m)^(1/4) (-1)^n q^(n(n+1))          (sin((2n+1) v): sn times theta_4)
    2 (q/m)^(1/4) mc^(1/4) q^(n(n+1))        (cos((2n+1) v): cn times theta_4)
    2 (-1)^(n+1) q^((n+1)^2) cosh(2(n+1) alpha'),  2 (-1)^(n+1) q^((n+1)^2) sinh(2(n+1) alpha')
                                             (theta_4(v + i alpha'), real and imaginary parts);
    ``origin`` = theta_4(i alpha') (see ``evaluate_series``) without cancellation, ``amplitude`` = A,
    ``quarter`` = K(m), ``nome`` = q.  ``characteristic`` chi <= 0 is the one whose integral is
    expanded; ``integrals`` = elliprf(*integral_arguments(m, mc, chi)) (computed here if None).
    """
    if integrals is None:
        integrals = elliprf(*integral_arguments(m, mc, characteristic))
    quarter, shift_integral, distance_integral = integrals[0], integrals[1], integrals[2]
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
    for j in range(terms):
        n = j + 1
        q_odd = q ** (j * (j + 1))
        rows[0].append(odd_scale * (-1) ** j * q_odd)
        rows[1].append(odd_scale * mc_fourth * q_odd)
        growing = q ** (n * (n - 1)) * rho**n
        # q^(n(n+1)) rho^(-n) = q^(n^2) (q/rho)^n with q/rho = exp(-2 alpha') <= 1.
        decaying = q ** (n * n) * jnp.exp(-np.pi * n * shift / quarter)
        sign = (-1) ** n
        rows[2].append(sign * (growing + decaying))
        rows[3].append(jnp.where(moving, sign * growing * -jnp.expm1(-2 * np.pi * n * shift / quarter), 0))
        if n < terms:
            origin = origin + sign * decaying * -jnp.expm1(-(2 * n + 1) * two_beta)
    stacked = jnp.stack([jnp.stack(jnp.broadcast_arrays(*row), -1) for row in rows], -2)
    return SeriesData(stacked, amplitude, origin, quarter, q)


def evaluate_series(data: SeriesData, mc, u, third_kind=True):
    """(sn_r, cn_r, dn, third_kind_periodic, turns) at u from the per-body ``coefficients``.

    u = 2 turns K + u_r with |u_r| <= K; sn_r = sn(u_r), cn_r = cn(u_r) >= 0 (so sn(u) = (-1)^turns sn_r,
    cn(u) = (-1)^turns cn_r), dn = dn(u), and A arg theta_4(v + i alpha') (period 2K in u).
    """
    rows, amplitude, origin, quarter = data.rows, data.amplitude, data.origin, data.quarter
    terms = rows.shape[-1]
    turns = jnp.round(u / (2 * quarter))
    half_angle = (u - 2 * quarter * turns) * (np.pi / 2) / quarter
    sin_v, cos_v = materialise((jnp.sin(half_angle), jnp.cos(half_angle)))
    # cos(k v), sin(k v) for k = 1 .. 2 terms by the rotation recurrence.
    cosines, sines = [cos_v], [sin_v]
    for _ in range(2 * terms - 1):
        c, s = cosines[-1], sines[-1]
        cosines.append(c * cos_v - s * sin_v)
        sines.append(s * cos_v + c * sin_v)
    # Term axis first, so that each term's coefficients are contiguous over the bodies.
    odd_sin, odd_cos, third_cos, third_sin = jnp.moveaxis(rows, (-2, -1), (0, 1))
    # sn : cn = theta_1 : mc^(1/4) theta_2 (theta_4 cancels), normalised so that sn^2 + cn^2 = 1 to an
    # ulp, and dn = sqrt(cn^2 + mc sn^2) = sqrt(1 - m sn^2) without cancellation: L then keeps |L| and
    # the energy to an ulp, as the Landen path does.
    sn_scaled = sum(odd_sin[j] * sines[2 * j] for j in range(terms))
    cn_scaled = sum(odd_cos[j] * cosines[2 * j] for j in range(terms))
    norm = jnp.sqrt(sn_scaled * sn_scaled + cn_scaled * cn_scaled)
    sn_reduced = sn_scaled / norm
    cn_reduced = cn_scaled / norm
    dn = jnp.sqrt(cn_reduced * cn_reduced + mc * (sn_reduced * sn_reduced))
    if not third_kind:
        return (*materialise((sn_reduced, cn_reduced, dn)), None, turns)
    # Re theta_4(v + i alpha') = theta_4(i alpha') - 2 sum c_n sin^2(n v) (1 - cos 2nv = 2 sin^2 nv):
    # the form 1 + sum c_n cos 2nv loses all digits where both are small (chi -> -infinity, v -> 0).
    real = origin - 2 * sum(third_cos[j] * (sines[j] * sines[j]) for j in range(terms))
    imaginary = -sum(third_sin[j] * sines[2 * j + 1] for j in range(terms))
    periodic = amplitude * jnp.arctan2(imaginary, real)
    # Materialised: each output feeds several later fused loops, which would otherwise recompute it.
    return (*materialise((sn_reduced, cn_reduced, dn, periodic)), turns)
