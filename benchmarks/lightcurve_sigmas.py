"""Are the light-curve fit's sigmas honest in the truth's basin?  (issue 42, "Honest uncertainty")

Each member of benchmarks/_tumbler_family.py (shapes outside the model's family, 20 fitted nights)
is refined from its true motion (``fit_lightcurve(..., initial=`` the true body ``, search_rounds=1)``:
the basin the data put the truth in, without the search's luck), and the distance of the true
periods and moments from the fit's is measured in the sigmas of three covariances of the same fit:

- ``model``: ``LightcurveFit.covariance``, (J^T J)^+ s^2: right for independent noise and a model
  that describes the body;
- ``robust``: ``LightcurveFit.robust_covariance``, the cluster jackknife over the nights (CR3);
- ``basin``: the larger of the two per quantity with the shape's resolution error (from 2026-12-05,
  ``fit_lightcurve``'s ``resolution_error``: the larger of the two shapes' sigmas and the change of
  the values on the finer shape in quadrature), the fit's ``basin_period_sigma`` (what
  ``period_sigma`` reports where there are no competing basins).

For a calibrated sigma |z| < 1, 2, 3 hold at 68.3%, 95.4%, 99.7%.  The moments are the two smaller
ones (scaled to a largest of 1, matched to the true moments by rank); a principal-axis rotator's
are fixed.  Writes ``benchmarks/results/lightcurve_sigmas.json`` (updated after every member).

``--convex-subdivisions 3`` refines with the convex shape's 1280 normals instead of the default 320
(``lightcurve_sigmas_subdivisions3.json``), ``--smoothness-weight W`` with the regularisation
(10, W) instead of (10, 1) (``..._smoothness2.json`` for W = 2), ``--no-resolution-error`` without
the shape's resolution error (``resolution_error=False``: ``..._without_resolution_error.json``, the
name of the files written before 2026-12-05, when it did not exist; at 1280 normals its finer shape
has 5120).  Each record also has
``held_out_error``: the four later nights' prediction against the noiseless truth (as
``lightcurve_family.py``).

A run split over processes (``--members`` and ``--output-dir`` each) is put together with ``--merge
A.json B.json`` (the same settings; written to ``--output-dir``, rates recomputed).

Usage: python benchmarks/lightcurve_sigmas.py [--members 0,5,12] [--convex-subdivisions N] [--output-dir DIR]
       [--smoothness-weight W] [--no-resolution-error] [--merge JSON ...]
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
import lightcurve  # noqa: E402  (its `problems`: tests/test_lightcurve_fit.py's helpers)


warnings.filterwarnings("ignore", category=AmbiguousFitWarning)
KINDS = ("model", "robust", "basin")


def member(case, **options):
    """The member's truth refinement (``options`` pass on to the fit) and its periods' and moments' |z|
    under each covariance."""
    rotator = case.kind == "PA"
    true_periods = np.asarray(case.periods[:1] if rotator else case.periods)
    start = time.perf_counter()
    fit = case.refine_from_truth(**options)
    seconds = time.perf_counter() - start
    record = {
        "index": case.index,
        "kind": case.kind,
        "seconds": seconds,
        "noise_ratio": float(fit.noise_ratio),
        "held_out_error": lightcurve.problems.held_out_rms(fit, case.held_out_data()),
    }
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


def write(output, records, settings):
    """The records (sorted by member), the fit's ``settings`` and the rates to ``output``."""
    records = sorted(records, key=lambda record: record["index"])
    result = {
        "description": __doc__.split("\n\n")[0],
        "machine": {"platform": platform.platform(), "jax": jax.__version__},
        **settings,
        "rates": rates(records),
        "members": records,
    }
    output.write_text(json.dumps(result, indent=1) + "\n")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--members", default=",".join(str(k) for k in range(_tumbler_family.SIZE)))
    parser.add_argument("--convex-subdivisions", type=int, default=2)
    parser.add_argument("--smoothness-weight", type=float, default=1.0)
    parser.add_argument(
        "--no-resolution-error", action="store_true", help="fit_lightcurve(..., resolution_error=False)"
    )
    parser.add_argument("--output-dir", default=str(pathlib.Path(__file__).parent / "results"))
    parser.add_argument("--merge", nargs="+", metavar="JSON", help="write the members of these runs' files instead")
    options = parser.parse_args(argv)
    subdivisions, weight = options.convex_subdivisions, options.smoothness_weight
    name = "lightcurve_sigmas"
    name += "" if subdivisions == 2 else f"_subdivisions{subdivisions}"
    name += "" if weight == 1 else f"_smoothness{weight:g}"
    name += "" if not options.no_resolution_error else "_without_resolution_error"
    output = pathlib.Path(options.output_dir) / f"{name}.json"
    settings = dict(
        convex_subdivisions=subdivisions,
        regularisation=[10.0, weight],
        resolution_error=not options.no_resolution_error,
    )
    output.parent.mkdir(parents=True, exist_ok=True)
    records = []
    if options.merge:
        for path in options.merge:
            run = json.loads(pathlib.Path(path).read_text())
            # A file without the settings is a run at the defaults (before the options existed; before
            # 2026-12-05, without the resolution error).
            found = dict(
                convex_subdivisions=run.get("convex_subdivisions", 2),
                regularisation=run.get("regularisation", [10.0, 1.0]),
                resolution_error=run.get("resolution_error", False),
            )
            if found != settings:
                parser.error(f"{path} was run with {found}, not {settings}: merge runs of the same settings")
            records += run["members"]
        write(output, records, settings)
    else:
        for index in (int(x) for x in options.members.split(",")):
            records.append(member(_tumbler_family.tumbler(index), **settings))
            print(json.dumps(records[-1]), flush=True)
            write(output, records, settings)
    print(json.dumps(rates(records), indent=1))


if __name__ == "__main__":
    main()
