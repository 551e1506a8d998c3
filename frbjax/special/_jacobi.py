r"""Jacobi elliptic functions sn, cn, dn and the amplitude am (DLMF 22.2, 22.16.1).

Evaluation (fixed operation count, per dtype):

1. Reduce $u$ by whole half-periods: $u = 2jK + u_r$ with $|u_r| \le K$ (DLMF 22.4.3 table: sn and cn
   change sign, dn does not, am gains $j\pi$).  $K = R_F(0, m_c, 1)$ is computed from the complement,
   so the reduction error grows only linearly with the number of periods.
2. For $|u_r| \le K/2$, Bulirsch's form of the descending Landen transformation (AGM, DLMF 22.20.ii),
   which carries cn/sn and dn down the AGM levels with positive products and sums only (each point
   through its own levels, up to the one where the AGM has converged: 4 to 6 for most parameters,
   12 for mc = 1e-300; over an array the higher levels only when some point uses them); for
   $K/2 < |u_r| \le K$ the quarter-period reflection $u_r = K - w$ (DLMF 22.4.3).  sn, cn and dn then
   all have a few ulp *relative* error, also where cn and dn are as small as $\sqrt{m_c}$ ($u$ near
   $K$, $m \to 1$), which is what the rigid body near its separatrix needs.
3. $\mathrm{am} = j\pi + \mathrm{atan2}(\mathrm{sn}_r, \mathrm{cn}_r)$.

$m = 1$ ($m_c = 0$) is the limit sn = tanh, cn = dn = sech, am = gd($u$) (DLMF 22.5.ii, 4.23.39).

Derivatives (custom JVP):

- in $u$: $\mathrm{sn}' = \mathrm{cn}\,\mathrm{dn}$, $\mathrm{cn}' = -\mathrm{sn}\,\mathrm{dn}$,
  $\mathrm{dn}' = -m\,\mathrm{sn}\,\mathrm{cn}$, $\mathrm{am}' = \mathrm{dn}$ (DLMF 22.13.1-22.13.3, 22.16.1);
- in $m$: $\mathrm{am}(u|m)$ inverts $u = F(\mathrm{am}|m)$, so
  $\partial\,\mathrm{am}/\partial m = -\mathrm{dn}\; \partial F/\partial m$ at fixed amplitude, with
  $\partial F/\partial m = 2j\, dK/dm + (\mathrm{sn}_r^3/6)\, R_D(\mathrm{cn}_r^2, 1, \mathrm{dn}^2)$
  (DLMF 19.25.5, 19.18.1); sn, cn and dn follow by the chain rule.  At $m = 1$ the limits of DLMF
  22.10.ii give $\partial\,\mathrm{am}/\partial m = -(\sinh u - u\,\mathrm{sech}\,u)/4$.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import Array, lax
from jax.typing import ArrayLike

from .._fusion import when_any
from . import _compiled
from ._carlson import _rd
from ._circular import cos_sin_near_zero
from ._common import complement, is_double, over_sqrt, promote, rolled
from ._legendre import _complete_first_any


def _agm_steps(x) -> int:
    # b_n/a_n -> 1 quadratically once a_n ~ b_n; from b_0 = sqrt(mc) = 1e-150 that takes 10 steps
    # (checked against mpmath down to mc = 1e-300).
    return 13 if is_double(x) else 8


def _agm_plan(x):
    """(the sizes of the blocks of levels over an array, relative gap at which a level is the last
    one used).

    Once (a_n - b_n)/a_n <= 2^-26 (2^-12 in float32), the next gap, about (a_n - b_n)^2/(8 a_n), is
    below half an ulp: the levels above n are a_{n+1} repeated, and each of them would be an identity
    of the ascent (``_jacobi_to_half_quarter``).  Over an array the levels come in blocks, the first
    always computed and the rest only when some point uses them: 6 levels serve every mc >= 1e-4
    (4 in float32).
    """
    return ((6,), 2.0**-26) if is_double(x) else ((4,), 2.0**-12)


def _agm_blocks(x):
    """The blocks of ``_agm_plan``, the last one holding the remaining levels."""
    sizes, _ = _agm_plan(x)
    return tuple(size for size in sizes + (_agm_steps(x) - sum(sizes),) if size)


def _tiny_argument(x) -> float:
    # Below this |w| the Bulirsch recursion (cot^2 w) would overflow; sn = w, cn = dn = 1 is then exact
    # to w^2 (1e-200 in float64, 1e-30 in float32).
    return 1e-100 if is_double(x) else 1e-15


def _agm_levels(mc):
    """The AGM levels of DLMF 22.20.1 for parameter m = 1 - mc (mc > 0): (a_n, b_n, used_n) for
    n < N and each point's top mean.

    a_0 = 1, b_0 = sqrt(mc), a_{n+1} = (a_n + b_n)/2, b_{n+1} = sqrt(a_n b_n), at most N =
    ``_agm_steps`` levels.  A point uses its levels up to the first whose relative gap is below
    ``_agm_plan``'s, and its top mean is the next a (the AGM to rounding); its higher levels
    (``used_n`` false) are not needed.  Over an array the levels above the first few are computed
    only when some point uses them (a conditional: ``_fusion.when_any``; most parameters need 4 to
    6), and then the ascent goes through them at every point (``_jacobi_to_half_quarter``).
    The levels depend on the parameter alone, so a caller that evaluates many arguments at one
    parameter (the rigid body) computes them once.  Returned with the level axis last (batch
    dimensions first, as in a pytree of per-body data).
    """
    _, tolerance = _agm_plan(mc)

    def descend(state, _):
        a, b, used, mean = state
        next_a = (a + b) / 2
        # |a - b|: for m < 0 (mc > 1) b_0 = sqrt(mc) > a_0 = 1, and a - b < 0 stopped the AGM at once.
        last = used & (jnp.abs(a - b) <= tolerance * a)
        mean = jnp.where(used, next_a, mean)
        return (next_a, jnp.sqrt(a * b), used & ~last, mean), (a, b, used)

    start = (jnp.ones_like(mc), jnp.sqrt(mc), jnp.ones(mc.shape, bool), jnp.ones_like(mc))
    if rolled(mc):
        # One point or a few: one rolled loop (``_common.rolled``: one kernel, faster compile).
        (_, _, _, mean), levels = lax.scan(descend, start, None, length=_agm_steps(mc))
    else:
        # Unrolled (one fused pass over the points), each block after the first only for a batch
        # that uses it.
        state, blocks = start, []
        for index, size in enumerate(_agm_blocks(mc)):

            def compute(state, size=size):
                return lax.scan(descend, state, None, length=size, unroll=True)

            def unused(state, size=size):
                a, b, used, _ = state
                return state, tuple(jnp.broadcast_to(x, (size,) + x.shape) for x in (a, b, used))

            state, block = compute(state) if index == 0 else when_any(state[2], compute, unused, state)
            blocks.append(block)
        mean = state[3]
        levels = tuple(jnp.concatenate(parts) for parts in zip(*blocks))
    a_levels, b_levels, used = (jnp.moveaxis(level, 0, -1) for level in levels)
    return a_levels, b_levels, used, mean


def _jacobi_to_half_quarter(w, levels):
    """(sn, cn, dn)(w|m) for 0 <= w <= K(m)/2 and mc = 1 - m > 0, each to a few ulp *relative*.

    Bulirsch's form of the descending Landen transformation (R. Bulirsch, Numer. Math. 7 (1965)
    78-90, procedure sncndn; DLMF 22.7.i and 22.20.ii) on the AGM levels of ``_agm_levels``: from the
    top angle theta = a_N w (<= pi/4 here, so sin and cos lose nothing) the ratio c = cn/sn and dn
    are carried down with products and sums of positive numbers only.  Nothing cancels, so cn and dn
    keep their relative precision even when they are as small as mc^(1/4) (m -> 1, w -> K/2).
    Each point ascends through the levels it uses only (``_agm_levels``), but for the top block of
    levels, which a batch needs only where some parameter converges late: it ascends unmasked, and
    a point converged below it goes through levels with a_n = b_n to half an ulp, each an identity
    of the ascent to rounding.  So a point's values depend on its parameter alone in every batch
    that does not need the top block, and by rounding otherwise.
    """
    a_levels, b_levels, used_levels, mean = levels
    tiny = w < _tiny_argument(w)
    theta = mean * jnp.where(tiny, 1, w)
    # theta <= pi/4: the polynomials of _circular need no reduction (XLA's float64 sin and cos are scalar).
    cos_theta, sin_theta = cos_sin_near_zero(theta)
    ratio = cos_theta / sin_theta

    def unmasked_ascend(state, level):
        ratio, cot_ratio, dn = state
        a_n, b_n, _ = level
        ratio_next = ratio * cot_ratio
        cot_ratio_next = cot_ratio * dn
        dn_next = (b_n + ratio_next) / (a_n + ratio_next)
        return (cot_ratio_next / a_n, cot_ratio_next, dn_next), None

    def ascend(state, level):
        stepped, _ = unmasked_ascend(state, level)
        return tuple(jnp.where(level[2], new, kept) for new, kept in zip(stepped, state)), None

    start = (ratio, mean * ratio, jnp.ones_like(ratio))
    levels = tuple(jnp.moveaxis(level, -1, 0) for level in (a_levels, b_levels, used_levels))
    if rolled(ratio):
        # One point or a few: a rolled loop (``_common.rolled``).
        (_, cot_ratio, dn), _ = lax.scan(ascend, start, levels, reverse=True)
    else:
        # Unrolled: XLA fuses the ascent into one loop over the points (a rolled loop writes every
        # level's state to memory and back, several times slower); the higher levels only for a batch
        # where some point uses them.
        state, end = start, _agm_steps(w)
        blocks = _agm_blocks(w)
        for index, size in reversed(list(enumerate(blocks))):
            block = tuple(level[end - size : end] for level in levels)
            # The top block ascends unmasked (docstring): masks in that long fused chain cost XLA a
            # kernel per level.
            top = index == len(blocks) - 1 and index > 0

            def ascend_block(state, block, top=top):
                return lax.scan(unmasked_ascend if top else ascend, state, block, reverse=True, unroll=True)[0]

            state = (
                ascend_block(state, block)
                if index == 0
                else when_any(block[2][0], ascend_block, lambda state, block: state, state, block)
            )
            end -= size
        _, cot_ratio, dn = state
    sn = over_sqrt(1, cot_ratio * cot_ratio + 1)
    cn = cot_ratio * sn
    one = jnp.ones_like(cn)
    return jnp.where(tiny, w, sn), jnp.where(tiny, one, cn), jnp.where(tiny, one, dn)


def _quarter_period(mc):
    """K(m) from mc (``_legendre._complete_first_any``: every mc > 0, so m < 0 too), with a finite
    stand-in K = 1 where mc = 0."""
    return _complete_first_any(jnp.where(mc == 0, 1, mc))


def parameter_data(mc):
    """Everything ellipj needs that depends on the parameter alone: (K, AGM levels).

    Computed once per parameter by callers that evaluate many arguments (see ``ellipj_given``);
    mc = 0 (m = 1) gets harmless stand-ins (the tanh/sech limit needs none).
    """
    safe_mc = jnp.where(mc == 0, 0.5, mc)
    return _quarter_period(mc), _agm_levels(safe_mc)


def _half_periods(u, mc, quarter):
    """u = 2jK + u_r; returns (j, u_r) (j = 0 where mc = 0: no period)."""
    turns = jnp.where(mc == 0, 0, jnp.round(u / (2 * quarter)))
    return turns, u - 2 * quarter * turns


def _ellipj_primal(u, m, mc, quarter, levels):
    limit = mc == 0
    safe_mc = jnp.where(limit, 0.5, mc)
    turns, u_reduced = _half_periods(u, mc, quarter)
    # |u_r| in (K/2, K]: the quarter-period reflection u_r = K - w (DLMF 22.4.3, 22.6.1):
    # sn = cd(w), cn = sqrt(mc) sd(w), dn = sqrt(mc) nd(w), so that cn and dn near u = K, where they are
    # as small as sqrt(mc), come out with full relative precision (K - |u_r| is exact to eps K).
    magnitude = jnp.abs(jnp.where(limit, 0, u_reduced))
    upper = magnitude > quarter / 2
    w = jnp.where(upper, quarter - magnitude, magnitude)
    sn_w, cn_w, dn_w = _jacobi_to_half_quarter(w, levels)
    root_mc = jnp.sqrt(safe_mc)
    # cd^2 + mc sd^2 = 1 holds to a few ulp; dividing by the rounded norm makes sn^2 + cn^2 = 1 to one.
    norm_squared = cn_w * cn_w + (root_mc * sn_w) ** 2
    sn_abs = jnp.where(upper, over_sqrt(cn_w, norm_squared), sn_w)
    cn_reduced = jnp.where(upper, over_sqrt(root_mc * sn_w, norm_squared), cn_w)
    dn_generic = jnp.where(upper, root_mc / dn_w, dn_w)
    sn_reduced = jnp.where(u_reduced < 0, -sn_abs, sn_abs)
    sign = 1 - 2 * jnp.mod(turns, 2)
    # m = 1: sn = tanh u, cn = dn = sech u = 2 e/(1 + e^2) with e = exp(-|u|) (no overflow),
    # am = gd(u) = atan2(tanh u, sech u).
    decay = jnp.exp(-jnp.abs(jnp.where(limit, u, 0)))
    sech = 2 * decay / (1 + decay * decay)
    sn_reduced = jnp.where(limit, jnp.tanh(jnp.where(limit, u, 0)), sn_reduced)
    cn_reduced = jnp.where(limit, sech, cn_reduced)
    # am = j pi + atan2(sn_r, cn_r) with cn_r >= 0 (|u_r| <= K): an arctangent of the quotient.
    positive = cn_reduced > 0
    angle = jnp.where(
        positive, jnp.arctan(sn_reduced / jnp.where(positive, cn_reduced, 1)), jnp.copysign(jnp.pi / 2, sn_reduced)
    )
    am = turns * jnp.pi + angle
    sn = jnp.where(limit, sn_reduced, sign * sn_reduced)
    cn = jnp.where(limit, cn_reduced, sign * cn_reduced)
    dn = jnp.where(limit, sech, dn_generic)
    return sn, cn, dn, am


def _rd_rule(x, y, z):
    return _rd(x, y, z, True)


def _ellipj_tangents(u, m, mc, quarter, values, tangents, rd=_rd_rule):
    """The JVP of (sn, cn, dn, am) (module note); ``quarter`` is K(m) (stand-in 1 at m = 1), ``rd``
    the R_D it is written with (the compiled kernel's on that path)."""
    sn, cn, dn, am = values
    du, dm, dmc = tangents
    dparam = 0.5 * (dm - dmc)
    limit = mc == 0

    # d am/dm for m < 1: -dn (2j dK/dm + (sn_r^3/6) R_D(cn_r^2, 1, dn^2)).
    turns, _ = _half_periods(u, mc, quarter)
    # dK/dm = R_D(0, 1, mc)/6 depends on the parameter alone (m and mc may have fewer dimensions
    # than u); a stand-in where m = 1 (no period there).
    safe_mc = jnp.where(limit, 0.5, mc)
    dk_dm = rd(jnp.zeros_like(safe_mc), jnp.ones_like(safe_mc), safe_mc) / 6
    sn_reduced = jnp.abs(sn) * jnp.sign(jnp.sin(am - turns * jnp.pi))
    cn_reduced = jnp.abs(cn)
    safe_dn = jnp.where(limit, 1, dn)
    df_dm = (
        jnp.where(turns == 0, 0, 2 * turns * dk_dm)
        + sn_reduced**3 * rd(cn_reduced * cn_reduced, jnp.ones_like(cn_reduced), safe_dn * safe_dn) / 6
    )
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
    d_dn_limit = -m * sn * cn * du - jnp.tanh(safe_u) * (jnp.sinh(safe_u) + safe_u / jnp.cosh(safe_u)) / 4 * dparam
    d_dn = jnp.where(limit, d_dn_limit, d_dn_generic)
    return d_sn, d_cn, d_dn, d_am


@jax.custom_jvp
def _ellipj(u, m, mc):
    return _ellipj_primal(u, m, mc, *parameter_data(mc))


@_ellipj.defjvp
def _ellipj_jvp(primals, tangents):
    u, m, mc = primals
    values = _ellipj(u, m, mc)
    return values, _ellipj_tangents(u, m, mc, _quarter_period(mc), values, tangents)


@jax.custom_jvp
def ellipj_given(u, m, mc, quarter, levels):
    """``ellipj`` with the parameter's data ``(quarter, levels) = parameter_data(mc)`` given.

    For callers that evaluate many arguments at one parameter: K and the AGM levels are not
    recomputed per argument.  Derivatives are those of ellipj in (u, m, mc); ``quarter`` and
    ``levels`` are functions of mc and their own tangents are not used.
    """
    return _ellipj_primal(u, m, mc, quarter, levels)


@ellipj_given.defjvp
def _ellipj_given_jvp(primals, tangents):
    u, m, mc, quarter, levels = primals
    values = ellipj_given(u, m, mc, quarter, levels)
    return values, _ellipj_tangents(u, m, mc, quarter, values, tangents[:3])


@_compiled.one_program
def ellipj(u: ArrayLike, m: ArrayLike, *, mc: ArrayLike | None = None) -> tuple[Array, Array, Array, Array]:
    r"""Jacobi elliptic functions sn, cn, dn and the amplitude am of argument $u$, parameter $m$.

    ``sn, cn, dn, am = ellipj(u, m)`` as ``scipy.special.ellipj`` (DLMF 22.2.4, 22.16.1), for
    $0 \le m \le 1$ and every real $u$.  The amplitude $\phi = \mathrm{am}(u|m)$ inverts the
    incomplete integral of the first kind, and the three functions are

    $$u = \int_0^\phi \frac{d\theta}{\sqrt{1 - m \sin^2\theta}}, \qquad
      \mathrm{sn}\,u = \sin\phi, \quad \mathrm{cn}\,u = \cos\phi, \quad
      \mathrm{dn}\,u = \sqrt{1 - m \sin^2\phi}.$$

    ``am`` is continuous (it grows by $\pi$ every $2K(m)$).  ``mc`` $= 1 - m$ may be passed directly
    when it is known more accurately than ``1 - m`` (e.g. ``mc=1e-20``).  The absolute error is a few
    ulp times $\max(1, |u|/K(m))$.
    """
    m, mc = complement(m, mc)
    u, m, mc = promote(u, m, mc)
    if _compiled.selected(u):
        return _compiled_ellipj(u, m, mc)
    return _ellipj(u, m, mc)


@jax.custom_jvp
def _compiled_ellipj(u, m, mc):
    """ellipj through the compiled kernel (``_compiled``), with the JVP rule of the JAX path written
    with the kernel's R_D."""
    out = _compiled.call("ellipj", 0, (u, m, mc), width=4)
    return out[..., 0], out[..., 1], out[..., 2], out[..., 3]


@_compiled_ellipj.defjvp
def _compiled_ellipj_jvp(primals, tangents):
    u, m, mc = primals
    values = _compiled_ellipj(u, m, mc)
    return values, _ellipj_tangents(u, m, mc, _quarter_period(mc), values, tangents, rd=_compiled.elliprd)
