"""Torques of every kind: frbjax against Basilisk, the long-time energy picture, and a debris spin-down.

Three parts (``--parts``, default all), each writing JSON (and a PNG) into benchmarks/results/:

* ``basilisk`` (torques_basilisk.json/png): a satellite (principal moments 900, 800, 600 kg m^2) on
  a circular orbit of radius 7000 km (Earth, mu = 3.986004360e14 m^3/s^2, Basilisk's value), tumbling
  at about 0.02 rad/s, under the gravity-gradient torque and a linear viscous damping D = 0.005 N m s
  (``frbjax.torques.GravityGradient`` + ``LinearDamping`` as the term's ``momentum_torque``: the
  gravity gradient alone kicks by its closed form, with the damping the kick is the exact affine
  one), to T = one day.  Work-precision: frbjax's
  splitting methods (``RigidBodySplitting`` in ``diffrax.diffeqsolve``, final state only) over step
  sizes, diffrax's Tsit5 and Dopri8 on the same ``RigidBodyTerm`` over tolerances, and Basilisk's
  spacecraft hub (``GravityGradientEffector``) with its RK4 over step sizes and RKF78 over
  tolerances.  The error is max(|L - L_ref|_inf / |L_ref|, |q - q_ref|_inf) at T against diffrax
  Dopri8 at rtol = atol = 1e-14 (its floor, the distance to Dopri8 at 1e-13 and to blanes_moan6 at
  its smallest step, is in the JSON).  Basilisk integrates the orbit too (point-mass Earth), where
  frbjax is given the circular orbit exactly; Basilisk has no torque that depends on the state at
  each Runge-Kutta stage, so its damping is an ``ExtForceTorque`` set from the rates once per step
  (zero-order hold) by a Python module: the same problem to first order in the step only.  Basilisk
  therefore also runs the undamped satellite (``undamped``: the same ODE at every stage, where its
  RK4 and RKF78 converge), against which the frbjax methods are timed too.  Times: best of
  ``--repeats`` runs after compilation (Basilisk: after ``InitializeSimulation``), one body; then
  1024 bodies with different initial states at the step (tolerance) that gives 1e-8 for one body,
  per body (Basilisk has no batch: its per-body time is its one-body time): the fastest splitting
  method (one batched state; the state at T by ``splitting_trajectory(save_every=steps)``, which
  joins the free flows across steps, and through ``diffeqsolve`` for comparison) and the fastest
  diffrax solver (``jax.vmap``: each body its own steps),
  except the splitting on the damped satellite (its matrix-exponential kicks cost as much per body
  in a batch as alone, minutes for 1024 bodies; its one-body time is behind Dopri8's anyway).
* ``energy`` (torques_energy.json/png): the heavy top (``torques.UniformGravity`` as a potential) over
  10^6 steps of blanes_moan4 at a large step (energy error about 1e-4) and at a small one, against
  Tsit5 and Dopri8 with fixed steps set for the same wall time (their per-step cost measured first,
  at most 20 times the splitting's steps).
* ``debris`` (torques_debris.json/png): a tumbling rocket body (moments 2050, 1950, 450 kg m^2) on a
  polar-ish circular orbit (7178 km, inclination 82 deg) in an aligned dipole field, spun down by
  eddy currents (magnetic tensor diag(1e5, 1e5, 3e4) S m^4) with the gravity-gradient torque, over a
  simulated year: blanes_moan4 with exact (matrix-exponential) kicks against Dopri8 at rtol = atol =
  1e-10, the spin rate along the way and at the end, and the time each takes.

``--quick`` shrinks everything (a smoke test: T = 1 h and a few points, 10^3 energy steps, a 2-day
debris run, 8 bodies).  ``--without-basilisk`` leaves Basilisk out (so does its absence, with a
message).  Install Basilisk for this script only: ``.venv/bin/pip install bsk`` (never a test
dependency).  Run under ``taskset -c 1`` for one core.  The numbers are wall times on the machine that
runs the script; say which when quoting.

Usage: python benchmarks/torques_basilisk.py [--quick] [--parts basilisk energy debris]
       [--without-basilisk] [--output-dir DIR] [--repeats N]
       python benchmarks/torques_basilisk.py --parts batch [--batch-bodies N]   # e.g. on a GPU

``--parts batch`` runs the batch rows alone on JAX's default device (a GPU where there is one), at the
one-body settings recorded in benchmarks/results/torques_basilisk.json, into torques_batch_<backend>.json.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import platform
import time
from pathlib import Path


os.environ.setdefault("EQX_ON_ERROR", "nan")

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import frbjax  # noqa: E402
from frbjax import torques  # noqa: E402


RESULTS = Path(__file__).resolve().parent / "results"
TARGET_ERROR = 1e-8
MU_EARTH = 3.986004360e14  # Basilisk's createEarth() value
DAY = 86400.0
YEAR = 365.25 * DAY


def best_time(function, repeats):
    """Best wall time of ``function()`` over ``repeats`` runs (one when a run takes over 2 s).

    The caller's warm-up call must have finished (``jax.block_until_ready``): JAX dispatches
    asynchronously, and a first timed run would otherwise wait for it (the batch rows, timed once,
    took twice their time so until 2026-11-26)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(function())
        times.append(time.perf_counter() - start)
        if times[-1] > 2:
            break
    return min(times)


