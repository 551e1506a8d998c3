"""Regenerate tests/data/hessian_references.json: 30-digit second derivatives of the motion.

    .venv/bin/python tests/data/make_hessian_references.py [--processes 1]    # ~15 min on one core

For each point x = (I (3), L (3), t) (attitude q0 fixed, ``make_gradient_references.ATTITUDE``) the
file holds the outputs y = (L(t) (3), q(t) (4)) and their Hessians d^2 y / dx dx (7 x 7 x 7), from
mpmath.odefun's Taylor-series solution of dL/dt = L x (L / I), dq/dt = 1/2 q ⊗ (0, L / I) at DPS digits
(tests/_reference.py ``mp_field``):

* in I and L: second central differences with step h = STEP, of solutions started from the exact
  binary values of the float64 inputs plus or minus h (exactly, in mpmath).  Truncation h^2 y''''/12
  ~ 1e-13 relative, solver error 10^-DPS / h^2 ~ 1e-20: good to ~1e-12, far below the test's 1e-9;
* in t: dy/dt is the right-hand side f(y) of the equations, so d^2 y/dt dx_j is the central
  difference of f(y) and d^2 y/dt^2 the second difference of y in t along the same solution.

The symmetric body next to the plane of its equal moments ("I1=I2 near plane 1e-02"), where frbjax's
elliptic parameter moves as dI / (e . n)^2, takes h = FINE_STEP at FINE_DPS digits: its second
differences are then exact far below the test's tolerance (truncation h^2 y''''/12 ~ 1e-32, solver
error 10^-FINE_DPS / h^2 ~ 1e-18) with no assumption on how fast the motion bends there.
``--only NAME ...`` recomputes the named points and keeps the others of the existing file.

Nothing here uses a formula of frbjax.
"""

from __future__ import annotations

import os
import sys

import mpmath


HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)

import _reference as ref  # noqa: E402
from make_gradient_references import _point, ATTITUDE, text, timed, write_references  # noqa: E402


DPS = 32
STEP = "1e-6"
FINE_DPS = 50
FINE_STEP = "1e-16"
OUTPUT = os.path.join(HERE, "hessian_references.json")


def points():
    """(name, x) of every point: x = (I, L, t)."""
    chosen = [
        ("major", _point([1.0, 2.0, 3.0], [0.9, 0.3, 0.2], t=1.3)),
        ("minor unsorted", _point([2.5, 0.7, 1.4], [-0.4, 0.7, 0.5], t=0.9)),
        (
            "separatrix -1e-03",
            _point([1.0, 2.0, 3.0], ref.separatrix_momentum((1.0, 2.0, 3.0), -1e-3, -0.5, (-1, 1, 1)), t=1.1),
        ),
        ("I1=I2 near plane 1e-02", _point([1.2, 1.2, 2.1], [0.6, 0.8, 1e-2], t=1.7)),
    ]
    return [(name, x[:6] + x[10:]) for name, x in chosen]


def _field(inertia):
    return ref.mp_field(inertia)


def _solution(inertia, momentum, q0):
    """t -> (L(t), q(t)) as one mpmath.odefun solution of both time directions."""
    field = _field(inertia)
    forward = mpmath.odefun(field, 0, list(momentum) + list(q0))
    backward = mpmath.odefun(lambda s, y: [-v for v in field(-s, y)], 0, list(momentum) + list(q0))
    return lambda t: forward(t) if t >= 0 else backward(-t)


def reference(x, dps=DPS, step=STEP):
    """(values (7,), Hessian (7, 7, 7)) as mpf at x = (I, L, t)."""
    with mpmath.workdps(dps):
        x = [mpmath.mpf(v) for v in x]
        h = mpmath.mpf(step)
        q0 = [mpmath.mpf(v) for v in ATTITUDE]
        norm = mpmath.sqrt(sum(v * v for v in q0))
        q0 = [v / norm for v in q0]
        t = x[6]

        def state(shifts):
            y = list(x[:6])
            for j, s in shifts:
                y[j] += s * h
            return y

        def at(shifts, time=t):
            y = state(shifts)
            return _solution(y[:3], y[3:6], q0)(time)

        def rate(shifts):
            y = state(shifts)
            return _field(y[:3])(t, at(shifts))

        center = at(())
        hessian = [[[mpmath.mpf(0)] * 7 for _ in range(7)] for _ in range(7)]
        plus = [at(((j, 1),)) for j in range(6)]
        minus = [at(((j, -1),)) for j in range(6)]
        for j in range(6):
            for k in range(7):
                hessian[k][j][j] = (plus[j][k] - 2 * center[k] + minus[j][k]) / (h * h)
            for i in range(j):
                corners = [at(((i, si), (j, sj))) for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1))]
                for k in range(7):
                    value = (corners[0][k] - corners[1][k] - corners[2][k] + corners[3][k]) / (4 * h * h)
                    hessian[k][i][j] = hessian[k][j][i] = value
            rate_plus, rate_minus = rate(((j, 1),)), rate(((j, -1),))
            for k in range(7):
                hessian[k][j][6] = hessian[k][6][j] = (rate_plus[k] - rate_minus[k]) / (2 * h)
        solution = _solution(x[:3], x[3:6], q0)
        later, earlier = solution(t + h), solution(t - h)
        for k in range(7):
            hessian[k][6][6] = (later[k] - 2 * center[k] + earlier[k]) / (h * h)
        return center, hessian


def _task(item):
    name, x = item
    values, hessian = timed(name, reference, x, *((FINE_DPS, FINE_STEP) if "near plane" in name else (DPS, STEP)))
    return dict(
        name=name,
        x=x,
        values=[text(v) for v in values],
        hessian=[[[text(v) for v in row] for row in block] for block in hessian],
    )


def main():
    write_references(
        __doc__.splitlines()[0],
        _task,
        points(),
        OUTPUT,
        1,
        dps=DPS,
        step=STEP,
        fine=dict(dps=FINE_DPS, step=FINE_STEP, points="near plane"),
        outputs="L(3), q(4)",
        inputs="I(3), L(3), t",
        attitude=[float(v) for v in ATTITUDE],
    )


if __name__ == "__main__":
    main()
