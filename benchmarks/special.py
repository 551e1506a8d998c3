"""Benchmark frbjax.special against scipy.special on the same random points.

For each function: ns per point for frbjax (float64, jit-compiled, after warm-up, best of a few
repeats, ``block_until_ready``) and for scipy.special on the same points in the same run, their
ratio, the jit compile time (lower + compile), and the largest difference between the two results
(relative to max(1, |scipy|), a sanity check that both computed the same thing).  Also the compile time of
ellippiinc together
with its gradient (jax.grad of the sum over a batch with respect to phi, m and n).

scipy has no incomplete Pi; it is timed as the closed form through Carlson integrals,
Pi(n; phi|m) = s R_F(c^2, 1 - m s^2, 1) + n/3 s^3 R_J(c^2, 1 - m s^2, 1, 1 - n s^2)  (DLMF 19.25.14),
with phi reduced to [-pi/2, pi/2] and 2k Pi(n|m) added (Pi(n|m) from the same formula at phi = pi/2).

Usage: python benchmarks/special.py [--n 1000000] [--repeats 5] [--quick] [--output PATH]
Writes the table as JSON to benchmarks/results/special.json (or --output).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402
import scipy.special as sc  # noqa: E402


sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import frbjax.special as fs  # noqa: E402


DEFAULT_OUTPUT = Path(__file__).resolve().parent / "results" / "special.json"


def scipy_ellippiinc(n, phi, m):
    """Pi(n; phi|m) for any real phi through scipy's Carlson integrals (see module docstring)."""
    k = np.round(phi / np.pi)
    r = phi - k * np.pi
    s, c = np.sin(r), np.cos(r)
    s2 = s * s
    delta = 1 - m * s2
    value = s * sc.elliprf(c * c, delta, 1.0) + n / 3 * s * s2 * sc.elliprj(c * c, delta, 1.0, 1 - n * s2)
    mc = 1 - m
    complete = sc.elliprf(0.0, mc, 1.0) + n / 3 * sc.elliprj(0.0, mc, 1.0, 1 - n)
    return value + 2 * k * complete


def points(rng, size):
    """Random points inside each function's domain (float64)."""
    uni = rng.uniform
    m = uni(0, 1, size)
    carlson = lambda: 10 ** uni(-3, 3, size)  # noqa: E731
    return {
        "ellipj": (uni(-20, 20, size), m),
        "ellipk": (m,),
        "ellipe": (m,),
        "ellipkinc": (uni(-2 * np.pi, 2 * np.pi, size), m),
        "ellippiinc": (uni(-1, 0.95, size), uni(-2 * np.pi, 2 * np.pi, size), m),
        "elliprf": (carlson(), carlson(), carlson()),
        "elliprd": (carlson(), carlson(), carlson()),
        "elliprj": (carlson(), carlson(), carlson(), carlson()),
        "elliprc": (carlson(), carlson()),
    }


SCIPY = {
    "ellipj": sc.ellipj,
    "ellipk": sc.ellipk,
    "ellipe": sc.ellipe,
    "ellipkinc": sc.ellipkinc,
    "ellippiinc": scipy_ellippiinc,
    "elliprf": sc.elliprf,
    "elliprd": sc.elliprd,
    "elliprj": sc.elliprj,
    "elliprc": sc.elliprc,
}


