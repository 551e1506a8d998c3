"""frbjax.posterior.lightcurve_posterior on the smallest light-curve inversion there is: the docs'
principal-axis rotator (period 0.3 days, 8 nights of 8 samples, 1% noise, an ellipsoid; the data of
tests/test_lightcurve_nan_policy.py, clean).  The posterior of the period must agree with the fit's
linearised uncertainty (a rotator's likelihood is close to Gaussian in its motion: measured ratio
1.014 with the shape held, test_period_posterior_of_a_rotator) and contain the true period;
tumblers at full size are the benchmark's (benchmarks/lightcurve_posterior.py; posterior_vs_fit.py
compares attitude posteriors the same way)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from _compile_options import fast_jit
from test_lightcurve_nan_policy import observations, OPTIONS

from frbjax.lightcurve import fit_lightcurve
from frbjax.posterior import lightcurve_posterior, LightcurvePosterior, PosteriorWarning


@pytest.fixture(scope="module")
def data_and_fit():
    times, flux, sun, observer, night = observations()
    fit = fit_lightcurve(times, flux, sun, observer, lightcurve=night, **OPTIONS)
    return (times, flux, sun, observer), night, fit


def test_bad_input_refused(data_and_fit):
    arguments, night, fit = data_and_fit
    with pytest.raises(ValueError, match="initial must be a LightcurveFit"):
        lightcurve_posterior(*arguments, lightcurve=night, initial=None, sigma=0.01)
    with pytest.raises(ValueError, match="sigma"):
        lightcurve_posterior(*arguments, lightcurve=night, initial=fit, sigma=0.0)
    with pytest.raises(ValueError, match="light curves"):
        lightcurve_posterior(*arguments, initial=fit, sigma=0.01)
    with pytest.raises(ValueError, match="unknown blocks"):
        lightcurve_posterior(*arguments, lightcurve=night, initial=fit, sigma=0.01, prior={"shape": None})
    with pytest.raises(ValueError, match="num_samples"):
        lightcurve_posterior(*arguments, lightcurve=night, initial=fit, sigma=0.01, num_samples=1)
    with pytest.raises(ValueError, match="shape must be"):
        lightcurve_posterior(*arguments, lightcurve=night, initial=fit, sigma=0.01, shape="free")


def test_period_posterior_of_a_rotator(data_and_fit):
    """4 chains of 200 + 200 draws (the sampler's one compiled loop is most of the time): the period's
    posterior standard deviation within 25% of the fit's model sigma (measured ratio 1.014, the shape held
    at the fit's: the default), the truth inside its 99.9% interval, converged chains (split R-hat
    1.0015, no divergence), and the fixed parameters of a principal-axis rotation (its moments) not
    sampled."""
    arguments, night, fit = data_and_fit
    with warnings.catch_warnings():
        warnings.simplefilter("error", PosteriorWarning)
        result = lightcurve_posterior(
            *arguments,
            lightcurve=night,
            initial=fit,
            sigma=0.01,
            num_chains=4,
            num_warmup=200,
            num_samples=200,
            progress=False,
        )
    assert isinstance(result, LightcurvePosterior) and result.periods.shape == (800, 2)
    period = np.asarray(result.periods[:, 0])
    # The model covariance's sigma of the winner's basin: the chains sample that basin under the
    # model's likelihood (the fit's period_sigma also spans the competing basins of these eight
    # nights' aliases; with fewer than 12 light curves there is no cluster-robust covariance, so the
    # basin's sigma is the model's).
    sigma = float(fit.standard_errors(fit.covariance)[0][0])
    assert sigma == float(fit.basin_period_sigma[0]) < float(fit.period_sigma[0])
    assert 0.75 < period.std(ddof=1) / sigma < 1.25, (period.std(ddof=1), sigma)
    assert np.quantile(period, 0.0005) < 0.3 < np.quantile(period, 0.9995)
    assert np.all(np.asarray(result.r_hat) < 1.05) and "log_I1" not in result.parameter_names
    summary = result.summary()
    assert set(summary) >= {"P_psi", "log_L", "delta_1"} and "P_phi" not in summary
    assert result.mode_probabilities()["short_axis"] == 1.0


def test_one_chain(data_and_fit):
    """A single chain runs (numpyro's MCMC took a (1, D) start for one unbatched chain and failed) and
    reports no R-hat (split R-hat needs chains to compare; its effective sample sizes are given).
    200 + 200 steps, as test_period_posterior_of_a_rotator: the sampler runs sequential chains one
    program call each, so this chain finds that program compiled (2.5 s instead of 23 s with its
    own sizes, 100 + 20)."""
    arguments, night, fit = data_and_fit
    with warnings.catch_warnings():
        warnings.simplefilter("error", PosteriorWarning)  # no divergence after 200 warmup steps
        result = lightcurve_posterior(
            *arguments,
            lightcurve=night,
            initial=fit,
            sigma=0.01,
            num_chains=1,
            num_warmup=200,
            num_samples=200,
            progress=False,
        )
    assert result.periods.shape == (200, 2) and np.all(np.isfinite(np.asarray(result.periods[:, 0])))
    assert np.all(np.isnan(np.asarray(result.r_hat))) and np.all(np.asarray(result.ess_bulk) > 0)
    # The shape held (the default): every draw's shape is the fit's, and shape() builds it.
    assert not result.shape_sampled and result.shape_parameters.shape == (200, 2)
    assert np.all(np.asarray(result.shape_parameters) == np.asarray(fit.parameters[8:]))
    drawn = result.shape(17)
    np.testing.assert_allclose(np.asarray(drawn.areas), np.asarray(fit.shape.areas), rtol=1e-14)
    np.testing.assert_allclose(np.asarray(drawn.normals), np.asarray(fit.shape.normals), atol=1e-15)


def test_the_potential_is_the_fits_cost(data_and_fit):
    """The negative log likelihood that the posterior samples is the fit's cost (the same rows), and
    its gradient (reverse mode) is that cost's: central differences along random directions of all
    the sampled parameters, the shape's included, half a sigma from the fit (at the fit itself one
    facet of the ellipsoid lies on the terminator at one sample: the flux has a kink there, where
    the fit's solver stopped).  Steps of 1e-4 sigma: measured relative differences 1.7e-8 to 4e-8
    from 1e-4 to 1e-6 sigma; steps of 1e-3 and 1e-2 sigma cross other facets' kinks (1e-3, 6e-2)."""
    import jax
    import jax.numpy as jnp

    from frbjax.posterior import _lightcurve

    arguments, night, fit = data_and_fit
    # The sampler's data for the shape sampled (lightcurve_posterior's own preparation).
    data, config, _ = _lightcurve._problem(*arguments, night, False, "raise", fit, 0.01, "sampled")
    assert config[0] == "ellipsoid" and config[4]
    # The configuration bound (it is static); the programs compiled with tests/_compile_options.py's options
    # (a check of the derivative against differences of the cost: 19 s with XLA's defaults).
    cost = fast_jit(lambda parameters, data: _lightcurve._fit_cost(parameters, data, config))
    assert abs(float(cost(jnp.asarray(fit.parameters), data)) / fit.cost - 1) < 1e-9
    rng = np.random.default_rng(0)
    sigmas = np.sqrt(np.maximum(np.diag(np.asarray(fit.covariance)), 0))

    def random_step(scale):
        direction = np.zeros(sigmas.size)
        direction[np.asarray(data["sampled"])] = rng.normal(size=len(data["sampled"]))
        return scale * direction * sigmas

    parameters = jnp.asarray(fit.parameters) + random_step(0.5)
    gradient = fast_jit(jax.grad(lambda parameters, data: _lightcurve._fit_cost(parameters, data, config)))(
        parameters, data
    )
    for _ in range(3):
        step = random_step(1e-4)
        plus, minus = (float(cost(parameters + sign * step, data)) for sign in (1, -1))
        expected = (plus - minus) / 2
        assert abs(float(gradient @ step) / expected - 1) < 1e-6, (float(gradient @ step), expected)
