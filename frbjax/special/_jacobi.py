"""Jacobi elliptic functions sn, cn, dn and the amplitude am (DLMF 22.2, 22.16.1).

Evaluation (fixed operation count, per dtype):
1. Reduce u by whole half-periods: u = 2jK + u_r with |u_r| <= K (DLMF 22.4.3 table: sn and cn change
   sign, dn does not, am gains j pi).  K = R_F(0, mc, 1) is computed from the complement, so the
   reduction error grows only linearly with the number of periods.
2. For |u_r| <= K/2, Bulirsch's form of the descending Landen transformation (AGM, DLMF 22.20.ii),
   which carries cn/sn and dn down the AGM levels with positive products and sums only; for
   K/2 < |u_r| <= K the quarter-period reflection u_r = K - w (DLMF 22.4.3).  sn, cn and dn then all
   have a few ulp *relative* error, also where cn and dn are as small as sqrt(mc) (u near K, m -> 1),
   which is what the rigid body near its separatrix needs.
3. am = j pi + atan2(sn_r, cn_r).
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
    # b_n/a_n -> 1 quadratically once a_n ~ b_n; from b_0 = sqrt(mc) = 1e-150 that takes 10 steps
    # (checked against mpmath down to mc = 1e-300).  Extra steps are exact identities.
    return 13 if is_double(x) else 8


def _tiny_argument(x) -> float:
    # Below this |w| the Bulirsch recursion (cot^2 w) would overflow; sn = w, cn = dn = 1 is then exact
    # to w^2 (1e-200 in float64, 1e-30 in float32).
    return 1e-100 if is_double(x) else 1e-15


def _jacobi_to_half_quarter(w, mc):
    """(sn, cn, dn)(w|m) for 0 <= w <= K(m)/2 and mc = 1 - m > 0, each to a few ulp *relative*.

    Bulirsch's form of the descending Landen transformation (R. Bulirsch, Numer. Math. 7 (1965)
    78-90, procedure sncndn; DLMF 22.7.i and 22.20.ii): the AGM a_{n+1} = (a_n + b_n)/2,
    b_{n+1} = sqrt(a_n b_n) from a_0 = 1, b_0 = sqrt(mc), then from the top angle theta = a_N w
    (<= pi/4 here, so sin and cos lose nothing) the ratio c = cn/sn and dn are carried down with
    products and sums of positive numbers only.  Nothing cancels, so cn and dn keep their relative
    precision even when they are as small as mc^(1/4) (m -> 1, w -> K/2).  Two rolled loops.
    """
    steps = _agm_steps(w)

    def descend(state, _):
        a, b = state
        return ((a + b) / 2, jnp.sqrt(a * b)), (a, b)

    (mean, _), (a_levels, b_levels) = lax.scan(descend, (jnp.ones_like(mc), jnp.sqrt(mc)), None,
                                               length=steps)
    tiny = w < _tiny_argument(w)
    theta = mean * jnp.where(tiny, 1, w)
    ratio = jnp.cos(theta) / jnp.sin(theta)

    def ascend(state, levels):
        ratio, cot_ratio, dn = state
        a_n, b_n = levels
        ratio = ratio * cot_ratio
        cot_ratio = cot_ratio * dn
        dn = (b_n + ratio) / (a_n + ratio)
        return (cot_ratio / a_n, cot_ratio, dn), None

    start = (ratio, mean * ratio, jnp.ones_like(w))
    (_, cot_ratio, dn), _ = lax.scan(ascend, start, (a_levels, b_levels), reverse=True)
    sn = 1 / jnp.sqrt(cot_ratio * cot_ratio + 1)
    cn = cot_ratio * sn
    one = jnp.ones_like(w)
    return jnp.where(tiny, w, sn), jnp.where(tiny, one, cn), jnp.where(tiny, one, dn)


def _half_periods(u, mc):
    """u = 2jK + u_r; returns (j, u_r, K) with a finite stand-in K = 1 where mc = 0 (K infinite)."""
    limit = mc == 0
    quarter = _rf(jnp.zeros_like(mc), jnp.where(limit, 1, mc), jnp.ones_like(mc))
    turns = jnp.where(limit, 0, jnp.round(u / (2 * quarter)))
    return turns, u - 2 * quarter * turns, quarter


def _ellipj_primal(u, m, mc):
    limit = mc == 0
    safe_mc = jnp.where(limit, 0.5, mc)
    turns, u_reduced, quarter = _half_periods(u, mc)
    # |u_r| in (K/2, K]: the quarter-period reflection u_r = K - w (DLMF 22.4.3, 22.6.1):
    # sn = cd(w), cn = sqrt(mc) sd(w), dn = sqrt(mc) nd(w), so that cn and dn near u = K, where they are
    # as small as sqrt(mc), come out with full relative precision (K - |u_r| is exact to eps K).
    magnitude = jnp.abs(jnp.where(limit, 0, u_reduced))
    upper = magnitude > quarter / 2
    w = jnp.where(upper, quarter - magnitude, magnitude)
    sn_w, cn_w, dn_w = _jacobi_to_half_quarter(w, safe_mc)
    root_mc = jnp.sqrt(safe_mc)
    # cd^2 + mc sd^2 = 1 holds to a few ulp; dividing by the rounded norm makes sn^2 + cn^2 = 1 to one.
    norm = jnp.sqrt(cn_w * cn_w + (root_mc * sn_w) ** 2)
    sn_abs = jnp.where(upper, cn_w / norm, sn_w)
    cn_reduced = jnp.where(upper, root_mc * sn_w / norm, cn_w)
    dn_generic = jnp.where(upper, root_mc / dn_w, dn_w)
    sn_reduced = jnp.where(u_reduced < 0, -sn_abs, sn_abs)
    sign = 1 - 2 * jnp.mod(turns, 2)
    am_generic = turns * jnp.pi + jnp.arctan2(sn_reduced, cn_reduced)
    # m = 1: sn = tanh u, cn = dn = sech u, am = gd(u) = 2 arctan(tanh(u/2)).
    sech = 1 / jnp.cosh(u)
    sn = jnp.where(limit, jnp.tanh(u), sign * sn_reduced)
    cn = jnp.where(limit, sech, sign * cn_reduced)
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
