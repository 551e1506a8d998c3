"""frbjax: the exact motion of the torque-free rigid body in JAX.

- :class:`FreeRigidBody`: angular momentum, angular velocity, quaternion and rotation matrix at any
  times, for batches of bodies, under jit/vmap/grad.
- :mod:`frbjax.special`: Jacobi elliptic functions and Legendre/Carlson elliptic integrals.

The library never changes JAX's global configuration: enable float64 yourself
(``jax.config.update("jax_enable_x64", True)``) for double precision.
"""

from . import special
from ._body import FreeRigidBody

__all__ = ["FreeRigidBody", "special"]
__version__ = "0.1.0"
