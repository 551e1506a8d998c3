"""Torques that depend on the angular momentum, and the ready-made torques of frbjax.torques.

References no one here wrote, or that the method cannot fake:

- diffrax's Dopri8 on the same ODE at rtol = atol = 1e-13 (its distance to 1e-14 checked): the error
  of every splitting method falls with the step at the slope of the order it keeps;
- the damped sphere's closed form, L(t) = L(0) exp(-c t / I), q(t) a rotation about the fixed axis
  L(0) by the angle |L(0)| (1 - exp(-c t / I)) / c;
- each ready-made torque against a hand-written formula: central differences of a potential written
  with rotation matrices, the torque's formula in the space frame, scipy's axis-angle of the error
  rotation, the field's rate seen by the body by central differences along the rotation, the orbit
  against Newton's law by central differences in time.
"""

from __future__ import annotations

import functools
import re

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import frbjax
from frbjax import torques


INERTIA = np.array([1.0, 1.6, 2.3])
_Q0 = np.array([0.9, 0.3, -0.2, 0.1])
Y0 = (np.array([0.3, 0.8, 2.0]), _Q0 / np.linalg.norm(_Q0))
_TARGET = np.array([0.8, 0.2, -0.5, 0.3])
TARGET = _TARGET / np.linalg.norm(_TARGET)
DAMPING = np.array([[0.2, 0.05, 0.0], [0.05, 0.1, 0.02], [0.0, 0.02, 0.15]])

# A PD controller to TARGET with an extra damping tensor: a torque depending on q and L, affine in L.
CONTROLLED = frbjax.RigidBodyTerm(
    INERTIA,
    momentum_torque=torques.PDController(INERTIA, 0.6, 0.1, target=TARGET) + torques.LinearDamping(INERTIA, DAMPING),
)


def nonlinear_torque(t, q, L, args):
    """Quadratic-in-speed drag plus a turning body torque and an attitude spring: not affine in L."""
    omega = L / INERTIA
    return -0.2 * jnp.sqrt(1 + omega @ omega) * omega + 0.3 * jnp.stack([jnp.cos(t), 0 * t, 0 * t]) - 0.5 * q[1:]


NONLINEAR = frbjax.RigidBodyTerm(INERTIA, momentum_torque=nonlinear_torque)
TERMS = {"controlled": CONTROLLED, "nonlinear": NONLINEAR}


def state_error(y, reference):
    return float(
        max(
            np.abs(np.asarray(y[0]) - np.asarray(reference[0])).max(),
            np.abs(np.asarray(y[1]) - np.asarray(reference[1])).max(),
        )
    )


@functools.cache
def dopri8_runner(name):
    """Dopri8's final state for one term, compiled once for every final time and tolerance
    (diffeqsolve called with Python numbers compiles again for each)."""

    @jax.jit
    def run(final_time, tolerance):
        solution = diffrax.diffeqsolve(
            TERMS[name],
            diffrax.Dopri8(),
            0.0,
            final_time,
            0.01,
            Y0,
            max_steps=1_000_000,
            stepsize_controller=diffrax.PIDController(rtol=tolerance, atol=tolerance),
        )
        return solution.ys[0][-1], solution.ys[1][-1]

    return run


@functools.cache
def dopri8(name, final_time, tolerance):
    return dopri8_runner(name)(np.float64(final_time), np.float64(tolerance))


@functools.cache
def splitting_runner(name, method):
    term = TERMS[name]

    @jax.jit
    def run(step):
        solution = diffrax.diffeqsolve(term, frbjax.RigidBodySplitting(method), 0.0, 10.0, step, Y0, max_steps=10_000)
        return solution.ys[0][-1], solution.ys[1][-1]

    return run


# ------------------------------------------------------------------------------------- orders

