"""The exact motion in the working frame: per-body constants of each regime and their evaluation.

Notation, formulas and their derivation: ``docs/theory.md`` (checked numerically on both signs of every branch).
The working frame has sorted moments J1 <= J2 <= J3 and a unit angular momentum l with l1 >= 0 and
l3 >= 0 (the body's symmetry under rotation by pi about a principal axis makes this free: see
``_body.working_frame``), so every orbit sign of the formulas is +1 here.

With g1 = 1 - d J1, g3 = d J3 - 1, g2 = d J2 - 1 computed without cancellation (docs/theory.md §3), and the
gaps a = J2 - J1, b = J3 - J2, c = J3 - J1:

- regime "around the major axis" (g2 < 0, parameter m = g3 a/(g1 b) < 1):
  L = (A1 cn, A2 sn, A3 dn)(u),  psi = t/J1 + atan2(L2, L3) - alpha Pi(nu; am u | m),
  quaternion chart built on 1 + L1;
- regime "around the minor axis" (g2 > 0, m = g1 b/(g3 a) < 1, older write-ups' mu = 1/m):
  L = (A1 dn, A2 sn, A3 cn)(u),  psi = t/J3 - atan2(L2, L1) + alpha Pi(nu; am u | m),
  quaternion chart built on 1 + L3;
- separatrix (g2 = 0): L = (A1 sech, tanh, A3 sech)(u), psi = t/J2 + 2 atan(delta tanh(u/2)),
  chart built on 1 + L1;
- uniform rotation (L along a principal direction, a sphere, L = 0) is handled in ``_body``.

Where nu >= -1 the code uses alpha Pi = alpha u + alpha (Pi - F) (F(am u|m) = u, alpha B = 1/J1 - 1/J3):
psi = t/J3 + atan2(L2, L3) - alpha (Pi - F) in the major regime, psi = t/J1 - atan2(L2, L1) +
alpha (Pi - F) in the minor one, up to a constant (see ``constants``).

u = u0 + B t where the phase u0 matches the initial angular momentum (computed from the ratios of its
components, not from an amplitude, so that it keeps its digits next to the separatrix).  The complement mc = 1 - m is
formed from g2 directly (mc = c |g2| / (g1 b) or c g2 / (g3 a)) so that it keeps full relative precision
next to the separatrix.
"""

from __future__ import annotations

import jax.numpy as jnp

from . import _series
from ._fusion import materialise, when_any
from .special._carlson import _rf_unrolled
from .special._circular import cos_sin
from .special._jacobi import _ellipj, _half_periods, _quarter_period
from .special._legendre import (
    _LARGE_NEGATIVE_CHARACTERISTIC,
    pi_without_first_kind,
    pi_without_first_kind_from,
    rj_complete,
    third_kind_arguments,
)


MAJOR, MINOR, SEPARATRIX, UNIFORM = 0, 1, 2, 3

# Harmless stand-in bodies for the branches not taken (safe-where pattern): each lies well inside the
# regime whose formulas it feeds, so no square root of zero or division by zero is ever evaluated.
_SAFE_INERTIA = (1.0, 2.0, 3.0)
_SAFE_MAJOR = (0.3, 0.0, 0.9539392014169456)


def _substitute(condition, inertia, unit_momentum, safe_momentum):
    safe_j = jnp.asarray(_SAFE_INERTIA, inertia.dtype)
    safe_l = jnp.asarray(safe_momentum, inertia.dtype)
    j = jnp.where(condition[..., None], inertia, safe_j)
    l = jnp.where(condition[..., None], unit_momentum, safe_l)
    return j, l


def energy_gaps(inertia, unit_momentum):
    """(g1, g2, g3) = (1 - d J1, d J2 - 1, d J3 - 1) without cancellation (docs/theory.md §3)."""
    j1, j2, j3 = inertia[..., 0], inertia[..., 1], inertia[..., 2]
    l1s, l2s, l3s = unit_momentum[..., 0] ** 2, unit_momentum[..., 1] ** 2, unit_momentum[..., 2] ** 2
    g1 = l2s * (j2 - j1) / j2 + l3s * (j3 - j1) / j3
    g3 = l1s * (j3 - j1) / j1 + l2s * (j3 - j2) / j2
    g2 = l1s * (j2 - j1) / j1 - l3s * (j3 - j2) / j3
    return g1, g2, g3


