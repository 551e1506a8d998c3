"""attitude_posterior: the posterior of fit_attitude's parameters, sampled by numpyro's NUTS."""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import numpyro.distributions as dist
from jax.typing import ArrayLike

from .. import _checks as checks, _progress
from .._errors import FitError
from .._multistart import starts_in_sequence
from ..fit import (
    _checked_data,
    _finite_difference_rate,
    _normalised_inertia,
    _PRINCIPAL_PARAMETERS,
    _reference_sample,
    _scaled_tensor,
    _TENSOR_PARAMETERS,
    AttitudeFit,
    fit_attitude,
)
from . import _sampler as sampler
from ._prior import default_prior, DEFAULT_RATE_SCALE, PARAMETER_BLOCKS
from ._result import (
    AttitudePosterior,
    bulk_ess,
    long_axis_mode,
    PosteriorWarning,
    R_HAT_LIMIT,
    split_r_hat,
    tail_ess,
)


# The whitening's covariance: eigenvalues floored at this fraction of the largest (a fit whose
# Jacobian is rank-deficient has zero variance along its null direction, which must still move).
_COVARIANCE_FLOOR = 1e-10
_CHAIN_METHODS = ("vectorized", "sequential")


def _checked_prior(prior, tensor, rate_scale):
    """The prior as a complete dict of numpyro distributions (defaults for missing keys)."""
    defaults = default_prior(rate_scale, tensor=tensor)
    if prior is None:
        return defaults
    if not isinstance(prior, dict):
        raise ValueError(f"prior must be a dict of numpyro distributions or None, got {type(prior).__name__}")
    allowed = tuple(defaults)
    checked = dict(defaults)
    for name, distribution in prior.items():
        if name not in allowed:
            raise ValueError(f"prior has an unknown key {name!r}; its keys are {list(allowed)}")
        if not isinstance(distribution, dist.Distribution):
            raise ValueError(f"prior[{name!r}] must be a numpyro distribution, got {type(distribution).__name__}")
        size = len(PARAMETER_BLOCKS[name][1])
        shape = tuple(distribution.batch_shape) + tuple(distribution.event_shape)
        if shape not in ((size,), ()):
            raise ValueError(
                f"prior[{name!r}] must be a distribution of ({size},) values (batch and event shape together), "
                f"got batch shape {distribution.batch_shape} and event shape {distribution.event_shape}"
            )
        if shape == ():
            distribution = distribution.expand((size,)).to_event(1)
        elif distribution.event_shape == ():
            distribution = distribution.to_event(1)
        checked[name] = distribution
    return checked


def _whitening(fit_parameters, fit_covariance):
    """(center, chol): theta = center + chol @ z, chol a square root of the fit's covariance (floored)."""
    covariance = np.asarray(fit_covariance, float)
    covariance = 0.5 * (covariance + covariance.T)
    if not np.all(np.isfinite(covariance)):
        covariance = np.diag(np.maximum(np.abs(np.asarray(fit_parameters)), 1.0) * 1e-3) ** 2
    values, vectors = np.linalg.eigh(covariance)
    largest = max(float(np.max(values)), 1e-300)
    values = np.maximum(values, _COVARIANCE_FLOOR * largest)
    # A symmetric square root: chol @ chol.T = covariance (the "chol" of the sampler).
    return np.asarray(fit_parameters, float), vectors @ np.diag(np.sqrt(values)) @ vectors.T


