"""Torqued rigid bodies: the splitting methods against diffrax's Runge-Kutta methods, same problems, same run.

Three parts (``--parts``, default all), each writing JSON (and a PNG) into benchmarks/results/:

* ``work_precision`` (torqued_work_precision.json/png): a spinning heavy top (moments 1, 1.6, 2.3;
  weight 1 along -z; centre of mass (0.05, 0.1, 0.4) in the body; L(0) = (0.3, 0.8, 10): its motion
  is regular, where the same top with L(0) = (0.3, 0.8, 2) is chaotic and no method, Dopri8 at 1e-13
  included, gets one digit right at T = 1000) and a satellite on a circular orbit under the
  gravity-gradient torque (orbit rate 1: V = 3/2 u . I u with u = Q^T e_r(t), e_r = (cos t, sin t, 0),
  a time-dependent potential), to T = 1000.  The named splitting methods (``RigidBodySplitting`` in
  ``diffrax.diffeqsolve``, final state only) over step sizes; diffrax Tsit5, Dopri5 and Dopri8 on the
  same ``RigidBodyTerm`` (its ODE) with a PID controller over tolerances rtol = atol.  Error: max norm
  over L and q at T against Dopri8 at rtol = atol = 1e-14 (its own floor: the distance to 1e-13,
  written to the JSON).  Time: best of ``--repeats`` runs after compilation, one body, one core
  (run under ``taskset -c 0``).  Each method's time at error 1e-8 is interpolated (log-log) from its
  two neighbouring points; the JSON gives the fastest diffrax's time over the fastest splitting's.
* ``energy`` (torqued_energy.json/png): the heavy top's energy error over 10^6 steps of
  blanes_moan4 (h = 0.1, T = 10^5) against Tsit5 and Dopri8 with fixed steps chosen so that each
  costs about as much wall time as the splitting (their per-step cost measured first; at most 20x
  the splitting's steps), at 1000 times.
* ``batch`` (torqued_batch.json): 4096 heavy tops with different initial states against one body,
  blanes_moan6, microseconds per free flow per body.

``--quick`` shrinks everything (a smoke test of the script: the heavy top to T = 10 with
blanes_moan6 and Dopri8 at two points each, 10^3 energy steps against Tsit5, 8 bodies).  The numbers
are wall times on the machine that runs the script; say which when quoting.

``--single-kernel-loops`` runs everything (diffrax's solvers too) with XLA's small-loop threshold
raised for the whole process through XLA_FLAGS (a small loop compiled as one kernel, so that one
body's step costs its arithmetic rather than the dispatch of its kernels) and writes
``torqued_*_single_kernel_loops.*``.

Usage: python benchmarks/torqued.py [--quick] [--parts work_precision energy batch] [--output-dir DIR]
       [--single-kernel-loops]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import time
from pathlib import Path


os.environ.setdefault("EQX_ON_ERROR", "nan")

import diffrax  # noqa: E402
import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import frbjax  # noqa: E402


RESULTS = Path(__file__).resolve().parent / "results"
TARGET_ERROR = 1e-8


# ------------------------------------------------------------------------------------- problems


def heavy_top_potential(t, q, args):
    return args["weight"] * (frbjax.quaternion_to_matrix(q)[2] @ args["chi"])


def gravity_gradient_potential(t, q, args):
    radial = jnp.stack([jnp.cos(t), jnp.sin(t), jnp.zeros_like(t)])
    u = frbjax.quaternion_to_matrix(q).T @ radial
    return 1.5 * u @ (args * u)


def problems():
    q0 = np.array([0.9, 0.3, -0.2, 0.1])
    heavy_inertia = jnp.array([1.0, 1.6, 2.3])
    satellite_inertia = jnp.array([0.8, 1.0, 1.3])
    return {
        "heavy_top": dict(
            term=frbjax.RigidBodyTerm(heavy_inertia, potential=heavy_top_potential),
            args={"weight": jnp.asarray(1.0), "chi": jnp.array([0.05, 0.1, 0.4])},
            y0=(jnp.array([0.3, 0.8, 10.0]), jnp.asarray(q0 / np.linalg.norm(q0))),
        ),
        "gravity_gradient": dict(
            term=frbjax.RigidBodyTerm(satellite_inertia, potential=gravity_gradient_potential),
            args=satellite_inertia,
            y0=(satellite_inertia * jnp.array([0.05, -0.03, 1.1]), jnp.array([1.0, 0.0, 0.0, 0.0])),
        ),
    }


SPLITTING_STEPS = {  # T = 1000: from ~1e-3 towards the reference's floor
    "leapfrog": [0.02, 0.01, 0.005],
    "yoshida4": [0.05, 0.025, 0.0125, 0.00625],
    "blanes_moan4": [0.125, 0.0625, 0.03125, 0.015625],
    "blanes_moan6": [0.5, 0.35, 0.25, 0.18, 0.125],
}
TOLERANCES = [1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12]
RUNGE_KUTTA = {"Tsit5": diffrax.Tsit5(), "Dopri5": diffrax.Dopri5(), "Dopri8": diffrax.Dopri8()}


def best_time(function, repeats):
    """Best wall time of ``function()`` over ``repeats`` runs (one when a run takes over 2 s)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(function())
        times.append(time.perf_counter() - start)
        if times[-1] > 2:
            break
    return min(times)


