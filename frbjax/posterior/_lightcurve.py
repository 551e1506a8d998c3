r"""The posterior of a light-curve fit's spin state, inertia ratios and shape (``lightcurve_posterior``).

The parameters are those of :func:`frbjax.lightcurve.fit_lightcurve` (its module docstring): the
motion $\theta$ = (log I1, log I2 with I3 = 1, log |L|, the attitude's rotation vector about the
fit's reference attitude, L's inertial direction as a tangent of the sphere about its reference)
at the epoch, and the shape's $s$ (a convex shape's log-areas on the fit's normals, or an
ellipsoid's two log axis ratios).  The negative log posterior is the fit's own cost, the half sum of
squares of its residual rows, less the log prior of $\theta$:

$$-\log p(\theta, s \mid \text{data}) = \frac{1}{2\sigma^2} \sum_i \big(r_i - \bar r_{c(i)}\big)^2
+ \frac{1}{2} \lVert R(s) \rVert^2 - \log p(\theta) + \text{const},
\qquad r_i = \log b_i - \log m_i(\theta, s),$$

$m_i$ the model flux (Kaasalainen & Torppa 2001) through the exact motion, $\sigma$ the relative
noise, and $R(s)$ the convex shape's regularisation rows (the closure of its Gaussian image, the
smoothness of the log-areas, their mean), which make the shape's prior a proper one.  The light
curves' unknown scales, under a flat prior on each log-scale, are integrated out exactly: for
Gaussian noise in log flux the integral over one curve's offset leaves the residuals about the
curve's mean and a constant.  The gradient is the cost's, in reverse mode (one pass for all the
sampled parameters, hundreds of facet areas included).

By default the shape is held at the fit's values and the motion sampled given it; ``shape="sampled"``
draws the shape with the motion.  On the light-curve benchmark's tumbler (384 samples, 320 facets:
benchmarks/lightcurve_posterior.py) the held shape's periods have posterior standard deviations 0.73
and 0.94 of the fit's sigmas, its moments 0.59 and 0.54 (4 chains of 300 + 300: 170 s on one core, 47 s with
today's gradient);
with the shape sampled they are 1.12 and 1.08, the moments 1.36 and 1.05, but 2 chains of 100 + 100
took 1047 s (with a gradient three times as costly as today's) and had not converged (split R-hat
1.24): the log-areas' posterior is far from Gaussian (its curvature along the whitened directions
ranges from 0.002 to 600 a third of a standard deviation from the centre in every coordinate), so
that NUTS takes steps of about 0.01 and 700 of them a draw.  numpyro's NUTS samples whitened
coordinates $z$: the sampled parameters are
$\hat p + V S^{-1} z$ with $J = U S V^T$ the singular value decomposition of the fit's rows'
Jacobian in the sampled columns (given the shape when it is held) and $\hat p$ one Gauss-Newton
step from the fit (the prior of an ellipsoid's axes included), in the attitude posterior's program
(``_sampler``: the chains one after another, a call each of one compiled loop, the data and the
whitening as its arguments, so that a second posterior of the same sizes and scattering law
compiles nothing).
"""

from __future__ import annotations

import functools
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import numpyro

from .. import _checks as checks, _progress
from .._kernel_path import keyed_by_path
from ..lightcurve._fit import (
    _curve_mean,
    _laplacian,
    _log_model,
    _periods,
    _regularisation,
    _rows,
    _SEARCH_SUBDIVISIONS,
    _unit_normals,
    _validate,
    LightcurveFit,
)
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


# The precision of the Gaussian prior (mean 0) of an ellipsoid's two log axis ratios when sampled.
ELLIPSOID_PRIOR_PRECISION = 1.0
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


