r"""Torqued rigid bodies by splitting: exact free flows alternated with kicks from the torque.

The body (principal moments I, body angular momentum L, attitude q: wxyz, Hamilton, body to space)
under a body-frame torque tau(t, q) moves by

    dL/dt = L x Omega + tau(t, q),      dq/dt = q ⊗ (0, Omega) / 2,      Omega = L / I.

The right-hand side is the sum of two vector fields whose flows are known exactly: the free rigid
body (tau = 0: :func:`~frbjax._free_flow.free_flow`, through Jacobi elliptic functions and the elliptic
integral of the third kind) and the kick (Omega terms dropped: q fixed, L += h tau(t, q)).  A splitting
method composes them within a step of size h as

    K(k_0 h) F(f_0 h) K(k_1 h) F(f_1 h) ... F(f_{n-1} h) K(k_n h),

with kicks K by k_i h and free flows F by f_i h (the time advances with the free flows, so a
time-dependent torque is evaluated at t + h (f_0 + ... + f_{i-1}) in kick i).  A torque that depends
on L too (damping, controllers, eddy currents: :mod:`frbjax.torques`) makes the kick the flow of
dL/dt = tau(t, q, L) at fixed q: a matrix exponential where tau is affine in L, else a Runge-Kutta
sub-step of at least the method's order (:class:`RigidBodySplitting`).  Each piece is the exact
flow of a Hamiltonian (Poisson) vector field when the torque derives from a potential, so the method
is symplectic (Poisson), keeps |q| = 1 exactly and, with fixed steps, keeps the energy error bounded
over exponentially long times (Hairer, Lubich and Wanner, "Geometric Numerical Integration", 2nd ed.,
Springer 2006, chapters IX.8 and VII.5).  Symmetric (palindromic) coefficient lists give even orders;
because the kick moves L only and the free vector field is quadratic in L and linear in L for q,
[B, [B, [B, A]]] = 0 and the Runge-Kutta-Nyström order conditions of Blanes and Moan apply.

References: Celledoni, Fassò, Säfström and Zanna, "The exact computation of the free rigid body
motion and its use in splitting methods", SIAM J. Sci. Comput. 30 (2008) 2084-2112; Celledoni and
Zanna, "Algorithm 903: FRB", ACM TOMS 37(2) (2010); Blanes and Moan, "Practical symplectic partitioned
Runge-Kutta and Runge-Kutta-Nyström methods", J. Comput. Appl. Math. 142 (2002) 313-330; Blanes,
Casas, Farrés, Laskar, Makazaga and Murua, "New families of symplectic splitting methods for
numerical integration in dynamical astronomy", Appl. Numer. Math. 68 (2013) 58-72 (methods for
A + eps B); Yoshida,
"Construction of higher order symplectic integrators", Phys. Lett. A 150 (1990) 262-268.
"""

from __future__ import annotations

import functools
import math
from typing import ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from . import _quaternion as quaternion
from ._checks import is_concrete, real_array
from ._free_flow import free_flow
from ._inertia import InertiaTensor, validate_tensor
from ._kernel_path import keyed_by_path


__all__ = ["METHODS", "RigidBodySplitting", "RigidBodyTerm", "splitting_trajectory"]


# ------------------------------------------------------------------------------------ the methods


def _palindrome(half, middle_repeated):
    """The full list of a palindrome given its first half (the middle entry once or twice)."""
    half = list(half)
    return half + (half[::-1] if middle_repeated else half[-2::-1])


def _yoshida4():
    cube_root = 2.0 ** (1.0 / 3.0)
    outer = 1.0 / (2.0 - cube_root)
    inner = -cube_root * outer
    return (outer / 2, (outer + inner) / 2, (outer + inner) / 2, outer / 2), (outer, inner, outer)


def _blanes_moan4():
    # PRK S6 of order 4 (Blanes and Moan 2002, Table 2), its a_i on the kicks: 7 kicks, 6 free flows.
    a1, a2, a3 = 0.0792036964311957, 0.353172906049774, -0.0420650803577195
    b1, b2 = 0.209515106613362, -0.143851773179818
    kicks = _palindrome((a1, a2, a3, 1 - 2 * (a1 + a2 + a3)), middle_repeated=False)
    flows = _palindrome((b1, b2, 0.5 - (b1 + b2)), middle_repeated=True)
    return tuple(kicks), tuple(flows)


def _blanes_moan6():
    # SRKN6a (Blanes and Moan 2002, Table 3) as in CALGO 903 example 1 (init_example1.dat): a_i on the
    # free flows (8, the middle one once), b_i on the kicks; no kick at either end.
    a = (
        0.0378593198406116,
        0.102635633102435,
        -0.0258678882665587,
        0.314241403071477,
        -0.130144459517415,
        0.106417700369543,
        -0.00879424312851058,
        0.207305069056835,
    )
    b = (
        0.091719152624462,
        0.183983170005006,
        -0.056534365832888,
        0.004914688774713,
        0.143761127168358,
        0.328567693746804,
        -0.196411466486454,
    )
    kicks = (0.0, *_palindrome(b, middle_repeated=True), 0.0)
    flows = _palindrome(a, middle_repeated=False)
    return kicks, tuple(flows)