def classify(inertia, unit_momentum, momentum_norm):
    """Regime code per body (MAJOR, MINOR, SEPARATRIX or UNIFORM), from exact tests only."""
    j1, j2, j3 = inertia[..., 0], inertia[..., 1], inertia[..., 2]
    l1, l3 = unit_momentum[..., 0], unit_momentum[..., 2]
    g1, g2, g3 = energy_gaps(inertia, unit_momentum)
    # L along a principal direction (including the degenerate planes of symmetric bodies): Omega || L.
    uniform = (
        (momentum_norm == 0)
        | (j1 == j3)
        | ((g2 < 0) & (g3 == 0))
        | ((g2 > 0) & (g1 == 0))
        | ((g2 == 0) & ((j1 == j2) | (j2 == j3) | ((l1 == 0) & (l3 == 0))))
    )
    code = jnp.where(g2 < 0, MAJOR, jnp.where(g2 > 0, MINOR, SEPARATRIX))
    return jnp.where(uniform, UNIFORM, code)


def orbit_constants(inertia, unit_momentum, regime):
    """The elementwise per-body constants of the regime's exact solution (docs/theory.md §4-5): no
    elliptic integral.  A dict of arrays: amplitude (..., 3), rate B, m, mc, alpha, nu, precession,
    without_first_kind, regime, the point (sn0, cn0) (unit, stand-ins outside the elliptic regimes)
    and the separatrix phase u0 (stand-ins outside it)."""
    is_major, is_minor, is_sep = regime == MAJOR, regime == MINOR, regime == SEPARATRIX

    # Around the major axis (around the minor axis): one set of formulas in the roles of the axes.
    # The pivot axis p is the one the quaternion chart is built on, J1 (J3), o the other extreme, J3
    # (J1) (the one the orbit circles); g_p = g1 (g3) and g_o = g3 (g1) are their energy gaps, and
    # gap_p = J3 - J2 (J2 - J1) and gap_o = J2 - J1 (J3 - J2) the gaps of J2 from o and from p.  Then
    # the regime's formulas (docs/theory.md §4) read
    #   A_p = sqrt(J_p g_o/c), A2 = sqrt(J2 g_o/gap_p), A_o = sqrt(J_o g_p/c), B = sqrt(g_p gap_p/(J1 J2 J3)),
    #   m = g_o gap_o/(g_p gap_p), mc = c |g2|/(g_p gap_p), alpha = c/sqrt(J_p g_p gap_p J_o/J2),
    #   nu = -J_p g_o/(J_o g_p), precession 1/J_p,
    # so that the minor axis regime is the major one with the roles of J1 and J3 exchanged.
    is_elliptic = is_major | is_minor
    j, l = _substitute(is_elliptic, inertia, unit_momentum, _SAFE_MAJOR)
    j1, j2, j3 = j[..., 0], j[..., 1], j[..., 2]
    g1, g2, g3 = energy_gaps(j, l)
    a, b, c = j2 - j1, j3 - j2, j3 - j1
    j_pivot, j_other = jnp.where(is_minor, j3, j1), jnp.where(is_minor, j1, j3)
    g_pivot, g_other = jnp.where(is_minor, g3, g1), jnp.where(is_minor, g1, g3)
    gap_pivot, gap_other = jnp.where(is_minor, a, b), jnp.where(is_minor, b, a)
    amplitude_pivot = jnp.sqrt(j_pivot * g_other / c)
    amplitude_middle = jnp.sqrt(j2 * g_other / gap_pivot)
    amplitude_other = jnp.sqrt(j_other * g_pivot / c)
    elliptic = dict(
        amplitude=jnp.stack(
            [
                jnp.where(is_minor, amplitude_other, amplitude_pivot),
                amplitude_middle,
                jnp.where(is_minor, amplitude_pivot, amplitude_other),
            ],
            -1,
        ),
        rate=jnp.sqrt(g_pivot * gap_pivot / (j1 * j2 * j3)),
        m=g_other * gap_other / (g_pivot * gap_pivot),
        mc=c * jnp.abs(g2) / (g_pivot * gap_pivot),
        alpha=c / jnp.sqrt(j1 * g_pivot * gap_pivot * j3 / j2),
        nu=-j_pivot * g_other / (j_other * g_pivot),
        precession=1 / j_pivot,
    )
    # sn0 : cn0 = l2/A2 : l_p/A_p (cn0 >= 0 in the working frame): ratios of the given components.
    sn_scaled = l[..., 1] * amplitude_pivot
    cn_scaled = jnp.where(is_minor, l[..., 2], l[..., 0]) * amplitude_middle

    # Separatrix: constants depend on the moments alone.
    j, l = _substitute(is_sep, inertia, unit_momentum, (0.0, 0.0, 1.0))
    j1, j2, j3 = j[..., 0], j[..., 1], j[..., 2]
    a, b, c = j2 - j1, j3 - j2, j3 - j1
    one = jnp.ones_like(j1)
    separatrix = dict(
        amplitude=jnp.stack([jnp.sqrt(j1 * b / (j2 * c)), one, jnp.sqrt(j3 * a / (j2 * c))], -1),
        rate=jnp.sqrt(a * b / (j1 * j3)) / j2,
        m=one,
        mc=jnp.zeros_like(j1),
        # delta = (sqrt(J2 c) - sqrt(J1 b))/sqrt(J3 a) = sqrt(J3 a)/(sqrt(J2 c) + sqrt(J1 b)).
        alpha=jnp.sqrt(j3 * a) / (jnp.sqrt(j2 * c) + jnp.sqrt(j1 * b)),
        nu=jnp.zeros_like(j1),
        precession=1 / j2,
    )
    # sech(u0) = l1/A1 and tanh(u0) = l2, so sinh(u0) = l2 A1/l1 (l1 > 0 on a moving separatrix orbit):
    # unlike artanh(l2) this keeps its precision when l is within rounding of the saddle (l2 -> 1).
    separatrix_u0 = jnp.arcsinh(l[..., 1] * separatrix["amplitude"][..., 0] / jnp.where(is_sep, l[..., 0], 1))

    def pick(key):
        # Vector constants (the amplitudes) need the regime masks with a trailing axis.
        vector = elliptic[key].ndim > regime.ndim
        separatrix_mask = is_sep[..., None] if vector else is_sep
        return jnp.where(separatrix_mask, separatrix[key], elliptic[key])

    out = {key: pick(key) for key in elliptic}
    # alpha Pi(nu; am u|m) = alpha u + alpha (Pi - F)(nu; am u|m) for nu >= -1 (F(am u|m) = u).  The
    # constant alpha u0 drops out (only differences of psi matter) and alpha B = 1/J1 - 1/J3 turns the
    # precession rate 1/J1 (1/J3) into 1/J3 (1/J1).  This matters where alpha ~ 1/sqrt(J2 - J1) is huge
    # (nearly symmetric bodies with L near the plane of the two close axes): alpha Pi ~ alpha K there,
    # and its rounding error alone (1e-7 for a one-ulp gap) would swamp the motion, while
    # alpha (Pi - F) = alpha nu (...) stays O(1) because nu ~ J2 - J1.  For nu < -1 (L near the axis
    # the orbit circles, alpha ~ 1/sqrt(g) but Pi ~ sqrt(g)) the whole Pi is used.
    out["without_first_kind"] = (out["nu"] >= _LARGE_NEGATIVE_CHARACTERISTIC) & ~is_sep
    swapped_rate = jnp.where(is_minor, 1 / inertia[..., 0], 1 / inertia[..., 2])
    out["precession"] = jnp.where(out["without_first_kind"], swapped_rate, out["precession"])

    # The point (sn0, cn0) of the phase, with stand-ins outside the elliptic regimes.
    out["sn0"], out["cn0"] = _unit_point(jnp.where(is_elliptic, sn_scaled, 0.6), jnp.where(is_elliptic, cn_scaled, 0.8))
    out["separatrix_u0"] = separatrix_u0
    out["regime"] = regime
    return out


