"""frbjax.fit_attitude on synthetic data: recovery of the normalised moments and the angular velocity.

Problems: random triaxial bodies (moments in random order in the data's body axes), some next to the
separatrix, samples at uneven times over several rotation periods, 1e-3 rad attitude noise, random
signs on the observed quaternions.

Compiling the fit dominates (see frbjax.fit, "Compilation"): every fit here has the same number of
samples (CI_SAMPLES) and starts (N_STARTS), so the whole module compiles the solver once.  The true
motions are evaluated by one jitted program (``motion``): evaluating FreeRigidBody eagerly costs
~10 s per body.  The acceptance runs (100 problems of 200 samples, and sparse asteroid-like
observations) are in benchmarks/fit_success.py, which imports ``synthetic_problem`` from here.
"""

from __future__ import annotations

import functools
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from frbjax import _quaternion as quaternion, AttitudeFit, fit_attitude, FitError, FreeRigidBody
from frbjax.fit import _attitude_residual


N_SAMPLES = 200  # the acceptance problems (benchmarks/fit_success.py)
NOISE = 1e-3
CI_SAMPLES = 64  # every fit in this module (and in the notebook): one compilation
N_STARTS = 6


@jax.jit
def motion(inertia, momentum, attitude, times):
    """(q(t), Omega(t)) of FreeRigidBody(inertia, momentum, attitude): one program per shape of times."""
    body = FreeRigidBody(inertia, momentum, attitude)
    return body.quaternion(times), body.angular_velocity(times)


def synthetic_problem(seed, n=N_SAMPLES, noise=NOISE, periods=5.0, separatrix=False, inertia=None):
    """(times, observed quaternions, true normalised moments, true Omega(0), true q(0))."""
    rng = np.random.default_rng(seed)
    if inertia is None:
        inertia = np.sort(rng.uniform(0.3, 1.0, 3))
        while np.min(np.diff(inertia)) < 0.05:  # clearly triaxial
            inertia = np.sort(rng.uniform(0.3, 1.0, 3))
    inertia = np.sort(np.asarray(inertia, float)) / np.max(inertia)
    if separatrix:
        # d = |L|^2-normalised energy 1/I2 (1 +- 1e-3), L2 = 0 at t = 0, either side.
        d = (1 + rng.choice([-1, 1]) * 1e-3) / inertia[1]
        i1, _, i3 = inertia
        l1 = np.sqrt((d - 1 / i3) / (1 / i1 - 1 / i3))
        momentum = np.array([l1, 0.0, np.sqrt(1 - l1**2)]) * rng.choice([-1, 1], 3)
    else:
        momentum = rng.normal(size=3)
        momentum /= np.linalg.norm(momentum)
    order = rng.permutation(3)  # the data's body axes: the moments in any order
    inertia, momentum = inertia[order], momentum[order]
    attitude = rng.normal(size=4)
    attitude /= np.linalg.norm(attitude)
    attitude *= np.sign(attitude[0])
    omega = momentum / inertia
    period = 2 * np.pi / np.linalg.norm(omega)
    times = np.sort(rng.uniform(0, periods * period, n))
    times[0] = 0.0
    q = np.asarray(motion(inertia, momentum, attitude, times)[0])
    perturbation = np.asarray(quaternion.exp_pure(jnp.asarray(rng.normal(scale=noise, size=(n, 3)))))
    q = np.asarray(quaternion.multiply(jnp.asarray(q), jnp.asarray(perturbation)))
    q = q * rng.choice([-1.0, 1.0], size=(n, 1))
    return times, q, inertia, omega, attitude


def errors(fit, inertia, omega):
    inertia_error = np.max(np.abs(np.asarray(fit.inertia) - inertia) / inertia)
    omega_error = np.linalg.norm(np.asarray(fit.angular_velocity) - omega) / np.linalg.norm(omega)
    return inertia_error, omega_error


# ----------------------------------------------------------------------------------- one compilation


@pytest.fixture
def fit():
    """fit_attitude at the module's sizes (one compiled program for the module)."""

    def run(times, q, **options):
        assert len(times) == CI_SAMPLES
        options.setdefault("n_starts", N_STARTS)
        return fit_attitude(times, q, **options)

    return run


@functools.cache
def problem(seed, separatrix=False):
    return synthetic_problem(seed, n=CI_SAMPLES, separatrix=separatrix)


# ------------------------------------------------------------------------------------------ tests

