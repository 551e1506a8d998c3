"""Small quaternion helpers: $(w, x, y, z)$ order, Hamilton product, unit quaternions map body to space."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from ._checks import check_finite, check_rotation_matrices, check_trailing_shape, check_unit_rows, on_host, real_array
from ._fusion import sum_last


def multiply(p: Array, q: Array) -> Array:
    r"""Hamilton product $p \otimes q$ of (..., 4) arrays."""
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return jnp.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def conjugate(q: Array) -> Array:
    r"""$\bar q = (w, -x, -y, -z)$, the inverse of a unit quaternion."""
    return q * jnp.broadcast_to(jnp.array([1, -1, -1, -1], dtype=q.dtype), q.shape)


def as_matrix(q: ArrayLike) -> Array:
    r"""Rotation matrix $R(q)$ of a unit quaternion $q = (w, x, y, z)$, shape (..., 3, 3).

    $R(q)\, v = q \otimes (0, v) \otimes \bar q$: the columns of $R$ are the body axes in space
    ($x_\text{space} = R\, x_\text{body}$), and

    $$R = \begin{pmatrix}
      1 - 2(y^2 + z^2) & 2(xy - wz) & 2(xz + wy) \\
      2(xy + wz) & 1 - 2(x^2 + z^2) & 2(yz - wx) \\
      2(xz - wy) & 2(yz + wx) & 1 - 2(x^2 + y^2)
    \end{pmatrix}.$$
    """
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return jnp.stack(
        [
            jnp.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            jnp.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            jnp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def from_matrix(matrix: ArrayLike) -> Array:
    r"""Unit quaternion ($w \ge 0$ where possible) of a rotation matrix $R$ (..., 3, 3), by Shepperd's method.

    Picks the largest of $1 + \mathrm{tr}\,R$ and $1 + 2R_{ii} - \mathrm{tr}\,R$ so that the square
    root is of a number $\ge 1$, then divides the off-diagonal sums by it.
    """
    r = matrix
    trace = r[..., 0, 0] + r[..., 1, 1] + r[..., 2, 2]
    candidates = jnp.stack(
        [1 + trace, 1 + 2 * r[..., 0, 0] - trace, 1 + 2 * r[..., 1, 1] - trace, 1 + 2 * r[..., 2, 2] - trace],
        axis=-1,
    )
    choice = jnp.argmax(candidates, axis=-1)
    largest = jnp.sqrt(jnp.max(candidates, axis=-1)) / 2
    quarter = 1 / (4 * largest)
    from_w = jnp.stack(
        [
            largest,
            (r[..., 2, 1] - r[..., 1, 2]) * quarter,
            (r[..., 0, 2] - r[..., 2, 0]) * quarter,
            (r[..., 1, 0] - r[..., 0, 1]) * quarter,
        ],
        -1,
    )
    from_x = jnp.stack(
        [
            (r[..., 2, 1] - r[..., 1, 2]) * quarter,
            largest,
            (r[..., 0, 1] + r[..., 1, 0]) * quarter,
            (r[..., 0, 2] + r[..., 2, 0]) * quarter,
        ],
        -1,
    )
    from_y = jnp.stack(
        [
            (r[..., 0, 2] - r[..., 2, 0]) * quarter,
            (r[..., 0, 1] + r[..., 1, 0]) * quarter,
            largest,
            (r[..., 1, 2] + r[..., 2, 1]) * quarter,
        ],
        -1,
    )
    from_z = jnp.stack(
        [
            (r[..., 1, 0] - r[..., 0, 1]) * quarter,
            (r[..., 0, 2] + r[..., 2, 0]) * quarter,
            (r[..., 1, 2] + r[..., 2, 1]) * quarter,
            largest,
        ],
        -1,
    )
    options = jnp.stack([from_w, from_x, from_y, from_z], axis=-2)
    return jnp.take_along_axis(options, choice[..., None, None], axis=-2)[..., 0, :]


def exp_pure(rotation_vector: Array) -> Array:
    r"""$\exp(v/2)$ as a unit quaternion for a rotation vector $v$ (..., 3): rotation by $|v|$ about $v/|v|$.

    Uses the safe-where pattern: the series $1 - \theta^2/8$ and $1/2 - \theta^2/48$ below
    $\theta^2 = 10^{-8}$ keep the value and its gradient finite at $v = 0$.
    """
    theta2 = sum_last(rotation_vector * rotation_vector)
    small = theta2 < 1e-8
    theta = jnp.sqrt(jnp.where(small, 1, theta2))
    scalar = jnp.where(small, 1 - theta2 / 8, jnp.cos(theta / 2))
    vector_scale = jnp.where(small, 0.5 - theta2 / 48, jnp.sin(theta / 2) / theta)
    return jnp.concatenate([scalar[..., None], vector_scale[..., None] * rotation_vector], axis=-1)


# The public conversions' arithmetic as one program each: called eagerly, their few dozen operations
# were dispatched one by one (quaternion_from_matrix: 2.4 ms a call against 0.05 ms compiled).
_as_matrix_program = jax.jit(as_matrix)
_from_matrix_program = jax.jit(from_matrix)


def quaternion_to_matrix(q: ArrayLike) -> Array:
    r"""Rotation matrix $R(q)$ (..., 3, 3) of unit quaternions $q = (w, x, y, z)$ (..., 4), body to space.

    $R(q)\, v = q \otimes (0, v) \otimes \bar q$: the columns of $R$ are the body axes in space
    ($x_\text{space} = R\, x_\text{body}$).  Refused (ValueError, for values on the host): trailing
    axis other than 4, non-finite entries, quaternions whose norm is not 1 (to 1e-6; 1e-3 in float32).
    """
    check_trailing_shape("q", q, (4,))
    if on_host(q):
        values = real_array("q", q)
        check_finite("q", values)
        check_unit_rows("q", values)
    return _as_matrix_program(jnp.asarray(q))


def quaternion_from_matrix(matrix: ArrayLike) -> Array:
    r"""Unit quaternions (..., 4), $w \ge 0$ where possible, of rotation matrices $R$ (..., 3, 3)
    (Shepperd's method: the largest of $1 + \mathrm{tr}\,R$ and $1 + 2R_{ii} - \mathrm{tr}\,R$ under the
    square root).  Refused (ValueError, for values on the host): trailing axes other than (3, 3),
    non-finite entries, matrices that are not rotations ($|R^T R - 1|$ above 1e-6, 1e-3 in float32,
    or a negative determinant).
    """
    check_trailing_shape("matrix", matrix, (3, 3))
    if on_host(matrix):
        values = real_array("matrix", matrix)
        check_finite("matrix", values)
        check_rotation_matrices("matrix", values)
    return _from_matrix_program(jnp.asarray(matrix))