def time_at_target(points):
    """Time at TARGET_ERROR, log-log interpolated between the two points around it (None if not bracketed)."""
    points = sorted((p["error"], p["seconds"]) for p in points if math.isfinite(p["error"]))
    for (e1, t1), (e2, t2) in zip(points, points[1:]):
        if e1 <= TARGET_ERROR <= e2 and e1 < e2:
            w = (math.log(TARGET_ERROR) - math.log(e1)) / (math.log(e2) - math.log(e1))
            return math.exp(math.log(t1) + w * (math.log(t2) - math.log(t1)))
    return None


def relative_error(y, reference):
    """max(|L - L_ref|_inf / |L_ref|, |q - q_ref|_inf) per body (q up to its sign)."""
    momentum, attitude = (np.asarray(x) for x in y)
    momentum_ref, attitude_ref = (np.asarray(x) for x in reference)
    sign = np.sign(np.sum(attitude * attitude_ref, axis=-1, keepdims=True))
    return np.maximum(
        np.abs(momentum - momentum_ref).max(axis=-1) / np.linalg.norm(momentum_ref, axis=-1),
        np.abs(sign * attitude - attitude_ref).max(axis=-1),
    )


# ------------------------------------------------------------------------------ the satellite

SATELLITE_INERTIA = np.array([900.0, 800.0, 600.0])
ORBIT_RADIUS = 7.0e6
DAMPING = 0.005
SIGMA0 = np.array([0.1, -0.05, 0.2])  # Basilisk's initial attitude (MRP, B relative to N)
OMEGA0 = np.array([0.01, -0.005, 0.02])


def mrp_to_quaternion(sigma):
    """frbjax's q (body to space) of the MRP sigma_BN: q = (1 - s^2, 2 sigma) / (1 + s^2) (Schaub and
    Junkins, Analytical Mechanics of Space Systems, section 3.7); [BN] = R(q)^T."""
    s2 = sigma @ sigma
    return np.concatenate([[1 - s2], 2 * sigma]) / (1 + s2)


def satellite_term(damped):
    """The ready-made torques as the momentum torque: the gravity gradient alone does not depend on L
    (plain kicks L += s tau, its closed form), with the damping the kick is the exact affine one."""
    inertia = jnp.asarray(SATELLITE_INERTIA)
    torque = torques.GravityGradient(inertia, torques.CircularOrbit(ORBIT_RADIUS, MU_EARTH))
    if damped:
        torque = torque + torques.LinearDamping(inertia, DAMPING)
    return frbjax.RigidBodyTerm(inertia, momentum_torque=torque)


def satellite_states(bodies):
    """The one body of Basilisk's run first, then random tumbles of the same size: the rate
    |omega| = |OMEGA0| about random directions, from random attitudes (so that the one body's step
    means the same accuracy for all of them)."""
    rng = np.random.default_rng(7)
    directions = rng.normal(size=(bodies - 1, 3))
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    omegas = np.concatenate([OMEGA0[None], np.linalg.norm(OMEGA0) * directions])
    attitudes = np.concatenate([mrp_to_quaternion(SIGMA0)[None], rng.normal(size=(bodies - 1, 4))])
    attitudes /= np.linalg.norm(attitudes, axis=-1, keepdims=True)
    return jnp.asarray(omegas * SATELLITE_INERTIA), jnp.asarray(attitudes)


def frbjax_programs(term, final_time):
    def rk(solver):
        @jax.jit
        def run(y0, tolerance):
            solution = diffrax.diffeqsolve(
                term,
                solver,
                0.0,
                final_time,
                1.0,
                y0,
                max_steps=10_000_000,
                throw=False,
                stepsize_controller=diffrax.PIDController(rtol=tolerance, atol=tolerance),
            )
            return solution.ys[0][-1], solution.ys[1][-1]

        return run

    def splitting(method):
        @jax.jit
        def run(y0, step):
            solution = diffrax.diffeqsolve(
                term, frbjax.RigidBodySplitting(method), 0.0, final_time, step, y0, max_steps=10_000_000
            )
            return solution.ys[0][-1], solution.ys[1][-1]

        return run

    def final_state(method, step):
        """The state at T alone by ``splitting_trajectory(save_every=steps)``: the same method, with
        the free flows joined across steps where it starts and ends with one (aba864, aba1064)."""
        steps = round(final_time / step)
        if not math.isclose(steps * step, final_time):
            raise ValueError(f"the step {step} does not divide T = {final_time}")

        @jax.jit
        def run(y0):
            _, (momenta, attitudes) = frbjax.splitting_trajectory(
                term, y0, dt=step, steps=steps, method=method, save_every=steps
            )
            return momenta[-1], attitudes[-1]

        return run

    return rk, splitting, final_state