def constants(inertia, unit_momentum, regime):
    """Per-body constants of the regime's exact solution (docs/theory.md §4-5), as a dict of arrays:
    ``orbit_constants`` and the elliptic integrals of the theta series (``_series``)."""
    out = orbit_constants(inertia, unit_momentum, regime)
    is_minor, is_sep = regime == MINOR, regime == SEPARATRIX
    is_elliptic = (regime == MAJOR) | is_minor
    separatrix_u0 = out.pop("separatrix_u0")
    sn0, cn0 = out.pop("sn0"), out.pop("cn0")
    # The elliptic integrals of the constructor, all from one duplication loop (below).  Bodies outside
    # the elliptic regimes (separatrix, uniform rotation) get harmless stand-ins (their results are not
    # used).
    nu = jnp.where(is_elliptic, out["nu"], -0.5)
    m = jnp.where(is_elliptic, out["m"], 0.5)
    mc = jnp.where(is_elliptic, out["mc"], 0.5)
    # Materialised: the integrals below and their derivatives would otherwise each recompute the
    # regime formulas above inside their own fused loops (see _fusion), in the gradient most of all.
    nu, m, mc, sn0, cn0 = materialise((nu, m, mc, sn0, cn0))
    # R_F: the phase u0 = F(am0|m) = sn0 R_F(cn0^2, dn0^2, 1) (DLMF 19.25.5 from sn0, cn0 themselves:
    # near the separatrix am0 is within 1e-13 of pi/2 and only cn0 carries the digits), and the
    # series' K(m), a' and b (``_series.integral_arguments``).  Where cn0^2 < mc sn0^2 (cn0 = 0 included)
    # the phase is taken from the quarter period instead, |u0| = K - cn0 R_F(mc sn0^2, mc, dn0^2) (the
    # integral from am0 to pi/2 with theta -> pi/2 - theta: DLMF 19.25.5 with parameter -m/mc, scaled
    # by mc since R_F is homogeneous of degree -1/2).  Through cn0^2 the derivative in cn0 would be lost
    # at cn0 = 0 (0 times the infinite dR_F/dx); the reflected arguments all lie between mc sn0^2 and
    # 2 mc.  Not wider: where cn0^2 >> mc, K and the reflected integral have large derivatives in mc
    # (~ 1/mc next to the separatrix) that cancel in u0.
    mc_sn0_squared = mc * (sn0 * sn0)
    reflected = cn0 * cn0 < mc_sn0_squared
    dn0_squared = cn0 * cn0 + mc_sn0_squared
    phase_x = jnp.where(reflected, mc_sn0_squared, cn0 * cn0)
    phase_y = jnp.where(reflected, mc, dn0_squared)
    phase_z = jnp.where(reflected, dn0_squared, jnp.ones_like(sn0))
    series_x, series_y, series_z = _series.integral_arguments(m, mc, nu)
    # One duplication (``_rf_unrolled``: R_F alone) on five rows (x, y, z): the phase (u0), (0, mc, 1)
    # (K(m)) and the series' a', b and K'.  Its twelve steps are unrolled (an R_F step is three square
    # roots: little code, one fused pass) and always all taken, so that a body gets the same bits alone
    # or in any batch; its JVP rule is a rolled loop.
    # The only third-kind integral of the constructor is the complete Pi(nu|m) (- K for nu >= -1) of
    # every whole half-period, from R_J(0, mc, 1, 1 - n') (n' the characteristic of DLMF 19.7.8) by
    # Bulirsch's cel iteration (``rj_complete``: a square root and a quotient per step, where R_J's
    # duplication costs an R_C at every step).  Pi at the phase u0, for the attitude at t = 0, is the
    # series' own value at u0 (``reference``): the same function as at every other time.
    first_kind = _rf_unrolled(
        jnp.concatenate([phase_x[None], series_x]),
        jnp.concatenate([phase_y[None], series_y]),
        jnp.concatenate([phase_z[None], series_z]),
    )
    first_kind, complete_third_kind = materialise((first_kind, _complete_third_kind(nu, m, mc)))
    quarter, phase_integral = first_kind[1], first_kind[0]
    sign = jnp.where(sn0 < 0, -1.0, 1.0).astype(sn0.dtype)
    remaining_phase = cn0 * phase_integral  # K - |u0| where reflected
    elliptic_u0 = jnp.where(reflected, sign * (quarter - remaining_phase), sn0 * phase_integral)
    out["u0"] = jnp.where(is_sep, separatrix_u0, elliptic_u0)
    out["third_kind_complete"] = complete_third_kind
    # The theta series (``_series``) of every body: Pi(nu; am u|m) - u (nu >= -1) or Pi(nu; am u|m)
    # (nu < -1) on a reduced argument, in the nome q or (next to the separatrix) in the complementary
    # nome q'.  Unlike a Fourier series, whose terms fall like rho^n (rho -> 1 as nu -> -infinity),
    # the theta series' terms fall like q^(n(n-1)) rho^n, so every nu < 0 is expanded directly.
    series = _series.coefficients(m, mc, nu, first_kind[1:], complete_third_kind)
    # The separatrix is the limit m = 1 of the major regime (q' = 0): its L is (A1 cn, sn, A3 dn) with
    # cn = dn = sech, sn = tanh, and its psi = u/(J2 B) + 2 arctan(delta tanh(u/2)) (docs/theory.md §5) equals
    # t/J2 + atan2(L2, L3) - arctan((A1/A3) tanh u): the major regime's alpha Pi(nu; gd u|1), with
    # nu = -J1 b/(J3 a), is alpha (u + sqrt(-nu) arctan(sqrt(-nu) tanh u))/(1 - nu), whose linear part
    # turns t/J1 into t/J2 (alpha B/(1 - nu) = 1/J1 - 1/J2) and whose bounded part has
    # alpha sqrt(-nu)/(1 - nu) = 1 and sqrt(-nu) = A1/A3 (A1^2 + A3^2 = 1).  So the series' third kind
    # there is A arctan(tan beta' tanh u) with sin beta' = A1, cos beta' = A3, no slope, and
    # A = 1/delta = (1 + A1)/A3 (alpha = delta on the separatrix).
    first_amplitude = jnp.where(is_sep, out["amplitude"][..., 0], 0.5)
    third_amplitude = jnp.where(is_sep, out["amplitude"][..., 2], 0.5)
    series = _series.at_separatrix(
        series,
        is_sep,
        first_amplitude,
        third_amplitude,
        (1 + first_amplitude) / third_amplitude,
        jnp.zeros_like(first_amplitude),
    )
    out["series"] = series
    # Materialised: otherwise XLA fuses the last steps of the per-body constants (the series'
    # coefficients, the tail of the complete Pi) into the evaluation's loops over
    # bodies and times, and recomputes them at every time and for each output that uses them.
    return materialise(out)


