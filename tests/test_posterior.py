"""frbjax.posterior.attitude_posterior: refused input, recovery of a known body, and a small
simulation-based calibration (Talts et al. 2018).

Every posterior here has the same sizes (40 attitudes, CHAINS chains of WARMUP + DRAWS steps), so
the module compiles fit_attitude's solver and the sampler once (about 5 s and 19 s on two loaded
cores); each further posterior runs in about 2 s (fit 0.1 s, 4 x 200 NUTS steps).  The synthetic
data come from FreeRigidBody (one jitted program, ``motion``) with isotropic Gaussian rotation
noise: q_k = q(t_k) exp(n_k / 2), n_k ~ N(0, NOISE^2 I), each with a random sign.  The full
calibration (100+ data sets) is benchmarks/posterior_calibration.py, which imports
``calibration_ranks`` from here.
"""

from __future__ import annotations

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import numpyro.distributions as dist
import pytest

from frbjax import _quaternion as quaternion, FreeRigidBody
from frbjax.posterior import (
    attitude_posterior,
    AttitudePosterior,
    IsotropicRotation,
    PosteriorWarning,
    TriangleLogUniform,
)


N_SAMPLES = 40
NOISE = 1e-3
CHAINS, WARMUP, DRAWS = 4, 100, 100
# The calibration's data sets (CI size) and the thinning of each posterior's draws for the ranks.
CALIBRATION_SETS = 20
THINNING = 4
# The calibration's prior (narrow, so that every data set is a clearly triaxial, well-sampled body),
# of the default prior's kinds (the sampler compiled for the recovery test serves it): log-ratios
# uniform within +-0.15 of those of moments (0.6, 0.8, 1) (far inside the triangle inequality),
# angular velocity at t = 0 normal about (0.4, 0.3, 0.8) rad/s with standard deviation 0.1, any attitude.
PRIOR_LOG_RATIOS = (math.log(0.8 / 0.6), math.log(1.0 / 0.6))
PRIOR_LOG_RATIO_HALF_WIDTH = 0.15
PRIOR_RATE = (0.4, 0.3, 0.8)
PRIOR_RATE_SCALE = 0.1
# 40 fixed uneven times over about three rotation periods (2 pi / 0.94 s each), t = 0 first.
TIMES = np.concatenate([[0.0], np.sort(np.random.default_rng(2018).uniform(0.0, 20.0, N_SAMPLES - 1))])


def calibration_prior():
    return {
        "log_inertia_ratios": TriangleLogUniform(
            np.asarray(PRIOR_LOG_RATIOS) - PRIOR_LOG_RATIO_HALF_WIDTH,
            np.asarray(PRIOR_LOG_RATIOS) + PRIOR_LOG_RATIO_HALF_WIDTH,
        ),
        "angular_velocity": dist.Normal(jnp.asarray(PRIOR_RATE), jnp.full(3, PRIOR_RATE_SCALE)).to_event(1),
        "attitude": IsotropicRotation(),
    }


@jax.jit
def motion(inertia, momentum, attitude, times):
    """(q(t), Omega(t)) of FreeRigidBody(inertia, momentum, attitude): one program per shape of times."""
    body = FreeRigidBody(inertia, momentum, attitude)
    return body.quaternion(times), body.angular_velocity(times)


def observed(inertia, omega, attitude, times, rng, noise=NOISE):
    """Noisy attitudes of the body (moments ``inertia``, Omega(0) ``omega``, q(0) ``attitude``)."""
    q = np.asarray(motion(jnp.asarray(inertia), jnp.asarray(inertia * omega), jnp.asarray(attitude), times)[0])
    perturbation = np.asarray(quaternion.exp_pure(jnp.asarray(rng.normal(scale=noise, size=(len(times), 3)))))
    q = np.asarray(quaternion.multiply(jnp.asarray(q), jnp.asarray(perturbation)))
    return q * rng.choice([-1.0, 1.0], size=(len(times), 1))