PROBLEMS = [(0, False), (101, True)]  # a generic body; one next to the separatrix


@pytest.mark.parametrize("seed, separatrix", PROBLEMS)
def test_recovers_moments_and_angular_velocity(fit, seed, separatrix):
    times, q, inertia, omega, attitude = problem(seed, separatrix)
    result = fit(times, q, seed=seed)
    assert isinstance(result, AttitudeFit)
    inertia_error, omega_error = errors(result, inertia, omega)
    assert bool(result.success)
    assert inertia_error < 0.01 and omega_error < 0.01, (inertia_error, omega_error)
    # The attitude at t = 0 (either sign) and the residuals at the noise level.
    assert (
        min(np.abs(np.asarray(result.attitude) - attitude).max(), np.abs(np.asarray(result.attitude) + attitude).max())
        < 0.01
    )
    rms = np.sqrt(np.mean(np.sum(np.asarray(result.residuals) ** 2, -1)))
    assert rms < 3 * NOISE * np.sqrt(3)
    assert np.max(np.asarray(result.inertia)) == pytest.approx(1.0)
    # The fitted body holds the reported state at t = 0, and its motion gives the residuals.
    body = result.body
    assert np.allclose(
        np.asarray(body.initial_angular_momentum / body.inertia),
        np.asarray(result.angular_velocity),
        rtol=1e-14,
        atol=0,
    )
    model = motion(body.inertia, body.initial_angular_momentum, body.initial_attitude, times)[0]
    expected = np.asarray(_attitude_residual(model, jnp.asarray(q)))
    assert np.allclose(np.asarray(result.residuals), expected, rtol=0, atol=1e-8)
    # The covariance: symmetric positive definite, and the errors within a few standard deviations.
    assert result.covariance.shape == (8, 8) and result.inertia_covariance.shape == (3, 3)
    assert result.residuals.shape == (CI_SAMPLES, 3) and result.start_costs.shape == (N_STARTS,)
    assert result.start_parameters.shape == (N_STARTS, result.parameters.shape[0])
    np.testing.assert_array_equal(
        np.asarray(result.start_parameters)[int(np.argmin(result.start_costs))], result.parameters
    )
    covariance = np.asarray(result.covariance)
    assert np.allclose(covariance, covariance.T) and np.all(np.linalg.eigvalsh(covariance) > 0)
    sigma = np.sqrt(np.diag(np.asarray(result.inertia_covariance)))
    assert np.all(np.abs(np.asarray(result.inertia) - inertia) <= 5 * sigma + 1e-12)


def test_time_origin_and_order_do_not_matter(fit):
    """The same data shifted in time (no sample at t = 0) and shuffled: the same motion at t = 0."""
    times, q, inertia, omega, attitude = problem(0)
    shift = 0.37 * (times[1] - times[0])
    # Observations of the same motion, at times counted from a new origin: t' = t - shift.
    shuffled = np.random.default_rng(3).permutation(CI_SAMPLES)
    result = fit(times[shuffled] - shift, q[shuffled], seed=0)
    at_shift = motion(inertia, inertia * omega, attitude, np.full(CI_SAMPLES, shift))
    expected_attitude, expected_omega = (np.asarray(a[0]) for a in at_shift)
    assert np.linalg.norm(np.asarray(result.angular_velocity) - expected_omega) < 0.01 * np.linalg.norm(omega)
    assert (
        min(
            np.abs(np.asarray(result.attitude) - expected_attitude).max(),
            np.abs(np.asarray(result.attitude) + expected_attitude).max(),
        )
        < 0.01
    )
    assert float(result.reference_time) == pytest.approx(-shift)  # the sample nearest t' = 0
    # Residuals come back in the caller's order: those of the fitted body against the data.
    body = result.body
    model = motion(body.inertia, body.initial_angular_momentum, body.initial_attitude, times[shuffled] - shift)[0]
    expected = np.asarray(_attitude_residual(model, jnp.asarray(q[shuffled])))
    assert np.allclose(np.asarray(result.residuals), expected, rtol=0, atol=1e-8)


