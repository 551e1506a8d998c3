"""frbjax.fit_attitude(inertia="tensor"): the inertia tensor (up to scale) in the data's body frame.

Problems: triaxial bodies whose principal axes are tilted from the body axes (up to 20 degrees about
a random axis, moments in random order), star-tracker attitudes with 1e-4 rad noise at uneven times
over five rotation periods, optionally gyro rates.  The data are made without the tensor code path:
the motion of the principal frame (FreeRigidBody with principal moments, L_p = R^T L, q_p = q ⊗ q(R))
turned back to the body frame, q = q_p ⊗ conj(q(R)).

Every fit here has CI_SAMPLES samples and N_STARTS starts: the module compiles the tensor solver once.
The acceptance run (100 problems with and without gyro data) is benchmarks/fit_tensor_success.py, which imports
``tilted_problem`` from here.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from frbjax import _quaternion as quaternion, fit_attitude, FreeRigidBody


CI_SAMPLES = 64
N_STARTS = 6
NOISE = 1e-4


def _rotation(axis_angle):
    """Rodrigues' rotation matrix of a rotation vector (numpy; independent of frbjax)."""
    angle = np.linalg.norm(axis_angle)
    if angle == 0:
        return np.eye(3)
    k = axis_angle / angle
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def _quaternion_of(matrix):
    """Unit quaternion (w, x, y, z) of a rotation matrix with a positive trace (numpy)."""
    w = np.sqrt(1 + np.trace(matrix)) / 2
    return np.array(
        [
            w,
            (matrix[2, 1] - matrix[1, 2]) / (4 * w),
            (matrix[0, 2] - matrix[2, 0]) / (4 * w),
            (matrix[1, 0] - matrix[0, 1]) / (4 * w),
        ]
    )


@jax.jit
def principal_motion(inertia, momentum, attitude, times):
    body = FreeRigidBody(inertia, momentum, attitude)
    return body.quaternion(times), body.angular_momentum(times)


def tilted_problem(seed, n=CI_SAMPLES, noise=NOISE, periods=5.0, tilt_degrees=20.0, moments=None, gyro_noise=None):
    """(times, observed quaternions, observed rates or None, true scaled tensor, true Omega(0), true q(0)).

    The axes' rotation is kept small enough (< 20 degrees) for its quaternion formula above.
    """
    rng = np.random.default_rng(seed)
    if moments is None:
        moments = np.sort(rng.uniform(0.3, 1.0, 3))
        while np.min(np.diff(moments)) < 0.05:
            moments = np.sort(rng.uniform(0.3, 1.0, 3))
        moments = rng.permutation(moments)
    moments = np.asarray(moments, float) / np.max(moments)
    axis = rng.normal(size=3)
    axes = _rotation(axis / np.linalg.norm(axis) * np.radians(rng.uniform(0, tilt_degrees)))
    tensor = axes @ np.diag(moments) @ axes.T
    momentum = rng.normal(size=3)
    momentum /= np.linalg.norm(momentum)
    attitude = rng.normal(size=4)
    attitude *= np.sign(attitude[0]) / np.linalg.norm(attitude)
    omega = np.linalg.solve(tensor, momentum)
    times = np.sort(rng.uniform(0, periods * 2 * np.pi / np.linalg.norm(omega), n))
    times[0] = 0.0
    frame = _quaternion_of(axes)
    principal_attitude = quaternion.multiply(jnp.asarray(attitude), jnp.asarray(frame))
    q_principal, l_principal = principal_motion(moments, axes.T @ momentum, principal_attitude, times)
    q = np.asarray(quaternion.multiply(q_principal, quaternion.conjugate(jnp.asarray(frame))))
    rates = np.asarray(l_principal) / moments @ axes.T
    perturbation = np.asarray(quaternion.exp_pure(jnp.asarray(rng.normal(scale=noise, size=(n, 3)))))
    q = np.asarray(quaternion.multiply(jnp.asarray(q), jnp.asarray(perturbation)))
    q = q * rng.choice([-1.0, 1.0], size=(n, 1))
    observed_rates = None if gyro_noise is None else rates + rng.normal(scale=gyro_noise, size=rates.shape)
    return times, q, observed_rates, tensor, omega, attitude


@pytest.fixture
def fit():
    """fit_attitude(inertia="tensor") at the module's sizes (one compiled program for the module)."""

    def run(times, q, **options):
        assert len(times) == CI_SAMPLES
        options.setdefault("n_starts", N_STARTS)
        options.setdefault("attitude_sigma", NOISE)
        return fit_attitude(times, q, inertia="tensor", **options)

    return run


