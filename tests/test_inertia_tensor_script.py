"""Smoke run of benchmarks/inertia_tensor.py (--quick --no-orekit): every row measured and written out.

At the quick sizes (64 bodies x 16 times; 16 tensors in the sweep) the cost ratios are dominated by
dispatch and are only checked to be measured (the 5% target is for the full size, see the script);
the tensor and the principal-moment descriptions give the same motion (measured 2.4e-14), and the
sweep agrees with diffrax at the level of the test file (measured L 1.2e-13, q 1.3e-13).
"""

from __future__ import annotations

import json
import subprocess
import sys

from _benchmark_runs import finite_positive, ROOT


def test_inertia_tensor_quick(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            str(ROOT / "benchmarks" / "inertia_tensor.py"),
            "--quick",
            "--no-orekit",
            "--output-dir",
            str(tmp_path),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=1800,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    result = json.loads((tmp_path / "inertia_tensor.json").read_text())
    cost = result["cost"]
    for label in ("times_axis", "scalar_time"):
        for method in ("quaternion", "angular_momentum"):
            row = cost[f"{label}_{method}"]
            for name in ("ratio_median", "tensor_seconds_median", "moments_seconds_median"):
                assert finite_positive(row[name]), (label, method, name)
    assert cost["same_motion_max_difference_q"] < 1e-13
    accuracy = result["accuracy"]
    for path in ("FreeRigidBody", "free_flow"):
        assert accuracy[path]["max_L"] < 2e-13 and accuracy[path]["max_q"] < 2e-13, accuracy[path]
    assert result["orekit"]["skipped"] and "orekit-jpype" in result["orekit"]["how"]
