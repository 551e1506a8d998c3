"""numpyro's NUTS over whitened parameters: the potential, and one compiled program per run's sizes.

The sampled vector is z, with theta = center + chol @ z (center: the fit's parameters, chol: the
Cholesky factor of its covariance): where the posterior is close to the fit's Gaussian, z is close
to standard normal and NUTS starts with a well-scaled, decorrelated target (step size about 1, a
few leapfrog steps per draw).  The map is linear, so its Jacobian is a constant and the posterior
of theta is that of z.  numpyro's diagonal mass matrix adaptation corrects what the fit's
covariance misses.

The program (``_run``) is jitted once per (samples, parameters, chains, warmup, draws, chain method)
and takes everything else as arguments: the data, the whitening and the prior's
distributions (numpyro distributions are pytrees), so a second posterior of the same sizes runs
without compiling.  It holds numpyro's ``init_kernel`` and ``sample_kernel`` (``numpyro.infer.hmc.hmc``,
algorithm NUTS) in one ``lax.fori_loop`` over warmup and draws, the chains by ``jax.vmap``
("vectorized") or one after another by ``lax.map`` ("sequential"), and the motion at t = 0 of every
draw.  It advances the progress bar (``frbjax._progress``) through ``jax.debug.callback`` every
fiftieth of the run, whether a bar is shown or not.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from numpyro.infer.hmc import hmc

from .. import _progress
from .._kernel_path import keyed_by_path
from ..fit import _attitude_residual, _model
from ._prior import PARAMETER_BLOCKS


# NUTS settings (numpyro's defaults, written out).
TARGET_ACCEPT_PROB = 0.8
MAX_TREE_DEPTH = 10
# The potential's gradient by forward mode (P tangents in one pass, as the fits' Jacobians): the
# motion's derivatives are forward-mode rules, and the program compiles in 25.5 s against 32.3 s by
# reverse mode (vectorized chains, 40 samples, two cores), running as fast.
FORWARD_MODE = True


def log_prior(theta, prior):
    """Sum of the prior's log densities at theta; -inf outside a distribution's support."""
    total = jnp.zeros((), theta.dtype)
    for name, distribution in prior.items():
        value = theta[PARAMETER_BLOCKS[name][0]]
        inside = jnp.all(distribution.support(value))
        log_density = jnp.sum(distribution.log_prob(value))
        total = total + jnp.where(inside, log_density, -jnp.inf)
    return total


def log_likelihood(theta, data):
    """Gaussian attitude residuals (those of ``fit_attitude``) and gyro residuals, up to a constant."""
    q_model, omega_model = _model(theta, data["reference"], data["times"], 1.0)
    residual = _attitude_residual(q_model, data["quaternions"])
    gyro = omega_model - data["angular_velocity_data"]
    attitude_part = jnp.sum(residual * residual) * data["attitude_weight"] ** 2
    gyro_part = jnp.sum(gyro * gyro) * data["gyro_weight"] ** 2
    return -0.5 * (attitude_part + gyro_part)


def parameters_of(z, data):
    """theta = center + chol @ z (z of any leading shape)."""
    center = data["center"].reshape((1,) * (z.ndim - 1) + data["center"].shape)
    return center + z @ data["chol"].T


def _potential_generator(data, prior):
    def potential(z):
        theta = parameters_of(z, data)
        value = -(log_likelihood(theta, data) + log_prior(theta, prior))
        # NaN (a body the motion cannot evaluate) as an infinite potential: NUTS rejects it.
        return jnp.where(jnp.isnan(value), jnp.inf, value)

    return potential


@functools.cache
def _kernels(num_warmup, potential_generator):
    """numpyro's NUTS (init_kernel, sample_kernel) for the potentials ``potential_generator(data,
    prior)``.  One pair per warmup length: ``hmc`` keeps the warmup's settings of the last
    ``init_kernel`` trace."""
    return hmc(potential_fn_gen=potential_generator, algo="NUTS")


def _chain_loop(
    z0, key, data, prior, num_warmup, num_samples, progress_every, vectorized, potential_generator, forward_mode
):
    """Warmup and draws of one chain, or of a batch of chains (``vectorized``: leading axis)."""
    init_kernel, sample_kernel = _kernels(num_warmup, potential_generator)

    def init(z, key):
        return init_kernel(
            z,
            num_warmup,
            target_accept_prob=TARGET_ACCEPT_PROB,
            max_tree_depth=MAX_TREE_DEPTH,
            forward_mode_differentiation=forward_mode,
            model_args=(data, prior),
            rng_key=key,
        )

    def step(state):
        return sample_kernel(state, model_args=(data, prior))

    if vectorized:
        init, step = jax.vmap(init), jax.vmap(step)
    state = init(z0, key)
    draw_shape = z0.shape[:-1]
    collection = (
        jnp.zeros((num_samples,) + z0.shape, z0.dtype),
        jnp.zeros((num_samples,) + draw_shape, bool),
        jnp.zeros((num_samples,) + draw_shape, jnp.int32),
    )

    def body(i, carry):
        state, collection = carry
        state = step(state)
        index = jnp.maximum(i - num_warmup, 0)
        keep = i >= num_warmup
        new = (state.z, state.diverging, state.num_steps.astype(jnp.int32))
        collection = tuple(
            stored.at[index].set(jnp.where(keep, value, stored[index])) for stored, value in zip(collection, new)
        )
        if progress_every:
            jax.lax.cond(
                (i + 1) % progress_every == 0,
                lambda: jax.debug.callback(_progress.advance, "posterior", progress_every),
                lambda: None,
            )
        return state, collection

    state, collection = jax.lax.fori_loop(0, num_warmup + num_samples, body, (state, collection))
    draws, diverging, num_steps = collection
    axis = 1 if vectorized else 0  # draws (S, C, P) -> (C, S, P)
    return (
        jnp.moveaxis(draws, 0, axis) if vectorized else draws,
        jnp.moveaxis(diverging, 0, axis) if vectorized else diverging,
        jnp.moveaxis(num_steps, 0, axis) if vectorized else num_steps,
        state.adapt_state.step_size,
        state.mean_accept_prob,
    )


def _chains(
    z0, keys, data, prior, num_warmup, num_samples, progress_every, vectorized, potential_generator, forward_mode
):
    """Every chain's (draws, diverging, num_steps, step size, acceptance), leading axis the chain."""
    options = (num_warmup, num_samples, progress_every)
    if vectorized:
        return _chain_loop(z0, keys, data, prior, *options, True, potential_generator, forward_mode)
    return jax.lax.map(
        lambda start: _chain_loop(*start, data, prior, *options, False, potential_generator, forward_mode),
        (z0, keys),
    )