@functools.cache
def problem(seed, **options):
    return tilted_problem(seed, **options)


def tensor_error(result, tensor):
    return float(np.max(np.abs(np.asarray(result.inertia_tensor) - tensor)))


@pytest.mark.parametrize("seed", [0, 1])
def test_recovers_tilted_tensor(fit, seed):
    times, q, _, tensor, omega, attitude = problem(seed)
    result = fit(times, q, seed=seed)
    assert bool(result.success) and bool(result.axes_identifiable)
    assert tensor_error(result, tensor) < 1e-3, tensor_error(result, tensor)
    assert np.linalg.norm(np.asarray(result.angular_velocity) - omega) < 1e-3 * np.linalg.norm(omega)
    # The reported pieces agree: the tensor from its principal moments (largest 1) and axes.
    moments, axes = np.asarray(result.inertia), np.asarray(result.principal_axes)
    assert np.max(moments) == pytest.approx(1.0) and np.all(np.diff(moments) >= 0)
    assert np.allclose(axes @ np.diag(moments) @ axes.T, np.asarray(result.inertia_tensor), atol=1e-14)
    assert np.linalg.det(axes) == pytest.approx(1.0)
    # Errors within a few standard deviations of the reported covariance of the entries.
    sigma = np.sqrt(np.einsum("ijij->ij", np.asarray(result.inertia_tensor_covariance)))
    assert np.all(np.abs(np.asarray(result.inertia_tensor) - tensor) <= 5 * sigma + 1e-12)
    # The fitted body (built from the tensor) reproduces the data to the noise.
    model = np.asarray(result.body.quaternion(times))
    misfit = np.minimum(np.abs(model - q).max(-1), np.abs(model + q).max(-1))
    assert np.sqrt(np.mean(misfit**2)) < 5 * NOISE


def test_gyro_data(fit):
    times, q, rates, tensor, omega, _ = problem(2, gyro_noise=1e-4)
    result = fit(times, q, angular_velocity_data=rates, angular_velocity_sigma=1e-4, seed=2)
    assert bool(result.axes_identifiable)
    assert tensor_error(result, tensor) < 1e-3, tensor_error(result, tensor)
    assert np.sqrt(np.mean(np.asarray(result.angular_velocity_residuals) ** 2)) < 3e-4


def test_axisymmetric_body_is_flagged(fit):
    """An axisymmetric body (moments 0.6, 0.6, 1): the tensor is determined, the axes about the
    symmetry axis are not, and the result says so instead of presenting an angle."""
    times, q, _, tensor, _, _ = problem(3, moments=(0.6, 1.0, 0.6))
    result = fit(times, q, seed=3)
    assert tensor_error(result, tensor) < 1e-3, tensor_error(result, tensor)
    assert not bool(result.axes_identifiable)
    eigenvalues, eigenvectors = np.linalg.eigh(tensor)
    symmetry_axis = eigenvectors[:, 2]  # the distinct (largest) moment's axis
    assert abs(abs(float(np.dot(np.asarray(result.symmetry_axis), symmetry_axis))) - 1) < 1e-4
    direction = np.asarray(result.unidentified_direction)
    assert direction.shape == (11,) and np.linalg.norm(direction) == pytest.approx(1.0)


def test_triangle_inequality_on_request(fit):
    """Data of a body violating I1 + I2 >= I3 (possible for Euler's equations, not for matter): the
    ordinary fit finds it; asked to respect the inequality, the fit does."""
    times, q, _, tensor, _, _ = problem(4, moments=(0.35, 1.0, 0.45), tilt_degrees=10.0)
    free = fit(times, q, seed=4)
    assert tensor_error(free, tensor) < 1e-3
    constrained = fit(times, q, seed=4, triangle_inequality=True)
    moments = np.asarray(constrained.inertia)
    # A penalty, not a hard constraint: measured I1 + I2 - I3 = +5.7e-10.
    assert moments[0] + moments[1] >= moments[2] - 1e-8
    assert float(constrained.cost) > float(free.cost)


def test_principal_fit_reports_a_diagonal_tensor():
    from frbjax.fit import _principal_result

    result = _principal_result(np.array([0.5, 0.8, 1.0]), np.diag([1e-6, 2e-6, 0.0]))
    assert np.array_equal(result["inertia_tensor"], np.diag([0.5, 0.8, 1.0]))
    assert result["inertia_tensor_covariance"][1, 1, 1, 1] == 2e-6


def test_rejects_bad_inertia_option():
    with pytest.raises(ValueError, match="inertia"):
        fit_attitude(np.arange(5.0), np.ones((5, 4)), inertia="full")
