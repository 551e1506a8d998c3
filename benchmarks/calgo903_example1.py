"""CALGO 903 example 1 in full: 10,000 steps of the torqued body, timed and compared with the Fortran.

Example 1 of CALGO 903 (Celledoni and Zanna, ACM TOMS 37(2), 2010) integrates a torqued body with
the 6th-order Blanes-Moan splitting SRKN6a: per step 15 exact free flows and 14 kicks, 150,000 free
flows in all.  This script runs it the way ``frbjax run init_example1.dat`` does (through the public
``frbjax.splitting_trajectory``) and prints

- the time to compile the step program and the best of three runs of all the steps (compilation
  excluded), to compare with the Fortran driver's 0.21 s (gfortran -O2, one core; run this script
  under ``taskset -c 0`` for one core);
- both with XLA's default flags as a user's own script has them: on the CPU each free flow is one
  call of the package's compiled motion kernel, and, in a second process with ``FRBJAX_KERNELS=jax``,
  the JAX formulas compiled by XLA (every free flow runs its some hundred kernels one by one), so
  that the JSON has both;
- the maximum difference from out_example1.dat over Pi and Q, after 1000 steps and at the end
  (gfortran reproduces that file only to 2.3e-10).

Usage: ``python benchmarks/calgo903_example1.py [--steps N] [--quick] [--output-dir DIR]
[--jax-formulas]``; writes ``calgo903_example1.json`` there (default benchmarks/results).
``--jax-formulas`` measures the JAX formulas only (no second process).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import jax


jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from frbjax import _calgo903 as calgo  # noqa: E402
from frbjax.special import _compiled  # noqa: E402


REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
DATA = REPOSITORY / "tests" / "data" / "calgo903"
RESULTS = REPOSITORY / "benchmarks" / "results"
FORTRAN_SECONDS = 0.21  # the CALGO 903 driver, gfortran -O2, one core of this machine class
QUICK_STEPS = 200


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=None, help="steps to run (default: all 10,000)")
    parser.add_argument("--quick", action="store_true", help=f"smoke test: {QUICK_STEPS} steps, one run")
    parser.add_argument("--output-dir", type=pathlib.Path, default=RESULTS)
    parser.add_argument(
        "--jax-formulas",
        action="store_true",
        help="the JAX formulas only (FRBJAX_KERNELS=jax; no second process)",
    )
    args = parser.parse_args(argv)
    environment = dict(os.environ)
    if args.jax_formulas:
        os.environ["FRBJAX_KERNELS"] = "jax"
    runtime = "compiled_kernels" if _compiled.selected(np.zeros(3)) else "jax_formulas"

    problem = calgo.read_input(DATA / "init_example1.dat")
    expected = calgo.read_output(DATA / "out_example1.dat", problem.layout)
    steps = QUICK_STEPS if args.quick else (problem.steps if args.steps is None else args.steps)
    program = calgo.example1_program(problem, steps)
    momentum, attitude = problem.initial_state()

    def run():
        return jax.block_until_ready(program(momentum, attitude))

    start = time.perf_counter()
    run()
    first = time.perf_counter() - start
    timings = []
    for _ in range(1 if args.quick else 3):
        start = time.perf_counter()
        run()
        timings.append(time.perf_counter() - start)
    run_seconds = min(timings)
    trajectory = calgo.solve(problem, steps=steps)

    def error(records):
        return float(
            max(
                np.abs(trajectory.momentum[:records] - expected.momentum[:records]).max(),
                np.abs(trajectory.attitude[:records] - expected.attitude[:records]).max(),
            )
        )

    results = {
        "steps": steps,
        "free_flows": 15 * steps,
        "compile_seconds": round(first - run_seconds, 2),
        "run_seconds": round(run_seconds, 4),
        "microseconds_per_step": round(1e6 * run_seconds / steps, 2),
        "microseconds_per_free_flow": round(1e6 * run_seconds / (15 * steps), 3),
        "fortran_seconds_10000_steps": FORTRAN_SECONDS,
        "ratio_to_fortran": round(run_seconds * problem.steps / steps / FORTRAN_SECONDS, 2),
        "max_error_first_1000_steps": error(min(steps, 1000) + 1),
        "max_error_all_steps": error(steps + 1),
        "device": str(jax.devices()[0]),
        "motion": runtime,
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
    }
    if not args.jax_formulas:
        results["jax_formulas"] = _jax_formulas(_argv_steps(args), environment)
    for key, value in results.items():
        print(f"{key:28s} {value}")
    args.output_dir.mkdir(parents=True, exist_ok=True)
    (args.output_dir / "calgo903_example1.json").write_text(json.dumps(results, indent=2) + "\n")


def _argv_steps(args):
    return (["--quick"] if args.quick else []) + ([] if args.steps is None else ["--steps", str(args.steps)])


def _jax_formulas(extra, environment):
    """This script in a second process with the JAX formulas (the switch is read once per process)."""
    with tempfile.TemporaryDirectory() as folder:
        subprocess.run(
            [sys.executable, __file__, "--jax-formulas", "--output-dir", folder, *extra],
            check=True,
            stdout=subprocess.DEVNULL,
            env=environment,
        )
        other = json.loads((pathlib.Path(folder) / "calgo903_example1.json").read_text())
    keys = ("compile_seconds", "run_seconds", "microseconds_per_free_flow", "ratio_to_fortran", "max_error_all_steps")
    return {key: other[key] for key in keys}


if __name__ == "__main__":
    main()
