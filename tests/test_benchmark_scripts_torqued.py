"""Smoke runs of benchmarks/torqued.py and benchmarks/calgo903_example1.py (--quick).

The JSON must have the expected keys and finite numbers, and what the quick sizes can show must hold:
at T = 10 the splitting and Dopri8 reach the errors measured, the energy error of the splitting stays
bounded over its 10^3 steps, example 1's first 200 steps agree with the Fortran output.
"""

from __future__ import annotations

import json

from _benchmark_runs import finite_positive, run_quick


def test_torqued_quick(tmp_path):
    run_quick("torqued.py", tmp_path)
    precision = json.loads((tmp_path / "torqued_work_precision.json").read_text())
    assert (tmp_path / "torqued_work_precision.png").stat().st_size > 0
    top = precision["problems"]["heavy_top"]
    assert top["reference_floor"] < 1e-12
    assert set(top["methods"]) == {"blanes_moan6", "Dopri8"}
    for method in top["methods"].values():
        for point in method["points"]:
            assert finite_positive(point["seconds"]) and finite_positive(point["error"]), point
    # The spinning top, blanes_moan6 at h = 0.25 to T = 10: measured 1.7e-9.
    assert top["methods"]["blanes_moan6"]["points"][-1]["error"] < 5e-9

    energy = json.loads((tmp_path / "torqued_energy.json").read_text())
    assert (tmp_path / "torqued_energy.png").stat().st_size > 0
    assert set(energy["runs"]) == {"blanes_moan4", "Tsit5"}
    assert energy["runs"]["blanes_moan4"]["ratio_last_to_first_tenth"] <= 2

    batch = json.loads((tmp_path / "torqued_batch.json").read_text())
    assert batch["batch"]["bodies"] == 8 and batch["one_body"]["bodies"] == 1
    assert finite_positive(batch["batch"]["microseconds_per_free_flow_per_body"])


def test_calgo903_example1_quick(tmp_path):
    run_quick("calgo903_example1.py", tmp_path)
    result = json.loads((tmp_path / "calgo903_example1.json").read_text())
    assert result["steps"] == 200 and result["free_flows"] == 3000
    assert finite_positive(result["run_seconds"])
    # Measured 2.4e-13 over the first 200 steps, with the compiled kernels and, in the script's second
    # process, with the JAX formulas (FRBJAX_KERNELS=jax).
    assert result["motion"] == "compiled_kernels"
    assert result["max_error_all_steps"] < 1e-12
    assert finite_positive(result["jax_formulas"]["run_seconds"])
    assert result["jax_formulas"]["max_error_all_steps"] < 1e-12
