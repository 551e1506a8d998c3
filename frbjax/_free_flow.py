"""The exact torque-free flow over one time: the building block of the splitting integrators.

Every free flow of :mod:`frbjax._splitting` goes through :func:`free_flow`, so that a cheaper
one-shot evaluation of the free motion replaces it here alone.
"""

from __future__ import annotations

from ._body import FreeRigidBody


def free_flow(inertia, angular_momentum, attitude, t):
    """(L(t), q(t)) of the free body that has body angular momentum L and attitude q at time 0.

    ``inertia`` (..., 3), ``angular_momentum`` (..., 3), ``attitude`` (..., 4) (wxyz, body to space) and
    ``t`` (scalar or (...)) broadcast over their leading dimensions.  Exact (the motion of
    :class:`~frbjax.FreeRigidBody`); differentiable in every input.  Both come from one evaluation of
    the motion (:meth:`~frbjax.FreeRigidBody.state`).
    """
    return FreeRigidBody(inertia, angular_momentum, attitude).state(t)
