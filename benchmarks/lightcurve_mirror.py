"""The pole's mirror image: which basins win the family's members whose later nights miss (issue 42).

For each member given (default: the six of benchmarks/results/lightcurve_family.json whose later nights
miss 1.5%), ``fit_lightcurve`` searches as benchmarks/lightcurve_family.py runs it (ranges +-10% around
the true periods, ``mode="both"``, the defaults), and the winner's mirror image through the plane of
the observations is refined with ``initial=`` and ``search_rounds=1`` (the refinement from the truth of
the family benchmark, from the mirror image instead).

The mirror image: n the normal of the plane nearest the Sun's and the observer's directions (the
smallest eigenvector of sum s s^T + o o^T), M = I - 2 n n^T, D = diag(1, 1, -1); the attitude
R -> M R D and the body-frame angular momentum L -> -D L.  A torque-free motion maps to another with
the same moments and periods (Euler's equations are invariant under the body reflection with
omega -> -D omega), and with the mirrored shape it gives the same light curves exactly when every
direction lies in the plane (Kaasalainen & Lamberg 2006, Inverse Problems 22, 749: the pole
ambiguity of observations in one plane).

Per member: the angles of the winner's inertial L from the truth's and from the truth's mirror image
(-M L_true), the costs and later nights' RMS (each night's scale fitted; 1% noise) of the winner and of
its refined mirror image, the latter's L from the truth's, and the directions' RMS elevation from the
plane over the fitted and the later nights.  Writes benchmarks/results/lightcurve_mirror.json.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/lightcurve_mirror.py [--members 3,6,10,13,14,15]
        [--output-dir DIR]
(about 7 minutes a member on one core; each member's record is merged into the file as it finishes, so
two processes with disjoint ``--members`` can share one output directory)
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

from frbjax import FreeRigidBody, quaternion_from_matrix  # noqa: E402
from frbjax.lightcurve import fit_lightcurve  # noqa: E402
from frbjax.lightcurve._fit import _plane_normal  # noqa: E402  (the fit's own, ``mirror_pole``)


sys.path.insert(0, str(pathlib.Path(__file__).parent))
import _tumbler_family  # noqa: E402
import lightcurve  # noqa: E402  (its `problems`: tests/test_lightcurve_fit.py's helpers)


ROOT = pathlib.Path(__file__).resolve().parents[1]
MISSED = (3, 6, 10, 13, 14, 15)


def mirror_image(body, normal):
    """The torque-free motion mirrored through the plane of ``normal``: R -> M R D, L -> -D L."""
    reflection = np.eye(3) - 2 * np.outer(normal, normal)
    body_reflection = np.diag([1.0, 1.0, -1.0])
    attitude = np.asarray(body.rotation_matrix(0.0))
    return FreeRigidBody(
        np.asarray(body.inertia),
        -body_reflection @ np.asarray(body.angular_momentum(0.0)),
        np.asarray(quaternion_from_matrix(reflection @ attitude @ body_reflection)),
    )


def pole(body):
    """The inertial direction of L at the body's time origin."""
    momentum = np.asarray(body.rotation_matrix(0.0)) @ np.asarray(body.angular_momentum(0.0))
    return momentum / np.linalg.norm(momentum)


def degrees_between(a, b):
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))


def elevation(sun, observer, normal):
    """RMS angle (degrees) of the directions from the plane of ``normal``."""
    sines = np.concatenate([sun @ normal, observer @ normal])
    return float(np.degrees(np.arcsin(np.sqrt(np.mean(sines**2)))))


def member(index):
    case = _tumbler_family.tumbler(index, 0)
    ranges = tuple((p * 0.9, p * 1.1) for p in np.asarray(case.periods))
    common = dict(lightcurve=case.night, principal_axis=False, throw=False, progress=False)
    data = (case.times, case.flux, case.sun, case.observer)
    held_out = case.held_out_data(noiseless=False)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        found = fit_lightcurve(*data, periods=ranges, mode="both", **common)
    search_seconds = time.perf_counter() - start
    normal = _plane_normal(case.sun, case.observer)
    reflection = np.eye(3) - 2 * np.outer(normal, normal)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mirrored = fit_lightcurve(
            *data,
            periods=ranges,
            initial=mirror_image(found.body, normal),
            epoch=float(found.epoch),
            search_rounds=1,
            **common,
        )
    mirror_seconds = time.perf_counter() - start
    truth = pole(case.body_at(float(found.epoch)))
    return {
        "index": index,
        "kind": case.kind,
        "true_periods": list(case.periods),
        "plane_normal": normal.tolist(),
        "elevation_fitted_nights_deg": elevation(case.sun, case.observer, normal),
        "elevation_later_nights_deg": elevation(held_out[2], held_out[3], normal),
        "winner_pole_from_truth_deg": degrees_between(pole(found.body), truth),
        "winner_pole_from_mirrored_truth_deg": degrees_between(pole(found.body), -reflection @ truth),
        "winner_cost": float(found.cost),
        "winner_periods": np.asarray(found.periods).tolist(),
        "winner_held_out_rms": lightcurve.problems.held_out_rms(found, held_out),
        "mirror_refined_pole_from_truth_deg": degrees_between(pole(mirrored.body), truth),
        "mirror_refined_cost": float(mirrored.cost),
        "mirror_refined_periods": np.asarray(mirrored.periods).tolist(),
        "mirror_refined_held_out_rms": lightcurve.problems.held_out_rms(mirrored, held_out),
        "cost_difference_noise_units": (float(mirrored.cost) - float(found.cost)) / np.sqrt(len(case.times) / 2),
        "search_seconds": search_seconds,
        "mirror_seconds": mirror_seconds,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--members", default=",".join(str(i) for i in MISSED))
    parser.add_argument("--output-dir", type=pathlib.Path, default=ROOT / "benchmarks" / "results")
    arguments = parser.parse_args()
    path = arguments.output_dir / "lightcurve_mirror.json"
    arguments.output_dir.mkdir(parents=True, exist_ok=True)
    for index in (int(text) for text in arguments.members.split(",")):
        record = member(index)
        print(json.dumps(record), flush=True)
        # Merged into the file after each member (read again just before writing), so that two
        # processes with disjoint members can share it.
        stored = json.loads(path.read_text())["members"] if path.exists() else []
        records = sorted([r for r in stored if r["index"] != index] + [record], key=lambda r: r["index"])
        output = {
            "description": __doc__.splitlines()[0],
            "machine": {"platform": platform.platform(), "jax": jax.__version__},
            "members": records,
        }
        path.write_text(json.dumps(output, indent=1) + "\n")


if __name__ == "__main__":
    main()