@pytest.mark.parametrize("loss", ["cauchy"])
def test_robust_losses_with_outliers(fit, loss):
    """6 grossly wrong attitudes (random rotations): the robust loss still recovers the body (the Huber
    loss: notebooks/fit_inertia.ipynb, also run in CI)."""
    times, q, inertia, omega, _ = problem(5)
    rng = np.random.default_rng(0)
    bad = rng.choice(np.arange(1, CI_SAMPLES), 6, replace=False)
    q = q.copy()
    random = rng.normal(size=(6, 4))
    q[bad] = random / np.linalg.norm(random, axis=-1, keepdims=True)
    result = fit(times, q, loss=loss)
    inertia_error, omega_error = errors(result, inertia, omega)
    assert inertia_error < 0.01 and omega_error < 0.01, (loss, inertia_error, omega_error)
    residual = np.linalg.norm(np.asarray(result.residuals), axis=-1)
    assert np.all(residual[bad] > 10 * np.median(residual))  # the outliers stand out


def test_gyro_data(fit):
    times, q, inertia, omega, attitude = problem(6)
    rng = np.random.default_rng(1)
    gyro = np.asarray(motion(inertia, inertia * omega, attitude, times)[1])
    gyro = gyro + rng.normal(scale=1e-3, size=(CI_SAMPLES, 3))
    result = fit(times, q, angular_velocity_data=gyro, attitude_sigma=1e-3, angular_velocity_sigma=1e-3)
    inertia_error, omega_error = errors(result, inertia, omega)
    assert inertia_error < 0.01 and omega_error < 0.01
    assert np.sqrt(np.mean(np.asarray(result.angular_velocity_residuals) ** 2)) < 3e-3


def test_asteroid_sparse_noisy(fit):
    """A tumbling asteroid: moments 0.64 : 0.97 : 1, uneven, noisy (3e-3 rad) observations over six
    rotation periods (about ten per period)."""
    times, q, inertia, omega, _ = synthetic_problem(
        2024, n=CI_SAMPLES, noise=3e-3, periods=6.0, inertia=[0.64, 0.97, 1.0]
    )
    result = fit(times, q, seed=1)
    inertia_error, omega_error = errors(result, inertia, omega)
    assert inertia_error < 0.01 and omega_error < 0.01, (inertia_error, omega_error)


def _clean_problem():
    times, q, *_ = problem(0)
    return times.copy(), q.copy()


def _with_row(array, row, value):
    array = np.array(array, dtype=float)
    array[row] = value
    return array


# (argument named by the message, a fragment of it, how the clean problem is spoiled): the cases a
# user meets in telemetry (a dropped sample, a zero-filled record, a frozen clock) and misuse.
REFUSED = {
    "one NaN quaternion row": ("quaternions", "samples 7 \\(1 of 64\\)", lambda t, q: (t, _with_row(q, 7, np.nan))),
    "all-NaN quaternions": ("quaternions", "64 of 64", lambda t, q: (t, np.full_like(q, np.nan))),
    "an infinite time": ("times", "samples 3 ", lambda t, q: (_with_row(t, 3, np.inf), q)),
    "all-zero quaternions": ("quaternions", "quaternions\\[0\\] is zero", lambda t, q: (t, np.zeros_like(q))),
    "one zero quaternion": ("quaternions", "quaternions\\[5\\] is zero", lambda t, q: (t, _with_row(q, 5, 0.0))),
    "every time equal": ("times", "times\\[0\\] and times\\[1\\]", lambda t, q: (np.zeros_like(t), q)),
    "a repeated time": ("times", "times\\[2\\] and times\\[9\\]", lambda t, q: (_with_row(t, 9, t[2]), q)),
    "non-unit quaternions": ("quaternions", "unit quaternions", lambda t, q: (t, 2 * q)),
    "quaternions (N, 3)": ("quaternions", "shape", lambda t, q: (t, q[:, :3])),
    "times (N, 1)": ("times", "one-dimensional", lambda t, q: (t[:, None], q)),
    "mismatched lengths": ("quaternions", "\\(64, 4\\)", lambda t, q: (t, q[:-1])),
    "three samples": ("times", "at least 4", lambda t, q: (t[:3], q[:3])),
    "string times": ("times", "real numbers", lambda t, q: (t.astype(str), q)),
    "complex quaternions": ("quaternions", "real numbers", lambda t, q: (t, q.astype(complex))),
}


@pytest.mark.parametrize("case", REFUSED)
def test_refuses_data_it_cannot_use(case):
    """Refused before anything is compiled, naming the argument and the offending rows or entry."""
    argument, fragment, spoil = REFUSED[case]
    times, q = spoil(*_clean_problem())
    with pytest.raises(ValueError, match=argument) as error:
        fit_attitude(times, q)
    assert re.search(fragment, str(error.value)), str(error.value)