def state_error(y, reference):
    return float(max(jnp.abs(y[0] - reference[0]).max(), jnp.abs(y[1] - reference[1]).max()))


def time_at_target(points):
    """Time at TARGET_ERROR, log-log interpolated between the two points around it (None if not bracketed)."""
    points = sorted((e, t) for e, t in points if math.isfinite(e))
    for (e1, t1), (e2, t2) in zip(points, points[1:]):
        if e1 <= TARGET_ERROR <= e2 and e1 < e2:
            w = (math.log(TARGET_ERROR) - math.log(e1)) / (math.log(e2) - math.log(e1))
            return math.exp(math.log(t1) + w * (math.log(t2) - math.log(t1)))
    return None


def _time_at_target(points):
    return time_at_target([(point["error"], point["seconds"]) for point in points])


def work_precision(quick, repeats):
    final_time = 10.0 if quick else 1000.0
    methods = {"blanes_moan6": [0.5, 0.25]} if quick else SPLITTING_STEPS
    tolerances = [1e-6, 1e-9] if quick else TOLERANCES
    runge_kutta = {"Dopri8": RUNGE_KUTTA["Dopri8"]} if quick else RUNGE_KUTTA
    results = {"final_time": final_time, "target_error": TARGET_ERROR, "problems": {}}
    chosen = {"heavy_top": problems()["heavy_top"]} if quick else problems()
    for name, problem in chosen.items():
        term, args, y0 = problem["term"], problem["args"], problem["y0"]

        def rk_program(solver):
            @jax.jit
            def run(tolerance):
                solution = diffrax.diffeqsolve(
                    term,
                    solver,
                    0.0,
                    final_time,
                    0.01,
                    y0,
                    args=args,
                    max_steps=10_000_000,
                    stepsize_controller=diffrax.PIDController(rtol=tolerance, atol=tolerance),
                    throw=False,
                )
                return solution.ys[0][-1], solution.ys[1][-1], solution.stats["num_steps"]

            return run

        dopri8 = rk_program(diffrax.Dopri8())
        reference = dopri8(jnp.asarray(1e-14))[:2]
        floor = state_error(dopri8(jnp.asarray(1e-13))[:2], reference)
        entry = {"reference": "Dopri8 rtol=atol=1e-14", "reference_floor": floor, "methods": {}}
        print(f"{name}: reference floor {floor:.1e}", flush=True)
        for method, steps in methods.items():

            @jax.jit
            def run(step, method=method):
                solution = diffrax.diffeqsolve(
                    term, frbjax.RigidBodySplitting(method), 0.0, final_time, step, y0, args=args, max_steps=2_000_000
                )
                return solution.ys[0][-1], solution.ys[1][-1]

            points = []
            for step in steps:
                state = jax.block_until_ready(run(jnp.asarray(step)))
                seconds = best_time(lambda: run(jnp.asarray(step)), repeats)
                points.append({"step": step, "error": state_error(state, reference), "seconds": seconds})
                print(f"  {method:13s} h={step:<8g} error {points[-1]['error']:.2e}  {seconds:.4f} s", flush=True)
            entry["methods"][method] = {
                "kind": "splitting",
                "points": points,
                "seconds_at_target": _time_at_target(points),
            }
        for solver_name, solver in runge_kutta.items():
            run = dopri8 if solver_name == "Dopri8" else rk_program(solver)
            points = []
            for tolerance in tolerances:
                *state, count = jax.block_until_ready(run(jnp.asarray(tolerance)))
                seconds = best_time(lambda: run(jnp.asarray(tolerance)), repeats)
                points.append(
                    {
                        "tolerance": tolerance,
                        "steps": int(count),
                        "error": state_error(state, reference),
                        "seconds": seconds,
                    }
                )
                print(
                    f"  {solver_name:13s} tol={tolerance:<8g} error {points[-1]['error']:.2e}  {seconds:.4f} s",
                    flush=True,
                )
            entry["methods"][solver_name] = {
                "kind": "diffrax",
                "points": points,
                "seconds_at_target": _time_at_target(points),
            }
        fastest = {
            kind: min(
                (
                    m["seconds_at_target"]
                    for m in entry["methods"].values()
                    if m["kind"] == kind and m["seconds_at_target"]
                ),
                default=None,
            )
            for kind in ("splitting", "diffrax")
        }
        entry["fastest_seconds_at_target"] = fastest
        entry["speedup_at_target"] = (
            fastest["diffrax"] / fastest["splitting"] if fastest["diffrax"] and fastest["splitting"] else None
        )
        print(
            f"  at error {TARGET_ERROR:g}: fastest splitting {fastest['splitting']}, fastest diffrax "
            f"{fastest['diffrax']}, ratio {entry['speedup_at_target']}",
            flush=True,
        )
        results["problems"][name] = entry
    return results


