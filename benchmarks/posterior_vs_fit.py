"""Where the posterior and fit_attitude's Gaussian differ: a well-determined triaxial body, a body next
to the separatrix and a nearly symmetric body (issue 39).

Each case: 40 attitudes over a short record (TIMESPAN seconds, about one rotation) with NOISE rad of
isotropic attitude noise, so that the data leave the inertia ratios uncertain enough for the shape
of the posterior to show; attitude_posterior with 4 chains of 500 warmup steps and 1000 draws under
the default prior.  For the two inertia log-ratios the script records the posterior's standard
deviation against the fit's (from its Jacobian, ``AttitudeFit.covariance``), the skewness of the
draws, the probability of long-axis mode, and draws a figure: per case, the histograms of the two
log-ratios with the fit's Gaussian over them (benchmarks/results/posterior_vs_fit.png and .json).

    .venv/bin/python benchmarks/posterior_vs_fit.py [--quick] [--output-dir DIR]
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time
import warnings

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from frbjax import _quaternion as quaternion, FreeRigidBody  # noqa: E402
from frbjax.posterior import attitude_posterior, PosteriorWarning  # noqa: E402


ROOT = pathlib.Path(__file__).resolve().parents[1]
NOISE = 1e-2
TIMESPAN = 8.0
SAMPLES = 40
# (name, moments, angular velocity at t = 0): the energy ratio 2 E I2 / |L|^2 says where the body is
# (1: on the separatrix of the middle axis; below 1 short-axis mode about the largest axis).
CASES = [
    ("triaxial", (0.6, 0.8, 1.0), (0.4, 0.3, 0.8)),
    ("next to the separatrix", (0.6, 0.8, 1.0), (0.6, 0.05, 0.462)),
    ("nearly symmetric", (0.8, 0.81, 1.0), (0.4, 0.3, 0.8)),
]


def energy_ratio(moments, omega):
    moments, omega = np.asarray(moments), np.asarray(omega)
    momentum = moments * omega
    return float(np.sum(moments * omega**2) * moments[1] / np.sum(momentum**2))


@jax.jit
def _motion(inertia, momentum, attitude, times):
    return FreeRigidBody(inertia, momentum, attitude).quaternion(times)


def observed(moments, omega, times, rng):
    moments, omega = np.asarray(moments), np.asarray(omega)
    q = _motion(jnp.asarray(moments), jnp.asarray(moments * omega), jnp.array([1.0, 0.0, 0.0, 0.0]), times)
    noise = quaternion.exp_pure(jnp.asarray(rng.normal(scale=NOISE, size=(len(times), 3))))
    return np.asarray(quaternion.multiply(q, noise))


def skewness(x):
    x = np.asarray(x) - np.mean(x)
    return float(np.mean(x**3) / np.mean(x**2) ** 1.5)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one chain of 50 + 50 steps per case (smoke test)")
    parser.add_argument("--output-dir", type=pathlib.Path, default=ROOT / "benchmarks" / "results")
    arguments = parser.parse_args()
    sizes = dict(num_chains=1, num_warmup=50, num_samples=50) if arguments.quick else {}
    rng = np.random.default_rng(3)
    times = np.concatenate([[0.0], np.sort(rng.uniform(0.0, TIMESPAN, SAMPLES - 1))])
    results, draws = {}, {}
    for name, moments, omega in CASES:
        q = observed(moments, omega, times, rng)
        start = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", PosteriorWarning)
            posterior = attitude_posterior(times, q, attitude_sigma=NOISE, progress=False, **sizes)
        seconds = time.perf_counter() - start
        ratios = np.asarray(posterior.parameters[:, :2])
        fit_sd = np.sqrt(np.diag(np.asarray(posterior.fit.covariance))[:2])
        truth = np.log(np.asarray(moments[1:]) / moments[0])
        results[name] = {
            "moments": list(moments),
            "omega0": list(omega),
            "energy_ratio_2E_I2_over_L2": energy_ratio(moments, omega),
            "truth_log_ratios": truth.tolist(),
            "fit_log_ratios": np.asarray(posterior.fit.parameters[:2]).tolist(),
            "fit_sd": fit_sd.tolist(),
            "posterior_mean": np.mean(ratios, axis=0).tolist(),
            "posterior_sd": np.std(ratios, axis=0).tolist(),
            "sd_ratio_posterior_over_fit": (np.std(ratios, axis=0) / fit_sd).tolist(),
            "skewness": [skewness(ratios[:, k]) for k in range(2)],
            "mode_probabilities": {k: float(v) for k, v in posterior.mode_probabilities().items() if np.ndim(v) == 0},
            "max_r_hat": float(np.max(posterior.r_hat)),
            "divergences": int(np.sum(posterior.divergences)),
            "warnings": [str(w.message)[:200] for w in caught],
            "seconds": round(seconds, 1),
        }
        draws[name] = (ratios, np.asarray(posterior.fit.parameters[:2]), fit_sd, truth)
        print(name, json.dumps(results[name], indent=1))
    arguments.output_dir.mkdir(parents=True, exist_ok=True)
    (arguments.output_dir / "posterior_vs_fit.json").write_text(
        json.dumps({"noise_rad": NOISE, "timespan_s": TIMESPAN, "samples": SAMPLES, "cases": results}, indent=2) + "\n"
    )
    plot(draws, arguments.output_dir / "posterior_vs_fit.png")


def plot(draws, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(2, len(draws), figsize=(4 * len(draws), 6), squeeze=False)
    for column, (name, (ratios, fit, fit_sd, truth)) in enumerate(draws.items()):
        for row, label in enumerate(("log I2/I1", "log I3/I1")):
            axis = axes[row, column]
            axis.hist(ratios[:, row], bins=50, density=True, color="tab:blue", alpha=0.6, label="posterior (NUTS)")
            grid = np.linspace(*np.quantile(ratios[:, row], [0.0005, 0.9995]), 400)
            gaussian = np.exp(-0.5 * ((grid - fit[row]) / fit_sd[row]) ** 2) / (np.sqrt(2 * np.pi) * fit_sd[row])
            axis.plot(grid, gaussian, color="tab:red", label="fit_attitude's Gaussian")
            axis.axvline(truth[row], color="black", linestyle="--", label="truth")
            axis.set_xlabel(label)
            if row == 0:
                axis.set_title(name)
            if row == 0 and column == 0:
                axis.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
