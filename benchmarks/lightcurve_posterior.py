"""The light-curve posterior of a tumbler at full size: lightcurve_posterior against the fit's Gaussian.

The tests' short-axis-mode tumbler (tests/test_lightcurve_fit.py: Apophis's moments, E/E0 = 1.024,
P_psi = 4.8 hours, a bumpy convex hull, 24 nights of 16 samples over 90 days, 1% noise, a scale per
night), inverted by ``fit_lightcurve`` as benchmarks/lightcurve.py does (ranges +-0.5% around
centres 0.23% off the truth), then ``lightcurve_posterior`` (``--chains`` chains of ``--warmup`` +
``--draws``, the shape held at the fit's or sampled with the motion: ``--shape``).  Reported: each
period's and moment's posterior standard deviation against the fit's linearised sigma, whether the
truth lies in the 90% and 99% central intervals, split R-hat, divergences, wall times.

Usage: python benchmarks/lightcurve_posterior.py [--shape held] [--chains 4] [--warmup 300]
    [--draws 300] [--output-dir DIR]
Writes lightcurve_posterior.json (``--shape held``) or lightcurve_posterior_sampled_shape.json into
benchmarks/results/ (or --output-dir).  Measured (2026-12-02, one core): held, 4 chains of 300 + 300,
170 s; sampled, 2 chains of 100 + 100, 1047 s, split R-hat 1.24 (a 1-chain run: NUTS's step 0.012, about
680 leapfrog steps a draw: the log-areas' posterior is far from Gaussian).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import pathlib
import sys
import time
import warnings

import jax


jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from frbjax.lightcurve import fit_lightcurve  # noqa: E402
from frbjax.posterior import lightcurve_posterior, PosteriorWarning  # noqa: E402


ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
_spec = importlib.util.spec_from_file_location("_lightcurve_benchmark", ROOT / "benchmarks" / "lightcurve.py")
lightcurve_benchmark = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(lightcurve_benchmark)
problems = lightcurve_benchmark.problems


def data_and_fit():
    """The tumbler's data (times, flux, sun, observer, night), true periods, its fit and the fit's seconds."""
    body, periods = lightcurve_benchmark.tumbler("SAM")
    data, _ = problems.observe(body, seed=3, per_night=problems.SAMPLES_PER_NIGHT)
    times, flux, sun, observer, night = data
    size = problems.SIZES["SAM"]
    options = dict(
        problems.FIT_OPTIONS,
        lightcurve=night,
        mode="SAM",
        starts_per_period=size["starts_per_period"],
        n_refine=size["n_refine"],
        periods=tuple(
            (p * (1 + problems.RANGE_OFFSET - 0.005), p * (1 + problems.RANGE_OFFSET + 0.005)) for p in periods
        ),
    )
    start = time.perf_counter()
    fit = fit_lightcurve(times, flux, sun, observer, **options)
    return data, periods, fit, time.perf_counter() - start


def posterior_of(data, fit, **options):
    """lightcurve_posterior of the tumbler's data about ``fit`` at the data's noise (no progress bar)."""
    times, flux, sun, observer, night = data
    return lightcurve_posterior(
        times, flux, sun, observer, lightcurve=night, initial=fit, sigma=problems.NOISE, progress=False, **options
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--warmup", type=int, default=300)
    parser.add_argument("--draws", type=int, default=300)
    parser.add_argument("--shape", choices=("held", "sampled"), default="held")
    parser.add_argument("--chains", type=int, default=4)
    parser.add_argument("--output-dir", default=str(ROOT / "benchmarks" / "results"))
    args = parser.parse_args()

    data, periods, fit, fit_seconds = data_and_fit()
    times = data[0]
    print(f"fit: {fit_seconds:.1f} s, periods {np.asarray(fit.periods)} (truth {periods})", flush=True)

    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", PosteriorWarning)
        posterior = posterior_of(
            data, fit, num_warmup=args.warmup, num_samples=args.draws, num_chains=args.chains, shape=args.shape
        )
    posterior_seconds = time.perf_counter() - start
    drawn = np.asarray(posterior.periods)
    rows = {}
    # The posterior samples the winner's basin under the model's likelihood: its spread is compared
    # with the model covariance's sigmas (before 2026-12-03 these were ``fit.period_sigma``).
    period_sigma, inertia_sigma = fit.standard_errors(fit.covariance)
    for k, name in enumerate(("P_psi", "P_phi")):
        low90, high90, low99, high99 = np.quantile(drawn[:, k], [0.05, 0.95, 0.005, 0.995])
        rows[name] = {
            "truth": float(periods[k]),
            "fit": float(fit.periods[k]),
            "fit_sigma": float(period_sigma[k]),
            "posterior_mean": float(drawn[:, k].mean()),
            "posterior_sd": float(drawn[:, k].std(ddof=1)),
            "sd_over_fit_sigma": float(drawn[:, k].std(ddof=1) / period_sigma[k]),
            "truth_in_90": bool(low90 <= periods[k] <= high90),
            "truth_in_99": bool(low99 <= periods[k] <= high99),
        }
    moments = np.asarray(posterior.inertia)
    result = {
        "case": "SAM, tests/test_lightcurve_fit.py's tumbler",
        "shape": args.shape,
        "samples": len(times),
        "chains": posterior.num_chains,
        "warmup": args.warmup,
        "draws": args.draws,
        "fit_seconds": fit_seconds,
        "posterior_seconds": posterior_seconds,
        "periods": rows,
        "inertia_posterior_sd": moments.std(axis=0, ddof=1).tolist(),
        "inertia_fit_sigma": np.asarray(inertia_sigma).tolist(),
        "max_r_hat": float(np.nanmax(np.asarray(posterior.r_hat))),
        "divergences": np.asarray(posterior.divergences).tolist(),
        "long_axis_fraction": float(np.mean(np.asarray(posterior.long_axis_mode))),
        "warnings": [str(w.message) for w in caught],
    }
    print(json.dumps(result, indent=1), flush=True)
    output = pathlib.Path(args.output_dir)
    output.mkdir(parents=True, exist_ok=True)
    name = "lightcurve_posterior.json" if args.shape == "held" else "lightcurve_posterior_sampled_shape.json"
    (output / name).write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
