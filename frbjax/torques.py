r"""Ready-made torques for :class:`~frbjax.RigidBodyTerm`: gravity, gravity gradient, eddy currents,
damping, attitude control.

Each torque is a callable ``torque(t, q, L, args) -> (3,)``: the body-frame torque on one body with
attitude ``q`` (4,) (wxyz, body to space: a body vector x is x_space = R(q) x) and body angular
momentum ``L`` (3,) at time ``t``; ``args`` is not used (the parameters are the torque's fields, so
that they are traced and differentiated like any array).  Pass one, or a sum of them, as
``RigidBodyTerm(inertia, momentum_torque=...)``:

    torque = torques.GravityGradient(inertia, torques.CircularOrbit(7.0e6, 3.986e14))
    torque = torque + torques.LinearDamping(inertia, 1e-3)
    term = frbjax.RigidBodyTerm(inertia, momentum_torque=torque)

Every torque here is affine in L (``linear_in_momentum = True``), so that the splitting's kick is
exact (a matrix exponential; :class:`~frbjax.RigidBodySplitting`); those that do not depend on L at
all (``depends_on_momentum = False``: gravity, the gravity gradient, a constant torque, and their
sums) kick as a ``torque=`` does, L += s tau(t, q).  The torques that derive from a
potential (uniform gravity, gravity gradient) also give it, ``.potential(t, q, args)``, for
``RigidBodyTerm(potential=...)``: the kick is then a plain L += s tau and the splitting symplectic.

Torques that need the angular velocity Omega = I^-1 L, or the inertia itself, take the inertia of
the body they act on, the same as the term's: principal moments (3,) or an ``InertiaTensor`` of one
body (3, 3) in its body frame.  Matrices (damping,
magnetic tensor, gains) are given as a scalar (times the identity), three diagonal entries or a 3 x
3 matrix, all in the body frame.  Vectors fixed in space (a field, an orbit position) are given as a
(3,) array or as a function of time ``t -> (3,)``.
"""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._checks import check_positive, real_array
from ._inertia import InertiaTensor
from ._quaternion import as_matrix, conjugate, multiply


__all__ = [
    "AbstractTorque",
    "BDot",
    "CircularOrbit",
    "ConstantTorque",
    "EddyCurrent",
    "GravityGradient",
    "LinearDamping",
    "PDController",
    "SumOfTorques",
    "UniformGravity",
]


# ---------------------------------------------------------------------------------- parameters


def _float_array(value, name="value"):
    if _is_concrete(value):
        real_array(name, value)  # strings, objects, complex numbers: refused by name
    value = jnp.asarray(value)
    return value if jnp.issubdtype(value.dtype, jnp.floating) else value.astype(float)


def _is_concrete(value) -> bool:
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(value))


def _moments(inertia):
    """(J, J^-1) as (3, 3) matrices of one body: from principal moments (3,) or an InertiaTensor."""
    if isinstance(inertia, InertiaTensor):
        if inertia.matrix.shape != (3, 3):
            raise ValueError(
                f"inertia must be the inertia tensor of one body, shape (3, 3), got shape {tuple(inertia.matrix.shape)}"
            )
        axes, moments = inertia.principal_axes, inertia.principal_moments
        return inertia.matrix, (axes / moments[None, :]) @ axes.T
    inertia = _float_array(inertia, "inertia")
    if inertia.shape != (3,):
        raise ValueError(
            f"inertia must be the three principal moments, shape (3,), or an InertiaTensor, "
            f"got shape {tuple(inertia.shape)}"
        )
    if _is_concrete(inertia) and not (np.all(np.isfinite(inertia)) and np.all(np.asarray(inertia) > 0)):
        raise ValueError("inertia: the principal moments of inertia must be finite and > 0")
    return jnp.diag(inertia), jnp.diag(1 / inertia)


def _vector(value, name):
    value = _float_array(value, name)
    if value.shape != (3,):
        raise ValueError(f"{name} must be a (3,) vector, got shape {tuple(value.shape)}")
    if _is_concrete(value) and not np.all(np.isfinite(value)):
        raise ValueError(f"{name} must be finite")
    return value