# The orders kept with a torque that depends on L: blanes_moan6 (SRKN6a) keeps 4, its sixth order
# needing kicks that depend on q only.  Steps in the asymptotic regime, errors far above the
# reference's floor (measured 5.1e-14 for the controlled body, 4.4e-14 for the nonlinear one).
KEPT_ORDERS = {
    "leapfrog": 2,
    "strang": 2,
    "yoshida4": 4,
    "blanes_moan4": 4,
    "blanes_moan6": 4,
    "aba864": 4,
    "aba1064": 4,
}
ORDER_STEPS = {
    "leapfrog": (0.04, 0.02, 0.01),
    "strang": (0.04, 0.02, 0.01),
    "yoshida4": (0.08, 0.04, 0.02),
    "blanes_moan4": (0.2, 0.1, 0.05),
    "blanes_moan6": (0.5, 0.25, 0.125),
    "aba864": (0.2, 0.1, 0.05),
    "aba1064": (0.2, 0.1, 0.05),
}


@pytest.mark.parametrize(
    "name,method",
    [("controlled", m) for m in KEPT_ORDERS] + [("nonlinear", m) for m in ("leapfrog", "yoshida4", "blanes_moan6")],
)
def test_order_with_momentum_torques(name, method):
    """T = 10 against Dopri8 at 1e-13: slopes within 0.3 of the order kept.

    controlled (exact matrix-exponential kicks), measured slopes 2.00, 2.00, 4.00, 4.00, 3.99, 4.00
    (aba864, smallest error 1.1e-11), 4.00 (aba1064, 6.9e-12);
    nonlinear (a Runge-Kutta sub-step in each kick: Tsit5, or Dopri8 for blanes_moan6): 2.00, 4.00, 4.00.
    """
    reference = dopri8(name, 10.0, 1e-13)
    assert state_error(reference, dopri8(name, 10.0, 1e-14)) < 1e-12
    steps = np.array(ORDER_STEPS[method])
    run = splitting_runner(name, method)
    measured = np.array([state_error(run(jnp.asarray(h)), reference) for h in steps])
    assert measured.min() > 1e-12, measured  # 5.7e-12 the smallest (blanes_moan4): 100x the floor
    slope = np.polyfit(np.log(steps), np.log(measured), 1)[0]
    assert abs(slope - KEPT_ORDERS[method]) <= 0.3, (method, measured, slope)


def test_order_six_with_a_momentum_torque_free_of_momentum():
    """Gravity given as a momentum torque (it does not depend on L: a plain kick L += s tau):
    blanes_moan6 keeps order 6 on the heavy top of tests/test_splitting.py, against Dopri8 on its
    potential (measured slope 6.0)."""
    gravity = torques.UniformGravity([0.05, 0.1, 0.4], [0.0, 0.0, -1.0])
    term = frbjax.RigidBodyTerm(INERTIA, momentum_torque=gravity)
    by_potential = frbjax.RigidBodyTerm(INERTIA, potential=gravity.potential)
    solution = diffrax.diffeqsolve(
        by_potential,
        diffrax.Dopri8(),
        0.0,
        20.0,
        0.01,
        Y0,
        max_steps=100_000,
        stepsize_controller=diffrax.PIDController(rtol=1e-14, atol=1e-14),
    )
    reference = (solution.ys[0][-1], solution.ys[1][-1])
    run = jax.jit(
        lambda h: (
            diffrax.diffeqsolve(term, frbjax.RigidBodySplitting("blanes_moan6"), 0.0, 20.0, h, Y0, max_steps=1000).ys
        )
    )
    steps = np.array([0.5, 0.35, 0.25])
    measured = [state_error(tuple(y[-1] for y in run(jnp.asarray(h))), reference) for h in steps]
    slope = np.polyfit(np.log(steps), np.log(measured), 1)[0]
    assert abs(slope - 6) <= 0.3, (measured, slope)


