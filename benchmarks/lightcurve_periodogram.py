"""Period ranges from the data: tumbler_periodogram on the synthetic family of benchmarks/_tumbler_family.py.

For each of the family's 24 tumblers (principal-axis rotators, SAM near principal-axis rotation and at
Apophis-like energies, both modes next to the separatrix, LAM; bumpy convex hulls; 24 nights of 36 to
44 samples over 90 to 150 days; 1% noise; one scale per night) ``tumbler_periodogram`` searches the
broad band of basis periods 0.1 to 5 days (``--band``; the family's P_psi lie between 3 hours and 2
days, its P_phi up to 16 days) and the script records whether the true (P_psi, P_phi) lie inside one of
the proposed ranges (for a principal-axis rotator: P inside a "PA" proposal), inside the top-ranked
one, the rank of the first that holds them, the relative half-widths of that proposal's ranges, and the
wall time (one process, OPENBLAS_NUM_THREADS=1 recommended).  For a tumbler it also scores the true
periods' own reading as the periodogram scores its readings (``truth_rms``) and counts the tumbling
proposals that score better (``truth_rank_if_formed``; ``listed_if_formed`` when that is fewer than
the list holds): whether a miss is the search's (the truth's reading not formed) or the ranking's
(formed, it would rank below the list), and ``inside_or_listed_if_formed`` in the summary: what a
search that formed the truth's reading would reach with the same ranking.

Writes benchmarks/results/lightcurve_periodogram.json and .png (the RMS map around the best basis for
one member with the truth's basis marked, the one-period scan, and the family's outcomes).
The periodogram gets the Sun's and the observer's directions (``sun=``, ``observer=``: the geometric
ranking, as a user with the data for ``fit_lightcurve`` calls it); ``--no-geometry``: the light
curves alone (the Fourier ranking; files ``lightcurve_periodogram_fourier*``).
``--quick``: four members (a smoke test); ``--options '{"peaks": 16}'``: keyword arguments of
``tumbler_periodogram`` other than its defaults (a trial; with ``--output-dir`` to keep the stored results).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/lightcurve_periodogram.py [--quick] [--no-geometry] [--seed S] \
        [--options JSON --output-dir D]
"""

from __future__ import annotations

import argparse
import inspect
import json
import pathlib
import platform
import sys
import time

import jax


jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402


matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from _tumbler_family import SIZE, tumbler  # noqa: E402

from frbjax.lightcurve import tumbler_periodogram  # noqa: E402
from frbjax.lightcurve._periodogram import (  # noqa: E402
    _Data,
    _fibonacci_sphere,
    _geometric_fit,
    _pole_angles,
    _reading_indices,
    _refine,
)


def truth_score(case, geometry):
    """The RMS of the true (P_psi, P_phi)'s own reading, scored as ``tumbler_periodogram`` scores the
    readings it proposes (at its defaults: the drifting series refined locally from the truth, or with
    ``geometry`` the geometric series at its best pole): where it would rank had the search formed
    it.  (The periodogram's private series: a diagnostic, not an interface.)"""
    defaults = {name: value.default for name, value in inspect.signature(tumbler_periodogram).parameters.items()}
    resolution = 1 / float(np.ptp(case.times))
    f_psi, f_phi = 1 / case.periods[0], 1 / case.periods[1]
    if geometry:
        series = _Data(case.times, np.log(case.flux), case.night)
        indices = _reading_indices(*defaults["geometric_orders"])
        poles = _fibonacci_sphere(defaults["poles"])
        bisector = case.sun + case.observer
        bisector = bisector / np.linalg.norm(bisector, axis=-1, keepdims=True)
        angles = _pole_angles(bisector, poles, defaults["geometric_orders"][0])
        rss = _geometric_fit(series, f_psi, f_phi, indices, poles, angles, bisector, 0.4 * resolution, levels=3)
        return float(np.sqrt(rss / (series.dof - 4 * len(indices))))
    drift = defaults["drift"]
    series = _Data(case.times, np.log(case.flux), case.night, drift=drift)
    indices = _reading_indices(defaults["psi_order"], defaults["phi_order"])
    rss = _refine(series, indices, f_psi, f_phi, 0.15 * resolution, levels=2, points=5)[2]
    return float(np.sqrt(rss / (series.dof - 2 * len(indices) * (drift + 1))))


