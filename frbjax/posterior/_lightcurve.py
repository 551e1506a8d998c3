r"""The posterior of a light-curve fit's spin state and inertia ratios (``lightcurve_posterior``).

The parameters are those of :func:`frbjax.lightcurve.fit_lightcurve` (its module docstring): the
motion $\theta$ = (log I1, log I2 with I3 = 1, log |L|, the attitude's rotation vector about the
fit's reference attitude, L's inertial direction as a tangent of the sphere about its reference)
at the epoch.  The shape is held at its fitted values (sampling its hundreds of facet areas is left
out), so the posterior is conditional on the shape: on a full-size tumbler its periods' standard
deviations were 0.32 and 0.40 of the fit's sigmas, which carry the shape's uncertainty too
(benchmarks/lightcurve_posterior.py).  The light curves' unknown scales, under a flat prior on each
log-scale, are integrated out exactly: for Gaussian noise in log flux the integral over one curve's offset leaves
the residuals about the curve's mean, the residuals of the fit, and a constant.  The log likelihood
is then

$$\log p(\text{data} \mid \theta) = -\frac{1}{2\sigma^2} \sum_i \big(r_i - \bar r_{c(i)}\big)^2,
\qquad r_i = \log b_i - \log m_i(\theta),$$

$m_i$ the model flux of the fitted shape (Kaasalainen & Torppa 2001) through the exact motion, and
$\sigma$ the relative noise.  numpyro's NUTS samples it in whitened coordinates
$\theta = \hat\theta + C^{1/2} z$, $C$ the fit's covariance of $\theta$ conditional on the shape
(the inverse of the precision's motion block), in the attitude posterior's program
(``_sampler``: the chains one after another, a call each of one compiled loop, the data and the whitening as its
arguments, so that a second posterior of the same sizes and scattering law compiles nothing).
"""

from __future__ import annotations

import functools
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import numpyro

from .. import _checks as checks, _progress
from ..lightcurve._fit import _curve_mean, _facet_fluxes, _periods, _safe_log, _validate, LightcurveFit
from . import _sampler as sampler
from ._result import (
    bulk_ess,
    LIGHTCURVE_PARAMETER_NAMES,
    LightcurvePosterior,
    PosteriorWarning,
    R_HAT_LIMIT,
    split_r_hat,
    tail_ess,
)


# The blocks of theta that a user's prior may give distributions for.
LIGHTCURVE_BLOCKS = {
    "log_moments": slice(0, 2),
    "log_momentum": slice(2, 3),
    "attitude": slice(3, 6),
    "momentum_direction": slice(6, 8),
}


def _triangle_inequality(log_moments):
    """Whether the moments (e^a, e^b, 1) can be a rigid body's: each at most the sum of the others."""
    moments = jnp.concatenate([jnp.exp(log_moments), jnp.ones(1, log_moments.dtype)])
    return jnp.all(2 * moments <= jnp.sum(moments))


def _log_prior(theta, prior):
    """The default prior (flat in theta, moments within the triangle inequality) times the user's
    distributions of blocks of theta."""
    total = jnp.where(_triangle_inequality(theta[:2]), 0.0, -jnp.inf).astype(theta.dtype)
    for name, distribution in prior.items():
        value = theta[LIGHTCURVE_BLOCKS[name]]
        inside = jnp.all(distribution.support(value))
        total = total + jnp.where(inside, jnp.sum(distribution.log_prob(value)), -jnp.inf)
    return total


@functools.cache
def _potential_generator(law):
    """The potential of the whitened parameters z for the scattering ``law`` (one function per law,
    so that the sampler's program is found compiled by a later call): ``data`` holds the light
    curves, the held shape, the whitening and the noise."""

    def generator(data, prior):
        def potential(z):
            theta = data["fixed"].at[data["free"]].set(data["centre"] + data["root"] @ z)
            fluxes = _facet_fluxes(theta, data["reference"], data["normals"], data, law, data["c"])
            difference = data["log_brightness"] - _safe_log(fluxes @ data["areas"])
            residual = (difference - _curve_mean(difference, data["ones"], data["curves"])) / data["sigma"]
            value = 0.5 * jnp.sum(residual * residual) - _log_prior(theta, prior)
            return jnp.where(jnp.isnan(value), jnp.inf, value)

        return potential

    return generator


