"""Everything before the first evaluation: construction, one-body, eager and compile costs (one core).

Every row pairs frbjax with its peer or its own floor, both measured in this run, on one core (the
process pins itself to CPU 0 and runs XLA single-threaded before JAX starts), float64:

* ``prebuilt_scalar_time``: 16384 prebuilt bodies evaluated at one scalar time per call (a scene
  drawn frame by frame) against the same bodies at a times axis of length 1 (their series); target
  ratio <= 1.25 (a prebuilt body always evaluates through its series).
* ``prebuilt_vmap_rows``: ``jax.vmap`` of ``body.quaternion`` over 128 rows of per-body times (1024
  bodies) against the same times as one (128, N) array (target ratio <= 1.25) and against the
  numpy/scipy closed form of benchmarks/_scipy_closed_form.py at the same times
  (``prebuilt_vmap_rows_vs_scipy``: scipy / frbjax, target >= 4).
* ``construction``: build + one evaluation per body (16384 random bodies, one time each, one jitted
  program: ``frbjax.free_flow``, the one-shot entry point) against one evaluation of the prebuilt
  bodies (their theta series); target ratio <= 3.
* ``state_at_T``: the state (L, q) at T = 10 of 1024 random bodies by ``free_flow``, against
  diffrax Dopri8 at rtol = atol = 1e-12 (vmapped, benchmarks/work_precision.py's solve); target
  diffrax / frbjax >= 500 (stretch 1000).
* ``one_body``: jitted ``free_flow(I, L, q, t)`` (the one-shot entry point) for
  one body and one time against a trivial jitted function of the same four arguments (JAX's
  dispatch); target ratio <= 2; with its compile time and that of its gradient (targets 1 s, 3 s),
  and the same figures for ``FreeRigidBody(I, L, q).quaternion(t)`` (series prepared).  Also, in
  subprocesses (``--latency-only``), the same latency pair on all the machine's cores and on one
  core with ``jax_cpu_enable_async_dispatch`` off: XLA:CPU runs a program of 1000 or more estimated
  flops on its worker thread, which on one core costs two context switches per call.
* ``eager``: ``FreeRigidBody(I, L, q).quaternion(t)`` at 1000 times without jit, second call, against
  the same under jit; target ratio <= 10; the first eager call (compilation included) is reported.
* ``compile``: compile time of a quaternion loss over 1000 bodies x 100 common times, forward and
  value_and_grad (in inertia and L), against diffrax Dopri8 solving the same loss (rtol = atol = 1e-12),
  XLA's default options; target frbjax / diffrax <= 1.
* ``fit_first_call``: ``fit_attitude`` on 200 samples, first call (compilation included), against the
  diffrax value_and_grad compile time above; target ratio <= 1.5.
* ``gpu_construction``: construction per body at 10^6 bodies on the default device, only where JAX
  has a GPU; target <= 2 ns.

The one-body and compile rows also record the XLA kernels of each program (``kernels``: fused loops,
conditionals, while loops), which set its compile time and one-body latency (docs/performance.md).

Usage: python benchmarks/setup_cost.py [--quick] [--output-dir DIR]
       python benchmarks/setup_cost.py --latency-only [--no-async-dispatch]   (one JSON line)
Writes setup_cost.json and setup_cost.png into benchmarks/results/ (or --output-dir).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import sys
import time
from pathlib import Path


# SETUP_COST_ALL_CORES=1: the subprocess that measures the one-body latency on every core.
if hasattr(os, "sched_setaffinity"):
    if os.environ.get("SETUP_COST_ALL_CORES") == "1":
        os.sched_setaffinity(0, range(os.cpu_count()))
    else:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")

import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402


HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _scipy_closed_form import ScipyFreeRigidBody  # noqa: E402
from throughput import (  # noqa: E402
    best_time as _best_time,  # noqa: E402
    bodies,
    compile_time,
)
from work_precision import diffrax_function  # noqa: E402

from frbjax import fit_attitude, free_flow, FreeRigidBody  # noqa: E402


# The figures of frbjax 0.1.0, before the constructor work (one core, same machine class).
BEFORE = {
    "prebuilt_scalar_time": 385 / 107,
    "prebuilt_vmap_rows": 210 / 130,
    "prebuilt_vmap_rows_vs_scipy": 1.8,
    "construction": 1367 / 115,
    "state_at_T": 233.0,
    "one_body": 21.1 / 5.2,
    "one_body_compile": 2.6,
    "one_body_gradient_compile": 8.2,
    "calgo903_example1": 0.72 / 0.21,
    "eager": 693 / 0.11,
    "compile_forward": 3.3 / 1.5,
    "compile_value_and_grad": 11.5 / 5.1,
    "fit_first_call": 18.0 / 5.1,
}
# Targets: a ratio at most this (or, for the rows of AT_LEAST, at least this).
AT_LEAST = ("state_at_T", "prebuilt_vmap_rows_vs_scipy")
TARGETS = {
    "prebuilt_scalar_time": 1.25,
    "prebuilt_vmap_rows": 1.25,
    "prebuilt_vmap_rows_vs_scipy": 4.0,
    "construction": 3.0,
    "state_at_T": 500.0,
    "one_body": 2.0,
    "one_body_compile": 1.0,
    "one_body_gradient_compile": 3.0,
    "calgo903_example1": 1.0,
    "eager": 10.0,
    "compile_forward": 1.0,
    "compile_value_and_grad": 1.0,
    "fit_first_call": 1.5,
}


def kernels(compiled):
    """XLA's kernels of a compiled CPU program: fused loops, conditionals and while loops (every
    branch and loop body included), and calls of frbjax's compiled kernels (csrc/).  XLA:CPU compiles
    each fused loop separately (about 15 ms each on this machine class, whatever its size) and
    launches each one per call, so that the count, rather than the arithmetic, sets compile time and
    one-body latency; a compiled kernel costs XLA one custom call, whatever it computes."""
    text = compiled.as_text()
    return {
        "fusions": text.count(" fusion("),
        "conditionals": text.count(" conditional("),
        "while_loops": text.count(" while("),
        "compiled_kernels": len(re.findall(r'custom_call_target="frbjax_', text)),
    }


def best_time(call, repeats, min_total=0.2):
    """throughput.best_time of an already compiled call (the first call, which compiles, is not timed)."""
    jax.block_until_ready(call())
    return _best_time(call, repeats, min_total)


def prebuilt(options, rng):
    n = 1024 if options.quick else 16384
    rows = 128
    inertia, momentum, attitude = (jnp.asarray(a) for a in bodies(rng, n))
    body = jax.jit(FreeRigidBody)(inertia, momentum, attitude)
    scalar_time = jnp.asarray(12.5)
    along_axis = jax.jit(lambda body, t: body.quaternion(t[None]))
    at_scalar = jax.jit(lambda body, t: body.quaternion(t))
    floor_s = best_time(lambda: along_axis(body, scalar_time), options.repeats)
    scalar_s = best_time(lambda: at_scalar(body, scalar_time), options.repeats)
    few = n // 16
    small = jax.tree_util.tree_map(lambda a: a[:few], body)
    times = jnp.asarray(rng.uniform(0, 100, (rows, few)))
    mapped = jax.jit(jax.vmap(lambda body, t: body.quaternion(t), in_axes=(None, 0)))
    array = jax.jit(lambda body, t: body.quaternion(t))
    mapped_s = best_time(lambda: mapped(small, times), options.repeats)
    array_s = best_time(lambda: array(small, times), options.repeats)
    # The peer: the numpy/scipy closed form of the same bodies at the same times (one call).
    peer = ScipyFreeRigidBody(*(np.asarray(a)[:few] for a in (inertia, momentum, attitude)))
    times_np = np.asarray(times)
    scipy_s = _best_time(lambda: peer.quaternion(times_np), options.repeats)
    evaluations = rows * few
    return {
        "bodies": n,
        "series_ns": floor_s / n * 1e9,
        "scalar_time_ns": scalar_s / n * 1e9,
        "ratio_scalar_time": scalar_s / floor_s,
        "vmap_rows": rows,
        "vmap_bodies": few,
        "vmap_ns": mapped_s / evaluations * 1e9,
        "array_ns": array_s / evaluations * 1e9,
        "scipy_ns": scipy_s / evaluations * 1e9,
        "ratio_vmap_rows": mapped_s / array_s,
        "scipy_over_vmap_rows": scipy_s / mapped_s,
    }


def construction(options, rng):
    n = 1024 if options.quick else 16384
    inertia, momentum, attitude = (jnp.asarray(a) for a in bodies(rng, n))
    t = jnp.asarray(rng.uniform(0, 100, n))
    build = jax.jit(FreeRigidBody)
    built = build(inertia, momentum, attitude)
    # The floor: one evaluation of each prebuilt body through its series.
    evaluate = jax.jit(lambda body, t: body.quaternion(t))
    both = jax.jit(lambda i, m, a, t: free_flow(i, m, a, t)[1])
    evaluation_s = best_time(lambda: evaluate(built, t), options.repeats)
    both_s = best_time(lambda: both(inertia, momentum, attitude, t), options.repeats)
    return {
        "bodies": n,
        "evaluation_ns": evaluation_s / n * 1e9,
        "construction_and_evaluation_ns": both_s / n * 1e9,
        "ratio": both_s / evaluation_s,
    }


def state_at_final_time(options, rng):
    n = 128 if options.quick else 1024
    inertia, momentum, attitude = (jnp.asarray(a) for a in bodies(rng, n))
    final = jnp.asarray([10.0])
    frbjax_state = jax.jit(lambda i, m, a, t: free_flow(i, m, a, t[0]))
    dopri8 = diffrax_function("Dopri8")
    frbjax_s = best_time(lambda: frbjax_state(inertia, momentum, attitude, final), options.repeats)
    diffrax_s = best_time(lambda: dopri8(inertia, momentum, attitude, final, 1e-12), 3)
    momentum_frbjax, attitude_frbjax = frbjax_state(inertia, momentum, attitude, final)
    momentum_diffrax, attitude_diffrax, _, ok = dopri8(inertia, momentum, attitude, final, 1e-12)
    # Attitude difference up to the sign of q (diffrax integrates q directly: the same sign).
    difference = max(
        float(jnp.max(jnp.abs(momentum_frbjax - momentum_diffrax[:, 0]))),
        float(jnp.max(jnp.abs(attitude_frbjax - attitude_diffrax[:, 0]))),
    )
    return {
        "bodies": n,
        "T": 10.0,
        "frbjax_s": frbjax_s,
        "diffrax_dopri8_1e-12_s": diffrax_s,
        "ratio": diffrax_s / frbjax_s,
        "max_difference": difference,
        "diffrax_ok": bool(jnp.all(ok)),
    }


def one_body_case(rng):
    """One random body at t = 3 and JAX's dispatch floor: a trivial jitted function of the same four
    arguments."""
    inertia, momentum, attitude = (jnp.asarray(a[0]) for a in bodies(rng, 1))
    trivial = jax.jit(lambda i, m, a, t: a * t + jnp.sum(i * m))
    return (inertia, momentum, attitude, jnp.asarray(3.0)), trivial


def one_body(options, rng):
    arguments, trivial = one_body_case(rng)
    inertia, momentum, attitude, t = arguments
    trivial_s = best_time(lambda: trivial(*arguments), max(options.repeats, 200), min_total=0.5)
    from frbjax.special import _compiled

    row = {"trivial_jit_us": trivial_s * 1e6, "compiled_kernels": _compiled.selected(inertia)}
    programs = {
        "free_flow": lambda i, m, a, t: free_flow(i, m, a, t)[1],
        "FreeRigidBody": lambda i, m, a, t: FreeRigidBody(i, m, a).quaternion(t),
    }
    for name, function in programs.items():
        # Compile times first (a later compile of the same program is a cache hit), and the kernels
        # from that compile: jit does not expose the executable it runs, and timing a
        # jax.stages.Compiled instead adds about 3 us of Python dispatch.
        compiled, compile_s = compile_time(function, inertia, momentum, attitude, t)
        _, gradient_s = compile_time(
            jax.grad(lambda i, m, a, t: jnp.sum(function(i, m, a, t)), argnums=(0, 1)), inertia, momentum, attitude, t
        )
        motion = jax.jit(function)
        motion_s = best_time(lambda: motion(inertia, momentum, attitude, t), max(options.repeats, 200), min_total=0.5)
        row[name] = {
            "us": motion_s * 1e6,
            "ratio": motion_s / trivial_s,
            "compile_s": compile_s,
            "gradient_compile_s": gradient_s,
            "kernels": kernels(compiled),
        }
    row["ratio"] = row["free_flow"]["ratio"]
    return row


def latency(repeats=2000):
    """``one_body``'s latency pair alone (best single call: dispatch, execution, wait), in us."""
    arguments, trivial = one_body_case(np.random.default_rng(0))
    motion = jax.jit(lambda i, m, a, t: free_flow(i, m, a, t)[1])
    times = {
        name: best_time(lambda function=function: function(*arguments), repeats) * 1e6
        for name, function in (("trivial_jit_us", trivial), ("free_flow_us", motion))
    }
    return {
        **times,
        "ratio": times["free_flow_us"] / times["trivial_jit_us"],
        "cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
    }


