"""Smoke runs of benchmarks/torqued.py and benchmarks/calgo903_example1.py (--quick).

The JSON must have the expected keys and finite numbers, and what the quick sizes can show must hold:
at T = 10 the splitting and Dopri8 reach the errors measured, the energy error of the splitting stays
bounded over its 10^3 steps, example 1's first 200 steps agree with the Fortran output.  Compilation
dominates the wall time; the subprocesses share the session's persistent compilation cache.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(script, output_dir, request):
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


def _finite_positive(value):
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0


def test_torqued_quick(tmp_path, request):
    _run("torqued.py", tmp_path, request)
    precision = json.loads((tmp_path / "torqued_work_precision.json").read_text())
    assert (tmp_path / "torqued_work_precision.png").stat().st_size > 0
    top = precision["problems"]["heavy_top"]
    assert top["reference_floor"] < 1e-12
    assert set(top["methods"]) == {"blanes_moan6", "Dopri8"}
    for method in top["methods"].values():
        for point in method["points"]:
            assert _finite_positive(point["seconds"]) and _finite_positive(point["error"]), point
    # The spinning top, blanes_moan6 at h = 0.25 to T = 10: measured 1.7e-9.
    assert top["methods"]["blanes_moan6"]["points"][-1]["error"] < 5e-9

    energy = json.loads((tmp_path / "torqued_energy.json").read_text())
    assert (tmp_path / "torqued_energy.png").stat().st_size > 0
    assert set(energy["runs"]) == {"blanes_moan4", "Tsit5"}
    assert energy["runs"]["blanes_moan4"]["ratio_last_to_first_tenth"] <= 2

    batch = json.loads((tmp_path / "torqued_batch.json").read_text())
    assert batch["batch"]["bodies"] == 8 and batch["one_body"]["bodies"] == 1
    assert _finite_positive(batch["batch"]["microseconds_per_free_flow_per_body"])


def test_calgo903_example1_quick(tmp_path, request):
    _run("calgo903_example1.py", tmp_path, request)
    result = json.loads((tmp_path / "calgo903_example1.json").read_text())
    assert result["steps"] == 200 and result["free_flows"] == 3000
    assert _finite_positive(result["run_seconds"])
    # Measured 2.4e-13 over the first 200 steps.
    assert result["max_error_all_steps"] < 1e-12