def plot_work_precision(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, len(results["problems"]), figsize=(12, 4.8))
    for axis, (name, entry) in zip(np.atleast_1d(axes), results["problems"].items()):
        for method, data in entry["methods"].items():
            points = [p for p in data["points"] if math.isfinite(p["error"])]
            style = "-o" if data["kind"] == "splitting" else "--s"
            axis.loglog([p["error"] for p in points], [p["seconds"] for p in points], style, label=method)
        axis.axvline(TARGET_ERROR, color="grey", lw=0.8)
        axis.axvspan(1e-18, max(entry["reference_floor"], 1e-18), color="grey", alpha=0.15)
        ratio = entry["speedup_at_target"]
        title = f"{name}, T = {results['final_time']:g}"
        if ratio:
            title += f"\nfastest diffrax / fastest splitting at {TARGET_ERROR:g}: {ratio:.2g}x"
        axis.set(title=title, xlabel="max error at T (L and q)", ylabel="seconds (one body, after compile)")
        axis.invert_xaxis()
        axis.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=120)


# --------------------------------------------------------------------------------------- energy


def energy(quick, repeats):
    problem = problems()["heavy_top"]
    term, args, y0 = problem["term"], problem["args"], problem["y0"]
    step = 0.1
    steps = 1000 if quick else 1_000_000
    final_time = steps * step
    samples = jnp.linspace(0.0, final_time, 101 if quick else 1001)
    energy0 = float(term.energy(0.0, y0, args))

    def program(solver, dt):
        @jax.jit
        def run():
            solution = diffrax.diffeqsolve(
                term,
                solver,
                0.0,
                final_time,
                dt,
                y0,
                args=args,
                saveat=diffrax.SaveAt(ts=samples),
                max_steps=steps * 20 + 10,
            )
            return solution.ys

        return run

    splitting = program(frbjax.RigidBodySplitting("blanes_moan4"), step)
    states = jax.block_until_ready(splitting())
    splitting_seconds = best_time(splitting, 1 if not quick else repeats)
    splitting_error = np.abs(np.asarray(term.energy(0.0, states, args)) - energy0)
    results = {
        "steps": steps,
        "step": step,
        "final_time": final_time,
        "times": np.asarray(samples).tolist(),
        "runs": {
            "blanes_moan4": {"step": step, "seconds": splitting_seconds, "energy_error": splitting_error.tolist()}
        },
    }
    print(f"energy: blanes_moan4 {steps} steps in {splitting_seconds:.2f} s", flush=True)
    solvers = [("Tsit5", diffrax.Tsit5())] + ([] if quick else [("Dopri8", diffrax.Dopri8())])
    for name, solver in solvers:
        # The cost of a step of this solver, measured on a short run, sets its step for equal wall time.
        probe_steps = 2000
        probe = jax.jit(
            lambda solver=solver: (
                diffrax.diffeqsolve(
                    term, solver, 0.0, probe_steps * 0.01, 0.01, y0, args=args, max_steps=probe_steps + 10
                ).ys
            )
        )
        jax.block_until_ready(probe())
        per_step = best_time(probe, repeats) / probe_steps
        count = max(int(splitting_seconds / per_step), 100)
        count = min(count, steps * 20)
        run = program(solver, final_time / count)
        states = jax.block_until_ready(run())
        seconds = best_time(run, 1)
        error = np.abs(np.asarray(term.energy(0.0, states, args)) - energy0)
        results["runs"][name] = {
            "step": final_time / count,
            "steps": count,
            "seconds": seconds,
            "energy_error": error.tolist(),
        }
        print(f"energy: {name} {count} steps of {final_time / count:.3g} in {seconds:.2f} s", flush=True)
    for name, run in results["runs"].items():
        error = np.asarray(run["energy_error"][1:])
        tenth = max(len(error) // 10, 1)
        run["max_first_tenth"] = float(error[:tenth].max())
        run["max_last_tenth"] = float(error[-tenth:].max())
        run["ratio_last_to_first_tenth"] = run["max_last_tenth"] / run["max_first_tenth"]
        print(
            f"  {name:13s} max |dE| first tenth {run['max_first_tenth']:.2e}, last tenth "
            f"{run['max_last_tenth']:.2e} (x{run['ratio_last_to_first_tenth']:.3g})",
            flush=True,
        )
    return results


def plot_energy(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(7.5, 4.5))
    times = np.asarray(results["times"])
    for name, run in results["runs"].items():
        label = f"{name}: {run.get('steps', results['steps'])} steps, {run['seconds']:.1f} s"
        axis.loglog(times[1:], np.maximum(np.asarray(run["energy_error"])[1:], 1e-17), label=label)
    axis.set(
        xlabel="t",
        ylabel="|E(t) - E(0)|",
        title=f"heavy top, energy error: {results['steps']} splitting steps; Runge-Kutta steps\n"
        "set for the same wall time (at most 20x as many)",
    )
    axis.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=120)


