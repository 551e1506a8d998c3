"""Are the light-curve fit's sigmas honest in the truth's basin?  (issue 42, "Honest uncertainty")

Each member of benchmarks/_tumbler_family.py (shapes outside the model's family, 20 fitted nights)
is refined from its true motion (``fit_lightcurve(..., initial=`` the true body ``, search_rounds=1)``:
the basin the data put the truth in, without the search's luck), and the distance of the true
periods and moments from the fit's is measured in the sigmas of three covariances of the same fit:

- ``model``: ``LightcurveFit.covariance``, (J^T J)^+ s^2: right for independent noise and a model
  that describes the body;
- ``robust``: ``LightcurveFit.robust_covariance``, the cluster jackknife over the nights (CR3);
- ``basin``: the larger of the two per quantity, the fit's ``basin_period_sigma`` (what
  ``period_sigma`` reports where there are no competing basins).

For a calibrated sigma |z| < 1, 2, 3 hold at 68.3%, 95.4%, 99.7%.  The moments are the two smaller
ones (scaled to a largest of 1, matched to the true moments by rank); a principal-axis rotator's
are fixed.  Writes ``benchmarks/results/lightcurve_sigmas.json`` (updated after every member).

Usage: python benchmarks/lightcurve_sigmas.py [--members 0,5,12] [--output-dir DIR]
"""

from __future__ import annotations

import argparse
import json
import pathlib
import platform
import sys
import time
import warnings

import jax


jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from frbjax.lightcurve import AmbiguousFitWarning  # noqa: E402


sys.path.insert(0, str(pathlib.Path(__file__).parent))
import _tumbler_family  # noqa: E402


warnings.filterwarnings("ignore", category=AmbiguousFitWarning)
KINDS = ("model", "robust", "basin")


def member(case):
    """The member's truth refinement and its periods' and moments' |z| under each covariance."""
    rotator = case.kind == "PA"
    true_periods = np.asarray(case.periods[:1] if rotator else case.periods)
    start = time.perf_counter()
    fit = case.refine_from_truth()
    seconds = time.perf_counter() - start
    record = {"index": case.index, "kind": case.kind, "seconds": seconds, "noise_ratio": float(fit.noise_ratio)}
    for kind, covariance in zip(KINDS, (fit.covariance, fit.robust_covariance, None)):
        period_sigma, inertia_sigma = fit.standard_errors(covariance)
        count = len(true_periods)
        record[f"{kind}_period_z"] = (
            np.abs(np.asarray(fit.periods)[:count] - true_periods) / period_sigma[:count]
        ).tolist()
        record[f"{kind}_inertia_z"] = case.moments_z(fit.inertia, inertia_sigma)
    return record


def rates(records):
    """Per covariance: the share of all periods' and moments' |z| below 1, 2 and 3, and the members
    whose every period (moment) is within 3 sigmas."""
    out = {}
    for kind in KINDS:
        for quantity in ("period", "inertia"):
            values = np.concatenate([r[f"{kind}_{quantity}_z"] for r in records])
            with_values = [r for r in records if r[f"{kind}_{quantity}_z"]]
            if not with_values:
                continue
            out[f"{kind}_{quantity}"] = {
                "count": int(values.size),
                "within_1_2_3": [float(np.mean(values < k)) for k in (1, 2, 3)],
                "members_within_3": [sum(max(r[f"{kind}_{quantity}_z"]) <= 3 for r in with_values), len(with_values)],
            }
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--members", default=",".join(str(k) for k in range(_tumbler_family.SIZE)))
    parser.add_argument("--output-dir", default=str(pathlib.Path(__file__).parent / "results"))
    options = parser.parse_args(argv)
    output = pathlib.Path(options.output_dir) / "lightcurve_sigmas.json"
    output.parent.mkdir(parents=True, exist_ok=True)
    records = []
    for index in (int(x) for x in options.members.split(",")):
        records.append(member(_tumbler_family.tumbler(index)))
        print(json.dumps(records[-1]), flush=True)
        result = {
            "description": __doc__.split("\n\n")[0],
            "machine": {"platform": platform.platform(), "jax": jax.__version__},
            "rates": rates(records),
            "members": records,
        }
        output.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(rates(records), indent=1))


if __name__ == "__main__":
    main()
