"""The periodogram's proposals, fitted: do the data decide where the periodogram's series does not?

For members of the tumbler family (benchmarks/_tumbler_family.py) this runs ``tumbler_periodogram``
as benchmarks/lightcurve_periodogram.py does (the band 0.1 to 5 days, the geometric ranking), then
``fit_lightcurve`` on proposal ``--rank`` (``**result.fit_options(rank)``, the fit's defaults), and
compares it with the same data refined from the true motion (one search round, no mirror image: the
reference of benchmarks/lightcurve_family.py, or its stored figures with ``--truth-from``).  Per
member: the fit's periods, its cost above the truth's refinement in noise units of a cost
(sqrt(N / 2)), the RMS of its prediction of the four later nights against the noiseless truth, its
residual level ``noise_ratio`` (s / sigma) and whether it warned of a misfit (``MisfitWarning``),
the competing basins it reports, and the wall time.  Run on the members whose truth the periodogram's
list misses (the default), it tells the misses the data cannot decide (a wrong proposal's fit within
the noise of the truth's cost) from those the light curve's own model decides (docs/lightcurves.md).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/lightcurve_periodogram_fits.py --seed 0 \\
        --members 2,3,4,6,10 --truth-from benchmarks/results/lightcurve_family.json

Writes benchmarks/results/lightcurve_periodogram_fits_seed{S}.json, each member merged into it as it
is done (several runs of one seed may share the file).
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import platform
import sys
import time
import warnings

import jax


jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402


ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import lightcurve  # noqa: E402
from _tumbler_family import tumbler  # noqa: E402

from frbjax.lightcurve import AmbiguousFitWarning, fit_lightcurve, MisfitWarning, tumbler_periodogram  # noqa: E402


BAND = (0.1, 5.0)  # days: benchmarks/lightcurve_periodogram.py's band


def truth_refinement(case):
    """The truth's basin (its cost and later nights' error), as benchmarks/lightcurve_family.py has it:
    the data refined from the true motion without the mirror image's solve."""
    refined = case.refine_from_truth(mirror_pole=False)
    return float(refined.cost), lightcurve.problems.held_out_rms(refined, case.held_out_data())


def fit(case, **options):
    """``fit_lightcurve`` on the member's data (its nights' scales free), without progress bars."""
    return fit_lightcurve(
        case.times, case.flux, case.sun, case.observer, lightcurve=case.night, throw=False, progress=False, **options
    )


def run_member(index, seed, rank, stored):
    case = tumbler(index, seed)
    if stored is None:
        truth_cost, truth_held_out = truth_refinement(case)
    else:
        truth_cost, truth_held_out = stored["truth_refined_cost"], stored.get("truth_refined_held_out_error")
    result = tumbler_periodogram(
        case.times, case.flux, lightcurve=case.night, period_range=BAND, sun=case.sun, observer=case.observer
    )
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", MisfitWarning)
        warnings.simplefilter("ignore", AmbiguousFitWarning)
        found = fit(case, **result.fit_options(rank))
    seconds = time.perf_counter() - start
    rotator = case.kind == "PA"
    centre = result.centres[rank]
    return dict(
        index=index,
        kind=case.kind,
        true_periods=[case.periods[0]] if rotator else list(case.periods),
        proposal_rank=rank,
        proposal_mode=result.modes[rank],
        proposal_centres=[float(c) if np.isfinite(c) else None for c in centre],
        periods=[float(p) if np.isfinite(p) else None for p in np.asarray(found.periods)],
        long_axis_mode=bool(found.long_axis_mode),
        cost=float(found.cost),
        truth_refined_cost=truth_cost,
        cost_excess=(float(found.cost) - truth_cost) / math.sqrt(len(case.times) / 2),
        held_out_error=lightcurve.problems.held_out_rms(found, case.held_out_data()),
        truth_refined_held_out_error=truth_held_out,
        noise_ratio=float(found.noise_ratio),
        misfit_warned=any(issubclass(w.category, MisfitWarning) for w in caught),
        competing_basins=len(found.competing_basins().cost_excess),
        seconds=seconds,
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--members", required=True, help="e.g. 2,3,4,6,10")
    parser.add_argument("--rank", type=int, default=0, help="the proposal fitted (0: the first)")
    parser.add_argument("--truth-from", help="a lightcurve_family.py JSON of this seed: its truth refinements")
    parser.add_argument("--output-dir", default=str(ROOT / "benchmarks" / "results"))
    options = parser.parse_args(argv)
    stored = {}
    if options.truth_from:
        record = json.loads(pathlib.Path(options.truth_from).read_text())
        if record.get("seed", 0) != options.seed:
            raise SystemExit(f"--truth-from holds seed {record.get('seed')}, not {options.seed}")
        stored = {member["index"]: member for member in record["members"]}
    path = pathlib.Path(options.output_dir) / f"lightcurve_periodogram_fits_seed{options.seed}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    for index in (int(k) for k in options.members.split(",")):
        member = run_member(index, options.seed, options.rank, stored.get(index))
        print(json.dumps(member), flush=True)
        # Merged into the file as it stands now (runs of other members may be writing it too).
        earlier = json.loads(path.read_text())["members"] if path.exists() else []
        members = [m for m in earlier if (m["index"], m["proposal_rank"]) != (index, options.rank)] + [member]
        output = dict(
            seed=options.seed,
            band_days=list(BAND),
            machine=f"{platform.machine()}, {platform.python_version()}, jax {jax.__version__}",
            members=sorted(members, key=lambda m: (m["index"], m["proposal_rank"])),
        )
        path.write_text(json.dumps(output, indent=1) + "\n")


if __name__ == "__main__":
    main()
