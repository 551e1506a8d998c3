"""Batches of bodies split over several devices with jax.sharding.

Every array of a batched `frbjax.FreeRigidBody` (its inputs, and everything it precomputes per
body) has the batch as its leading axis, and every evaluation is elementwise over bodies.  Splitting
that axis over the devices therefore makes a jit-compiled evaluation run on all of them at once, with
no communication and the same numbers as on one device.

Recipe ($N$ bodies, any number of devices; on CPU, ``XLA_FLAGS=--xla_force_host_platform_device_count=4``
set before JAX starts gives 4 devices):

    import jax
    from frbjax import FreeRigidBody, shard_bodies

    body = FreeRigidBody(inertia, momentum, attitude)        # (N, 3), (N, 3), (N, 4)
    sharded = shard_bodies(body)                             # leading axis split over jax.devices()
    quaternion = jax.jit(lambda b, t: b.quaternion(t))
    q = quaternion(sharded, t)[:N]                           # t: a scalar, or per body (see below)

- ``shard_bodies`` pads the batch to a multiple of the number of devices by repeating the last body
  (a valid body, so the padding evaluates to finite numbers); slice the results back with ``[:N]``.
  ``pad=False`` raises instead when $N$ is not a multiple.
- Times per body: pass ``t`` of shape (N,) through ``shard_batch(t)`` (same padding, same sharding).
  $T$ common times for every body: build the body with batch shape (N, 1) and pass ``t`` of shape
  (T,); the results, (N, T, ...), are split along $N$.
- Building the bodies in parallel too: ``inertia, momentum, attitude = shard_batch((inertia, momentum,
  attitude))`` then ``body = jax.jit(FreeRigidBody)(inertia, momentum, attitude)``; the per-body
  constants are computed on every device and stay sharded.

Only the leading axis is split (the others stay whole on each device).  The mesh is a one-dimensional
``jax.sharding.Mesh`` (``batch_mesh``); pass your own to use a subset of the devices.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, TypeVar

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ._checks import integer


if TYPE_CHECKING:
    from ._body import FreeRigidBody

Tree = TypeVar("Tree")

__all__ = ["batch_mesh", "pad_batch", "shard_batch", "shard_bodies"]


def batch_mesh(devices: Sequence[jax.Device] | None = None, axis_name: str = "batch") -> Mesh:
    """A one-dimensional mesh over ``devices`` (default: all of ``jax.devices()``)."""
    devices = jax.devices() if devices is None else list(devices)
    if not devices:
        raise ValueError("devices: a mesh needs at least one device")
    return Mesh(np.array(devices), (axis_name,))


def _batch_size(tree) -> int:
    leaves = jax.tree_util.tree_leaves(tree)
    if not leaves:
        raise ValueError("tree: nothing to shard, the tree has no array leaves")
    sizes = {np.shape(leaf)[0] if np.ndim(leaf) > 0 else None for leaf in leaves}
    if None in sizes:
        raise ValueError("tree: every array must have a leading batch axis (a 0-d array has none)")
    if len(sizes) != 1:
        raise ValueError(f"tree: the arrays disagree on the leading batch size: {sorted(sizes)}")
    return sizes.pop()


def pad_batch(tree: Tree, multiple: int) -> Tree:
    """Pad every array of ``tree`` along its leading axis to a multiple of ``multiple``, repeating the
    last entry (for bodies: the last body, which evaluates like any other).  ``multiple``: an
    integer >= 1 (ValueError otherwise)."""
    multiple = integer("multiple", multiple, minimum=1)
    n = _batch_size(tree)
    if n == 0:
        raise ValueError("cannot pad an empty batch")
    extra = -n % multiple
    if extra == 0:
        return tree

    def pad(leaf):
        leaf = jnp.asarray(leaf)
        tail = jnp.broadcast_to(leaf[-1:], (extra,) + leaf.shape[1:])
        return jnp.concatenate([leaf, tail], axis=0)

    return jax.tree_util.tree_map(pad, tree)


def shard_batch(tree: Tree, mesh: Mesh | None = None, *, pad: bool = True) -> Tree:
    """Place every array of ``tree`` with its leading (batch) axis split over ``mesh``.

    ``tree`` is any pytree of arrays that share the leading batch size $N$ (a ``FreeRigidBody``, a
    tuple of its inputs, per-body times).  ``mesh`` is a one-dimensional mesh (default
    ``batch_mesh()``: all devices).  With ``pad`` (default) $N$ is padded to a multiple of the mesh
    size by repeating the last entry (``pad_batch``); otherwise an $N$ that is not a multiple raises
    ValueError.  Returns the tree with every leaf placed by ``NamedSharding(mesh, PartitionSpec(axis))``:
    device $k$ holds entries $kN'/D$ to $(k + 1)N'/D - 1$ ($N'$ the padded size, $D$ the number of
    devices).
    """
    mesh = batch_mesh() if mesh is None else mesh
    if len(mesh.axis_names) != 1:
        raise ValueError(f"expected a one-dimensional mesh, got axes {mesh.axis_names}")
    devices = mesh.devices.size
    n = _batch_size(tree)
    if n % devices:
        if not pad:
            raise ValueError(f"batch size {n} is not a multiple of the {devices} devices (pass pad=True)")
        tree = pad_batch(tree, devices)
    sharding = NamedSharding(mesh, PartitionSpec(mesh.axis_names[0]))
    return jax.device_put(tree, sharding)


def shard_bodies(body: FreeRigidBody, mesh: Mesh | None = None, *, pad: bool = True) -> FreeRigidBody:
    """A batched ``FreeRigidBody`` with its bodies (leading batch axis) split over the devices of ``mesh``.

    See the module docstring for the recipe: evaluate the result under ``jax.jit`` (the evaluation then
    runs on every device in parallel, each on its bodies) and slice the outputs back to the original
    batch size $N$ (``[:N]``) when $N$ was padded.  A single body (no batch axis) raises ValueError.
    """
    if jnp.ndim(body.momentum_norm) == 0:
        raise ValueError("body: shard_bodies needs a batch of bodies (inputs of shape (N, 3)), got a single body")
    return shard_batch(body, mesh, pad=pad)
