"""Torqued rigid bodies by splitting (frbjax.RigidBodyTerm, RigidBodySplitting, splitting_trajectory).

References no one here wrote, or that the method cannot fake:

- diffrax's Dopri8 on the same ODE (dL/dt = L x Omega + tau, dq/dt = q (0, Omega)/2) at tight
  tolerances: the error of every method falls with the step at the slope of its order;
- the Fortran output of CALGO 903 example 1 (tests/data/calgo903/out_example1.dat), all 10,000 steps;
- invariants the method cannot fake: |q| = 1, the vertical component of the spatial angular momentum
  of a heavy top (the rotation about gravity is a symmetry), energy error bounded over long times
  (where a Runge-Kutta method drifts), time reversibility of the symmetric methods;
- central differences (Richardson-extrapolated, float64) of the integration for the derivatives.

The heavy top: principal moments (1, 1.6, 2.3), weight 1 along -z, centre of mass chi = (0.05, 0.1,
0.4) in the body; V(q) = weight (R(q) chi)_z.
"""

from __future__ import annotations

import functools
import pathlib
import re

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import frbjax
from frbjax import _calgo903 as calgo


REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
DATA = REPOSITORY / "tests" / "data" / "calgo903"

INERTIA = np.array([1.0, 1.6, 2.3])
ARGS = {"weight": 1.0, "chi": np.array([0.05, 0.1, 0.4])}
_Q0 = np.array([0.9, 0.3, -0.2, 0.1])
Y0 = (np.array([0.3, 0.8, 2.0]), _Q0 / np.linalg.norm(_Q0))
ORDERS = {"leapfrog": 2, "strang": 2, "yoshida4": 4, "blanes_moan4": 4, "blanes_moan6": 6, "aba864": 4, "aba1064": 4}