def attitude_posterior(
    times: ArrayLike,
    quaternions: ArrayLike,
    *,
    angular_velocity_data: ArrayLike | None = None,
    attitude_sigma: float,
    angular_velocity_sigma: float | None = None,
    inertia: str = "principal",
    prior: dict | None = None,
    num_warmup: int = 500,
    num_samples: int = 1000,
    num_chains: int = 4,
    seed: int = 0,
    initial: AttitudeFit | None = None,
    progress: bool | None = None,
    chain_method: str | None = None,
) -> AttitudePosterior:
    r"""The posterior of a free rigid body's inertia ratios, angular velocity and attitude, by NUTS.

    The parameters are those of :func:`frbjax.fit_attitude`,
    $\theta = (\log I_2/I_1, \log I_3/I_1, \Omega(t_\text{ref}), \delta)$ (and $\psi$, the rotation
    vector of the principal axes, for ``inertia="tensor"``), all unconstrained: the attitude at the
    reference time (the sample time nearest 0) is $q_\text{ref} \otimes \exp(\delta/2)$ about the
    observed attitude $q_\text{ref}$ there, a tangent vector without the sign ambiguity of $q$.

    Likelihood: isotropic Gaussian attitude noise of ``attitude_sigma`` radians on the rotation
    residual of the fit, $r_k = 2\,\mathrm{sign}(e_w)\, e_\text{vec}$ with
    $e = \bar q_\text{model}(t_k) \otimes q_k$, and, with ``angular_velocity_data`` (N, 3), Gaussian
    gyro noise of ``angular_velocity_sigma`` on each component:

    $$\log p(\text{data} \mid \theta) = -\frac{1}{2\sigma_q^2} \sum_k |r_k|^2
      - \frac{1}{2\sigma_\omega^2} \sum_k |\Omega_\text{model}(t_k) - \Omega_k|^2 + \text{const}.$$

    Default prior (each replaceable, by key, by a numpyro distribution in the dict ``prior``):

    - ``"log_inertia_ratios"``: `TriangleLogUniform`: $\log I_2/I_1$ and $\log I_3/I_1$ uniform in
      $[-\log 100, \log 100]$, weighted by a smooth step (width 0.01 in $(I_a + I_b - I_c)/I_c$) at
      the triangle inequality $I_a + I_b \ge I_c$;
    - ``"angular_velocity"``: each component of $\Omega(t_\text{ref})$ normal with mean 0 and a
      standard deviation 10 times the magnitude of the data's finite-difference rate at
      $t_\text{ref}$ (broad, and scaled to the data: an empirical choice; pass a prior of your own
      for a calibrated analysis);
    - ``"attitude"``: `IsotropicRotation`, the uniform distribution of rotations (in $\delta$);
    - ``"principal_axes"`` (tensor only): `IsotropicRotation` of $\psi$.

    A user's distribution must have values of the block's size ((2,) or (3,), as batch and event
    shape together, or a scalar distribution, applied to each entry).  Outside its support the
    log density is $-\infty$: a bounded prior is a wall that NUTS reports as divergences when the
    posterior reaches it; prefer smooth priors.

    Sampling: numpyro's NUTS (target acceptance 0.8, tree depth 10) on the whitened parameters $z$,
    $\theta = \hat\theta + C^{1/2} z$, with $\hat\theta$ and $C$ the fit's parameters and
    covariance (``initial``, or :func:`frbjax.fit_attitude` run on the data with the same sigmas and
    ``inertia`` option, without its triangle-inequality penalty: the prior brings that).  Chain 0
    starts at the fit; chains 1, 2, ... at the fit's distinct runner-up basins (converged starts
    within 10 of the fit's cost and more than 5 of its standard deviations from it and from each
    other), so that a second mode that the fit's starts found is explored; the remaining chains at
    $z$ drawn from a standard normal (``seed``), the fit's covariance.
    A fit outside a bounded prior's support (a truth next to its edge) starts the chains, block by
    block, just inside the edge (on the way to the nearest of 512 prior draws); a fit further than
    20 of its standard deviations from the support is refused (the prior excludes the data).
    Chains from one fit explore its mode: a second mode far from it (another period alias) is found
    only by a chain started near it.  ``num_warmup`` adaptation steps (step size and
    diagonal mass matrix), then ``num_samples`` draws per chain; ``chain_method``: "sequential"
    (one chain after another, ``lax.map``: the default on CPU) or "vectorized" (the chains as one
    batch, ``jax.vmap``: the default elsewhere).  On CPU (two cores, 40 samples, 4 chains of 300 +
    300 steps) sequential chains ran in 3.2 s against 5.1 s, and compiled in 19 s against 26 s:
    batched NUTS trees run every chain to the deepest tree of the batch.  One compiled program per
    sizes (samples, chains, warmup, draws, chain method): later calls with other data or priors of
    the same kinds reuse it.

    ``progress``: a progress bar (tqdm) while sampling; by default shown in a terminal or an IPython
    session, not otherwise (tests, scripts whose output goes to a file).

    Returns :class:`AttitudePosterior`.  A `PosteriorWarning` is issued when the largest split R-hat
    exceeds 1.01 or any transition diverged.  Refused with a ValueError naming the argument: the
    data errors of :func:`frbjax.fit_attitude`, non-positive sigmas, gyro data without
    ``angular_velocity_sigma``, counts below their minimum (``num_chains`` >= 1, ``num_samples``
    >= 4, ``num_warmup`` >= 0), unknown options, a prior with unknown keys or wrong shapes or
    that excludes the fit, and an ``initial`` fit of other data or another ``inertia``.
    Runs in the dtype of the data: enable float64.
    """
    checks.choice("inertia", inertia, ("principal", "tensor"))
    if chain_method is None:
        chain_method = "sequential" if starts_in_sequence() else "vectorized"
    checks.choice("chain_method", chain_method, _CHAIN_METHODS)
    attitude_sigma = checks.scalar("attitude_sigma", attitude_sigma, positive=True)
    if angular_velocity_sigma is not None:
        angular_velocity_sigma = checks.scalar("angular_velocity_sigma", angular_velocity_sigma, positive=True)
    elif angular_velocity_data is not None:
        raise ValueError("angular_velocity_sigma must be given (> 0) with angular_velocity_data")
    num_chains = checks.integer("num_chains", num_chains, minimum=1)
    num_samples = checks.integer("num_samples", num_samples, minimum=4)
    num_warmup = checks.integer("num_warmup", num_warmup, minimum=0)
    seed = checks.integer("seed", seed, minimum=0)
    progress = _progress.check_option(progress)
    if initial is not None and not isinstance(initial, AttitudeFit):
        raise ValueError(f"initial must be an AttitudeFit (from fit_attitude) or None, got {type(initial).__name__}")
    times_np, q_np, gyro_np, _, dtype = _checked_data(times, quaternions, angular_velocity_data, "raise")
    tensor = inertia == "tensor"
    n_parameters = _TENSOR_PARAMETERS if tensor else _PRINCIPAL_PARAMETERS

    # The fit's reference: the sample time nearest 0 and the observed attitude there (w >= 0).
    order, times_sorted, q_sorted, index, reference_time, reference = _reference_sample(times_np, q_np)
    rate = _finite_difference_rate(times_sorted, q_sorted, index, 3)
    rate_scale = DEFAULT_RATE_SCALE * max(float(np.linalg.norm(rate)), 1e-300)
    prior = _checked_prior(prior, tensor, rate_scale)

    if initial is None:
        initial = fit_attitude(
            times_np,
            q_np,
            angular_velocity_data=gyro_np,
            attitude_sigma=attitude_sigma,
            angular_velocity_sigma=1.0 if angular_velocity_sigma is None else angular_velocity_sigma,
            inertia=inertia,
            seed=seed,
            throw=False,
        )
        if not np.all(np.isfinite(np.asarray(initial.parameters))):
            raise FitError("attitude_posterior: fit_attitude found no finite start for the chains", initial)
    else:
        if initial.parameters.shape != (n_parameters,):
            raise ValueError(
                f"initial must be a fit with inertia={inertia!r} ({n_parameters} parameters), "
                f"got {initial.parameters.shape[0]} parameters"
            )
        if float(initial.reference_time) != float(reference_time):
            raise ValueError(
                f"initial must be a fit of these data: its reference time {float(initial.reference_time)!r} "
                f"is not theirs ({reference_time!r})"
            )

    center, chol = _whitening(initial.parameters, initial.covariance)
    as_array = lambda value: jnp.asarray(value, dtype)  # noqa: E731
    data = dict(
        times=as_array(times_sorted - reference_time),
        quaternions=as_array(q_sorted),
        angular_velocity_data=as_array(np.zeros_like(q_sorted[:, 1:]) if gyro_np is None else gyro_np[order]),
        attitude_weight=as_array(1.0 / attitude_sigma),
        gyro_weight=as_array(0.0 if gyro_np is None else 1.0 / angular_velocity_sigma),
        reference=as_array(reference),
        center=as_array(center),
        chol=as_array(chol),
        time_zero=as_array(-reference_time),
    )
    key = jax.random.key(seed)
    start_key, chain_key = jax.random.split(key)
    z0, mode_chains = _chain_starts(
        center, chol, prior, start_key, num_chains, dtype, _runner_up_modes(initial, tensor)
    )
    keys = jax.random.split(chain_key, num_chains)
    out = sampler.run(
        jnp.asarray(z0, dtype),
        keys,
        data,
        prior,
        num_warmup=num_warmup,
        num_samples=num_samples,
        vectorized=chain_method == "vectorized",
        progress=progress,
    )
    return _result(out, initial, reference_time, tensor, num_chains, dtype, mode_chains)