def _blanes_near_integrable(flows_half, kicks_half):
    """An ABA method of Blanes et al. (2013) for A + eps B: free flows (A) at both ends, kicks (B)
    between them, both lists palindromes given by their first halves up to the middle entry."""
    # As many halves of each: an even count of free flows and an odd one of kicks; one half more of
    # the free flows: the other way round.
    flows_even = len(flows_half) == len(kicks_half)
    flows = _palindrome(flows_half, middle_repeated=flows_even)
    kicks = _palindrome(kicks_half, middle_repeated=not flows_even)
    return (0.0, *kicks, 0.0), tuple(flows)


def _aba864():
    # ABA(8,6,4) (Blanes et al. 2013, Table 2): 8 free flows, 7 kicks.
    return _blanes_near_integrable(
        (
            0.0711334264982231177779387300061549964174,
            0.241153427956640098736487795326289649618,
            0.521411761772814789212136078067994229991,
            -0.333698616227678005726562603400438876027,
        ),
        (
            0.183083687472197221961703757166430291072,
            0.310782859898574869507522291054262796375,
            -0.0265646185119588006972121379164987592663,
            0.0653961422823734184559721793911134363710,
        ),
    )


def _aba1064():
    # ABA(10,6,4) (Blanes et al. 2013, Table 2): 9 free flows, 8 kicks.
    return _blanes_near_integrable(
        (
            0.0380944974224121954569753223086375653406,
            0.145298716116913749294020072660663749744,
            0.207627695725541250716205611324988206516,
            0.435909703651526159223154862401065184401,
            -0.653861225832786709380711737390709412002,
        ),
        (
            0.0958588808370752106107715037714588477692,
            0.204446153142998780680507783916434477976,
            0.217070347978991101714338592430633671453,
            -0.0173753819590650930056178801185269971987,
        ),
    )


#: The named methods: name -> (kicks k_0..k_n, free flows f_0..f_{n-1}, order).  A step is
#: K(k_0 h) F(f_0 h) K(k_1 h) ... F(f_{n-1} h) K(k_n h); a kick of 0 at either end costs nothing.
METHODS = {
    "leapfrog": ((0.5, 0.5), (1.0,), 2),
    "strang": ((0.0, 1.0, 0.0), (0.5, 0.5), 2),
    "yoshida4": (*_yoshida4(), 4),
    "blanes_moan4": (*_blanes_moan4(), 4),
    "blanes_moan6": (*_blanes_moan6(), 6),
    "aba864": (*_aba864(), 4),
    "aba1064": (*_aba1064(), 4),
}

# User coefficients must add up to one step (kicks and flows separately) to this accuracy.
_CONSISTENCY_TOLERANCE = 1e-10


# ----------------------------------------------------------------------------------- the term


def _concrete(value):
    """The value as a numpy array, or None for a JAX tracer (no value yet: under jit, vmap, grad)."""
    leaves = jax.tree_util.tree_leaves(value)
    if any(isinstance(leaf, jax.core.Tracer) for leaf in leaves):
        return None
    return value


def _per_body(function, t, attitude, args):
    """function(t, q, args) for each body of a (..., 4) attitude, args shared: a (...)-batched result."""
    batch = attitude.shape[:-1]
    flat = attitude.reshape((-1, 4))
    values = jax.vmap(function, in_axes=(None, 0, None))(t, flat, args)
    return values.reshape(batch + values.shape[1:])


def _per_body_with_momentum(function, t, attitude, momentum, args):
    """function(t, q, L, args) for each body of (..., 4) attitudes and (..., 3) momenta, args shared."""
    batch = jnp.broadcast_shapes(attitude.shape[:-1], momentum.shape[:-1])
    flat_attitude = jnp.broadcast_to(attitude, batch + (4,)).reshape((-1, 4))
    flat_momentum = jnp.broadcast_to(momentum, batch + (3,)).reshape((-1, 3))
    values = jax.vmap(function, in_axes=(None, 0, 0, None))(t, flat_attitude, flat_momentum, args)
    return values.reshape(batch + values.shape[1:])


class _Function(eqx.Module):
    """A user's function kept in a term: its arrays are pytree leaves, the rest static.

    A plain function is all static (the term stays a pytree of arrays, as jit needs); a module
    holding parameters (the torques of :mod:`frbjax.torques`, a bound method of one) keeps its arrays
    as leaves, so that they are traced and differentiated, never hashed.
    """

    arrays: object
    rest: object = eqx.field(static=True)

    def __init__(self, function):
        self.arrays, self.rest = eqx.partition(function, eqx.is_array)

    @property
    def function(self):
        return eqx.combine(self.arrays, self.rest)

    def __call__(self, *arguments):
        return self.function(*arguments)


class _WithoutMomentum(eqx.Module):
    """A momentum torque that does not depend on L (``depends_on_momentum`` False) as a torque (t, q, args)."""

    momentum_torque: object

    def __call__(self, t, q, args):
        return self.momentum_torque(t, q, jnp.zeros((3,), q.dtype), args)


class _SumOfTorques(eqx.Module):
    """Two torques (t, q, args) -> (3,) added."""

    first: object
    second: object

    def __call__(self, t, q, args):
        return self.first(t, q, args) + self.second(t, q, args)