def heavy_top_potential(t, q, args):
    """weight (R(q) chi)_z, the third row of R(q) written out: each kick of a compiled method traces
    the potential, and the row alone traces in half the time of the whole matrix."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    row = jnp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)
    return args["weight"] * (row @ args["chi"])


TERM = frbjax.RigidBodyTerm(INERTIA, potential=heavy_top_potential)


def state_error(y, reference):
    return float(
        max(
            np.abs(np.asarray(y[0]) - np.asarray(reference[0])).max(),
            np.abs(np.asarray(y[1]) - np.asarray(reference[1])).max(),
        )
    )


# One compiled program per solver, shared by the tests: everything but the solver and the shapes is an
# argument (compiling the free flow takes seconds; the number of steps varies at run time).  The times
# are passed as float64 arrays: a weakly typed scalar (a Python float) and a float64 one are different
# signatures, and each would compile the solver again.
MAX_STEPS = 50_010


@functools.cache
def runner(solver):
    @jax.jit
    def run(y0, args, t0, t1, step):
        solution = diffrax.diffeqsolve(
            TERM, solver, t0, t1, step, y0, args=args, saveat=diffrax.SaveAt(steps=True), max_steps=MAX_STEPS
        )
        return solution.ts, solution.ys, solution.stats["num_steps"]

    return run


def solve(method, t1, step, y0=Y0, args=ARGS, t0=0.0):
    """(ts, (L, q)) after each step from t0 to t1 (``method``: a name or a diffrax solver)."""
    solver = frbjax.RigidBodySplitting(method) if isinstance(method, str) else method
    ts, ys, count = runner(solver)(y0, args, *(np.float64(x) for x in (t0, t1, step)))
    count = int(count)  # sliced in NumPy: a slice of a JAX array compiles once per length
    return np.asarray(ts)[:count], (np.asarray(ys[0])[:count], np.asarray(ys[1])[:count])


def final(method, t1, step, **kwargs):
    _, (momenta, attitudes) = solve(method, t1, step, **kwargs)
    return momenta[-1], attitudes[-1]


@jax.jit
def _dopri8_final_state(final_time, tolerance, weight):
    solution = diffrax.diffeqsolve(
        TERM,
        diffrax.Dopri8(),
        0.0,
        final_time,
        0.01,
        Y0,
        args=dict(ARGS, weight=weight),
        max_steps=1_000_000,
        stepsize_controller=diffrax.PIDController(rtol=tolerance, atol=tolerance),
    )
    return solution.ys[0][-1], solution.ys[1][-1]


@functools.cache
def dopri8(final_time, tolerance, weight=ARGS["weight"]):
    """The reference state at ``final_time``: one compiled program for every time, tolerance and weight
    (diffeqsolve called with Python numbers compiles again for each)."""
    return _dopri8_final_state(*(np.float64(x) for x in (final_time, tolerance, weight)))


def errors(method, steps, final_time, reference):
    return np.array([state_error(final(method, final_time, h), reference) for h in steps])


# ------------------------------------------------------------------------------------- orders

# Steps where the error lies well above the reference's uncertainty and in the asymptotic regime.
ORDER_STEPS = {
    "leapfrog": (0.04, 0.02, 0.01),
    "strang": (0.04, 0.02, 0.01),
    "yoshida4": (0.08, 0.04, 0.02),
    "blanes_moan4": (0.2, 0.1, 0.05),
    "blanes_moan6": (0.5, 0.35, 0.25),
    "aba864": (0.2, 0.1, 0.05),
    "aba1064": (0.2, 0.1, 0.05),
}


@pytest.mark.parametrize("method", ORDERS)
def test_order_against_dopri8(method):
    """T = 20: the error against Dopri8 at 1e-14 falls at the slope of the order (within 0.3).

    Measured for the ABA methods (their classical order 4 at a weight that is no perturbation):
    slopes 4.02 (aba864) and 4.01 (aba1064); at T = 100 halving 0.2 divides by 2^3.99 and 2^4.00."""
    reference = dopri8(20.0, 1e-14)
    # The reference is good to ~2e-13 (against Dopri8 at 1e-13), far below the errors measured.
    assert state_error(dopri8(20.0, 1e-13), reference) < 1e-12
    steps = np.array(ORDER_STEPS[method])
    measured = errors(method, steps, 20.0, reference)
    assert measured.min() > 1e-12
    slope = np.polyfit(np.log(steps), np.log(measured), 1)[0]
    assert abs(slope - ORDERS[method]) <= 0.3, (method, measured, slope)


# (h, h/2) at T = 100.  Dopri8 at 1e-13 is itself good to ~3.5e-11 there (against 1e-14), which is the
# size of blanes_moan6's error at h = 0.25 (measured 2.4e-9 at 0.5, 7.8e-11 at 0.25).
LONG_STEPS = {
    "leapfrog": 0.02,
    "strang": 0.02,
    "yoshida4": 0.08,
    "blanes_moan4": 0.2,
    "blanes_moan6": 0.5,
    "aba864": 0.2,
    "aba1064": 0.2,
}


@pytest.mark.parametrize("method", ORDERS)
def test_agreement_with_dopri8_at_t100(method):
    """T = 100, Dopri8 at rtol = atol = 1e-13: halving the step divides the distance by 2^order
    (within 2^0.3), down to the reference's own error (twice its distance from Dopri8 at 1e-14)."""
    reference = dopri8(100.0, 1e-13)
    uncertainty = state_error(reference, dopri8(100.0, 1e-14))
    assert uncertainty < 1e-10
    step, order = LONG_STEPS[method], ORDERS[method]
    coarse, fine = errors(method, [step, step / 2], 100.0, reference)
    assert coarse > 1e-9
    assert coarse * 2.0 ** -(order + 0.3) <= fine <= coarse * 2.0 ** -(order - 0.3) + 2 * uncertainty, (
        method,
        coarse,
        fine,
        uncertainty,
    )


@pytest.mark.parametrize("method", ["aba864", "aba1064"])
def test_near_integrable_error_is_second_order_in_the_torque(method):
    """A light top (weight eps): the ABA methods' error is O(eps h^8 + eps^2 h^6 + eps^3 h^4)
    (Blanes et al. 2013), so at eps = 0.01 it falls at slope 6 with the step and dividing eps by 10
    divides it by about 100.  A method of order 4 for any torque has an eps h^4 term: its error falls
    at slope 4 and in proportion to eps (measured for blanes_moan4: slopes 4.20, 4.25, ratio 10.0).

    Measured at T = 20, steps (1, 0.8, 0.63): slopes 5.87, 6.11 (aba864) and 5.91, 6.08 (aba1064);
    error ratios between eps = 0.01 and 0.001 at h = 1: 128 and 104, with the reference good to
    1.3e-13 and the errors at eps = 0.001 2.6e-12 and more.
    """
    measured = {}
    for weight, steps in ((0.01, (1.0, 0.8, 0.63)), (0.001, (1.0,))):
        reference = dopri8(20.0, 1e-14, weight)
        measured[weight] = np.array(
            [state_error(final(method, 20.0, h, args=dict(ARGS, weight=weight)), reference) for h in steps]
        )
    assert measured[0.001][0] > 2e-12, measured
    slope = np.polyfit(np.log([1.0, 0.8, 0.63]), np.log(measured[0.01]), 1)[0]
    assert abs(slope - 6) <= 0.3, (method, measured, slope)
    assert measured[0.01][0] / measured[0.001][0] > 60, measured


# ------------------------------------------------------------------------------ CALGO example 1