def posterior(times, q, **options):
    options = dict(dict(num_chains=CHAINS, num_warmup=WARMUP, num_samples=DRAWS, progress=False), **options)
    return attitude_posterior(times, q, attitude_sigma=NOISE, **options)


# ----------------------------------------------------------------------------------- bad input


def test_bad_input_refused():
    """Each refused before any fit or sampling (the data: the first 8 of 40 attitudes, whose motion
    program the other tests share; 8 times of their own compiled one more), except a prior that
    excludes the data, which only the fit (compiled for the other tests) can tell."""
    rng = np.random.default_rng(0)
    times = TIMES[:8]
    q40 = observed(np.array([0.6, 0.8, 1.0]), np.array(PRIOR_RATE), np.array([1.0, 0.0, 0.0, 0.0]), TIMES, rng)
    q = q40[:8]
    cases = [
        (dict(attitude_sigma=0.0), "attitude_sigma"),
        (dict(attitude_sigma=-1e-3), "attitude_sigma"),
        (dict(attitude_sigma=1e-3, angular_velocity_data=np.zeros((8, 3)), angular_velocity_sigma=0.0), "angular"),
        (dict(attitude_sigma=1e-3, angular_velocity_data=np.zeros((8, 3))), "angular_velocity_sigma"),
        (dict(attitude_sigma=1e-3, num_chains=0), "num_chains"),
        (dict(attitude_sigma=1e-3, num_samples=2), "num_samples"),
        (dict(attitude_sigma=1e-3, num_warmup=-1), "num_warmup"),
        (dict(attitude_sigma=1e-3, inertia="diagonal"), "inertia"),
        (dict(attitude_sigma=1e-3, chain_method="parallel"), "chain_method"),
        (dict(attitude_sigma=1e-3, prior={"moments": dist.Normal(0, 1)}), "prior"),
        (dict(attitude_sigma=1e-3, prior={"angular_velocity": dist.Normal(jnp.zeros(2), 1)}), "prior"),
        (dict(attitude_sigma=1e-3, prior={"attitude": "isotropic"}), "prior"),
        (dict(attitude_sigma=1e-3, initial=np.zeros(8)), "initial"),
    ]
    for options, name in cases:
        with pytest.raises(ValueError, match=name):
            attitude_posterior(times, q, **options)
    # A prior of moments (1, e^2 to e^3, e^2 to e^3), far from the data's (0.6, 0.8, 1) (40 samples:
    # the fit compiled for the other tests).
    with pytest.raises(ValueError, match="prior excludes"):
        posterior(TIMES, q40, prior={"log_inertia_ratios": TriangleLogUniform(2.0, 3.0)})
    # The data's checks are fit_attitude's.
    with pytest.raises(ValueError, match="quaternions"):
        attitude_posterior(times, q[:, :3], attitude_sigma=1e-3)
    with pytest.raises(ValueError, match="quaternions"):
        attitude_posterior(times, 2 * q, attitude_sigma=1e-3)
    with pytest.raises(ValueError, match="times"):
        attitude_posterior(times[:7], q, attitude_sigma=1e-3)


# ----------------------------------------------------------------------------------- recovery