class RigidBodyTerm(diffrax.AbstractTerm):
    r"""A rigid body under torques, as a diffrax term: the state is ``y = (L, q)``.

    ``RigidBodyTerm(inertia, *, potential=None, torque=None, momentum_torque=None)``, with at least
    one of the three (they add up):

    - ``potential(t, q, args) -> scalar``: the potential energy V of one body in terms of its attitude
      ``q`` (4,) (wxyz, body to space: a body vector x is x_space = R(q) x in space).  The body-frame
      torque is tau = -dV(q ⊗ exp(w / 2))/dw at w = 0 = -vec(conj(q) ⊗ dV/dq) / 2, by autodiff;
    - ``torque(t, q, args) -> (3,)``: a body-frame torque of one body that depends on time and
      attitude only (thrusters fixed in the body, magnetic torquers with a given dipole, ...);
    - ``momentum_torque(t, q, L, args) -> (3,)``: a body-frame torque of one body that may also depend
      on its body angular momentum L (3,), hence on its angular velocity Omega = L / I (damping,
      eddy currents, attitude controllers, B-dot: :mod:`frbjax.torques`).  One whose attribute
      ``depends_on_momentum`` is False (gravity, the gravity gradient, a constant torque of
      :mod:`frbjax.torques`, and their sums) is taken as a ``torque``: the term holds it there.

    The body moves by

        dL/dt = L x Omega + tau(t, q, L),      dq/dt = q ⊗ (0, Omega) / 2,      Omega = L / I,

    tau the sum of the torques given.  With any diffrax solver other than
    :class:`RigidBodySplitting` (``Tsit5``, ``Dopri8``, ...) this ODE is integrated as written
    (``vf``).  With :class:`RigidBodySplitting` the kick is the flow of dL/dt = tau(t, q, L) at fixed
    attitude and time:

    - without a momentum torque, L += s tau(t, q): exact;
    - with a momentum torque that is affine in L, tau = A(t, q) L + c(t, q) (declare it with
      ``linear_in_momentum=True``; every torque of :mod:`frbjax.torques` declares it itself through
      its attribute ``linear_in_momentum``): exact, the matrix exponential of the 4 x 4 matrix
      s [[A, c], [0, 0]] applied to (L, 1) (A = dtau/dL by forward-mode autodiff, c = tau at L = 0).
      Declaring a torque affine that is not gives a kick that is wrong, not merely inaccurate;
    - otherwise one step of a diffrax Runge-Kutta method (``RigidBodySplitting(kick_solver=...)``)
      of at least the splitting's order, so that the order of the method is kept.

    ``linear_in_momentum`` (``None``: the ``momentum_torque``'s own attribute of that name, else
    False) matters only to the splitting.

    The functions are written for one body; the term maps them over the leading dimensions of the
    state with ``args`` shared (per-body parameters: ``jax.vmap`` the whole solve).  ``inertia``
    (..., 3) are the principal moments (> 0, finite), broadcasting with the state's leading
    dimensions, or an `InertiaTensor` (``RigidBodyTerm.from_inertia_tensor``: the state and the torques
    are then those of the tensor's body frame); ``y = (L, q)`` with L (..., 3) in the body frame and q (..., 4)
    must carry the full
    batch shape.  Everything that uses the moments goes through :meth:`angular_velocity` and the
    free flow.
    """

    inertia: Float[Array, "... 3"] | InertiaTensor
    potential: _Function | None
    torque: _Function | None
    momentum_torque: _Function | None
    linear_in_momentum: bool = eqx.field(static=True)

    def __init__(self, inertia, *, potential=None, torque=None, momentum_torque=None, linear_in_momentum=None):
        if potential is None and torque is None and momentum_torque is None:
            raise ValueError(
                "RigidBodyTerm needs at least one of potential=V(t, q, args) (a scalar), "
                "torque=tau(t, q, args) and momentum_torque=tau(t, q, L, args) (body-frame "
                "(3,) vectors)"
            )
        signatures = {
            "potential": "(t, q, args) -> scalar",
            "torque": "(t, q, args) -> (3,) body torque",
            "momentum_torque": "(t, q, L, args) -> (3,) body torque",
        }
        for name, function in (("potential", potential), ("torque", torque), ("momentum_torque", momentum_torque)):
            if function is not None and not callable(function):
                raise ValueError(f"{name} must be a function {signatures[name]}")
        if not isinstance(inertia, InertiaTensor):
            if is_concrete(inertia):
                real_array("inertia", inertia)
            inertia = jnp.asarray(inertia)
            if inertia.ndim == 0 or inertia.shape[-1] != 3:
                raise ValueError(f"inertia must have shape (..., 3), got shape {tuple(inertia.shape)}")
            if not jnp.issubdtype(inertia.dtype, jnp.floating):
                inertia = inertia.astype(float)
            value = _concrete(inertia)
            if value is not None and not (np.all(np.isfinite(value)) and np.all(np.asarray(value) > 0)):
                raise ValueError("inertia: the principal moments of inertia must be finite and > 0")
        if momentum_torque is not None and getattr(momentum_torque, "depends_on_momentum", True) is False:
            # A torque of frbjax.torques that does not depend on L (gravity, the gravity gradient): a
            # torque of (t, q), kicked by L += s tau, not by the matrix exponential of an affine kick.
            position_torque = _WithoutMomentum(momentum_torque)
            torque = position_torque if torque is None else _SumOfTorques(torque, position_torque)
            momentum_torque = None
        if linear_in_momentum is None:
            linear_in_momentum = bool(getattr(momentum_torque, "linear_in_momentum", False))
        self.inertia = inertia
        self.potential = None if potential is None else _Function(potential)
        self.torque = None if torque is None else _Function(torque)
        self.momentum_torque = None if momentum_torque is None else _Function(momentum_torque)
        self.linear_in_momentum = bool(linear_in_momentum)

    # --------------------------------------------------------------------------- the moments

    @classmethod
    def from_inertia_tensor(cls, inertia_tensor, **functions) -> RigidBodyTerm:
        """The term of a body with inertia tensor ``inertia_tensor`` (..., 3, 3) in its body frame:
        ``RigidBodyTerm(InertiaTensor(inertia_tensor), **functions)``; L, q, torques in that frame."""
        validate_tensor(jnp.asarray(inertia_tensor), "inertia_tensor")
        return cls(InertiaTensor(inertia_tensor), **functions)

    def angular_velocity(self, momentum) -> Float[Array, "... 3"]:
        """Omega = I^-1 L, the body angular velocity of a body angular momentum L (..., 3)."""
        if isinstance(self.inertia, InertiaTensor):
            return self.inertia.angular_velocity(momentum)
        # A batch of momenta against the moments (or the reverse), with the ranks made equal
        # explicitly (no numpy rank promotion).
        momentum = jnp.asarray(momentum)
        inertia = self.inertia
        extra = momentum.ndim - inertia.ndim
        if extra > 0:
            inertia = inertia.reshape((1,) * extra + inertia.shape)
        elif extra < 0:
            momentum = momentum.reshape((1,) * -extra + momentum.shape)
        return momentum / inertia

    def free_motion(self, momentum, attitude, time):
        """The exact torque-free motion of the state (L, q) over ``time``: (L(time), q(time))."""
        return free_flow(self.inertia, momentum, attitude, time)

    def kinetic_energy(self, momentum) -> Float[Array, ...]:
        """L . Omega / 2 per body."""
        return 0.5 * jnp.sum(momentum * self.angular_velocity(momentum), axis=-1)

    # ---------------------------------------------------------------------------- the torque

    def _check_shapes(self, t, attitude, args):
        one = jax.ShapeDtypeStruct((4,), attitude.dtype)
        if self.potential is not None:
            shape = jax.eval_shape(self.potential, t, one, args).shape
            if shape != ():
                raise ValueError(
                    f"potential must return a scalar (the potential energy of one body), got shape {shape}"
                )
        if self.torque is not None:
            shape = jax.eval_shape(self.torque, t, one, args).shape
            if shape != (3,):
                raise ValueError(f"torque must return the body-frame torque of one body, shape (3,), got shape {shape}")
        if self.momentum_torque is not None:
            momentum = jax.ShapeDtypeStruct((3,), attitude.dtype)
            shape = jax.eval_shape(self.momentum_torque, t, one, momentum, args).shape
            if shape != (3,):
                raise ValueError(
                    f"momentum_torque must return the body-frame torque of one body, shape (3,), got shape {shape}"
                )

    def body_torque(self, t, attitude, args, momentum=None) -> Float[Array, "... 3"]:
        """The total body-frame torque tau(t, q, L) of every body, (..., 3) for an attitude (..., 4).

        ``momentum`` (..., 3), the body angular momentum, is needed when the term has a momentum
        torque.  Raises ValueError when a function does not return the shape it should (shapes are
        static: under jit too).
        """
        self._check_shapes(t, attitude, args)
        if self.momentum_torque is not None and momentum is None:
            raise ValueError("body_torque needs the momentum L: this term has a momentum_torque")
        torque = jnp.zeros(attitude.shape[:-1] + (3,), attitude.dtype)
        if self.potential is not None:
            torque = torque + _per_body(self._torque_of_potential, t, attitude, args)
        if self.torque is not None:
            torque = torque + _per_body(self.torque, t, attitude, args)
        if self.momentum_torque is not None:
            torque = torque + _per_body_with_momentum(self.momentum_torque, t, attitude, momentum, args)
        return torque.astype(attitude.dtype)

    def _torque_of_potential(self, t, attitude, args):
        # tau = -dV/dtheta at theta = 0 for the body-frame rotation q -> q ⊗ (1, theta/2), to first
        # order q ⊗ exp(theta/2).  Differentiating in the three body angles costs less than the
        # gradient in the four components of q projected afterwards (8% of a gravity-gradient
        # satellite's splitting step, a batch of 1024; same torque to rounding).
        def rotated(angles):
            turn = jnp.concatenate([jnp.ones((1,), angles.dtype), angles / 2])
            return self.potential(t, quaternion.multiply(attitude, turn), args)

        return -jax.grad(rotated)(jnp.zeros((3,), attitude.dtype))

    def energy(self, t, y, args) -> Float[Array, ...]:
        """Kinetic plus potential energy, L . Omega / 2 + V(t, q, args), per body (needs a potential).

        With only torques (no potential) use :meth:`kinetic_energy`.
        """
        if self.potential is None:
            raise ValueError(
                "energy needs a potential; this term has only torque functions (kinetic_energy(L) gives L . Omega / 2)"
            )
        momentum, attitude = y
        return self.kinetic_energy(momentum) + _per_body(self.potential, t, attitude, args)

    # ------------------------------------------------------------------------- diffrax term

    def vf(self, t, y, args):
        """(dL/dt, dq/dt) = (L x Omega + tau(t, q, L), q ⊗ (0, Omega) / 2), Omega = L / I."""
        momentum, attitude = y
        omega = self.angular_velocity(momentum)
        torque = self.body_torque(t, attitude, args, momentum)
        pure = jnp.concatenate([jnp.zeros_like(omega[..., :1]), omega], axis=-1)
        return jnp.cross(momentum, omega) + torque, 0.5 * quaternion.multiply(attitude, pure)

    def contr(self, t0, t1, **kwargs):
        return t1 - t0

    def prod(self, vf, control):
        return jax.tree_util.tree_map(lambda v: v * control, vf)