def _positive_semidefinite(value, name):
    """A scalar, (3,) diagonal or (3, 3) matrix as a symmetric positive semidefinite (3, 3) matrix."""
    value = _float_array(value, name)
    if value.shape == ():
        matrix = value * jnp.eye(3, dtype=value.dtype)
    elif value.shape == (3,):
        matrix = jnp.diag(value)
    elif value.shape == (3, 3):
        matrix = value
    else:
        raise ValueError(
            f"{name} must be a scalar, three diagonal entries (3,) or a (3, 3) matrix, got shape {tuple(value.shape)}"
        )
    if _is_concrete(matrix):
        concrete = np.asarray(matrix, dtype=float)
        if not np.all(np.isfinite(concrete)):
            raise ValueError(f"{name} must be finite")
        scale = max(np.abs(concrete).max(), np.finfo(float).tiny)
        if np.abs(concrete - concrete.T).max() > 1e-12 * scale:
            raise ValueError(f"{name} must be a symmetric positive semidefinite matrix; it is not symmetric")
        smallest = np.linalg.eigvalsh(concrete).min()
        if smallest < -1e-12 * scale:
            raise ValueError(
                f"{name} must be a symmetric positive semidefinite matrix; its smallest eigenvalue is {smallest:.3g}"
            )
    return matrix


class _Fixed(eqx.Module):
    """A vector that does not change with time, as a function of time."""

    vector: Float[Array, 3]

    def __call__(self, t):
        return self.vector


def _function_of_time(value, name):
    if callable(value):
        return value
    return _Fixed(_vector(value, name))


def _body(q, space_vector):
    """A space vector in the body frame: R(q)^T x."""
    return as_matrix(q).T @ space_vector


# ------------------------------------------------------------------------------------- the base


class AbstractTorque(eqx.Module):
    """A body-frame torque ``torque(t, q, L, args) -> (3,)`` on one body; torques add up with ``+``.

    ``linear_in_momentum``: whether the torque is affine in L (all of this module's are), which
    :class:`~frbjax.RigidBodyTerm` reads to make the splitting's kick exact.
    ``depends_on_momentum``: whether it depends on L at all (gravity, the gravity gradient and a
    constant torque do not): a term kicks with such a torque as with ``torque=``, L += s tau(t, q),
    with no matrix exponential.
    """

    def __call__(self, t, q, L, args) -> Float[Array, 3]:
        raise NotImplementedError

    @property
    def linear_in_momentum(self) -> bool:
        return True

    @property
    def depends_on_momentum(self) -> bool:
        return True

    def __add__(self, other):
        if not isinstance(other, AbstractTorque):
            return NotImplemented
        left = self.torques if isinstance(self, SumOfTorques) else (self,)
        right = other.torques if isinstance(other, SumOfTorques) else (other,)
        return SumOfTorques(left + right)


class SumOfTorques(AbstractTorque):
    """The sum of torques (what ``a + b`` gives); affine in L when every one of them is."""

    torques: tuple

    def __init__(self, torques):
        torques = tuple(torques)
        if not torques or not all(callable(torque) for torque in torques):
            raise ValueError("SumOfTorques needs one or more torques (t, q, L, args) -> (3,)")
        self.torques = torques

    def __call__(self, t, q, L, args):
        return sum(torque(t, q, L, args) for torque in self.torques)

    @property
    def linear_in_momentum(self) -> bool:
        return all(getattr(torque, "linear_in_momentum", False) for torque in self.torques)

    @property
    def depends_on_momentum(self) -> bool:
        return any(getattr(torque, "depends_on_momentum", True) for torque in self.torques)


# ------------------------------------------------------------------------------ the torques


class ConstantTorque(AbstractTorque):
    """A torque fixed in the body (a thruster pair, a momentum wheel's constant friction): tau = c."""

    torque: Float[Array, 3]

    def __init__(self, torque):
        self.torque = _vector(torque, "torque")

    def __call__(self, t, q, L, args):
        return self.torque.astype(jnp.result_type(q, self.torque))

    @property
    def depends_on_momentum(self) -> bool:
        return False


