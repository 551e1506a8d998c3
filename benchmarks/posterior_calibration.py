"""Simulation-based calibration (Talts et al. 2018) of frbjax.posterior.attitude_posterior.

``--sets`` synthetic attitude data sets (default 100) drawn from the calibration prior of
tests/test_posterior.py (log-ratios uniform within +-0.15 of those of moments 0.6 : 0.8 : 1, angular
velocity at t = 0 normal about (0.4, 0.3, 0.8) rad/s with standard deviation 0.1, isotropic attitude),
40 attitudes each over about three rotation periods with 1e-3 rad isotropic noise; each posterior
with the test's sizes (4 chains of 100 warmup steps and 100 draws, every 4th draw kept for the
ranks).  For each of the five quantities (log I2/I1, log I3/I1, Omega_1..3) and pooled: the
chi-square p-value of the truths' ranks over 5 bins (uniform if calibrated), and how often the 50%
and 90% central intervals cover the truth, with the 3-sigma binomial band.  Also the wall time per
posterior after compilation (the fit and the sampler) and the first call's.  Writes
benchmarks/results/posterior_calibration.json.  ``--quick``: 4 data sets (a smoke test).

    .venv/bin/python benchmarks/posterior_calibration.py [--sets 100] [--quick] [--output-dir DIR]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import pathlib
import platform
import sys
import time

import jax


jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")


ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
_spec = importlib.util.spec_from_file_location("_posterior_problems", ROOT / "tests" / "test_posterior.py")
problems = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(problems)

QUANTITIES = ("log_I2_over_I1", "log_I3_over_I1", "omega_1", "omega_2", "omega_3")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", type=int, default=100)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--bins", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="4 data sets (smoke test)")
    parser.add_argument("--output-dir", type=pathlib.Path, default=ROOT / "benchmarks" / "results")
    arguments = parser.parse_args()
    if arguments.quick:
        arguments.sets = 4
    machine = {
        "backend": jax.default_backend(),
        "device": str(jax.devices()[0]),
        "cpus": os.cpu_count(),
        "platform": platform.platform(),
        "jax": jax.__version__,
    }
    # The first call compiles the fit and the sampler (one data set, not counted below).
    start = time.perf_counter()
    problems.calibration_ranks(1, seed=10_000 + arguments.seed)
    first_call_seconds = time.perf_counter() - start

    start = time.perf_counter()
    ranks, inside_50, inside_90, n_draws = problems.calibration_ranks(arguments.sets, seed=arguments.seed)
    seconds = time.perf_counter() - start

    per_quantity = {}
    for i, name in enumerate(QUANTITIES):
        p_value, counts = problems.chi_square_p(ranks[:, i], n_draws, arguments.bins)
        per_quantity[name] = {
            "chi_square_p": p_value,
            "rank_counts": counts.tolist(),
            "coverage_50": float(inside_50[:, i].mean()),
            "coverage_90": float(inside_90[:, i].mean()),
        }
    pooled_p, pooled_counts = problems.chi_square_p(ranks, n_draws, arguments.bins)
    n = inside_50.size
    band_50 = problems.binomial_band(n, 0.5)
    band_90 = problems.binomial_band(n, 0.9)
    pooled = {
        "chi_square_p": pooled_p,
        "rank_counts": pooled_counts.tolist(),
        "covered_50": int(inside_50.sum()),
        "band_50": [band_50[0], band_50[1]],
        "covered_90": int(inside_90.sum()),
        "band_90": [band_90[0], min(band_90[1], n)],
        "of": n,
    }
    pooled["calibrated"] = bool(
        pooled_p > 0.01
        and band_50[0] <= pooled["covered_50"] <= band_50[1]
        and band_90[0] <= pooled["covered_90"] <= pooled["band_90"][1]
    )
    output = {
        "machine": machine,
        "quick": arguments.quick,
        "sets": arguments.sets,
        "seed": arguments.seed,
        "samples_per_set": problems.N_SAMPLES,
        "noise_rad": problems.NOISE,
        "chains": problems.CHAINS,
        "warmup": problems.WARMUP,
        "draws_per_chain": problems.DRAWS,
        "ranked_draws": n_draws,
        "bins": arguments.bins,
        "first_call_seconds": first_call_seconds,
        "seconds_per_posterior": seconds / arguments.sets,
        "total_seconds": seconds,
        "pooled": pooled,
        "per_quantity": per_quantity,
    }
    print(json.dumps(output, indent=1), flush=True)
    arguments.output_dir.mkdir(parents=True, exist_ok=True)
    (arguments.output_dir / "posterior_calibration.json").write_text(json.dumps(output, indent=1) + "\n")


if __name__ == "__main__":
    main()