# --------------------------------------------------------------------------------- the solver


def _unwrap(terms):
    """The RigidBodyTerm inside diffrax's wrappers and the direction of time (+1, or -1 backwards)."""
    # diffeqsolve hands the solver its term wrapped (WrapTerm, which carries the direction of time,
    # is not public API): unwrap by the wrappers' fields.
    direction = 1
    term = terms
    while not isinstance(term, RigidBodyTerm) and isinstance(getattr(term, "term", None), diffrax.AbstractTerm):
        direction = direction * getattr(term, "direction", 1)
        term = term.term
    if not isinstance(term, RigidBodyTerm):
        raise ValueError(f"RigidBodySplitting integrates a RigidBodyTerm, got {type(term).__name__}")
    return term, direction


class RigidBodySplitting(diffrax.AbstractSolver):
    r"""Splitting integrator for a :class:`RigidBodyTerm`: exact free flows and kicks, fixed steps.

    ``RigidBodySplitting(method="blanes_moan6")`` or ``RigidBodySplitting(kicks=..., flows=...,
    order=None)``.  One step of size h is

        K(k_0 h) F(f_0 h) K(k_1 h) F(f_1 h) ... F(f_{n-1} h) K(k_n h)

    with F(s) the exact torque-free motion over a time s and K(s) the kick L += s tau(t, q) (q and
    the time unchanged).  Named methods (``METHODS``):

    ==============  =====  ===========  =====  ===============================================
    name            order  free flows   kicks  coefficients
    ==============  =====  ===========  =====  ===============================================
    leapfrog        2      1            2      k = (1/2, 1/2), f = (1)
    strang          2      2            1      f = (1/2, 1/2), k = (0, 1, 0)
    yoshida4        4      3            4      triple jump of leapfrog (Yoshida 1990)
    blanes_moan4    4      6            7      PRK S6 (Blanes and Moan 2002), a_i on the kicks
    blanes_moan6    6      15           14     SRKN6a (Blanes and Moan 2002), CALGO 903 ex. 1
    aba864          4      8            7      ABA(8,6,4) (Blanes et al. 2013), A = free flow
    aba1064         4      9            8      ABA(10,6,4) (Blanes et al. 2013), A = free flow
    ==============  =====  ===========  =====  ===============================================

    For a torque small against the free motion (a satellite's environment torques: the kick is
    eps B, the free flow A), the ABA methods' error is O(eps h^8 + eps^2 h^6 + eps^3 h^4) (O(eps
    h^10 + ...) for aba1064) with about half the free flows of blanes_moan6 per step: on the
    gravity-gradient satellite of benchmarks/torques_basilisk.py, aba1064 at h = 40 s is within a
    factor 2 of blanes_moan6's error at the same step (8.3e-9 against 4.5e-9) for 9 free flows
    instead of 15, and 1.6 times faster (docs/torqued.md).  Their classical order (any torque) is 4.
    Between saved states (``splitting_trajectory(save_every=...)``) a method that starts and ends
    with a free flow joins them across steps: 8 free flows a step for aba1064.

    Your own coefficients: ``kicks`` (n + 1 numbers) and ``flows`` (n numbers), each adding up to 1
    (put a 0 kick at both ends for a method that starts and ends with a free flow); ``order`` is
    informational.  The cost of a step is dominated by its free flows.

    Torques that depend on L (``RigidBodyTerm(momentum_torque=...)``): the kick is the flow of
    dL/dt = tau(t, q, L) at fixed q, exact for a torque affine in L (a matrix exponential), else one
    step of ``kick_solver`` (default: ``diffrax.Tsit5()``, order 5, for the methods of order <= 4;
    ``diffrax.Dopri8()``, order 8, for blanes_moan6 and your own coefficients).  The orders kept,
    measured against Dopri8 in tests/test_torques.py: leapfrog and strang 2, yoshida4,
    blanes_moan4, aba864 and aba1064 4, and blanes_moan6 4, not 6: SRKN6a's sixth order rests on
    [B, [B, [B, A]]] = 0, which holds for kicks that depend on q only, not for kicks that move L by
    a function of L.  The
    sub-integrated kick is not time-symmetric, so such a method is no longer time-reversible.

    Fixed steps only: the method has no error estimate; use ``dt0`` with the default
    ``diffrax.ConstantStepSize()`` (an adaptive controller is refused by diffrax).  Dense output and
    ``SaveAt(ts=...)`` between steps interpolate linearly (|q| = 1 holds only at the steps).
    """

    kicks: tuple = eqx.field(static=True)
    flows: tuple = eqx.field(static=True)
    method_order: int | None = eqx.field(static=True)
    kick_solver: diffrax.AbstractRungeKutta = eqx.field(static=True)

    term_structure: ClassVar = RigidBodyTerm
    interpolation_cls: ClassVar = diffrax.LocalLinearInterpolation

    def __init__(self, method="blanes_moan6", *, kicks=None, flows=None, order=None, kick_solver=None):
        if kicks is not None or flows is not None:
            if kicks is None or flows is None:
                raise ValueError("give both kicks (n + 1 coefficients) and flows (n coefficients)")
            kicks = tuple(float(k) for k in np.ravel(kicks))
            flows = tuple(float(f) for f in np.ravel(flows))
            if len(flows) < 1 or len(kicks) != len(flows) + 1:
                raise ValueError(
                    f"kicks must have one coefficient more than flows (n + 1 and n >= 1), "
                    f"got {len(kicks)} kicks and {len(flows)} flows"
                )
            for name, values in (("kicks", kicks), ("flows", flows)):
                if not all(math.isfinite(v) for v in values):
                    raise ValueError(f"{name}: the coefficients must be finite")
                if abs(math.fsum(values) - 1) > _CONSISTENCY_TOLERANCE:
                    raise ValueError(
                        f"{name}: the coefficients must add up to 1 (one step), they add up to {math.fsum(values)!r}"
                    )
        else:
            if method not in METHODS:
                raise ValueError(
                    f"unknown splitting method {method!r}; expected one of {', '.join(METHODS)}, or kicks= and flows="
                )
            kicks, flows, order = METHODS[method]
        if kick_solver is None:
            # One step of order 5 (Tsit5) keeps orders up to 4, order 8 (Dopri8) anything higher.
            kick_solver = diffrax.Tsit5() if order is not None and order <= 4 else diffrax.Dopri8()
        if not isinstance(kick_solver, diffrax.AbstractRungeKutta):
            raise ValueError(
                f"kick_solver must be an explicit diffrax Runge-Kutta solver (Tsit5, Dopri8, "
                f"...), got {type(kick_solver).__name__}"
            )
        self.kicks = kicks
        self.flows = flows
        self.method_order = order
        self.kick_solver = kick_solver

    def order(self, terms):
        return self.method_order

    def init(self, terms, t0, t1, y0, args):
        return None

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del solver_state, made_jump
        term, direction = _unwrap(terms)
        arguments = (term, direction * t0, direction * (t1 - t0), y0, args)
        if any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves(arguments)):
            y1 = self.advance(*arguments)
        else:
            # A step called eagerly, outside diffeqsolve: one compiled program, not op by op.
            y1 = _eager_advance(self, *arguments)
        return y1, None, dict(y0=y0, y1=y1), None, diffrax.RESULTS.successful

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def kick(self, term, t, s, momentum, attitude, args):
        """The flow of dL/dt = tau(t, q, L) over a time s at fixed attitude q and time t (the class doc)."""
        if term.momentum_torque is None:
            return momentum + s * term.body_torque(t, attitude, args)
        # Shape errors are raised here, once, rather than inside the per-body maps below.
        term.body_torque(t, attitude, args, momentum)
        if term.linear_in_momentum:
            return _affine_kick(term, t, s, momentum, attitude, args)
        kick_term = diffrax.ODETerm(lambda _, momentum, attitude: term.body_torque(t, attitude, args, momentum))
        zero = jnp.zeros((), s.dtype)
        state = self.kick_solver.init(kick_term, zero, s, momentum, attitude)
        momentum, *_ = self.kick_solver.step(kick_term, zero, s, momentum, attitude, state, made_jump=False)
        return momentum

    def advance(self, term, t, h, y, args):
        """One step of size h (any sign) from the state y = (L, q) at time t."""
        momentum, attitude = y
        dtype = jnp.result_type(momentum, attitude)
        # diffrax's times are float64 under x64 even for a float32 state: keep the state's precision.
        t, h = jnp.asarray(t, dtype), jnp.asarray(h, dtype)
        kick, free_motion = self._pieces(term, h, args)
        kicks = jnp.asarray(self.kicks, dtype)
        flows = jnp.asarray(self.flows, dtype)
        # Kick i + 1 comes after the free flows 0..i: at time t + h (f_0 + ... + f_i).
        kick_times = jnp.asarray(np.cumsum(self.flows), dtype)
        if self.kicks[0] != 0:
            momentum = kick(momentum, attitude, kicks[0], t)

        # One loop over the stages, the last kick included even when its coefficient is 0: one copy
        # of the stage in the program, whatever the method's number of stages.
        def stage(state, coefficients):
            momentum, attitude = state
            flow, next_kick, time = coefficients
            momentum, attitude = free_motion(momentum, attitude, flow * h)
            return (kick(momentum, attitude, next_kick, t + time * h), attitude), None

        (momentum, attitude), _ = jax.lax.scan(stage, (momentum, attitude), (flows, kicks[1:], kick_times))
        return momentum.astype(dtype), attitude.astype(dtype)

    def advance_steps(self, term, t, h, y, args, count):
        """``count`` steps of size h (any sign) from the state y = (L, q) at time t: the state after
        the last one.

        A method that starts and ends with a free flow (k_0 = k_n = 0) joins each step's last free
        flow with the next step's first, F(f_{n-1} h) F(f_0 h) = F((f_{n-1} + f_0) h) (the free motion
        is a flow: exact): n - 1 free flows a step instead of n, for a caller that needs the state
        every ``count`` steps only.  Other methods take ``count`` steps of ``advance``.
        """
        if count == 1:
            return self.advance(term, t, h, y, args)
        momentum, attitude = y
        dtype = jnp.result_type(momentum, attitude)
        # diffrax's times are float64 under x64 even for a float32 state: keep the state's precision.
        t, h = jnp.asarray(t, dtype), jnp.asarray(h, dtype)
        kick, free_motion = self._pieces(term, h, args)
        flows, kicks = self.flows, self.kicks
        # Kick i comes after the free flows 0..i-1 of its step: at time t + h (j + f_0 + ... + f_{i-1}).
        offsets = np.concatenate([[0.0], np.cumsum(flows)])

        def constant(values):
            return jnp.asarray(np.asarray(values, float), dtype)

        def stages(state, time, coefficients):
            # (kick i, then free flow i) for the stages given: kick coefficient, time offset, flow.
            def stage(state, stage_coefficients):
                momentum, attitude = state
                kick_coefficient, offset, flow = stage_coefficients
                momentum = kick(momentum, attitude, kick_coefficient, time + offset * h)
                return free_motion(momentum, attitude, flow * h), None

            length = coefficients[0].shape[0]
            if length <= 1:
                # No loop of zero or one iteration: the stage itself, if any.
                return stage(state, tuple(c[0] for c in coefficients))[0] if length else state
            return jax.lax.scan(stage, state, coefficients)[0]

        def repeat(one_step, state):
            return jax.lax.scan(one_step, state, jnp.arange(count, dtype=dtype))[0]

        state = (momentum, attitude)
        if kicks[0] == 0 and kicks[-1] == 0 and len(flows) > 1:
            # [F(f_0 + f_{n-1}) K(k_1) F(f_1) ... F(f_{n-2}) K(k_{n-1})] per step, the first step's
            # first free flow F(f_0), then the last step's last free flow F(f_{n-1}).
            first, joined_first = constant(flows[0]), constant(flows[0] + flows[-1])
            rest = (constant(kicks[1:-1]), constant(offsets[1:-1]))

            def one_step(state, j):
                momentum, attitude = free_motion(*state, jnp.where(j == 0, first, joined_first) * h)
                # Kick i, then free flow i, for i = 1..n-2; kick n-1 last.
                momentum, attitude = stages(
                    (momentum, attitude), t + j * h, (rest[0][:-1], rest[1][:-1], constant(flows[1:-1]))
                )
                return (kick(momentum, attitude, rest[0][-1], t + (j + rest[1][-1]) * h), attitude), None

            state = repeat(one_step, state)
            momentum, attitude = free_motion(*state, constant(flows[-1]) * h)
            return momentum.astype(dtype), attitude.astype(dtype)

        # Kicks at both ends: nothing to join, the steps one after the other.
        def one_step(state, j):
            return self.advance(term, t + j * h, h, state, args), None

        momentum, attitude = repeat(one_step, state)
        return momentum.astype(dtype), attitude.astype(dtype)

    def _pieces(self, term, h, args):
        """(kick(L, q, coefficient, time) -> L, free_motion(L, q, time) -> (L, q)) of a step of size h."""

        def kick(momentum, attitude, coefficient, time):
            return self.kick(term, time, coefficient * h, momentum, attitude, args)

        def free_motion(momentum, attitude, time):
            return term.free_motion(momentum, attitude, time)

        return kick, free_motion