@keyed_by_path(static_argnames=("num_warmup", "num_samples", "progress_every", "vectorized"))
def _run(z0, keys, data, prior, *, num_warmup, num_samples, progress_every, vectorized):
    out = _chains(
        z0, keys, data, prior, num_warmup, num_samples, progress_every, vectorized, _potential_generator, FORWARD_MODE
    )
    draws = out[0]
    thetas = parameters_of(draws, data)
    # The motion of each draw at t = 0 (the data's times are relative to the reference time).
    at_zero = data["time_zero"][None]
    flat = thetas.reshape(-1, thetas.shape[-1])
    q0, omega0 = jax.vmap(lambda theta: _model(theta, data["reference"], at_zero, 1.0))(flat)
    return dict(
        parameters=thetas,
        attitude=q0[:, 0].reshape(thetas.shape[:-1] + (4,)),
        angular_velocity=omega0[:, 0].reshape(thetas.shape[:-1] + (3,)),
        diverging=out[1],
        num_steps=out[2],
        step_size=out[3],
        acceptance=out[4],
    )


@keyed_by_path(
    static_argnames=(
        "num_warmup",
        "num_samples",
        "progress_every",
        "vectorized",
        "potential_generator",
        "forward_mode",
    ),
)
def _run_chains(
    z0, keys, data, prior, *, num_warmup, num_samples, progress_every, vectorized, potential_generator, forward_mode
):
    draws, diverging, num_steps, step_size, acceptance = _chains(
        z0, keys, data, prior, num_warmup, num_samples, progress_every, vectorized, potential_generator, forward_mode
    )
    return dict(draws=draws, diverging=diverging, num_steps=num_steps, step_size=step_size, acceptance=acceptance)


def run(
    z0,
    keys,
    data,
    prior,
    *,
    num_warmup,
    num_samples,
    vectorized,
    progress,
    potential_generator=None,
    forward_mode=FORWARD_MODE,
):
    """The chains' draws (dict of arrays, leading axes (chains, draws)), with a tqdm bar if ``progress``.

    Without ``potential_generator``: the attitude posterior's program (``_run``: the potential of
    this module, the draws' motion at t = 0).  With it (a module-level function, or one cached per
    static setting, so that a second call finds the program compiled): NUTS on
    ``potential_generator(data, prior)``, the draws in whitened coordinates (``draws``); sequential
    chains then run one program call each, so that one program serves every number of chains.
    ``forward_mode`` (with ``potential_generator``): the potential's gradient by forward mode (one
    tangent per sampled parameter: for a few) or by reverse mode (for many, or where the potential's
    reverse pass is the cheaper, as the light-curve posterior's)."""
    total = num_warmup + num_samples
    # The bar's callbacks are in the program whether it is shown or not: showing it compiles nothing.
    progress_every = max(total // 50, 1)
    arguments = dict(
        num_warmup=num_warmup,
        num_samples=num_samples,
        progress_every=progress_every,
        vectorized=vectorized,
    )
    chains = z0.shape[0]
    custom = dict(potential_generator=potential_generator, forward_mode=forward_mode)
    with _progress.bar("posterior", total * (1 if vectorized else chains), "NUTS", "it", shown=progress):
        if potential_generator is None:
            return jax.device_get(jax.block_until_ready(_run(z0, keys, data, prior, **arguments)))
        if vectorized:
            return jax.device_get(jax.block_until_ready(_run_chains(z0, keys, data, prior, **custom, **arguments)))
        # Sequential chains one program call each (a batch of one): the program is compiled once
        # whatever the number of chains, so that runs of other chain counts find it compiled.
        each = [
            jax.device_get(
                jax.block_until_ready(
                    _run_chains(
                        z0[chain : chain + 1],
                        keys[chain : chain + 1],
                        data,
                        prior,
                        **custom,
                        **arguments,
                    )
                )
            )
            for chain in range(chains)
        ]
        return {name: np.concatenate([out[name] for out in each]) for name in each[0]}