def example1_problem():
    problem = calgo.read_input(DATA / "init_example1.dat")
    return problem, calgo.read_output(DATA / "out_example1.dat", problem.layout)


def test_calgo903_example1_all_steps_through_diffeqsolve():
    """The named blanes_moan6 in diffeqsolve, a potential written here: out_example1.dat to 3e-10.

    Measured 1.51e-10 over the 10,000 steps (gfortran itself reproduces the file to 2.3e-10: the
    difference is rounding amplified by the motion over the run; 7e-13 after 1000 steps).
    """
    problem, expected = example1_problem()
    u0 = jnp.asarray(problem["u0"])

    def potential(t, q, u0):  # V(Q) = u0 . Q e3: the kick adds h (u2, -u1, 0) with u = Q^T u0
        return u0 @ frbjax.quaternion_to_matrix(q)[:, 2]

    term = frbjax.RigidBodyTerm(problem["I"], potential=potential)

    @jax.jit  # one program (called eagerly, the conversions around diffeqsolve compile one by one)
    def run(momentum, matrix, u0):
        y0 = (momentum, frbjax.quaternion_from_matrix(matrix))
        solution = diffrax.diffeqsolve(
            term,
            frbjax.RigidBodySplitting("blanes_moan6"),
            0.0,
            problem["T"],
            jnp.asarray(problem.step),
            y0,
            args=u0,
            saveat=diffrax.SaveAt(steps=True),
            max_steps=problem.steps,
        )
        return solution.ts, solution.ys[0], frbjax.quaternion_to_matrix(solution.ys[1])

    times, momenta, matrices = (np.asarray(x) for x in run(problem["Pi"], problem["Q"].reshape(3, 3).T, u0))
    assert momenta.shape == (problem.steps, 3)
    np.testing.assert_allclose(times, expected.time[1:], rtol=0, atol=1e-9)
    difference = max(np.abs(momenta - expected.momentum[1:]).max(), np.abs(matrices - expected.attitude[1:]).max())
    assert difference <= 3e-10


def test_calgo903_example1_all_steps_through_the_cli_path():
    """frbjax run's example 1 (the file's coefficients, splitting_trajectory): measured 2.05e-10."""
    problem, expected = example1_problem()
    trajectory = calgo.solve(problem)
    assert len(trajectory.time) == problem.steps + 1
    difference = max(
        np.abs(trajectory.momentum - expected.momentum).max(), np.abs(trajectory.attitude - expected.attitude).max()
    )
    assert difference <= 3e-10


# ---------------------------------------------------------------------------------- invariants


def test_unit_quaternion_and_vertical_momentum():
    """|q| = 1 to a few ulp at every step; the spatial L_z of the heavy top to roundoff x steps."""
    _, (momenta, attitudes) = solve("blanes_moan4", 100.0, 0.05)
    steps = len(momenta)
    assert steps == 2000
    eps = np.finfo(np.float64).eps
    assert np.abs(np.linalg.norm(attitudes, axis=-1) - 1).max() <= 4 * eps
    vertical = np.einsum("nj,nj->n", np.asarray(frbjax.quaternion_to_matrix(attitudes))[:, 2], momenta)
    initial = np.asarray(frbjax.quaternion_to_matrix(Y0[1]))[2] @ Y0[0]
    # |L| ~ 2.2: the drift measured is 3.0e-14 over the 2000 steps (12,000 free flows); |q| - 1: 2.2e-16.
    assert np.abs(vertical - initial).max() <= eps * steps * abs(initial)


def test_float32():
    """float32 in, float32 out: |q| = 1 to a few float32 ulp; the motion follows float64's."""
    y32 = tuple(x.astype(np.float32) for x in Y0)
    term32 = frbjax.RigidBodyTerm(INERTIA.astype(np.float32), potential=heavy_top_potential)
    args32 = jax.tree_util.tree_map(lambda x: np.asarray(x, np.float32), ARGS)
    _, single = jax.jit(
        lambda y0, args: frbjax.splitting_trajectory(term32, y0, dt=0.05, steps=2000, args=args, method="blanes_moan4")
    )(y32, args32)
    single = tuple(np.asarray(x) for x in single)
    assert single[0].dtype == np.float32 and single[1].dtype == np.float32
    norms = np.linalg.norm(np.asarray(single[1], np.float64), axis=-1)
    assert np.abs(norms - 1).max() <= 4 * np.finfo(np.float32).eps
    momenta, attitudes = solve("blanes_moan4", 100.0, 0.05)[1]
    # Over the first 200 steps (T = 10, 1200 free flows) measured 2.2e-5 (float32 eps 1.2e-7); later
    # the top's own sensitivity to its initial state amplifies float32's rounding (6e-3 at T = 100).
    assert state_error((single[0][1:201], single[1][1:201]), (momenta[:200], attitudes[:200])) < 6e-5
    # diffeqsolve keeps float32 given float32 times (diffrax promotes the state to the times' dtype).
    times = [np.float32(x) for x in (0.0, 10.0, 0.05)]
    solution = diffrax.diffeqsolve(
        term32, frbjax.RigidBodySplitting("blanes_moan4"), *times, y32, args=args32, max_steps=250
    )
    ends = tuple(np.asarray(x)[-1] for x in solution.ys)
    assert ends[0].dtype == np.float32 and ends[1].dtype == np.float32
    assert state_error(ends, (momenta[199], attitudes[199])) < 6e-5