def _affine_kick(term, t, s, momentum, attitude, args):
    """L(s) of dL/ds = A L + c at fixed (t, q): (L(s), 1) = expm(s [[A, c], [0, 0]]) (L, 1), per body."""

    def one_body(attitude, momentum):
        def torque(momentum):
            return term.body_torque(t, attitude[None], args, momentum[None])[0]

        zero = jnp.zeros_like(momentum)
        constant = torque(zero)
        matrix = jax.jacfwd(torque)(zero)
        generator = jnp.zeros((4, 4), momentum.dtype)
        generator = generator.at[:3, :3].set(s * matrix).at[:3, 3].set(s * constant)
        flow = jax.scipy.linalg.expm(generator)
        return flow[:3, :3] @ momentum + flow[:3, 3]

    batch = momentum.shape[:-1]
    moved = jax.vmap(one_body)(attitude.reshape((-1, 4)), momentum.reshape((-1, 3)))
    return moved.reshape(batch + (3,))


# --------------------------------------------------------------------------- the lean driver


def _checked_step(dt):
    """dt if finite and > 0; ValueError when concrete, NaN (hence NaN states) when traced."""
    if is_concrete(dt):
        real_array("dt", dt)
    dt = jnp.asarray(dt)
    value = _concrete(dt)
    if value is not None:
        if dt.ndim != 0 or not (np.isfinite(value) and value > 0):
            raise ValueError(f"dt: the step must be a finite scalar > 0, got {np.asarray(value)!r}")
        return dt
    return jnp.where(jnp.isfinite(dt) & (dt > 0), dt, jnp.nan)


