"""The first answer: what a user waits for before frbjax's first result, against diffrax (one core).

Each scenario runs in a fresh Python process (nothing compiled before it, JAX's persistent cache
off), pinned to one core with XLA single-threaded, float64, for each of frbjax's CPU paths:

* ``jax``: ``FRBJAX_KERNELS=jax``, the JAX code everywhere (the path of accelerators);
* ``kernels``: the special functions and a ``FreeRigidBody``'s series as compiled kernels, the
  one-time motion in JAX (``FRBJAX_MOTION_KERNEL=jax``);
* ``motion``: the default on the CPU, the one-time motion as one compiled kernel too
  (frbjax/_compiled_motion.py),

and diffrax 0.7 Dopri8 at rtol = atol = 1e-12 on dL/dt = L x Omega, dq/dt = q (0, Omega)/2 (the
solver of benchmarks/work_precision.py) in the same run.  Rows (issue 41's targets):

* ``readme``: the README's example as a script, the whole process (import, a body at 2001 times,
  ``jax.grad`` of a one-body quaternion component); diffrax: the same solve and gradient;
* ``one_body``: ``jax.jit`` of ``FreeRigidBody(I, L, q).quaternion(t)`` for one body: compile; its
  gradient in (I, L, q): compile; the same for ``free_flow``; and the jitted call's latency against a
  trivial jitted function of the same arguments;
* ``batched``: a quaternion loss over 1000 bodies x 100 times, compile of the forward program and of
  ``value_and_grad`` in (I, L), frbjax against diffrax;
* ``fit``: the first ``fit_attitude`` call (200 samples) against diffrax's ``value_and_grad`` compile;
* ``throughput``: a prebuilt body's quaternion per point (1e4 and 1e6 points), ``free_flow`` per
  body and building a body (16384 bodies), and the batched loss's ``value_and_grad`` per point
  (1000 bodies x 100 times), compiled (second call);
* ``lightcurve`` (the default path only): the light-curve inversion of benchmarks/lightcurve.py (LAM,
  seed 0, its full size), its first ``fit_lightcurve`` call and the part of it that JAX spent
  tracing, lowering and XLA compiling (``jax_log_compiles``' timings of every program compiled during
  the call): compile's share of the first call.

Usage: python benchmarks/first_answer.py [--quick] [--output-dir DIR]
Writes first_answer.json and first_answer.png into benchmarks/results/ (or --output-dir).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path


PATHS = {
    "jax": {"FRBJAX_KERNELS": "jax"},
    "kernels": {"FRBJAX_KERNELS": "auto", "FRBJAX_MOTION_KERNEL": "jax"},
    "motion": {"FRBJAX_KERNELS": "auto", "FRBJAX_MOTION_KERNEL": "compiled"},
}

README = """
import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
from frbjax import FreeRigidBody

body = FreeRigidBody(inertia=[1.0, 2.0, 3.0], angular_momentum=[0.1, 1.0, 0.05], attitude=None)
t = jnp.linspace(-100.0, 100.0, 2001)
body.angular_momentum(t).block_until_ready()
body.quaternion(t).block_until_ready()
body.rotation_matrix(t).block_until_ready()
gradient = jax.grad(lambda I: FreeRigidBody(I, [0.1, 1.0, 0.05]).quaternion(10.0)[0])
gradient(jnp.array([1.0, 2.0, 3.0])).block_until_ready()
"""

README_DIFFRAX = """
import jax

jax.config.update("jax_enable_x64", True)
import diffrax
import jax.numpy as jnp


def field(t, y, inertia):
    l, q = y[:3], y[3:]
    o = l / inertia
    qw, qx, qy, qz = q
    dq = 0.5 * jnp.stack([-qx * o[0] - qy * o[1] - qz * o[2], qw * o[0] + qy * o[2] - qz * o[1],
                          qw * o[1] - qx * o[2] + qz * o[0], qw * o[2] + qx * o[1] - qy * o[0]])
    return jnp.concatenate([jnp.cross(l, o), dq])


def solve(inertia, momentum, ts):
    y0 = jnp.concatenate([jnp.asarray(momentum), jnp.array([1.0, 0.0, 0.0, 0.0])])
    controller = diffrax.PIDController(rtol=1e-12, atol=1e-12)
    return diffrax.diffeqsolve(diffrax.ODETerm(field), diffrax.Dopri8(), t0=0.0, t1=ts[-1], dt0=None, y0=y0,
                               args=inertia, saveat=diffrax.SaveAt(ts=ts), stepsize_controller=controller,
                               max_steps=100000).ys


