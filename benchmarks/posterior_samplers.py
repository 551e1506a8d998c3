"""NUTS with the exact gradients against numpyro's gradient-free ensemble samplers, and the wall time
of attitude_posterior (issue 39, "Benchmark").

1. Effective samples per second, one core.  One attitude posterior: a triaxial body (moments
   0.6 : 0.8 : 1, Omega(0) = (0.4, 0.3, 0.8) rad/s, a random attitude), the 40 uneven times of
   tests/test_posterior.py (about three rotation periods) with 1e-3 rad isotropic attitude noise
   (its data generator ``observed``), the default prior.  Every sampler runs on the same potential:
   the whitened one of frbjax.posterior._sampler (theta = center + chol @ z, center and chol from
   fit_attitude, as attitude_posterior builds it), from the same kind of starts (the fit, and the fit
   jittered by a standard normal in z):

   - NUTS: frbjax.posterior._sampler's compiled program (numpyro's NUTS, forward-mode gradients of
     the exact motion), 4 chains one after another ("sequential", the CPU default), and the same
     4 chains as one batch ("NUTS vectorized", for comparison);
   - AIES: ``numpyro.infer.AIES`` (affine-invariant ensemble, differential-evolution move);
   - ESS: ``numpyro.infer.ESS`` (ensemble slice sampling, differential move, tuned scale);

   the ensembles vectorized (``chain_method="vectorized"``: num_chains = the number of walkers), each
   kernel's ``init`` and ``sample`` (numpyro's ``sample`` moves both halves of the ensemble) driven
   by one jitted ``lax.fori_loop`` over warmup and draws, as ``MCMC``'s ``fori_collect`` does
   (``MCMC.run`` with a ``potential_fn`` recompiles its loop on every call: 4 s each).  Each
   sampler runs twice with the same sizes: the first call compiles (its excess over the second is
   reported as the compile time), the second is timed.  ESS/s = bulk effective sample size
   (``numpyro.diagnostics.effective_sample_size``, chains or walkers as the chain axis) of each of
   the 8 parameters theta over the second call's wall time (warmup and draws together, compilation
   excluded); reported for the two inertia log-ratios and the minimum over all parameters, with the
   ratios NUTS / AIES and NUTS / ESS (issue target: >= 20 for the inertia ratios), and each sampler's
   largest split R-hat (converged: < 1.05).  This part runs in a child process pinned to one core
   (``taskset -c 0``, or ``os.sched_setaffinity`` where taskset is missing).

   The bound (``bound_at_value_cost`` in each ratio): the potential's value at one point is timed
   inside a compiled loop (``potential_value_seconds``), and NUTS's effective samples are divided by
   its draws' leapfrog steps times that (``seconds_floor``): the ESS/s of a NUTS that spent on each
   step one evaluation of the value and nothing else (no gradient, no tree building, no warmup), a
   ceiling for any implementation of the same sampler on the same posterior.  Against an ensemble's
   measured ESS/s it bounds the ratio any work on NUTS's gradients could reach
   (``target_20x_reachable``: the bound >= 20).

2. Wall time of a 4-chain posterior of 200 attitudes (200 uneven times over 40 s, same body kind and
   noise) through the public ``attitude_posterior(times, q, attitude_sigma=1e-3, num_chains=4)`` with
   its defaults (500 warmup steps, 1000 draws, the fit included): the first call (compilation of
   the fit and the sampler included) and a second call with new data of the same size (compiled).
   Runs in a second child process, unpinned (the machine's cores; the figures of the issue are for
   two).  Issue target: under a minute.

Measured (2026-11-28, one core of a 2-core x86 CPU, the sizes of FULL below): ESS/s of the inertia
log-ratios NUTS 690-720, NUTS vectorized 540, AIES 790-800, ESS 2860-2920, all converged (split
R-hat <= 1.005) with the same posterior means and standard deviations (to 2%): NUTS / AIES 0.86 and
NUTS / ESS 0.24, the issue's 20x target not met on this posterior.  It is an easy one for the
ensembles: 8 parameters, whitened to nearly standard normal, where a potential evaluation batched
over 16 walkers costs 0.2 ms and one forward-mode gradient (8 tangents) 0.25 ms.  The walkers'
ESS treats them as independent chains, which they are not (each move uses the other half of the
ensemble).  attitude_posterior for 200 attitudes: 54.5 s first call, 38.9 s second (two cores).
Again on 2026-11-29 (a body's derivatives from its series on dual numbers: the model's
value_and_grad 89 us against 256 us): NUTS 911, NUTS vectorized 765, AIES 1224, ESS 6752 (the
ensembles' code unchanged and faster too: this machine's speed varies between runs), NUTS / AIES
0.74 and NUTS / ESS 0.13; attitude_posterior for 200 attitudes 24.5 s first call, 15.8 s second.
Again on 2026-12-03 (a faster run of the same machine type): NUTS 2276, NUTS vectorized 1640, AIES
2894, ESS 10342; NUTS / AIES 0.79 and NUTS / ESS 0.22; the potential's value 4.8 us and its value
and gradient 64 us, so that NUTS / AIES could reach at most 1.3 at the gradient's cost and 17.4 at
the value's, NUTS / ESS 0.37 and 4.9 (a run an hour earlier timed the value at 3.9 us: 25 and 7.5);
attitude_posterior for 200 attitudes 19.7 s first call, 12.4 s second.

3. ``--lightcurve`` (run on its own: about a quarter of an hour): effective samples per second on a
   light-curve posterior, the short-axis tumbler of benchmarks/lightcurve_posterior.py (384 samples,
   320 facets, the shape held: 8 motion parameters), NUTS through ``lightcurve_posterior`` (4 chains
   of 300 + 300) and AIES and ESS (32 walkers) on its own whitened potential, each called once with
   its compilation (seconds against minutes); writes posterior_samplers_lightcurve.json.
   Measured 2026-12-03: log I1 and log I2 NUTS 5.7 and 15.2, AIES 3.4 and 10.3 (not converged:
   R-hat 1.087), ESS 78 and 94; the value 106 us, value and gradient 916 us: NUTS / AIES at most 4.4
   at the gradient's cost and 38 at the value's, NUTS / ESS 0.22 and 1.9.

Writes benchmarks/results/posterior_samplers.json and posterior_samplers.png (ESS/s per sampler,
log scale).  ``--quick``: tiny sizes (a smoke test of a few seconds of sampling, plus compilation).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/posterior_samplers.py [--quick] [--lightcurve]
        [--output-dir DIR]

(the script starts ``taskset -c 0`` for parts 1 and 3 itself; ``--part samplers``, ``wall`` or
``lightcurve`` runs one part in the current process and prints its JSON).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import shutil
import subprocess
import sys
import time


ROOT = pathlib.Path(__file__).resolve().parents[1]

# Part 1 sizes: (chains or walkers, warmup, draws); part 2: attitudes, and attitude_posterior's sizes.
FULL = dict(
    nuts=(4, 500, 1000),
    aies=(32, 6000, 6000),
    ess=(32, 2000, 2000),
    wall_attitudes=200,
    wall_steps=(500, 1000),
    lightcurve_nuts=(4, 300, 300),
    lightcurve_aies=(32, 3000, 3000),
    lightcurve_ess=(32, 1000, 1000),
)
QUICK = dict(
    nuts=(4, 50, 50),
    aies=(16, 200, 200),
    ess=(16, 50, 50),
    wall_attitudes=200,
    wall_steps=(50, 50),
    lightcurve_nuts=(2, 20, 20),
    lightcurve_aies=(16, 50, 50),
    lightcurve_ess=(16, 20, 20),
)
MOMENTS = (0.6, 0.8, 1.0)
CONVERGED_R_HAT = 1.05
WALL_SPAN_SECONDS = 40.0


def _load_problems():
    """tests/test_posterior.py as a module (its data generator ``observed`` and ``TIMES``)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("_posterior_problems", ROOT / "tests" / "test_posterior.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _machine():
    import jax

    return {
        "backend": jax.default_backend(),
        "device": str(jax.devices()[0]),
        "cpus": os.cpu_count(),
        "affinity": sorted(os.sched_getaffinity(0)),
        "platform": platform.platform(),
        "jax": jax.__version__,
    }


def _data_set(problems, times, rng):
    """Noisy attitudes of a 0.6 : 0.8 : 1 body with Omega(0) = (0.4, 0.3, 0.8) and a random attitude."""
    import numpy as np

    attitude = rng.normal(size=4)
    attitude = attitude / np.linalg.norm(attitude) * np.sign(attitude[0])
    return problems.observed(np.asarray(MOMENTS), np.asarray(problems.PRIOR_RATE), attitude, times, rng)


def _whitened_problem(times, q, sigma):
    """(data, prior, center, chol) of attitude_posterior's sampler for these data (principal axes, no
    gyro, the default prior), built with frbjax.posterior's own functions, as attitude_posterior does."""
    import jax.numpy as jnp
    import numpy as np

    from frbjax.fit import _finite_difference_rate, fit_attitude
    from frbjax.posterior import _attitude

    times = np.asarray(times, float)
    order = np.argsort(times, kind="stable")
    times, q = times[order], np.asarray(q, float)[order]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    index = int(np.argmin(np.abs(times)))
    reference_time = times[index]
    reference = q[index] * (1.0 if q[index, 0] >= 0 else -1.0)
    rate = _finite_difference_rate(times, q, index, 3)
    prior = _attitude._checked_prior(None, False, _attitude.DEFAULT_RATE_SCALE * float(np.linalg.norm(rate)))
    fit = fit_attitude(times, q, attitude_sigma=sigma, angular_velocity_sigma=1.0, seed=0, throw=False)
    center, chol = _attitude._whitening(fit.parameters, fit.covariance)
    data = dict(
        times=jnp.asarray(times - reference_time),
        quaternions=jnp.asarray(q),
        angular_velocity_data=jnp.zeros((len(times), 3)),
        attitude_weight=jnp.asarray(1.0 / sigma),
        gyro_weight=jnp.asarray(0.0),
        reference=jnp.asarray(reference),
        center=jnp.asarray(center),
        chol=jnp.asarray(chol),
        time_zero=jnp.asarray(-reference_time),
    )
    return data, prior, center, chol


def _diagnostics(thetas, seconds, names):
    """Bulk ESS, ESS/s and split R-hat of draws thetas (chains, draws, P)."""
    import numpy as np
    from numpyro.diagnostics import effective_sample_size, split_gelman_rubin

    ess = np.asarray(effective_sample_size(thetas), float)
    r_hat = np.asarray(split_gelman_rubin(thetas), float)
    per_second = ess / seconds
    return {
        "seconds": seconds,
        "ess_bulk": dict(zip(names, ess.tolist())),
        "ess_per_second": dict(zip(names, per_second.tolist())),
        "ess_per_second_log_ratios": per_second[:2].tolist(),
        "ess_per_second_min_log_ratios": float(per_second[:2].min()),
        "ess_per_second_min_all": float(per_second.min()),
        "split_r_hat": dict(zip(names, r_hat.tolist())),
        "max_split_r_hat": float(r_hat.max()),
        "converged": bool(r_hat.max() < CONVERGED_R_HAT),
        "posterior_mean": dict(zip(names, thetas.reshape(-1, thetas.shape[-1]).mean(0).tolist())),
        "posterior_std": dict(zip(names, thetas.reshape(-1, thetas.shape[-1]).std(0).tolist())),
    }


def _timed(function):
    start = time.perf_counter()
    out = function()
    return out, time.perf_counter() - start


def _ensemble_row(kernel_class, potential, walkers, warmup, draws, starts, thetas_of, names, twice):
    """Run numpyro's ensemble kernel ``kernel_class`` (AIES or ESS) on ``potential`` and return its
    diagnostics row and draws z (walkers, draws, P).  ``twice``: run it twice with the same sizes and
    time the second call (the first compiles); otherwise one call, compilation included."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    kernel = kernel_class(potential_fn=potential)
    total = warmup + draws

    @jax.jit
    def chains_of(state):
        # numpyro's kernel step (both halves of the ensemble) in one compiled loop, as MCMC's
        # fori_collect does; MCMC.run itself recompiles on every call with a potential_fn.
        def body(i, carry):
            state, collection = carry
            state = kernel.sample(state, (), {})
            index = jnp.maximum(i - warmup, 0)
            collection = collection.at[index].set(jnp.where(i >= warmup, state.z, collection[index]))
            return state, collection

        collection = jnp.zeros((draws,) + state.z.shape, state.z.dtype)
        _, collection = jax.lax.fori_loop(0, total, body, (state, collection))
        return jnp.swapaxes(collection, 0, 1)  # (walkers, draws, P)

    def ensemble(seed):
        keys = jax.random.split(jax.random.PRNGKey(seed), walkers)
        state = kernel.init(keys, warmup, init_params=starts(walkers, seed), model_args=(), model_kwargs={})
        return np.asarray(jax.block_until_ready(chains_of(state)))

    if twice:
        _, first = _timed(lambda: ensemble(1))
    z, second = _timed(lambda: ensemble(2))
    row = _diagnostics(thetas_of(z), second, names)
    row.update(
        walkers=walkers,
        warmup=warmup,
        draws_per_walker=draws,
        chain_method="vectorized",
        first_call_seconds=first if twice else second,
        compile_seconds=first - second if twice else None,
    )
    return row, z


def _evaluation_seconds(potential, z, evaluations=2000):
    """Seconds of one evaluation at one point, inside a compiled loop (each evaluation depends on the
    last, so that none is hoisted or batched), of the potential's value and of its value and gradient
    (the cheaper of reverse and forward mode): what any NUTS step costs at least, whatever its
    bookkeeping's cost, and what it costs at least with the gradient it needs."""
    import jax
    import jax.numpy as jnp

    def reverse(z):
        value, gradient = jax.value_and_grad(potential)(z)
        return value + jnp.sum(gradient)

    def forward(z):
        value, tangents = jax.vmap(lambda v: jax.jvp(potential, (z,), (v,)), out_axes=(None, 0))(jnp.eye(len(z)))
        return value + jnp.sum(tangents)

    def seconds(function):
        @jax.jit
        def chain(z):
            def body(_, total):
                return total + function(z + 1e-300 * total)

            return jax.lax.fori_loop(0, evaluations, body, jnp.zeros((), z.dtype))

        jax.block_until_ready(chain(z))
        _, elapsed = _timed(lambda: jax.block_until_ready(chain(z)))
        return elapsed / evaluations

    return seconds(potential), min(seconds(reverse), seconds(forward))


def _ratios(results, nuts_label, keys, evaluation_seconds):
    """NUTS (the row ``nuts_label``) / each ensemble, in ESS/s, for the inertia log-ratios ``keys``, and
    two bounds on that ratio: for a NUTS whose every leapfrog step of the draws costs one evaluation of the potential's
    value and nothing more (no gradient, no tree building, no warmup), ESS / (gradient evaluations x
    the value's seconds) against the ensemble's measured ESS/s; and the same at the cost of the value
    and gradient (no tree building, no warmup).  Where the first is under 20, no work on NUTS's
    gradients reaches the issue's 20x on this posterior."""
    value_seconds, gradient_seconds = evaluation_seconds
    nuts = results[nuts_label]
    floor = nuts["gradient_evaluations"] * value_seconds
    nuts["potential_value_seconds"] = value_seconds
    nuts["potential_value_and_gradient_seconds"] = gradient_seconds
    nuts["seconds_floor"] = floor
    nuts["seconds_at_gradient_cost"] = nuts["gradient_evaluations"] * gradient_seconds
    ratios = {}
    for name in ("AIES", "ESS"):
        other = results[name]
        ratio = {key: nuts["ess_per_second"][key] / other["ess_per_second"][key] for key in keys}
        ratio["min_log_ratios"] = nuts["ess_per_second_min_log_ratios"] / other["ess_per_second_min_log_ratios"]
        ratio["min_all"] = nuts["ess_per_second_min_all"] / other["ess_per_second_min_all"]
        ratio["target_20x_met"] = bool(ratio["min_log_ratios"] >= 20)
        bound = min(nuts["ess_bulk"][key] / floor / other["ess_per_second"][key] for key in keys)
        ratio["bound_at_value_cost"] = bound
        ratio["bound_at_gradient_cost"] = bound * value_seconds / gradient_seconds
        ratio["target_20x_reachable"] = bool(bound >= 20)
        ratios[f"{nuts_label}/{name}"] = ratio
    return ratios


def samplers_part(sizes):
    """Part 1 (run pinned to one core): ESS/s of NUTS, AIES and ESS on one whitened potential."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np
    import numpyro
    from numpyro.infer import AIES, ESS

    from frbjax.posterior import _attitude, _sampler
    from frbjax.posterior._prior import PARAMETER_BLOCKS

    problems = _load_problems()
    times = problems.TIMES
    q = _data_set(problems, times, np.random.default_rng(39))
    data, prior, center, chol = _whitened_problem(times, q, problems.NOISE)
    names = [name for block in list(PARAMETER_BLOCKS.values())[:3] for name in block[1]]
    potential = _sampler._potential_generator(data, prior)

    def starts(count, seed):
        return _attitude._chain_starts(center, chol, prior, jax.random.key(seed), count, jnp.float64)[0]

    def thetas_of(z):
        return center + np.asarray(z, float) @ chol.T

    results = {}
    # NUTS: frbjax's compiled program, chains one after another ("sequential", attitude_posterior's
    # CPU default) and, for comparison, as one batch ("vectorized").
    chains, warmup, draws = sizes["nuts"]
    for label, vectorized in (("NUTS", False), ("NUTS vectorized", True)):

        def nuts(seed):
            keys = jax.random.split(jax.random.key(seed), chains)
            out = _sampler._run(
                starts(chains, seed),
                keys,
                data,
                prior,
                num_warmup=warmup,
                num_samples=draws,
                progress_every=0,
                vectorized=vectorized,
            )
            return jax.device_get(jax.block_until_ready(out))

        _, first = _timed(lambda: nuts(1))
        out, second = _timed(lambda: nuts(2))
        row = _diagnostics(np.asarray(out["parameters"], float), second, names)
        row.update(
            chains=chains,
            warmup=warmup,
            draws_per_chain=draws,
            chain_method="vectorized" if vectorized else "sequential",
            first_call_seconds=first,
            compile_seconds=first - second,
            mean_leapfrog_steps=float(np.mean(out["num_steps"])),
            gradient_evaluations=int(np.sum(out["num_steps"])),
            divergences=int(np.sum(out["diverging"])),
            step_size=np.asarray(out["step_size"]).tolist(),
        )
        results[label] = row
        print(
            f"{label}: {second:.2f} s (first {first:.2f} s), max R-hat {row['max_split_r_hat']:.4f}",
            file=sys.stderr,
        )

    for name, kernel_class in (("AIES", AIES), ("ESS", ESS)):
        walkers, warmup, draws = sizes[name.lower()]
        row, z = _ensemble_row(kernel_class, potential, walkers, warmup, draws, starts, thetas_of, names, twice=True)
        results[name] = row
        print(
            f"{name}: {row['seconds']:.2f} s (first {row['first_call_seconds']:.2f} s), "
            f"max R-hat {row['max_split_r_hat']:.4f}",
            file=sys.stderr,
        )

    seconds = _evaluation_seconds(potential, starts(1, 0)[0])
    ratios = {**_ratios(results, "NUTS", names[:2], seconds), **_ratios(results, "NUTS vectorized", names[:2], seconds)}
    return {
        "machine": _machine(),
        "numpyro": numpyro.__version__,
        "attitudes": len(times),
        "noise_rad": problems.NOISE,
        "moments": list(MOMENTS),
        "omega0": list(problems.PRIOR_RATE),
        "parameters": names,
        "samplers": results,
        "ratios": ratios,
    }


def wall_part(sizes):
    """Part 2: attitude_posterior's wall time for 200 attitudes, 4 chains, first and second call."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import warnings

    import numpy as np

    from frbjax.posterior import attitude_posterior

    problems = _load_problems()
    count = sizes["wall_attitudes"]
    warmup, draws = sizes["wall_steps"]
    rng = np.random.default_rng(200)
    times = np.concatenate([[0.0], np.sort(rng.uniform(0.0, WALL_SPAN_SECONDS, count - 1))])
    calls = []
    for call in range(2):
        q = _data_set(problems, times, np.random.default_rng(1000 + call))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result, seconds = _timed(
                lambda: attitude_posterior(
                    times,
                    q,
                    attitude_sigma=problems.NOISE,
                    num_chains=4,
                    num_warmup=warmup,
                    num_samples=draws,
                    progress=False,
                )
            )
        calls.append(
            {
                "seconds": seconds,
                "max_split_r_hat": float(np.nanmax(np.asarray(result.r_hat))),
                "divergences": int(np.sum(np.asarray(result.divergences))),
                "min_ess_bulk": float(np.min(np.asarray(result.ess_bulk))),
                "warnings": [str(w.message) for w in caught],
            }
        )
        print(f"attitude_posterior call {call + 1}: {seconds:.1f} s", file=sys.stderr)
    return {
        "machine": _machine(),
        "attitudes": count,
        "span_seconds": WALL_SPAN_SECONDS,
        "chains": 4,
        "warmup": warmup,
        "draws_per_chain": draws,
        "first_call_seconds": calls[0]["seconds"],
        "second_call_seconds": calls[1]["seconds"],
        "under_a_minute": bool(calls[1]["seconds"] < 60.0),
        "calls": calls,
    }


def lightcurve_part(sizes):
    """Part 3 (run pinned to one core): ESS/s of NUTS, AIES and ESS on a light-curve posterior.

    The short-axis tumbler of benchmarks/lightcurve_posterior.py (384 samples, 320 facets, 1% noise),
    its fit as there, the shape held (8 motion parameters); every sampler on lightcurve_posterior's
    own whitened potential (captured from its call), one call each with compilation included (a
    second call would double the run; the compilation is seconds against minutes of sampling)."""
    import importlib.util
    import warnings

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np
    from numpyro.infer import AIES, ESS

    from frbjax.posterior import _lightcurve

    spec = importlib.util.spec_from_file_location(
        "_posterior_benchmark", ROOT / "benchmarks" / "lightcurve_posterior.py"
    )
    benchmark = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(benchmark)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        observed, _, fit, _ = benchmark.data_and_fit()

    # NUTS: lightcurve_posterior itself, its sampler's call timed and its data and potential kept.
    captured = {}
    original = _lightcurve.sampler.run

    def timed_run(z0, keys, data, prior, **options):
        out, seconds = _timed(lambda: original(z0, keys, data, prior, **options))
        captured.update(data=data, prior=prior, generator=options["potential_generator"], seconds=seconds, out=out)
        return out

    chains, warmup, draws = sizes["lightcurve_nuts"]
    _lightcurve.sampler.run = timed_run
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            posterior = benchmark.posterior_of(observed, fit, num_chains=chains, num_warmup=warmup, num_samples=draws)
    finally:
        _lightcurve.sampler.run = original
    data = captured["data"]
    sampled = np.asarray(data["sampled"])
    names = list(posterior.parameter_names)
    thetas = np.asarray(posterior.parameters).reshape(chains, draws, -1)[..., sampled]
    results = {"NUTS": _diagnostics(thetas, captured["seconds"], names)}
    out = captured["out"]
    results["NUTS"].update(
        chains=chains,
        warmup=warmup,
        draws_per_chain=draws,
        chain_method="sequential",
        mean_leapfrog_steps=float(np.mean(out["num_steps"])),
        gradient_evaluations=int(np.sum(out["num_steps"])),
        divergences=int(np.sum(out["diverging"])),
        step_size=np.asarray(out["step_size"]).reshape(-1).tolist(),
    )
    print(f"NUTS: {captured['seconds']:.1f} s", file=sys.stderr)

    potential = captured["generator"](data, captured["prior"])
    centre, root = np.asarray(data["centre"]), np.asarray(data["root"])

    def starts(count, seed):
        return jnp.asarray(np.random.default_rng(seed).normal(size=(count, len(sampled))))

    def thetas_of(z):
        return centre + np.asarray(z, float) @ root.T

    for name, kernel_class in (("AIES", AIES), ("ESS", ESS)):
        walkers, warmup, draws = sizes[f"lightcurve_{name.lower()}"]
        row, _ = _ensemble_row(kernel_class, potential, walkers, warmup, draws, starts, thetas_of, names, twice=False)
        results[name] = row
        print(f"{name}: {row['seconds']:.1f} s, max R-hat {row['max_split_r_hat']:.4f}", file=sys.stderr)

    ratios = _ratios(results, "NUTS", names[:2], _evaluation_seconds(potential, starts(1, 0)[0]))
    return {
        "machine": _machine(),
        "case": "SAM tumbler of benchmarks/lightcurve_posterior.py, shape held",
        "samples": len(observed[0]),
        "facets": int(fit.shape.normals.shape[0]),
        "parameters": names,
        "samplers": results,
        "ratios": ratios,
    }


def _child(part, quick, pin):
    """Run one part in a fresh process (pinned to core 0 if ``pin``) and return its JSON."""
    command = [sys.executable, __file__, "--part", part] + (["--quick"] if quick else [])
    preexec = None
    if pin:
        if shutil.which("taskset"):
            command = ["taskset", "-c", "0"] + command
        else:
            preexec = lambda: os.sched_setaffinity(0, {0})  # noqa: E731
    environment = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    result = subprocess.run(command, env=environment, stdout=subprocess.PIPE, text=True, check=True, preexec_fn=preexec)
    return json.loads(result.stdout.strip().splitlines()[-1])


def _plot(samplers, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    names = list(samplers)
    groups = (("log I2/I1", "log_I2_over_I1"), ("log I3/I1", "log_I3_over_I1"), ("min over all 8", None))
    figure, axes = plt.subplots(figsize=(7.2, 4.8))
    width = 0.8 / len(names)
    for k, name in enumerate(names):
        row = samplers[name]
        values = [row["ess_per_second_min_all"] if key is None else row["ess_per_second"][key] for _, key in groups]
        kind = {"AIES": "affine-invariant ensemble", "ESS": "ensemble slice"}.get(name, "exact gradients")
        count = f"{row['walkers']} walkers" if "walkers" in row else f"{row['chains']} chains {row['chain_method']}"
        converged = "" if row["converged"] else ", not converged"
        label = f"{name.split()[0]} ({kind}, {count}{converged})"
        offset = (k - (len(names) - 1) / 2) * width
        axes.bar(np.arange(len(groups)) + offset, values, width, label=label)
    axes.set_xticks(np.arange(len(groups)), [label for label, _ in groups])
    axes.set_yscale("log")
    axes.set_ylabel("bulk ESS per second (one core)")
    axes.set_title("Attitude posterior, 40 attitudes, 1 mrad: NUTS vs ensembles")
    axes.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize="small")
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="tiny sizes (smoke test)")
    parser.add_argument("--output-dir", type=pathlib.Path, default=ROOT / "benchmarks" / "results")
    parser.add_argument(
        "--part", choices=("samplers", "wall", "lightcurve"), help="run one part here and print its JSON"
    )
    parser.add_argument(
        "--lightcurve",
        action="store_true",
        help="run part 3 only (a light-curve posterior) and write posterior_samplers_lightcurve.json",
    )
    arguments = parser.parse_args()
    sizes = QUICK if arguments.quick else FULL
    if arguments.part == "samplers":
        print(json.dumps(samplers_part(sizes)), flush=True)
        return
    if arguments.part == "wall":
        print(json.dumps(wall_part(sizes)), flush=True)
        return
    if arguments.part == "lightcurve":
        print(json.dumps(lightcurve_part(sizes)), flush=True)
        return
    if arguments.lightcurve:
        samplers = _child("lightcurve", arguments.quick, pin=True)
        output = {"quick": arguments.quick, "sizes": sizes, "ess_per_second": samplers}
        print(json.dumps(output, indent=1), flush=True)
        arguments.output_dir.mkdir(parents=True, exist_ok=True)
        (arguments.output_dir / "posterior_samplers_lightcurve.json").write_text(json.dumps(output, indent=1) + "\n")
        return
    start = time.perf_counter()
    samplers = _child("samplers", arguments.quick, pin=True)
    wall = _child("wall", arguments.quick, pin=False)
    output = {
        "quick": arguments.quick,
        "sizes": sizes,
        "ess_per_second": samplers,
        "attitude_posterior_wall_time": wall,
        "total_seconds": time.perf_counter() - start,
    }
    print(json.dumps(output, indent=1), flush=True)
    arguments.output_dir.mkdir(parents=True, exist_ok=True)
    (arguments.output_dir / "posterior_samplers.json").write_text(json.dumps(output, indent=1) + "\n")
    _plot(samplers["samplers"], arguments.output_dir / "posterior_samplers.png")


if __name__ == "__main__":
    main()