class UniformGravity(AbstractTorque):
    r"""Uniform gravity on a body fixed at a point away from its centre of mass: the heavy top.

    With the centre of mass at ``centre_of_mass`` c from the fixed point (body frame) and the weight
    F = m g a force fixed in space (``weight``, e.g. (0, 0, -m g)), the potential energy and the
    body-frame torque are

        V(q) = -F . R(q) c,        tau = c x (R(q)^T F).

    Reference: H. Goldstein, C. Poole and J. Safko, *Classical Mechanics*, 3rd ed., Addison-Wesley
    (2002), section 5.7 (the heavy symmetrical top with one point fixed); the same top with any
    moments in E. Celledoni, F. Fassò, N. Säfström and A. Zanna, SIAM J. Sci. Comput. 30 (2008)
    2084-2112, section 5.
    """

    centre_of_mass: Float[Array, 3]
    weight: Float[Array, 3]

    def __init__(self, centre_of_mass, weight):
        self.centre_of_mass = _vector(centre_of_mass, "centre_of_mass")
        self.weight = _vector(weight, "weight")

    def __call__(self, t, q, L, args):
        return jnp.cross(self.centre_of_mass, _body(q, self.weight))

    @property
    def depends_on_momentum(self) -> bool:
        return False

    def potential(self, t, q, args):
        """V(q) = -F . R(q) c (zero with the centre of mass at the fixed point's height)."""
        return -self.weight @ (as_matrix(q) @ self.centre_of_mass)


class CircularOrbit(eqx.Module):
    r"""The position r(t) (space frame, from the attracting body's centre) on a circular orbit.

        r(t) = radius (cos u, cos i sin u, sin i sin u),    u = n t + phase,    n = sqrt(mu / radius^3),

    the orbit in the x-y plane turned by the inclination i about x.  ``rate`` is n (rad/s for SI
    units).  Reference: H. D. Curtis, *Orbital Mechanics for Engineering Students*, 3rd ed.,
    Butterworth-Heinemann (2014), section 2.9 (circular orbits).
    """

    radius: Float[Array, ""]
    rate: Float[Array, ""]
    inclination: Float[Array, ""]
    phase: Float[Array, ""]

    def __init__(self, radius, mu, *, inclination=0.0, phase=0.0):
        radius, mu = (
            jnp.asarray(_float_array(value, name), dtype=float) for name, value in (("radius", radius), ("mu", mu))
        )
        if _is_concrete((radius, mu)) and not (np.isfinite(radius) and np.isfinite(mu) and radius > 0 and mu > 0):
            raise ValueError("CircularOrbit needs a finite radius > 0 and gravitational parameter mu > 0")
        self.radius = radius
        self.rate = jnp.sqrt(mu / radius**3)
        self.inclination = jnp.asarray(inclination, dtype=float)
        self.phase = jnp.asarray(phase, dtype=float)

    def __call__(self, t):
        angle = self.rate * t + self.phase
        in_plane = jnp.sin(angle)
        return self.radius * jnp.stack(
            [jnp.cos(angle), jnp.cos(self.inclination) * in_plane, jnp.sin(self.inclination) * in_plane]
        )


class GravityGradient(AbstractTorque):
    r"""The gravity-gradient torque of a point mass (gravitational parameter ``mu``) at the origin.

    With the body's centre of mass at ``position(t)`` r (space frame) and n = R(q)^T r / |r| the unit
    vector to it from the attracting body, in the body frame, J the inertia tensor (diag(inertia)
    for principal moments):

        tau = (3 mu / |r|^3) n x (J n),        V(q) = (3 mu / (2 |r|^3)) n . J n

    (MacCullagh's approximation, the attitude-dependent part; the torque is -dV/dw).  ``position``
    is a function of time (a :class:`CircularOrbit`, or your own orbit) or a fixed (3,) vector.

    Reference: F. L. Markley and J. L. Crassidis, *Fundamentals of Spacecraft Attitude Determination
    and Control*, Springer (2014), section 3.3.6.1; P. C. Hughes, *Spacecraft Attitude Dynamics*,
    Wiley (1986), section 8.1.
    """

    inertia: Float[Array, "3 3"]
    inverse_inertia: Float[Array, "3 3"]
    position: Callable
    mu: Float[Array, ""]

    def __init__(self, inertia, position, mu=None):
        if mu is None:
            if not isinstance(position, CircularOrbit):
                raise ValueError(
                    "GravityGradient needs mu (the gravitational parameter) unless the position is a CircularOrbit"
                )
            mu = position.rate**2 * position.radius**3
        self.inertia, self.inverse_inertia = _moments(inertia)
        self.position = _function_of_time(position, "position")
        self.mu = jnp.asarray(_float_array(mu, "mu"), dtype=float)
        if _is_concrete(self.mu):
            check_positive("mu", self.mu)

    def _direction_and_strength(self, t, q):
        position = _body(q, self.position(t))
        distance = jnp.linalg.norm(position)
        return position / distance, 3 * self.mu / distance**3

    def __call__(self, t, q, L, args):
        direction, strength = self._direction_and_strength(t, q)
        return strength * jnp.cross(direction, self.inertia @ direction)

    @property
    def depends_on_momentum(self) -> bool:
        return False

    def potential(self, t, q, args):
        """V(t, q) = (3 mu / (2 |r|^3)) n . J n."""
        direction, strength = self._direction_and_strength(t, q)
        return 0.5 * strength * (direction @ (self.inertia @ direction))


