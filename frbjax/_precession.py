r"""Regular precession of a symmetric body and its first-order neighbours (docs/theory.md §6,
"Symmetric bodies next to the plane of their equal moments").

A body with two equal moments $a$ (axes $u$, $v$) and a third $c$ (the symmetry axis $e$) precesses
regularly: with $\alpha = 1/a$, $\gamma = 1/c$ and $\nu = (\gamma - \alpha)\, e \cdot L_0$,

$$L(t) = Q(t)\, L_0, \qquad q(t) = q_0 \otimes \exp(t \alpha L_0 / 2) \otimes \exp(t \nu e / 2),$$

$Q(t)$ the rotation by $-\nu t$ about $e$ ($\Omega = \alpha L + \nu e$).  The elliptic formulas give the
same motion ($m = 0$), but where $L_0$ is close to the plane of the equal moments their derivative in
an unequal change of those moments, $\delta I_u = -\delta I_v$, is the difference of terms
$1/(e \cdot n)^2$ larger than itself (and the one in a change of $e \cdot n$ loses about
$10^{-16} / (e \cdot n)$).  Here that derivative is the solution of the variational
equations of the precession, linear with coefficients that are constant in the frame that turns with
$Q$: with $x = Q^{\mathsf T} \delta L$ and $\Delta = (1/I_u - 1/I_v)/2$ (zero in value, its tangent the
change),

$$\dot x = A x + f(s),\quad A w = (\gamma - \alpha)(e \cdot w)\, L_0 \times e\ (A^2 = 0),\quad
f(s) = \Delta\, L_0 \times \big(\cos(2\nu s)\, J L_0 + \sin(2\nu s)\, e \times J L_0\big),$$

$J w = (u \cdot w) u - (v \cdot w) v$, so $x(t) = F_1 + A F_2$ with the repeated integrals
$F_k = \int_0^t (t - s)^{k-1}/(k-1)!\, f(s)\, ds$ (``response_functions`` of $(2\nu t)^2$).  The
attitude is $q(t) \otimes \exp(\varphi/2)$, $\varphi = Q \psi$: across $n = L_0/|L_0|$ the
conservation of the angular momentum in space gives $\psi \times L_0 = -x$; along it
$n \cdot \psi = (\gamma - \alpha)(n \cdot e)(e \cdot F_2) + \Delta \int_0^t
n \cdot (\cos(2\nu s) J L_0 + \sin(2\nu s) e \times J L_0)\, ds$ ($f$ and $A$ map across $L_0$).

``precession`` is that first-order expansion off the symmetric bodies, written as ordinary
differentiable functions of the moments (their equal pair through its mean and $\Delta$), $L_0$, $t$
and the axes: every derivative of first order is that of the motion, and so are those of second
order except the one twice in the unequal direction (the expansion is linear in $\Delta$).  Its
values are those of the elliptic formulas (to rounding), so the bodies keep those values and take
the expansion's derivatives only (``with_precession_derivatives``): evaluating costs nothing more.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax.custom_derivatives import SymbolicZero

from . import _quaternion as quaternion
from ._frame import dot, to_body
from ._fusion import sum_last, when_any
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
    not to be used).  ``t`` broadcasts against the bodies' batch shape.

    Written in components along (u, v, e) (a right-handed frame per body), where J L0 = (l_u, -l_v, 0),
    L0 x J L0 = (l_e l_v, l_e l_u, -2 l_u l_v), L0 x (e x J L0) = (-l_e l_u, l_e l_v, l_u^2 - l_v^2) and
    L0 x e = (l_v, -l_u, 0): scalars over bodies and times, a few fused loops with their derivatives."""
    dtype = inertia.dtype
    inertia = jnp.where(band[..., None], inertia, jnp.asarray(_SAFE_INERTIA, dtype))
    momentum = jnp.where(band[..., None], momentum, jnp.asarray(_SAFE_MOMENTUM, dtype))
    odd = _odd_axis(inertia).astype(dtype)
    first, second = jnp.roll(odd, 1, -1), jnp.roll(odd, 2, -1)  # (u, v, e) cyclic: right-handed
    axis, u, v = (to_body(axes, w) for w in (odd, first, second))
    alpha = 2 / sum_last((1 - odd) * inertia)  # 1 / the equal pair's mean (exact in value)
    gap = 1 / sum_last(odd * inertia) - alpha
    # (1/I_u - 1/I_v)/2: zero in value, the unequal change of the pair in its tangent.
    unequal = (sum_last(first / inertia) - sum_last(second / inertia)) / 2
    l_u, l_v, l_e = dot(u, momentum), dot(v, momentum), dot(axis, momentum)
    size = jnp.sqrt(l_u * l_u + l_v * l_v + l_e * l_e)

    # Functions of time: Q(t) turns by -nu t about e; the repeated integrals of cos and sin(2 nu s).
    t = jnp.asarray(t, dtype)
    half = gap * l_e * t / 2
    half_cosine, half_sine = jnp.cos(half), jnp.sin(half)
    cosine, sine = 1 - 2 * half_sine * half_sine, 2 * half_sine * half_cosine  # of nu t
    double = 4 * half  # 2 nu t
    f1, f2, f3 = response_functions(double * double)
    once_cosine, once_sine = t * f1, t * double * f2  # F1 = once_cosine f_c + once_sine f_s
    twice_cosine, twice_sine = t * t * f2, t * t * double * f3  # F2 likewise
    # x = F1 + A F2 = F1 + (e . F2) gap L0 x e, f_c = unequal L0 x J L0, f_s = unequal L0 x (e x J L0).
    along_twice = unequal * (twice_sine * (l_u * l_u - l_v * l_v) - 2 * twice_cosine * l_u * l_v)  # e . F2
    drift = gap * along_twice
    x_u = unequal * l_e * (once_cosine * l_v - once_sine * l_u) + drift * l_v
    x_v = unequal * l_e * (once_cosine * l_u + once_sine * l_v) - drift * l_u
    x_e = unequal * (once_sine * (l_u * l_u - l_v * l_v) - 2 * once_cosine * l_u * l_v)

    def turned(w_u, w_v, w_e):
        """Q(t) w in the body frame from w's components along (u, v, e)."""
        return (
            (cosine * w_u + sine * w_v)[..., None] * u
            + (cosine * w_v - sine * w_u)[..., None] * v
            + w_e[..., None] * axis
        )

    angular_momentum = turned(l_u + x_u, l_v + x_v, l_e + x_e)
    if not attitude:
        return angular_momentum, None

    # psi = -n x x / |L0| + (n . psi) n (n . F2 = n . x = 0: f_c, f_s and L0 x e are across L0).
    n_u, n_v, n_e = l_u / size, l_v / size, l_e / size
    parallel = (
        gap * n_e * along_twice + unequal * (once_cosine * (l_u * l_u - l_v * l_v) + 2 * once_sine * l_u * l_v) / size
    )
    psi_u = -(n_v * x_e - n_e * x_v) / size + parallel * n_u
    psi_v = -(n_e * x_u - n_u * x_e) / size + parallel * n_v
    psi_e = -(n_u * x_v - n_v * x_u) / size + parallel * n_e
    # s(t) = exp(t alpha L0 / 2) ⊗ exp(nu t e / 2) in (u, v, e) components, then s ⊗ (1, phi / 2).
    spin_angle = alpha * size * t / 2
    spin_cosine, spin_sine = jnp.cos(spin_angle), jnp.sin(spin_angle)
    crossed = spin_sine * half_sine  # coefficient of n x e = (n_v, -n_u, 0)
    s_w = spin_cosine * half_cosine - crossed * n_e
    s_u = spin_sine * half_cosine * n_u + crossed * n_v
    s_v = spin_sine * half_cosine * n_v - crossed * n_u
    s_e = spin_cosine * half_sine + spin_sine * half_cosine * n_e
    # phi = Q psi, taken along (u, v, e) (the frame of s's components) and halved.
    p_u, p_v, p_e = (cosine * psi_u + sine * psi_v) / 2, (cosine * psi_v - sine * psi_u) / 2, psi_e / 2
    w = s_w - (s_u * p_u + s_v * p_v + s_e * p_e)
    c_u = s_u + s_w * p_u + (s_v * p_e - s_e * p_v)
    c_v = s_v + s_w * p_v + (s_e * p_u - s_u * p_e)
    c_e = s_e + s_w * p_e + (s_u * p_v - s_v * p_u)
    vector = c_u[..., None] * u + c_v[..., None] * v + c_e[..., None] * axis
    return angular_momentum, jnp.concatenate([w[..., None], vector], -1)