_log_priors = jax.jit(jax.vmap(sampler.log_prior, in_axes=(0, None)))
# Prior draws among which a start inside the prior's support is sought when the fit is outside it.
_SUPPORT_CANDIDATES = 512
# A fit further outside the prior's support than this (in its whitened units, the nearest prior draw)
# is an error (a prior that excludes the data), not a truth next to the prior's edge.
_OUTSIDE_LIMIT = 20.0

# Runner-up basins of the fit that start chains: converged starts whose cost is within this of the
# best (a posterior density exp(-cost) at most e^-10 of the fit's: below that a basin holds no mass
# worth a chain unless it is far broader), and further than this from the fit and from each other,
# in the fit's standard deviations (closer ones are the fit's own basin, which the jittered chains
# explore anyway).
_MODE_COST_GAP = 10.0
_MODE_SEPARATION = 5.0


def _edge_point(theta, block, inside_value, prior, dtype, steps=50):
    """The point of the segment from theta[block] (outside the prior's support) to ``inside_value``
    (inside it) just inside the support's edge, by bisection (the first inside for a convex support)."""
    outside_value = theta[block].copy()
    low, high = 0.0, 1.0  # fractions of the way to inside_value: outside at low, inside at high
    trial = theta.copy()
    for _ in range(steps):
        middle = 0.5 * (low + high)
        trial[block] = outside_value + middle * (inside_value - outside_value)
        if np.isfinite(float(_log_priors(jnp.asarray(trial[None], dtype), prior)[0])):
            high = middle
        else:
            low = middle
    return outside_value + high * (inside_value - outside_value)