def basilisk_run(final_time, step, integrator, damped, tolerance=None):
    """(seconds, (L, q)) of Basilisk's spacecraft hub at ``final_time`` (task step ``step``)."""
    from Basilisk.architecture import sysModel
    from Basilisk.simulation import extForceTorque, GravityGradientEffector, spacecraft, svIntegrators
    from Basilisk.utilities import macros, simIncludeGravBody, SimulationBaseClass

    simulation = SimulationBaseClass.SimBaseClass()
    process = simulation.CreateNewProcess("dynamics")
    process.addTask(simulation.CreateNewTask("step", macros.sec2nano(step)))
    body = spacecraft.Spacecraft()
    body.ModelTag = "satellite"
    body.hub.mHub = 500.0
    body.hub.IHubPntBc_B = np.diag(SATELLITE_INERTIA).tolist()
    gravity = simIncludeGravBody.gravBodyFactory()
    earth = gravity.createEarth()
    earth.isCentralBody = True
    gravity.addBodiesTo(body)
    assert abs(earth.mu - MU_EARTH) < 1e3, earth.mu
    body.hub.r_CN_NInit = [ORBIT_RADIUS, 0.0, 0.0]
    body.hub.v_CN_NInit = [0.0, math.sqrt(earth.mu / ORBIT_RADIUS), 0.0]
    body.hub.sigma_BNInit = SIGMA0.tolist()
    body.hub.omega_BN_BInit = OMEGA0.tolist()
    gradient = GravityGradientEffector.GravityGradientEffector()
    gradient.ModelTag = "gravity_gradient"
    gradient.addPlanetName(earth.planetName)
    body.addDynamicEffector(gradient)
    if integrator == "RKF78":
        solver = svIntegrators.svIntegratorRKF78(body)
        solver.relTol = tolerance
        solver.absTol = tolerance
    else:
        solver = svIntegrators.svIntegratorRK4(body)
    body.setIntegrator(solver)
    simulation.AddModelToTask("step", body)
    simulation.AddModelToTask("step", gradient)
    keep = []
    if damped:
        external = extForceTorque.ExtForceTorque()
        external.ModelTag = "damping"
        body.addDynamicEffector(external)
        simulation.AddModelToTask("step", external)

        class Damper(sysModel.SysModel):
            def UpdateState(self, nanoseconds):
                rates = np.asarray(body.scStateOutMsg.read().omega_BN_B)
                external.extTorquePntB_B = (-DAMPING * rates).tolist()

        damper = Damper()
        damper.ModelTag = "damper"
        simulation.AddModelToTask("step", damper, 10)
        keep.append(damper)
    simulation.InitializeSimulation()
    simulation.ConfigureStopTime(macros.sec2nano(final_time))
    start = time.perf_counter()
    simulation.ExecuteSimulation()
    seconds = time.perf_counter() - start
    state = body.scStateOutMsg.read()
    momentum = SATELLITE_INERTIA * np.asarray(state.omega_BN_B)
    return seconds, (momentum, mrp_to_quaternion(np.asarray(state.sigma_BN)))


def basilisk_available():
    try:
        import Basilisk  # noqa: F401
    except ImportError:
        return False
    return True


SPLITTING_STEPS = {
    "leapfrog": [10.0, 5.0, 2.5, 1.25],
    "yoshida4": [40.0, 20.0, 10.0, 5.0],
    "blanes_moan4": [80.0, 40.0, 20.0, 10.0],
    "blanes_moan6": [80.0, 40.0, 20.0, 10.0],
    "aba864": [80.0, 40.0, 20.0, 10.0],
    "aba1064": [80.0, 40.0, 20.0, 10.0],
}
TOLERANCES = [1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13]
BASILISK_STEPS = [8.0, 4.0, 2.0, 1.0, 0.5]
BASILISK_TOLERANCES = [1e-6, 1e-8, 1e-10, 1e-12]


