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
time-dependent torque is evaluated at t + h (f_0 + ... + f_{i-1}) in kick i).  Each piece is the exact
flow of a Hamiltonian (Poisson) vector field when the torque derives from a potential, so the method
is symplectic (Poisson), keeps |q| = 1 exactly and, with fixed steps, keeps the energy error bounded
over exponentially long times (Hairer, Lubich and Wanner, "Geometric Numerical Integration", 2nd ed.,
Springer 2006, chapters IX.8 and VII.5).  Symmetric (palindromic) coefficient lists give even orders;
because the kick moves L only and the free vector field is quadratic in L and linear in L for q,
[B, [B, [B, A]]] = 0 and the Runge-Kutta-Nyström order conditions of Blanes and Moan apply.

References: Celledoni, Fassò, Säfström and Zanna, "The exact computation of the free rigid body
motion and its use in splitting methods", SIAM J. Sci. Comput. 30 (2008) 2084-2112; Celledoni and
Zanna, "Algorithm 903: FRB", ACM TOMS 37(2) (2010); Blanes and Moan, "Practical symplectic partitioned
Runge-Kutta and Runge-Kutta-Nyström methods", J. Comput. Appl. Math. 142 (2002) 313-330; Yoshida,
"Construction of higher order symplectic integrators", Phys. Lett. A 150 (1990) 262-268.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from . import _quaternion as quaternion
from ._free_flow import free_flow
from ._kernel import one_kernel

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
    a = (0.0378593198406116, 0.102635633102435, -0.0258678882665587, 0.314241403071477,
         -0.130144459517415, 0.106417700369543, -0.00879424312851058, 0.207305069056835)
    b = (0.091719152624462, 0.183983170005006, -0.056534365832888, 0.004914688774713,
         0.143761127168358, 0.328567693746804, -0.196411466486454)
    kicks = (0.0, *_palindrome(b, middle_repeated=True), 0.0)
    flows = _palindrome(a, middle_repeated=False)
    return kicks, tuple(flows)


