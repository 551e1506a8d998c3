"""frbjax: the exact motion of the torque-free rigid body in JAX.

- :class:`FreeRigidBody`: angular momentum, angular velocity, quaternion and rotation matrix at any
  times, for batches of bodies, under jit/vmap/grad.
- :mod:`frbjax.special`: Jacobi elliptic functions and Legendre/Carlson elliptic integrals.
- :func:`fit_attitude` (:mod:`frbjax.fit`): the torque-free motion (moments of inertia, angular
  velocity, attitude) that best explains observed attitudes; imported on first use (it needs
  optimistix).

The library never changes JAX's global configuration: enable float64 yourself
(``jax.config.update("jax_enable_x64", True)``) for double precision.
"""

from . import special
from ._body import FreeRigidBody
from ._sharding import batch_mesh, pad_batch, shard_batch, shard_bodies

__all__ = ["AttitudeFit", "FreeRigidBody", "fit_attitude", "special"]


def __getattr__(name):
    # frbjax.fit imports optimistix (and lineax); only users who fit pay for that import.
    if name in ("AttitudeFit", "fit_attitude"):
        from . import fit

        return getattr(fit, name)
    raise AttributeError(f"module 'frbjax' has no attribute {name!r}")
__version__ = "0.1.0"