def _fit_cost(parameters, data, config):
    """The fit's cost at ``parameters`` (motion and shape): half the sum of squares of its data rows
    (about each light curve's mean: its scale eliminated) and of a convex shape's regularisation
    rows.  Its value alone, differentiated in reverse mode: on the benchmark's tumbler (384 samples,
    320 facets, the shape held) a gradient takes 1.5 ms, the fit's forward-mode Jacobian times its rows
    4.5 ms."""
    difference = data["log_brightness"] - _log_model(parameters, data["reference"], data, config)
    residual = (difference - _curve_mean(difference, data["ones"], data["curves"])) / data["sigma"]
    cost = 0.5 * residual @ residual
    if config[0] == "convex":
        regularisation = _regularisation(parameters[8:], data)
        cost = cost + 0.5 * regularisation @ regularisation
    return cost


@functools.cache
def _potential_generator(config):
    """The potential of the whitened parameters z for the fit's static ``config`` (shape model,
    scattering law, its c, principal axis): one function per config, so that the sampler's program
    is found compiled by a later call.  ``data`` holds the light curves, the fit's parameters, which
    of them are sampled, the whitening and the noise."""

    def generator(data, prior):
        def potential(z):
            parameters = data["fixed"].at[data["sampled"]].set(data["centre"] + data["root"] @ z)
            value = _fit_cost(parameters, data, config) - _log_prior(parameters[:8], prior)
            if config[0] == "ellipsoid":
                # The ellipsoid's log axis ratios, which relative photometry may leave undetermined (a
                # rotator seen near its equator: the axis along the spin): a Gaussian prior.
                value = value + 0.5 * ELLIPSOID_PRIOR_PRECISION * jnp.sum(parameters[8:] ** 2)
            # NaN (a motion the formulas cannot evaluate) as an infinite potential: NUTS rejects it.
            return jnp.where(jnp.isnan(value), jnp.inf, value)

        return potential

    return generator


@keyed_by_path(static_argnums=2)
def _rows_at(parameters, data, config):
    """The fit's rows and their Jacobian at ``parameters`` (one compiled program)."""
    return _rows(parameters, data["reference"], data, (data["ones"], None, None), config)


def _whitening(parameters, residual, jacobian, sampled, prior_precision):
    """(centre, root) with the ``sampled`` parameters = centre + root @ z, z about standard normal.

    The Gauss-Newton (Laplace) approximation of the posterior at the fit: from the singular value
    decomposition of the fit's rows' Jacobian in the sampled columns, J = U S V^T, root = V S^-1 (the
    rows' Hessian J^T J in z is then the identity; the square root of the fit's covariance matrix had
    lost two of the periods' well-determined directions to rounding, curvatures 8866 and 30412),
    and the centre one Gauss-Newton step from the fit, with the rows of a Gaussian prior of mean 0
    and diagonal ``prior_precision`` (per sampled parameter) that the fit's rows do not hold."""
    values = np.asarray(parameters, float)[sampled]
    jacobian = np.asarray(jacobian, float)[:, sampled]
    residual = np.asarray(residual, float)
    prior_root = np.sqrt(np.asarray(prior_precision, float))
    if np.any(prior_root):
        jacobian = np.concatenate([jacobian, np.diag(prior_root)])
        residual = np.concatenate([residual, prior_root * values])
    left, singular, right = np.linalg.svd(jacobian, full_matrices=False)
    singular = np.maximum(singular, 1e-10 * max(float(singular[0]), 1e-300))
    centre = values - right.T @ ((left.T @ residual) / singular)
    return centre, right.T / singular