#: The named methods: name -> (kicks k_0..k_n, free flows f_0..f_{n-1}, order).  A step is
#: K(k_0 h) F(f_0 h) K(k_1 h) ... F(f_{n-1} h) K(k_n h); a kick of 0 at either end costs nothing.
METHODS = {
    "leapfrog": ((0.5, 0.5), (1.0,), 2),
    "strang": ((0.0, 1.0, 0.0), (0.5, 0.5), 2),
    "yoshida4": (*_yoshida4(), 4),
    "blanes_moan4": (*_blanes_moan4(), 4),
    "blanes_moan6": (*_blanes_moan6(), 6),
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


class RigidBodyTerm(diffrax.AbstractTerm):
    r"""A rigid body under a torque, as a diffrax term: the state is ``y = (L, q)``.

    ``RigidBodyTerm(inertia, *, potential=None, torque=None)``, with exactly one of

    - ``potential(t, q, args) -> scalar``: the potential energy V of one body in terms of its attitude
      ``q`` (4,) (wxyz, body to space: a body vector x is x_space = R(q) x in space).  The body-frame
      torque is tau = -dV(q ⊗ exp(w / 2))/dw at w = 0 = -vec(conj(q) ⊗ dV/dq) / 2, by autodiff;
    - ``torque(t, q, args) -> (3,)``: the body-frame torque of one body (non-conservative torques:
      thrusters fixed in the body, magnetic torquers, ...).  It may depend on time and attitude, not on
      L: the kick then has the exact flow L += h tau(t, q) that the splitting needs.

    Both are written for one body; the term maps them over the leading dimensions of the state with
    ``args`` shared (per-body parameters: ``jax.vmap`` the whole solve).  ``inertia`` (..., 3) are the
    principal moments (> 0, finite), broadcasting with the state's leading dimensions; ``y = (L, q)``
    with L (..., 3) in the body frame and q (..., 4) must carry the full batch shape.

    The term is an ordinary diffrax term: with :class:`RigidBodySplitting` it is integrated by
    splitting; with any other diffrax solver (``Tsit5``, ``Dopri8``, ...) the same ODE
    dL/dt = L x Omega + tau, dq/dt = q ⊗ (0, Omega)/2 is integrated by that solver (``vf``).
    """

    inertia: Float[Array, "... 3"]
    potential: Callable | None = eqx.field(static=True)
    torque: Callable | None = eqx.field(static=True)

    def __init__(self, inertia, *, potential=None, torque=None):
        if (potential is None) == (torque is None):
            raise ValueError("RigidBodyTerm needs exactly one of potential=V(t, q, args) (a scalar) and "
                             "torque=tau(t, q, args) (a body-frame (3,) vector)")
        for name, function in (("potential", potential), ("torque", torque)):
            if function is not None and not callable(function):
                raise ValueError(f"{name} must be a function (t, q, args) -> "
                                 f"{'scalar' if name == 'potential' else '(3,) body torque'}")
        inertia = jnp.asarray(inertia)
        if inertia.ndim == 0 or inertia.shape[-1] != 3:
            raise ValueError(f"inertia must have shape (..., 3), got shape {tuple(inertia.shape)}")
        if not jnp.issubdtype(inertia.dtype, jnp.floating):
            inertia = inertia.astype(float)
        value = _concrete(inertia)
        if value is not None and not (np.all(np.isfinite(value)) and np.all(np.asarray(value) > 0)):
            raise ValueError("inertia: the principal moments of inertia must be finite and > 0")
        self.inertia = inertia
        self.potential = potential
        self.torque = torque

    # ---------------------------------------------------------------------------- the torque

    def body_torque(self, t, attitude, args) -> Float[Array, "... 3"]:
        """The body-frame torque tau(t, q) of every body, shape (..., 3) for an attitude (..., 4).

        Raises ValueError when the potential does not return a scalar or the torque function does
        not return a (3,) vector (shapes are static: under jit too).
        """
        one = jax.ShapeDtypeStruct((4,), attitude.dtype)
        if self.potential is not None:
            shape = jax.eval_shape(self.potential, t, one, args).shape
            if shape != ():
                raise ValueError(f"potential must return a scalar (the potential energy of one body), "
                                 f"got shape {shape}")
            return _per_body(self._torque_of_potential, t, attitude, args).astype(attitude.dtype)
        shape = jax.eval_shape(self.torque, t, one, args).shape
        if shape != (3,):
            raise ValueError(f"torque must return the body-frame torque of one body, shape (3,), got "
                             f"shape {shape}")
        return _per_body(self.torque, t, attitude, args).astype(attitude.dtype)

    def _torque_of_potential(self, t, attitude, args):
        gradient = jax.grad(self.potential, argnums=1)(t, attitude, args)
        return -0.5 * quaternion.multiply(quaternion.conjugate(attitude), gradient)[1:]

    def energy(self, t, y, args) -> Float[Array, "..."]:
        """Kinetic plus potential energy, sum L_i^2 / (2 I_i) + V(t, q, args), per body (potential only)."""
        if self.potential is None:
            raise ValueError("energy needs a potential; this term has a torque function")
        momentum, attitude = y
        kinetic = 0.5 * jnp.sum(momentum * momentum / self.inertia, axis=-1)
        return kinetic + _per_body(self.potential, t, attitude, args)

    # ------------------------------------------------------------------------- diffrax term

    def vf(self, t, y, args):
        """(dL/dt, dq/dt) = (L x Omega + tau(t, q), q ⊗ (0, Omega) / 2), Omega = L / I."""
        momentum, attitude = y
        omega = momentum / self.inertia
        torque = self.body_torque(t, attitude, args)
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
    while not isinstance(term, RigidBodyTerm) and isinstance(getattr(term, "term", None),
                                                              diffrax.AbstractTerm):
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
    ==============  =====  ===========  =====  ===============================================

    Your own coefficients: ``kicks`` (n + 1 numbers) and ``flows`` (n numbers), each adding up to 1
    (put a 0 kick at both ends for a method that starts and ends with a free flow); ``order`` is
    informational.  The cost of a step is dominated by its free flows.

    Fixed steps only: the method has no error estimate; use ``dt0`` with the default
    ``diffrax.ConstantStepSize()`` (an adaptive controller is refused by diffrax).  Dense output and
    ``SaveAt(ts=...)`` between steps interpolate linearly (|q| = 1 holds only at the steps).
    """

    kicks: tuple = eqx.field(static=True)
    flows: tuple = eqx.field(static=True)
    method_order: int | None = eqx.field(static=True)

    term_structure: ClassVar = RigidBodyTerm
    interpolation_cls: ClassVar = diffrax.LocalLinearInterpolation

    def __init__(self, method="blanes_moan6", *, kicks=None, flows=None, order=None):
        if kicks is not None or flows is not None:
            if kicks is None or flows is None:
                raise ValueError("give both kicks (n + 1 coefficients) and flows (n coefficients)")
            kicks = tuple(float(k) for k in np.ravel(kicks))
            flows = tuple(float(f) for f in np.ravel(flows))
            if len(flows) < 1 or len(kicks) != len(flows) + 1:
                raise ValueError(f"kicks must have one coefficient more than flows (n + 1 and n >= 1), "
                                 f"got {len(kicks)} kicks and {len(flows)} flows")
            for name, values in (("kicks", kicks), ("flows", flows)):
                if not all(math.isfinite(v) for v in values):
                    raise ValueError(f"{name}: the coefficients must be finite")
                if abs(math.fsum(values) - 1) > _CONSISTENCY_TOLERANCE:
                    raise ValueError(f"{name}: the coefficients must add up to 1 (one step), "
                                     f"they add up to {math.fsum(values)!r}")
        else:
            if method not in METHODS:
                raise ValueError(f"unknown splitting method {method!r}; expected one of "
                                 f"{', '.join(METHODS)}, or kicks= and flows=")
            kicks, flows, order = METHODS[method]
        self.kicks = kicks
        self.flows = flows
        self.method_order = order

    def order(self, terms):
        return self.method_order

    def init(self, terms, t0, t1, y0, args):
        return None

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del solver_state, made_jump
        term, direction = _unwrap(terms)
        # A step of one body (or a few) as one kernel (frbjax._kernel): diffrax's loop then launches
        # one kernel per step for it instead of some hundred.
        y1 = one_kernel(self.advance)(term, direction * t0, direction * (t1 - t0), y0, args)
        return y1, None, dict(y0=y0, y1=y1), None, diffrax.RESULTS.successful

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def advance(self, term, t, h, y, args):
        """One step of size h (any sign) from the state y = (L, q) at time t."""
        momentum, attitude = y
        dtype = jnp.result_type(momentum, attitude)
        # diffrax's times are float64 under x64 even for a float32 state: keep the state's precision.
        t, h = jnp.asarray(t, dtype), jnp.asarray(h, dtype)
        kicks = jnp.asarray(self.kicks, dtype)
        flows = jnp.asarray(self.flows, dtype)
        # Kick i + 1 comes after the free flows 0..i: at time t + h (f_0 + ... + f_i).
        kick_times = jnp.asarray(np.cumsum(self.flows), dtype)

        def kick(momentum, attitude, coefficient, time):
            return momentum + (coefficient * h) * term.body_torque(time, attitude, args)

        if self.kicks[0] != 0:
            momentum = kick(momentum, attitude, kicks[0], t)

        def stage(state, coefficients):
            momentum, attitude = state
            flow, next_kick, time = coefficients
            momentum, attitude = free_flow(term.inertia, momentum, attitude, flow * h)
            return (kick(momentum, attitude, next_kick, t + time * h), attitude), None

        (momentum, attitude), _ = jax.lax.scan(stage, (momentum, attitude), (flows, kicks[1:], kick_times))
        return momentum.astype(dtype), attitude.astype(dtype)


# --------------------------------------------------------------------------- the lean driver


def _checked_step(dt):
    """dt if finite and > 0; ValueError when concrete, NaN (hence NaN states) when traced."""
    dt = jnp.asarray(dt)
    value = _concrete(dt)
    if value is not None:
        if dt.ndim != 0 or not (np.isfinite(value) and value > 0):
            raise ValueError(f"dt: the step must be a finite scalar > 0, got {np.asarray(value)!r}")
        return dt
    return jnp.where(jnp.isfinite(dt) & (dt > 0), dt, jnp.nan)


def _checked_state(y0, term):
    momentum, attitude = y0
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
    dtype = jnp.result_type(momentum, attitude, term.inertia, float)
    batch = jnp.broadcast_shapes(momentum.shape[:-1], attitude.shape[:-1], term.inertia.shape[:-1])
    attitude = attitude / jnp.linalg.norm(attitude, axis=-1, keepdims=True)
    return (jnp.broadcast_to(momentum, batch + (3,)).astype(dtype),
            jnp.broadcast_to(attitude, batch + (4,)).astype(dtype))


def splitting_trajectory(term, y0, *, dt, steps, t0=0.0, args=None, method="blanes_moan6"):
    r"""The states after each of ``steps`` fixed steps of a splitting method: a lean ``lax.scan``.

    Returns ``(ts, (L, q))`` with ``ts`` (steps + 1,) = t0 + n dt and L (steps + 1, ..., 3), q
    (steps + 1, ..., 4), the initial state first.  ``method`` is a name of ``METHODS`` or a
    :class:`RigidBodySplitting`; the step is the same code as ``diffrax.diffeqsolve(term,
    RigidBodySplitting(...), ...)``.  ``steps`` is a Python int (the program is compiled for it).

    Use it for many saved steps of a small system (no per-step bookkeeping of diffeqsolve) and for
    forward-mode derivatives; reverse mode through it stores every step (memory grows with ``steps``):
    for long reverse-mode runs use diffeqsolve with its ``RecursiveCheckpointAdjoint``.

    Bad input: ``dt`` <= 0 or not finite, or a non-finite or zero initial state, raise ValueError
    naming the argument when they are concrete; under jit the states are NaN instead.  The attitude
    is normalised and the state broadcast to the batch of ``term.inertia``.
    """
    solver = method if isinstance(method, RigidBodySplitting) else RigidBodySplitting(method)
    if not isinstance(term, RigidBodyTerm):
        raise ValueError(f"term must be a RigidBodyTerm, got {type(term).__name__}")
    if not isinstance(steps, (int, np.integer)) or steps < 0:
        raise ValueError(f"steps must be a Python int >= 0, got {steps!r}")
    y0 = _checked_state(y0, term)
    dtype = y0[0].dtype
    dt = _checked_step(dt).astype(dtype)
    t0 = jnp.asarray(t0, dtype)

    def trajectory(term, y0, dt, t0, args):
        def one_step(state, n):
            state = solver.advance(term, t0 + n * dt, dt, state, args)
            return state, state

        return jax.lax.scan(one_step, y0, jnp.arange(steps, dtype=dtype))[1]

    # One body (or a few): the whole loop over steps as one kernel (frbjax._kernel), the speed that
    # XLA reaches for small loops, without a process-wide flag.  Everything the loop reads is an
    # argument: a region closes over no tracer of the caller's.
    momenta, attitudes = one_kernel(trajectory)(term, y0, dt, t0, args)
    ts = t0 + dt * jnp.arange(steps + 1, dtype=dtype)
    return ts, (jnp.concatenate([y0[0][None], momenta]), jnp.concatenate([y0[1][None], attitudes]))