def _complete_third_kind(nu, m, mc):
    """Pi(nu|m) - K(m) (nu >= -1) or Pi(nu|m) (nu < -1): the integral of ``pi_without_first_kind``
    over a half period, its R_J(0, mc, 1, 1 - n') (n' the characteristic of DLMF 19.7.8) by Bulirsch's
    cel iteration (``rj_complete``)."""
    one, zero = jnp.ones_like(m), jnp.zeros_like(m)
    *_, complete_parameter = third_kind_arguments(nu, one, zero, m, mc)
    return pi_without_first_kind_from(nu, one, zero, m, mc, rj_complete(mc, complete_parameter))


def _unit_point(sn_scaled, cn_scaled):
    """(sn, cn) with sn^2 + cn^2 = 1 from (sn, cn) known up to a common positive factor."""
    # Scale by the larger one first: both can be ~1e-222 (an L component of 1e-111), whose squares underflow.
    largest = jnp.maximum(jnp.abs(sn_scaled), jnp.abs(cn_scaled))
    largest = jnp.exp2(jnp.floor(jnp.log2(jnp.where(largest > 0, largest, 1))))  # a power of 2: exact
    sn_scaled, cn_scaled = sn_scaled / largest, cn_scaled / largest
    norm = jnp.sqrt(sn_scaled * sn_scaled + cn_scaled * cn_scaled)
    return sn_scaled / norm, cn_scaled / norm


