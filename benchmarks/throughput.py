"""Throughput, cost and compile time of frbjax.FreeRigidBody (float64, CPU).

* Evaluations per second of ``quaternion``, ``rotation_matrix`` and ``angular_momentum`` alone (the
  bodies built beforehand), against the batch size from 1 to 1e7 evaluations: N = min(size, 1000)
  bodies times K = size / N times per body (a (K, N) array of times in [0, 100]), one jit-compiled
  program per size, best of a few repeats (a call longer than 2 s is timed once), block_until_ready.
  Next to it, the numpy/scipy closed form of benchmarks/_scipy_closed_form.py (``quaternion`` of
  prebuilt bodies, up to ``--scipy-max``).
* On all cores (this process, XLA's default CPU thread pool) and on one core: the same sweep re-run in
  a subprocess under ``taskset -c 0`` with XLA_FLAGS=--xla_cpu_multi_thread_eigen=false (a flag of the
  installed jaxlib; TensorFlow's ``intra_op_parallelism_threads`` is not an XLA flag: XLA rejects it
  as unknown, so it is not passed).  numpy/scipy use one core in both.
* Body construction cost per body (jit of ``FreeRigidBody(inertia, L, attitude)``), one core and all.
* Gradient: loss = sum(w . quaternion(t)) over N bodies x K times with fixed weights w, the bodies
  built inside the loss; time of jax.value_and_grad with respect to (inertia, angular momentum) over
  the time of the loss alone.
* jit compile time (lower + compile) of the forward loss and of its value_and_grad, and of every
  evaluation program of the sweep; the loss and its value_and_grad again compiled with XLA:CPU's
  fusion emitters off (compile and run times; not with --quick).

Usage: python benchmarks/throughput.py [--max-size 10000000] [--quick] [--output-dir DIR]
Writes throughput.json and throughput.png into benchmarks/results/ (or --output-dir).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


if __name__ == "__main__" and "--worker" in sys.argv and not shutil.which("taskset"):
    # No taskset on this system: pin the one-core worker before XLA starts its threads.
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})

import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402


HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.append(str(HERE.parent))
from _scipy_closed_form import ScipyFreeRigidBody  # noqa: E402

from frbjax import FreeRigidBody  # noqa: E402


DEFAULT_OUTPUT_DIR = HERE / "results"
ONE_THREAD_FLAGS = "--xla_cpu_multi_thread_eigen=false"
FUNCTIONS = ("quaternion", "rotation_matrix", "angular_momentum")
MAX_BODIES = 1000
FAST_COMPILE_OPTIONS = {"xla_cpu_use_fusion_emitters": False}


def bodies(rng, n):
    inertia = 10 ** rng.uniform(0.0, np.log10(4.0), (n, 3))
    momentum = rng.normal(size=(n, 3))
    attitude = rng.normal(size=(n, 4))
    attitude /= np.linalg.norm(attitude, axis=-1, keepdims=True)
    return inertia, momentum, attitude


def layout(size):
    n = min(size, MAX_BODIES)
    return n, size // n


def best_time(call, repeats, min_total=0.2):
    """Best wall time of call() (block_until_ready); repeats more for fast calls, once for slow ones."""
    start = time.perf_counter()
    jax.block_until_ready(call())
    first = time.perf_counter() - start
    if first > 2.0:
        return first
    best, total, count = first, first, 1
    while count < repeats or (total < min_total and count < 200):
        start = time.perf_counter()
        jax.block_until_ready(call())
        elapsed = time.perf_counter() - start
        best, total, count = min(best, elapsed), total + elapsed, count + 1
    return best


def compile_time(fn, *args, compiler_options=None):
    start = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile(compiler_options=compiler_options)
    return compiled, time.perf_counter() - start


def evaluation_sweep(sizes, repeats, scipy_max, rng):
    rows = []
    for size in sizes:
        n, k = layout(size)
        inertia, momentum, attitude = bodies(rng, n)
        body = FreeRigidBody(jnp.asarray(inertia), jnp.asarray(momentum), jnp.asarray(attitude))
        t = jnp.asarray(rng.uniform(0, 100, (k, n)))
        row = {"size": n * k, "bodies": n, "times_per_body": k}
        for name in FUNCTIONS:
            compiled, seconds = compile_time(lambda body, t, name=name: getattr(body, name)(t), body, t)
            elapsed = best_time(lambda compiled=compiled: compiled(body, t), repeats)
            row[f"{name}_compile_s"] = seconds
            row[f"{name}_s"] = elapsed
            row[f"{name}_ns_per_eval"] = elapsed / (n * k) * 1e9
            row[f"{name}_evals_per_s"] = n * k / elapsed
            del compiled
        if n * k <= scipy_max:
            peer = ScipyFreeRigidBody(inertia, momentum, attitude)
            t_np = np.asarray(t)
            elapsed = best_time(lambda: peer.quaternion(t_np), repeats)
            row["scipy_quaternion_s"] = elapsed
            row["scipy_quaternion_ns_per_eval"] = elapsed / (n * k) * 1e9
            row["scipy_quaternion_evals_per_s"] = n * k / elapsed
        rows.append(row)
        print(
            f"  size {n * k:>9} ({n} x {k}): ns/eval quaternion {row['quaternion_ns_per_eval']:9.1f}  "
            f"rotation_matrix {row['rotation_matrix_ns_per_eval']:9.1f}  angular_momentum "
            f"{row['angular_momentum_ns_per_eval']:9.1f}"
            + (f"  scipy quaternion {row['scipy_quaternion_ns_per_eval']:9.1f}" if "scipy_quaternion_s" in row else ""),
            flush=True,
        )
    return rows


def construction_sweep(sizes, repeats, rng):
    rows = []
    for n in sizes:
        args = [jnp.asarray(a) for a in bodies(rng, n)]
        compiled, seconds = compile_time(lambda i, l, q: FreeRigidBody(i, l, q), *args)
        elapsed = best_time(lambda: compiled(*args), repeats)
        rows.append({"bodies": n, "s": elapsed, "ns_per_body": elapsed / n * 1e9, "compile_s": seconds})
        print(f"  construction of {n:>8} bodies: {elapsed / n * 1e9:9.1f} ns per body", flush=True)
    return rows


def measurements(options, label):
    rng = np.random.default_rng(options.seed)
    print(f"[{label}] evaluation sweep, sizes {options.sizes}", flush=True)
    result = {"label": label, "affinity": sorted(os.sched_getaffinity(0)), "xla_flags": os.environ.get("XLA_FLAGS", "")}
    result["evaluation"] = evaluation_sweep(options.sizes, options.repeats, options.scipy_max, rng)
    result["construction"] = construction_sweep(options.construction_sizes, options.repeats, rng)
    return result


def gradient_cost(options):
    """Time and compile time of loss and value_and_grad(loss) w.r.t. (inertia, angular momentum)."""
    rng = np.random.default_rng(options.seed + 1)
    n, k = options.gradient_bodies, options.gradient_times
    inertia, momentum, attitude = (jnp.asarray(a) for a in bodies(rng, n))
    t = jnp.asarray(rng.uniform(0, 100, (k, n)))
    weights = jnp.asarray(rng.normal(size=4))

    def loss(inertia, momentum, attitude, t):
        return jnp.sum(FreeRigidBody(inertia, momentum, attitude).quaternion(t) * weights)

    forward, forward_compile = compile_time(loss, inertia, momentum, attitude, t)
    both, both_compile = compile_time(jax.value_and_grad(loss, argnums=(0, 1)), inertia, momentum, attitude, t)
    forward_s = best_time(lambda: forward(inertia, momentum, attitude, t), options.repeats)
    both_s = best_time(lambda: both(inertia, momentum, attitude, t), options.repeats)
    value, (d_inertia, d_momentum) = both(inertia, momentum, attitude, t)
    finite = bool(np.all(np.isfinite(np.asarray(d_inertia))) and np.all(np.isfinite(np.asarray(d_momentum))))
    row = {
        "bodies": n,
        "times_per_body": k,
        "loss": "sum(w . quaternion(t)), bodies built inside the loss",
        "forward_s": forward_s,
        "value_and_grad_s": both_s,
        "ratio_value_and_grad_over_forward": both_s / forward_s,
        "forward_compile_s": forward_compile,
        "value_and_grad_compile_s": both_compile,
        "gradient_finite": finite,
        "fusion_emitters_off": None,
    }
    print(
        f"  gradient: forward {forward_s * 1e3:.2f} ms, value_and_grad {both_s * 1e3:.2f} ms "
        f"(ratio {row['ratio_value_and_grad_over_forward']:.2f}); compile forward {forward_compile:.1f} s, "
        f"value_and_grad {both_compile:.1f} s",
        flush=True,
    )
    if options.quick:  # two more large compilations: not in the smoke run
        return row
    # The same two programs compiled with XLA:CPU's fusion emitters off (the README's recipe).
    forward, forward_compile = compile_time(loss, inertia, momentum, attitude, t, compiler_options=FAST_COMPILE_OPTIONS)
    both, both_compile = compile_time(
        jax.value_and_grad(loss, argnums=(0, 1)), inertia, momentum, attitude, t, compiler_options=FAST_COMPILE_OPTIONS
    )
    forward_s = best_time(lambda: forward(inertia, momentum, attitude, t), options.repeats)
    both_s = best_time(lambda: both(inertia, momentum, attitude, t), options.repeats)
    row["fusion_emitters_off"] = {
        "compiler_options": FAST_COMPILE_OPTIONS,
        "forward_s": forward_s,
        "value_and_grad_s": both_s,
        "ratio_value_and_grad_over_forward": both_s / forward_s,
        "forward_compile_s": forward_compile,
        "value_and_grad_compile_s": both_compile,
    }
    print(
        f"  with {FAST_COMPILE_OPTIONS}: forward {forward_s * 1e3:.2f} ms, value_and_grad {both_s * 1e3:.2f} ms; "
        f"compile forward {forward_compile:.1f} s, value_and_grad {both_compile:.1f} s",
        flush=True,
    )
    return row


def run_one_thread(options, argv):
    """Re-run the sweeps in a subprocess pinned to one core, without XLA's multithreaded Eigen."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "one_thread.json"
        command = [sys.executable, str(Path(__file__).resolve()), "--worker", str(out)] + argv
        taskset = shutil.which("taskset")
        if taskset:
            command = [taskset, "-c", str(sorted(os.sched_getaffinity(0))[0])] + command
        env = dict(os.environ)
        env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + " " + ONE_THREAD_FLAGS).strip()
        print(f"one core: {' '.join(command[:4])} ... with XLA_FLAGS={env['XLA_FLAGS']!r}", flush=True)
        subprocess.run(command, env=env, check=True)
        result = json.loads(out.read_text())
    result["command"] = ("taskset -c 0 " if taskset else "sched_setaffinity({0}) ") + "python throughput.py --worker"
    return result