def _checked_state(y0, term):
    momentum, attitude = y0
    for name, value in (("y0[0] (angular momentum)", momentum), ("y0[1] (attitude)", attitude)):
        if is_concrete(value):
            real_array(name, value)
    momentum, attitude = jnp.asarray(momentum), jnp.asarray(attitude)
    for name, value, size in (("y0[0] (angular momentum)", momentum, 3), ("y0[1] (attitude)", attitude, 4)):
        if value.ndim == 0 or value.shape[-1] != size:
            raise ValueError(f"{name} must have shape (..., {size}), got shape {tuple(value.shape)}")
        concrete = _concrete(value)
        if concrete is not None and not np.all(np.isfinite(concrete)):
            raise ValueError(f"{name} must be finite")
    concrete = _concrete(attitude)
    if concrete is not None and not np.all(np.any(np.asarray(concrete) != 0, axis=-1)):
        raise ValueError("y0[1] (attitude) must be a non-zero quaternion")
    moments = term.inertia.principal_moments if isinstance(term.inertia, InertiaTensor) else term.inertia
    dtype = jnp.result_type(momentum, attitude, moments, float)
    batch = jnp.broadcast_shapes(momentum.shape[:-1], attitude.shape[:-1], moments.shape[:-1])
    attitude = attitude / jnp.linalg.norm(attitude, axis=-1, keepdims=True)
    return (
        jnp.broadcast_to(momentum, batch + (3,)).astype(dtype),
        jnp.broadcast_to(attitude, batch + (4,)).astype(dtype),
    )