def evaluate(consts, tau, attitude=True):
    """Unit angular momentum and (if ``attitude``) the particular quaternion q̂ at unit-|L| time tau.

    q̂ is the solution of docs/theory.md §5 at phase u = u0 + B tau, except that the precession angle psi
    counts from tau = 0 (psi = precession * tau + the bounded terms at u): only differences of psi
    enter the motion (q̂ is a rotation about the fixed spatial axis by psi times a function of L), and
    the phase time t0 = u0/B of the textbook form is unbounded for nearly spherical bodies (B -> 0).

    Every body goes through its theta series (``_series``: in the nome q, or next to the separatrix
    and on it in the complementary nome q'), elementwise: the third-kind integral is 2 turns times the
    complete one plus the series' integral over the reduced argument (DLMF 19.2.10).
    """
    u = consts["u0"] + consts["rate"] * tau
    sn_r, cn_r, dn, reduced_third_kind, turns = _series.evaluate_series(consts["series"], consts["mc"], u, attitude)
    parity = 1 - 2 * jnp.mod(turns, 2)
    sn, cn = parity * sn_r, parity * cn_r
    minor = consts["regime"] == MINOR
    first = jnp.where(minor, dn, cn)
    third = jnp.where(minor, cn, dn)
    momentum = consts["amplitude"] * jnp.stack([first, sn, third], -1)
    if not attitude:
        return momentum, None
    l1, l2, l3 = momentum[..., 0], momentum[..., 1], momentum[..., 2]
    third_kind = 2 * turns * consts["third_kind_complete"] + reduced_third_kind
    orientation = jnp.where(minor, -1, 1)
    partner = jnp.where(minor, l1, l3)
    psi = consts["precession"] * tau + orientation * (jnp.arctan2(l2, partner) - consts["alpha"] * third_kind)
    return _chart(psi, l1, l2, l3, minor), momentum


def reference(consts, unit_momentum):
    """q̂ at tau = 0: the chart of ``evaluate`` at u0, on the given unit angular momentum itself.

    At tau = 0 the phase u0 lies in [-K, K] (cn0 >= 0 in the working frame), so the third-kind
    integral needs no whole periods: the series' own value at u0 (``_series.third_kind_at``), so that
    differences of psi between tau and 0 come from one function.
    """
    regime = consts["regime"]
    minor = regime == MINOR
    # Uniform rotation (L = 0 included) has stand-in constants of the major regime; its stand-in L too,
    # so that nothing here is NaN (its result is not used).
    uniform = (regime == UNIFORM)[..., None]
    unit_momentum = jnp.where(uniform, jnp.asarray(_SAFE_MAJOR, unit_momentum.dtype), unit_momentum)
    l1, l2, l3 = unit_momentum[..., 0], unit_momentum[..., 1], unit_momentum[..., 2]
    partner = jnp.where(minor, l1, l3)
    third_kind = _series.third_kind_at(consts["series"], consts["u0"])
    orientation = jnp.where(minor, -1, 1)
    psi = orientation * (jnp.arctan2(l2, partner) - consts["alpha"] * third_kind)
    return _chart(psi, l1, l2, l3, minor)