def test_recovery_of_a_triaxial_body():
    """A physical triaxial body (moments 0.55 : 0.8 : 1 in the order 0.8, 1, 0.55) under the default
    prior: its inertia ratios and angular velocity at t = 0 inside the posterior's 99% central
    intervals, the chains converged (split R-hat < 1.01, no divergences), and, the posterior being
    Gaussian here, its standard deviations within 15% of fit_attitude's for the known noise (the
    Monte Carlo error of a standard deviation from 400 draws, bulk ESS about 400, is 3.5%; measured:
    0.93 to 1.08)."""
    rng = np.random.default_rng(7)
    inertia = np.array([0.8, 1.0, 0.55])
    momentum = rng.normal(size=3)
    omega = momentum / np.linalg.norm(momentum) / inertia
    attitude = rng.normal(size=4)
    attitude = attitude / np.linalg.norm(attitude) * np.sign(attitude[0])
    q = observed(inertia, omega, attitude, TIMES, rng)
    with warnings.catch_warnings():
        warnings.simplefilter("error", PosteriorWarning)
        result = posterior(TIMES, q)
    assert isinstance(result, AttitudePosterior)
    size = CHAINS * DRAWS
    assert result.inertia.shape == (size, 3) and result.angular_velocity.shape == (size, 3)
    assert result.attitude.shape == (size, 4) and result.parameters.shape == (size, 8)
    assert np.all(np.asarray(result.attitude[:, 0]) >= 0)
    assert np.allclose(np.max(np.asarray(result.inertia), axis=1), 1.0)
    assert float(np.max(result.r_hat)) < 1.01
    assert int(np.sum(result.divergences)) == 0
    truths = {f"I_{i + 1}": inertia[i] for i in range(3)} | {f"omega0_{i + 1}": omega[i] for i in range(3)}
    for name, truth in truths.items():
        draws = result.quantities()[name]
        low, high = np.quantile(draws, [0.005, 0.995])
        assert low <= truth <= high, (name, truth, low, high)
    # The attitude at t = 0: the posterior mean's rotation from the truth within 5 posterior standard
    # deviations of the rotation vector (its norm: sqrt(3) of them).
    mean_attitude = np.mean(np.asarray(result.attitude), axis=0)
    error = quaternion.multiply(quaternion.conjugate(jnp.asarray(attitude)), jnp.asarray(mean_attitude))
    spread = np.max(np.std(np.asarray(result.parameters[:, 5:8]), axis=0))
    assert 2 * float(np.linalg.norm(error[1:])) < 5 * math.sqrt(3) * spread
    # fit_attitude's covariance is (J^T J)^-1 s^2 with s^2 the residuals' variance; with the noise
    # known (J weighted by 1 / NOISE), (J^T J)^-1: its s^2 = 2 cost / (3 N - 8) divided out.
    variance = 2 * float(result.fit.cost) / (3 * N_SAMPLES - 8)
    fit_sd = np.sqrt(np.diag(np.asarray(result.fit.covariance)) / variance)
    ratio = np.std(np.asarray(result.parameters), axis=0) / fit_sd
    assert np.all(np.abs(ratio - 1) < 0.15), ratio
    # A short-axis mode body: every draw says so.
    energy_gap = np.sum(inertia * omega**2 * (inertia - 0.8))
    expected = "long_axis" if energy_gap < 0 else "short_axis"
    assert result.mode_probabilities()[expected] == 1.0
    summary = result.summary()
    assert set(summary) >= set(truths) | set(result.parameter_names)
    assert "r_hat" in str(summary)


def test_two_modes_next_to_the_separatrix():
    """A body 1.4e-4 from the separatrix on the long-axis side (moments 0.6 : 0.8 : 1, Omega(0) =
    (0.6, 0.05, 0.4645), 2 E I2 / |L|^2 = 1.00014): with 10 mrad of noise the data cannot tell the
    modes apart and the posterior holds both (measured: 18.5% short-axis, 81.5% long-axis, R-hat
    1.001: the chains cross the separatrix, a surface inside one connected posterior); with 1 mrad
    they can, and every draw is in long-axis mode.  The module's sampler program serves both (1.3 s
    each)."""
    moments, omega = np.array([0.6, 0.8, 1.0]), np.array([0.6, 0.05, 0.4645])
    probabilities = {}
    for noise in (1e-2, 1e-3):
        q = observed(moments, omega, np.array([1.0, 0.0, 0.0, 0.0]), TIMES, np.random.default_rng(5), noise=noise)
        with warnings.catch_warnings():
            warnings.simplefilter("error", PosteriorWarning)
            result = attitude_posterior(
                TIMES, q, attitude_sigma=noise, num_chains=CHAINS, num_warmup=WARMUP, num_samples=DRAWS, progress=False
            )
        probabilities[noise] = result.mode_probabilities()
    assert 0.05 < probabilities[1e-2]["short_axis"] < 0.5 < probabilities[1e-2]["long_axis"], probabilities
    assert probabilities[1e-3]["long_axis"] == 1.0, probabilities