def basilisk_part(quick, repeats, with_basilisk):
    final_time = 3600.0 if quick else DAY
    splitting_steps = {"blanes_moan4": [40.0, 20.0]} if quick else SPLITTING_STEPS
    tolerances = [1e-7, 1e-9] if quick else TOLERANCES
    rk_solvers = {"Dopri8": diffrax.Dopri8()} if quick else {"Tsit5": diffrax.Tsit5(), "Dopri8": diffrax.Dopri8()}
    bodies = 8 if quick else 1024
    results = {
        "final_time": final_time,
        "target_error": TARGET_ERROR,
        "bodies_in_batch": bodies,
        "error": "max(|L - L_ref|_inf / |L_ref|, |q - q_ref|_inf) at T",
        "problems": {},
    }
    if not with_basilisk:
        results["basilisk"] = (
            "left out: Basilisk is not installed (.venv/bin/pip install bsk) or --without-basilisk was given"
        )
        print(f"basilisk: {results['basilisk']}", flush=True)
    for name, damped in (("damped", True), ("undamped", False)):
        term = satellite_term(damped)
        rk, splitting, final_state = frbjax_programs(term, final_time)
        y0 = tuple(x[0] for x in satellite_states(1))
        dopri8 = rk(diffrax.Dopri8())
        reference = dopri8(y0, jnp.asarray(1e-14))
        floor = float(relative_error(dopri8(y0, jnp.asarray(1e-13)), reference))
        entry = {"reference": "diffrax Dopri8 rtol=atol=1e-14", "reference_distance_to_1e-13": floor, "methods": {}}
        print(f"{name}: reference's distance to Dopri8 at 1e-13: {floor:.1e}", flush=True)
        programs = {}
        for method, steps in splitting_steps.items():
            run = splitting(method)
            programs[method] = run
            points = []
            for step in steps:
                state = jax.block_until_ready(run(y0, jnp.asarray(step)))
                seconds = best_time(lambda: run(y0, jnp.asarray(step)), repeats)
                points.append({"step": step, "error": float(relative_error(state, reference)), "seconds": seconds})
                print(f"  {method:13s} h={step:<8g} error {points[-1]['error']:.2e}  {seconds:.4f} s", flush=True)
            entry["methods"][method] = {
                "kind": "frbjax splitting",
                "points": points,
                "seconds_at_target": time_at_target(points),
            }
        smallest = min(entry["methods"].items(), key=lambda item: item[1]["points"][-1]["error"])
        entry["reference_distance_to_best_splitting"] = smallest[1]["points"][-1]["error"]
        for solver_name, solver in rk_solvers.items():
            run = dopri8 if solver_name == "Dopri8" else rk(solver)
            programs[solver_name] = run
            points = []
            for tolerance in tolerances:
                state = jax.block_until_ready(run(y0, jnp.asarray(tolerance)))
                seconds = best_time(lambda: run(y0, jnp.asarray(tolerance)), repeats)
                points.append(
                    {"tolerance": tolerance, "error": float(relative_error(state, reference)), "seconds": seconds}
                )
                print(
                    f"  {solver_name:13s} tol={tolerance:<8g} error {points[-1]['error']:.2e}  {seconds:.4f} s",
                    flush=True,
                )
            entry["methods"][solver_name] = {
                "kind": "frbjax diffrax",
                "points": points,
                "seconds_at_target": time_at_target(points),
            }
        if with_basilisk:
            for integrator, settings in (
                ("RK4", BASILISK_STEPS[:2] if quick else BASILISK_STEPS),
                ("RKF78", BASILISK_TOLERANCES[:2] if quick else BASILISK_TOLERANCES),
            ):
                points = []
                for setting in settings:
                    step, tolerance = (setting, None) if integrator == "RK4" else (60.0, setting)
                    runs = [
                        basilisk_run(final_time, step, integrator, damped, tolerance)
                        for _ in range(1 if quick else repeats)
                    ]
                    seconds = min(r[0] for r in runs)
                    point = {"error": float(relative_error(runs[0][1], reference)), "seconds": seconds}
                    point.update({"step": step} if integrator == "RK4" else {"tolerance": tolerance, "task_step": step})
                    points.append(point)
                    print(
                        f"  Basilisk {integrator:5s} {setting:<8g} error {point['error']:.2e}  {seconds:.4f} s",
                        flush=True,
                    )
                entry["methods"][f"Basilisk {integrator}"] = {
                    "kind": "Basilisk",
                    "points": points,
                    "seconds_at_target": time_at_target(points),
                }
        fastest = {}
        for kind in ("frbjax splitting", "frbjax diffrax", "Basilisk"):
            timed = [
                (m["seconds_at_target"], label)
                for label, m in entry["methods"].items()
                if m["kind"] == kind and m["seconds_at_target"]
            ]
            fastest[kind] = min(timed) if timed else None
        entry["fastest_at_target"] = fastest
        frbjax_best = min((f for k, f in fastest.items() if k.startswith("frbjax") and f), default=None)
        entry["basilisk_over_frbjax_one_body"] = (
            fastest["Basilisk"][0] / frbjax_best[0] if frbjax_best and fastest["Basilisk"] else None
        )
        entry.update(batch_rows(term, rk, splitting, final_state, entry, damped, quick, bodies, repeats))
        print(
            f"  {name}: fastest at {TARGET_ERROR:g}: {fastest}; Basilisk / frbjax one body "
            f"{entry['basilisk_over_frbjax_one_body']}, per body in a batch "
            f"{entry.get('basilisk_over_frbjax_per_body_batch')}",
            flush=True,
        )
        results["problems"][name] = entry
    return results


