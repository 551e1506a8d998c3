"""benchmarks/fuzz.py with a small N, in-process: no NaN and the invariants within measured bounds."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np


FUZZ = Path(__file__).resolve().parent.parent / "benchmarks" / "fuzz.py"

# Measured worst (n = 2000, seed 0, 4 times per body, |L| 1e-3 .. 1e3, |t| up to 1e3): |q| - 1 4.4e-16
# (sphere), |L| 4.6e-16, energy 9.4e-16 (generic), R L 5.6e-15 (nearly symmetric); tolerances ~2x.
TOLERANCE = dict(quaternion_norm=9e-16, momentum_norm=1e-15, energy=2e-15, spatial_momentum=1.1e-14)


def _load():
    spec = importlib.util.spec_from_file_location("frbjax_benchmark_fuzz", FUZZ)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_fuzz_small(tmp_path):
    fuzz = _load()
    output = tmp_path / "fuzz.json"
    result = fuzz.main(n=2000, seed=0, chunk=2000, output=output, verbose=False)
    assert json.loads(output.read_text())["n"] == 2000
    assert result["non_finite"] == 0, result["non_finite_examples"]
    for name, bound in TOLERANCE.items():
        value = result["worst"][name]["value"]
        assert np.isfinite(value) and value <= bound, f"{name}: {value:.3g} ({result['worst'][name]})"