def test_chains_start_in_the_fits_runner_up_basins():
    """Chains 1, 2, ... start at the fit's distinct runner-up basins: converged starts within
    ``_MODE_COST_GAP`` of the fit's cost and more than ``_MODE_SEPARATION`` of its standard
    deviations from it and from each other.  The fit's starts here all end in one basin (so does
    every calibration data set below: measured, none has a runner-up); three made-up ones are put
    beside them: a distinct basin 3 above the fit's cost (kept), the same basin again (dropped as a
    duplicate), and a basin 50 above (dropped: no mass worth a chain).  No sampling."""
    import equinox as eqx

    from frbjax import fit_attitude
    from frbjax.posterior import _attitude

    rng = np.random.default_rng(4)
    q = observed(np.array([0.6, 0.8, 1.0]), np.array(PRIOR_RATE), np.array([1.0, 0.0, 0.0, 0.0]), TIMES, rng)
    fit = fit_attitude(TIMES, q, attitude_sigma=NOISE, triangle_inequality=False)
    assert _attitude._runner_up_modes(fit, False) == []
    sigma = np.sqrt(np.diag(np.asarray(fit.covariance)))
    best = np.asarray(fit.parameters)
    other = best + 40 * sigma * np.array([0, 0, 1, -1, 0, 0, 0, 0])
    made_up = np.stack([other, other + 0.1 * sigma, best + 30 * sigma * np.eye(8)[1]])
    cost = float(fit.cost)
    fit = eqx.tree_at(
        lambda f: (f.start_parameters, f.start_costs, f.start_success),
        fit,
        (
            jnp.concatenate([fit.start_parameters, jnp.asarray(made_up)]),
            jnp.concatenate([fit.start_costs, jnp.asarray([cost + 3, cost + 3.5, cost + 50])]),
            jnp.concatenate([fit.start_success, jnp.ones(3, bool)]),
        ),
    )
    modes = _attitude._runner_up_modes(fit, False)
    assert len(modes) == 1 and np.allclose(modes[0], other)
    center, chol = _attitude._whitening(fit.parameters, fit.covariance)
    prior = _attitude.default_prior(1.0)
    starts, mode_chains = _attitude._chain_starts(center, chol, prior, jax.random.key(0), 4, jnp.float64, modes)
    thetas = center + np.asarray(starts) @ chol.T
    assert mode_chains == 1
    np.testing.assert_allclose(thetas[0], best, rtol=0, atol=1e-12)
    np.testing.assert_allclose(thetas[1], other, rtol=0, atol=1e-9)
    assert all(np.linalg.norm(np.linalg.solve(chol, theta - other)) > 5 for theta in thetas[2:])


# ----------------------------------------------------------------------------------- calibration


