"""Explore the hypothesis properties of tests/test_properties.py on many random examples.

The tests run a few dozen derandomized examples; their tolerances come from this script, which draws
N random examples from the same strategies and records the worst ratio (error / rounding scale) of
each property, with the body that produced it.

Usage: python benchmarks/properties.py [--n 2000] [--output PATH]
Writes benchmarks/results/properties.json (or --output).
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import jax
import numpy as np
from hypothesis import given, HealthCheck, settings, strategies as st


ROOT = Path(__file__).resolve().parent.parent
DEFAULT_OUTPUT = ROOT / "benchmarks" / "results" / "properties.json"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=2000)
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT)
    args = parser.parse_args()
    jax.config.update("jax_enable_x64", True)
    warnings.simplefilter("ignore")
    sys.path.insert(0, str(ROOT / "tests"))
    import test_properties as properties

    worst = {}

    def record(errors, case):
        for name, value in errors.items():
            if value > worst.get(name, {"ratio": -1.0})["ratio"]:
                worst[name] = {"ratio": float(value), "case": [np.asarray(a).tolist() for a in case]}

    @settings(max_examples=args.n, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(
        properties.cases(),
        st.lists(st.integers(0, 23), min_size=properties.BATCH, max_size=properties.BATCH),
        st.lists(st.integers(-10, 10), min_size=properties.BATCH, max_size=properties.BATCH),
    )
    def explore(case, permutations, exponents):
        record(properties.invariant_errors(case), case)
        record(properties.group_errors(case), case)
        record(properties.permutation_errors(case, permutations, 2.0 ** np.array(exponents)), case)

    explore()
    tolerances = {**properties.INVARIANT_TOLERANCE, **properties.GROUP_TOLERANCE, **properties.PERMUTATION_TOLERANCE}
    print(f"{'property':<18} {'worst':>10} {'tolerance':>10}   ({args.n} examples of {properties.BATCH} bodies)")
    for name, entry in worst.items():
        print(f"{name:<18} {entry['ratio']:10.3g} {tolerances[name]:10.3g}")
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps({"examples": args.n, "worst": worst}, indent=1))


if __name__ == "__main__":
    main()