def _conditional_whitening(fit_parameters, covariance, free):
    """(centre, square root of the motion's covariance given the shape) on the free motion parameters."""
    covariance = np.asarray(covariance, float)
    precision = np.linalg.pinv(0.5 * (covariance + covariance.T))
    block = precision[np.ix_(free, free)]
    conditional = np.linalg.pinv(0.5 * (block + block.T))
    values, vectors = np.linalg.eigh(0.5 * (conditional + conditional.T))
    values = np.maximum(values, 1e-10 * max(float(values.max()), 1e-300))
    return np.asarray(fit_parameters, float)[free], vectors @ np.diag(np.sqrt(values)) @ vectors.T


def lightcurve_posterior(
    times,
    brightness,
    sun,
    observer,
    *,
    initial: LightcurveFit,
    sigma: float,
    lightcurve=None,
    magnitudes: bool = False,
    prior: dict | None = None,
    num_warmup: int = 500,
    num_samples: int = 1000,
    num_chains: int = 4,
    seed: int = 0,
    progress: bool | None = None,
    nan_policy: str = "raise",
) -> LightcurvePosterior:
    r"""Posterior draws of a tumbler's spin state, inertia ratios and periods from light curves.

    The data as for :func:`frbjax.lightcurve.fit_lightcurve` (``times``, ``brightness``, ``sun``,
    ``observer``, ``lightcurve``, ``magnitudes``, ``nan_policy``); ``initial``: the
    :class:`frbjax.lightcurve.LightcurveFit` of these data, about which the parameters are whitened
    and the chains started; ``sigma``: the relative noise (the standard deviation of the log flux).
    The shape is held at ``initial``'s (the intervals are conditional on it: narrower than the fit's
    on a tumbler, module docstring), the light curves' scales are integrated out; a principal-axis
    fit keeps its fixed parameters and samples the rest.

    ``prior``: the default is flat in the parameters (log moments, log |L|, the attitude's and L's
    tangent coordinates) with the moments within the triangle inequality; a dict of numpyro
    distributions for blocks of them (``"log_moments"`` (2,), ``"log_momentum"`` (1,),
    ``"attitude"`` (3,), ``"momentum_direction"`` (2,)) multiplies it.  numpyro's NUTS
    (``num_warmup``, ``num_samples`` per chain, ``num_chains`` one after another, ``seed``), its
    progress bar when ``progress`` (default: in a terminal or a notebook).  Chain 0 starts at the
    fit, the others a standard normal away in the whitened parameters.

    Returns :class:`LightcurvePosterior` (periods, inertia, long-axis mode per draw, diagnostics);
    a :class:`PosteriorWarning` when split R-hat exceeds 1.01 or transitions diverged.  Refused
    (ValueError): the data errors of ``fit_lightcurve``, an ``initial`` that is not a
    LightcurveFit of as many light curves, ``sigma`` not > 0, counts below their minimum, unknown
    prior blocks.
    """
    if not isinstance(initial, LightcurveFit) or not initial._reference:
        raise ValueError(f"initial must be a LightcurveFit (from fit_lightcurve), got {type(initial).__name__}")
    sigma = checks.scalar("sigma", sigma, positive=True)
    num_chains = checks.integer("num_chains", num_chains, minimum=1)
    num_samples = checks.integer("num_samples", num_samples, minimum=4)
    num_warmup = checks.integer("num_warmup", num_warmup, minimum=0)
    seed = checks.integer("seed", seed, minimum=0)
    progress = _progress.check_option(progress)
    prior = {} if prior is None else dict(prior)
    unknown = sorted(set(prior) - set(LIGHTCURVE_BLOCKS))
    if unknown:
        raise ValueError(f"prior has unknown blocks {unknown}; known: {sorted(LIGHTCURVE_BLOCKS)}")
    times, flux, sun, observer, labels, _ = _validate(
        times, brightness, sun, observer, lightcurve, magnitudes, nan_policy
    )
    _, curve_index = np.unique(labels, return_inverse=True)
    curves = np.eye(curve_index.max() + 1)[curve_index]
    if curves.shape[1] != initial.scales.shape[0]:
        raise ValueError(
            f"initial must be a fit of these data: it has {initial.scales.shape[0]} light curves, the data "
            f"{curves.shape[1]}"
        )
    log_brightness = -0.4 * np.log(10.0) * flux if magnitudes else np.log(flux)
    dtype = initial.parameters.dtype
    fit_theta = np.asarray(initial.parameters, float)[:8]
    covariance = np.asarray(initial.covariance, float)
    free = np.flatnonzero(np.diag(covariance)[:8] > 0)
    centre, root = _conditional_whitening(fit_theta, covariance, free)
    principal_axis = not np.isfinite(float(initial.periods[1]))

    as_array = lambda value: jnp.asarray(value, dtype)  # noqa: E731
    reference = initial._reference
    data = dict(
        times=as_array(times - initial.epoch),
        sun=as_array(sun),
        observer=as_array(observer),
        log_brightness=as_array(log_brightness),
        curves=as_array(curves),
        ones=jnp.ones(len(times), dtype),
        normals=initial.shape.normals,
        areas=initial.shape.areas,
        reference=reference,
        c=as_array(initial.c),
        sigma=as_array(sigma),
        fixed=as_array(fit_theta),
        free=jnp.asarray(free),
        centre=as_array(centre),
        root=as_array(root),
    )

    key = jax.random.key(seed)
    start_key, chain_key = jax.random.split(key)
    z0 = np.array(jax.random.normal(start_key, (num_chains, len(free)), dtype), float)
    z0[0] = 0.0
    with numpyro.validation_enabled(False):
        out = sampler.run(
            jnp.asarray(z0, dtype),
            jax.random.split(chain_key, num_chains),
            data,
            prior,
            num_warmup=num_warmup,
            num_samples=num_samples,
            vectorized=False,
            progress=progress,
            potential_generator=_potential_generator(initial.law),
        )
    z = np.asarray(out["draws"])  # (C, D, free)
    diverging = np.asarray(out["diverging"])
    fixed, free_index = data["fixed"], data["free"]

    def theta_of(z):
        return fixed.at[free_index].set(data["centre"] + data["root"] @ z)

    thetas = np.asarray(jax.jit(jax.vmap(theta_of))(jnp.asarray(z.reshape(-1, z.shape[-1]), dtype)))
    periods, long_axis = (
        np.asarray(x)
        for x in jax.jit(jax.vmap(lambda theta: _periods(theta, reference, principal_axis)))(as_array(thetas))
    )
    logs = np.concatenate([thetas[:, :2], np.zeros((len(thetas), 1))], 1)
    inertia = np.exp(logs - logs.max(axis=1, keepdims=True))
    chains = thetas.reshape(num_chains, -1, 8)[..., free]
    with np.errstate(invalid="ignore", divide="ignore"):
        r_hat = split_r_hat(chains) if num_chains > 1 else np.full(len(free), np.nan)
        ess_bulk, ess_tail = bulk_ess(chains), tail_ess(chains)
    divergences = diverging.sum(axis=1)
    result = LightcurvePosterior(
        inertia=as_array(inertia),
        periods=as_array(periods),
        long_axis_mode=jnp.asarray(np.asarray(long_axis, bool) & ~principal_axis),
        parameters=as_array(thetas),
        chain=jnp.asarray(np.repeat(np.arange(num_chains), chains.shape[1])),
        diverging=jnp.asarray(diverging.reshape(-1)),
        r_hat=as_array(r_hat),
        ess_bulk=as_array(ess_bulk),
        ess_tail=as_array(ess_tail),
        divergences=jnp.asarray(divergences),
        fit=initial,
        parameter_names=tuple(LIGHTCURVE_PARAMETER_NAMES[i] for i in free),
        num_chains=num_chains,
    )
    problems = []
    worst = float(np.nanmax(r_hat)) if np.any(np.isfinite(r_hat)) else (np.nan if num_chains == 1 else np.inf)
    if num_chains > 1 and not worst <= R_HAT_LIMIT:
        problems.append(f"largest split R-hat {worst:.4f} > {R_HAT_LIMIT}")
    if divergences.sum():
        problems.append(f"{int(divergences.sum())} divergent transitions (per chain {divergences.tolist()})")
    if problems:
        warnings.warn(
            "lightcurve_posterior: "
            + "; ".join(problems)
            + ": the draws may not represent the posterior (run longer chains, or look for several modes)",
            PosteriorWarning,
            stacklevel=2,
        )
    return result