def _check_initial_torque(term, t0, y0, args):
    """ValueError when the torque at the (concrete) initial state is not finite; nothing when traced."""
    momentum, attitude = y0
    if _concrete((term, t0, momentum, attitude, args)) is None:
        return
    torque = term.body_torque(t0, attitude, args, momentum)
    if _concrete(torque) is not None and not np.all(np.isfinite(np.asarray(torque))):
        names = [name for name in ("potential", "torque", "momentum_torque") if getattr(term, name) is not None]
        raise ValueError(
            f"the torque at the initial state is not finite (NaN or inf): check "
            f"{' and '.join(names)} at t0 = {float(t0)!r}"
        )


@keyed_by_path(jit=eqx.filter_jit)
def _eager_advance(solver, term, t, h, y, args):
    return solver.advance(term, t, h, y, args)


@functools.lru_cache(maxsize=64)
def _trajectory_program(solver, steps, dtype, save_every=1):
    """The loop over ``steps`` steps of ``solver``, the state saved every ``save_every`` steps, as one
    jitted function, made once per (solver, steps, dtype, save_every), so that eager calls of
    ``splitting_trajectory`` reuse its compiled program."""

    def trajectory(term, y0, dt, t0, args):
        def saved_steps(state, n):
            state = solver.advance_steps(term, t0 + n * dt, dt, state, args, save_every)
            return state, state

        if steps == save_every:
            # One block: its state directly, without a loop of one iteration around it.
            return jax.tree.map(lambda x: x[None], saved_steps(y0, jnp.zeros((), dtype))[1])
        return jax.lax.scan(saved_steps, y0, jnp.arange(0, steps, save_every, dtype=dtype))[1]

    return keyed_by_path(trajectory, jit=eqx.filter_jit)


