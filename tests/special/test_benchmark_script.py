"""The benchmark scripts run (tiny smoke runs, so CI proves they work)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from _benchmark_runs import run_quick


ROOT = Path(__file__).resolve().parents[2]


def test_benchmark_quick(tmp_path):
    output = tmp_path / "special.json"
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "special.py"), "--quick", "--output", str(output)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    result = json.loads(output.read_text())
    names = {row["function"] for row in result["functions"]}
    assert names == {
        "ellipj",
        "ellipk",
        "ellipe",
        "ellipkinc",
        "ellippiinc",
        "elliprf",
        "elliprd",
        "elliprj",
        "elliprc",
    }
    for row in result["functions"]:
        assert row["frbjax_ns_per_point"] > 0 and row["scipy_ns_per_point"] > 0, row
        # Same function on the same points (scipy's ellipj is accurate on this moderate grid).
        assert row["max_diff_vs_scipy"] < 1e-10, row
    assert result["gradient"]["compile_s"] > 0
    assert "ellippiinc" in proc.stdout


def test_kernels_benchmark_quick():
    """benchmarks/kernels.py --quick: R_C on both paths, each in its own process."""
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "kernels.py"), "--quick"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "elliprc: first value" in proc.stdout and "scipy / kernels" in proc.stdout, proc.stdout


def test_special_eager_quick(tmp_path):
    """benchmarks/special_eager.py --quick: ellipk called eagerly, one program and scipy, each in its own process."""
    stdout = run_quick("special_eager.py", tmp_path)
    row = json.loads((tmp_path / "special_eager.json").read_text())["functions"]["ellipk"]
    for mode in ("one program", "scipy"):
        assert row[mode]["first_s"] > 0 and row[mode]["call_s"] > 0, row
    assert "one program / scipy per call" in stdout