class LinearDamping(AbstractTorque):
    r"""Viscous damping of the rotation: tau = -D Omega = -D L / I, D symmetric positive semidefinite.

    The torque of Rayleigh's dissipation function F = Omega . D Omega / 2 (tau = -dF/dOmega); the
    kinetic energy falls at the rate 2 F.  A sphere (moments I) with D = c 1 spins down as
    L(t) = L(0) exp(-c t / I).  ``damping``: a scalar, three diagonal entries or a (3, 3) matrix, in
    the body frame; a matrix that is not symmetric positive semidefinite raises ValueError.

    Reference: H. Goldstein, C. Poole and J. Safko, *Classical Mechanics*, 3rd ed. (2002), section
    1.5 (Rayleigh's dissipation function).
    """

    inertia: Float[Array, "3 3"]
    inverse_inertia: Float[Array, "3 3"]
    damping: Float[Array, "3 3"]

    def __init__(self, inertia, damping):
        self.inertia, self.inverse_inertia = _moments(inertia)
        self.damping = _positive_semidefinite(damping, "damping")

    def __call__(self, t, q, L, args):
        return -self.damping @ (self.inverse_inertia @ L)


class EddyCurrent(AbstractTorque):
    r"""The eddy-current torque on a conducting body spinning in a magnetic field.

        tau = (M (Omega x B)) x B,        B = R(q)^T B_space(t),

    with M the body's magnetic tensor (symmetric positive semidefinite, body frame; for a thin
    spherical shell of radius a, thickness d and conductivity sigma, M = (2 pi / 3) sigma a^4 d times
    the identity) and B the field in the body frame.  For an isotropic M = m 1 the torque is
    -m |B|^2 Omega_perp: the spin about axes across the field decays, the spin along it does not.
    ``field``: a function of time giving the field in space, or a fixed (3,) vector.

    Reference: N. Ortiz Gómez and S. J. I. Walker, *Eddy currents applied to de-tumbling of space
    debris: analysis and validation of approximate proposed methods*, Acta Astronautica 114 (2015)
    34-53 (the magnetic tensor and this torque).
    """

    inertia: Float[Array, "3 3"]
    inverse_inertia: Float[Array, "3 3"]
    tensor: Float[Array, "3 3"]
    field: Callable

    def __init__(self, inertia, tensor, field):
        self.inertia, self.inverse_inertia = _moments(inertia)
        self.tensor = _positive_semidefinite(tensor, "tensor (the magnetic tensor)")
        self.field = _function_of_time(field, "field")

    def __call__(self, t, q, L, args):
        field = _body(q, self.field(t))
        return jnp.cross(self.tensor @ jnp.cross(self.inverse_inertia @ L, field), field)