def test_torques_free_of_momentum_kick_as_torques():
    """Gravity, the gravity gradient and a constant torque (and their sums) do not depend on L: given
    as momentum_torque, the term holds them as a torque (plain kicks, no matrix exponential), with
    the torque of their potential to rounding and the same splitting steps (measured 5.6e-17 and,
    after 20 steps, 5.7e-16); a sum with damping stays a momentum torque (the exact affine kick)."""
    gravity = torques.UniformGravity([0.05, 0.1, 0.4], [0.0, 0.0, -1.0])
    gradient = torques.GravityGradient(INERTIA, torques.CircularOrbit(3.0, 1.0))
    constant = torques.ConstantTorque([0.01, -0.02, 0.03])
    damping = torques.LinearDamping(INERTIA, 0.1)
    for torque in (gravity, gradient, constant, gravity + gradient + constant):
        assert torque.depends_on_momentum is False
    assert (gradient + damping).depends_on_momentum and damping.depends_on_momentum
    term = frbjax.RigidBodyTerm(INERTIA, momentum_torque=gravity + gradient)
    assert term.momentum_torque is None and term.torque is not None
    both = frbjax.RigidBodyTerm(
        INERTIA, potential=lambda t, q, args: gravity.potential(t, q, args) + gradient.potential(t, q, args)
    )
    with_user = frbjax.RigidBodyTerm(
        INERTIA, torque=lambda t, q, args: jnp.array([0.0, 0.0, 0.2]), momentum_torque=gradient
    )

    @jax.jit  # one program: called eagerly, each operation of the torques compiles on its own
    def torques_at(momentum, attitude):
        q = attitude / jnp.linalg.norm(attitude)
        return (
            term.body_torque(0.7, q, None, momentum),
            both.body_torque(0.7, q, None),
            with_user.body_torque(0.7, q, None),
            gradient(0.7, q, None, None) + jnp.array([0.0, 0.0, 0.2]),
        )

    torque, by_potential, user_and_gradient, by_hand = (np.asarray(x) for x in torques_at(*Y0))
    np.testing.assert_allclose(torque, by_potential, rtol=0, atol=2e-16)
    np.testing.assert_allclose(user_and_gradient, by_hand, rtol=0, atol=1e-15)
    damped = frbjax.RigidBodyTerm(INERTIA, momentum_torque=gradient + damping)
    assert damped.momentum_torque is not None and damped.linear_in_momentum
    steps = [
        jax.jit(lambda y0, term=term: frbjax.splitting_trajectory(term, y0, dt=0.1, steps=20, method="blanes_moan4"))(
            Y0
        )[1]
        for term in (term, both)
    ]
    assert state_error((steps[0][0][-1], steps[0][1][-1]), (steps[1][0][-1], steps[1][1][-1])) < 1.5e-15


# ------------------------------------------------------------------------------ the damped sphere


def test_damped_sphere_exact_damping_kick():
    """L(t) = L0 exp(-c t / I) to rounding at every step; |q| = 1 to an ulp or two; q against the
    closed-form rotation about the fixed axis (the angle's quadrature is the method's only error)."""
    moment, c = 2.0, 0.3
    inertia = np.full(3, moment)
    term = frbjax.RigidBodyTerm(inertia, momentum_torque=torques.LinearDamping(inertia, c))
    momentum0 = np.array([0.3, -0.5, 1.1])
    q0 = np.array([0.6, 0.0, 0.8, 0.0])
    ts, (momenta, attitudes) = jax.tree.map(
        np.asarray,
        jax.jit(lambda y0: frbjax.splitting_trajectory(term, y0, dt=0.1, steps=400, method="blanes_moan4"))(
            (momentum0, q0)
        ),
    )
    expected = momentum0 * np.exp(-c * ts[:, None] / moment)
    eps = np.finfo(np.float64).eps
    # Rounding only, growing with the steps (7 matrix exponentials and 6 free flows each): the
    # relative error after n steps is at most 2.8 n eps (measured: 2.77 eps after the first step, 811
    # eps after the 400 steps).
    relative = (np.abs(np.asarray(momenta) - expected) / np.abs(expected)).max(axis=-1)
    assert np.all(relative <= 3 * eps * np.maximum(np.arange(len(ts)), 1))
    assert np.abs(np.linalg.norm(np.asarray(attitudes), axis=-1) - 1).max() <= 2 * eps
    angle = np.linalg.norm(momentum0) * (1 - np.exp(-c * ts / moment)) / c
    axis = momentum0 / np.linalg.norm(momentum0)
    turned = Rotation.from_quat(q0[[1, 2, 3, 0]]) * Rotation.from_rotvec(angle[:, None] * axis)
    closed_form = turned.as_quat()[:, [3, 0, 1, 2]]
    closed_form *= np.sign(np.sum(closed_form * np.asarray(attitudes), axis=-1))[:, None]
    # Measured 2.2e-12 (compiled kernels and JAX formulas): blanes_moan4's quadrature of the decaying
    # speed.
    assert np.abs(np.asarray(attitudes) - closed_form).max() < 3.5e-12