def splitting_trajectory(term, y0, *, dt, steps, t0=0.0, args=None, method="blanes_moan6", save_every=1):
    r"""The states after each of ``steps`` fixed steps of a splitting method: a lean ``lax.scan``.

    Returns ``(ts, (L, q))`` with ``ts`` (steps / save_every + 1,) = t0 + n save_every dt and L
    (steps / save_every + 1, ..., 3), q (..., 4), the initial state first.  ``method`` is a name of
    ``METHODS`` or a :class:`RigidBodySplitting`; the step is the same code as
    ``diffrax.diffeqsolve(term, RigidBodySplitting(...), ...)``.  ``steps`` is a Python int (the
    program is compiled for it), and so is ``save_every``, which must divide it.

    ``save_every`` > 1 saves every ``save_every``-th state only, and for a method that starts and
    ends with a free flow (strang, aba864, aba1064) joins the last free flow of each step with the
    first of the next between saved states (``RigidBodySplitting.advance_steps``): one free flow a
    step fewer (aba1064: 8 instead of 9), the same method.  ``save_every=steps`` returns the initial
    and the final state.

    Use it for many saved steps of a small system (no per-step bookkeeping of diffeqsolve), for the
    state at a final time, and for forward-mode derivatives; reverse mode through it stores every
    step (memory grows with ``steps``): for long reverse-mode runs use diffeqsolve with its
    ``RecursiveCheckpointAdjoint``.
    Bad input: ``dt`` <= 0 or not finite, a non-finite or zero initial state, or a torque that is not
    finite at the initial state (a NaN-returning function) raise ValueError naming the argument when
    they are concrete; under jit the states are NaN instead.  The attitude
    is normalised and the state broadcast to the batch of ``term.inertia``.
    """
    solver = method if isinstance(method, RigidBodySplitting) else RigidBodySplitting(method)
    if not isinstance(term, RigidBodyTerm):
        raise ValueError(f"term must be a RigidBodyTerm, got {type(term).__name__}")
    if not isinstance(steps, (int, np.integer)) or steps < 0:
        raise ValueError(f"steps must be a Python int >= 0, got {steps!r}")
    if not isinstance(save_every, (int, np.integer)) or save_every < 1 or steps % save_every:
        raise ValueError(f"save_every must be a Python int >= 1 that divides steps ({steps}), got {save_every!r}")
    y0 = _checked_state(y0, term)
    dtype = y0[0].dtype
    dt = _checked_step(dt).astype(dtype)
    t0 = jnp.asarray(t0, dtype)
    _check_initial_torque(term, t0, y0, args)

    # Everything the loop reads is an argument, so that its compiled program serves any state.
    key = (solver, int(steps), jnp.dtype(dtype).name, int(save_every))
    try:
        program = _trajectory_program(*key)
    except TypeError:  # a solver that cannot be hashed (a kick solver of the user's, say): no cache
        program = _trajectory_program.__wrapped__(*key)
    momenta, attitudes = program(term, y0, dt, t0, args)
    ts = t0 + dt * (save_every * jnp.arange(steps // save_every + 1, dtype=dtype))
    return ts, (jnp.concatenate([y0[0][None], momenta]), jnp.concatenate([y0[1][None], attitudes]))