def _problem(times, brightness, sun, observer, lightcurve, magnitudes, nan_policy, initial, sigma, shape):
    """(data, config, free): what the sampler needs of these light curves about the fit ``initial``
    (the data, the fit's parameters, which of them are sampled, the whitening and the noise), the
    fit's static config (shape model, law, c, principal axis), and the free motion parameters."""
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
    fit_parameters = np.asarray(initial.parameters, float)
    variances = np.diag(np.asarray(initial.covariance, float))
    free = np.flatnonzero(variances[:8] > 0)
    sampled = free if shape == "held" else np.flatnonzero(variances > 0)
    principal_axis = not np.isfinite(float(initial.periods[1]))
    free_mask = np.zeros(fit_parameters.size)
    free_mask[sampled] = 1.0
    if initial.shape_model == "convex":
        subdivisions = round(math.log(initial.shape.normals.shape[0] / 20, 4))
        laplacian = _laplacian(_unit_normals(subdivisions)[2])
    else:
        laplacian = np.zeros((1, 1))
    config = (initial.shape_model, initial.law, float(initial.c), _SEARCH_SUBDIVISIONS, principal_axis)

    as_array = lambda value: jnp.asarray(value, dtype)  # noqa: E731
    reference = initial._reference
    data = dict(
        times=as_array(times - initial.epoch),
        sun=as_array(sun),
        observer=as_array(observer),
        log_brightness=as_array(log_brightness),
        curves=as_array(curves),
        ones=jnp.ones(len(times), dtype),
        normals=as_array(initial.shape.normals),
        laplacian=as_array(laplacian),
        regularisation=as_array(initial.regularisation),
        free=as_array(free_mask),
        reference=reference,
        sigma=as_array(sigma),
        fixed=as_array(fit_parameters),
        sampled=jnp.asarray(sampled),
    )
    residual, jacobian = _rows_at(data["fixed"], data, config)
    # The ellipsoid's log axis ratios have a Gaussian prior that the fit's rows lack.
    prior_precision = np.where((sampled >= 8) & (initial.shape_model == "ellipsoid"), ELLIPSOID_PRIOR_PRECISION, 0.0)
    centre, root = _whitening(fit_parameters, residual, jacobian, sampled, prior_precision)
    data.update(centre=as_array(centre), root=as_array(root))
    return data, config, free


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
    shape: str = "held",
    prior: dict | None = None,
    num_warmup: int = 500,
    num_samples: int = 1000,
    num_chains: int = 4,
    seed: int = 0,
    progress: bool | None = None,
    nan_policy: str = "raise",
) -> LightcurvePosterior:
    r"""Posterior draws of a tumbler's spin state, inertia ratios, periods and shape from light curves.

    The data as for :func:`frbjax.lightcurve.fit_lightcurve` (``times``, ``brightness``, ``sun``,
    ``observer``, ``lightcurve``, ``magnitudes``, ``nan_policy``); ``initial``: the
    :class:`frbjax.lightcurve.LightcurveFit` of these data, about which the parameters are whitened
    and the chains started; ``sigma``: the relative noise (the standard deviation of the log flux).
    ``shape``: ``"held"`` at ``initial``'s (default: the motion's posterior given the fitted shape,
    narrower intervals on a tumbler) or ``"sampled"`` with the motion (its uncertainty then in the
    periods' and moments' intervals; far slower: module docstring).  The prior of a convex shape is
    the fit's regularisation (closure, smoothness, mean log-area) with ``initial``'s weights, an
    ellipsoid's log axis ratios are standard normal.  The light curves' scales are integrated out;
    a principal-axis fit keeps its fixed parameters and samples the rest.

    ``prior``: the default is flat in the parameters (log moments, log |L|, the attitude's and L's
    tangent coordinates) with the moments within the triangle inequality; a dict of numpyro
    distributions for blocks of them (``"log_moments"`` (2,), ``"log_momentum"`` (1,),
    ``"attitude"`` (3,), ``"momentum_direction"`` (2,)) multiplies it.  numpyro's NUTS
    (``num_warmup``, ``num_samples`` per chain, ``num_chains`` one after another, ``seed``), its
    progress bar when ``progress`` (default: in a terminal or a notebook).  Chain 0 starts at the
    whitening's centre (the fit, one Gauss-Newton step on), the others a standard normal away in the
    whitened parameters.

    Returns :class:`LightcurvePosterior` (periods, inertia, long-axis mode, shape parameters per
    draw, diagnostics); a :class:`PosteriorWarning` when split R-hat (of any sampled parameter, the
    shape's included) exceeds 1.01 or transitions diverged.  Refused (ValueError): the data errors
    of ``fit_lightcurve``, an ``initial`` that is not a LightcurveFit of as many light curves,
    ``sigma`` not > 0, a ``shape`` other than the two, counts below their minimum, unknown prior
    blocks.
    """
    if not isinstance(initial, LightcurveFit) or not initial._reference:
        raise ValueError(f"initial must be a LightcurveFit (from fit_lightcurve), got {type(initial).__name__}")
    sigma = checks.scalar("sigma", sigma, positive=True)
    if shape not in ("sampled", "held"):
        raise ValueError(f"shape must be 'held' or 'sampled', got {shape!r}")
    num_chains = checks.integer("num_chains", num_chains, minimum=1)
    num_samples = checks.integer("num_samples", num_samples, minimum=4)
    num_warmup = checks.integer("num_warmup", num_warmup, minimum=0)
    seed = checks.integer("seed", seed, minimum=0)
    progress = _progress.check_option(progress)
    prior = {} if prior is None else dict(prior)
    unknown = sorted(set(prior) - set(LIGHTCURVE_BLOCKS))
    if unknown:
        raise ValueError(f"prior has unknown blocks {unknown}; known: {sorted(LIGHTCURVE_BLOCKS)}")
    data, config, free = _problem(
        times, brightness, sun, observer, lightcurve, magnitudes, nan_policy, initial, sigma, shape
    )
    dtype = initial.parameters.dtype
    fit_parameters = np.asarray(initial.parameters, float)
    centre, root, sampled = (np.asarray(data[name]) for name in ("centre", "root", "sampled"))
    reference, principal_axis = data["reference"], config[4]
    as_array = lambda value: jnp.asarray(value, dtype)  # noqa: E731

    key = jax.random.key(seed)
    start_key, chain_key = jax.random.split(key)
    z0 = np.array(jax.random.normal(start_key, (num_chains, len(sampled)), dtype), float)
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
            potential_generator=_potential_generator(config),
            # Reverse mode: one pass for the gradient, whatever the count of sampled parameters.
            forward_mode=False,
        )
    z = np.asarray(out["draws"])  # (C, D, sampled)
    diverging = np.asarray(out["diverging"])
    draws = fit_parameters + np.zeros((z.shape[0] * z.shape[1], 1))
    draws[:, sampled] = centre + z.reshape(-1, z.shape[-1]) @ root.T
    thetas = draws[:, :8]
    periods, long_axis = (
        np.asarray(x)
        for x in jax.jit(jax.vmap(lambda theta: _periods(theta, reference, principal_axis)))(as_array(thetas))
    )
    logs = np.concatenate([thetas[:, :2], np.zeros((len(thetas), 1))], 1)
    inertia = np.exp(logs - logs.max(axis=1, keepdims=True))
    by_chain = draws.reshape(num_chains, -1, draws.shape[-1])
    chains = by_chain[..., free]
    with np.errstate(invalid="ignore", divide="ignore"):
        r_hat = split_r_hat(chains) if num_chains > 1 else np.full(len(free), np.nan)
        ess_bulk, ess_tail = bulk_ess(chains), tail_ess(chains)
        shape_r_hat = (
            split_r_hat(by_chain[..., sampled[sampled >= 8]]) if num_chains > 1 and shape == "sampled" else np.zeros(0)
        )
    divergences = diverging.sum(axis=1)
    result = LightcurvePosterior(
        inertia=as_array(inertia),
        periods=as_array(periods),
        long_axis_mode=jnp.asarray(np.asarray(long_axis, bool) & ~principal_axis),
        parameters=as_array(thetas),
        shape_parameters=as_array(draws[:, 8:]),
        chain=jnp.asarray(np.repeat(np.arange(num_chains), chains.shape[1])),
        diverging=jnp.asarray(diverging.reshape(-1)),
        r_hat=as_array(r_hat),
        ess_bulk=as_array(ess_bulk),
        ess_tail=as_array(ess_tail),
        divergences=jnp.asarray(divergences),
        fit=initial,
        parameter_names=tuple(LIGHTCURVE_PARAMETER_NAMES[i] for i in free),
        num_chains=num_chains,
        shape_sampled=shape == "sampled",
    )
    problems = []
    every_r_hat = np.concatenate([r_hat, shape_r_hat])
    worst = (
        float(np.nanmax(every_r_hat)) if np.any(np.isfinite(every_r_hat)) else (np.nan if num_chains == 1 else np.inf)
    )
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
