"""frbjax: the exact motion of the torque-free rigid body in JAX.

- :class:`FreeRigidBody`: angular momentum, angular velocity, quaternion and rotation matrix at any
  times, for batches of bodies, under jit/vmap/grad.
- :func:`free_flow`: the state (L(t), q(t)) of bodies each at one time, without per-body setup.
- :class:`InertiaTensor`: a body's inertia as a (..., 3, 3) tensor in its own body frame, accepted
  wherever principal moments are (``FreeRigidBody.from_inertia_tensor``, ``free_flow``,
  ``RigidBodyTerm``).
- :mod:`frbjax.special`: Jacobi elliptic functions and Legendre/Carlson elliptic integrals.
- :class:`RigidBodyTerm`, :class:`RigidBodySplitting`, :func:`splitting_trajectory`: torqued bodies
  (a potential or a body-frame torque) integrated by splitting methods built on the exact free flow,
  inside ``diffrax.diffeqsolve`` or as a lean ``lax.scan``; :func:`quaternion_from_matrix` and
  :func:`quaternion_to_matrix` for attitudes given as rotation matrices.  Imported on first use
  (they need diffrax).
- :func:`fit_attitude` (:mod:`frbjax.fit`): the torque-free motion (moments of inertia, angular
  velocity, attitude) that best explains observed attitudes; imported on first use (it needs
  optimistix).  A fit that does not converge raises :class:`FitError` (``throw=False`` returns it).

The library never changes JAX's global configuration: enable float64 yourself
(``jax.config.update("jax_enable_x64", True)``) for double precision.
"""

from typing import TYPE_CHECKING

from . import special
from ._body import FreeRigidBody
from ._errors import FitError
from ._free_flow import free_flow
from ._inertia import InertiaTensor
from ._quaternion import quaternion_from_matrix, quaternion_to_matrix
from ._sharding import batch_mesh, pad_batch, shard_batch, shard_bodies


if TYPE_CHECKING:
    # The names imported on first use (``__getattr__`` below), as type checkers should see them.
    from . import lightcurve as lightcurve, posterior as posterior, torques as torques
    from ._splitting import METHODS as SPLITTING_METHODS, RigidBodySplitting, RigidBodyTerm, splitting_trajectory
    from .fit import AttitudeFit, fit_attitude


__all__ = [
    "SPLITTING_METHODS",
    "AttitudeFit",
    "FitError",
    "FreeRigidBody",
    "InertiaTensor",
    "RigidBodySplitting",
    "RigidBodyTerm",
    "batch_mesh",
    "fit_attitude",
    "free_flow",
    "pad_batch",
    "quaternion_from_matrix",
    "quaternion_to_matrix",
    "shard_batch",
    "shard_bodies",
    "special",
    "splitting_trajectory",
]


def __getattr__(name):
    # frbjax.fit imports optimistix (and lineax); only users who fit pay for that import.
    if name in ("AttitudeFit", "fit_attitude"):
        from . import fit

        return getattr(fit, name)
    # The splitting integrators import diffrax (0.4 s): only users who integrate torques pay for it.
    if name in ("RigidBodySplitting", "RigidBodyTerm", "splitting_trajectory"):
        from . import _splitting

        return getattr(_splitting, name)
    # frbjax.torques: ready-made torques for RigidBodyTerm (it imports the core, never the reverse).
    if name == "torques":
        import importlib

        return importlib.import_module(".torques", __name__)
    # frbjax.lightcurve (shapes, brightness, light-curve inversion) imports optimistix and scipy.
    if name == "lightcurve":
        import importlib

        return importlib.import_module(".lightcurve", __name__)
    # frbjax.posterior (sampling by numpyro's NUTS) imports numpyro.
    if name == "posterior":
        import importlib

        return importlib.import_module(".posterior", __name__)
    if name == "SPLITTING_METHODS":
        from ._splitting import METHODS

        return METHODS
    raise AttributeError(f"module 'frbjax' has no attribute {name!r}")


__version__ = "0.1.0"
