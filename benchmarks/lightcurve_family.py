"""Light-curve inversion across a family of tumblers unlike the tests' (issue 42, "Tests and benchmark").

Each member of benchmarks/_tumbler_family.py (24 tumblers: principal-axis rotators, short-axis mode
near principal-axis rotation and at Apophis-like energies, both sides of the separatrix, long-axis
mode; shapes of about 2000 facets outside the model's family; 24 nights of about 40 samples over 3 to
5 months, 1% noise, one unknown scale per night; four later nights held out) is inverted by
``fit_lightcurve`` as a user without the mode would run it: the periods' ranges +-10% around the true
periods (``--width``), ``mode="both"``, the principal-axis model for the rotators (one period), the
search's other settings at their defaults unless given.  Then the same data are refined from the true
motion (``initial=`` the true body), which gives the cost the data allow.  Per member:

- ``cost_excess``: the search's cost minus the truth-refined cost, in units of the noise of a cost
  (sqrt(N / 2), the standard deviation of half a chi-square with N degrees of freedom); the issue's
  "within the noise" is ``cost_excess <= 1``;
- ``held_out_error``: the RMS of log(truth / model) over the four later nights against the noiseless
  truth, each night's scale fitted: the prediction's own error, the measure of the issue's table
  ("later nights predicted, rms vs the noiseless truth"); "within 1.5x the noise" is ``<= 0.015``;
- ``held_out_rms``: the same against the noisy data (the 1% noise included: about
  sqrt(held_out_error^2 + 0.01^2)), the measure of the runs before 2026-12-04, held to ``<= 0.015``
  too (``rates``: ``held_out_data_within_1.5_noise``);
- ``period_z``: |P - P_true| / sigma for each period (the issue: within 3 reported sigmas), and
  ``truth_refined_period_z`` the same for the refinement from the truth in its basin's sigmas
  (``LightcurveFit.basin_period_sigma``: the truth's basin alone); ``basin_period_sigma`` the
  winner's basin's own sigmas (``period_sigma`` also spans the competing basins);
- ``inertia_z``: the same for the two smaller moments (scaled to a largest of 1, matched to the true
  moments by rank; a principal-axis rotator's are fixed, none);
- ``resolution_periods``, ``resolution_inertia`` and their sigmas: the winner solved again on the
  finer convex shape (``fit_lightcurve``'s ``resolution_error``, from 2026-12-05), whose difference
  and sigmas the reported sigmas include;
- ``competing_basins``, ``ambiguous``: the fit's runner-up basins within the noise of its cost at
  other periods (``LightcurveFit.competing_basins``), which ``fit_lightcurve`` warns of;
- ``noise_ratio``, ``search_rounds``, ``misfit_warned``: the fit's residual level over the noise
  (``LightcurveFit.noise_ratio``), the search's rounds (more while it is above its chi-square
  bound) and whether the fit warned that it still is (``MisfitWarning``);
- ``pole_from_truth``, ``mirror_pole_from_truth``: the angles (degrees) of the fit's pole (the inertial
  direction of L) and of its other pole (the winner's mirror image through the plane of the
  observations, ``mirror_pole``) from the truth's; ``mirror_cost_excess``, ``pole_separation``,
  ``pole_ambiguous``: the other pole's cost above the winner's (noise units), its angle from the
  winner's, and whether the fit warns of the two (``LightcurveFit.pole_ambiguous``);
- wall time of the inversion (first call in the process includes compilation).

The refinement from the truth runs one round of the search (``search_rounds=1``) without the mirror
image's solve (``mirror_pole=False``): it is the reference the data allow in the truth's basin, not a
search.  ``--truth-from PATH`` takes its figures from an earlier run's members
(a JSON of this script) instead of computing them again: the same computation, for a rerun of the
fits alone (the records of runs before 2026-12-04 have no ``truth_refined_held_out_error``: none is
then recorded).

Rates over the members run are printed and written with the members to
``benchmarks/results/lightcurve_family.json`` (among them ``sigma_coverage``: the shares of all the
periods' and of all the smaller moments' |z| within 1, 2 and 3 sigmas; ``--rates-only`` recomputes
them from the stored members); the file is updated after every member, and members already in it are
skipped (``--resume``), so that a long run can be continued.  A run split over processes (``--members``
and ``--output-dir`` each) is put together with ``--merge A.json B.json`` (``--earlier-name NAME``:
the file's run so far kept under ``earlier_runs.NAME``).  ``--seed s``: a second family drawn the same way
(``_tumbler_family.tumbler(index, s)``), to check that the defaults chosen on the first hold on members
they were not chosen on; stored as ``lightcurve_family_seed<s>.json`` (``--merge`` writes the runs' own seed's file).
``--truth-only``: only the refinements from the truth (without the finer shape's solve), at the options given
(e.g. ``--regularisation 100,4``: the convex shape's closure and smoothness weights), written to
``lightcurve_family_truth[_seed<s>].json``: what the options allow in the truth's basin, a minute and a
half a member instead of the search's seven.  ``--x-scale jac``: the convex solves with Marquardt's scaling
(``fit_lightcurve``'s ``x_scale``), the truth's refinements too.

Usage: python benchmarks/lightcurve_family.py [--members 0,5,12] [--seed 0] [--width 0.1] [--resume] [--truth-from PATH]
       [--starts-per-period 16] [--period-grid 16,16] [--refine 8] [--convex-subdivisions 1] [--regularisation 10,1]
       [--x-scale jac] [--stop-at-noise] [--truth-only] [--output-dir DIR] [--plot-only] [--basins-only]
       [--merge JSON ... [--earlier-name NAME] [--description D]]
(the figure: lightcurve_family.png beside the JSON, redrawn after each run or with --plot-only)
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import platform
import sys
import time
import types
import warnings

import jax


jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from frbjax.lightcurve import AmbiguousFitWarning, fit_lightcurve, LightcurveFit, MisfitWarning  # noqa: E402


sys.path.insert(0, str(pathlib.Path(__file__).parent))
import _tumbler_family  # noqa: E402
import lightcurve  # noqa: E402  (its `problems`: tests/test_lightcurve_fit.py's helpers)


NOISE = _tumbler_family.NOISE
# The fits' competing basins are recorded with each member (``with_basins``) instead of printed.
warnings.filterwarnings("ignore", category=AmbiguousFitWarning)


def invert(case, width, options, stored=None):
    """The member's search and its refinement from the truth: the figures of the module docstring.
    The refinement from the truth is one round (``search_rounds=1``: a reference, not a search); with
    ``stored`` (the member's record of an earlier run, ``--truth-from``) its figures are taken from
    there instead of computed again."""
    rotator = case.kind == "PA"
    true_periods = np.asarray(case.periods[:1] if rotator else case.periods)
    ranges = tuple((p * (1 - width), p * (1 + width)) for p in true_periods)
    ranges = ranges[0] if rotator else ranges  # a rotator's one period: (P_min, P_max)
    common = dict(lightcurve=case.night, principal_axis=rotator, throw=False, progress=False)
    data = (case.times, case.flux, case.sun, case.observer)
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", MisfitWarning)
        found = fit_lightcurve(*data, periods=ranges, mode="both", **common, **options)
    seconds = time.perf_counter() - start
    held_out_rms = lambda result: lightcurve.problems.held_out_rms(result, case.held_out_data(noiseless=False))  # noqa: E731
    held_out_error = lambda result: lightcurve.problems.held_out_rms(result, case.held_out_data())  # noqa: E731
    # The true motion, its time counted from the fit's epoch (fit_lightcurve's default: the median time).
    truth = case.body_at(float(np.median(case.times)))
    if stored is None:
        # The truth's basin, without the mirror image's solve: the truth's own basin, whatever its mirror's cost.
        refined = case.refine_from_truth(width, **{**options, "search_rounds": 1, "mirror_pole": False})
        truth_refined = {
            "truth_refined_period_z": (
                np.abs(np.asarray(refined.periods)[: len(true_periods)] - true_periods)
                / np.asarray(refined.basin_period_sigma)[: len(true_periods)]
            ).tolist(),
            "truth_refined_cost": float(refined.cost),
            "truth_refined_held_out_rms": held_out_rms(refined),
            "truth_refined_held_out_error": held_out_error(refined),
            "truth_refined_noise_ratio": float(refined.noise_ratio),
        }
    else:
        truth_refined = {key: value for key, value in stored.items() if key.startswith("truth_refined")}
    samples = len(case.times)
    periods, sigma = np.asarray(found.periods), np.asarray(found.period_sigma)
    z = np.abs(periods[: len(true_periods)] - true_periods) / sigma[: len(true_periods)]
    inertia_z = case.moments_z(found.inertia, found.inertia_sigma)
    true_pole = np.asarray(truth.rotation_matrix(0.0)) @ np.asarray(truth.angular_momentum(0.0))
    true_pole /= np.linalg.norm(true_pole)
    degrees_from_truth = lambda pole: float(np.degrees(np.arccos(np.clip(np.asarray(pole) @ true_pole, -1, 1))))  # noqa: E731
    member = {
        "index": case.index,
        "kind": case.kind,
        "samples": samples,
        "true_periods": true_periods.tolist(),
        "true_long_axis": case.long_axis,
        "energy_ratio": case.energy_ratio,
        "periods": periods.tolist(),
        "period_sigma": sigma.tolist(),
        "period_z": z.tolist(),
        "basin_period_sigma": np.asarray(found.basin_period_sigma).tolist(),
        "inertia": np.asarray(found.inertia).tolist(),
        "inertia_sigma": np.asarray(found.inertia_sigma).tolist(),
        "inertia_z": inertia_z,
        # The winner solved on the finer shape (``resolution_error``): its periods and moments and their
        # sigmas, which the sigmas above include (NaN for the ellipsoid or an unconverged solve).
        "resolution_periods": np.asarray(found.resolution_periods).tolist(),
        "resolution_period_sigma": np.asarray(found.resolution_period_sigma).tolist(),
        "resolution_inertia": np.asarray(found.resolution_inertia).tolist(),
        "resolution_inertia_sigma": np.asarray(found.resolution_inertia_sigma).tolist(),
        # The same for the refinement from the truth: what the model allows in the truth's basin.
        **truth_refined,
        "long_axis_mode": bool(found.long_axis_mode),
        "cost": float(found.cost),
        "cost_excess": (float(found.cost) - truth_refined["truth_refined_cost"]) / math.sqrt(samples / 2),
        "held_out_error": held_out_error(found),
        "held_out_rms": held_out_rms(found),
        "noise_ratio": float(found.noise_ratio),
        "search_rounds": int(found.search_rounds),
        "misfit_warned": any(issubclass(w.category, MisfitWarning) for w in caught),
        # The pole (the inertial direction of L) and the mirror image's (``mirror_pole``), in degrees
        # from the truth's; the mirror's cost above the winner's (noise units) and whether it warns.
        "pole_from_truth": degrees_from_truth(found.momentum_direction),
        "mirror_pole_from_truth": degrees_from_truth(found.mirror_momentum_direction),
        "mirror_cost_excess": float(found.mirror_cost_excess),
        "pole_separation": float(found.pole_separation),
        "pole_ambiguous": bool(found.pole_ambiguous),
        "refine_costs": np.asarray(found.refine_costs).tolist(),
        "refine_periods": np.asarray(found.refine_periods).tolist(),
        "seconds": seconds,
    }
    return with_basins(member)


def with_basins(member):
    """The member's record with the fit's competing basins (``LightcurveFit.competing_basins``: the
    last stage's runner-ups within the noise of the winner's cost at periods more than 3 sigmas away)
    and whether there are any (``ambiguous``), from the fields the record keeps (the method reads only
    those), so that a stored run's members get them too (``--basins-only``)."""
    fit = types.SimpleNamespace(
        refine_costs=np.asarray(member["refine_costs"], float),
        refine_periods=np.asarray(member["refine_periods"], float),
        periods=np.asarray(member["periods"], float),
        period_sigma=np.asarray(member["period_sigma"], float),
        # Runs before 2026-12-03 reported the basin's sigma as period_sigma.
        basin_period_sigma=np.asarray(member.get("basin_period_sigma", member["period_sigma"]), float),
        residuals=np.zeros(member["samples"]),
        cost=member["cost"],
    )
    basins = LightcurveFit.competing_basins(fit)
    return {
        **member,
        "competing_basins": {key: np.asarray(value).tolist() for key, value in basins._asdict().items()},
        "ambiguous": bool(len(basins.cost_excess)),
    }


def later_nights(member):
    """The later nights' prediction error against the noiseless truth (``held_out_error``), or for a
    record of the runs before 2026-12-04, which have none, the RMS against the data."""
    return member.get("held_out_error", member["held_out_rms"])


def rates(members):
    count = len(members)
    if not count:
        return {}
    return {
        "members": count,
        "cost_within_noise": sum(m["cost_excess"] <= 1 for m in members) / count,
        # The measure (the prediction against the noiseless truth) and, as in the runs before
        # 2026-12-04, the same against the noisy data.
        "held_out_within_1.5_noise": sum(later_nights(m) <= 1.5 * NOISE for m in members) / count,
        "held_out_data_within_1.5_noise": sum(m["held_out_rms"] <= 1.5 * NOISE for m in members) / count,
        "periods_within_3_sigma": sum(max(m["period_z"]) <= 3 for m in members) / count,
        # The moments of the tumblers (a rotator's are fixed): both smaller ones within 3 sigmas.
        "inertia_within_3_sigma": (
            sum(max(m["inertia_z"]) <= 3 for m in members if m.get("inertia_z"))
            / max(sum(bool(m.get("inertia_z")) for m in members), 1)
        ),
        # Every period's and smaller moment's |z| (both of each fit): the shares within 1, 2 and 3
        # sigmas, for a Gaussian 68%, 95% and 99.7%.
        "sigma_coverage": {
            name: [float(np.mean(np.array(values) <= k)) if values else None for k in (1, 2, 3)]
            for name, values in (
                ("periods", [z for m in members for z in m["period_z"]]),
                ("inertia", [z for m in members for z in (m.get("inertia_z") or [])]),
            )
        },
        # The fits that warn of competing basins, and among those whose periods are more than 3
        # sigmas off, the share that warns (the "says when the landscape has competing basins").
        "ambiguous": sum(m.get("ambiguous", False) for m in members) / count,
        "periods_off_and_warned": [
            sum(m.get("ambiguous", False) for m in members if max(m["period_z"]) > 3),
            sum(max(m["period_z"]) > 3 for m in members),
        ],
        # The fits that warn of two poles (the winner's mirror image within the noise), and among
        # those whose later nights miss, the share that warns.
        "pole_ambiguous": sum(m.get("pole_ambiguous", False) for m in members) / count,
        "later_nights_missed_and_pole_warned": [
            sum(m.get("pole_ambiguous", False) for m in members if later_nights(m) > 1.5 * NOISE),
            sum(later_nights(m) > 1.5 * NOISE for m in members),
        ],
        # The fits that warn that their residuals still exceed the noise after their last round.
        "misfit_warned": sum(m.get("misfit_warned", False) for m in members) / count,
        "median_seconds": float(np.median([m["seconds"] for m in members])),
        "max_seconds": float(np.max([m["seconds"] for m in members])),
    }


# The run drawn in grey beside the present one: the same family at the convex shape's former default
# weights (``fit_lightcurve``'s ``regularisation`` (10, 1), until 2026-12-07).
EARLIER_RUN = ("shape_weights_10_1", "the former shape weights (10, 1)")


def plot(result, path):
    """Per member: the cost's excess over the truth's refinement (noise units), the later nights' RMS,
    the periods' and the moments' largest |z|, against the issue's thresholds; the run
    ``EARLIER_RUN`` (when the file has it) in grey; ringed in red, the fits that warn of two poles
    (``pole_ambiguous``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [("now", result["members"], "C0")]
    earlier = result.get("earlier_runs", {}).get(EARLIER_RUN[0])
    if earlier:
        runs.insert(0, (EARLIER_RUN[1], earlier["members"], "0.6"))
    panels = [
        (
            "cost excess over the truth's refinement\n(noise units, sqrt(N/2); below 0.01 at 0.01)",
            lambda m: max(m["cost_excess"], 1e-2),
            1,
        ),
        ("later nights' RMS vs the noiseless truth", later_nights, 1.5 * NOISE),
        ("periods' largest |P - P_true| / sigma\n(below 0.01 at 0.01)", lambda m: max(max(m["period_z"]), 1e-2), 3),
        (
            "moments' largest |I - I_true| / sigma\n(below 0.01 at 0.01; rotators: fixed)",
            lambda m: max(max(m["inertia_z"]), 1e-2) if m.get("inertia_z") else np.nan,
            3,
        ),
    ]
    figure, axes = plt.subplots(4, 1, figsize=(10, 10), sharex=True)
    for axis, (label, value, threshold) in zip(axes, panels):
        for offset, (name, members, colour) in zip((-0.15, 0.15) if len(runs) == 2 else (0.0,), runs):
            index = np.array([m["index"] for m in members])
            axis.scatter(index + offset, [value(m) for m in members], color=colour, s=22, label=name, zorder=3)
            poles = [m for m in members if m.get("pole_ambiguous")]
            if poles:
                axis.scatter(
                    np.array([m["index"] for m in poles]) + offset,
                    [value(m) for m in poles],
                    facecolors="none",
                    edgecolors="C3",
                    s=70,
                    label="warns of two poles" if axis is axes[0] and name == "now" else None,
                    zorder=4,
                )
        axis.axhline(threshold, color="C3", lw=1, ls="--", label="the issue's threshold")
        axis.set_yscale("log")
        axis.set_ylabel(label, fontsize=8)
        axis.grid(alpha=0.3, which="major")
    # Placed by the members' indices, not their positions: a run may hold only some members.
    kinds = [m["kind"] for m in result["members"]]
    indices = [m["index"] for m in result["members"]]
    for axis in axes:
        for k in range(1, len(kinds)):
            if kinds[k] != kinds[k - 1]:
                axis.axvline(indices[k] - 0.5, color="0.8", lw=0.8)
    for k, kind in enumerate(kinds):
        if k == 0 or kinds[k - 1] != kind:
            axes[0].text(indices[k] - 0.4, axes[0].get_ylim()[1], kind, fontsize=7, va="bottom")
    axes[0].legend(fontsize=7, loc="upper right")
    axes[-1].set_xlabel("member")
    axes[-1].set_xticks(indices)
    rates_now = result["rates"]
    figure.suptitle(
        f"fit_lightcurve, tumbler family{', seed ' + str(result['seed']) if result.get('seed') else ''} "
        "(+-10% ranges): within the noise "
        f"{rates_now['cost_within_noise']:.0%}, later nights {rates_now['held_out_within_1.5_noise']:.0%}, "
        f"periods {rates_now['periods_within_3_sigma']:.0%}, moments {rates_now['inertia_within_3_sigma']:.0%}"
        + (f"; two poles warned {rates_now['pole_ambiguous']:.0%}" if "pole_ambiguous" in rates_now else ""),
        fontsize=9,
    )
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def truth_refinement(case, width, options):
    """The refinement from the truth alone (``--truth-only``): the reference of :func:`invert` without
    the search and without the finer shape's solve, for comparing fit options (e.g. the shape's weights)
    by what they allow in the truth's basin: its later nights, residuals and cost."""
    start = time.perf_counter()
    refined = case.refine_from_truth(
        width, **{**options, "search_rounds": 1, "mirror_pole": False, "resolution_error": False}
    )
    return {
        "index": case.index,
        "kind": case.kind,
        "truth_refined_cost": float(refined.cost),
        "truth_refined_held_out_error": lightcurve.problems.held_out_rms(refined, case.held_out_data()),
        "truth_refined_noise_ratio": float(refined.noise_ratio),
        "seconds": time.perf_counter() - start,
    }