def test_energy_bounded_where_tsit5_drifts():
    """50,000 steps of 0.1 (T = 5000): the energy error of blanes_moan4 over the last tenth stays
    within 2x the first tenth's (measured 1.24x: 4.1e-9 then 5.1e-9 with the compiled kernels, 0.98x
    with the JAX formulas), while Tsit5 at the same step, as accurate at the start (3.3e-9), drifts
    (measured 22x: 7.2e-8)."""
    energy = jax.jit(lambda y: TERM.energy(0.0, y, ARGS))  # eagerly, each operation compiles on its own
    energy0 = float(energy(Y0))
    ratios = {}
    for method in ("blanes_moan4", diffrax.Tsit5()):
        _, states = solve(method, 5000.0, 0.1)
        assert len(states[0]) == 50_000
        error = np.abs(np.asarray(energy(states)) - energy0)
        ratios[str(method)] = error[-5000:].max() / error[:5000].max()
    splitting, runge_kutta = ratios.values()
    assert splitting <= 2, ratios
    assert runge_kutta >= 5, ratios


@pytest.mark.parametrize("method", ["leapfrog", "blanes_moan6"])
def test_time_reversible(method):
    """A symmetric method run back from T returns to the initial state (to roundoff)."""
    end = final(method, 10.0, 0.1)
    assert state_error(end, Y0) > 0.1
    back = final(method, 0.0, -0.1, y0=end, t0=10.0)
    assert state_error(back, Y0) < 3e-13  # measured 1.4e-14 (leapfrog), 8.3e-14 (blanes_moan6)


def test_no_torque_is_the_free_motion():
    """Zero weight: the splitting is the exact free motion, and Tsit5 on the term agrees."""
    exact = frbjax.FreeRigidBody(INERTIA, Y0[0], Y0[1])
    expected = (exact.angular_momentum(3.0), exact.quaternion(3.0))
    weightless = dict(ARGS, weight=0.0)
    # Measured 4.6e-16 and 8.9e-16 (Tsit5 at 0.1: 7.8e-11, at 0.3: 2.5e-8: its order 5).
    assert state_error(final("leapfrog", 3.0, 0.5, args=weightless), expected) < 3e-15
    assert state_error(final(diffrax.Tsit5(), 3.0, 0.01, args=weightless), expected) < 5e-15


def test_torque_of_the_potential():
    """tau = -dV/dw for a small rotation Q exp(hat(w)) (central differences), and equal to the heavy
    top's torque written by hand, -weight chi x (Q^T e_z)."""
    q = Y0[1]
    torque, up = (np.asarray(x) for x in jax.jit(_torque_and_up)(q))
    epsilon = 1e-6
    numeric = []
    for axis in np.eye(3):
        values = [float(_potential_turned(q, _rotation(sign * epsilon * axis))) for sign in (1, -1)]
        numeric.append(-(values[0] - values[1]) / (2 * epsilon))
    np.testing.assert_allclose(torque, numeric, rtol=0, atol=5e-11)  # measured 1.1e-11
    np.testing.assert_allclose(torque, -ARGS["weight"] * np.cross(ARGS["chi"], up), rtol=0, atol=1e-16)


def _torque_and_up(q):
    """The term's torque at q and e_z in the body frame."""
    return TERM.body_torque(0.0, q, ARGS), frbjax.quaternion_to_matrix(q)[2]


@jax.jit  # one program for the six turned attitudes (eagerly, each operation compiles on its own)
def _potential_turned(q, rotation):
    """V at the attitude Q rotation, Q the matrix of q."""
    return heavy_top_potential(0.0, frbjax.quaternion_from_matrix(frbjax.quaternion_to_matrix(q) @ rotation), ARGS)


def _rotation(vector):
    """exp(hat(vector)) by Rodrigues' formula."""
    angle = np.linalg.norm(vector)
    axis = vector / angle
    hat = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * hat + (1 - np.cos(angle)) * hat @ hat


