"""Inertia tensors in the body frame: the principal decomposition, and derivatives through it.

A body whose inertia is given as a symmetric positive definite tensor T in its own body frame moves
as the body with principal moments lambda and principal axes R (columns, a rotation) with
T = R diag(lambda) R^T: its angular momentum in the principal frame is R^T L, its principal frame's
attitude q ⊗ q(R) (docs/theory.md §12, "Inertia tensors").  The motion is smooth (analytic) in T,
but the decomposition is not where two moments meet: there the axes in their plane are arbitrary and
their derivatives infinite.  :func:`through_principal_frame` therefore differentiates the motion
with respect to T directly, by first-order perturbation theory in the principal frame:

- a diagonal change of T (in principal coordinates) changes the moments;
- an off-diagonal change dT_ij between distinct moments turns the axes, dR = R W with
  W_ij = dT_ij / (lambda_j - lambda_i) (the eigenvector derivative);
- an off-diagonal change between equal moments, b (e_i e_j^T + e_j e_i^T), is the change of moments
  b (e_i' e_i'^T - e_j' e_j'^T) along the axes e_i' = (e_i + e_j)/sqrt(2), e_j' = (e_j - e_i)/sqrt(2)
  turned by 45 degrees in their plane: the derivative of the motion of the same body described in
  those axes (any axes of that plane are principal), with respect to lambda_i - lambda_j.

Moments closer than sqrt(eps) (relative) count as equal: the first form then loses digits as
eps / gap and the last is off by the gap, so that either is accurate to about sqrt(eps) relative
there and to rounding elsewhere.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._checks import check_finite, is_concrete, real_array
from ._fusion import when_any


# Pairs of principal axes (ascending moments) whose moments may meet.
_PAIRS = ((0, 1), (1, 2), (0, 2))


def _symmetric_part(matrix):
    return 0.5 * (matrix + jnp.swapaxes(matrix, -1, -2))


def _eigen(matrix):
    """Ascending eigenvalues and a rotation (det +1) of eigenvectors of symmetric 3 x 3 matrices.

    Eigenvalues within a few ulp of each other (a tensor that is symmetric or spherical to its own
    rounding) are made equal, their mean: the body is then exactly axisymmetric or a sphere, whose
    motion frbjax computes by the formulas of that case.
    """
    moments, axes = jnp.linalg.eigh(matrix)
    # Eigenvectors are defined up to sign: flip the last one where they form a reflection.
    determinant = jnp.linalg.det(axes)
    flip = jnp.where(determinant < 0, -1.0, 1.0).astype(axes.dtype)
    axes = axes.at[..., :, 2].multiply(flip[..., None])
    first, second, third = moments[..., 0], moments[..., 1], moments[..., 2]
    rounding = _EQUAL_TO_ROUNDING * jnp.finfo(moments.dtype).eps * jnp.abs(third)
    low, high = second - first <= rounding, third - second <= rounding
    mean_all = (first + second + third) / 3
    mean_low, mean_high = (first + second) / 2, (second + third) / 2
    first = jnp.where(low & high, mean_all, jnp.where(low, mean_low, first))
    second = jnp.where(low & high, mean_all, jnp.where(low, mean_low, jnp.where(high, mean_high, second)))
    third = jnp.where(low & high, mean_all, jnp.where(high, mean_high, third))
    return jnp.stack([first, second, third], -1), axes


# Eigenvalues this close (in ulp of the largest) are taken as equal (_eigen).
_EQUAL_TO_ROUNDING = 8


def _rotation_generator(principal_change, moments, equal):
    """W (antisymmetric, ... 3 x 3) with W_ij = dT_ij / (lambda_j - lambda_i), 0 for equal moments.

    Safe where: the division never sees a zero gap, so no NaN reaches any derivative.
    """
    generator = jnp.zeros_like(principal_change)
    for (i, j), same in zip(_PAIRS, equal):
        gap = moments[..., j] - moments[..., i]
        rate = jnp.where(same, 0, principal_change[..., i, j] / jnp.where(same, 1, gap))
        generator = generator.at[..., i, j].set(rate).at[..., j, i].set(-rate)
    return generator


def _equal_pairs(moments, tolerance):
    largest = moments[..., 2]
    return tuple(moments[..., j] - moments[..., i] <= tolerance * largest for i, j in _PAIRS)


@jax.custom_jvp
def principal_decomposition(matrix):
    """(lambda ascending (..., 3), R (..., 3, 3) with T = R diag(lambda) R^T, det R = +1).

    Derivatives: d lambda_i = (R^T dT R)_ii (exact, also at repeated moments); dR = R W with the
    eigenvector rates W_ij = (R^T dT R)_ij / (lambda_j - lambda_i) between distinct moments and 0
    between equal ones (where the axes have no derivative: any choice in their plane is principal).
    """
    return _eigen(matrix)


@principal_decomposition.defjvp
def _principal_decomposition_jvp(primals, tangents):
    (matrix,), (matrix_dot,) = primals, tangents
    moments, axes = _eigen(matrix)
    principal_change = jnp.swapaxes(axes, -1, -2) @ matrix_dot @ axes
    equal = tuple(jnp.asarray(gap_is_zero) for gap_is_zero in _equal_pairs(moments, 0.0))
    generator = _rotation_generator(principal_change, moments, equal)
    return (moments, axes), (jnp.diagonal(principal_change, axis1=-2, axis2=-1), axes @ generator)


def _turned_in_plane(axes, i, j):
    """The axes with e_i, e_j replaced by (e_i + e_j)/sqrt(2), (e_j - e_i)/sqrt(2) (a rotation)."""
    half = np.sqrt(0.5)
    first, second = axes[..., :, i], axes[..., :, j]
    return axes.at[..., :, i].set(half * (first + second)).at[..., :, j].set(half * (second - first))


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1))
def through_principal_frame(motion, evaluate, matrix, prepared, arguments):
    """``evaluate(prepared, arguments)``, the motion of a body with inertia tensor ``matrix``, with
    derivatives with respect to ``matrix`` and ``arguments`` taken through ``motion``.

    ``motion(moments, axes, arguments)`` is the same motion from a principal decomposition (smooth in
    both); ``evaluate`` may use data ``prepared`` from that decomposition (a body's series), whose own
    derivatives are ignored.  See the module docstring for the derivative with respect to the tensor.
    """
    del motion, matrix
    return evaluate(prepared, arguments)


@through_principal_frame.defjvp
def _through_principal_frame_jvp(motion, evaluate, primals, tangents):
    matrix, prepared, arguments = primals
    matrix_dot, _, arguments_dot = tangents
    value = evaluate(prepared, arguments)
    # Differentiable itself (principal_decomposition), so that derivatives of this rule (second
    # derivatives) follow the decomposition too.
    moments, axes = principal_decomposition(matrix)
    principal_change = jnp.swapaxes(axes, -1, -2) @ matrix_dot @ axes
    tolerance = jnp.sqrt(jnp.finfo(moments.dtype).eps)
    equal = _equal_pairs(jax.lax.stop_gradient(moments), tolerance)
    generator = _rotation_generator(principal_change, moments, equal)
    moment_change = jnp.diagonal(principal_change, axis1=-2, axis2=-1)
    _, tangent = jax.jvp(motion, (moments, axes, arguments), (moment_change, axes @ generator, arguments_dot))

    no_arguments_change = jax.tree.map(jnp.zeros_like, arguments)
    for (i, j), same in zip(_PAIRS, equal):
        split = jnp.where(same, principal_change[..., i, j], 0)
        direction = jnp.zeros_like(moments).at[..., i].set(split).at[..., j].set(-split)

        def between_equal_moments(direction, i=i, j=j):
            turned = _turned_in_plane(axes, i, j)
            return jax.jvp(
                motion, (moments, turned, arguments), (direction, jnp.zeros_like(turned), no_arguments_change)
            )[1]

        extra = when_any(same, between_equal_moments, lambda _: jax.tree.map(jnp.zeros_like, tangent), direction)
        tangent = jax.tree.map(jnp.add, tangent, extra)
    return value, tangent


def validate_tensor(matrix, name):
    """Shape always; symmetry (beyond rounding), finiteness and positive definiteness when concrete."""
    shape = tuple(matrix.shape)
    if len(shape) < 2 or shape[-2:] != (3, 3):
        raise ValueError(f"{name} must have shape (..., 3, 3), got shape {shape}")
    if isinstance(matrix, jax.core.Tracer):
        return
    value = np.asarray(matrix, dtype=np.float64 if matrix.dtype == np.float64 else np.float32)
    check_finite(name, value)
    asymmetry = np.max(np.abs(value - np.swapaxes(value, -1, -2)), axis=(-2, -1))
    scale = np.max(np.abs(value), axis=(-2, -1))
    if np.any(asymmetry > _SYMMETRY_TOLERANCE * np.finfo(value.dtype).eps * scale):
        raise ValueError(
            f"{name} must be symmetric (T[i, j] == T[j, i] to rounding); the largest "
            f"difference is {np.max(asymmetry):.3g}"
        )
    if not np.all(np.linalg.eigvalsh(0.5 * (value + np.swapaxes(value, -1, -2)))[..., 0] > 0):
        raise ValueError(f"{name} must be positive definite (all principal moments > 0)")


# Asymmetry accepted as rounding, in ulps of the largest entry (a tensor computed as a sum of
# rotated parts is symmetric to a few ulps).
_SYMMETRY_TOLERANCE = 64


@jax.jit
def _decomposed(matrix):
    """(T symmetrised, its principal moments, its principal axes), NaN for an invalid tensor: under
    tracing, invalid tensors cannot raise (InertiaTensor's docstring).  One program: called eagerly,
    the decomposition's operations were dispatched one by one (3.9 ms a call, 1.2 s the first)."""
    symmetric = _symmetric_part(matrix)
    moments, axes = principal_decomposition(symmetric)
    valid = (
        jnp.all(jnp.isfinite(matrix), axis=(-2, -1))
        & (moments[..., 0] > 0)
        & (
            jnp.max(jnp.abs(matrix - jnp.swapaxes(matrix, -1, -2)), axis=(-2, -1))
            <= _SYMMETRY_TOLERANCE * jnp.finfo(matrix.dtype).eps * jnp.max(jnp.abs(matrix), axis=(-2, -1))
        )
    )
    return (
        jnp.where(valid[..., None, None], symmetric, jnp.nan),
        jnp.where(valid[..., None], moments, jnp.nan),
        jnp.where(valid[..., None, None], axes, jnp.nan),
    )


class InertiaTensor(eqx.Module):
    r"""A body's inertia tensor in its own body frame, with its principal moments and axes.

    ``InertiaTensor(matrix)``: ``matrix`` (..., 3, 3) symmetric positive definite, in any consistent
    units (the motion depends only on the ratios of the moments to $|L|$).  Its principal decomposition
    $T = R \operatorname{diag}(\lambda) R^T$ is computed once: ``principal_moments`` $\lambda$ (..., 3)
    ascending and ``principal_axes`` $R$ (..., 3, 3), the unit principal axes as columns in body
    coordinates, a rotation ($\det R = +1$): $x_\text{body} = R\, x_\text{principal}$.  Moments within
    8 ulp of each other are made equal (an axisymmetric or spherical tensor to its own rounding).

    Wherever frbjax takes principal moments it takes an ``InertiaTensor`` too (an explicit type, never
    a guess from shapes: a (3, 3) array of moments stays a batch of three bodies):
    ``FreeRigidBody.from_inertia_tensor``, `free_flow`, `RigidBodyTerm`.  Angular momentum, angular
    velocity ($\Omega = T^{-1} L$) and attitude are then those of the body frame of the tensor.

    Bad input: a matrix that is not (..., 3, 3), not symmetric beyond rounding (64 ulp of its largest
    entry), not finite or not positive definite raises ValueError naming ``inertia_tensor`` when it is
    concrete; under ``jax.jit`` such a tensor has NaN moments and axes, and every output of a body
    built from it is NaN.  The triangle inequality of physical bodies ($\lambda_1 + \lambda_2 \ge
    \lambda_3$) is not required: the motion is that of Euler's equations for any positive moments.

    Derivatives of the motion with respect to every entry of the matrix are finite and correct also
    at repeated moments (axisymmetric bodies, a sphere), where ``principal_axes`` itself has no
    derivative: they are taken by first-order perturbation theory in the principal frame
    (docs/theory.md §12), exact to rounding except where two moments agree to about $10^{-8}$
    (relative), where they are good to about $10^{-8}$.  The derivatives of ``principal_axes`` are
    those of the eigenvectors between distinct moments and 0 in the plane of equal ones.
    """

    matrix: Float[Array, "... 3 3"]
    principal_moments: Float[Array, "... 3"]
    principal_axes: Float[Array, "... 3 3"]

    def __init__(self, matrix):
        if is_concrete(matrix):
            real_array("matrix", matrix)
        matrix = jnp.asarray(matrix)
        if not jnp.issubdtype(matrix.dtype, jnp.floating):
            matrix = matrix.astype(float)
        validate_tensor(matrix, "matrix")
        self.matrix, self.principal_moments, self.principal_axes = _decomposed(matrix)

    @property
    def shape(self) -> tuple[int, ...]:
        """The batch shape (the leading dimensions of ``matrix``)."""
        return self.matrix.shape[:-2]

    def as_matrix(self) -> Float[Array, "... 3 3"]:
        """The tensor $T$ (..., 3, 3), symmetrised."""
        return self.matrix

    def angular_velocity(self, angular_momentum) -> Float[Array, "... 3"]:
        r"""$\Omega = T^{-1} L = R (R^T L / \lambda)$ for body-frame angular momenta $L$ (..., 3)."""
        axes = self.principal_axes
        principal = jnp.einsum("...ji,...j->...i", axes, angular_momentum)
        return jnp.einsum("...ij,...j->...i", axes, principal / self.principal_moments)