def calibration_ranks(n_sets, seed=0, thinning=THINNING):
    """Simulation-based calibration: for each of ``n_sets`` data sets drawn from calibration_prior(),
    the rank of each true value (log I2/I1, log I3/I1, Omega_1..3 at t = 0 = t_ref) among the thinned
    posterior draws, and whether the truth lies in the 50% and 90% central intervals of all draws.

    Returns (ranks (n_sets, 5) in 0..L, L = the thinned draws, inside_50 (n_sets, 5), inside_90,
    number of draws L)."""
    prior = calibration_prior()
    key = jax.random.key(seed)
    rng = np.random.default_rng(seed)
    ranks, inside_50, inside_90 = [], [], []
    for k in range(n_sets):
        key, ratio_key, rate_key, attitude_key = jax.random.split(key, 4)
        log_ratios = np.asarray(prior["log_inertia_ratios"].sample(ratio_key))
        omega = np.asarray(prior["angular_velocity"].sample(rate_key))
        delta = np.asarray(prior["attitude"].sample(attitude_key))
        attitude = np.asarray(quaternion.exp_pure(jnp.asarray(delta)))
        moments = np.exp(np.concatenate([[0.0], log_ratios]))
        q = observed(moments, omega, attitude, TIMES, rng)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PosteriorWarning)  # a truth next to the box's wall
            result = posterior(TIMES, q, prior=prior, seed=k)
        draws = np.asarray(result.parameters[:, :5])
        truth = np.concatenate([log_ratios, omega])
        thinned = draws.reshape(CHAINS, -1, 5)[:, ::thinning].reshape(-1, 5)
        ranks.append(np.sum(thinned < truth, axis=0))
        low50, high50, low90, high90 = np.quantile(draws, [0.25, 0.75, 0.05, 0.95], axis=0)
        inside_50.append((low50 <= truth) & (truth <= high50))
        inside_90.append((low90 <= truth) & (truth <= high90))
    return np.asarray(ranks), np.asarray(inside_50), np.asarray(inside_90), thinned.shape[0]


