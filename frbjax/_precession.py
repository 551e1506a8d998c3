r"""Regular precession of a symmetric body and its first-order neighbours (docs/theory.md §6,
"Symmetric bodies next to the plane of their equal moments").

A body with two equal moments $a$ (axes $u$, $v$) and a third $c$ (the symmetry axis $e$) precesses
regularly: with $\alpha = 1/a$, $\gamma = 1/c$ and $\nu = (\gamma - \alpha)\, e \cdot L_0$,

$$L(t) = Q(t)\, L_0, \qquad q(t) = q_0 \otimes \exp(t \alpha L_0 / 2) \otimes \exp(t \nu e / 2),$$

$Q(t)$ the rotation by $-\nu t$ about $e$ ($\Omega = \alpha L + \nu e$).  The elliptic formulas give the
same motion ($m = 0$), but where $L_0$ is close to the plane of the equal moments their derivative in
an unequal change of those moments, $\delta I_u = -\delta I_v$, is the difference of terms
$1/(e \cdot n)^2$ larger than itself.  Here that derivative is the solution of the variational
equations of the precession, linear with coefficients that are constant in the frame that turns with
$Q$: with $x = Q^{\mathsf T} \delta L$ and $\Delta = (1/I_u - 1/I_v)/2$ (zero in value, its tangent the
change),

$$\dot x = A x + f(s),\quad A w = (\gamma - \alpha)(e \cdot w)\, L_0 \times e\ (A^2 = 0),\quad
f(s) = \Delta\, L_0 \times \big(\cos(2\nu s)\, J L_0 + \sin(2\nu s)\, e \times J L_0\big),$$

$J w = (u \cdot w) u - (v \cdot w) v$, so $x(t) = F_1 + A F_2$ with the repeated integrals
$F_k = \int_0^t (t - s)^{k-1}/(k-1)!\, f(s)\, ds$ (``response_functions`` of $(2\nu t)^2$).  The
attitude is $q(t) \otimes \exp(\varphi/2)$, $\varphi = Q \psi$: across $n = L_0/|L_0|$ the
conservation of the angular momentum in space gives $\psi \times L_0 = -x$; along it
$n \cdot \psi = \alpha\, n \cdot F_2 + (\gamma - \alpha)(n \cdot e)(e \cdot F_2) + \Delta \int_0^t
n \cdot (\cos(2\nu s) J L_0 + \sin(2\nu s) e \times J L_0)\, ds$.

The functions here are that first-order expansion off the symmetric bodies, written as ordinary
differentiable functions of the moments (their equal pair through its mean and $\Delta$), $L_0$, $t$
and the axes: every derivative of first order is that of the motion, and so are those of second
order except the one twice in the unequal direction (the expansion is linear in $\Delta$).
"""

from __future__ import annotations

import jax.numpy as jnp

from . import _quaternion as quaternion
from ._frame import dot, to_body
from ._fusion import sum_last
from ._uniform import response_functions

# Symmetric bodies whose unit L is closer than this to the plane of the equal moments take the
# precession: there the elliptic formulas' derivative in an unequal change of those moments loses
# about 1e-16 / (e . n)^2 relative (median over random bodies 2e-15 at 1/8, 1.2e-14 at 1/16, 6.5e-14
# at 0.03; 8e-5 at 1e-6), here none.  Not wider: the expansion misses the second derivative taken
# twice in that direction, which the elliptic formulas give.
PLANE_BAND = 1 / 8

# A stand-in symmetric body next to its plane for the bodies that do not take this branch (safe-where).
_SAFE_INERTIA = (1.0, 1.0, 2.0)
_SAFE_MOMENTUM = (0.6, 0.8, 0.05)


def _odd_axis(inertia):
    """The symmetry axis as a one-hot (..., 3) in the principal frame: where exactly two moments are
    equal, the third; zeros for a body without two equal moments, ones for a sphere."""
    i0, i1, i2 = inertia[..., 0], inertia[..., 1], inertia[..., 2]
    return jnp.stack([i1 == i2, i0 == i2, i0 == i1], -1)


