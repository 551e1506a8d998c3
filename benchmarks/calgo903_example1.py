"""CALGO 903 example 1 in full: 10,000 steps of the torqued body, timed and compared with the Fortran.

Example 1 of CALGO 903 (Celledoni and Zanna, ACM TOMS 37(2), 2010) integrates a torqued body with
the 6th-order Blanes-Moan splitting SRKN6a_14: per step 15 exact free flows and 14 kicks, 150,000
free flows in all.  The test suite runs the first 1000 steps; this script runs them all and prints

- the time to compile the step program and the time to run the steps (no persistent cache);
- the maximum difference from out_example1.dat over Pi and Q, after 1000 steps and at the end
  (gfortran reproduces that file only to 2.3e-10).

Usage: ``python benchmarks/calgo903_example1.py [--steps N] [--data FOLDER] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from frbjax import _calgo903 as calgo  # noqa: E402

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
DATA = REPOSITORY / "tests" / "data" / "calgo903"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=None, help="steps to run (default: all 10,000)")
    parser.add_argument("--data", type=pathlib.Path, default=DATA, help=f"CALGO 903 data (default {DATA})")
    parser.add_argument("--json", type=pathlib.Path, help="also write the results to this JSON file")
    args = parser.parse_args(argv)

    problem = calgo.read_input(args.data / "init_example1.dat")
    expected = calgo.read_output(args.data / "out_example1.dat", problem.layout)
    steps = problem.steps if args.steps is None else args.steps

    kicks, flows = calgo._stage_coefficients(problem["a"], problem["b"])
    momentum, attitude = problem.initial_state()
    arguments = (problem["I"], problem["u0"], kicks, flows, problem.step, momentum, attitude)
    timings = []
    for _ in range(2):  # the first call compiles the step program, the second only runs it
        start = time.perf_counter()
        jax.block_until_ready(calgo._splitting_chunk(*arguments))
        timings.append(time.perf_counter() - start)
    compile_seconds = timings[0] - timings[1]

    start = time.perf_counter()
    trajectory = calgo.solve(problem, steps=steps)
    run_seconds = time.perf_counter() - start

    def error(records):
        return float(max(np.abs(trajectory.momentum[:records] - expected.momentum[:records]).max(),
                         np.abs(trajectory.attitude[:records] - expected.attitude[:records]).max()))

    results = {
        "steps": steps,
        "free_flows": 15 * steps,
        "compile_seconds": round(compile_seconds, 2),
        "run_seconds": round(run_seconds, 2),
        "microseconds_per_free_flow": round(1e6 * run_seconds / (15 * steps), 1),
        "max_error_first_1000_steps": error(min(steps, 1000) + 1),
        "max_error_all_steps": error(steps + 1),
        "device": str(jax.devices()[0]),
    }
    for key, value in results.items():
        print(f"{key:28s} {value}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
