"""The public-input harness of tests/test_public_inputs.py with many more examples per entry point.

The test suite draws 12 examples per entry point (each spoiling one argument or calling with valid
ones); this run draws ``--examples`` (default 500), the way a fuzzer would, and reports pytest's
summary.  Usage:

    .venv/bin/python benchmarks/fuzz_inputs.py [--examples 500]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=500, help="hypothesis examples per entry point")
    args = parser.parse_args(argv)
    environment = dict(os.environ, FRBJAX_HARNESS_EXAMPLES=str(args.examples))
    command = [
        sys.executable,
        "-m",
        "pytest",
        "-q",
        "-p",
        "no:cacheprovider",
        "--durations=10",
        str(ROOT / "tests" / "test_public_inputs.py"),
    ]
    return subprocess.call(command, cwd=ROOT, env=environment)


if __name__ == "__main__":
    sys.exit(main())