def holds(proposal, mode, periods):
    """True when the proposal's ranges hold the true periods."""
    p_psi, p_phi = periods
    if mode == "PA":
        return bool(np.isinf(p_phi) and proposal[0] <= p_psi <= proposal[1])
    if np.isinf(p_phi):
        return False
    (psi_low, psi_high), (phi_low, phi_high) = proposal
    return bool(psi_low <= p_psi <= psi_high and phi_low <= p_phi <= phi_high)


def run_case(index, band, seed=0, geometry=True, options=None):
    case = tumbler(index, seed)
    directions = dict(sun=case.sun, observer=case.observer) if geometry else {}
    start = time.perf_counter()
    result = tumbler_periodogram(
        case.times, case.flux, lightcurve=case.night, period_range=band, **directions, **(options or {})
    )
    elapsed = time.perf_counter() - start
    rank = next((k for k, (p, m) in enumerate(zip(result.proposals, result.modes)) if holds(p, m, case.periods)), None)
    record = dict(
        index=index,
        kind=case.kind,
        periods=[case.periods[0], case.periods[1] if np.isfinite(case.periods[1]) else None],
        long_axis=case.long_axis,
        energy_ratio=case.energy_ratio,
        span_days=case.span,
        samples=len(case.times),
        inside_any=rank is not None,
        inside_top=rank == 0,
        rank=rank,
        proposals=len(result.proposals),
        modes=list(result.modes),
        wall_s=elapsed,
        best_basis=result.bases[0].tolist() if len(result.bases) else None,
        rms_best=float(result.scores[0]) if len(result.scores) else None,
    )
    if np.isfinite(case.periods[1]):
        # Where the truth's own reading would rank among the tumbling proposals: the ranking's bound.
        record["truth_rms"] = truth_score(case, geometry)
        tumbling = [score for score, mode in zip(result.scores, result.modes) if mode != "PA"]
        record["truth_rank_if_formed"] = int(sum(score < record["truth_rms"] for score in tumbling))
        record["listed_if_formed"] = record["truth_rank_if_formed"] < len(tumbling)
    if rank is not None:
        proposal = result.proposals[rank]
        ranges = [proposal] if result.modes[rank] == "PA" else list(proposal)
        record["half_widths"] = [float((high - low) / (high + low)) for low, high in ranges]
        record["mode_of_hit"] = result.modes[rank]
    return case, result, record