REFUSED_OPTIONS = {
    "loss": "l1",
    "inertia": "diagonal",
    "nan_policy": "drop",
    "attitude_sigma": -1.0,
    "angular_velocity_sigma": np.nan,
    "loss_scale": 0.0,
    "n_starts": 0,
    "max_steps": 1.5,
    "rtol": -1e-10,
    "seed": -3,
    "angular_velocity_data": np.zeros((5, 3)),
}


@pytest.mark.parametrize("option", REFUSED_OPTIONS)
def test_refuses_options_it_cannot_use(option):
    times, q = _clean_problem()
    with pytest.raises(ValueError, match=option):
        fit_attitude(times, q, **{option: REFUSED_OPTIONS[option]})


def test_omitted_rows_fit_as_clean_data(fit):
    """nan_policy="omit": samples with a NaN or infinite time, quaternion or gyro entry are left out,
    and the fit of the rest is the fit of the clean samples alone (the same numbers) and as accurate
    (1%, as every fit here).  The residuals keep the input's rows, NaN where a sample was left out."""
    times, q, inertia, omega, _ = synthetic_problem(11, n=CI_SAMPLES + 6)
    gyro = np.array(motion(inertia, inertia * omega, np.array([1.0, 0, 0, 0]), times)[1])  # any finite rates
    bad = np.array([0, 5, 17, 40, 41, CI_SAMPLES + 5])
    times[bad[:2]] = [np.nan, np.inf]
    q[bad[2:4], 1] = np.nan
    gyro[bad[4:], 2] = -np.inf
    kept = np.setdiff1d(np.arange(CI_SAMPLES + 6), bad)
    with pytest.raises(ValueError, match="samples 0, 5, 17, 40, 41, 69 \\(6 of 70\\)"):
        fit_attitude(times, q, angular_velocity_data=gyro, angular_velocity_sigma=1e6)
    # gyro weighted off (sigma 1e6): the rates above are not the body's, only their rows' NaNs matter.
    omitted = fit_attitude(
        times, q, angular_velocity_data=gyro, angular_velocity_sigma=1e6, nan_policy="omit", n_starts=N_STARTS
    )  # CI_SAMPLES kept: the module's compiled fit
    clean = fit(times[kept], q[kept], angular_velocity_data=gyro[kept], angular_velocity_sigma=1e6)
    np.testing.assert_array_equal(np.asarray(omitted.parameters), np.asarray(clean.parameters))
    inertia_error, omega_error = errors(omitted, inertia, omega)
    assert inertia_error < 0.01 and omega_error < 0.01, (inertia_error, omega_error)
    residuals = np.asarray(omitted.residuals)
    assert residuals.shape == (CI_SAMPLES + 6, 3)
    assert np.isnan(residuals[bad]).all() and np.array_equal(residuals[kept], np.asarray(clean.residuals))


def test_a_fit_that_does_not_converge_raises():
    """Two Levenberg-Marquardt steps cannot converge: FitError by default, carrying the unconverged
    result; ``throw=False`` returns that result, marked ``success`` False, instead."""
    times, q = _clean_problem()
    with pytest.raises(FitError, match="did not converge") as error:
        fit_attitude(times, q, n_starts=N_STARTS, max_steps=2)
    assert isinstance(error.value.result, AttitudeFit) and not bool(error.value.result.success)
    result = fit_attitude(times, q, n_starts=N_STARTS, max_steps=2, throw=False)
    assert not bool(result.success)
    np.testing.assert_array_equal(np.asarray(result.parameters), np.asarray(error.value.result.parameters))


def test_attitude_residual_ignores_quaternion_sign():
    rng = np.random.default_rng(0)
    q_model = rng.normal(size=(5, 4))
    q_model /= np.linalg.norm(q_model, axis=-1, keepdims=True)
    q_obs = rng.normal(size=(5, 4))
    q_obs /= np.linalg.norm(q_obs, axis=-1, keepdims=True)
    plus = np.asarray(_attitude_residual(jnp.asarray(q_model), jnp.asarray(q_obs)))
    minus = np.asarray(_attitude_residual(jnp.asarray(q_model), jnp.asarray(-q_obs)))
    flipped = np.asarray(_attitude_residual(jnp.asarray(-q_model), jnp.asarray(q_obs)))
    assert np.array_equal(plus, minus) and np.array_equal(plus, flipped)