def best_time(fn, repeats):
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def bench_function(name, args, repeats):
    jitted = jax.jit(getattr(fs, name))
    device_args = [jax.device_put(jnp.asarray(a)) for a in args]
    start = time.perf_counter()
    compiled = jitted.lower(*device_args).compile()
    compile_s = time.perf_counter() - start
    ours_out = jax.block_until_ready(compiled(*device_args))  # warm-up
    ours = best_time(lambda: jax.block_until_ready(compiled(*device_args)), repeats)
    with np.errstate(all="ignore"):
        theirs_fn = SCIPY[name]
        theirs_out = theirs_fn(*args)  # warm-up
        theirs = best_time(lambda: theirs_fn(*args), repeats)
    # Same function on the same points: the largest difference, relative to max(1, |scipy|).
    pairs = zip(ours_out, theirs_out) if isinstance(ours_out, tuple) else [(ours_out, theirs_out)]
    with np.errstate(all="ignore"):
        diff = max(float(np.nanmax(np.abs(np.asarray(a) - b) / np.maximum(1.0, np.abs(b)))) for a, b in pairs)
    size = args[0].size
    return {
        "function": name,
        "frbjax_ns_per_point": ours / size * 1e9,
        "scipy_ns_per_point": theirs / size * 1e9,
        "ratio_frbjax_over_scipy": ours / theirs,
        "compile_s": compile_s,
        "max_diff_vs_scipy": diff,
    }


def bench_gradient(args, repeats):
    """Compile (and run) time of ellippiinc with its gradient w.r.t. phi, m and n."""
    n, phi, m = (jnp.asarray(a) for a in args)

    def loss(phi, m, n):
        return jnp.sum(fs.ellippiinc(n, phi, m))

    value_and_grad = jax.jit(jax.value_and_grad(loss, argnums=(0, 1, 2)))
    start = time.perf_counter()
    compiled = value_and_grad.lower(phi, m, n).compile()
    compile_s = time.perf_counter() - start
    jax.block_until_ready(compiled(phi, m, n))
    run = best_time(lambda: jax.block_until_ready(compiled(phi, m, n)), repeats)
    return {
        "function": "ellippiinc value_and_grad (phi, m, n)",
        "compile_s": compile_s,
        "frbjax_ns_per_point": run / phi.size * 1e9,
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1_000_000, help="points per function")
    parser.add_argument("--repeats", type=int, default=5, help="timed repeats (best is kept)")
    parser.add_argument("--quick", action="store_true", help="tiny smoke run (1000 points, 1 repeat)")
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT, help="JSON output path")
    parser.add_argument("--only", nargs="*", help="restrict to these functions")
    options = parser.parse_args(argv)
    size, repeats = (1000, 1) if options.quick else (options.n, options.repeats)

    rng = np.random.default_rng(0)
    grid = points(rng, size)
    names = options.only or list(grid)
    rows = []
    header = f"{'function':<12} {'frbjax ns/pt':>13} {'scipy ns/pt':>12} {'ratio':>7} {'compile s':>10} {'max diff':>9}"
    print(
        f"frbjax.special vs scipy.special {scipy.__version__}, {size} float64 points, "
        f"best of {repeats}, device {jax.devices()[0]}"
    )
    print(header)
    print("-" * len(header))
    for name in names:
        row = bench_function(name, grid[name], repeats)
        rows.append(row)
        print(
            f"{name:<12} {row['frbjax_ns_per_point']:>13.1f} {row['scipy_ns_per_point']:>12.1f} "
            f"{row['ratio_frbjax_over_scipy']:>7.2f} {row['compile_s']:>10.2f} "
            f"{row['max_diff_vs_scipy']:>9.1e}",
            flush=True,
        )
    gradient = None
    if not options.only or "ellippiinc" in names:
        gradient = bench_gradient(grid["ellippiinc"], repeats)
        print(
            f"ellippiinc + grad w.r.t. (phi, m, n): compile {gradient['compile_s']:.2f} s, "
            f"{gradient['frbjax_ns_per_point']:.1f} ns per point (value and gradient)"
        )
    result = {
        "points": size,
        "repeats": repeats,
        "dtype": "float64",
        "device": str(jax.devices()[0]),
        "jax": jax.__version__,
        "scipy": scipy.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "quick": options.quick,
        "functions": rows,
        "gradient": gradient,
    }
    options.output.parent.mkdir(parents=True, exist_ok=True)
    options.output.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {options.output}")
    return result


if __name__ == "__main__":
    main()