def latency_elsewhere(arguments, all_cores):
    """``latency()`` in a fresh process (every core, or this one with other JAX options)."""
    import subprocess

    environment = dict(os.environ, SETUP_COST_ALL_CORES="1" if all_cores else "0")
    output = subprocess.run(
        [sys.executable, __file__, "--latency-only", *arguments],
        env=environment,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    return json.loads(output.strip().splitlines()[-1])


def calgo903_example1(options, rng):
    """Example 1 with XLA's default flags against the Fortran driver's 0.21 s."""
    from calgo903_example1 import DATA, FORTRAN_SECONDS

    from frbjax import _calgo903 as calgo

    problem = calgo.read_input(DATA / "init_example1.dat")
    steps = 1000 if options.quick else problem.steps
    program = calgo.example1_program(problem, steps)
    momentum, attitude = problem.initial_state()
    seconds = best_time(lambda: program(momentum, attitude), 3, min_total=0.0)
    return {
        "steps": steps,
        "seconds": seconds,
        "fortran_seconds": FORTRAN_SECONDS * steps / problem.steps,
        "ratio": seconds / (FORTRAN_SECONDS * steps / problem.steps),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
    }


def eager(options, rng):
    inertia, momentum, attitude = (jnp.asarray(a[0]) for a in bodies(rng, 1))
    t = jnp.linspace(-100.0, 100.0, 1000)
    start = time.perf_counter()
    jax.block_until_ready(FreeRigidBody(inertia, momentum, attitude).quaternion(t))
    first_s = time.perf_counter() - start
    eager_s = _best_time(lambda: FreeRigidBody(inertia, momentum, attitude).quaternion(t), options.repeats)
    jitted = jax.jit(lambda i, m, a, t: FreeRigidBody(i, m, a).quaternion(t))
    jitted_s = best_time(lambda: jitted(inertia, momentum, attitude, t), options.repeats)
    return {
        "times": 1000,
        "first_call_s": first_s,
        "eager_ms": eager_s * 1e3,
        "jitted_ms": jitted_s * 1e3,
        "ratio": eager_s / jitted_s,
    }


def compile_times(options, rng):
    n, k = (100, 10) if options.quick else (1000, 100)
    inertia, momentum, attitude = (jnp.asarray(a) for a in bodies(rng, n))
    times = jnp.linspace(1.0, 100.0, k)
    weights = jnp.asarray(rng.normal(size=4))

    def frbjax_loss(inertia, momentum):
        return jnp.sum(FreeRigidBody(inertia, momentum, attitude).quaternion(times[:, None]) * weights)

    solve = diffrax_function("Dopri8")

    def diffrax_loss(inertia, momentum):
        _, q, _, _ = solve(inertia, momentum, attitude, times, 1e-12)
        return jnp.sum(q * weights)

    row = {"bodies": n, "times": k}
    for name, loss in (("frbjax", frbjax_loss), ("diffrax_dopri8", diffrax_loss)):
        forward, forward_s = compile_time(loss, inertia, momentum)
        both, both_s = compile_time(jax.value_and_grad(loss, argnums=(0, 1)), inertia, momentum)
        row[f"{name}_forward_s"], row[f"{name}_value_and_grad_s"] = forward_s, both_s
        row[f"{name}_forward_kernels"], row[f"{name}_value_and_grad_kernels"] = kernels(forward), kernels(both)
    row["ratio_forward"] = row["frbjax_forward_s"] / row["diffrax_dopri8_forward_s"]
    row["ratio_value_and_grad"] = row["frbjax_value_and_grad_s"] / row["diffrax_dopri8_value_and_grad_s"]
    return row


def fit_first_call(options, rng, diffrax_value_and_grad_s):
    samples = 200
    body = FreeRigidBody(jnp.asarray([0.6, 0.8, 1.0]), jnp.asarray([0.3, 1.0, 0.2]))
    times = jnp.linspace(0.0, 60.0, samples)
    observed = body.quaternion(times)
    start = time.perf_counter()
    jax.block_until_ready(fit_attitude(times, observed).inertia)
    first_s = time.perf_counter() - start
    return {
        "samples": samples,
        "first_call_s": first_s,
        "diffrax_value_and_grad_compile_s": diffrax_value_and_grad_s,
        "ratio": first_s / diffrax_value_and_grad_s,
    }


def gpu_construction(options, rng):
    if jax.default_backend() != "gpu":
        return None
    n = 10**5 if options.quick else 10**6
    inertia, momentum, attitude = (jax.device_put(jnp.asarray(a)) for a in bodies(rng, n))
    build = jax.jit(FreeRigidBody)
    seconds = best_time(lambda: build(inertia, momentum, attitude), options.repeats)
    return {"bodies": n, "ns_per_body": seconds / n * 1e9, "device": str(jax.devices()[0])}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes (a smoke run)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output-dir", default=str(HERE / "results"))
    parser.add_argument("--latency-only", action="store_true", help="print latency() as one JSON line")
    parser.add_argument(
        "--no-async-dispatch",
        action="store_true",
        help="with --latency-only: jax_cpu_enable_async_dispatch off (programs run inline)",
    )
    options = parser.parse_args(argv)
    if options.latency_only:
        if options.no_async_dispatch:
            jax.config.update("jax_cpu_enable_async_dispatch", False)
        print(json.dumps(latency()))
        return
    rng = np.random.default_rng(options.seed)
    # First, while this process has started no XLA thread that could share the other cores.
    elsewhere = {
        "all_cores": latency_elsewhere([], all_cores=True),
        "one_core_async_dispatch_off": latency_elsewhere(["--no-async-dispatch"], all_cores=False),
    }
    rows = {}
    for name, measure in (
        ("prebuilt", prebuilt),
        ("construction", construction),
        ("state_at_T", state_at_final_time),
        ("one_body", one_body),
        ("calgo903_example1", calgo903_example1),
        ("eager", eager),
        ("compile", compile_times),
    ):
        rows[name] = measure(options, rng)
        if name == "one_body":
            rows[name]["elsewhere"] = elsewhere
        print(name, json.dumps(rows[name]), flush=True)
    rows["fit_first_call"] = fit_first_call(options, rng, rows["compile"]["diffrax_dopri8_value_and_grad_s"])
    print("fit_first_call", json.dumps(rows["fit_first_call"]), flush=True)
    rows["gpu_construction"] = gpu_construction(options, rng)
    ratios = {
        "prebuilt_scalar_time": rows["prebuilt"]["ratio_scalar_time"],
        "prebuilt_vmap_rows": rows["prebuilt"]["ratio_vmap_rows"],
        "prebuilt_vmap_rows_vs_scipy": rows["prebuilt"]["scipy_over_vmap_rows"],
        "construction": rows["construction"]["ratio"],
        "state_at_T": rows["state_at_T"]["ratio"],
        "one_body": rows["one_body"]["ratio"],
        "one_body_compile": rows["one_body"]["free_flow"]["compile_s"],
        "one_body_gradient_compile": rows["one_body"]["free_flow"]["gradient_compile_s"],
        "calgo903_example1": rows["calgo903_example1"]["ratio"],
        "eager": rows["eager"]["ratio"],
        "compile_forward": rows["compile"]["ratio_forward"],
        "compile_value_and_grad": rows["compile"]["ratio_value_and_grad"],
        "fit_first_call": rows["fit_first_call"]["ratio"],
    }
    met = {
        name: (ratios[name] >= TARGETS[name]) if name in AT_LEAST else (ratios[name] <= TARGETS[name])
        for name in ratios
    }
    for name in ratios:
        print(
            f"{name:24s} before {BEFORE[name]:9.3g}  now {ratios[name]:9.3g}  target "
            f"{'>=' if name in AT_LEAST else '<='} {TARGETS[name]:g}  {'met' if met[name] else 'MISSED'}"
        )
    result = {
        "script": "benchmarks/setup_cost.py",
        "quick": options.quick,
        "machine": {
            "platform": platform.platform(),
            "cpus_used": 1,
            "jax": jax.__version__,
            "backend": jax.default_backend(),
        },
        "rows": rows,
        "ratios": ratios,
        "before": BEFORE,
        "targets": TARGETS,
        "met": met,
    }
    output = Path(options.output_dir)
    output.mkdir(parents=True, exist_ok=True)
    (output / "setup_cost.json").write_text(json.dumps(result, indent=1) + "\n")
    plot(result, output / "setup_cost.png")
    print("wrote", output / "setup_cost.json", "and", output / "setup_cost.png")


def plot(result, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(result["ratios"])

    # Every row as "how far from its target": ratio / target (>= 1 missed), state_at_T inverted.
    def distance(name, ratio):
        target = result["targets"][name]
        return target / ratio if name in AT_LEAST else ratio / target

    before = [distance(name, result["before"][name]) for name in names]
    now = [distance(name, result["ratios"][name]) for name in names]
    positions = np.arange(len(names))
    figure, axes = plt.subplots(figsize=(9, 4.5))
    axes.barh(
        positions + 0.2,
        before,
        height=0.4,
        color="0.75",
        label="before (frbjax 0.1.0; later rows: the release before them)",
    )
    axes.barh(positions - 0.2, now, height=0.4, color="tab:blue", label="now")
    axes.axvline(1.0, color="k", lw=1)
    axes.set_xscale("log")
    axes.set_yticks(positions, names)
    axes.invert_yaxis()
    axes.set_xlabel("measured / target (left of the line: target met)")
    axes.set_title("Setup costs on one core, each against its peer in the same run")
    axes.legend(loc="lower right")
    figure.tight_layout()
    figure.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