def test_fitted_body_of_a_non_finite_fit_is_nan_not_an_error():
    """``AttitudeFit.body`` of a fit that ended non-finite: the NaN body (as under jit), no exception."""
    from frbjax.fit import _fitted_body

    body = _fitted_body(np.array([0.5, 0.8, 1.0]), np.array([np.nan, 0.0, 0.0]), np.array([1.0, 0, 0, 0]))
    assert np.all(np.isnan(np.asarray(body.quaternion(np.linspace(0.0, 1.0, 3)))))
    finite = _fitted_body(np.array([0.5, 0.8, 1.0]), np.array([0.1, 0.7, 0.0]), np.array([1.0, 0, 0, 0]))
    assert np.all(np.isfinite(np.asarray(finite.quaternion(np.linspace(0.0, 1.0, 3)))))


# (moments, L): a triaxial body; exactly symmetric ones with unit L 0.02 and 1e-6 off the plane of
# their equal moments (inside the band of frbjax._precession); a uniform rotation.
MODEL_BODIES = {
    "triaxial": ([0.6, 0.8, 1.0], [0.3, 0.4, 0.2]),
    "symmetric_near_plane": ([1.0, 1.0, 1.5], [0.3, 0.5, 0.02]),
    "symmetric_1e-6_off_plane": ([1.0, 1.0, 1.5], [0.3, 0.5, 1e-6]),
    "principal_axis": ([0.6, 0.8, 1.0], [0.0, 0.0, 0.7]),
}
# Largest |dJ| of the fits' model's Jacobian from the body's (entries of order 1), the same for L and q:
# on the JAX path (FRBJAX_KERNELS=jax) measured 0, 0, 1.26e-13 and 9.0e-5.  Next to the plane it is the
# expansion's derivative against the elliptic formulas', which lose about 1e-16 / (e . n)^2 = 2.5e-13
# at e . n = 0.02: the bound.  On the CPU's default path both take the flow kernels' derivatives: 0.
MODEL_JACOBIAN_DIFFERENCE = {
    "triaxial": 0.0,
    "principal_axis": 0.0,
    "symmetric_near_plane": 2.5e-13,
    "symmetric_1e-6_off_plane": 1.1e-4,
}


@functools.cache
def _model_program(fits):
    """Jitted (values, Jacobian in (I, L, q, t)) of the fits' evaluation of the state, or the body's."""
    from frbjax._body import state_with_elliptic_derivatives

    def state(inertia, momentum, attitude, times):
        body = FreeRigidBody(inertia, momentum, attitude)
        return state_with_elliptic_derivatives(body, times) if fits else body.state(times)

    return jax.jit(lambda *args: (state(*args), jax.jacfwd(state, argnums=(0, 1, 2, 3))(*args)))


@pytest.mark.parametrize("name", MODEL_BODIES)
def test_model_derivatives_are_the_bodys_except_on_exactly_symmetric_bodies(name):
    """The fits' model evaluates the motion with the elliptic formulas' own derivatives
    (frbjax._body.state_with_elliptic_derivatives): values bit for bit the body's, and the Jacobian in
    (I, L, q, t) too except for exactly symmetric bodies next to the plane of their equal moments (a
    fit's continuous parameters never are one), where it is finite and close."""
    from frbjax._body import quaternion_with_elliptic_derivatives

    inertia, momentum = (jnp.asarray(a) for a in MODEL_BODIES[name])
    arguments = (inertia, momentum, jnp.asarray([0.9, 0.1, -0.3, 0.2]), jnp.linspace(-3.0, 7.0, 11))
    (values, ours), (expected, theirs) = (_model_program(fits)(*arguments) for fits in (True, False))
    assert all(np.array_equal(a, b) for a, b in zip(jax.tree.leaves(values), jax.tree.leaves(expected)))
    assert all(np.all(np.isfinite(a)) for a in jax.tree.leaves(ours))
    difference = max(float(np.max(np.abs(a - b))) for a, b in zip(jax.tree.leaves(ours), jax.tree.leaves(theirs)))
    assert difference <= MODEL_JACOBIAN_DIFFERENCE[name], difference
    # The light-curve fit's evaluation of the attitude alone: the same values.
    body = FreeRigidBody(*arguments[:3])
    attitude = jax.jit(quaternion_with_elliptic_derivatives)(body, arguments[3])
    assert np.array_equal(attitude, jax.jit(lambda body, t: body.quaternion(t))(body, arguments[3]))