def batch_rows(term, rk, splitting, final_state, entry, damped, quick, bodies, repeats):
    """The batch rows of one problem: its fastest frbjax methods at ``entry``'s one-body settings, and
    the per-body time against Basilisk's one body."""
    fastest = entry["fastest_at_target"]
    rows = {"batch": {}}
    for kind in ("frbjax splitting", "frbjax diffrax"):
        if kind == "frbjax splitting" and damped and not quick:
            # Its matrix-exponential kicks cost about 100 us a step per body in a batch too
            # (measured with 64 bodies): minutes for 1024, and one body's Tsit5 is faster anyway.
            rows["batch_splitting"] = "left out: the exact damping kicks cost as much per body in a batch"
            continue
        if fastest[kind]:
            rows["batch"][fastest[kind][1]] = batch(
                term, rk, splitting, final_state, entry, fastest[kind][1], bodies, repeats
            )
    if rows["batch"]:
        per_body = min(run["seconds_per_body"] for run in rows["batch"].values())
        rows["fastest_seconds_per_body_in_batch"] = per_body
        rows["basilisk_over_frbjax_per_body_batch"] = fastest["Basilisk"][0] / per_body if fastest["Basilisk"] else None
    return rows


def batch(term, rk, splitting, final_state, entry, method, bodies, repeats):
    """``bodies`` satellites at once with ``method`` at the setting that gives TARGET_ERROR for one body.

    A splitting method steps all bodies together (one state (bodies, 3), (bodies, 4)), both through
    ``diffeqsolve`` and through ``splitting_trajectory(save_every=steps)`` (the final state alone, the
    free flows joined across steps: the row's time and errors); a Runge-Kutta method is
    ``jax.vmap``-ed over the bodies, so that each body keeps its own adaptive steps.
    """
    points = entry["methods"][method]["points"]
    kind = "step" if "step" in points[0] else "tolerance"
    # The largest step (loosest tolerance) whose one-body error is at or below the target.
    good = [p for p in points if p["error"] <= TARGET_ERROR] or points[-1:]
    setting = max(p[kind] for p in good)
    y0 = satellite_states(bodies)
    extra = {}
    if kind == "step":
        through_diffeqsolve = splitting(method)
        jax.block_until_ready(through_diffeqsolve(y0, jnp.asarray(setting)))
        extra["seconds_diffeqsolve"] = best_time(lambda: through_diffeqsolve(y0, jnp.asarray(setting)), repeats)
        final = final_state(method, setting)

        def run(y0, setting):
            return final(y0)

        extra["program"] = "splitting_trajectory(save_every=steps): the final state, free flows joined"
    else:
        run = jax.jit(jax.vmap(rk({"Tsit5": diffrax.Tsit5(), "Dopri8": diffrax.Dopri8()}[method]), in_axes=(0, None)))
    state = jax.block_until_ready(run(y0, jnp.asarray(setting)))
    seconds = best_time(lambda: run(y0, jnp.asarray(setting)), repeats)
    references = jax.jit(jax.vmap(rk(diffrax.Dopri8()), in_axes=(0, None)))
    reference = references(y0, jnp.asarray(1e-14))
    errors = relative_error(state, reference)
    # The reference's own uncertainty per body (its distance to Dopri8 at 1e-13): a tumble whose
    # state at T amplifies rounding errors this much is ill-conditioned for every method.
    uncertainty = relative_error(references(y0, jnp.asarray(1e-13)), reference)
    through = f" (diffeqsolve {1e6 * extra['seconds_diffeqsolve'] / bodies:.1f} us)" if extra else ""
    print(
        f"  batch of {bodies}: {method} {kind}={setting:g}: {seconds:.3f} s, {1e6 * seconds / bodies:.1f} us "
        f"per body{through}; error median {np.median(errors):.1e}, 90% {np.quantile(errors, 0.9):.1e}, max "
        f"{errors.max():.1e}; reference's own uncertainty max {uncertainty.max():.1e}",
        flush=True,
    )
    return {
        "method": method,
        kind: setting,
        "bodies": bodies,
        "seconds": seconds,
        "seconds_per_body": seconds / bodies,
        **extra,
        "max_error": float(errors.max()),
        "median_error": float(np.median(errors)),
        "p90_error": float(np.quantile(errors, 0.9)),
        "fraction_within_target": float(np.mean(errors <= TARGET_ERROR)),
        "max_reference_uncertainty": float(uncertainty.max()),
    }