def _runner_up_modes(fit, tensor):
    """The parameters of the fit's distinct runner-up basins (best first; ``_MODE_COST_GAP``,
    ``_MODE_SEPARATION``).  Distances: the parameters whitened by the fit's covariance; for a tensor
    fit the tensor's entries (in their standard deviations) in place of the moments and the axes'
    rotation vector, which name one tensor in several ways (axes relabelled or reversed)."""
    costs = np.asarray(fit.start_costs, float)
    parameters = np.asarray(fit.start_parameters, float)
    covariance = np.asarray(fit.covariance, float)
    candidates = np.flatnonzero(
        np.asarray(fit.start_success) & np.isfinite(costs) & (costs <= float(fit.cost) + _MODE_COST_GAP)
    )
    candidates = candidates[np.argsort(costs[candidates], kind="stable")]
    motion = slice(2, 8)  # the angular velocity and the attitude's tangent: one meaning in every fit
    motion_root = np.linalg.cholesky(covariance[motion, motion] + 1e-300 * np.eye(6))
    if tensor:
        tensor_covariance = np.asarray(fit.inertia_tensor_covariance, float)
        tensor_sigma = np.sqrt(np.maximum(np.einsum("ijij->ij", tensor_covariance), 1e-300))

    shape_root = np.linalg.cholesky(covariance[:2, :2] + 1e-300 * np.eye(2))

    def signature(theta):
        whitened_motion = np.linalg.solve(motion_root, theta[motion])
        if tensor:
            return np.concatenate([(_scaled_tensor(theta)[2] / tensor_sigma).reshape(-1), whitened_motion])
        return np.concatenate([np.linalg.solve(shape_root, theta[:2]), whitened_motion])

    kept = [signature(np.asarray(fit.parameters, float))]
    modes = []
    for index in candidates:
        candidate = signature(parameters[index])
        if all(np.linalg.norm(candidate - other) > _MODE_SEPARATION for other in kept):
            kept.append(candidate)
            modes.append(parameters[index])
    return modes


def _chain_starts(center, chol, prior, key, num_chains, dtype, modes=()):
    """(whitened starts (num_chains, P), how many chains start at runner-up basins): chain 0 at the
    fit, chains 1, 2, ... at the runner-up basins ``modes`` (those inside the prior's support, as
    many as there are chains), the others jittered
    about the fit by a standard normal (halved until inside the prior's support).  A fit outside the
    support (a truth next to a bounded prior's edge) starts instead, block by block, just inside the
    edge (``_edge_point``)."""
    start = np.asarray(center, float).copy()
    if not np.isfinite(float(_log_priors(jnp.asarray(start[None], dtype), prior)[0])):
        for name, distribution in prior.items():
            block = PARAMETER_BLOCKS[name][0]
            inside = np.isfinite(float(_log_priors(jnp.asarray(start[None], dtype), {name: distribution})[0]))
            if not inside:
                key, subkey = jax.random.split(key)
                draws = np.asarray(distribution.sample(subkey, (_SUPPORT_CANDIDATES,)), float)
                nearest = draws[np.argmin(np.sum((draws - start[block]) ** 2, axis=-1))]
                start[block] = _edge_point(start, block, nearest, {name: distribution}, dtype)
        if not np.isfinite(float(_log_priors(jnp.asarray(start[None], dtype), prior)[0])):
            raise ValueError(
                "prior has zero density at the fit's parameters and at the draws of its own nearest to them: "
                f"theta = {np.asarray(center).round(6).tolist()}"
            )
    z_start = np.linalg.solve(chol, start - center)
    if np.linalg.norm(z_start) > _OUTSIDE_LIMIT:
        raise ValueError(
            f"prior excludes the data's parameters: the fit lies {np.linalg.norm(z_start):.3g} of its standard "
            f"deviations (whitened) outside the prior's support; theta = {np.asarray(center).round(6).tolist()}"
        )
    jitter = np.array(jax.random.normal(key, (num_chains, len(center)), dtype), float)
    jitter[0] = 0.0
    starts = z_start + jitter
    for _ in range(10):
        thetas = center + starts @ chol.T
        outside = ~np.isfinite(np.asarray(_log_priors(jnp.asarray(thetas, dtype), prior)))
        if not np.any(outside):
            break
        starts[outside] = z_start + (starts[outside] - z_start) / 2
    else:
        starts[outside] = z_start
    inside = [m for m in modes if np.isfinite(float(_log_priors(jnp.asarray(np.asarray(m)[None], dtype), prior)[0]))]
    inside = inside[: num_chains - 1]
    for chain, mode in enumerate(inside, start=1):
        starts[chain] = np.linalg.solve(chol, np.asarray(mode, float) - center)
    return jnp.asarray(starts, dtype), len(inside)


