"""Work-precision benchmark: frbjax against diffrax and a scipy closed form, run time against error.

One batch of bodies (``--bodies`` random triaxial bodies plus a few hard cases: near the separatrix
on both sides, nearly symmetric, nearly spinning about an axis, a large inertia ratio) is solved to
the final times T = 10 and T = 1000, in two cases: "state" (the angular momentum and the attitude at
T, one time per body) and "dense" (``--samples`` equally spaced times T k/samples, k = 1..samples,
per body).  Methods, on the same batch in the same process:

* frbjax ``FreeRigidBody`` in float64 and float32: one jit-compiled function builds the bodies and
  evaluates angular_momentum and quaternion; its time INCLUDES the body construction (per-body
  constants), in both cases;
* diffrax Tsit5, Dopri5 and Dopri8 with a PID step-size controller at rtol = atol = ``--tolerances``,
  on the 7 equations dL/dt = L x Omega, dq/dt = q ⊗ (0, Omega)/2 (Omega = L/I; the state carries
  L/|L(0)| so the absolute tolerance means the same for every |L|; q is renormalised at output),
  vmapped over the batch and jit-compiled once per solver and output shape (the tolerances and T are
  traced arguments), SaveAt(ts=...);
* the numpy/scipy closed form of benchmarks/_scipy_closed_form.py (what a user would write by hand
  on scipy.special.ellipj, elliprf and elliprj), construction included.

equinox's runtime checks are set to EQX_ON_ERROR=nan (unless set otherwise): diffrax's failures are
read from its result codes (throw=False), and a failed body counts as an infinite error.

Times are wall times after compilation (best of ``--repeats``; a run that takes more than 2 s is timed
once), with ``block_until_ready``.  frbjax and diffrax use XLA's CPU thread pool (all cores), numpy /
scipy one core.  A diffrax configuration whose predicted run time (previous tolerance's time times
10^(1/order) times 1.2) exceeds ``--budget`` seconds is not run and is listed as skipped.

Error: per body, the largest over its times of max(|q - q_ref| up to the sign of q, |L - L_ref| / |L|)
(max norm over components); the plotted number is the largest over the whole batch (hard cases
included); the JSON also has the largest and the median over the random bodies alone.

Reference: diffrax Dopri8 in float64 at rtol = atol = 1e-16 (as in tests/_reference.py), with its
steps ending exactly on the output times (no dense interpolation), independent of both closed forms.  Its own
error floor is estimated in three ways, the largest is written next to
every result and drawn in the plot: (1) the largest difference to the same integration at 1e-15 (a
proxy: the two share rounding behaviour); (2) the largest difference to the independent 30-digit
mpmath closed form of benchmarks/stability.py (``Reference``: its own derivation of the attitude,
checked there against mpmath.odefun) on ``--mpmath-bodies`` bodies (half random, half hard), at every
time; (3) at T = 10 only, the largest difference to mpmath's Taylor integrator (``odefun``, 30 digits)
on two bodies.  Errors near that floor are the reference's, not the method's.  Every method's error
against the mpmath closed form on that subsample is reported too (``max_error_vs_mpmath_subsample``,
free of the reference's floor), and so is the agreement of frbjax with the scipy closed form.

Usage: python benchmarks/work_precision.py [--bodies 1000] [--quick] [--output-dir DIR]
Writes work_precision.json and work_precision.png into benchmarks/results/ (or --output-dir).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path


# equinox's runtime checks inside diffrax (not frbjax) become NaN instead of a host callback: failures
# are read from diffrax's result codes (throw=False) anyway, and programs without host callbacks can
# be kept in JAX's persistent compilation cache.
os.environ.setdefault("EQX_ON_ERROR", "nan")

import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import mpmath  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402


HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.append(str(HERE.parent))
from _scipy_closed_form import ScipyFreeRigidBody  # noqa: E402
from stability import Reference as StabilityReference  # noqa: E402  (an independent mpmath closed form)

from frbjax import FreeRigidBody  # noqa: E402


DEFAULT_OUTPUT_DIR = HERE / "results"
TOLERANCES = [10.0**-k for k in range(4, 14)]
SOLVERS = {"Tsit5": (diffrax.Tsit5, 5), "Dopri5": (diffrax.Dopri5, 5), "Dopri8": (diffrax.Dopri8, 8)}
REFERENCE_TOL = 1e-16
CHECK_TOL = 1e-15
MAX_STEPS = 4_000_000
TARGET_ERROR = 1e-12

# --------------------------------------------------------------------------------------------------
# The batch of bodies.


def random_bodies(rng, n):
    """n triaxial bodies: moments log-uniform in [1, 4] (any order), |L| log-uniform in [0.5, 2],
    direction of L and attitude uniform."""
    inertia = 10 ** rng.uniform(0.0, math.log10(4.0), (n, 3))
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    momentum = direction * 10 ** rng.uniform(-0.3, 0.3, (n, 1))
    attitude = rng.normal(size=(n, 4))
    attitude /= np.linalg.norm(attitude, axis=-1, keepdims=True)
    return inertia, momentum, attitude


def _separatrix_momentum(inertia, offset, l2):
    """Unit L with d I2 - 1 = offset for sorted moments (d = sum l_i^2/I_i), l1, l3 > 0."""
    i1, i2, i3 = inertia
    a, b = (i2 - i1) / i1, (i3 - i2) / i3
    rest = 1 - l2 * l2
    return np.array([math.sqrt((rest * b + offset) / (a + b)), l2, math.sqrt((rest * a - offset) / (a + b))])


def hard_bodies(rng, quick=False):
    """(names, inertia, momentum, attitude): well-posed but awkward bodies (conditioning kept >= ~1e-13
    at T = 10 so that 1e-12 stays reachable in float64)."""
    generic = np.array([0.48, -0.62, 0.62])
    cases = [
        ("separatrix +1e-3", (1.0, 2.0, 3.0), _separatrix_momentum((1.0, 2.0, 3.0), 1e-3, 0.3)),
        ("nearly symmetric (I2-I1)/I1=1e-6", (1.0, 1.0 + 1e-6, 2.5), generic),
        ("separatrix -1e-3", (1.0, 2.0, 3.0), _separatrix_momentum((1.0, 2.0, 3.0), -1e-3, -0.5)),
        ("nearly symmetric (I3-I2)/I2=1e-6", (1.0, 2.5, 2.5 * (1 + 1e-6)), generic),
        ("near the major axis (1e-3 off)", (1.5, 2.5, 3.0), np.array([1e-3, 1e-3, 1.0])),
        ("near the minor axis (1e-3 off)", (1.5, 2.5, 3.0), np.array([1.0, -1e-3, 1e-3])),
        ("inertia ratio 100", (1.0, 10.0, 100.0), generic),
        ("nearly spherical (1e-3)", (2.0, 2.002, 2.004), generic),
    ]
    if quick:
        cases = cases[:2]
    names = [c[0] for c in cases]
    inertia = np.array([c[1] for c in cases], float)
    momentum = np.array([c[2] / np.linalg.norm(c[2]) for c in cases])
    attitude = rng.normal(size=(len(cases), 4))
    attitude /= np.linalg.norm(attitude, axis=-1, keepdims=True)
    return names, inertia, momentum, attitude


# --------------------------------------------------------------------------------------------------
# Methods.  Each returns (L, q) with shapes (N, K, 3), (N, K, 4).


def _field(t, y, args):
    inertia, scale = args
    l, q = y[:3], y[3:]
    o = scale * l / inertia
    dl = jnp.cross(l, o)
    qw, qx, qy, qz = q[0], q[1], q[2], q[3]
    dq = 0.5 * jnp.stack(
        [
            -qx * o[0] - qy * o[1] - qz * o[2],
            qw * o[0] + qy * o[2] - qz * o[1],
            qw * o[1] - qx * o[2] + qz * o[0],
            qw * o[2] + qx * o[1] - qy * o[0],
        ]
    )
    return jnp.concatenate([dl, dq])


def diffrax_function(solver_name, step_to_outputs=False):
    """jit(vmap) of one diffrax solve per body; (inertia, momentum, attitude, ts, tol) -> L, q, steps, ok.

    With ``step_to_outputs`` (the reference) the steps end exactly on the output times
    (ClipStepSizeController(step_ts=ts)) instead of interpolating between steps.
    """
    solver = SOLVERS[solver_name][0]()

    def controller(tol, ts):
        pid = diffrax.PIDController(rtol=tol, atol=tol)
        return diffrax.ClipStepSizeController(pid, step_ts=ts) if step_to_outputs else pid

    def run(inertia, momentum, attitude, ts, tol):
        def one(inertia, momentum, attitude):
            scale = jnp.linalg.norm(momentum)
            y0 = jnp.concatenate([momentum / scale, attitude])
            solution = diffrax.diffeqsolve(
                diffrax.ODETerm(_field),
                solver,
                t0=jnp.zeros_like(ts[-1]),
                t1=ts[-1],
                dt0=None,
                y0=y0,
                args=(inertia, scale),
                saveat=diffrax.SaveAt(ts=ts),
                stepsize_controller=controller(tol, ts),
                max_steps=MAX_STEPS,
                throw=False,
            )
            ys = solution.ys
            q = ys[:, 3:] / jnp.linalg.norm(ys[:, 3:], axis=-1, keepdims=True)
            ok = solution.result == diffrax.RESULTS.successful
            return scale * ys[:, :3], q, solution.stats["num_steps"], ok

        return jax.vmap(one)(inertia, momentum, attitude)

    return jax.jit(run)


def frbjax_function():
    """jit of: build the bodies, evaluate L and q at ts (K,) for every body -> (K, N, 3), (K, N, 4)."""

    def run(inertia, momentum, attitude, ts):
        body = FreeRigidBody(inertia, momentum, attitude)
        t = ts[:, None]
        return body.angular_momentum(t), body.quaternion(t)

    return jax.jit(run)


def scipy_method(inertia, momentum, attitude, ts):
    body = ScipyFreeRigidBody(inertia, momentum, attitude)
    t = ts[:, None]
    return body.angular_momentum(t), body.quaternion(t)


def timed(call, repeats):
    """(best wall time, output) of call(); a run longer than 2 s is not repeated."""
    start = time.perf_counter()
    out = jax.block_until_ready(call())
    best = time.perf_counter() - start
    if best < 2.0:
        for _ in range(repeats):
            start = time.perf_counter()
            out = jax.block_until_ready(call())
            best = min(best, time.perf_counter() - start)
    return best, out


# --------------------------------------------------------------------------------------------------
# mpmath check of the reference.


def mpmath_solution(inertia, momentum, attitude, times, dps=30):
    """(L, q) at increasing positive times from mpmath.odefun (Taylor series) at dps digits."""
    with mpmath.workdps(dps):
        i1, i2, i3 = (mpmath.mpf(float(x)) for x in inertia)

        def field(t, y):
            l1, l2, l3, qw, qx, qy, qz = y
            o1, o2, o3 = l1 / i1, l2 / i2, l3 / i3
            return [
                l2 * o3 - l3 * o2,
                l3 * o1 - l1 * o3,
                l1 * o2 - l2 * o1,
                (-qx * o1 - qy * o2 - qz * o3) / 2,
                (qw * o1 + qy * o3 - qz * o2) / 2,
                (qw * o2 - qx * o3 + qz * o1) / 2,
                (qw * o3 + qx * o2 - qy * o1) / 2,
            ]

        q0 = [mpmath.mpf(float(x)) for x in attitude]
        norm = mpmath.sqrt(sum(x * x for x in q0))
        y0 = [mpmath.mpf(float(x)) for x in momentum] + [x / norm for x in q0]
        solution = mpmath.odefun(field, 0, y0)
        rows = [[float(v) for v in solution(mpmath.mpf(float(t)))] for t in times]
    rows = np.array(rows)
    return rows[:, :3], rows[:, 3:]


# --------------------------------------------------------------------------------------------------
# Errors.


def body_errors(L, q, L_ref, q_ref, norms):
    """Per-body largest error over the times: (total, quaternion, angular momentum), each (N,)."""
    q_err = np.minimum(np.abs(q - q_ref).max(-1), np.abs(q + q_ref).max(-1)).max(-1)
    L_err = (np.abs(L - L_ref).max(-1) / norms[:, None]).max(-1)
    total = np.maximum(q_err, L_err)
    total = np.where(np.isfinite(total), total, np.inf)
    return total, q_err, L_err


def summarize(errors, n_random):
    total, q_err, L_err = errors
    return {
        "max_error": float(np.max(total)),
        "max_error_quaternion": float(np.max(q_err)),
        "max_error_angular_momentum": float(np.max(L_err)),
        "max_error_random_bodies": float(np.max(total[:n_random])),
        "median_error_random_bodies": float(np.median(total[:n_random])),
        "worst_body": int(np.argmax(total)),
    }


def _fmt(x):
    return "   -    " if x is None else f"{x:8.2e}"


# --------------------------------------------------------------------------------------------------


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bodies", type=int, default=1000, help="random triaxial bodies (plus the hard cases)")
    parser.add_argument("--samples", type=int, default=100, help="dense samples per body")
    parser.add_argument("--final-times", type=float, nargs="+", default=[10.0, 1000.0])
    parser.add_argument("--tolerances", type=float, nargs="+", default=TOLERANCES)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--budget", type=float, default=60.0, help="largest predicted seconds of one diffrax run")
    parser.add_argument(
        "--mpmath-bodies",
        type=int,
        default=6,
        help="bodies (half random, half hard) checked against the mpmath closed form",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--quick",
        action="store_true",
        help="smoke run: 6 + 2 bodies, 1 sample (dense = state: one compiled program per "
        "method), tolerances 1e-4 and 1e-8, 1 mpmath body at 20 digits; compile times may come "
        "from the persistent compilation cache (JAX_COMPILATION_CACHE_DIR) if one is set",
    )
    parser.add_argument("--output-dir", type=Path, default=DEFAULT_OUTPUT_DIR)
    parser.add_argument("--note", default="", help="free text stored in the JSON (e.g. which frbjax was measured)")
    parser.add_argument("--no-plot", action="store_true")
    options = parser.parse_args(argv)
    if not options.quick:
        # Compile times are reported: never load them from a persistent cache.
        jax.config.update("jax_enable_compilation_cache", False)
    mp_dps = 30
    if options.quick:
        options.bodies, options.samples, options.repeats = 6, 1, 1
        options.tolerances = [1e-4, 1e-8]
        options.mpmath_bodies, mp_dps = 1, 20

    rng = np.random.default_rng(options.seed)
    random_set = random_bodies(rng, options.bodies)
    hard_names, *hard_set = hard_bodies(rng, options.quick)
    inertia, momentum, attitude = (np.concatenate([a, b]) for a, b in zip(random_set, hard_set))
    n_random, n = options.bodies, len(inertia)
    norms = np.linalg.norm(momentum, axis=-1)
    device_args = [jnp.asarray(a) for a in (inertia, momentum, attitude)]
    device_args32 = [jnp.asarray(a, jnp.float32) for a in (inertia, momentum, attitude)]
    print(
        f"work-precision: {n_random} random + {len(hard_names)} hard bodies, T = {options.final_times}, "
        f"{options.samples} dense samples, device {jax.devices()[0]}, {os.cpu_count()} cores",
        flush=True,
    )

    compile_s = {}

    def compiled(key, fn, *args):
        if key not in compile_s:
            start = time.perf_counter()
            compile_s[key] = (fn.lower(*args).compile(), time.perf_counter() - start)
            print(f"  compiled {key} in {compile_s[key][1]:.1f} s", flush=True)
        return compile_s[key][0]

    frbjax_fn = frbjax_function()
    diffrax_fns = {name: diffrax_function(name) for name in SOLVERS}
    reference_fn = diffrax_function("Dopri8", step_to_outputs=True)

    cases = []
    mp_cache, mp_closed, reference_cache = {}, {}, {}
    n_hard = len(hard_names)
    hard_picks = min(n_hard, -(-options.mpmath_bodies // 2))
    mp_picks = list(range(min(options.mpmath_bodies - hard_picks, n_random))) + list(
        range(n_random, n_random + hard_picks)
    )
    odefun_picks = mp_picks[:1] if options.quick else [0, n_random]
    for final_time in options.final_times:
        for kind in ("state", "dense"):
            samples = 1 if kind == "state" else options.samples
            ts = final_time * np.arange(1, samples + 1) / samples
            ts_dev = jnp.asarray(ts)
            shape_key = f"K={samples}"
            print(f"\nT = {final_time:g}, {kind} ({samples} time(s) per body)", flush=True)

            # Reference and its check run.
            dop8 = compiled(("reference Dopri8", shape_key), reference_fn, *device_args, ts_dev, 1e-8)
            if tuple(ts) not in reference_cache:  # (--quick: state and dense have the same times)
                start = time.perf_counter()
                L_ref, q_ref, steps_ref, ok = (np.asarray(a) for a in dop8(*device_args, ts_dev, REFERENCE_TOL))
                reference_s = time.perf_counter() - start
                if not ok.all():
                    raise RuntimeError(f"reference failed for bodies {np.flatnonzero(~ok)}")
                L_chk, q_chk, _, _ = (np.asarray(a) for a in dop8(*device_args, ts_dev, CHECK_TOL))
                floor = body_errors(L_chk, q_chk, L_ref, q_ref, norms)[0]
                reference_cache[tuple(ts)] = L_ref, q_ref, steps_ref, reference_s, floor
            L_ref, q_ref, steps_ref, reference_s, floor = reference_cache[tuple(ts)]
            reference = {
                "method": f"diffrax Dopri8 float64 rtol=atol={REFERENCE_TOL:g}, steps ending on the output times",
                "time_s": reference_s,
                "max_steps_per_body": int(steps_ref.max()),
                "floor_estimate_vs_tol_1e-15": float(floor.max()),
            }
            # The reference against mpmath on a subsample: the independent 30-digit closed form of
            # benchmarks/stability.py at every time, and mpmath.odefun (Taylor series) at T <= 10.
            start = time.perf_counter()
            for b in mp_picks:
                key = (b, tuple(ts))
                if key not in mp_closed:
                    exact = StabilityReference(inertia[b], momentum[b], attitude[b], dps=30)
                    values = [exact.at(t) for t in ts]
                    mp_closed[key] = (
                        np.array([[float(x) for x in v[0]] for v in values]),
                        np.array([[float(x) for x in v[1]] for v in values]),
                    )
            L_mp = np.stack([mp_closed[(b, tuple(ts))][0] for b in mp_picks])
            q_mp = np.stack([mp_closed[(b, tuple(ts))][1] for b in mp_picks])
            reference["floor_vs_mpmath_closed_form"] = float(
                body_errors(L_ref[mp_picks], q_ref[mp_picks], L_mp, q_mp, norms[mp_picks])[0].max()
            )
            reference["mpmath_closed_form"] = (
                f"benchmarks/stability.py Reference at 30 digits on bodies {mp_picks} "
                f"({time.perf_counter() - start:.0f} s)"
            )
            if final_time <= 10 and odefun_picks:
                worst = 0.0
                start = time.perf_counter()
                for b in odefun_picks:
                    key = (b, tuple(ts))
                    if key not in mp_cache:
                        mp_cache[key] = mpmath_solution(inertia[b], momentum[b], attitude[b], ts, dps=mp_dps)
                    L_o, q_o = mp_cache[key]
                    e = body_errors(L_ref[b : b + 1], q_ref[b : b + 1], L_o[None], q_o[None], norms[b : b + 1])[0]
                    worst = max(worst, float(e.max()))
                reference["floor_vs_mpmath_odefun"] = worst
                reference["mpmath_odefun"] = (
                    f"odefun at {mp_dps} digits on bodies {odefun_picks} ({time.perf_counter() - start:.0f} s)"
                )
            floor_value = max(
                reference[k]
                for k in ("floor_estimate_vs_tol_1e-15", "floor_vs_mpmath_closed_form", "floor_vs_mpmath_odefun")
                if k in reference
            )
            reference["floor"] = floor_value
            print(
                f"  reference: {reference['method']}, {reference_s:.1f} s, estimated error floor {floor_value:.1e} "
                f"(vs 1e-15: {reference['floor_estimate_vs_tol_1e-15']:.1e}, vs mpmath closed form "
                f"{reference['floor_vs_mpmath_closed_form']:.1e}"
                + (
                    f", vs mpmath odefun: {reference['floor_vs_mpmath_odefun']:.1e})"
                    if "floor_vs_mpmath_odefun" in reference
                    else ")"
                ),
                flush=True,
            )

            rows = []
            print(
                f"  {'method':<22} {'tol':>8} {'time s':>9} {'max err':>9} {'rand max':>9} {'rand med':>9} "
                f"{'vs mpmath':>9}"
            )

            def record(row, L, q):
                row.update(summarize(body_errors(L, q, L_ref, q_ref, norms), n_random))
                row["max_error_vs_mpmath_subsample"] = float(
                    body_errors(L[mp_picks], q[mp_picks], L_mp, q_mp, norms[mp_picks])[0].max()
                )
                rows.append(row)
                print(
                    f"  {row['method']:<22} {_fmt(row.get('tol'))} {row['time_s']:9.3g} {row['max_error']:9.2e} "
                    f"{row['max_error_random_bodies']:9.2e} {row['median_error_random_bodies']:9.2e} "
                    f"{row['max_error_vs_mpmath_subsample']:9.2e}",
                    flush=True,
                )
                return row

            # frbjax (construction included).
            for label, args, dtype in (
                ("frbjax float64", device_args, jnp.float64),
                ("frbjax float32", device_args32, jnp.float32),
            ):
                ts_typed = jnp.asarray(ts, dtype)
                fn = compiled((label, shape_key), frbjax_fn, *args, ts_typed)
                seconds, (L, q) = timed(lambda: fn(*args, ts_typed), options.repeats)
                L, q = (np.swapaxes(np.asarray(a, np.float64), 0, 1) for a in (L, q))
                record({"method": label, "time_s": seconds, "includes_construction": True}, L, q)
                if dtype == jnp.float64:
                    L_f, q_f = L, q
            frbjax64 = rows[0]

            # scipy closed form (construction included).
            seconds, (L, q) = timed(lambda: scipy_method(inertia, momentum, attitude, ts), options.repeats)
            L, q = (np.swapaxes(a, 0, 1) for a in (L, q))
            record({"method": "scipy closed form", "time_s": seconds, "includes_construction": True}, L, q)
            agreement = body_errors(L_f, q_f, L, q, norms)[0]

            # diffrax.
            for name, (_, order) in SOLVERS.items():
                fn = compiled((name, shape_key), diffrax_fns[name], *device_args, ts_dev, 1e-8)
                previous = None
                for tol in options.tolerances:
                    # Steps grow like tol^(-1/order); 1.2 for the step-size controller's overhead.
                    predicted = None if previous is None else previous * 10 ** (1 / order) * 1.2
                    if predicted is not None and predicted > options.budget:
                        rows.append(
                            {"method": f"diffrax {name}", "tol": tol, "skipped": True, "predicted_time_s": predicted}
                        )
                        print(
                            f"  {'diffrax ' + name:<22} {_fmt(tol)} skipped (predicted {predicted:.0f} s "
                            f"> budget {options.budget:g} s)"
                        )
                        continue
                    tol_dev = jnp.asarray(tol)
                    seconds, (L, q, steps, ok) = timed(lambda: fn(*device_args, ts_dev, tol_dev), options.repeats)
                    previous = seconds
                    ok = np.asarray(ok)
                    L, q = np.array(L), np.array(q)
                    L[~ok], q[~ok] = np.nan, np.nan
                    record(
                        {
                            "method": f"diffrax {name}",
                            "tol": tol,
                            "time_s": seconds,
                            "max_steps_per_body": int(np.max(steps)),
                            "failed_bodies": int((~ok).sum()),
                        },
                        L,
                        q,
                    )

            # Key comparisons.
            reached = [
                r
                for r in rows
                if r["method"].startswith("diffrax") and not r.get("skipped") and r["max_error"] <= TARGET_ERROR
            ]
            fastest = min(reached, key=lambda r: r["time_s"]) if reached else None
            scipy_row = next(r for r in rows if r["method"] == "scipy closed form")
            case = {
                "T": final_time,
                "kind": kind,
                "samples_per_body": samples,
                "evaluations": n * samples,
                "reference": reference,
                "frbjax_vs_scipy_closed_form_max_difference": float(agreement.max()),
                "methods": rows,
                "fastest_diffrax_reaching_1e-12": None
                if fastest is None
                else {
                    "method": fastest["method"],
                    "tol": fastest["tol"],
                    "time_s": fastest["time_s"],
                    "max_error": fastest["max_error"],
                },
                "ratio_fastest_diffrax_1e-12_over_frbjax64": None
                if fastest is None
                else fastest["time_s"] / frbjax64["time_s"],
                "ratio_scipy_over_frbjax64": scipy_row["time_s"] / frbjax64["time_s"],
            }
            cases.append(case)
            print(
                "  frbjax float64 vs scipy closed form: max difference "
                f"{case['frbjax_vs_scipy_closed_form_max_difference']:.1e}; "
                f"scipy / frbjax time {case['ratio_scipy_over_frbjax64']:.2f}"
            )
            if fastest is None:
                print("  no diffrax configuration reached error <= 1e-12")
            else:
                print(
                    f"  fastest diffrax <= 1e-12: {fastest['method']} tol {fastest['tol']:g}, "
                    f"{fastest['time_s']:.3g} s "
                    f"= {case['ratio_fastest_diffrax_1e-12_over_frbjax64']:.0f} x frbjax float64"
                )

    def find(T, kind):
        return next((c for c in cases if c["T"] == T and c["kind"] == kind), None)

    key_state, key_dense = find(10.0, "state"), find(10.0, "dense")
    summary = {
        "diffrax_over_frbjax64_T10_state_error_1e-12": None
        if key_state is None
        else key_state["ratio_fastest_diffrax_1e-12_over_frbjax64"],
        "fastest_diffrax_T10_state_error_1e-12": None
        if key_state is None
        else key_state["fastest_diffrax_reaching_1e-12"],
        "frbjax64_T10_state_max_error": None if key_state is None else key_state["methods"][0]["max_error"],
        "scipy_over_frbjax64_per_dense_sample_T10": None
        if key_dense is None
        else key_dense["ratio_scipy_over_frbjax64"],
        "frbjax64_ns_per_dense_sample_T10": None
        if key_dense is None
        else key_dense["methods"][0]["time_s"] / key_dense["evaluations"] * 1e9,
        "scipy_ns_per_dense_sample_T10": None
        if key_dense is None
        else key_dense["methods"][2]["time_s"] / key_dense["evaluations"] * 1e9,
        "note": "dense-sample times include body construction (amortised over the samples) and both L and q; "
        "frbjax on all cores (XLA thread pool), scipy on one; benchmarks/throughput.py measures "
        "quaternion-only evaluation on one core.",
    }
    print("\nKey ratios")
    if key_state is not None:
        r = summary["diffrax_over_frbjax64_T10_state_error_1e-12"]
        f = summary["fastest_diffrax_T10_state_error_1e-12"]
        print(
            f"  T = 10 state: frbjax float64 (construction included) max error "
            f"{summary['frbjax64_T10_state_max_error']:.1e}; fastest diffrax reaching 1e-12: "
            + (
                "none"
                if f is None
                else f"{f['method']} tol {f['tol']:g}, {f['time_s']:.3g} s -> {r:.0f} x slower than frbjax"
            )
        )
    if key_dense is not None:
        print(
            f"  T = 10 dense, per (body, sample) evaluation of L and q: frbjax float64 "
            f"{summary['frbjax64_ns_per_dense_sample_T10']:.0f} ns, scipy closed form "
            f"{summary['scipy_ns_per_dense_sample_T10']:.0f} ns -> scipy / frbjax = "
            f"{summary['scipy_over_frbjax64_per_dense_sample_T10']:.2f}"
        )

    result = {
        "description": "run time against max error; see the docstring of benchmarks/work_precision.py",
        "bodies": {
            "random": n_random,
            "hard": hard_names,
            "hard_indices_start": n_random,
            "random_distribution": "moments log-uniform [1, 4] any order, |L| log-uniform [0.5, 2], "
            "direction and attitude uniform",
            "seed": options.seed,
        },
        "error_definition": "per body max over times of max(|q - q_ref|_inf up to sign, |L - L_ref|_inf / |L|); "
        "max_error = max over all bodies",
        "reference": f"diffrax Dopri8 float64 rtol=atol={REFERENCE_TOL:g} stepping onto the output times; "
        "its error floor estimated per case "
        f"as the largest of: the difference to rtol=atol={CHECK_TOL:g}, the error against the 30-digit "
        f"mpmath closed form of benchmarks/stability.py on bodies {mp_picks}, and (T <= 10) against "
        f"mpmath.odefun on bodies {odefun_picks}",
        "max_error_vs_mpmath_subsample": "per method: the error against the mpmath closed form on the same subsample "
        "(free of the diffrax reference's floor)",
        "timing": "wall time after compilation, best of repeats (runs > 2 s timed once), block_until_ready; "
        "frbjax and diffrax: XLA CPU (all cores); numpy/scipy: one core",
        "compile_s": {f"{k[0]} {k[1]}": v[1] for k, v in compile_s.items()},
        "cases": cases,
        "summary": summary,
        "quick": options.quick,
        "compilation_cache": _cache_state(),
        "frbjax": _provenance(),
        "note": options.note,
        "device": str(jax.devices()[0]),
        "cpu_count": os.cpu_count(),
        "jax": jax.__version__,
        "diffrax": diffrax.__version__,
        "scipy": scipy.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
    }
    options.output_dir.mkdir(parents=True, exist_ok=True)
    json_path = options.output_dir / "work_precision.json"
    json_path.write_text(json.dumps(result, indent=2, default=float) + "\n")
    print(f"wrote {json_path}")
    if not options.no_plot:
        png = options.output_dir / "work_precision.png"
        plot(result, png)
        print(f"wrote {png}")
    return result


def _cache_state():
    enabled = jax.config.jax_enable_compilation_cache and jax.config.jax_compilation_cache_dir
    return f"persistent cache {jax.config.jax_compilation_cache_dir}" if enabled else "off"


def _provenance():
    """Where frbjax was imported from, and the git commit of this checkout (and whether frbjax/ is modified)."""
    import subprocess

    import frbjax

    path = Path(frbjax.__file__).resolve().parent
    info = {"path": str(path)}
    if path != HERE.parent / "frbjax":
        return info  # not this checkout's frbjax: its git state says nothing (see --note)
    try:
        root = HERE.parent
        info["git_head"] = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
        info["frbjax_modified_in_checkout"] = bool(
            subprocess.run(
                ["git", "-C", str(root), "status", "--porcelain", "frbjax"], capture_output=True, text=True, check=True
            ).stdout.strip()
        )
    except (OSError, subprocess.CalledProcessError):
        pass
    return info


def plot(result, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = result["cases"]
    columns = 2
    rows = -(-len(cases) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(6.2 * columns, 4.6 * rows), squeeze=False)
    styles = {
        "diffrax Tsit5": ("tab:blue", "o-"),
        "diffrax Dopri5": ("tab:orange", "s-"),
        "diffrax Dopri8": ("tab:green", "^-"),
    }
    singles = {
        "frbjax float64": ("tab:red", "*", 16),
        "frbjax float32": ("tab:pink", "*", 13),
        "scipy closed form": ("k", "D", 8),
    }
    for ax, case in zip(axes.flat, cases):
        floor = max(case["reference"]["floor"], 1e-17)
        for method, (color, style) in styles.items():
            pts = [r for r in case["methods"] if r["method"] == method and not r.get("skipped")]
            if pts:
                ax.plot(
                    [r["time_s"] for r in pts],
                    [max(r["max_error"], 1e-17) for r in pts],
                    style,
                    color=color,
                    label=f"{method} (tol {pts[0]['tol']:.0e}..{pts[-1]['tol']:.0e})",
                    ms=4,
                )
        for method, (color, marker, size) in singles.items():
            r = next(r for r in case["methods"] if r["method"] == method)
            ax.plot(
                [r["time_s"]],
                [max(r["max_error"], 1e-17)],
                marker,
                color=color,
                ms=size,
                ls="none",
                label=method + (" (incl. construction)" if r.get("includes_construction") else ""),
            )
        ax.axhline(floor, color="gray", ls="--", lw=1, label=f"reference error floor est. {floor:.0e}")
        ax.axhline(TARGET_ERROR, color="gray", ls=":", lw=1, label="1e-12")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time [s] (after compilation)")
        ax.set_ylabel("max error (q up to sign, L/|L|)")
        what = "state at T" if case["kind"] == "state" else f"{case['samples_per_body']} samples per body"
        ax.set_title(f"T = {case['T']:g}, {what}", fontsize=10)
        ax.grid(True, which="major", alpha=0.3)
    for ax in list(axes.flat)[len(cases) :]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7, loc="best")
    b = result["bodies"]
    fig.suptitle(
        f"Work-precision, {b['random']} random + {len(b['hard'])} hard bodies; reference: "
        f"{result['reference'].split(';')[0]}",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
