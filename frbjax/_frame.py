"""Vectors between a body's frames: matrix @ vector with a derivative written for reverse mode, the
change to and from principal axes given as columns in the body frame, and Omega = I^-1 L."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax.custom_derivatives import SymbolicZero

from ._fusion import sum_last


@jax.custom_jvp
def matrix_times(matrix, vector):
    """matrix @ vector over broadcast leading dimensions: (..., n, n) and (..., n) -> (..., n).

    The value is one fused product and sum over the last axis (the fastest form for a per-body matrix
    at many times).  Its derivative is written by ``_by_rows`` (see ``_matrix_times_jvp``).
    """
    matrix, rows = _equal_ranks(matrix, vector[..., None, :])
    return sum_last(matrix * rows)


def _equal_ranks(first, second):
    """``first`` and ``second`` with leading unit axes added to the one of lower rank: their leading
    dimensions then broadcast without numpy's rank promotion."""
    extra = second.ndim - first.ndim
    if extra > 0:
        first = first.reshape((1,) * extra + first.shape)
    elif extra < 0:
        second = second.reshape((1,) * -extra + second.shape)
    return first, second


def dot(first, second):
    """sum_j first[..., j] * second[..., j] as additions of (...)-shaped products, over j in order.

    Unlike a reduction over a trailing axis (or a product with a broadcast), its transpose in reverse
    mode is again products and additions of (...)-shaped arrays, never a reduction.
    """
    first, second = _equal_ranks(first, second)
    total = first[..., 0] * second[..., 0]
    for j in range(1, second.shape[-1]):
        total = total + first[..., j] * second[..., j]
    return total


def _by_rows(matrix, vector):
    """matrix @ vector as n ``_dot`` of (...)-shaped arrays."""
    return jnp.stack([dot(matrix[..., i, :], vector) for i in range(vector.shape[-1])], -1)


@functools.partial(matrix_times.defjvp, symbolic_zeros=True)
def _matrix_times_jvp(primals, tangents):
    """d(M v) = dM v + M dv, both by rows.

    For a per-body matrix and many times, reverse mode then gives the matrix's cotangent as n * n sums
    over the times of products of (...)-shaped arrays.  Through the (..., n, n) product of the value,
    XLA materialised the broadcast matrix and the product at every time and reduced them: a third of
    a quaternion gradient's run time.  (Writing the value by rows instead cost 5% of an evaluation.)
    """
    matrix, vector = primals
    matrix_tangent, vector_tangent = tangents
    terms = []
    if not isinstance(matrix_tangent, SymbolicZero):
        terms.append(_by_rows(matrix_tangent, vector))
    if not isinstance(vector_tangent, SymbolicZero):
        terms.append(_by_rows(matrix, vector_tangent))
    value = matrix_times(matrix, vector)
    if not terms:
        return value, jnp.zeros_like(value)
    return value, sum(terms[1:], terms[0])


def matrix_product(first, second):
    """first @ second for (..., 3, 3) arrays, as elementwise products and additions (no dot)."""
    return sum_last(first[..., :, None, :] * jnp.swapaxes(second, -1, -2)[..., None, :, :])


def to_principal(axes, vector):
    """R^T v: body-frame vectors in the principal frame (v itself where ``axes`` is None: the body
    axes are principal)."""
    return vector if axes is None else matrix_times(jnp.swapaxes(axes, -1, -2), vector)


def to_body(axes, vector):
    """R v: principal-frame vectors in the body frame."""
    return vector if axes is None else matrix_times(axes, vector)


def angular_velocity(inertia, axes, momentum):
    """Omega = L / I for principal body axes, R (R^T L / I) for principal axes R in the body frame."""
    return to_body(axes, to_principal(axes, momentum) / inertia)
