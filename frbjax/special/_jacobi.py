"""Jacobi elliptic functions sn, cn, dn and the amplitude am (DLMF 22.2, 22.16.1).

Evaluation (fixed operation count, per dtype):
1. Reduce u by whole half-periods: u = 2jK + u_r with |u_r| <= K (DLMF 22.4.3 table: sn and cn change
   sign, dn does not, am gains j pi).  K = R_F(0, mc, 1) is computed from the complement, so the
   reduction error grows only linearly with the number of periods.
2. On |u_r| <= K the descending Landen transformation / arithmetic-geometric mean (DLMF 22.20.1,
   22.20.ii): a_0 = 1, b_0 = sqrt(mc), c_0 = sqrt(m), c_{n+1} = c_n^2/(4 a_{n+1}) (no cancellation),
   phi_N = 2^N a_N u_r and phi_{n-1} = (phi_n + arcsin(c_n sin(phi_n)/a_n))/2; am_r = phi_0.
3. sn = sin am, cn = cos am, dn = sqrt(cn^2 + mc sn^2) (no cancellation as m -> 1, cn -> 0).
m = 1 (mc = 0) is the limit sn = tanh, cn = dn = sech, am = gd(u) (DLMF 22.5.ii, 4.23.39).

Derivatives (custom JVP):
- in u: sn' = cn dn, cn' = -sn dn, dn' = -m sn cn, am' = dn (DLMF 22.13.1-22.13.3, 22.16.1);
- in m: am(u|m) inverts u = F(am|m), so d am/dm = -dn dF/dm at fixed amplitude, with
  dF/dm = 2j dK/dm + (sn_r^3/6) R_D(cn_r^2, 1, dn^2) (DLMF 19.25.5, 19.18.1); sn, cn and dn follow by
  the chain rule.  At m = 1 the limits of DLMF 22.10.ii give d am/dm = -(sinh u - u sech u)/4.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax

from ._carlson import _rd, _rf
from ._common import complement, is_double, promote


def _agm_steps(x) -> int:
    # c_n/a_n falls quadratically once a_n ~ b_n; from b_0 = sqrt(mc) = 1e-150 that takes 10 steps,
    # after which c_n is below 1e-17 (checked against mpmath down to mc = 1e-300).
    return 13 if is_double(x) else 8


def _amplitude_reduced(u_reduced, m, mc):
    """am(u_r|m) for |u_r| <= K(m), m < 1, by the AGM (DLMF 22.20.ii).

    Two rolled loops (lax.scan), so that XLA compiles one step of each instead of ``steps`` copies.
    """
    steps = _agm_steps(u_reduced)

    def descend(state, _):
        a, b, c = state
        a_next = (a + b) / 2
        b_next = jnp.sqrt(a * b)
        c_next = c * c / (4 * a_next)
        return (a_next, b_next, c_next), (b_next, c_next)

    start = (jnp.ones_like(mc), jnp.sqrt(mc), jnp.sqrt(m))
    (a, _, _), sequence = lax.scan(descend, start, None, length=steps)

    def ascend(phi, b_and_c):
        b_n, c_n = b_and_c
        # arcsin((c_n/a_n) sin phi) written as atan2(c_n sin phi, sqrt(b_n^2 + c_n^2 cos^2 phi)), using
        # a_n^2 = b_n^2 + c_n^2: the plain arcsin loses digits when m -> 1 and phi -> pi/2.
        sin_phi, cos_phi = jnp.sin(phi), jnp.cos(phi)
        landen = jnp.arctan2(c_n * sin_phi, jnp.sqrt(b_n * b_n + (c_n * cos_phi) ** 2))
        return (phi + landen) / 2, None

    phi, _ = lax.scan(ascend, (2.0**steps) * a * u_reduced, sequence, reverse=True)
    return phi


def _half_periods(u, mc):
    """u = 2jK + u_r; returns (j, u_r, K) with a finite stand-in K = 1 where mc = 0 (K infinite)."""
    limit = mc == 0
    quarter = _rf(jnp.zeros_like(mc), jnp.where(limit, 1, mc), jnp.ones_like(mc))
    turns = jnp.where(limit, 0, jnp.round(u / (2 * quarter)))
    return turns, u - 2 * quarter * turns, quarter


def _ellipj_primal(u, m, mc):
    limit = mc == 0
    turns, u_reduced, _ = _half_periods(u, mc)
    safe_m = jnp.where(limit, 0.5, m)
    safe_mc = jnp.where(limit, 0.5, mc)
    am_reduced = _amplitude_reduced(jnp.where(limit, 0, u_reduced), safe_m, safe_mc)
    sign = 1 - 2 * jnp.mod(turns, 2)
    sn_generic = sign * jnp.sin(am_reduced)
    cn_generic = sign * jnp.cos(am_reduced)
    dn_generic = jnp.sqrt(cn_generic * cn_generic + mc * sn_generic * sn_generic)
    am_generic = am_reduced + turns * jnp.pi
    # m = 1: sn = tanh u, cn = dn = sech u, am = gd(u) = 2 arctan(tanh(u/2)).
    sech = 1 / jnp.cosh(u)
    sn = jnp.where(limit, jnp.tanh(u), sn_generic)
    cn = jnp.where(limit, sech, cn_generic)
    dn = jnp.where(limit, sech, dn_generic)
    am = jnp.where(limit, 2 * jnp.arctan(jnp.tanh(u / 2)), am_generic)
    return sn, cn, dn, am


@jax.custom_jvp
def _ellipj(u, m, mc):
    return _ellipj_primal(u, m, mc)


@_ellipj.defjvp
def _ellipj_jvp(primals, tangents):
    u, m, mc = primals
    du, dm, dmc = tangents
    sn, cn, dn, am = _ellipj(u, m, mc)
    dparam = 0.5 * (dm - dmc)
    limit = mc == 0

    # d am/dm for m < 1: -dn (2j dK/dm + (sn_r^3/6) R_D(cn_r^2, 1, dn^2)).
    turns, _, _ = _half_periods(u, mc)
    safe_mc = jnp.where(limit, 0.5, mc)
    zero, one = jnp.zeros_like(mc), jnp.ones_like(mc)
    dk_dm = _rd(zero, one, jnp.where(turns == 0, 1, safe_mc)) / 6
    sn_reduced = jnp.abs(sn) * jnp.sign(jnp.sin(am - turns * jnp.pi))
    cn_reduced = jnp.abs(cn)
    safe_dn = jnp.where(limit, 1, dn)
    df_dm = jnp.where(turns == 0, 0, 2 * turns * dk_dm) + sn_reduced**3 * _rd(
        cn_reduced * cn_reduced, one, safe_dn * safe_dn
    ) / 6
    dam_dm_generic = -safe_dn * df_dm
    # m = 1 (DLMF 22.10.ii): d am/dm = -(sinh u - u sech u)/4.
    # The m-derivatives at m = 1 grow like e^|u|/8; |u| is capped where sinh would overflow, so that a
    # zero parameter tangent contributes 0 rather than 0 * inf = NaN (d/du is exact for every u).
    safe_u = jnp.where(limit, jnp.clip(u, -700, 700), 0)
    dam_dm_limit = -(jnp.sinh(safe_u) - safe_u / jnp.cosh(safe_u)) / 4
    dam_dm = jnp.where(limit, dam_dm_limit, dam_dm_generic)

    d_am = dn * du + dam_dm * dparam
    d_sn = cn * d_am
    d_cn = -sn * d_am
    # dn^2 = 1 - m sn^2  =>  d dn = -(sn^2 dm + 2 m sn cn d am)/(2 dn)   (m < 1, dn >= sqrt(mc) > 0);
    # at m = 1, DLMF 22.10.ii: d dn/dm = -(tanh u)(sinh u + u sech u)/4.
    d_dn_generic = -(sn * sn * dparam + 2 * m * sn * cn * d_am) / (2 * safe_dn)
    d_dn_limit = -m * sn * cn * du - jnp.tanh(safe_u) * (
        jnp.sinh(safe_u) + safe_u / jnp.cosh(safe_u)
    ) / 4 * dparam
    d_dn = jnp.where(limit, d_dn_limit, d_dn_generic)
    return (sn, cn, dn, am), (d_sn, d_cn, d_dn, d_am)


def ellipj(u, m, *, mc=None):
    r"""Jacobi elliptic functions sn, cn, dn and the amplitude am of argument u, parameter m.

    ``sn, cn, dn, am = ellipj(u, m)`` as ``scipy.special.ellipj`` (DLMF 22.2.4, 22.16.1), for
    0 <= m <= 1 and every real u; ``am`` is continuous (it grows by pi every 2K(m)).  ``mc = 1 - m``
    may be passed directly when it is known more accurately than ``1 - m`` (e.g. mc = 1e-20).
    The absolute error is a few ulp times max(1, |u|/K(m)).
    """
    m, mc = complement(m, mc)
    u, m, mc = promote(u, m, mc)
    return _ellipj(u, m, mc)
