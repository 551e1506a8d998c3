r"""Uniform rotation and its first-order neighbours (docs/theory.md §6, "Derivatives at a uniform rotation").

Where $\Omega_0 = L_0 / I$ is parallel to $L_0$ (in the principal frame) the body rotates uniformly:
$L(t) = L_0$ and $q(t) = q_0 \otimes \exp(t\,\Omega_0 / 2)$.  Those values are exact, but their
derivatives are not those of the motion: a change of $L_0$ across the axis or of unequal moments starts a
nutation.  The functions here return the uniform values and, as their derivative rule (a custom JVP),
the solution of the variational equations of the uniform rotation, which are linear with constant
coefficients and solved in closed form:

$$\dot{\delta L} = A\,\delta L + b,\qquad A v = L_0 \times (D v),\quad D = I^{-1} - \omega,
\quad b = -L_0 \times (L_0\, \delta I / I^2),$$

with $\omega = \sum_i n_i^2 / I_i$, $n = L_0 / |L_0|$ ($D n = 0$).  $A^3 = -\kappa A$ with
$\kappa = |L_0|^2 (n_1^2 D_2 D_3 + n_2^2 D_1 D_3 + n_3^2 D_1 D_2)$ (its second invariant), so

$$\delta L(t) = \delta L_0 + (S A + G A^2)\,\delta L_0 + (t + G A + H A^2)\, b,$$

$S = \sin(\sqrt\kappa t)/\sqrt\kappa$, $G = (1 - \cos\sqrt\kappa t)/\kappa$,
$H = (t - S)/\kappa$ ($\sinh$, $\cosh$ where $\kappa < 0$: spin about the middle axis, which is
unstable).  The attitude is $q(t) \otimes \exp(\varphi/2)$ with $\dot\varphi = \delta\Omega - \Omega_0
\times \varphi$; the conservation of the angular momentum in space, $R(t) L(t) = $ const, gives its part
across $n$ without integrating ($\delta L(t) + \varphi \times L_0 = e^{-t \hat\Omega_0} \delta L_0$):

$$\varphi_\perp = \tfrac{1}{|L_0|}\, n \times \big(e^{-t \hat\Omega_0} \delta L_0 - \delta L(t)\big),\qquad
n \cdot \varphi = t\,\big((n / I) \cdot \delta L_0 - |L_0| \textstyle\sum_i n_i^2\, \delta I_i / I_i^2\big),$$

each term written with its factor $|L_0|$ cancelled, so that $L_0 = 0$ (any unit $n$) gives
$\varphi = t\,\delta L_0 / I$.  Second derivatives are those of this first-order expansion (its
coefficients held at the uniform rotation): exact in $t$ and mixed with $t$; in the other directions
without the motion's second-order terms (symmetric for $L$, not exactly for the attitude, whose rule
is a product).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from . import _quaternion as quaternion
from ._frame import angular_velocity, matrix_product, matrix_times, to_body, to_principal
from ._fusion import sum_last


# |kappa t^2| below which each function is its Taylor series: where the closed forms lose more than
# a few ulp to cancellation (x - sin x for x < 2) and the series do not (terms to (-y)^13 / 29!).
_SERIES_LIMITS = (1.0, 1.0, 4.0)
_SERIES_TERMS = 14
# cosh and sinh of more overflow; derivatives of an unstable spin that large (e^700) saturate there.
_LARGEST_GROWTH = 700.0


def response_functions(y):
    """(f1, f2, f3)(y) = sum_k (-y)^k / (2k + j)!, j = 1, 2, 3: at x = sqrt(y), sin x / x,
    (1 - cos x) / x^2 and (x - sin x) / x^3 (sinh and cosh of sqrt(-y) for y < 0; DLMF 4.19.1-2, 4.33.1-2)."""
    growing = y < 0

    def taylor(j):
        terms = [(-1) ** k / math.factorial(2 * k + j) for k in range(_SERIES_TERMS)]
        value = jnp.zeros_like(y) + terms[-1]
        for term in terms[-2::-1]:
            value = value * y + term
        return value

    # Safe-where: the closed forms see only |y| >= 1 (the series cover the rest).
    x = jnp.sqrt(jnp.where(jnp.abs(y) < 1, 1, jnp.where(growing, jnp.minimum(-y, _LARGEST_GROWTH**2), y)))
    sin_x = jnp.where(growing, jnp.sinh(x), jnp.sin(x))
    half = jnp.where(growing, jnp.sinh(x / 2), jnp.sin(x / 2))
    closed = (sin_x / x, 2 * half * half / (x * x), jnp.where(growing, sin_x - x, x - sin_x) / (x * x * x))
    return tuple(
        jnp.where(jnp.abs(y) < limit, taylor(j + 1), value)
        for j, (limit, value) in enumerate(zip(_SERIES_LIMITS, closed))
    )


def _response(moments, momentum, t, d_moments, d_momentum):
    """(delta L(t), phi(t)) of the module docstring, principal frame, shapes broadcast(batch, t) + (3,)."""
    t = jnp.asarray(t, moments.dtype)[..., None]
    size_squared = sum_last(momentum * momentum)[..., None]
    spinning = size_squared > 0
    size = jnp.sqrt(jnp.where(spinning, size_squared, 1))
    unit = jnp.where(spinning, momentum / size, jnp.asarray([1.0, 0, 0], moments.dtype))
    size = jnp.where(spinning, size, 0)
    omega = sum_last(unit * unit / moments)[..., None]
    gaps = 1 / moments - omega

    def across(v):  # A v / |L0| = n x (D v)
        return jnp.cross(unit, gaps * v)

    n1, n2, n3 = unit[..., 0] ** 2, unit[..., 1] ** 2, unit[..., 2] ** 2
    d1, d2, d3 = gaps[..., 0], gaps[..., 1], gaps[..., 2]
    kappa = size_squared[..., 0] * (n1 * d2 * d3 + n2 * d1 * d3 + n3 * d1 * d2)
    f1, f2, f3 = response_functions(kappa[..., None] * t * t)
    sine, versine, excess = t * f1, t * t * f2, t * t * t * f3  # S, G, H

    # b / |L0| and the forced part W: delta L(t) gets |L0| W, phi gets -n x W.
    forcing = -size * jnp.cross(unit, unit * d_moments / moments**2)
    forced = t * forcing + versine * size * across(forcing) + excess * size_squared * across(across(forcing))
    turned = across(d_momentum)
    turned_twice = across(turned)
    d_angular_momentum = d_momentum + sine * size * turned + versine * size_squared * turned_twice + size * forced

    spin_angle = t * omega * size
    g1, g2, _ = response_functions(spin_angle * spin_angle)
    normal = jnp.cross(unit, d_momentum)
    perpendicular = (
        -t * omega * (g1 * jnp.cross(unit, normal) + spin_angle * g2 * normal)
        - sine * jnp.cross(unit, turned)
        - versine * size * jnp.cross(unit, turned_twice)
        - jnp.cross(unit, forced)
    )
    parallel = (
        t
        * (sum_last(unit / moments * d_momentum) - size[..., 0] * sum_last(unit * unit * d_moments / moments**2))[
            ..., None
        ]
    )
    return d_angular_momentum, perpendicular + parallel * unit


def _frozen(moments, momentum):
    """The uniform rotation whose variational equations the rules solve, as constants: differentiated
    again, the rules give the second derivatives of the first-order expansion about it."""
    return jax.lax.stop_gradient(moments), jax.lax.stop_gradient(momentum)


def _shape(moments, momentum, t):
    return jnp.broadcast_shapes(moments.shape[:-1], momentum.shape[:-1], jnp.shape(t)) + (3,)


def _in_principal_frame(axes, momentum, d_axes, d_momentum):
    """(R^T L0, its tangent dR^T L0 + R^T dL0): the turn of the axes moves L0 in the principal frame."""
    principal, d_principal = to_principal(axes, momentum), to_principal(axes, d_momentum)
    if axes is not None:
        d_principal = d_principal + to_principal(d_axes, momentum)
    return principal, d_principal


@jax.custom_jvp
def uniform_momentum(moments, momentum, t, axes=None):
    """L(t) = L0 (body frame), with the derivatives of the motion (module docstring).

    ``axes`` (..., 3, 3): the principal axes as columns in the body frame, or None.  In value this is
    a broadcast: the change of frame is in the derivative rule alone.
    """
    return jnp.broadcast_to(momentum, _shape(moments, momentum, t))


@uniform_momentum.defjvp
def _uniform_momentum_jvp(primals, tangents):
    moments, momentum, t, axes = primals
    d_moments, d_momentum, _, d_axes = tangents  # L is constant in t
    principal, d_principal = _in_principal_frame(axes, momentum, d_axes, d_momentum)
    d_angular_momentum, _ = _response(*_frozen(moments, principal), t, d_moments, d_principal)
    if axes is not None:
        # L(t) = R P(t): dR P(t) + R dP(t), P(t) = R^T L0 in value; P(t) through this rule, so that its
        # derivative (in the second derivatives) is the nutation that a turn of the axes starts, dP(t).
        principal_now = uniform_momentum(moments, principal, t)
        d_angular_momentum = matrix_times(d_axes, principal_now) + to_body(axes, d_angular_momentum)
    return uniform_momentum(moments, momentum, t, axes), d_angular_momentum


@jax.custom_jvp
def uniform_spin(moments, momentum, t, axes=None):
    """exp(t Omega0 / 2) (body frame, ``axes`` as in ``uniform_momentum``), with the derivatives of
    the motion: the attitude of a uniform rotation is q0 ⊗ uniform_spin."""
    t = jnp.asarray(t, moments.dtype)
    rotation = t[..., None] * angular_velocity(moments, axes, momentum)
    return quaternion.exp_pure(jnp.broadcast_to(rotation, _shape(moments, momentum, t)))


def _pure(vector):
    return jnp.concatenate([jnp.zeros(vector.shape[:-1] + (1,), vector.dtype), vector], -1)


@uniform_spin.defjvp
def _uniform_spin_jvp(primals, tangents):
    moments, momentum, t, axes = primals
    d_moments, d_momentum, d_t, d_axes = tangents
    spin = uniform_spin(moments, momentum, t, axes)
    principal, d_principal = _in_principal_frame(axes, momentum, d_axes, d_momentum)
    _, turn = _response(*_frozen(moments, principal), t, d_moments, d_principal)
    # In the principal frame q(t) ⊗ exp(phi / 2) to first order, and dq/dt = q ⊗ (0, Omega(t) / 2),
    # Omega(t) = L(t) / I with L(t) of uniform_momentum: Omega0 in value, and its derivative (the
    # mixed second derivative in t) is that of the motion, as is d/dt of phi.
    velocity = uniform_momentum(moments, principal, t) / moments
    rate = turn + jnp.asarray(d_t, moments.dtype)[..., None] * velocity
    if axes is None:
        return spin, quaternion.multiply(spin, _pure(rate / 2))
    # The body-frame spin is r ⊗ s ⊗ conj(r) (r: the axes as a quaternion): its tangent gains the
    # commutator with the axes' own turn w = vee(dR R^T) (body frame), and rate is turned by R.
    turn_of_axes = matrix_product(d_axes, jnp.swapaxes(axes, -1, -2))  # dR R^T, skew
    w = jnp.stack([turn_of_axes[..., 2, 1], turn_of_axes[..., 0, 2], turn_of_axes[..., 1, 0]], -1)
    half_w = jnp.broadcast_to(_pure(w / 2), spin.shape)
    d_spin = (
        quaternion.multiply(half_w, spin)
        - quaternion.multiply(spin, half_w)
        + quaternion.multiply(spin, _pure(to_body(axes, rate) / 2))
    )
    return spin, d_spin