def check_truth_from(stored, indices, path):
    """Refuse a ``--truth-from`` file before any fit runs, rather than after the first member's search
    (minutes), where a member or its truth's cost (``truth_refined_cost``, which :func:`invert`
    computes the cost's excess from) is missing; the other ``truth_refined`` figures are copied where
    present (module docstring)."""
    missing = [index for index in indices if "truth_refined_cost" not in stored.get(index, {})]
    if missing:
        raise SystemExit(f"--truth-from {path}: no truth_refined_cost for members {missing}")


def output_path(output_dir, seed):
    """The run's JSON: lightcurve_family.json, a second family's (seed s != 0) lightcurve_family_seed<s>.json."""
    return pathlib.Path(output_dir) / f"lightcurve_family{f'_seed{seed}' if seed else ''}.json"


def merge(paths, output_dir, earlier_name, description=None):
    """The members of the runs in ``paths`` (parts of one run: the same seed, width and options) written
    as the run of their seed's file in ``output_dir`` (:func:`output_path`); the run it held is kept
    under ``earlier_runs[earlier_name]`` (with its own earlier runs left where they were), or replaced
    without ``earlier_name``; ``description``, how the run was made (by default the module docstring's
    first paragraph)."""
    runs = [json.loads(pathlib.Path(path).read_text()) for path in paths]
    settings = [{key: run.get(key) for key in ("seed", "width", "fit_options")} for run in runs]
    if any(setting != settings[0] for setting in settings):
        raise SystemExit(f"--merge: the runs' settings differ: {settings}")
    output = output_path(output_dir, settings[0]["seed"] or 0)
    members = sorted((m for run in runs for m in run["members"]), key=lambda m: m["index"])
    if len({m["index"] for m in members}) != len(members):
        raise SystemExit("--merge: a member is in more than one run")
    stored = json.loads(output.read_text()) if output.exists() else {}
    earlier_runs = dict(stored.get("earlier_runs", {}))
    if earlier_name:
        earlier_runs[earlier_name] = {key: value for key, value in stored.items() if key != "earlier_runs"}
    result = {
        "description": description or __doc__.split("\n\n")[0],
        **{key: value for key, value in runs[0].items() if key not in ("description", "rates", "members")},
        "rates": rates(members),
        "earlier_runs": earlier_runs,
        "members": members,
    }
    output.write_text(json.dumps(result, indent=1) + "\n")
    plot(result, output.with_suffix(".png"))
    print(json.dumps(result["rates"], indent=1))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--members", default=",".join(str(k) for k in range(_tumbler_family.SIZE)))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--width", type=float, default=0.1)
    parser.add_argument("--period-grid", default=None, help="e.g. 16,16 (fit_lightcurve's default)")
    parser.add_argument("--starts-per-period", type=int, default=None)
    parser.add_argument("--refine", type=int, default=None)
    parser.add_argument("--convex-subdivisions", type=int, default=None, help="fit_lightcurve's default: 2")
    parser.add_argument(
        "--regularisation",
        default=None,
        help="the convex shape's closure,smoothness weights, e.g. 10,1 (fit_lightcurve's default: 100,4)",
    )
    parser.add_argument("--x-scale", default=None, help="jac: fit_lightcurve's x_scale (Marquardt's scaling)")
    parser.add_argument(
        "--stop-at-noise", action="store_true", help="rounds only while the fit misses the noise (stop_at_noise=True)"
    )
    parser.add_argument("--resume", action="store_true")
    parser.add_argument("--truth-from", help="an earlier run's JSON: its members' truth-refined figures")
    parser.add_argument("--output-dir", default=str(pathlib.Path(__file__).parent / "results"))
    parser.add_argument("--plot-only", action="store_true", help="redraw lightcurve_family.png from the JSON")
    parser.add_argument(
        "--basins-only", action="store_true", help="add the competing basins to the JSON's members and its rates"
    )
    parser.add_argument("--rates-only", action="store_true", help="recompute the JSON's rates from its members")
    parser.add_argument(
        "--truth-only", action="store_true", help="only the refinements from the truth (lightcurve_family_truth*.json)"
    )
    parser.add_argument("--merge", nargs="+", metavar="JSON", help="put a run split over processes together")
    parser.add_argument("--earlier-name", help="with --merge: keep the file's run so far under earlier_runs.NAME")
    parser.add_argument("--description", help="with --merge: how the run was made (the JSON's description)")
    options = parser.parse_args(argv)
    output = output_path(options.output_dir, options.seed)
    if options.merge:
        merge(options.merge, options.output_dir, options.earlier_name, options.description)
        return
    if options.basins_only or options.rates_only:
        stored = json.loads(output.read_text())
        if options.basins_only:
            stored["members"] = [with_basins(m) for m in stored["members"]]
        stored["rates"] = rates(stored["members"])
        output.write_text(json.dumps(stored, indent=1) + "\n")
        print(json.dumps(stored["rates"], indent=1))
        return
    if options.plot_only:
        plot(json.loads(output.read_text()), output.with_suffix(".png"))
        return
    fit_options = {}
    if options.period_grid:
        fit_options["period_grid"] = tuple(int(x) for x in options.period_grid.split(","))
    if options.starts_per_period:
        fit_options["starts_per_period"] = options.starts_per_period
    if options.refine:
        fit_options["n_refine"] = options.refine
    if options.convex_subdivisions is not None:
        fit_options["convex_subdivisions"] = options.convex_subdivisions
    if options.regularisation:
        fit_options["regularisation"] = tuple(float(x) for x in options.regularisation.split(","))
    if options.stop_at_noise:
        fit_options["stop_at_noise"] = True
    if options.x_scale:
        fit_options["x_scale"] = options.x_scale
    output.parent.mkdir(parents=True, exist_ok=True)
    if options.truth_only:
        output = output.with_name(output.name.replace("lightcurve_family", "lightcurve_family_truth"))
    # A resumed run keeps what the file holds besides its members (e.g. a run at other settings).
    previous = json.loads(output.read_text()) if options.resume and output.exists() else {}
    members = previous.get("members", [])
    done = {m["index"] for m in members}
    indices = [int(x) for x in options.members.split(",")]
    stored = {}
    if options.truth_from:
        stored = {m["index"]: m for m in json.loads(pathlib.Path(options.truth_from).read_text())["members"]}
        check_truth_from(stored, indices, options.truth_from)
    for index in indices:
        if index in done:
            continue
        case = _tumbler_family.tumbler(index, options.seed)
        if options.truth_only:
            member = truth_refinement(case, options.width, fit_options)
        else:
            member = invert(case, options.width, fit_options, stored.get(index))
        members.append(member)
        print(json.dumps(member), flush=True)
        result = {
            **previous,
            "seed": options.seed,
            "width": options.width,
            "fit_options": {k: list(v) if isinstance(v, tuple) else v for k, v in fit_options.items()},
            "machine": {"platform": platform.platform(), "backend": jax.default_backend(), "jax": jax.__version__},
            **({} if options.truth_only else {"rates": rates(members)}),
            "members": members,
        }
        output.write_text(json.dumps(result, indent=1) + "\n")
    if options.truth_only:
        return
    if members:
        plot(json.loads(output.read_text()), output.with_suffix(".png"))
    print(json.dumps(rates(members), indent=1))


if __name__ == "__main__":
    main()