def test_time_dependent_torque_keeps_the_order():
    """A body-frame torque that turns with time: Yoshida's order 4 holds against Dopri8 (the kicks see
    the time advanced by the free flows; kicks at the step's start would give order 1)."""

    def torque(t, q, args):
        return 0.3 * jnp.stack([jnp.cos(2 * t), jnp.sin(2 * t), 0.5 + 0 * t]) - args * q[1:]

    term = frbjax.RigidBodyTerm(INERTIA, torque=torque)
    reference = diffrax.diffeqsolve(
        term,
        diffrax.Dopri8(),
        0.0,
        5.0,
        0.01,
        Y0,
        args=0.1,
        max_steps=100_000,
        stepsize_controller=diffrax.PIDController(rtol=1e-13, atol=1e-13),
    )
    reference = (np.asarray(reference.ys[0])[-1], np.asarray(reference.ys[1])[-1])
    run = jax.jit(
        lambda h: tuple(
            y[-1]
            for y in diffrax.diffeqsolve(
                term, frbjax.RigidBodySplitting("yoshida4"), 0.0, 5.0, h, Y0, args=0.1, max_steps=10_000
            ).ys
        )
    )
    measured = [state_error(run(jnp.asarray(h)), reference) for h in (0.1, 0.05)]
    assert abs(np.log2(measured[0] / measured[1]) - 4) <= 0.3, measured


# ------------------------------------------------------------------------------------ batches


def test_batch_of_bodies_and_vmap():
    """Leading dimensions: each body of a (2, 2) batch moves as it does alone; vmap agrees."""
    rng = np.random.default_rng(3)
    momenta = rng.normal(size=(2, 2, 3))
    attitudes = rng.normal(size=(2, 2, 4))
    attitudes /= np.linalg.norm(attitudes, axis=-1, keepdims=True)
    _, batched = jax.jit(
        lambda y0: frbjax.splitting_trajectory(TERM, y0, dt=0.1, steps=20, args=ARGS, method="leapfrog")
    )((momenta, attitudes))
    batched_momenta, batched_attitudes = (np.asarray(x) for x in batched)
    assert batched_momenta.shape == (21, 2, 2, 3) and batched_attitudes.shape == (21, 2, 2, 4)
    _, alone = solve("leapfrog", 2.0, 0.1, y0=(momenta[1, 0], attitudes[1, 0]))
    assert state_error((batched_momenta[1:, 1, 0], batched_attitudes[1:, 1, 0]), alone) < 3e-15  # 8.9e-16
    run = runner(frbjax.RigidBodySplitting("leapfrog"))
    _, mapped, _ = jax.vmap(run, in_axes=(0, None, None, None, None))(
        (momenta.reshape(4, 3), attitudes.reshape(4, 4)), ARGS, 0.0, 2.0, 0.1
    )
    mapped = [np.asarray(x) for x in mapped]
    assert (
        state_error(
            (mapped[0][:, 19], mapped[1][:, 19]),
            (batched_momenta[-1].reshape(4, 3), batched_attitudes[-1].reshape(4, 4)),
        )
        < 1e-14
    )  # 2.7e-15


@pytest.mark.parametrize("method", ["aba1064", "strang", "blanes_moan4"])
def test_saving_every_few_steps_joins_the_free_flows(method):
    """save_every = 10: the saved states are those of every step (aba1064 and strang join the free
    flows at the steps between, blanes_moan4 starts with a kick and steps as before), to rounding
    carried by the heavy top over 100 steps: measured 1.4e-14 (aba1064), 2.8e-14 (strang), 0
    (blanes_moan4), where the methods err by 1.4e-9, 1.7e-3 and 5.3e-9.  The last state alone against
    diffeqsolve's: 6.3e-14, 3.2e-14, 5.4e-15 (every step saved: 4.9e-14, 3.8e-15, 5.4e-15: diffrax
    advances the time by sums, the scan by t0 + n dt)."""
    ts, every = jax.tree.map(
        np.asarray,
        jax.jit(lambda y0: frbjax.splitting_trajectory(TERM, y0, dt=0.1, steps=100, args=ARGS, method=method))(Y0),
    )
    ts_saved, saved = jax.tree.map(
        np.asarray,
        jax.jit(
            lambda y0: frbjax.splitting_trajectory(TERM, y0, dt=0.1, steps=100, args=ARGS, method=method, save_every=10)
        )(Y0),
    )
    assert saved[0].shape == (11, 3) and saved[1].shape == (11, 4)
    np.testing.assert_allclose(ts_saved, ts[::10], rtol=1e-15)
    assert state_error(saved, (every[0][::10], every[1][::10])) < 1e-13
    # The last state alone (save_every = steps), against diffeqsolve's step.
    _, last = jax.tree.map(
        np.asarray,
        frbjax.splitting_trajectory(TERM, Y0, dt=0.1, steps=100, args=ARGS, method=method, save_every=100),
    )
    assert last[0].shape == (2, 3)
    assert state_error((last[0][-1], last[1][-1]), final(method, 10.0, 0.1)) < 1.5e-13


