"""A few points of each sweep of benchmarks/stability.py: error within 10x the conditioning floor.

For each case the 60-digit reference of benchmarks/stability.py (an independent mpmath closed form,
checked against mpmath.odefun in ``test_reference_against_odefun``) gives the error of frbjax, and the
same reference at 3 copies of the inputs moved by one ulp (every scalar: moments, L, attitude, time)
gives the conditioning floor.  The assertion is the accuracy target, error <= 10 max(floor, eps), with
eps = 2.2e-16 standing in for "a few ulp" where the floor is below one ulp of 1.
"""

from __future__ import annotations

import functools
import importlib.util
import math
from pathlib import Path

import numpy as np


STABILITY = Path(__file__).resolve().parent.parent / "benchmarks" / "stability.py"
EPS = float(np.finfo(np.float64).eps)
# Measured on these points (3 perturbations, jit, float64): worst error / max(floor, eps) per sweep
# separatrix 1.14 (L, d I2 - 1 = 1e-12), gaps 1.44 (L, one-ulp gap (I3-I2)/I2), time 0.90, ratios 2.19
# (q, I = (1, 1e3, 1e6) at |L| t = -100), momentum 0.72; saddle 22.4 (see SADDLE_FACTOR).  The bound
# is the accuracy target, 10.
FACTOR = 10.0


def _load():
    spec = importlib.util.spec_from_file_location("frbjax_benchmark_stability", STABILITY)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


stability = _load()


def _cases():
    """A few points of each sweep of the benchmark, 2 times each."""
    rng = np.random.default_rng(7)
    cases = []

    def add(sweep, label, inertia, momentum, taus):
        momentum = np.asarray(momentum, np.float64)
        norm = float(np.linalg.norm(momentum))
        cases.append(
            dict(
                sweep=sweep,
                label=label,
                inertia=np.array(inertia, np.float64),
                momentum=momentum,
                attitude=stability._unit(rng.normal(size=4)),
                times=np.array([tau / norm for tau in taus]),
            )
        )

    taus = (3.0, -300.0)
    for exponent in (4, 12, 16):
        for side in (1, -1):
            momentum = stability.near_separatrix(
                (1.0, 2.0, 3.0), side * 10.0**-exponent, 0.3, tuple(rng.choice([-1, 1], 3))
            )
            add("separatrix", f"d I2 - 1 = {side * 10.0**-exponent:g}", (1.0, 2.0, 3.0), momentum, taus)
    add("separatrix", "d I2 - 1 = 0", (1.0, 1.5, 3.0), (1.0, 0.3, 1.0), taus)
    for exponent in (8, 13, 15):
        for direction in ((0.6, 0.0, 0.8), (0.3, 0.0, 0.95)):
            momentum = rng.choice([-1.0, 1.0], 3) * (
                np.array([0.0, 1.0, 0.0]) + 10.0**-exponent * stability._unit(direction)
            )
            add(
                "saddle",
                f"L at 1e-{exponent} from the middle axis, direction {direction}",
                (1.0, 2.0, 3.0),
                momentum,
                (0.1, -1.0),
            )
    for label, inertia in (
        ("(I2-I1)/I1 = 1e-8", (1.0, 1 + 1e-8, 3.0)),
        ("(I2-I1)/I1 = 1 ulp", (1 - 2.0**-53, 1.0, 3.0)),
        ("(I3-I2)/I2 = 1 ulp", (1.0, 2 - 2.0**-52, 2.0)),
    ):
        add("gaps", label + ", generic L", inertia, stability._unit(stability.GENERIC), taus)
        close = (0.6, 0.79, 0.12) if "I2-I1" in label else (0.12, 0.6, 0.79)
        add("gaps", label + ", L near the close pair", inertia, stability._unit(close), taus)
    add("time", "generic, |L| t to 1e6", (1.0, 2.0, 3.0), stability._unit((0.3, 0.2, 0.93)), (1e3, 1e6))
    add("time", "around I1, |L| t to 1e6", (1.0, 2.0, 3.0), stability._unit((0.93, 0.2, 0.3)), (-1e4, 1e6))
    for r in (1e3, 1e6):
        add(
            "ratios",
            f"I = (1, sqrt r, r), r = {r:g}",
            (1.0, math.sqrt(r), r),
            stability._unit(stability.GENERIC),
            (1.0, -100.0),
        )
        add("ratios", f"I = (1, 2, r), r = {r:g}", (1.0, 2.0, r), stability._unit(stability.GENERIC), (1.0, -100.0))
    for scale in (1e-6, 1e6):
        add("momentum", f"|L| = {scale:g}", (1.0, 2.0, 3.0), scale * stability._unit(stability.GENERIC), (1.0, -100.0))
    return cases