def precessing(inertia, axes, momentum, uniform):
    """Bodies that take this branch: exactly two equal moments, not a uniform rotation, and unit L
    within ``PLANE_BAND`` of the plane of the equal moments."""
    odd = _odd_axis(inertia)
    symmetric = sum_last(odd.astype(jnp.int32)) == 1
    axis = to_body(axes, odd.astype(momentum.dtype))
    along = dot(axis, momentum)
    return symmetric & ~uniform & (along * along < PLANE_BAND**2 * sum_last(momentum * momentum))


def precession(band, inertia, momentum, t, axes=None, attitude=True):
    """(L(t), s(t)) of the bodies in ``band`` (body frame; q(t) = q0 ⊗ s(t); s None unless
    ``attitude``): the module docstring's first-order expansion.  Other bodies get a stand-in (finite,
    not to be used).  ``t`` broadcasts against the bodies' batch shape."""
    dtype = inertia.dtype
    inertia = jnp.where(band[..., None], inertia, jnp.asarray(_SAFE_INERTIA, dtype))
    momentum = jnp.where(band[..., None], momentum, jnp.asarray(_SAFE_MOMENTUM, dtype))
    odd = _odd_axis(inertia).astype(dtype)
    first, second = jnp.roll(odd, 1, -1), jnp.roll(odd, 2, -1)
    axis, u, v = (to_body(axes, w) for w in (odd, first, second))
    equal = sum_last((1 - odd) * inertia) / 2  # the mean of the equal pair: exact in value
    alpha, gamma = 1 / equal, 1 / sum_last(odd * inertia)
    # (1/I_u - 1/I_v)/2: zero in value, the unequal change of the pair in its tangent.
    unequal = (sum_last(first / inertia) - sum_last(second / inertia)) / 2

    t = jnp.asarray(t, dtype)[..., None]
    gap = (gamma - alpha)[..., None]
    along = dot(axis, momentum)[..., None]
    rate = gap * along  # nu
    angle = rate * t
    cosine, sine = jnp.cos(angle), jnp.sin(angle)

    def turned(w):  # Q(t) w: by -nu t about the symmetry axis
        w_along = dot(axis, w)[..., None]
        w_across = w - w_along * axis
        return w_along * axis + cosine * w_across - sine * jnp.cross(axis, w_across)

    reflected = dot(u, momentum)[..., None] * u - dot(v, momentum)[..., None] * v  # J L0
    spun = jnp.cross(axis, reflected)
    unequal = unequal[..., None]
    cosine_forcing = unequal * jnp.cross(momentum, reflected)
    sine_forcing = unequal * jnp.cross(momentum, spun)
    double = 2 * angle
    f1, f2, f3, _ = response_functions(double * double)
    once = t * (f1 * cosine_forcing + double * f2 * sine_forcing)  # F1
    twice = t * t * (f2 * cosine_forcing + double * f3 * sine_forcing)  # F2
    across_axis = jnp.cross(momentum, axis)
    response = once + gap * dot(axis, twice)[..., None] * across_axis  # x = F1 + A F2
    angular_momentum = turned(momentum + response)
    if not attitude:
        return angular_momentum, None

    size = jnp.sqrt(sum_last(momentum * momentum))[..., None]
    unit = momentum / size
    perpendicular = -jnp.cross(unit, response) / size
    parallel = (alpha[..., None] * dot(unit, twice)[..., None] + gap * dot(unit, axis)[..., None] * dot(axis, twice)[..., None]
                + unequal * t * (f1 * dot(unit, reflected)[..., None] + double * f2 * dot(unit, spun)[..., None]))
    turn = turned(perpendicular + parallel * unit)
    spin = quaternion.multiply(quaternion.exp_pure(t * alpha[..., None] * momentum), quaternion.exp_pure(angle * axis))
    half_turn = jnp.concatenate([jnp.zeros_like(turn[..., :1]), turn / 2], -1)
    return angular_momentum, spin + quaternion.multiply(spin, half_turn)
