"""Running a benchmark script's --quick smoke run from a test, and checks of its JSON.

The scripts' wall time is dominated by XLA compiling frbjax, so the subprocesses share the test
session's persistent compilation cache (pytest's cache directory, as conftest.py sets up).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_quick(script, output_dir, request):
    """stdout of ``benchmarks/<script> --quick --output-dir <output_dir>``; fails on a non-zero exit."""
    env = dict(os.environ)
    cache = getattr(request.config, "cache", None)
    if cache is not None:
        env.setdefault("JAX_COMPILATION_CACHE_DIR", str(cache.mkdir("jax-compilation-cache")))
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / script), "--quick", "--output-dir", str(output_dir)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=1800,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def finite_positive(value):
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0