def _result(out, fit, reference_time, tensor, num_chains, dtype, mode_chains=0):
    """AttitudePosterior from the sampler's draws (numpy), with its diagnostics and warning."""
    parameters = np.asarray(out["parameters"], float)  # (C, D, P)
    draws_per_chain, n_parameters = parameters.shape[1:]
    flat = parameters.reshape(-1, n_parameters)
    omega0 = np.asarray(out["angular_velocity"], float).reshape(-1, 3)
    attitude0 = np.asarray(out["attitude"], float).reshape(-1, 4)
    attitude0 = np.where(attitude0[:, :1] < 0, -attitude0, attitude0)
    if tensor:
        moments, axes = [], []
        for theta in flat:
            m, a, _ = _scaled_tensor(theta)
            moments.append(m)
            axes.append(a)
        moments, axes = np.asarray(moments), np.asarray(axes)
        rates_in_axes = np.einsum("sji,sj->si", axes, omega0)
    else:
        moments = np.asarray([_normalised_inertia(theta)[0] for theta in flat])
        axes = np.broadcast_to(np.eye(3), (len(flat), 3, 3))
        rates_in_axes = omega0
    long_axis = long_axis_mode(moments, rates_in_axes)
    names = tuple(name for block in PARAMETER_BLOCKS.values() for name in block[1])[:n_parameters]
    diverging = np.asarray(out["diverging"], bool)
    divergences = diverging.sum(axis=1)
    r_hat = split_r_hat(parameters)
    as_float = lambda value: jnp.asarray(value, dtype)  # noqa: E731
    result = AttitudePosterior(
        inertia=as_float(moments),
        principal_axes=as_float(axes),
        angular_velocity=as_float(omega0),
        attitude=as_float(attitude0),
        parameters=as_float(flat),
        long_axis_mode=jnp.asarray(long_axis),
        chain=jnp.asarray(np.repeat(np.arange(num_chains), draws_per_chain)),
        diverging=jnp.asarray(diverging.reshape(-1)),
        r_hat=as_float(r_hat),
        ess_bulk=as_float(bulk_ess(parameters)),
        ess_tail=as_float(tail_ess(parameters)),
        divergences=jnp.asarray(divergences),
        step_size=as_float(np.asarray(out["step_size"]).reshape(num_chains)),
        acceptance=as_float(np.asarray(out["acceptance"]).reshape(num_chains)),
        mean_steps=as_float(np.asarray(out["num_steps"], float).mean(axis=1)),
        fit=fit,
        reference_time=as_float(reference_time),
        parameter_names=names,
        num_chains=num_chains,
    )
    problems = []
    worst = float(np.nanmax(r_hat)) if np.any(np.isfinite(r_hat)) else np.inf
    if not worst <= R_HAT_LIMIT:
        problems.append(f"largest split R-hat {worst:.4f} > {R_HAT_LIMIT} ({names[int(np.nanargmax(r_hat))]})")
    if divergences.sum():
        problems.append(f"{int(divergences.sum())} divergent transitions (per chain {divergences.tolist()})")
    if mode_chains and not worst <= R_HAT_LIMIT:
        problems.append(
            f"chains 1 to {mode_chains} started in the fit's runner-up basins and did not mix with chain 0: the "
            "pooled draws weight each basin by its number of chains, not by its probability (compare the chains: "
            "`chain`)"
        )
    if problems:
        warnings.warn(
            "attitude_posterior: "
            + "; ".join(problems)
            + ": the draws may not represent the posterior (run longer chains, or look for several modes)",
            PosteriorWarning,
            stacklevel=3,
        )
    return result
