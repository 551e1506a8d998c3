"""Smoke run of benchmarks/setup_cost.py (--quick): every row measured, finite, and written out.

What the quick sizes can show must hold too: the eager call dispatches compiled programs (its
target, at most 10 times the jitted call, is met at any size: measured 3.4 to 3.6), and the state at
T = 10 agrees with diffrax Dopri8 at 1e-12 (measured 3.3e-12 at the full size).
"""

from __future__ import annotations

import json

import pytest
from _benchmark_runs import finite_positive, run_quick


@pytest.mark.slow(
    reason="140 s CPU on one pinned core: every row compiles its programs, diffrax's value_and_grad "
    "and fit_attitude's first call among them, and two latency subprocesses"
)
def test_setup_cost_quick(tmp_path):
    run_quick("setup_cost.py", tmp_path)
    result = json.loads((tmp_path / "setup_cost.json").read_text())
    assert (tmp_path / "setup_cost.png").stat().st_size > 0
    assert set(result["ratios"]) == set(result["targets"]) == set(result["before"])
    for name, ratio in result["ratios"].items():
        assert finite_positive(ratio), name
    assert result["met"]["eager"]
    # The kernel counts that explain the compile and one-body rows are recorded for both programs.
    compile_row = result["rows"]["compile"]
    for name in ("frbjax_forward", "frbjax_value_and_grad", "diffrax_dopri8_forward", "diffrax_dopri8_value_and_grad"):
        assert compile_row[f"{name}_kernels"]["fusions"] > 0, name
    # free_flow of one body is one compiled kernel on the CPU (csrc/free_flow.hpp): no fused loop of
    # XLA's of its own; FreeRigidBody's evaluation calls the series kernel among XLA's loops.
    free_flow_kernels = result["rows"]["one_body"]["free_flow"]["kernels"]
    assert free_flow_kernels["compiled_kernels"] == 1 and free_flow_kernels["fusions"] == 0, free_flow_kernels
    assert result["rows"]["one_body"]["FreeRigidBody"]["kernels"]["compiled_kernels"] >= 1
    # Example 1 runs with XLA's default loop settings.
    assert "xla_backend_extra_options" not in result["rows"]["calgo903_example1"]["xla_flags"]
    assert result["rows"]["state_at_T"]["diffrax_ok"]
    assert result["rows"]["state_at_T"]["max_difference"] < 1e-10
    # No GPU on the CI machines: the row is absent there rather than made up.
    assert (result["rows"]["gpu_construction"] is None) == (result["machine"]["backend"] != "gpu")