# --------------------------------------------------------------------------- ready-made torques


def _random_states(count, seed):
    rng = np.random.default_rng(seed)
    attitudes = rng.normal(size=(count, 4))
    return rng.normal(size=(count, 3)), attitudes / np.linalg.norm(attitudes, axis=-1, keepdims=True)


def _matrix(q):
    return Rotation.from_quat(np.asarray(q)[[1, 2, 3, 0]]).as_matrix()


def _torque_by_differences(potential_of_matrix, q, epsilon=1e-5):
    """-dV(R exp(hat w))/dw at w = 0 by central differences (Rodrigues' formula through scipy)."""
    matrix = _matrix(q)
    torque = []
    for axis in np.eye(3):
        values = [
            potential_of_matrix(matrix @ Rotation.from_rotvec(sign * epsilon * axis).as_matrix()) for sign in (1, -1)
        ]
        torque.append(-(values[0] - values[1]) / (2 * epsilon))
    return np.array(torque)


def test_uniform_gravity_against_its_potential():
    centre, weight = np.array([0.05, 0.1, 0.4]), np.array([0.3, -0.2, -9.8])
    gravity = torques.UniformGravity(centre, weight)
    for momentum, q in zip(*_random_states(3, 0)):

        def potential(matrix):
            return -weight @ (matrix @ centre)  # the height of the centre of mass times the weight

        torque = np.asarray(gravity(0.0, jnp.asarray(q), jnp.asarray(momentum), None))
        np.testing.assert_allclose(torque, _torque_by_differences(potential, q), rtol=0, atol=1e-9)  # 3e-11
        assert float(gravity.potential(0.0, jnp.asarray(q), None)) == pytest.approx(potential(_matrix(q)), abs=1e-14)


def test_gravity_gradient_against_maccullagh_in_space():
    """tau = -dV/dw with V = (3 mu / 2 |r|^3) rhat . (R J R^T) rhat written in the space frame."""
    mu = 3.986e14
    orbit = torques.CircularOrbit(7.0e6, mu, inclination=0.5, phase=0.3)
    inertia = np.array([120.0, 100.0, 80.0])
    gradient = torques.GravityGradient(inertia, orbit)
    for t, (momentum, q) in zip((0.0, 1234.5, 5000.0), zip(*_random_states(3, 1))):
        position = np.asarray(orbit(t))

        def potential(matrix):
            direction = position / np.linalg.norm(position)
            space_tensor = matrix @ np.diag(inertia) @ matrix.T
            return 1.5 * mu / np.linalg.norm(position) ** 3 * direction @ space_tensor @ direction

        torque = np.asarray(gradient(t, jnp.asarray(q), jnp.asarray(momentum), None))
        numeric = _torque_by_differences(potential, q)
        np.testing.assert_allclose(torque, numeric, rtol=1e-8, atol=1e-8 * np.abs(numeric).max())  # 2e-10 rel
        assert float(gradient.potential(t, jnp.asarray(q), None)) == pytest.approx(potential(_matrix(q)), rel=1e-13)