def plot_basilisk(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, len(results["problems"]), figsize=(12, 4.8))
    styles = {"frbjax splitting": "-o", "frbjax diffrax": "--s", "Basilisk": ":^"}
    for axis, (name, entry) in zip(np.atleast_1d(axes), results["problems"].items()):
        for method, data in entry["methods"].items():
            points = [p for p in data["points"] if math.isfinite(p["error"])]
            axis.loglog(
                [p["error"] for p in points], [p["seconds"] for p in points], styles[data["kind"]], label=method
            )
        axis.axvline(TARGET_ERROR, color="grey", lw=0.8)
        title = f"gravity-gradient satellite, {name}, T = {results['final_time'] / 3600:g} h"
        ratio = entry.get("basilisk_over_frbjax_one_body")
        if ratio:
            title += f"\nBasilisk's fastest / frbjax's fastest at {TARGET_ERROR:g}: {ratio:.2g}x"
        axis.set(title=title, xlabel="relative error at T (L and q)", ylabel="seconds (one body)")
        axis.invert_xaxis()
        axis.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=120)


# --------------------------------------------------------------------------------------- energy


def energy_part(quick, repeats):
    inertia = jnp.array([1.0, 1.6, 2.3])
    gravity = torques.UniformGravity([0.05, 0.1, 0.4], [0.0, 0.0, -1.0])
    term = frbjax.RigidBodyTerm(inertia, potential=gravity.potential)
    q0 = np.array([0.9, 0.3, -0.2, 0.1])
    y0 = (jnp.array([0.3, 0.8, 10.0]), jnp.asarray(q0 / np.linalg.norm(q0)))
    steps = 1000 if quick else 1_000_000
    energy0 = float(term.energy(0.0, y0, None))
    results = {"problem": "heavy top, moments (1, 1.6, 2.3), L(0) = (0.3, 0.8, 10)", "steps": steps, "cases": {}}
    # One program per solver, compiled once: the span, the step and the sample times are its arguments
    # (a closure over them compiled ten programs in all: half of the --quick run's time).
    programs = {}

    def program(solver):
        if id(solver) not in programs:

            @jax.jit
            def run(final_time, dt, samples):
                solution = diffrax.diffeqsolve(
                    term, solver, 0.0, final_time, dt, y0, saveat=diffrax.SaveAt(ts=samples), max_steps=steps * 20 + 10
                )
                return solution.ys

            programs[id(solver)] = run
        return programs[id(solver)]

    splitting_method = frbjax.RigidBodySplitting("blanes_moan4")
    reference_solvers = (("Tsit5", diffrax.Tsit5()), ("Dopri8", diffrax.Dopri8()))
    for case, step in (("large_step", 0.4), ("small_step", 0.05)):
        final_time = steps * step
        samples = jnp.linspace(0.0, final_time, 101 if quick else 1001)
        splitting = functools.partial(program(splitting_method), final_time, step, samples)
        states = jax.block_until_ready(splitting())
        seconds = best_time(splitting, 1)
        error = np.abs(np.asarray(term.energy(0.0, states, None)) - energy0)
        runs = {"blanes_moan4": {"step": step, "steps": steps, "seconds": seconds, "energy_error": error.tolist()}}
        print(
            f"energy {case}: blanes_moan4 {steps} steps of {step} in {seconds:.2f} s, max |dE| {error.max():.2e}",
            flush=True,
        )
        for name, solver in reference_solvers:
            # The cost of a step, measured with the very program that runs (its max_steps, its SaveAt)
            # over a fiftieth of the run, sets the step for the same wall time.
            probe_time = final_time / 50
            probe = functools.partial(program(solver), probe_time, step, jnp.linspace(0.0, probe_time, len(samples)))
            jax.block_until_ready(probe())
            per_step = best_time(probe, repeats) / (steps / 50)
            count = min(max(int(seconds / per_step), 100), steps * 20)
            run = functools.partial(program(solver), final_time, final_time / count, samples)
            states = jax.block_until_ready(run())
            rk_seconds = best_time(run, 1)
            rk_error = np.abs(np.asarray(term.energy(0.0, states, None)) - energy0)
            runs[name] = {
                "step": final_time / count,
                "steps": count,
                "seconds": rk_seconds,
                "energy_error": rk_error.tolist(),
            }
            print(
                f"energy {case}: {name} {count} steps of {final_time / count:.3g} in {rk_seconds:.2f} s, "
                f"max |dE| {np.nanmax(rk_error):.2e}",
                flush=True,
            )
        for run in runs.values():
            error = np.asarray(run["energy_error"][1:])
            tenth = max(len(error) // 10, 1)
            run["max_first_tenth"] = float(error[:tenth].max())
            run["max_last_tenth"] = float(error[-tenth:].max())
            run["ratio_last_to_first_tenth"] = run["max_last_tenth"] / run["max_first_tenth"]
        results["cases"][case] = {"final_time": final_time, "times": np.asarray(samples).tolist(), "runs": runs}
    return results


def plot_energy(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    for axis, (case, data) in zip(axes, results["cases"].items()):
        times = np.asarray(data["times"])
        for name, run in data["runs"].items():
            label = f"{name}: {run['steps']} steps of {run['step']:.3g}, {run['seconds']:.1f} s"
            axis.loglog(times[1:], np.maximum(np.asarray(run["energy_error"])[1:], 1e-17), label=label)
        axis.set(xlabel="t", ylabel="|E(t) - E(0)|", title=f"heavy top, {case.replace('_', ' ')}: equal wall time")
        axis.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=120)


# --------------------------------------------------------------------------------------- debris

EARTH_RADIUS = 6371.2e3
DIPOLE_FIELD = 3.12e-5  # T at the equator on the surface


class DipoleField(eqx.Module):
    """The aligned centred dipole (Earth's field, dipole along -z) along an orbit: B(r(t)) in space.

    B(r) = B0 (R_E / |r|)^3 (3 (m . rhat) rhat - m), m = (0, 0, -1) (Wertz, Spacecraft Attitude
    Determination and Control, appendix H; Markley and Crassidis 2014, section 3.3.5).
    """

    orbit: torques.CircularOrbit

    def __call__(self, t):
        position = self.orbit(t)
        distance = jnp.linalg.norm(position)
        direction = position / distance
        moment = jnp.array([0.0, 0.0, -1.0])
        return DIPOLE_FIELD * (EARTH_RADIUS / distance) ** 3 * (3 * (moment @ direction) * direction - moment)


DEBRIS_INERTIA = np.array([2050.0, 1950.0, 450.0])
MAGNETIC_TENSOR = np.array([1e5, 1e5, 3e4])


def debris_part(quick, days, step):
    final_time = 2 * DAY if quick else days * DAY
    inertia = jnp.asarray(DEBRIS_INERTIA)
    orbit = torques.CircularOrbit(7.178e6, MU_EARTH, inclination=math.radians(82.0))
    torque = torques.EddyCurrent(inertia, MAGNETIC_TENSOR, DipoleField(orbit)) + torques.GravityGradient(inertia, orbit)
    term = frbjax.RigidBodyTerm(inertia, momentum_torque=torque)
    y0 = (inertia * jnp.array([0.02, -0.01, 0.05]), jnp.array([1.0, 0.0, 0.0, 0.0]))
    samples = jnp.linspace(0.0, final_time, 366 if not quick else 49)

    def run_splitting():
        return diffrax.diffeqsolve(
            term,
            frbjax.RigidBodySplitting("blanes_moan4"),
            0.0,
            final_time,
            step,
            y0,
            saveat=diffrax.SaveAt(ts=samples),
            max_steps=int(final_time / step) + 10,
        ).ys

    def run_dopri8():
        return diffrax.diffeqsolve(
            term,
            diffrax.Dopri8(),
            0.0,
            final_time,
            1.0,
            y0,
            saveat=diffrax.SaveAt(ts=samples),
            max_steps=100_000_000,
            throw=False,
            stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-10),
        )

    results = {
        "final_time": final_time,
        "step": step,
        "method": "blanes_moan4",
        "reference": "Dopri8 rtol=atol=1e-10",
        "times": np.asarray(samples).tolist(),
    }
    for name, function in (("blanes_moan4", run_splitting), ("Dopri8", run_dopri8)):
        compiled = jax.jit(function).lower().compile()
        start = time.perf_counter()
        output = jax.block_until_ready(compiled())
        seconds = time.perf_counter() - start
        ys = output if name == "blanes_moan4" else output.ys
        rates = np.linalg.norm(np.asarray(ys[0]) / DEBRIS_INERTIA, axis=-1)
        results[name] = {
            "seconds": seconds,
            "spin_rate": rates.tolist(),
            "states": [np.asarray(y).tolist() for y in ys],
        }
        if name == "Dopri8":
            results[name]["steps"] = int(output.stats["num_steps"])
        print(
            f"debris: {name} to T = {final_time / DAY:g} days in {seconds:.1f} s; spin rate "
            f"{rates[0]:.4f} -> {rates[-1]:.4f} rad/s",
            flush=True,
        )
    splitting_states = [np.asarray(y) for y in results["blanes_moan4"]["states"]]
    reference_states = [np.asarray(y) for y in results["Dopri8"]["states"]]
    agreement = relative_error(splitting_states, reference_states)
    results["max_relative_difference"] = float(agreement.max())
    results["final_relative_difference"] = float(agreement[-1])
    rates = np.asarray(results["blanes_moan4"]["spin_rate"]), np.asarray(results["Dopri8"]["spin_rate"])
    results["max_spin_rate_relative_difference"] = float(np.max(np.abs(rates[0] - rates[1]) / rates[1]))
    for run in ("blanes_moan4", "Dopri8"):
        del results[run]["states"]
    print(
        f"debris: splitting and Dopri8 differ by at most {results['max_relative_difference']:.1e} "
        f"(state), {results['max_spin_rate_relative_difference']:.1e} (spin rate)",
        flush=True,
    )
    return results


