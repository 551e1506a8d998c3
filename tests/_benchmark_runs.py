"""Running a benchmark script's --quick smoke run from a test, and checks of its JSON."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]


def run_quick(script, output_dir):
    """stdout of ``benchmarks/<script> --quick --output-dir <output_dir>``; fails on a non-zero exit."""
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / script), "--quick", "--output-dir", str(output_dir)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=1800,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def finite_positive(value):
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0