def test_circular_orbit_obeys_newton():
    """r'' = -mu r / |r|^3 by central differences in time; |r| and the period as given."""
    mu, radius = 3.986e14, 7.0e6
    orbit = torques.CircularOrbit(radius, mu, inclination=1.1, phase=-0.4)
    step = 1.0
    for t in (0.0, 777.0, 4321.0):
        positions = [np.asarray(orbit(t + k * step)) for k in (-1, 0, 1)]
        acceleration = (positions[0] - 2 * positions[1] + positions[2]) / step**2
        np.testing.assert_allclose(acceleration, -mu * positions[1] / radius**3, rtol=1e-6)  # 1e-7 measured
        assert np.linalg.norm(positions[1]) == pytest.approx(radius, rel=1e-14)
    period = 2 * np.pi * np.sqrt(radius**3 / mu)
    np.testing.assert_allclose(np.asarray(orbit(period)), np.asarray(orbit(0.0)), atol=1e-6)


def test_eddy_current_and_damping_in_the_space_frame():
    """(M (omega x B)) x B and -D omega computed in space with M, D turned into space, turned back."""
    inertia = np.array([3.0, 2.0, 1.5])
    tensor = np.array([[2.0, 0.3, 0.1], [0.3, 1.0, -0.2], [0.1, -0.2, 1.5]])

    def field(t):
        return jnp.stack([jnp.cos(t), 0.5 + 0 * t, jnp.sin(2 * t)])

    eddy = torques.EddyCurrent(inertia, tensor, field)
    damping = torques.LinearDamping(inertia, DAMPING)
    for t, (momentum, q) in zip((0.0, 0.7, 2.0), zip(*_random_states(3, 2))):
        matrix = _matrix(q)
        omega = matrix @ (momentum / inertia)
        field_space = np.asarray(field(t))
        space = np.cross(matrix @ tensor @ matrix.T @ np.cross(omega, field_space), field_space)
        np.testing.assert_allclose(
            np.asarray(eddy(t, jnp.asarray(q), jnp.asarray(momentum), None)), matrix.T @ space, rtol=0, atol=1e-14
        )
        space = -(matrix @ DAMPING @ matrix.T) @ omega
        np.testing.assert_allclose(
            np.asarray(damping(t, jnp.asarray(q), jnp.asarray(momentum), None)), matrix.T @ space, rtol=0, atol=1e-14
        )


def test_pd_controller_against_the_axis_angle_of_the_error():
    """-K_p sin(theta/2) axis - K_d (Omega - Omega_t), axis and theta <= pi of R_t^T R (scipy)."""
    inertia = np.array([3.0, 2.0, 1.5])
    proportional, derivative = np.diag([1.0, 2.0, 0.5]), 0.3
    rate = np.array([0.01, -0.02, 0.03])
    controller = torques.PDController(inertia, proportional, derivative, target=TARGET, target_rate=rate)
    for momentum, q in zip(*_random_states(5, 3)):
        rotation_vector = Rotation.from_matrix(_matrix(TARGET).T @ _matrix(q)).as_rotvec()
        angle = np.linalg.norm(rotation_vector)
        axis = rotation_vector / angle
        expected = -proportional @ (np.sin(angle / 2) * axis) - derivative * (momentum / inertia - rate)
        for sign in (1, -1):  # q and -q are the same attitude
            torque = controller(0.0, jnp.asarray(sign * q), jnp.asarray(momentum), None)
            np.testing.assert_allclose(np.asarray(torque), expected, rtol=0, atol=1e-14)