def chi_square_p(ranks, n_draws, bins):
    """p-value of Pearson's chi-square test of uniform ranks 0..n_draws over ``bins`` equal bins."""
    from scipy import stats

    counts = np.bincount(np.asarray(ranks).reshape(-1) * bins // (n_draws + 1), minlength=bins)
    return float(stats.chisquare(counts).pvalue), counts


def binomial_band(n, probability, sigmas=3.0):
    spread = sigmas * math.sqrt(n * probability * (1 - probability))
    return n * probability - spread, n * probability + spread


def test_simulation_based_calibration():
    """20 data sets from the (narrow) calibration prior, 40 attitudes each: the truths' ranks among
    100 thinned draws (4 chains of 100, every 4th) uniform by a chi-square test over 5 bins of the
    100 pooled ranks (5 quantities per set), p > 0.01, and the 50% and 90% central intervals
    covering the truth within 3 binomial standard deviations of 50 and 90 of 100.  Measured (seed 0,
    two loaded cores): p = 0.054 (rank counts 11, 24, 29, 18, 18), coverage 59 and 92 of 100; 2.0 s
    per posterior (fit and sampler compiled), 35 s in all.  The 100 data sets of
    benchmarks/posterior_calibration.py: p = 0.16, coverage 247 and 441 of 500."""
    ranks, inside_50, inside_90, n_draws = calibration_ranks(CALIBRATION_SETS)
    p_value, counts = chi_square_p(ranks, n_draws, bins=5)
    assert p_value > 0.01, (p_value, counts)
    n = inside_50.size
    low, high = binomial_band(n, 0.5)
    assert low <= inside_50.sum() <= high, inside_50.sum()
    low, high = binomial_band(n, 0.9)
    assert low <= inside_90.sum() <= min(high, n), inside_90.sum()


# ----------------------------------------------------------------------------------- helpers


def test_default_prior_distributions():
    """TriangleLogUniform's draws obey the triangle inequality (up to its soft edge) within the box;
    IsotropicRotation's draws are uniform rotations: |delta| has the density (1 - cos a) / pi on (0, pi),
    whose mean is pi/2 + 2/pi."""
    key = jax.random.key(3)
    ratios = np.asarray(TriangleLogUniform().sample(key, (4000,)))
    assert np.all(np.abs(ratios) <= math.log(100.0))
    moments = np.exp(np.concatenate([np.zeros((4000, 1)), ratios], axis=1))
    excess = (moments.sum(1) - 2 * moments.max(1)) / moments.max(1)
    assert np.mean(excess < -0.05) < 1e-3
    angles = np.linalg.norm(np.asarray(IsotropicRotation().sample(key, (20000,))), axis=1)
    assert np.all(angles <= math.pi)
    assert abs(np.mean(angles) - (math.pi / 2 + 2 / math.pi)) < 4 * 0.7 / math.sqrt(20000)
    # Its density integrates to one over the ball (radial integral 4 pi a^2 p(a)).
    radii = np.linspace(1e-6, math.pi * (1 - 1e-12), 20001)
    vectors = np.stack([radii, np.zeros_like(radii), np.zeros_like(radii)], axis=1)
    density = np.exp(np.asarray(IsotropicRotation().log_prob(jnp.asarray(vectors))))
    assert abs(np.trapezoid(4 * math.pi * radii**2 * density, radii) - 1) < 1e-6


def test_to_arviz_without_arviz(monkeypatch):
    """to_arviz names the missing package (arviz is not a dependency)."""
    import sys

    result = AttitudePosterior.__new__(AttitudePosterior)
    monkeypatch.setitem(sys.modules, "arviz", None)
    with pytest.raises(ImportError, match="arviz"):
        result.to_arviz()


def test_tensor_with_gyro_data():
    """``inertia="tensor"`` with gyro data: a body whose principal axes are tilted from the data's
    axes (rotation vector (0.3, -0.2, 0.5)), moments 0.55 : 0.8 : 1, 40 attitudes at 1 mrad and body
    rates at 1 mrad/s.  The inertia tensor (every entry) and the angular velocity at t = 0 inside the
    posterior's 99% central intervals, converged chains.  Measured: all inside, R-hat 1.00, no
    divergences, the tensor's largest posterior standard deviation 1.4e-4 without gyro data; 27 s
    with its compilation (one more sampler program: the tensor's 11 parameters)."""
    rng = np.random.default_rng(11)
    moments = np.array([0.55, 0.8, 1.0])
    axes_rotation = quaternion.exp_pure(jnp.array([0.3, -0.2, 0.5]))
    axes = np.asarray(quaternion.as_matrix(axes_rotation))
    omega = np.array([0.5, 0.2, 0.7])  # principal frame, t = 0
    q_principal, omega_principal = motion(
        jnp.asarray(moments), jnp.asarray(moments * omega), jnp.array([1.0, 0.0, 0.0, 0.0]), TIMES
    )
    # x_space = R_principal(t) axes^T x_data: the data frame's attitude is q(t) ⊗ conj(q_axes).
    q = quaternion.multiply(q_principal, quaternion.conjugate(axes_rotation))
    q = np.asarray(quaternion.multiply(q, quaternion.exp_pure(jnp.asarray(rng.normal(scale=NOISE, size=(40, 3))))))
    rates = np.asarray(omega_principal) @ axes.T + rng.normal(scale=NOISE, size=(40, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("error", PosteriorWarning)
        result = posterior(
            TIMES, q, inertia="tensor", angular_velocity_data=rates, angular_velocity_sigma=NOISE, num_chains=2
        )
    assert result.parameters.shape == (2 * DRAWS, 11)
    assert float(np.max(result.r_hat)) < 1.01 and int(np.sum(result.divergences)) == 0
    tensors = np.einsum(
        "sij,sj,skj->sik",
        np.asarray(result.principal_axes),
        np.asarray(result.inertia),
        np.asarray(result.principal_axes),
    )
    low, high = np.quantile(tensors, [0.005, 0.995], axis=0)
    truth = axes @ np.diag(moments) @ axes.T
    assert np.all((low <= truth) & (truth <= high)), (truth, low, high)
    low, high = np.quantile(np.asarray(result.angular_velocity), [0.005, 0.995], axis=0)
    assert np.all((low <= axes @ omega) & (axes @ omega <= high))