t = jnp.linspace(0.0, 200.0, 2001)
solve(jnp.array([1.0, 2.0, 3.0]), [0.1, 1.0, 0.05], t).block_until_ready()
gradient = jax.grad(lambda I: solve(I, [0.1, 1.0, 0.05], jnp.array([0.0, 10.0]))[-1, 3])
gradient(jnp.array([1.0, 2.0, 3.0])).block_until_ready()
"""


def _pin():
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})


def _environment(path):
    env = dict(os.environ)
    env.pop("FRBJAX_MOTION_KERNEL", None)
    env.update(PATHS.get(path, {}))
    env.update(
        XLA_FLAGS="--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1",
        OPENBLAS_NUM_THREADS="1",
        JAX_ENABLE_COMPILATION_CACHE="false",
        JAX_PLATFORMS="cpu",
    )
    return env


def _whole_process(code, path):
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, "-c", "import os; os.sched_setaffinity(0, {0})\n" + code], check=True, env=_environment(path)
    )
    return time.perf_counter() - start


def _scenario(name, path, quick):
    command = [sys.executable, __file__, "--scenario", name] + (["--quick"] if quick else [])
    out = subprocess.run(command, check=True, env=_environment(path), capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


# ------------------------------------------------------------------------------ inside one process


def _compile_s(function, *arguments):
    import jax

    start = time.perf_counter()
    jax.jit(function).lower(*arguments).compile()
    return time.perf_counter() - start


def _best(call, repeats):
    import jax

    jax.block_until_ready(call())
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(call())
        best = min(best, time.perf_counter() - start)
    return best


def _one_body(quick):
    import jax
    import jax.numpy as jnp

    from frbjax import free_flow, FreeRigidBody

    inertia, momentum = jnp.array([1.0, 2.0, 3.0]), jnp.array([0.1, 1.0, 0.05])
    attitude, t = jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.asarray(10.0)
    body_q = lambda I, L, q, t: FreeRigidBody(I, L, q).quaternion(t)  # noqa: E731
    flow_q = lambda I, L, q, t: free_flow(I, L, q, t)[1]  # noqa: E731
    row = {}
    for name, function in (("body", body_q), ("free_flow", flow_q)):
        row[f"{name}_compile_s"] = _compile_s(function, inertia, momentum, attitude, t)
        gradient = jax.grad(lambda I, L, q, t: jnp.sum(function(I, L, q, t)), argnums=(0, 1, 2))
        row[f"{name}_gradient_compile_s"] = _compile_s(gradient, inertia, momentum, attitude, t)
        jitted = jax.jit(function)
        row[f"{name}_call_s"] = _best(lambda: jitted(inertia, momentum, attitude, t), 200 if quick else 2000)
    trivial = jax.jit(lambda I, L, q, t: q * t + jnp.sum(I * L))
    row["trivial_call_s"] = _best(lambda: trivial(inertia, momentum, attitude, t), 200 if quick else 2000)
    return row


def _diffrax_loss(bodies, times):
    import jax.numpy as jnp

    sys.path.insert(0, str(Path(__file__).parent))
    from work_precision import diffrax_function

    solve = diffrax_function("Dopri8")

    def loss(inertia, momentum, weights):
        return jnp.sum(solve(inertia, momentum, bodies[2], times, 1e-12)[1] * weights)

    return loss


def _bodies(n):
    import jax.numpy as jnp
    import numpy as np

    rng = np.random.default_rng(0)
    inertia = rng.uniform(0.5, 2.0, (n, 3))
    momentum = rng.normal(size=(n, 3))
    attitude = rng.normal(size=(n, 4))
    attitude /= np.linalg.norm(attitude, axis=-1, keepdims=True)
    return tuple(jnp.asarray(a) for a in (inertia, momentum, attitude))


def _batched(quick, with_diffrax):
    import jax
    import jax.numpy as jnp

    from frbjax import FreeRigidBody

    n, k = (100, 10) if quick else (1000, 100)
    bodies = _bodies(n)
    times = jnp.linspace(1.0, 100.0, k)
    weights = jnp.arange(1.0, 5.0)

    def frbjax_loss(inertia, momentum, weights):
        return jnp.sum(FreeRigidBody(inertia, momentum, bodies[2]).quaternion(times[:, None]) * weights)

    losses = [("frbjax", frbjax_loss)]
    if with_diffrax:
        losses.append(("diffrax", _diffrax_loss(bodies, times)))
    row = {"bodies": n, "times": k}
    for name, loss in losses:
        row[f"{name}_forward_s"] = _compile_s(loss, bodies[0], bodies[1], weights)
        both = jax.value_and_grad(loss, argnums=(0, 1))
        row[f"{name}_value_and_grad_s"] = _compile_s(both, bodies[0], bodies[1], weights)
    return row


def _fit(quick):
    import jax
    import jax.numpy as jnp

    from frbjax import fit_attitude, FreeRigidBody

    samples = 50 if quick else 200
    body = FreeRigidBody(jnp.asarray([0.6, 0.8, 1.0]), jnp.asarray([0.3, 1.0, 0.2]))
    times = jnp.linspace(0.0, 60.0, samples)
    observed = body.quaternion(times)
    start = time.perf_counter()
    jax.block_until_ready(fit_attitude(times, observed).inertia)
    return {"samples": samples, "first_call_s": time.perf_counter() - start}


def _throughput(quick):
    import jax
    import jax.numpy as jnp

    from frbjax import free_flow, FreeRigidBody

    row = {}
    body = FreeRigidBody(jnp.asarray([1.0, 2.0, 3.0]), jnp.asarray([0.1, 1.0, 0.05]))
    for points in (10**4,) if quick else (10**4, 10**6):
        t = jnp.linspace(-100.0, 100.0, points)
        row[f"series_per_point_{points}_ns"] = _best(lambda: body.quaternion(t), 3 if quick else 10) / points * 1e9
    n = 1024 if quick else 16384
    inertia, momentum, attitude = _bodies(n)
    t = jnp.linspace(0.0, 10.0, n)
    flow = jax.jit(free_flow)
    row["free_flow_per_body_ns"] = _best(lambda: flow(inertia, momentum, attitude, t), 3 if quick else 10) / n * 1e9
    # Building bodies (their records), and the batched loss's value_and_grad once compiled (the
    # "batched" scenario's program: 1000 bodies x 100 times, the bodies built in the loss).
    build = jax.jit(FreeRigidBody)
    row["construction_per_body_ns"] = _best(lambda: build(inertia, momentum, attitude), 3 if quick else 10) / n * 1e9
    bodies, count = _bodies(100 if quick else 1000), 10 if quick else 100
    times = jnp.linspace(1.0, 100.0, count)[:, None]
    weights = jnp.arange(1.0, 5.0)

    def loss(inertia, momentum):
        return jnp.sum(FreeRigidBody(inertia, momentum, bodies[2]).quaternion(times) * weights)

    both = jax.jit(jax.value_and_grad(loss, argnums=(0, 1)))
    points = count * len(bodies[0])
    row["value_and_grad_per_point_ns"] = _best(lambda: both(*bodies[:2]), 3 if quick else 5) / points * 1e9
    return row


def _lightcurve(quick):
    import logging
    import re

    import jax

    sys.path.insert(0, str(Path(__file__).parent))
    import lightcurve

    seconds = {"compilation": 0.0, "tracing": 0.0, "lowering": 0.0}
    kinds = {"XLA compilation": "compilation", "tracing": "tracing", "jaxpr to MLIR module conversion": "lowering"}
    pattern = re.compile(r"Finished (XLA compilation|tracing|jaxpr to MLIR module conversion) .* in ([0-9.e+-]+) s")

    class Timings(logging.Handler):
        def emit(self, record):
            found = pattern.search(record.getMessage())
            if found:
                seconds[kinds[found.group(1)]] += float(found.group(2))

    logger = logging.getLogger("jax._src.dispatch")
    logger.addHandler(Timings(logging.DEBUG))
    logger.setLevel(logging.DEBUG)
    logger.propagate = False  # the timings, not JAX's messages on stderr
    jax.config.update("jax_log_compiles", True)
    fit = lightcurve.fit_lightcurve
    row = {}

    def timed(*args, **kwargs):
        before = dict(seconds)
        start = time.perf_counter()
        result = fit(*args, **kwargs)
        row["first_call_s"] = time.perf_counter() - start
        row.update({f"{kind}_s": seconds[kind] - before[kind] for kind in seconds})
        return result

    lightcurve.fit_lightcurve = timed
    grid, states, refine = ([2, 2], 4, 2) if quick else ([5, 3], 128, 32)
    summary = lightcurve.inversion("LAM", 0, 0.01, grid, states, refine, False, 0.0023, None)[0]
    row["recovered"] = bool(summary["recovered"])
    row["compile_share"] = (row["compilation_s"] + row["tracing_s"] + row["lowering_s"]) / row["first_call_s"]
    return row


def _run_scenario(name, quick):
    import jax

    jax.config.update("jax_enable_x64", True)
    if name == "one_body":
        return _one_body(quick)
    if name == "batched":
        return _batched(quick, with_diffrax=False)
    if name == "batched_diffrax":
        return _batched(quick, with_diffrax=True)
    if name == "fit":
        return _fit(quick)
    if name == "throughput":
        return _throughput(quick)
    if name == "lightcurve":
        return _lightcurve(quick)
    raise ValueError(name)


# ------------------------------------------------------------------------------------------- main


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes (a smoke test)")
    parser.add_argument("--output-dir", default=str(Path(__file__).parent / "results"))
    parser.add_argument("--scenario", help=argparse.SUPPRESS)
    parser.add_argument("--paths", default=",".join(PATHS), help="frbjax paths to run (comma-separated)")
    options = parser.parse_args(argv)
    if options.scenario:
        _pin()
        print(json.dumps(_run_scenario(options.scenario, options.quick)))
        return None

    paths = options.paths.split(",")
    result = {"quick": options.quick, "paths": {}, "diffrax": {}}
    result["diffrax"]["readme_s"] = _whole_process(README_DIFFRAX, "jax")
    result["diffrax"].update(
        {k.replace("diffrax_", ""): v for k, v in _scenario("batched_diffrax", "jax", options.quick).items()}
    )
    for path in paths:
        row = {"readme_s": _whole_process(README, path)}
        for name in ("one_body", "batched", "fit", "throughput") + (("lightcurve",) if path == "motion" else ()):
            row.update({f"{name}.{k}": v for k, v in _scenario(name, path, options.quick).items()})
        result["paths"][path] = row
        print(path, json.dumps(row, indent=1), flush=True)
    diffrax = result["diffrax"]
    ratios = {}
    for path, row in result["paths"].items():
        ratios[path] = {
            "readme_vs_diffrax": row["readme_s"] / diffrax["readme_s"],
            "batched_forward_vs_diffrax": row["batched.frbjax_forward_s"] / diffrax["forward_s"],
            "batched_value_and_grad_vs_diffrax": row["batched.frbjax_value_and_grad_s"] / diffrax["value_and_grad_s"],
            "fit_first_call_vs_diffrax_value_and_grad": row["fit.first_call_s"] / diffrax["value_and_grad_s"],
            "body_call_vs_trivial": row["one_body.body_call_s"] / row["one_body.trivial_call_s"],
            "free_flow_call_vs_trivial": row["one_body.free_flow_call_s"] / row["one_body.trivial_call_s"],
        }
        if "lightcurve.compile_share" in row:
            ratios[path]["lightcurve_compile_share"] = row["lightcurve.compile_share"]
        if "jax" in result["paths"]:
            reference = result["paths"]["jax"]
            for key in [k for k in row if k.startswith("throughput.")]:
                ratios[path][f"{key}_speedup_vs_jax_path"] = reference[key] / row[key]
    result["ratios"] = ratios
    print(json.dumps({"diffrax": diffrax, "ratios": ratios}, indent=1))
    output = Path(options.output_dir)
    output.mkdir(parents=True, exist_ok=True)
    (output / "first_answer.json").write_text(json.dumps(result, indent=1) + "\n")
    plot(result, output / "first_answer.png")
    return result


def plot(result, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    rows = [
        ("README script", "readme_s", "readme_s"),
        ("batched forward compile", "batched.frbjax_forward_s", "forward_s"),
        ("batched value_and_grad compile", "batched.frbjax_value_and_grad_s", "value_and_grad_s"),
        ("first fit_attitude", "fit.first_call_s", "value_and_grad_s"),
    ]
    paths = list(result["paths"])
    figure, axis = plt.subplots(figsize=(8, 4))
    width = 0.8 / (len(paths) + 1)
    positions = np.arange(len(rows))
    for k, name in enumerate(paths + ["diffrax"]):
        values = [
            result["diffrax"][theirs] if name == "diffrax" else result["paths"][name][ours] for _, ours, theirs in rows
        ]
        axis.barh(positions + k * width, values, width, label=name if name == "diffrax" else f"frbjax ({name})")
    axis.set_yticks(positions + width * len(paths) / 2, [label for label, _, _ in rows])
    axis.invert_yaxis()
    axis.set_xlabel("seconds (one core, fresh process)")
    axis.set_title("Time to the first answer: frbjax's CPU paths against diffrax Dopri8")
    axis.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