# ---------------------------------------------------------------------------------------- batch


def batch(quick, repeats):
    problem = problems()["heavy_top"]
    term, args = problem["term"], problem["args"]
    bodies = 8 if quick else 4096
    steps = 20 if quick else 100
    rng = np.random.default_rng(0)
    momenta = rng.normal(size=(bodies, 3))
    attitudes = rng.normal(size=(bodies, 4))
    attitudes /= np.linalg.norm(attitudes, axis=-1, keepdims=True)
    solver = frbjax.RigidBodySplitting("blanes_moan6")
    run = jax.jit(
        lambda y: diffrax.diffeqsolve(term, solver, 0.0, steps * 0.1, 0.1, y, args=args, max_steps=steps + 10).ys
    )
    results = {"steps": steps, "method": "blanes_moan6", "free_flows_per_step": 15}
    for label, y0 in (
        ("one_body", (jnp.asarray(momenta[:1]), jnp.asarray(attitudes[:1]))),
        ("batch", (jnp.asarray(momenta), jnp.asarray(attitudes))),
    ):
        jax.block_until_ready(run(y0))
        seconds = best_time(lambda: run(y0), repeats)
        count = y0[0].shape[0]
        results[label] = {
            "bodies": count,
            "seconds": seconds,
            "microseconds_per_free_flow_per_body": 1e6 * seconds / (15 * steps * count),
        }
        print(
            f"batch: {count} bodies, {1e6 * seconds / (15 * steps * count):.3f} us per free flow per body", flush=True
        )
    results["one_body_over_batch_per_body"] = (
        results["one_body"]["microseconds_per_free_flow_per_body"]
        / results["batch"]["microseconds_per_free_flow_per_body"]
    )
    return results


# ----------------------------------------------------------------------------------------- main


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="smoke test: small sizes")
    parser.add_argument(
        "--parts",
        nargs="+",
        default=["work_precision", "energy", "batch"],
        choices=["work_precision", "energy", "batch"],
    )
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--output-dir", type=Path, default=RESULTS)
    parser.add_argument(
        "--single-kernel-loops",
        action="store_true",
        help="compile small loops as one kernel for the whole process (every "
        "method, diffrax's too); results go to torqued_*_single_kernel_loops.*",
    )
    args = parser.parse_args(argv)
    args.output_dir.mkdir(parents=True, exist_ok=True)
    suffix = ""
    if args.single_kernel_loops:
        # XLA's small-loop threshold raised to 64 MiB for this whole process (diffrax's loops too),
        # read once, when JAX starts its backend (this script has computed nothing yet).
        flags = os.environ.get("XLA_FLAGS", "")
        if "xla_backend_extra_options" in flags:
            parser.error("XLA_FLAGS already sets --xla_backend_extra_options")
        option = f"--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold={1 << 26}"
        os.environ["XLA_FLAGS"] = f"{flags} {option}".strip()
        suffix = "_single_kernel_loops"
    machine = {
        "device": str(jax.devices()[0]),
        "platform": platform.platform(),
        "jax": jax.__version__,
        "diffrax": diffrax.__version__,
        "cpus_visible": len(os.sched_getaffinity(0)),
        "quick": args.quick,
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
    }
    if "work_precision" in args.parts:
        results = dict(work_precision(args.quick, args.repeats), machine=machine)
        path = args.output_dir / f"torqued_work_precision{suffix}.json"
        path.write_text(json.dumps(results, indent=1) + "\n")
        plot_work_precision(results, args.output_dir / f"torqued_work_precision{suffix}.png")
    if "energy" in args.parts:
        results = dict(energy(args.quick, args.repeats), machine=machine)
        (args.output_dir / f"torqued_energy{suffix}.json").write_text(json.dumps(results) + "\n")
        plot_energy(results, args.output_dir / f"torqued_energy{suffix}.png")
    if "batch" in args.parts:
        results = dict(batch(args.quick, args.repeats), machine=machine)
        (args.output_dir / f"torqued_batch{suffix}.json").write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