class PDController(AbstractTorque):
    r"""A proportional-derivative attitude controller (quaternion feedback) to a target attitude.

        tau = -K_p s vec(q_e) - K_d (Omega - Omega_target),     q_e = conj(q_target) ⊗ q,

    with s = sign of q_e's scalar part (+1 at 0: the shorter way round) and vec(q_e) = sin(theta/2)
    times the axis of the rotation from the target to the body, in the body frame.  ``proportional``
    K_p and ``derivative`` K_d: scalars, three diagonal entries or (3, 3) symmetric positive
    semidefinite matrices.  With Omega_target = 0 and K_p, K_d > 0 the target is asymptotically
    stable.

    Reference: B. Wie, H. Weiss and A. Arapostathis, *Quaternion feedback regulator for spacecraft
    eigenaxis rotations*, J. Guidance, Control, and Dynamics 12(3) (1989) 375-380; B. Wie, *Space
    Vehicle Dynamics and Control*, 2nd ed., AIAA (2008), section 7.3.
    """

    inertia: Float[Array, "3 3"]
    inverse_inertia: Float[Array, "3 3"]
    proportional: Float[Array, "3 3"]
    derivative: Float[Array, "3 3"]
    target: Float[Array, 4]
    target_rate: Float[Array, 3]

    def __init__(self, inertia, proportional, derivative, *, target=(1.0, 0.0, 0.0, 0.0), target_rate=(0.0, 0.0, 0.0)):
        self.inertia, self.inverse_inertia = _moments(inertia)
        self.proportional = _positive_semidefinite(proportional, "proportional (the gain K_p)")
        self.derivative = _positive_semidefinite(derivative, "derivative (the gain K_d)")
        target = jnp.asarray(_float_array(target, "target"), dtype=float)
        if target.shape != (4,):
            raise ValueError(f"target must be a quaternion (4,), got shape {tuple(target.shape)}")
        if _is_concrete(target) and not (np.all(np.isfinite(target)) and np.linalg.norm(target) > 0):
            raise ValueError("target must be a finite non-zero quaternion")
        self.target = target / jnp.linalg.norm(target)
        self.target_rate = _vector(target_rate, "target_rate")

    def __call__(self, t, q, L, args):
        error = multiply(conjugate(self.target), q)
        # The sign is piecewise constant: no derivative flows through it.
        side = jnp.where(error[0] >= 0, 1.0, -1.0)
        rate_error = self.inverse_inertia @ L - self.target_rate
        return -side * (self.proportional @ error[1:]) - self.derivative @ rate_error


class BDot(AbstractTorque):
    r"""The B-dot detumbling law: a magnetic dipole against the change of the field seen by the body.

        m = -k dB/dt,    tau = m x B,    B = R(q)^T B_space(t),
        dB/dt = R(q)^T dB_space/dt - Omega x B   (the rate a body-fixed magnetometer sees),

    with gain k >= 0; dB_space/dt by forward-mode differentiation of ``field`` (zero for a fixed
    vector).  In a field fixed in space tau = k (Omega x B) x B = -k |B|^2 Omega_perp.

    Reference: A. C. Stickler and K. T. Alfriend, *Elementary magnetic attitude control system*,
    J. Spacecraft and Rockets 13(5) (1976) 282-287; F. L. Markley and J. L. Crassidis,
    *Fundamentals of Spacecraft Attitude Determination and Control*, Springer (2014), section 7.5.
    """

    inertia: Float[Array, "3 3"]
    inverse_inertia: Float[Array, "3 3"]
    gain: Float[Array, ""]
    field: Callable

    def __init__(self, inertia, gain, field):
        self.inertia, self.inverse_inertia = _moments(inertia)
        gain = jnp.asarray(_float_array(gain, "gain"), dtype=float)
        if gain.shape != ():
            raise ValueError(f"gain must be a scalar, got shape {tuple(gain.shape)}")
        if _is_concrete(gain) and not (np.isfinite(gain) and gain >= 0):
            raise ValueError("gain must be finite and >= 0")
        self.gain = gain
        self.field = _function_of_time(field, "field")

    def __call__(self, t, q, L, args):
        t = jnp.asarray(t, dtype=jnp.result_type(t, q))
        space_field, space_rate = jax.jvp(self.field, (t,), (jnp.ones_like(t),))
        matrix_transposed = as_matrix(q).T
        field = matrix_transposed @ space_field
        seen_rate = matrix_transposed @ space_rate - jnp.cross(self.inverse_inertia @ L, field)
        return jnp.cross(-self.gain * seen_rate, field)