def plot_debris(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(7.5, 4.5))
    days = np.asarray(results["times"]) / DAY
    for name, style in (("blanes_moan4", "-"), ("Dopri8", "--")):
        run = results[name]
        axis.plot(days, run["spin_rate"], style, label=f"{name}: {run['seconds']:.1f} s")
    axis.set(
        xlabel="days",
        ylabel="|Omega| (rad/s)",
        title=f"rocket body spun down by eddy currents\nstate difference at most "
        f"{results['max_relative_difference']:.1e}",
    )
    axis.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=120)


# ----------------------------------------------------------------------------------------- main


def batch_part(repeats, bodies, source):
    """The batch rows alone (``batch_rows``), on JAX's default device (a GPU where there is one), at the
    one-body settings of ``source`` (a torques_basilisk.json); Basilisk's one-body time is quoted from
    ``source``, which says the machine it ran on."""
    recorded = json.loads(Path(source).read_text())
    results = {
        "final_time": recorded["final_time"],
        "target_error": TARGET_ERROR,
        "bodies_in_batch": bodies,
        "source": str(source),
        "source_machine": recorded["machine"],
        "problems": {},
    }
    for name, damped in (("damped", True), ("undamped", False)):
        entry = recorded["problems"][name]
        term = satellite_term(damped)
        rk, splitting, final_state = frbjax_programs(term, recorded["final_time"])
        results["problems"][name] = batch_rows(term, rk, splitting, final_state, entry, damped, False, bodies, repeats)
        print(f"{name}: {results['problems'][name]}", flush=True)
    return results


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="smoke test: small sizes")
    parser.add_argument(
        "--parts",
        nargs="+",
        default=["basilisk", "energy", "debris"],
        choices=["basilisk", "energy", "debris", "batch"],
    )
    parser.add_argument("--batch-bodies", type=int, default=1024, help="the batch part's satellites")
    parser.add_argument("--without-basilisk", action="store_true", help="leave Basilisk's rows out")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--debris-days", type=float, default=YEAR / DAY, help="the debris run's length")
    parser.add_argument("--debris-step", type=float, default=10.0, help="the debris run's splitting step (s)")
    parser.add_argument("--output-dir", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    args.output_dir.mkdir(parents=True, exist_ok=True)
    with_basilisk = not args.without_basilisk and basilisk_available()
    if not args.without_basilisk and not with_basilisk:
        print(
            "Basilisk is not installed: its rows are left out (install it for this script only: "
            ".venv/bin/pip install bsk)",
            flush=True,
        )
    machine = {
        "device": str(jax.devices()[0]),
        "platform": platform.platform(),
        "jax": jax.__version__,
        "diffrax": diffrax.__version__,
        "cpus_visible": len(os.sched_getaffinity(0)),
        "quick": args.quick,
    }
    if with_basilisk:
        from importlib.metadata import version

        machine["basilisk"] = version("bsk")
    if "basilisk" in args.parts:
        results = dict(basilisk_part(args.quick, args.repeats, with_basilisk), machine=machine)
        (args.output_dir / "torques_basilisk.json").write_text(json.dumps(results, indent=1) + "\n")
        plot_basilisk(results, args.output_dir / "torques_basilisk.png")
    if "batch" in args.parts:
        results = dict(
            batch_part(args.repeats, args.batch_bodies, RESULTS / "torques_basilisk.json"),
            machine=dict(machine, backend=jax.default_backend(), device_kind=jax.devices()[0].device_kind),
        )
        (args.output_dir / f"torques_batch_{jax.default_backend()}.json").write_text(
            json.dumps(results, indent=1) + "\n"
        )
    if "energy" in args.parts:
        results = dict(energy_part(args.quick, args.repeats), machine=machine)
        (args.output_dir / "torques_energy.json").write_text(json.dumps(results) + "\n")
        plot_energy(results, args.output_dir / "torques_energy.png")
    if "debris" in args.parts:
        results = dict(debris_part(args.quick, args.debris_days, args.debris_step), machine=machine)
        (args.output_dir / "torques_debris.json").write_text(json.dumps(results) + "\n")
        plot_debris(results, args.output_dir / "torques_debris.png")


if __name__ == "__main__":
    main()