def jvp_of_moved(function, primals, tangents):
    """jax.jvp over the arguments whose tangents are not symbolic zeros (the others held fixed), so that
    a derivative in t alone does not differentiate a prebuilt body's per-body data."""
    leaves, tree = jax.tree.flatten(primals)
    tangent_leaves = jax.tree.leaves(tangents, is_leaf=lambda leaf: isinstance(leaf, SymbolicZero))
    moved = [k for k, tangent in enumerate(tangent_leaves) if not isinstance(tangent, SymbolicZero)]

    def of_moved(*values):
        arguments = list(leaves)
        for k, value in zip(moved, values):
            arguments[k] = value
        return function(*jax.tree.unflatten(tree, arguments))

    if not moved:
        value = function(*primals)
        return value, jax.tree.map(jnp.zeros_like, value)
    return jax.jvp(of_moved, [leaves[k] for k in moved], [tangent_leaves[k] for k in moved])


def _expansion(band, outputs):
    """(inertia, axes, momentum, attitude, t) -> ``outputs`` of the expansion: "momentum" L(t),
    "attitude" q0 ⊗ s(t), "state" both, "momentum alone" (L(t), None)."""

    def evaluate(inertia, axes, momentum, attitude, t):
        with_attitude = outputs in ("attitude", "state")
        angular_momentum, spin = precession(band, inertia, momentum, t, axes, attitude=with_attitude)
        if outputs == "momentum":
            return angular_momentum
        if outputs == "momentum alone":
            return angular_momentum, None
        attitude = quaternion.multiply(attitude, spin)
        return attitude if outputs == "attitude" else (angular_momentum, attitude)

    return evaluate


def with_precession_derivatives(function, outputs, band_of, inputs_of):
    """``function`` with its own values and, for the bodies in ``band_of(*args)`` (a per-body mask), the
    derivatives of the expansion at ``inputs_of(*args)`` = (inertia, axes, momentum, attitude, t)
    instead of its own: a custom JVP, so that evaluating costs nothing more.  ``outputs`` says what
    ``function`` returns (see ``_expansion``)."""
    wrapped = jax.custom_jvp(function)

    def rule(primals, tangents):
        value, tangent = jvp_of_moved(function, primals, tangents)
        band = band_of(*primals)

        def along_precession(tangent):
            inputs, d_inputs = jvp_of_moved(inputs_of, primals, tangents)
            _, precessing = jax.jvp(_expansion(band, outputs), inputs, d_inputs)
            return jax.tree.map(lambda new, old: jnp.where(band[..., None], new, old), precessing, tangent)

        # Most batches have no such body: then the expansion is not evaluated at all.
        return value, when_any(band, along_precession, lambda tangent: tangent, tangent)

    wrapped.defjvp(rule, symbolic_zeros=True)
    # A plain function, not the custom_jvp object: as a class attribute it must bind as a method.
    return functools.wraps(function)(lambda *arguments: wrapped(*arguments))