def figure(example, records, path):
    case, result = example
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    ax = axes[0]
    t = result.span
    mesh = ax.pcolormesh(
        (result.map_f1 - result.bases[0, 0]) * t,
        (result.map_f2 - result.bases[0, 1]) * t,
        result.map_rms,
        shading="auto",
        cmap="viridis",
    )
    fig.colorbar(mesh, ax=ax, label="RMS of the two-period series (log flux)")
    ax.plot(0, 0, "w+", ms=12, mew=2, label="best basis")
    ax.set_xlabel("f1 - best f1  [1 / span]")
    ax.set_ylabel("f2 - best f2  [1 / span]")
    p_psi, p_phi = case.periods
    ax.set_title(
        f"member {case.index} ({case.kind}): best (f1, f2) = ({result.bases[0, 0]:.4f}, {result.bases[0, 1]:.4f}) / d\n"
        f"true f_psi = {1 / p_psi:.4f}, f_phi = {1 / p_phi:.4f} / d",
        fontsize=9,
    )
    ax.legend(loc="upper right", fontsize=8)
    ax = axes[1]
    ax.plot(result.frequencies, result.rms, lw=0.6)
    for value, label, colour in ((1 / p_psi, "f_psi", "C1"), (1 / p_psi - 1 / p_phi, "f_psi - f_phi", "C2")):
        ax.axvline(value, color=colour, ls="--", lw=1, label=label)
    ax.set_xlabel("base frequency f  [1 / day]")
    ax.set_ylabel("RMS of the one-period series (harmonics 1, 2)")
    ax.set_title("one-period scan at the full span's resolution", fontsize=9)
    ax.legend(fontsize=8)
    ax = axes[2]
    kinds = list(dict.fromkeys(r["kind"] for r in records))
    for k, kind in enumerate(kinds):
        rows = [r for r in records if r["kind"] == kind]
        ranks = [r["rank"] + 1 if r["rank"] is not None else 14 for r in rows]
        ax.scatter([r["index"] for r in rows], ranks, color=f"C{k}", label=kind, s=40)
    ax.axhline(13, color="grey", lw=0.8)
    ax.set_yticks(list(range(1, 13)) + [14])
    ax.set_yticklabels([str(k) for k in range(1, 13)] + ["missed"])
    ax.set_xlabel("family member")
    ax.set_ylabel("rank of the first proposal holding the truth")
    hits = sum(r["inside_any"] for r in records)
    top = sum(r["inside_top"] for r in records)
    ax.set_title(f"inside a proposal: {hits} of {len(records)}; inside the top one: {top}", fontsize=9)
    ax.legend(fontsize=7, loc="center right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="four members (a smoke test)")
    parser.add_argument("--band", type=float, nargs=2, default=(0.1, 5.0), help="period_range in days")
    parser.add_argument("--seed", type=int, default=0, help="the family's seed (s != 0: _seed<s> files)")
    parser.add_argument("--example", type=int, default=8, help="the member whose map is drawn")
    parser.add_argument("--no-geometry", action="store_true", help="without sun and observer (Fourier ranking)")
    parser.add_argument(
        "--options",
        type=json.loads,
        default={},
        help="tumbler_periodogram keyword arguments as JSON, e.g. '{\"peaks\": 16}' (a trial: give --output-dir)",
    )
    parser.add_argument("--output-dir", type=pathlib.Path, default=ROOT / "benchmarks" / "results")
    args = parser.parse_args()
    indices = [0, 8, 13, 19] if args.quick else list(range(SIZE))
    records, example = [], None
    for index in indices:
        case, result, record = run_case(
            index, tuple(args.band), args.seed, geometry=not args.no_geometry, options=args.options
        )
        records.append(record)
        if index == args.example or example is None:
            example = (case, result) if index == args.example or example is None else example
        print(
            f"{index:2d} {record['kind']:15s} inside={record['inside_any']} rank={record['rank']} "
            f"widths={record.get('half_widths')} {record['wall_s']:.1f} s",
            flush=True,
        )
    hits = [r for r in records if r["inside_any"]]
    widths = np.array([w for r in hits for w in r["half_widths"]]) if hits else np.zeros(0)
    summary = dict(
        cases=len(records),
        inside_any=len(hits),
        inside_top=sum(r["inside_top"] for r in records),
        fraction_inside_any=len(hits) / len(records),
        median_rank_of_hits=float(np.median([r["rank"] for r in hits])) if hits else None,
        half_width_median=float(np.median(widths)) if len(widths) else None,
        half_width_max=float(np.max(widths)) if len(widths) else None,
        # Inside a proposal, or a tumbler whose true reading, had the search formed it, would have
        # been listed: what a search that formed it would reach with the same ranking.
        inside_or_listed_if_formed=sum(r["inside_any"] or r.get("listed_if_formed", False) for r in records),
        wall_s_median=float(np.median([r["wall_s"] for r in records])),
        wall_s_max=float(np.max([r["wall_s"] for r in records])),
    )
    print(json.dumps(summary, indent=2))
    output = dict(
        band_days=list(args.band),
        seed=args.seed,
        geometry=not args.no_geometry,
        options=args.options,
        machine=dict(platform=platform.platform(), processor=platform.processor(), jax=jax.__version__),
        summary=summary,
        cases=records,
    )
    args.output_dir.mkdir(parents=True, exist_ok=True)
    suffix = ("_fourier" if args.no_geometry else "") + ("_quick" if args.quick else "")
    suffix += f"_seed{args.seed}" if args.seed else ""
    (args.output_dir / f"lightcurve_periodogram{suffix}.json").write_text(json.dumps(output, indent=2) + "\n")
    figure(example, records, args.output_dir / f"lightcurve_periodogram{suffix}.png")


if __name__ == "__main__":
    main()