def evaluate_once(orbit, unit_momentum, tau, attitude=True):
    """The motion at one unit-|L| time tau per body from ``orbit_constants`` alone: no theta series.

    Returns (unit L(tau), q̂(0), q̂(tau)) in the working frame, the charts with psi counted from
    tau = 0 (so that q = q0 ⊗ P ⊗ conj(q̂(0)) ⊗ q̂(tau) ⊗ conj(P)), or (unit L(tau), None, None) when
    ``attitude`` is false.  For a body evaluated at one time, the series' per-body data (five R_F,
    the complete Pi, the coefficients) cost more than the motion itself; here (docs/theory.md §11):

    - the phase u0 is never formed: with v = B tau, the Jacobi functions at u0 + v follow from those
      at u0 (the given L: sn0, cn0) and at v (``special.ellipj``) by the addition theorem
      (DLMF 22.8.1-22.8.3, denominator 1 - m sn0^2 sn_v^2 = cn0^2 + sn0^2 dn_v^2 without cancellation);
    - the third kind f(u) = Pi(n; am u|m) obeys f(u0 + v) - f(u0) = f(v) - G(u0, v) with the
      elementary addition term (Jacobi's addition theorem for his Pi(u, a) at the imaginary a with
      m sn^2 a = n, Whittaker and Watson 22.74)
          G = A atan2(sqrt(-n (m - n)(1 - n)) sn0 sn_v sn_w, 1 - n sn_w^2 + n sn0 sn_v cn_w dn_w),
      A = sqrt(-n / ((1 - n)(m - n))), w = u0 + v (the real part stays positive: checked on 3e6
      random points, both sides of the separatrix, n from -1e-8 to -1e8);
    - f(v) = 2 j Pi(n|m) + f(v_r) (DLMF 19.2.10) with v = 2 j K + v_r, |v_r| <= K: one R_J at the
      reduced point (``pi_without_first_kind``) and, only for a batch where some v spans a half
      period, the complete Pi by cel.
    F is additive (F(am u) = u), so the same G serves Pi - F (nu >= -1, see ``orbit_constants``).
    On the separatrix L and psi are elementary in u = u0 + B tau (docs/theory.md §5).
    """
    regime = orbit["regime"]
    minor, separatrix = regime == MINOR, regime == SEPARATRIX
    elliptic = (regime == MAJOR) | minor
    m = jnp.where(elliptic, orbit["m"], 0.5)
    mc = jnp.where(elliptic, orbit["mc"], 0.5)
    nu = jnp.where(elliptic, orbit["nu"], -0.5)
    sn0, cn0 = orbit["sn0"], orbit["cn0"]
    dn0 = jnp.sqrt(cn0 * cn0 + mc * (sn0 * sn0))
    v = jnp.where(elliptic, orbit["rate"] * tau, 0)
    # Materialised: the Jacobi functions' fused loops would otherwise each recompute the constants.
    m, mc, nu, sn0, cn0, dn0, v = materialise((m, mc, nu, sn0, cn0, dn0, v))
    # Materialised here and below: each value feeds several outputs, whose fused loops would otherwise
    # each recompute it (see _fusion).
    # The amplitude am(v) is left out before the conditional: a conditional's results are all computed,
    # and its arctangent cost 3% of the one-time path.
    sn_v, cn_v, dn_v = materialise(_ellipj(v, m, mc)[:3])
    # DLMF 22.8.1-22.8.3 at u0 + v as increments over (sn0, cn0, dn0), which vanish at v = 0 and are
    # O(v) without cancellation: then L(tau) = l + A (increments) returns the given l exactly at
    # tau = 0, and over a short step it changes by the increments alone, whose rounding is relative to
    # them.  (Formed as sn(u0 + v) - sn0 instead, the rounding of a few ulp of |l| had a bias that
    # accumulated over the many short steps of a splitting method.)  With sn0^2 + cn0^2 = 1:
    #   1 - m sn0^2 sn_v^2 = D = cn0^2 + sn0^2 dn_v^2,
    #   D (sn_w - sn0) = cn0 dn0 sn_v - sn0 ((1 - cn_v dn_v) - sn0^2 (1 - dn_v^2)),
    #   D (cn_w - cn0) = -cn0 ((1 - cn_v) - sn0^2 (1 - dn_v^2)) - sn0 dn0 sn_v dn_v,
    #   dn_w - dn0 = ((cn_w - cn0)(cn_w + cn0) + mc (sn_w - sn0)(sn_w + sn0))/(dn_w + dn0),
    # with 1 - cn_v = sn_v^2/(1 + cn_v) (cn_v > 0) and 1 - dn_v = m sn_v^2/(1 + dn_v).
    # The numerators cancel to O(1) rounding where D is small (next to the saddle: cn0 and dn_v both
    # small), so there (D < 1/4), and for longer steps, the increments come from the direct form,
    # D sn_w = sn0 cn_v dn_v + cn0 dn0 sn_v and D cn_w = cn0 cn_v - sn0 dn0 sn_v dn_v (products of the
    # small factors themselves, normalised so that sn^2 + cn^2 = 1 to an ulp).
    sn_v_squared = sn_v * sn_v
    one_minus_cn = jnp.where(cn_v > 0, sn_v_squared / (1 + jnp.abs(cn_v)), 1 - cn_v)
    one_minus_dn = m * sn_v_squared / (1 + dn_v)
    one_minus_dn_squared = one_minus_dn * (1 + dn_v)
    one_minus_cn_dn = one_minus_cn + cn_v * one_minus_dn
    sn0_squared = sn0 * sn0
    denominator = cn0 * cn0 + sn0_squared * (dn_v * dn_v)
    # Increments for short steps (sn_v^2 <= 1/4, |v| below about K/3), where the bias mattered; the
    # normalised direct form elsewhere keeps |L| and the energy to an ulp over long times.
    incremental = (denominator >= 0.25) & (sn_v_squared <= 0.25)
    sn_change = (cn0 * dn0 * sn_v - sn0 * (one_minus_cn_dn - sn0_squared * one_minus_dn_squared)) / denominator
    cn_change = (-cn0 * (one_minus_cn - sn0_squared * one_minus_dn_squared) - sn0 * dn0 * sn_v * dn_v) / denominator
    sn_direct = (sn0 * cn_v * dn_v + sn_v * cn0 * dn0) / denominator
    cn_direct = (cn0 * cn_v - sn0 * dn0 * sn_v * dn_v) / denominator
    norm = jnp.sqrt(sn_direct * sn_direct + cn_direct * cn_direct)
    sn_w = jnp.where(incremental, sn0 + sn_change, sn_direct / norm)
    cn_w = jnp.where(incremental, cn0 + cn_change, cn_direct / norm)
    dn_w = jnp.sqrt(cn_w * cn_w + mc * (sn_w * sn_w))
    # dn_w^2 - dn0^2 = (cn_w^2 - cn0^2) + mc (sn_w^2 - sn0^2): the rounding of sn_change enters scaled by
    # mc, so that dn keeps its precision where dn_w + dn0 is as small as sqrt(mc) (next to the saddle).
    dn_change = (cn_change * (cn_w + cn0) + mc * sn_change * (sn_w + sn0)) / (dn_w + dn0)
    u = jnp.where(separatrix, orbit["separatrix_u0"] + orbit["rate"] * tau, 0)

    def on_separatrix(u, sn_w, cn_w, dn_w, momentum):
        # sn = tanh u, cn = dn = sech u = 2 e/(1 + e^2), e = exp(-|u|) (no overflow).
        decay = jnp.exp(-jnp.abs(u))
        sech = 2 * decay / (1 + decay * decay)
        values = jnp.stack([sech, jnp.tanh(u), sech], -1)
        momentum = jnp.where(separatrix[..., None], orbit["amplitude"] * values, momentum)
        return (
            jnp.where(separatrix, jnp.tanh(u), sn_w),
            jnp.where(separatrix, sech, cn_w),
            jnp.where(separatrix, sech, dn_w),
            momentum,
        )

    # L = l + A (increments) in the elliptic regimes (minor: (A1 dn, A2 sn, A3 cn)), A (sn, cn, dn)(w)
    # itself where the direct form was taken (there the increments are not used).
    changes = jnp.stack([jnp.where(minor, dn_change, cn_change), sn_change, jnp.where(minor, cn_change, dn_change)], -1)
    values = jnp.stack([jnp.where(minor, dn_w, cn_w), sn_w, jnp.where(minor, cn_w, dn_w)], -1)
    momentum = jnp.where(
        incremental[..., None], unit_momentum + orbit["amplitude"] * changes, orbit["amplitude"] * values
    )
    momentum = jnp.where(elliptic[..., None], momentum, unit_momentum)
    # Batches without a body on the separatrix (almost all) skip its hyperbolic functions.
    sn_w, cn_w, dn_w, momentum = when_any(separatrix, on_separatrix, lambda u, *w: w, u, sn_w, cn_w, dn_w, momentum)
    sn_w, cn_w, dn_w, momentum = materialise((sn_w, cn_w, dn_w, momentum))
    if not attitude:
        return momentum, None, None

    quarter = _quarter_period(mc)
    turns, _ = _half_periods(v, mc, quarter)
    parity = 1 - 2 * jnp.mod(turns, 2)
    reduced = materialise(pi_without_first_kind(nu, parity * sn_v, parity * cn_v, m, mc))

    def whole_turns(turns, nu, m, mc):
        return 2 * turns * _complete_third_kind(nu, m, mc)

    periods = when_any(turns != 0, whole_turns, lambda turns, *_: jnp.zeros_like(turns), turns, nu, m, mc)
    minus_nu = -nu
    addition_scale = jnp.sqrt(minus_nu * (m + minus_nu) * (1 + minus_nu))
    addition_amplitude = jnp.sqrt(minus_nu) / jnp.sqrt((1 + minus_nu) * (m + minus_nu))
    addition = addition_amplitude * jnp.arctan2(
        addition_scale * sn0 * sn_v * sn_w, 1 + minus_nu * (sn_w * sn_w) - minus_nu * sn0 * sn_v * cn_w * dn_w
    )
    third_kind_change = periods + reduced - addition

    # Uniform rotation has stand-in constants of the major regime: its stand-in L too (unused), at both
    # times, so that nothing here is NaN.
    uniform = (regime == UNIFORM)[..., None]
    safe = jnp.asarray(_SAFE_MAJOR, unit_momentum.dtype)
    unit_momentum = jnp.where(uniform, safe, unit_momentum)
    l1, l2, l3 = unit_momentum[..., 0], unit_momentum[..., 1], unit_momentum[..., 2]
    k1, k2, k3 = (jnp.where(uniform, safe, momentum)[..., k] for k in range(3))
    orientation = jnp.where(minor, -1, 1)
    # atan2(L2, L_o)(tau) - atan2(L2, L_o)(0) as one arctangent: L_o = L3 (L1 in the minor regime) is
    # A_o dn > 0 at both times, so both angles lie in (-pi/2, pi/2) and their difference in (-pi, pi).
    partner, partner_start = jnp.where(minor, k1, k3), jnp.where(minor, l1, l3)
    angle_change = jnp.arctan2(k2 * partner_start - partner * l2, partner * partner_start + k2 * l2)
    psi_elliptic = orientation * (angle_change - orbit["alpha"] * third_kind_change)

    def on_separatrix_angle(u, psi):
        # psi = tau/J2 + 2 arctan(delta tanh(u/2)) (docs/theory.md §5), delta = alpha.
        u0 = jnp.where(separatrix, orbit["separatrix_u0"], 0)
        delta = orbit["alpha"]
        bounded = 2 * (jnp.arctan(delta * jnp.tanh(u / 2)) - jnp.arctan(delta * jnp.tanh(u0 / 2)))
        return jnp.where(separatrix, bounded, psi)

    psi = when_any(separatrix, on_separatrix_angle, lambda u, psi: psi, u, psi_elliptic)
    psi = orbit["precession"] * tau + psi
    return momentum, _chart(None, l1, l2, l3, minor), _chart(psi, k1, k2, k3, minor)


