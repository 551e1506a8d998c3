"""The two periods of a torque-free motion, and the motion with given periods.

A free asymmetric body (moments sorted I1 < I2 < I3, angular momentum M = |L|, energy E) moves in one
of two modes (Landau & Lifshitz, Mechanics, section 37; Kaasalainen 2001, A&A 376, 302; Pravec et al.
2005, Icarus 173, 108):

- short-axis mode (SAM), M^2 > 2 E I2: L circulates about the axis of the largest moment I3;
- long-axis mode (LAM), M^2 < 2 E I2: L circulates about the axis of the smallest moment I1.

The body-frame motion is periodic with the rotation period (of the Euler angle phi about the
circulated axis)

    P_phi = 4 K(k^2) sqrt(I1 I2 I3 / p),   SAM: p = (I3 - I2)(M^2 - 2 E I1),
                                           k^2 = (I2 - I1)(2 E I3 - M^2) / p;
                                           LAM: the same with I1 and I3 exchanged,

and the angle psi of the precession about L advances at the rate (Euler angles about the circulated
axis, with Landau's cn and sn of u = 4 K t / P_phi)

    SAM: dpsi/dt = M (cn^2/(I3 - I1) + sn^2/(I3 - I2)) / (I1 cn^2/(I3 - I1) + I2 sn^2/(I3 - I2)),
    LAM: the same with I1 and I3 exchanged,

a rational function of sn^2 whose mean over one P_phi is a complete elliptic integral of the third
kind, Pi(n | k^2) / K(k^2) (DLMF 19.2.8), giving the precession period P_psi = 2 pi / <dpsi/dt>.  A
principal-axis rotation is the limit k -> 0 of either mode: P_psi = 2 pi I / M.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .. import special
from .._body import _validate
from .._cpu_options import cpu_jit


__all__ = ["tumbler_periods"]


def _mode_quantities(sorted_inertia, momentum_squared, twice_energy, long_axis):
    """(P_phi, <dpsi/dt> / M) for sorted moments; LAM exchanges I1 and I3."""
    i1, i2, i3 = sorted_inertia[..., 0], sorted_inertia[..., 1], sorted_inertia[..., 2]
    first = jnp.where(long_axis, i3, i1)
    last = jnp.where(long_axis, i1, i3)
    p = (last - i2) * (momentum_squared - twice_energy * first)
    k2 = jnp.clip((i2 - first) * (twice_energy * last - momentum_squared) / p, 0.0, 1.0)
    # K = R_F(0, 1 - k^2, 1) (DLMF 19.25.1): one compiled kernel with its derivative on the CPU, where
    # ellipk's polynomials and, for its derivative, E's were compiled into every program that
    # differentiates the periods (the light-curve refinement's period prior).
    quarter = special.elliprf(jnp.zeros_like(k2), 1 - k2, jnp.ones_like(k2))
    period_phi = 4 * quarter * jnp.sqrt(i1 * i2 * i3 / p)
    # dpsi/dt / M = (alpha + beta s) / (gamma (1 - n s)), s = sn^2 u, n = -delta/gamma.  Over a period
    # of u, <1 / (1 - n s)> = Pi(n | k^2) / K(k^2) = 1 + n R / (3 K) and <s / (1 - n s)> = R / (3 K), with
    # R = R_J(0, 1 - k^2, 1, 1 - n) (DLMF 19.25.2): no quotient by delta, which vanishes for a
    # symmetric body (I2 equal to the first moment), where the mean is (alpha + beta <sin^2>) / gamma.
    alpha = 1 / (last - first)
    beta = 1 / (last - i2) - alpha
    gamma = first * alpha
    delta = i2 / (last - i2) - gamma
    characteristic = -delta / gamma
    third_kind_over_k = special.elliprj(jnp.zeros_like(k2), 1 - k2, jnp.ones_like(k2), 1 - characteristic) / (
        3 * quarter
    )
    mean_rate = (alpha * (1 + characteristic * third_kind_over_k) + beta * third_kind_over_k) / gamma
    return period_phi, mean_rate


def tumbler_periods(inertia: Float[Array, "... 3"], angular_momentum: Float[Array, "... 3"]):
    """(P_psi, P_phi, long_axis_mode) of the free motion with moments ``inertia`` (any order) and
    body-frame angular momentum ``angular_momentum`` (module docstring).

    P_psi: the mean precession period of the body about L; P_phi: the period of the body-frame
    motion (rotation about the circulated axis); ``long_axis_mode``: True for LAM.  In the units of
    time of the motion; batched, differentiable.  On the separatrix P_phi is infinite; so it is for a
    uniform rotation (a sphere, L along a principal axis or in the plane of two equal moments), whose
    P_psi is 2 pi / |Omega|.  Symmetric bodies take the same formulas as triaxial ones (the mean
    precession rate through R_J, without a quotient by the moments' difference).  Refused
    (ValueError, as by `FreeRigidBody`): trailing axes other than 3, leading axes that do not
    broadcast, and for concrete inputs moments that are not finite and > 0 or a non-finite
    angular momentum (under ``jit`` only the shapes are checked).
    """
    _validate(inertia, angular_momentum, None)
    return _tumbler_periods(jnp.asarray(inertia), jnp.asarray(angular_momentum))


@cpu_jit  # one program per shape: eagerly, each new shape compiled the elliptic formulas' operations in turn
def _tumbler_periods(inertia, momentum):
    order = jnp.argsort(inertia, axis=-1)
    sorted_inertia = jnp.take_along_axis(inertia, order, -1)
    sorted_momentum = jnp.take_along_axis(momentum, order, -1)
    # Uniform rotation (Omega parallel to L: a sphere, L along a principal axis or in the plane of two
    # equal moments): the body frame is at rest relative to L, P_psi = 2 pi / |Omega|, P_phi infinite.
    # Such bodies enter the elliptic formulas at a harmless triaxial point (safe where).
    omega = sorted_momentum / sorted_inertia
    scale = jnp.sum(sorted_momentum**2, -1) * jnp.sum(omega**2, -1)
    transverse = jnp.sum(jnp.cross(sorted_momentum, omega) ** 2, -1)
    uniform = transverse <= (64 * jnp.finfo(omega.dtype).eps) ** 2 * scale
    harmless = jnp.asarray([1.0, 2.0, 3.0], sorted_inertia.dtype)
    elliptic_inertia = jnp.where(uniform[..., None], harmless, sorted_inertia)
    elliptic_momentum = jnp.where(uniform[..., None], jnp.asarray([0.6, 0.0, 0.8], omega.dtype), sorted_momentum)
    momentum_squared = jnp.sum(elliptic_momentum**2, -1)
    twice_energy = jnp.sum(elliptic_momentum**2 / elliptic_inertia, -1)
    long_axis = momentum_squared < twice_energy * elliptic_inertia[..., 1]
    period_phi, mean_rate = _mode_quantities(elliptic_inertia, momentum_squared, twice_energy, long_axis)
    period_psi = 2 * jnp.pi / (jnp.sqrt(momentum_squared) * mean_rate)
    omega_norm = jnp.sqrt(jnp.sum(jnp.where(uniform[..., None], omega, 1.0) ** 2, -1))
    period_psi = jnp.where(uniform, 2 * jnp.pi / omega_norm, period_psi)
    period_phi = jnp.where(uniform, jnp.inf, period_phi)
    return period_psi, period_phi, long_axis & ~uniform


def momentum_from_periods(sorted_inertia, period_psi, period_phi, long_axis, polhode_phase, iterations=60):
    """Body-frame L (|L| = M) of the motion with moments ``sorted_inertia`` (I1 < I2 < I3), in the given
    mode, whose periods are (period_psi, period_phi), at the point ``polhode_phase`` (radians, the
    Jacobi argument u = 2 K phase / pi) of its body-frame orbit; and whether such a motion exists.

    The ratio P_psi / P_phi depends on the energy alone (for given moments): bisection on
    d = 2 E / M^2 over the mode's interval (SAM: 1/I3 < d < 1/I2; LAM: 1/I2 < d < 1/I1); then M from
    P_psi, which scales as 1/M.  Starting points of the period search.
    """
    i1, i2, i3 = sorted_inertia[..., 0], sorted_inertia[..., 1], sorted_inertia[..., 2]
    target = period_psi / period_phi
    one = jnp.ones_like(i1)

    def ratio(d):
        p_phi, rate = _mode_quantities(sorted_inertia, one, d, long_axis)
        return 2 * jnp.pi / rate / p_phi

    margin = 1e-9
    low = jnp.where(long_axis, 1 / i2, 1 / i3) * (1 + margin)
    high = jnp.where(long_axis, 1 / i1, 1 / i2) * (1 - margin)
    # Both ends in one evaluation, and the formulas once more in the loop (not four copies): each copy
    # of the elliptic formulas is code that XLA compiles.
    f_low, f_high = jax.vmap(lambda d: ratio(d) - target)(jnp.stack([low, high]))

    def bisect(_, state):
        lo, hi, _, _ = state
        mid = (lo + hi) / 2
        p_phi, rate = _mode_quantities(sorted_inertia, one, mid, long_axis)
        same = jnp.sign(2 * jnp.pi / rate / p_phi - target) == jnp.sign(f_low)
        return jnp.where(same, mid, lo), jnp.where(same, hi, mid), mid, rate

    # The last of iterations + 1 steps evaluates the midpoint of the bracket after ``iterations``:
    # d and its mean rate.
    zero = jnp.zeros_like(low)
    _, _, d, rate_unit = jax.lax.fori_loop(0, iterations + 1, bisect, (low, high, zero, zero))
    exists = (jnp.sign(f_high) != jnp.sign(f_low)) & jnp.isfinite(d)
    # The body-frame orbit (Landau's solution, M = 1) at u = 2 K phase / pi.
    first = jnp.where(long_axis, i3, i1)
    last = jnp.where(long_axis, i1, i3)
    p = (last - i2) * (1 - d * first)
    k2 = jnp.clip((i2 - first) * (d * last - 1) / p, 0.0, 1.0)
    sn, cn, dn, _ = special.ellipj(2 * special.ellipk(k2) * polhode_phase / jnp.pi, k2)
    omega_first = jnp.sqrt(jnp.maximum((d * last - 1) / (first * (last - first)), 0)) * cn
    omega_middle = jnp.sqrt(jnp.maximum((d * last - 1) / (i2 * (last - i2)), 0)) * sn
    omega_last = jnp.sqrt(jnp.maximum((1 - d * first) / (last * (last - first)), 0)) * dn
    unit = jnp.stack([first * omega_first, i2 * omega_middle, last * omega_last], -1)
    # LAM: 'first' is axis 3 and 'last' axis 1.
    unit = jnp.where(long_axis[..., None], unit[..., ::-1], unit)
    unit = unit / jnp.linalg.norm(unit, axis=-1, keepdims=True)
    norm = (2 * jnp.pi / rate_unit) / period_psi
    return unit * norm[..., None], exists
