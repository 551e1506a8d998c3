"""Smoke run of benchmarks/torques_basilisk.py (--quick --without-basilisk: Basilisk is no test dependency).

The JSON must have the expected keys and finite numbers, and what the quick sizes can show must hold:
at T = 1 h the splitting and Dopri8 reach the errors measured on the damped satellite, the splitting
keeps the heavy top's energy bounded over its 10^3 steps, and the two-day debris run agrees with
Dopri8.
"""

from __future__ import annotations

import json
import subprocess
import sys

from _benchmark_runs import finite_positive, ROOT


def test_torques_basilisk_quick(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            str(ROOT / "benchmarks" / "torques_basilisk.py"),
            "--quick",
            "--without-basilisk",
            "--repeats",
            "1",
            "--output-dir",
            str(tmp_path),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=1800,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr

    basilisk = json.loads((tmp_path / "torques_basilisk.json").read_text())
    assert (tmp_path / "torques_basilisk.png").stat().st_size > 0
    assert "left out" in basilisk["basilisk"] and basilisk["bodies_in_batch"] == 8
    for name in ("damped", "undamped"):
        entry = basilisk["problems"][name]
        assert set(entry["methods"]) == {"blanes_moan4", "Dopri8"}
        assert entry["reference_distance_to_1e-13"] < 1e-11  # measured 3.7e-13
        for method in entry["methods"].values():
            for point in method["points"]:
                assert finite_positive(point["seconds"]) and finite_positive(point["error"]), point
    # The damped satellite to T = 1 h, blanes_moan4 at h = 20 s: measured 2.9e-8 (reference 3.6e-13).
    assert basilisk["problems"]["damped"]["methods"]["blanes_moan4"]["points"][-1]["error"] < 6e-8

    energy = json.loads((tmp_path / "torques_energy.json").read_text())
    assert (tmp_path / "torques_energy.png").stat().st_size > 0
    for case in ("large_step", "small_step"):
        runs = energy["cases"][case]["runs"]
        assert set(runs) == {"blanes_moan4", "Tsit5", "Dopri8"}
        assert runs["blanes_moan4"]["ratio_last_to_first_tenth"] <= 2  # measured 0.98 and 1.10

    debris = json.loads((tmp_path / "torques_debris.json").read_text())
    assert (tmp_path / "torques_debris.png").stat().st_size > 0
    assert finite_positive(debris["blanes_moan4"]["seconds"]) and finite_positive(debris["Dopri8"]["seconds"])
    # Two days at h = 10 s: measured 1.6e-7 in the spin rate, 1.0e-5 in the state.
    assert debris["max_spin_rate_relative_difference"] < 5e-7
    assert debris["max_relative_difference"] < 5e-5