def test_b_dot_against_the_field_rate_seen_by_the_body():
    """m = -k dB_body/dt with dB_body/dt by central differences of R(t)^T B(t) along the rotation."""
    inertia = np.array([3.0, 2.0, 1.5])
    gain = 2.5

    def field(t):
        return jnp.stack([jnp.cos(0.3 * t), jnp.sin(0.3 * t), 0.2 + 0 * t])

    b_dot = torques.BDot(inertia, gain, field)
    epsilon = 1e-5
    for t, (momentum, q) in zip((0.0, 1.3, 4.0), zip(*_random_states(3, 4))):
        omega = momentum / inertia

        def seen(s):
            matrix = _matrix(q) @ Rotation.from_rotvec(s * omega).as_matrix()  # constant Omega
            return matrix.T @ np.asarray(field(t + s))

        rate = (seen(epsilon) - seen(-epsilon)) / (2 * epsilon)
        expected = np.cross(-gain * rate, seen(0.0))
        torque = np.asarray(b_dot(t, jnp.asarray(q), jnp.asarray(momentum), None))
        np.testing.assert_allclose(torque, expected, rtol=0, atol=1e-9)  # measured 2e-11


def test_sums_and_constant_torque():
    inertia = np.array([3.0, 2.0, 1.5])
    parts = [
        torques.ConstantTorque([0.1, -0.2, 0.3]),
        torques.LinearDamping(inertia, 0.4),
        torques.EddyCurrent(inertia, 0.7, [0.0, 0.3, 1.0]),
    ]
    total = parts[0] + parts[1] + parts[2]
    assert isinstance(total, torques.SumOfTorques) and len(total.torques) == 3 and total.linear_in_momentum
    momentum, q = (x[0] for x in _random_states(1, 5))
    q, momentum = jnp.asarray(q), jnp.asarray(momentum)
    value = np.asarray(total(0.5, q, momentum, None))
    np.testing.assert_allclose(value, sum(np.asarray(p(0.5, q, momentum, None)) for p in parts), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(np.asarray(parts[0](0.0, q, momentum, None)), [0.1, -0.2, 0.3])
    mixed = torques.SumOfTorques([parts[0], lambda t, q, L, args: L])
    assert not mixed.linear_in_momentum
    assert not frbjax.RigidBodyTerm(inertia, momentum_torque=mixed).linear_in_momentum
    assert frbjax.RigidBodyTerm(inertia, momentum_torque=mixed, linear_in_momentum=True).linear_in_momentum


def test_three_kinds_of_torque_add_up():
    """potential + torque + momentum_torque: the term's torque is the sum of the three terms'."""
    gravity = torques.UniformGravity([0.05, 0.1, 0.4], [0.0, 0.0, -1.0])
    turning = lambda t, q, args: jnp.stack([jnp.sin(t), 0.2 + 0 * t, -q[1]])  # noqa: E731
    damping = torques.LinearDamping(INERTIA, DAMPING)
    together = frbjax.RigidBodyTerm(INERTIA, potential=gravity.potential, torque=turning, momentum_torque=damping)
    alone = [frbjax.RigidBodyTerm(INERTIA, potential=gravity.potential), frbjax.RigidBodyTerm(INERTIA, torque=turning)]

    @jax.jit  # one program: called eagerly, each operation of the torques compiles on its own
    def torques_at(momentum, q):
        parts = [term.body_torque(0.4, q, None) for term in alone] + [damping(0.4, q, momentum, None)]
        return together.body_torque(0.4, q, None, momentum), parts

    total, parts = torques_at(*Y0)
    expected = sum(np.asarray(part) for part in parts)
    np.testing.assert_allclose(np.asarray(total), expected, rtol=0, atol=1e-15)


def test_gradient_through_the_exact_damping_kick():
    """d L(T) / dc for a damped sphere through the matrix-exponential kicks: -T/I L0 exp(-c T / I)."""
    moment, final_time = 2.0, 3.0
    momentum0 = jnp.array([0.3, -0.5, 1.1])

    def final_momentum(c):
        term = frbjax.RigidBodyTerm(jnp.full(3, moment), momentum_torque=torques.LinearDamping(jnp.full(3, moment), c))
        solution = diffrax.diffeqsolve(
            term,
            frbjax.RigidBodySplitting("leapfrog"),
            0.0,
            final_time,
            0.1,
            (momentum0, jnp.array([1.0, 0.0, 0.0, 0.0])),
        )
        return solution.ys[0][-1]

    def final_momentum_lean(c):
        term = frbjax.RigidBodyTerm(jnp.full(3, moment), momentum_torque=torques.LinearDamping(jnp.full(3, moment), c))
        _, (momenta, _) = frbjax.splitting_trajectory(
            term, (momentum0, jnp.array([1.0, 0.0, 0.0, 0.0])), dt=0.1, steps=30, method="leapfrog"
        )
        return momenta[-1]

    c = 0.3
    expected = -final_time / moment * np.asarray(momentum0) * np.exp(-c * final_time / moment)
    gradient = jax.jit(jax.grad(lambda c: final_momentum(c).sum()))(c)
    assert float(gradient) == pytest.approx(expected.sum(), rel=1e-13)
    derivative = np.asarray(jax.jit(jax.jacfwd(final_momentum_lean))(c))
    np.testing.assert_allclose(derivative, expected, rtol=1e-13)


# ---------------------------------------------------------------------------------- bad input


def test_momentum_torque_of_the_wrong_shape():
    term = frbjax.RigidBodyTerm(INERTIA, momentum_torque=lambda t, q, L, args: q)
    message = re.escape("momentum_torque must return the body-frame torque of one body, shape (3,), got shape (4,)")
    with pytest.raises(ValueError, match=message):
        frbjax.splitting_trajectory(term, Y0, dt=0.1, steps=2)
    with pytest.raises(ValueError, match=message):
        diffrax.diffeqsolve(term, diffrax.Tsit5(), 0.0, 1.0, 0.1, Y0)


def test_momentum_torque_returning_nan():
    term = frbjax.RigidBodyTerm(INERTIA, momentum_torque=lambda t, q, L, args: jnp.log(L - 10.0))
    with pytest.raises(ValueError, match="the torque at the initial state is not finite"):
        frbjax.splitting_trajectory(term, Y0, dt=0.1, steps=2)
    # Under jit, no error can be raised: the states are NaN, never a plausible number.
    _, states = jax.jit(lambda y0: frbjax.splitting_trajectory(term, y0, dt=0.1, steps=2, method="leapfrog"))(Y0)
    assert np.all(np.isnan(np.asarray(states[0][1:])))


@pytest.mark.parametrize(
    "make",
    [
        lambda matrix: torques.LinearDamping(INERTIA, matrix),
        lambda matrix: torques.EddyCurrent(INERTIA, matrix, [0.0, 0.0, 1.0]),
        lambda matrix: torques.PDController(INERTIA, 1.0, matrix),
    ],
)
def test_tensors_must_be_positive_semidefinite(make):
    with pytest.raises(ValueError, match="symmetric positive semidefinite matrix; its smallest eigenvalue is -0.5"):
        make(np.diag([1.0, -0.5, 2.0]))
    with pytest.raises(ValueError, match="symmetric positive semidefinite matrix; it is not symmetric"):
        make(np.array([[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    with pytest.raises(ValueError, match="must be a symmetric positive semidefinite matrix; its smallest"):
        make(-1.0)
    make(np.zeros((3, 3)))  # no damping at all is allowed


def test_bad_torque_parameters():
    with pytest.raises(ValueError, match="inertia must be the three principal moments"):
        torques.LinearDamping([1.0, 2.0], 1.0)
    with pytest.raises(ValueError, match="inertia: the principal moments"):
        torques.EddyCurrent([1.0, 0.0, 2.0], 1.0, [0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="field must be a"):
        torques.BDot(INERTIA, 1.0, [0.0, 1.0])
    with pytest.raises(ValueError, match="gain must be finite and >= 0"):
        torques.BDot(INERTIA, -1.0, [0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="needs mu"):
        torques.GravityGradient(INERTIA, [7e6, 0.0, 0.0])
    with pytest.raises(ValueError, match="CircularOrbit needs a finite radius"):
        torques.CircularOrbit(-1.0, 3.986e14)
    with pytest.raises(ValueError, match="target must be a quaternion"):
        torques.PDController(INERTIA, 1.0, 1.0, target=[1.0, 0.0, 0.0])