def test_bad_save_every():
    for save_every in (0, 3, 2.0):
        with pytest.raises(ValueError, match="save_every must be a Python int >= 1 that divides steps"):
            frbjax.splitting_trajectory(TERM, Y0, dt=0.1, steps=10, args=ARGS, save_every=save_every)


def _saved_states_errors(methods, cases, bodies, jitted):
    """{case: the largest difference between the states saved every few steps and the same rows of
    every step}, one body eager or ``bodies`` under jit."""
    args = {"weight": 1.0, "chi": np.array([0.05, 0.1, 0.4])}
    term = frbjax.RigidBodyTerm(np.array([1.0, 1.6, 2.3]), potential=heavy_top_potential)
    rng = np.random.default_rng(1)
    attitudes = rng.normal(size=(bodies, 4))
    y0 = (rng.normal(size=(bodies, 3)), attitudes / np.linalg.norm(attitudes, axis=-1, keepdims=True))
    y0 = jax.tree.map(lambda x: x[0], y0) if bodies == 1 else y0

    def trajectory(method, steps, save_every):
        def run(y0):
            return frbjax.splitting_trajectory(
                term, y0, dt=0.1, steps=steps, args=args, method=method, save_every=save_every
            )[1]

        return [np.asarray(x) for x in (jax.jit(run) if jitted else run)(y0)]

    errors = {}
    for method in methods:
        # Every step of the longest case: the first steps of a trajectory are those of a shorter one.
        every = trajectory(method, max(steps for steps, _ in cases), 1)
        for steps, save_every in cases:
            saved = trajectory(method, steps, save_every)
            rows = [x[: steps + 1 : save_every] for x in every]
            finite = all(np.isfinite(x).all() for x in saved)
            errors[f"{method} {steps}/{save_every}"] = (
                max(float(np.abs(x - y).max()) for x, y in zip(saved, rows)) if finite else float("inf")
            )
        if bodies == 1 and not jitted:
            # The solver's own step, called eagerly outside diffeqsolve, against the first saved step.
            solver = frbjax.RigidBodySplitting(method)
            step = solver.step(term, 0.0, 0.1, y0, args, solver.init(term, 0.0, 0.1, y0, args), False)[0]
            errors[f"{method} step"] = max(float(np.abs(np.asarray(x) - y[1]).max()) for x, y in zip(step, every))
    return errors


@pytest.mark.parametrize(
    "bodies, jitted, methods, cases",
    [
        (1, False, ("leapfrog", "strang", "yoshida4", "blanes_moan4"), ((1, 1), (4, 2))),
        (1, False, ("blanes_moan6", "aba864", "aba1064"), ((1, 1), (4, 2))),
        (100, True, ("leapfrog",), ((1, 1), (4, 2), (10, 5))),
        (100, True, ("aba1064",), ((1, 1), (4, 2), (10, 5))),
    ],
    ids=[
        "one body eager, 2nd and 4th order",
        "one body eager, 6th order and aba",
        "100 bodies jit, leapfrog",
        "100 bodies jit, aba1064",
    ],
)
def test_saved_states_compile_for_every_method(bodies, jitted, methods, cases):
    """Every method compiles and saves the states of every step (one step, every 2nd of 4, and for
    100 bodies every 5th of 10): one body called eagerly and 100 bodies under jit.  One step is one
    block (steps == save_every), every 2nd of 4 the loop over blocks of several steps: every 5th of
    10 is a loop of the same form, left out for one body (about 2.5 s of compiling per method).
    Measured: the saved states equal the rows of save_every = 1 to 1.1e-15 (one body) and 4.4e-15
    (100 bodies), 0 for the methods that join no free flows; a larger matrix (7 methods x (steps,
    save_every) in (1, 1) (2, 1) (2, 2) (4, 2) (6, 3) (10, 5) (10, 10) (12, 4) x eager and jit, one
    body, and leapfrog's for 100 bodies: 144 cases), to 2.1e-15.  One body eager also calls each
    method's ``RigidBodySplitting.step`` on its own."""
    errors = _saved_states_errors(methods, cases, bodies, jitted)
    assert len(errors) == len(methods) * (len(cases) + (not jitted))
    assert max(errors.values()) < 1e-13, errors


# ---------------------------------------------------------------------------------- gradients