def parse(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-size", type=int, default=10_000_000, help="largest batch (evaluations)")
    parser.add_argument("--sizes", type=int, nargs="+", help="batch sizes (default 1, 10, ... --max-size)")
    parser.add_argument("--construction-sizes", type=int, nargs="+", default=[1, 1000, 100_000])
    parser.add_argument("--scipy-max", type=int, default=1_000_000, help="largest batch for the scipy peer")
    parser.add_argument("--gradient-bodies", type=int, default=1000)
    parser.add_argument("--gradient-times", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--quick",
        action="store_true",
        help="smoke run: one batch of 10, 10 bodies built, gradient on 10 x 10; compile times may "
        "come from the persistent compilation cache (JAX_COMPILATION_CACHE_DIR) if one is set",
    )
    parser.add_argument("--output-dir", type=Path, default=DEFAULT_OUTPUT_DIR)
    parser.add_argument("--note", default="", help="free text stored in the JSON (e.g. which frbjax was measured)")
    parser.add_argument("--no-plot", action="store_true")
    parser.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    options = parser.parse_args(argv)
    if options.quick:
        options.sizes = [10]
        options.construction_sizes = [10]
        options.gradient_bodies, options.gradient_times, options.repeats = 10, 10, 2
    if options.sizes is None:
        options.sizes = [10**e for e in range(0, 8) if 10**e <= options.max_size]
    return options


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    options = parse(argv)
    if not options.quick:
        # Compile times are part of the result: never load them from a persistent cache.
        jax.config.update("jax_enable_compilation_cache", False)
    if options.worker is not None:
        result = measurements(options, "one core")
        options.worker.write_text(json.dumps(result, indent=2) + "\n")
        return result

    print(f"throughput: frbjax float64 on {jax.devices()[0]}, {os.cpu_count()} cores", flush=True)
    all_cores = measurements(options, "all cores")
    gradient = gradient_cost(options)
    worker_argv = [a for a in argv if a not in ("--no-plot",)]
    skip = {"--output-dir"}
    cleaned, i = [], 0
    while i < len(worker_argv):
        if worker_argv[i] in skip:
            i += 2
            continue
        if not worker_argv[i].startswith("--output-dir="):
            cleaned.append(worker_argv[i])
        i += 1
    one_core = run_one_thread(options, cleaned)

    def at(result, size, key):
        return next((r.get(key) for r in result["evaluation"] if r["size"] == size), None)

    largest_scipy = max((r["size"] for r in one_core["evaluation"] if "scipy_quaternion_s" in r), default=None)
    largest = max(r["size"] for r in one_core["evaluation"])
    summary = {
        "quaternion_ns_per_eval_one_core_largest_batch": at(one_core, largest, "quaternion_ns_per_eval"),
        "quaternion_ns_per_eval_all_cores_largest_batch": at(all_cores, largest, "quaternion_ns_per_eval"),
        "largest_batch": largest,
        "scipy_over_frbjax_quaternion_one_core": None
        if largest_scipy is None
        else at(one_core, largest_scipy, "scipy_quaternion_s") / at(one_core, largest_scipy, "quaternion_s"),
        "scipy_comparison_batch": largest_scipy,
        "construction_ns_per_body_one_core": one_core["construction"][-1]["ns_per_body"],
        "construction_ns_per_body_all_cores": all_cores["construction"][-1]["ns_per_body"],
        "gradient_over_forward": gradient["ratio_value_and_grad_over_forward"],
        "forward_compile_s": gradient["forward_compile_s"],
        "value_and_grad_compile_s": gradient["value_and_grad_compile_s"],
        "forward_compile_s_fusion_emitters_off": (gradient["fusion_emitters_off"] or {}).get("forward_compile_s"),
        "value_and_grad_compile_s_fusion_emitters_off": (gradient["fusion_emitters_off"] or {}).get(
            "value_and_grad_compile_s"
        ),
        "targets": {
            "quaternion_ns_per_eval_per_core": 300,
            "scipy_over_frbjax_quaternion_one_core": 4,
            "gradient_over_forward": 4,
            "forward_plus_gradient_compile_s": 5,
        },
    }
    print("\nSummary")
    print(
        f"  quaternion, batch {largest}: {summary['quaternion_ns_per_eval_one_core_largest_batch']:.1f} ns/eval "
        f"on one core, {summary['quaternion_ns_per_eval_all_cores_largest_batch']:.1f} ns/eval on "
        f"{os.cpu_count()} cores (target <= 300 ns per core)"
    )
    if largest_scipy is not None:
        print(
            f"  scipy closed form / frbjax per quaternion evaluation, one core, batch {largest_scipy}: "
            f"{summary['scipy_over_frbjax_quaternion_one_core']:.2f} (target >= 4)"
        )
    print(f"  construction: {summary['construction_ns_per_body_one_core']:.0f} ns per body on one core")
    print(
        f"  value_and_grad / forward: {summary['gradient_over_forward']:.2f} (target <= 4); compile forward "
        f"{summary['forward_compile_s']:.1f} s, value_and_grad {summary['value_and_grad_compile_s']:.1f} s "
        f"(target forward + gradient <= 5 s)"
    )
    if gradient["fusion_emitters_off"] is not None:
        print(
            f"  compile with the fusion emitters off: forward "
            f"{summary['forward_compile_s_fusion_emitters_off']:.1f} s, "
            f"value_and_grad {summary['value_and_grad_compile_s_fusion_emitters_off']:.1f} s"
        )

    result = {
        "description": "see the docstring of benchmarks/throughput.py",
        "dtype": "float64",
        "all_cores": all_cores,
        "one_core": one_core,
        "gradient": gradient,
        "summary": summary,
        "quick": options.quick,
        "compilation_cache": _cache_state(),
        "frbjax": _provenance(),
        "note": options.note,
        "device": str(jax.devices()[0]),
        "cpu_count": os.cpu_count(),
        "cpu": _cpu_name(),
        "jax": jax.__version__,
        "scipy": scipy.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
    }
    options.output_dir.mkdir(parents=True, exist_ok=True)
    path = options.output_dir / "throughput.json"
    path.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {path}")
    if not options.no_plot:
        png = options.output_dir / "throughput.png"
        plot(result, png)
        print(f"wrote {png}")
    return result


def _cache_state():
    enabled = jax.config.jax_enable_compilation_cache and jax.config.jax_compilation_cache_dir
    return f"persistent cache {jax.config.jax_compilation_cache_dir}" if enabled else "off"


def _provenance():
    """Where frbjax was imported from, and the git commit of this checkout (and whether frbjax/ is modified)."""
    import frbjax

    path = Path(frbjax.__file__).resolve().parent
    info = {"path": str(path)}
    if path != HERE.parent / "frbjax":
        return info  # not this checkout's frbjax: its git state says nothing (see --note)
    try:
        root = HERE.parent
        info["git_head"] = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
        info["frbjax_modified_in_checkout"] = bool(
            subprocess.run(
                ["git", "-C", str(root), "status", "--porcelain", "frbjax"], capture_output=True, text=True, check=True
            ).stdout.strip()
        )
    except (OSError, subprocess.CalledProcessError):
        pass
    return info


def _cpu_name():
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def plot(result, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.2))
    colors = {"quaternion": "tab:red", "rotation_matrix": "tab:blue", "angular_momentum": "tab:green"}
    for key, style in (("all_cores", "-"), ("one_core", "--")):
        rows = result[key]["evaluation"]
        where = "all cores" if key == "all_cores" else "one core"
        for name, color in colors.items():
            ax.plot(
                [r["size"] for r in rows],
                [r[f"{name}_evals_per_s"] for r in rows],
                style,
                marker="o",
                ms=3,
                color=color,
                label=f"frbjax {name}, {where}",
            )
    rows = [r for r in result["one_core"]["evaluation"] if "scipy_quaternion_s" in r]
    ax.plot(
        [r["size"] for r in rows],
        [r["scipy_quaternion_evals_per_s"] for r in rows],
        ":",
        marker="D",
        ms=3,
        color="k",
        label="scipy closed form quaternion, one core",
    )
    ax.axhline(1e9 / 300, color="gray", lw=1, ls="-.", label="300 ns per evaluation")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("batch size (evaluations per call)")
    ax.set_ylabel("evaluations per second (float64)")
    s = result["summary"]
    ax.set_title(
        f"frbjax throughput ({result['cpu_count']} cores); construction "
        f"{s['construction_ns_per_body_one_core']:.0f} ns/body, grad/forward {s['gradient_over_forward']:.1f}, "
        f"compile fwd {s['forward_compile_s']:.0f} s + grad {s['value_and_grad_compile_s']:.0f} s",
        fontsize=8,
    )
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