def _chart(psi, l1, l2, l3, minor):
    """q̂ = exp(psi/2 about the spatial axis) ⊗ (the rotation taking that axis to l), docs/theory.md §5
    (psi None: psi = 0).

    The chart is built on 1 + L1 in the major axis regime and on the separatrix (1 + L1 >= 1 - A1 > 0),
    on 1 + L3 in the minor axis regime (1 + L3 >= 1 - A3 > 0).  Both are one formula: with the pivot
    component L_p = L1 or L3 and (first, second) = (L3, L2) or (L2, L1),
        w = cos(psi/2) r,  x_p = sin(psi/2) r,  (first cos + second sin)/(2r),  (first sin - second cos)/(2r),
    r = sqrt((1 + L_p)/2), in the order (w, x_p, y, z) for the major regime and (w, y, z, x_p) for the
    minor one: only the elementwise choice of inputs and the order of the outputs differ.
    """
    pivot = jnp.where(minor, l3, l1)
    first = jnp.where(minor, l2, l3)
    second = jnp.where(minor, l1, l2)
    if psi is None:
        # psi = 0 (the chart at the start of ``evaluate_once``).
        half_cos, half_sin = jnp.ones_like(pivot), jnp.zeros_like(pivot)
    else:
        # Materialised once: each of the four outputs below would otherwise recompute psi (and the
        # whole evaluation behind it) in its own fused loop (see _fusion).
        half_cos, half_sin, pivot, first, second = materialise((*cos_sin(psi / 2), pivot, first, second))
    base = 1 + pivot
    root, inverse = jnp.sqrt(base / 2), 1 / jnp.sqrt(2 * base)
    scalar = half_cos * root
    along_pivot = half_sin * root
    towards_first = (first * half_cos + second * half_sin) * inverse
    towards_second = (-second * half_cos + first * half_sin) * inverse
    return jnp.stack(
        [
            scalar,
            jnp.where(minor, towards_first, along_pivot),
            jnp.where(minor, towards_second, towards_first),
            jnp.where(minor, along_pivot, towards_second),
        ],
        -1,
    )