def _final_value(inertia, momentum, attitude, chi, step, steps=1000):
    """A scalar of the state after ``steps`` leapfrog steps: what the derivatives are taken of."""
    term = frbjax.RigidBodyTerm(inertia, potential=heavy_top_potential)
    args = {"weight": 1.0, "chi": chi}
    solution = diffrax.diffeqsolve(
        term,
        frbjax.RigidBodySplitting("leapfrog"),
        0.0,
        steps * step,
        step,
        (momentum, attitude),
        args=args,
        max_steps=steps + 10,
    )
    momentum, attitude = solution.ys[0][-1], solution.ys[1][-1]
    return momentum @ jnp.array([0.3, -0.5, 0.7]) + attitude @ jnp.array([0.2, 0.4, -0.1, 0.6])


def _central_difference(function, x, direction, epsilon):
    """Central differences D at eps, eps/2, eps/4, Richardson-extrapolated twice: error O(eps^6), so
    that eps can be large enough for the values' rounding (a thousand steps') to stay small."""

    def difference(e):
        return (function(x + e * direction) - function(x - e * direction)) / (2 * e)

    whole, half, quarter = difference(epsilon), difference(epsilon / 2), difference(epsilon / 4)
    first, second = (4 * half - whole) / 3, (4 * quarter - half) / 3
    return (16 * second - first) / 15


def test_gradients_through_1000_steps():
    """Reverse mode (diffeqsolve, RecursiveCheckpointAdjoint) and forward mode (splitting_trajectory)
    against Richardson-extrapolated central differences, in every input: moments, initial L and q,
    the potential's parameter chi, the step."""
    # The step a float64 array, not a weakly typed scalar: the shifted steps of the differences are
    # float64, and the values would otherwise compile twice.
    inputs = [jnp.asarray(x) for x in (INERTIA, Y0[0], Y0[1], ARGS["chi"], np.float64(0.01))]
    value = jax.jit(_final_value)
    gradients = jax.jit(jax.grad(_final_value, argnums=(0, 1, 2, 3, 4)))(*inputs)
    rng = np.random.default_rng(0)
    for index, gradient in enumerate(gradients):
        direction = rng.normal(size=np.shape(inputs[index]))
        direction = direction / np.linalg.norm(direction) if direction.ndim else np.asarray(1.0)

        def along(x, index=index):
            changed = list(inputs)
            changed[index] = x
            return float(value(*changed))

        numeric = _central_difference(along, inputs[index], direction, 2e-3 if index != 4 else 5e-5)
        # Measured on both paths of the motion (kernel, JAX): |difference| <= 1.1e-10 (moments, L, q,
        # chi; derivatives 0.12 to 8.2) and 1.1e-9 (kernel) and 1.5e-9 (JAX) for the step (derivative
        # -813, 2e-12 relative): the differences' own error.  The step's eps balances their rounding
        # against their truncation (left after extrapolation: 9.6e-9 at 1e-4, 6.8e-7 at 2e-4, as
        # eps^6): at 2e-5 the rounding of the thousand steps' values gave 1.0e-8 on the kernel's free
        # flow, 1.9e-9 on the JAX formulas' (the same gradient on both to 2e-14).
        np.testing.assert_allclose(np.sum(np.asarray(gradient) * direction), numeric, rtol=1e-11, atol=2e-10)

    # Forward mode through the lean scan: the same directional derivative in chi.
    def final_lean(chi):
        _, (momenta, attitudes) = frbjax.splitting_trajectory(
            frbjax.RigidBodyTerm(inputs[0], potential=heavy_top_potential),
            (inputs[1], inputs[2]),
            dt=0.01,
            steps=1000,
            args={"weight": 1.0, "chi": chi},
            method="leapfrog",
        )
        return momenta[-1] @ jnp.array([0.3, -0.5, 0.7]) + attitudes[-1] @ jnp.array([0.2, 0.4, -0.1, 0.6])

    direction = jnp.array([0.6, 0.0, -0.8])
    _, tangent = jax.jit(lambda chi: jax.jvp(final_lean, (chi,), (direction,)))(inputs[3])
    np.testing.assert_allclose(float(tangent), float(np.sum(gradients[3] * direction)), rtol=1e-10)


# ---------------------------------------------------------------------------------- bad input


def test_potential_must_return_a_scalar():
    term = frbjax.RigidBodyTerm(INERTIA, potential=lambda t, q, args: q[1:])
    with pytest.raises(ValueError, match="potential must return a scalar"):
        frbjax.splitting_trajectory(term, Y0, dt=0.1, steps=2)
    with pytest.raises(ValueError, match="potential must return a scalar"):
        jax.jit(lambda y: diffrax.diffeqsolve(term, frbjax.RigidBodySplitting(), 0.0, 1.0, 0.1, y).ys)(Y0)


