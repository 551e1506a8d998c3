"""frbjax.fit_attitude on synthetic data: recovery of the normalised moments and the angular velocity.

Problems: random triaxial bodies (moments in random order in the data's body axes), some next to the
separatrix, 200 samples at uneven times over five rotation periods, 1e-3 rad attitude noise, random
signs on the observed quaternions.  Every fit with the same (N, n_starts) shares one compilation.
benchmarks/fit_success.py runs 100 such problems.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from frbjax import AttitudeFit, FreeRigidBody, fit_attitude
from frbjax import _quaternion as quaternion

N_SAMPLES = 200
N_STARTS = 6
NOISE = 1e-3


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
    body = FreeRigidBody(inertia, momentum, attitude)
    q = np.asarray(body.quaternion(jnp.asarray(times)))
    perturbation = np.asarray(quaternion.exp_pure(jnp.asarray(rng.normal(scale=noise, size=(n, 3)))))
    q = np.asarray(quaternion.multiply(jnp.asarray(q), jnp.asarray(perturbation)))
    q = q * rng.choice([-1.0, 1.0], size=(n, 1))
    return times, q, inertia, omega, attitude


def errors(fit, inertia, omega):
    inertia_error = np.max(np.abs(np.asarray(fit.inertia) - inertia) / inertia)
    omega_error = np.linalg.norm(np.asarray(fit.angular_velocity) - omega) / np.linalg.norm(omega)
    return inertia_error, omega_error


PROBLEMS = [(seed, False) for seed in range(7)] + [(seed, True) for seed in range(100, 103)]


@pytest.mark.parametrize("seed, separatrix", PROBLEMS)
def test_recovers_moments_and_angular_velocity(seed, separatrix):
    times, q, inertia, omega, attitude = synthetic_problem(seed, separatrix=separatrix)
    fit = fit_attitude(times, q, n_starts=N_STARTS, seed=seed)
    assert isinstance(fit, AttitudeFit)
    inertia_error, omega_error = errors(fit, inertia, omega)
    assert bool(fit.success)
    assert inertia_error < 0.01 and omega_error < 0.01, (inertia_error, omega_error)
    # The attitude at t = 0 (either sign) and the residuals at the noise level.
    assert min(np.abs(np.asarray(fit.attitude) - attitude).max(),
               np.abs(np.asarray(fit.attitude) + attitude).max()) < 0.01
    rms = np.sqrt(np.mean(np.sum(np.asarray(fit.residuals) ** 2, -1)))
    assert rms < 3 * NOISE * np.sqrt(3)
    assert np.max(np.asarray(fit.inertia)) == pytest.approx(1.0)
    body_omega = np.asarray(fit.body.angular_velocity(0.0))
    assert np.allclose(body_omega, np.asarray(fit.angular_velocity), rtol=1e-10, atol=1e-12)


def test_covariance_and_result_shapes():
    times, q, inertia, omega, _ = synthetic_problem(3)
    fit = fit_attitude(times, q, n_starts=N_STARTS)
    assert fit.covariance.shape == (8, 8) and fit.inertia_covariance.shape == (3, 3)
    assert fit.residuals.shape == (N_SAMPLES, 3)
    covariance = np.asarray(fit.covariance)
    assert np.allclose(covariance, covariance.T) and np.all(np.linalg.eigvalsh(covariance) > 0)
    # The error of the moments is within a few standard deviations of the fit's own estimate.
    sigma = np.sqrt(np.diag(np.asarray(fit.inertia_covariance)))
    assert np.all(np.abs(np.asarray(fit.inertia) - inertia) <= 5 * sigma + 1e-12)


def test_robust_losses_with_outliers():
    """10 grossly wrong attitudes (random rotations): the robust losses still recover the body."""
    times, q, inertia, omega, _ = synthetic_problem(5)
    rng = np.random.default_rng(0)
    bad = rng.choice(np.arange(1, N_SAMPLES), 10, replace=False)
    q = q.copy()
    random = rng.normal(size=(10, 4))
    q[bad] = random / np.linalg.norm(random, axis=-1, keepdims=True)
    for loss in ("huber", "cauchy"):
        fit = fit_attitude(times, q, loss=loss, n_starts=N_STARTS)
        inertia_error, omega_error = errors(fit, inertia, omega)
        assert inertia_error < 0.01 and omega_error < 0.01, (loss, inertia_error, omega_error)


def test_gyro_data():
    times, q, inertia, omega, attitude = synthetic_problem(6)
    body = FreeRigidBody(inertia, inertia * omega, attitude)
    rng = np.random.default_rng(1)
    gyro = np.asarray(body.angular_velocity(jnp.asarray(times))) + rng.normal(scale=1e-3, size=(N_SAMPLES, 3))
    fit = fit_attitude(times, q, angular_velocity_data=gyro, attitude_sigma=1e-3,
                       angular_velocity_sigma=1e-3, n_starts=N_STARTS)
    inertia_error, omega_error = errors(fit, inertia, omega)
    assert inertia_error < 0.01 and omega_error < 0.01
    assert np.sqrt(np.mean(np.asarray(fit.angular_velocity_residuals) ** 2)) < 3e-3


def test_asteroid_sparse_noisy():
    """A tumbling asteroid: moments 0.64 : 0.97 : 1, 40 uneven, noisy (3e-3 rad) observations over
    several rotation periods."""
    times, q, inertia, omega, _ = synthetic_problem(
        2024, n=40, noise=3e-3, periods=6.0, inertia=[0.64, 0.97, 1.0])
    fit = fit_attitude(times, q, n_starts=N_STARTS, seed=1)
    inertia_error, omega_error = errors(fit, inertia, omega)
    assert inertia_error < 0.01 and omega_error < 0.01, (inertia_error, omega_error)


def test_rejects_bad_input():
    with pytest.raises(ValueError):
        fit_attitude(np.zeros(5), np.zeros((5, 3)))
    with pytest.raises(ValueError):
        fit_attitude(np.arange(5.0), np.ones((5, 4)), loss="l1")
