"""Light curves: forward-model throughput against RK4, and the inversion of a synthetic tumbler.

1. Forward model: the brightness of ``--bodies`` candidate tumblers (an 80-facet shape) at the times
   of the synthetic data set (24 nights over 90 days), as a period search evaluates it: frbjax's
   exact motion against RK4 on Euler's equations and the quaternion kinematics (what the current
   tumbler codes integrate, e.g. Mashchenko 2019), with the RK4 step the largest that keeps the
   flux within 1e-5 (relative) of the exact one over the whole record (1% photometric noise is 1e-2).
   Samples per second (bodies x times / s) after compilation, on the machine's backend.
2. Inversion: the synthetic Apophis-like tumblers of tests/test_lightcurve_fit.py (``--cases``
   SAM and LAM; a bumpy convex hull, 24 nights of 16 samples, 1% noise, one scale per night, the
   convex model of the tests), searched over +-``--width`` around centres ``--offset`` (relative)
   from the true periods, so that no grid point is the truth, on a ``--grid``
   (P_psi, P_phi) grid with ``--states`` random states each, ``--refine`` refined, once for each of
   the search's random ``--seeds``: wall time on this machine (compilation included, and again with
   the programs compiled for the first seed), the recovered periods, inertia ratios, held-out
   prediction error, and whether the run recovered the tumbler (both periods to 1e-4, held-out
   nights within 1.2 times the noise).

Writes benchmarks/results/lightcurve.json and lightcurve.png (the data and the fit, the search's
landscape over the two periods).  ``--quick``: tiny sizes (a smoke test).  ``--forward-only``: part 1
alone, with frbjax in float32 too (its flux against float64's), into lightcurve_forward_<backend>.json:
the run for an accelerator (``--bodies 16384`` on a GPU: JAX's default device is the GPU there).

    .venv/bin/python benchmarks/lightcurve.py [--quick] [--output-dir DIR]
    python benchmarks/lightcurve.py --forward-only --bodies 16384          # on a GPU machine
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import pathlib
import platform
import time

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402


matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from frbjax import (
    _quaternion as quaternion,  # noqa: E402
    FreeRigidBody,  # noqa: E402
)
from frbjax.lightcurve import brightness, ConvexShape, facet_brightness, fit_lightcurve, tumbler_periods  # noqa: E402


ROOT = pathlib.Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("_lightcurve_problems", ROOT / "tests" / "test_lightcurve_fit.py")
problems = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(problems)

FLUX_TOLERANCE = 1e-5


# ------------------------------------------------------------------------------------ RK4


def _rk4_attitudes(inertia, momentum, attitude, times, steps_per_day):
    """Attitudes at ``times`` (sorted, from 0) by RK4 on dL/dt = L x (L/I), dq/dt = q ⊗ (0, L/I) / 2."""

    def derivative(state):
        momentum, q = state[:3], state[3:]
        omega = momentum / inertia
        return jnp.concatenate(
            [jnp.cross(momentum, omega), 0.5 * quaternion.multiply(q, jnp.concatenate([jnp.zeros(1), omega]))]
        )

    def rk4(state, h):
        k1 = derivative(state)
        k2 = derivative(state + h / 2 * k1)
        k3 = derivative(state + h / 2 * k2)
        k4 = derivative(state + h * k3)
        return state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    def advance(carry, target):
        state, now = carry
        gap = target - now
        count = jnp.maximum(jnp.ceil(jnp.abs(gap) * steps_per_day), 1.0)
        h = gap / count
        state = jax.lax.fori_loop(0, count.astype(jnp.int32), lambda _, s: rk4(s, h), state)
        state = state.at[3:].set(state[3:] / jnp.linalg.norm(state[3:]))
        return (state, target), state[3:]

    initial = jnp.concatenate([momentum, attitude])
    _, attitudes = jax.lax.scan(advance, (initial, jnp.zeros((), times.dtype)), times)
    return attitudes


def _flux_from_attitudes(attitudes, normals, areas, sun, observer):
    matrices = quaternion.as_matrix(attitudes)
    sun_body = jnp.einsum("tji,tj->ti", matrices, sun)
    observer_body = jnp.einsum("tji,tj->ti", matrices, observer)
    return facet_brightness(normals, sun_body, observer_body) @ areas


def forward_throughput(n_bodies, repeats, single_precision=False):
    times, sun, observer, _ = problems.geometry(24, per_night=18)
    order = np.argsort(times)  # nights may overlap: RK4 steps from one sample to the next
    times, sun, observer = times[order] - times[order[0]], sun[order], observer[order]
    rng = np.random.default_rng(0)
    inertia = np.concatenate([np.sort(rng.uniform(0.4, 0.98, (n_bodies, 2)), -1), np.ones((n_bodies, 1))], -1)
    momentum = rng.normal(size=(n_bodies, 3))
    momentum *= (2 * np.pi / 1.2) / np.linalg.norm(momentum, axis=-1, keepdims=True)  # ~1 day rotations
    attitude = rng.normal(size=(n_bodies, 4))
    attitude /= np.linalg.norm(attitude, axis=-1, keepdims=True)
    shape = ConvexShape.ellipsoid(1.3, 1.0, 0.8, subdivisions=1)
    args = [jnp.asarray(x) for x in (inertia, momentum, attitude, times, sun, observer)]

    @jax.jit
    def exact(inertia, momentum, attitude, times, sun, observer):
        bodies = FreeRigidBody(inertia, momentum, attitude)
        return brightness(bodies, shape, times, sun, observer)

    # One program for every rung of the ladder: the step count per day is an argument (the loops'
    # trip counts are computed from it at run time anyway).
    @jax.jit
    def rk4(inertia, momentum, attitude, times, sun, observer, steps_per_day):
        def one(i, m, q):
            return _flux_from_attitudes(
                _rk4_attitudes(i, m, q, times, steps_per_day), shape.normals, shape.areas, sun, observer
            )

        return jax.vmap(one)(inertia, momentum, attitude)

    def rk4_program(steps_per_day):
        steps = jnp.asarray(float(steps_per_day))
        return lambda *arguments: rk4(*arguments, steps)

    def timed(function, arguments=args):
        jax.block_until_ready(function(*arguments))
        best = math.inf
        for _ in range(repeats):
            start = time.perf_counter()
            jax.block_until_ready(function(*arguments))
            best = min(best, time.perf_counter() - start)
        return best

    reference = np.asarray(exact(*args))
    exact_seconds = timed(exact)
    # The coarsest RK4 step (per day) within the flux tolerance, on a ladder of steps.
    ladder = []
    chosen = None
    for steps_per_day in (25, 50, 100, 200, 400, 800, 1600):
        program = rk4_program(float(steps_per_day))
        error = float(np.max(np.abs(np.asarray(program(*args)) / reference - 1)))
        ladder.append({"steps_per_day": steps_per_day, "max_relative_flux_error": error})
        if error < FLUX_TOLERANCE:
            chosen = (steps_per_day, program, error)
            break
    rk4_seconds = timed(chosen[1]) if chosen else math.nan
    samples = n_bodies * len(times)
    single = {}
    if single_precision:
        # frbjax in float32 (inputs rounded to float32, the shape's too): its flux against float64's.
        single_shape = ConvexShape(jnp.asarray(shape.normals, jnp.float32), jnp.asarray(shape.areas, jnp.float32))
        single_args = [a.astype(jnp.float32) for a in args]

        @jax.jit
        def exact_single(inertia, momentum, attitude, times, sun, observer):
            return brightness(FreeRigidBody(inertia, momentum, attitude), single_shape, times, sun, observer)

        flux = np.asarray(exact_single(*single_args), np.float64)
        best = timed(exact_single, single_args)
        single = {
            "float32_seconds": best,
            "float32_samples_per_second": samples / best,
            "float32_max_relative_flux_difference": float(np.max(np.abs(flux / reference - 1))),
            "float32_median_relative_flux_difference": float(np.median(np.abs(flux / reference - 1))),
        }
    return {
        "bodies": n_bodies,
        "times": len(times),
        "facets": int(shape.areas.shape[0]),
        "span_days": float(times[-1]),
        "frbjax_seconds": exact_seconds,
        "frbjax_samples_per_second": samples / exact_seconds,
        "rk4_ladder": ladder,
        "rk4_steps_per_day": chosen[0] if chosen else None,
        "rk4_max_relative_flux_error": chosen[2] if chosen else None,
        "rk4_seconds": rk4_seconds,
        "rk4_samples_per_second": samples / rk4_seconds,
        "speedup": rk4_seconds / exact_seconds,
        **single,
    }


# ------------------------------------------------------------------------------------ inversion


def tumbler(case):
    """The synthetic SAM or LAM tumbler of tests/test_lightcurve_fit.py and its two periods."""
    energy_ratio = {"SAM": 1.024, "LAM": 1.2}[case]
    inertia = np.array([0.61, 0.965, 1.0])
    direction = problems.momentum_with_energy(inertia, energy_ratio, 1.0)
    p_psi, _, _ = tumbler_periods(inertia, direction)
    momentum = direction * float(p_psi) / problems.PRECESSION_PERIOD
    body = FreeRigidBody(inertia, momentum, problems.ATTITUDE)
    return body, np.array([float(p) for p in tumbler_periods(inertia, momentum)[:2]])


def inversion(case, seed, width, grid, states, refine, compiled_run, offset=0.0, shape=None):
    """One inversion of the tests' tumbler with the search's random states ``seed``: wall time (and
    again once compiled, if ``compiled_run``), the recovered parameters, the held-out error."""
    body, periods = tumbler(case)
    inertia = np.asarray(body.inertia)
    data, held_out = problems.observe(body, seed=3, per_night=problems.SAMPLES_PER_NIGHT)
    times, flux, sun, observer, night = data
    options = dict(
        problems.FIT_OPTIONS,
        lightcurve=night,
        mode=case,
        seed=seed,
        throw=False,
        shape=shape or problems.FIT_OPTIONS["shape"],
        periods=tuple((p * (1 + offset - width), p * (1 + offset + width)) for p in periods),
        period_grid=tuple(grid),
        starts_per_period=states,
        n_refine=refine,
    )
    start = time.perf_counter()
    result = fit_lightcurve(times, flux, sun, observer, **options)
    first_seconds = time.perf_counter() - start
    seconds = None
    if compiled_run:
        start = time.perf_counter()
        result = fit_lightcurve(times, flux, sun, observer, **options)
        seconds = time.perf_counter() - start
    recovered = np.asarray(result.periods)
    period_error = np.abs(recovered / periods - 1)
    held_out_rms = problems.held_out_rms(result, held_out)
    summary = {
        "case": case,
        "seed": seed,
        "samples": len(times),
        "nights": 24,
        "starts": int(np.prod(grid)) * states,
        "refined": refine,
        "search_width": width,
        "search_offset": offset,
        "period_grid": list(grid),
        "first_call_seconds": first_seconds,
        "compiled_seconds": seconds,
        "true_periods": periods.tolist(),
        "periods": recovered.tolist(),
        "period_relative_error": period_error.tolist(),
        "period_sigma": (np.asarray(result.period_sigma) / periods).tolist(),
        "true_inertia": inertia.tolist(),
        "inertia": np.asarray(result.inertia).tolist(),
        "inertia_relative_error": np.abs(np.sort(np.asarray(result.inertia)) / inertia - 1).tolist(),
        "energy_ratio": result.energy_ratio,
        "long_axis_mode": result.long_axis_mode,
        "fit_rms": float(np.sqrt(np.mean(np.asarray(result.residuals) ** 2))),
        "held_out_rms": held_out_rms,
        "noise": problems.NOISE,
        "refine_costs": sorted(float(c) for c in np.asarray(result.refine_costs)),
        # Recovered: both periods to 1e-4 and the held-out nights within 1.2 times the noise.
        "recovered": bool(np.all(period_error < 1e-4) and held_out_rms < 1.2 * problems.NOISE),
    }
    return summary, result, data, periods


def plot(path, result, data, periods):
    times, flux, sun, observer, night = data
    figure, (curve_axis, landscape_axis) = plt.subplots(1, 2, figsize=(11, 4))
    model = np.asarray(result.predict(times, sun, observer))
    for k in range(3):
        chosen = night == k
        scale = np.exp(np.mean(np.log(flux[chosen]) - np.log(model[chosen])))
        hours = (times[chosen] - times[chosen][0]) * 24 + 8 * k
        curve_axis.plot(hours, flux[chosen] / scale, "o", ms=3, color=f"C{k}")
        curve_axis.plot(hours, model[chosen], "-", color=f"C{k}")
    curve_axis.set_xlabel("hours (three nights, offset)")
    curve_axis.set_ylabel("flux (each night's fitted scale removed)")
    curve_axis.set_title("data (dots) and fitted model (lines)")
    search = np.asarray(result.search_periods)
    costs = np.asarray(result.search_costs)
    finite = np.isfinite(costs) & np.all(np.isfinite(search), -1)
    keys = {}
    for (p_psi, p_phi), cost in zip(search[finite], costs[finite]):
        key = (round(p_psi, 9), round(p_phi, 9))
        keys[key] = min(keys.get(key, math.inf), cost)
    points = np.array([(a, b, c) for (a, b), c in keys.items()])
    scatter = landscape_axis.scatter(
        points[:, 0] * 24, points[:, 1] * 24, c=np.log10(points[:, 2]), cmap="viridis", s=60
    )
    landscape_axis.plot(periods[0] * 24, periods[1] * 24, "r+", ms=14, label="truth")
    landscape_axis.plot(
        np.asarray(result.periods)[0] * 24, np.asarray(result.periods)[1] * 24, "kx", ms=10, label="fit"
    )
    landscape_axis.set_xlabel("P_psi (h)")
    landscape_axis.set_ylabel("P_phi (h)")
    landscape_axis.set_title("search: best start cost per period pair")
    landscape_axis.legend()
    figure.colorbar(scatter, ax=landscape_axis, label="log10 cost (first window)")
    figure.tight_layout()
    figure.savefig(path, dpi=110)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="tiny sizes (smoke test)")
    parser.add_argument("--output-dir", type=pathlib.Path, default=ROOT / "benchmarks" / "results")
    parser.add_argument("--bodies", type=int, default=256)
    parser.add_argument("--cases", nargs="+", default=["SAM", "LAM"])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--grid", type=int, nargs=2, default=[5, 3])
    parser.add_argument("--states", type=int, default=128)
    parser.add_argument("--refine", type=int, default=32)
    parser.add_argument("--width", type=float, default=0.01)
    parser.add_argument(
        "--offset",
        type=float,
        default=0.0023,
        help="the ranges' centre relative to the true periods (the truth off the grid)",
    )
    parser.add_argument("--forward-only", action="store_true", help="part 1 alone, float32 too (module docstring)")
    arguments = parser.parse_args()
    machine = {
        "backend": jax.default_backend(),
        "device": str(jax.devices()[0]),
        "device_kind": jax.devices()[0].device_kind,
        "cpus": os.cpu_count(),
        "platform": platform.platform(),
        "jax": jax.__version__,
    }
    if arguments.quick:
        # The SAM case of tests/test_lightcurve_fit.py with a small search and the ellipsoid model:
        # the script runs, not the inversion's quality (the tests measure that).
        arguments.bodies, arguments.cases, arguments.seeds = 4, ["SAM"], [0]
        arguments.width, arguments.offset = 0.005, problems.RANGE_OFFSET
        arguments.grid, arguments.states, arguments.refine = [2, 2], 4, 2
    arguments.output_dir.mkdir(parents=True, exist_ok=True)
    throughput = forward_throughput(arguments.bodies, 1 if arguments.quick else 3, arguments.forward_only)
    print(json.dumps(throughput, indent=1), flush=True)
    if arguments.forward_only:
        output = {"machine": machine, "quick": arguments.quick, "forward": throughput}
        path = arguments.output_dir / f"lightcurve_forward_{machine['backend']}.json"
        path.write_text(json.dumps(output, indent=1) + "\n")
        return
    runs = []
    for case in arguments.cases:
        for seed in arguments.seeds:
            compiled_run = not arguments.quick and seed == arguments.seeds[0]
            summary, result, data, periods = inversion(
                case,
                seed,
                arguments.width,
                arguments.grid,
                arguments.states,
                arguments.refine,
                compiled_run,
                arguments.offset,
                "ellipsoid" if arguments.quick else None,
            )
            print(json.dumps(summary), flush=True)
            runs.append(summary)
            if case == arguments.cases[0] and seed == arguments.seeds[0]:
                plot(arguments.output_dir / "lightcurve.png", result, data, periods)
    output = {
        "machine": machine,
        "quick": arguments.quick,
        "forward": throughput,
        "inversions": runs,
        "recovered": f"{sum(run['recovered'] for run in runs)} of {len(runs)}",
    }
    (arguments.output_dir / "lightcurve.json").write_text(json.dumps(output, indent=1) + "\n")


if __name__ == "__main__":
    main()