CASES = _cases()
SWEEPS = ("separatrix", "saddle", "gaps", "time", "ratios", "momentum")
# Next to the middle axis (the saddle) frbjax misses the target: its error there is an error of the
# angle about L of ~K(m) eps (the phase terms are ~K ~ 30 in size and their rounding does not cancel),
# while the floor stays at ~1 ulp.  Measured on these points: worst 22.4 (q, 1e-15 from the axis, |L| t
# = 0.1; benchmark: see stability.json);
# this bound guards against regressions of that gap.
SADDLE_FACTOR = 60.0


@functools.cache
def frbjax_values():
    """frbjax's (L, q) at every case's times, (N, K, 3) and (N, K, 4), once per test process: one batch
    of N bodies at times (K, N), jit-compiled as a user would run it (~35 s of compilation)."""
    import jax

    from frbjax import FreeRigidBody

    @jax.jit
    def evaluate(inertia, momentum, attitude, times):
        body = FreeRigidBody(inertia, momentum, attitude)
        return body.angular_momentum(times), body.quaternion(times)

    stack = lambda key: np.stack([c[key] for c in CASES])  # noqa: E731
    L, q = evaluate(stack("inertia"), stack("momentum"), stack("attitude"), stack("times").T)
    return np.swapaxes(np.asarray(L), 0, 1), np.swapaxes(np.asarray(q), 0, 1)


def measured(sweep):
    """Errors and conditioning floor (3 perturbations) of the cases of one sweep, with their labels."""
    L, q = frbjax_values()
    out = []
    for i, c in enumerate(CASES):
        if c["sweep"] == sweep:
            signs = stability.perturbations(3, i)
            m = stability.measure(c["inertia"], c["momentum"], c["attitude"], c["times"], L[i], q[i], signs)
            out.append((c, m))
    return out


def test_error_within_conditioning():
    """Every sweep in one test: the frbjax values come from one jit compilation (~35 s cold), which a
    test per sweep would repeat in each pytest-xdist worker."""
    failures, worst = [], {}
    for sweep in SWEEPS:
        factor = SADDLE_FACTOR if sweep == "saddle" else FACTOR
        for c, m in measured(sweep):
            for k, t in enumerate(c["times"]):
                for quantity in ("L", "q"):
                    error, floor = m[f"error_{quantity}"][k], m[f"floor_{quantity}"][k]
                    ratio = error / max(floor, EPS)
                    worst[sweep] = max(worst.get(sweep, 0.0), ratio)
                    if not ratio <= factor:
                        failures.append(
                            f"{sweep}: {c['label']}, t = {t:g}: {quantity} error {error:.2e}, floor {floor:.2e}"
                        )
    assert not failures, "\n".join(failures)
    assert set(worst) == set(SWEEPS) and all(value > 0 for value in worst.values())


def test_reference_against_odefun():
    """The benchmark's closed-form reference agrees with a 30-digit Taylor integration (mpmath.odefun).

    Moments unsorted (an odd permutation), around the minor axis, |L| != 1, past one half period of the
    phase (so the period reduction of the reference is used).  Measured: 2e-29; ~4 s.
    """
    inertia, momentum, attitude = (1.1, 4.0, 1.0), (0.3, -0.35, 1.7), stability._unit((0.3, -0.5, 0.2, 0.7))
    body = stability.Reference(inertia, momentum, attitude)
    assert body.regime == "minor"
    t = 2.5
    assert round((body.u0 + body.rate * body.norm * t) / (2 * body.K)) >= 1  # u reduced by 2K at least once
    result = stability.check_reference(inertia, momentum, attitude, (t,))
    assert result["difference_L"] < 1e-26 and result["difference_q"] < 1e-26, result
