"""The compiled CPU kernels of the special functions against the JAX path and scipy.special.

For each Carlson integral and ellipj (sn's derivatives), in a fresh process per path (so that nothing
is compiled before): the
time to the first value, first gradient and first Hessian of one point under ``jax.jit`` (compile
included), then the time per evaluation over 10^6 points (best of 5, compiled), and scipy's time per
evaluation on the same points.  Prints the ratios JAX path / kernels and scipy / kernels, and writes
benchmarks/results/kernels.json.

    python benchmarks/kernels.py [--points N] [--quick]

One core: run it as ``taskset -c 0 python benchmarks/kernels.py`` for the figures of docs/performance.md.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys


FUNCTIONS = {"elliprf": 3, "elliprd": 3, "elliprj": 4, "elliprc": 2, "ellipj": 2}
RESULTS = pathlib.Path(__file__).resolve().parent / "results" / "kernels.json"

CHILD = r"""
import json, sys, time
start = time.perf_counter()
import jax
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp, numpy as np
import frbjax.special as special
name, arity, points = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
# ellipj: sn(u|m) (the gradient in u and m), at m in (0, 1).
function = (lambda u, m: special.ellipj(u, m)[0]) if name == "ellipj" else getattr(special, name)
point = [0.7, 0.4] if name == "ellipj" else [1.0 + k for k in range(arity)]
def first(program):
    t = time.perf_counter()
    jax.block_until_ready(program(*point))
    return time.perf_counter() - t
row = {"import_s": time.perf_counter() - start}
row["value_s"] = first(jax.jit(function))
row["gradient_s"] = first(jax.jit(jax.grad(function, argnums=tuple(range(arity)))))
row["hessian_s"] = first(jax.jit(jax.hessian(function, argnums=tuple(range(arity)))))
rng = np.random.default_rng(0)
arguments = [jnp.asarray(10 ** rng.uniform(-3, 3, points)) for _ in range(arity)]
if name == "ellipj":
    arguments = [jnp.asarray(rng.uniform(-10, 10, points)), jnp.asarray(rng.uniform(0, 1, points))]
program = jax.jit(special.ellipj if name == "ellipj" else function)
jax.block_until_ready(program(*arguments))
best = float("inf")
for _ in range(5):
    t = time.perf_counter()
    jax.block_until_ready(program(*arguments))
    best = min(best, time.perf_counter() - t)
row["ns_per_evaluation"] = best / points * 1e9
import scipy.special
host = [np.asarray(a) for a in arguments]
best = float("inf")
for _ in range(5):
    t = time.perf_counter()
    getattr(scipy.special, name)(*host)  # ellipj: all four functions, as frbjax's program
    best = min(best, time.perf_counter() - t)
row["scipy_ns_per_evaluation"] = best / points * 1e9
print(json.dumps(row))
"""


def measure(name, arity, path, points):
    environment = dict(os.environ, FRBJAX_KERNELS=path)
    result = subprocess.run(
        [sys.executable, "-c", CHILD, name, str(arity), str(points)],
        env=environment,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(result.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--points", type=int, default=10**6)
    parser.add_argument("--quick", action="store_true", help="R_C only, 10^4 points (a smoke run)")
    args = parser.parse_args()
    functions = {"elliprc": 2} if args.quick else FUNCTIONS
    points = 10**4 if args.quick else args.points
    rows = {}
    for name, arity in functions.items():
        compiled = measure(name, arity, "compiled", points)
        jax_path = measure(name, arity, "jax", points)
        rows[name] = {"compiled": compiled, "jax": jax_path}
        print(
            f"{name}: first value {compiled['value_s']:.3f} s (JAX path {jax_path['value_s']:.2f} s, "
            f"{jax_path['value_s'] / compiled['value_s']:.0f}x), first gradient {compiled['gradient_s']:.3f} s "
            f"({jax_path['gradient_s'] / compiled['gradient_s']:.0f}x), first Hessian {compiled['hessian_s']:.3f} s "
            f"({jax_path['hessian_s'] / compiled['hessian_s']:.0f}x)"
        )
        jax_ratio = jax_path["ns_per_evaluation"] / compiled["ns_per_evaluation"]
        scipy_ratio = compiled["scipy_ns_per_evaluation"] / compiled["ns_per_evaluation"]
        print(
            f"  per evaluation ({points} points): {compiled['ns_per_evaluation']:.0f} ns, JAX path "
            f"{jax_path['ns_per_evaluation']:.0f} ns (JAX / kernels {jax_ratio:.2f}), "
            f"scipy {compiled['scipy_ns_per_evaluation']:.0f} ns (scipy / kernels {scipy_ratio:.2f})"
        )
    if not args.quick:
        RESULTS.parent.mkdir(exist_ok=True)
        RESULTS.write_text(json.dumps({"points": points, "functions": rows}, indent=1) + "\n")
        print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