def test_torque_must_have_shape_3():
    term = frbjax.RigidBodyTerm(INERTIA, torque=lambda t, q, args: q)
    with pytest.raises(
        ValueError, match=re.escape("torque must return the body-frame torque of one body, shape (3,), got shape (4,)")
    ):
        frbjax.splitting_trajectory(term, Y0, dt=0.1, steps=2)


three_steps = jax.jit(
    lambda y0, step: frbjax.splitting_trajectory(TERM, y0, dt=step, steps=3, args=ARGS, method="leapfrog")
)


@pytest.mark.parametrize("step", [0.0, -0.1, np.nan, np.inf])
def test_bad_step(step):
    with pytest.raises(ValueError, match="dt: the step must be a finite scalar > 0"):
        frbjax.splitting_trajectory(TERM, Y0, dt=step, steps=3, args=ARGS)
    _, states = jax.tree.map(np.asarray, three_steps(Y0, step))
    assert np.all(np.isnan(states[0][1:])) and np.all(np.isnan(states[1][1:]))


@pytest.mark.parametrize("which", [0, 1])
def test_non_finite_state(which):
    y0 = [np.array(x) for x in Y0]
    y0[which][1] = np.nan
    with pytest.raises(ValueError, match=re.escape(f"y0[{which}]")):
        frbjax.splitting_trajectory(TERM, tuple(y0), dt=0.1, steps=3, args=ARGS)
    _, states = jax.tree.map(np.asarray, three_steps(tuple(y0), 0.1))
    assert np.all(np.isnan(states[0][1:])) and np.all(np.isnan(states[1][1:]))
    solved = final("leapfrog", 0.3, 0.1, y0=tuple(y0))
    assert np.all(np.isnan(solved[0])) and np.all(np.isnan(solved[1]))


def test_bad_term_and_method():
    with pytest.raises(ValueError, match="at least one of potential"):
        frbjax.RigidBodyTerm(INERTIA)
    with pytest.raises(ValueError, match=re.escape("momentum_torque must be a function (t, q, L, args)")):
        frbjax.RigidBodyTerm(INERTIA, momentum_torque=np.ones(3))
    with pytest.raises(ValueError, match="kick_solver must be an explicit diffrax Runge-Kutta solver"):
        frbjax.RigidBodySplitting("leapfrog", kick_solver=diffrax.Euler())
    with pytest.raises(ValueError, match="inertia"):
        frbjax.RigidBodyTerm([1.0, -2.0, 3.0], potential=heavy_top_potential)
    with pytest.raises(ValueError, match="unknown splitting method 'rk4'"):
        frbjax.RigidBodySplitting("rk4")
    with pytest.raises(ValueError, match="flows: the coefficients must add up to 1"):
        frbjax.RigidBodySplitting(kicks=[0.5, 0.5], flows=[0.9])
    with pytest.raises(ValueError, match="one coefficient more"):
        frbjax.RigidBodySplitting(kicks=[0.5, 0.5], flows=[0.5, 0.5])
    with pytest.raises(RuntimeError, match="error estimates"):
        diffrax.diffeqsolve(
            TERM,
            frbjax.RigidBodySplitting(),
            0.0,
            1.0,
            0.1,
            Y0,
            args=ARGS,
            stepsize_controller=diffrax.PIDController(rtol=1e-6, atol=1e-6),
        )


def test_user_coefficients():
    """Yoshida's triple jump written out by the user is the named yoshida4 (the CLI's example 1 runs
    the file's own coefficient lists: test_calgo903_example1_all_steps_through_the_cli_path)."""
    w1 = 1 / (2 - 2 ** (1 / 3))
    w0 = 1 - 2 * w1
    mine = frbjax.RigidBodySplitting(kicks=[w1 / 2, (w0 + w1) / 2, (w0 + w1) / 2, w1 / 2], flows=[w1, w0, w1])
    named = frbjax.RigidBodySplitting("yoshida4")
    np.testing.assert_allclose(mine.kicks, named.kicks, rtol=0, atol=1e-15)
    np.testing.assert_allclose(mine.flows, named.flows, rtol=0, atol=1e-15)
    assert named.order(None) == 4 and mine.order(None) is None


def test_matrix_helpers_round_trip():
    rng = np.random.default_rng(1)
    q = rng.normal(size=(5, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    matrices = np.asarray(jax.jit(frbjax.quaternion_to_matrix)(q))
    np.testing.assert_allclose(
        np.einsum("nij,nkj->nik", matrices, matrices), np.broadcast_to(np.eye(3), (5, 3, 3)), atol=1e-15
    )
    back = np.asarray(jax.jit(frbjax.quaternion_from_matrix)(matrices))
    np.testing.assert_allclose(np.abs(np.einsum("ni,ni->n", back, q)), 1, atol=1e-15)
