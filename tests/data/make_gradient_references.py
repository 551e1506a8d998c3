"""Regenerate tests/data/gradient_references.json: 30-digit derivatives of the free rigid body motion.

    .venv/bin/python tests/data/make_gradient_references.py [--processes 2]    # ~15 min on 2 cores

For every point x = (I (3), L (3), q0 (4), t) the file holds the outputs

    y = (L(t) (3), Omega(t) (3), q(t) (4), R(t) (9, row-major))

and their Jacobian dy/dx (19 x 11), from mpmath.odefun's Taylor-series solution of the 7 equations
dL/dt = L x (L / I), dq/dt = 1/2 q ⊗ (0, L / I) (tests/_reference.py ``mp_field``) at DPS digits:

* d/dI and d/dL: central differences (y(x + h e_j) - y(x - h e_j)) / 2h with h = STEP, of solutions
  started from the exact binary values of the float64 inputs (plus or minus h, exactly in mpmath).
  Truncation h^2 y'''/6 ~ 1e-20 and solver error ~ 10^-DPS / h ~ 1e-22: the differences are good to
  ~1e-18 relative, far below the 1e-9 of the test;
* d/dq0 and d/dt: exact, from the same solution: q(t) = (q0/|q0|) ⊗ r(t) is linear in the normalised
  q0, and dy/dt is the right-hand side of the equations at t.

Symmetric bodies next to the plane of their equal moments (the points "... near plane ..."), where
frbjax's elliptic parameter moves as dI / (e . n)^2, take h = FINE_STEP at FINE_DPS digits
(``precision``): their differences are then exact far below the test's tolerance (truncation
h^2 y'''/6 ~ 1e-56, solver error 10^-FINE_DPS / h ~ 1e-32) with no assumption on how fast the motion
bends in that direction (on the scale of 1, as it turns out, like everywhere else).
``--only NAME ...`` recomputes the named points and keeps the others of the existing file.

Nothing here uses a formula of frbjax.  ``kind`` says how tests/test_gradients_body.py uses a point:
"generic" and "smooth" points (the implementation's formulas are smooth there) are compared with
frbjax at 1e-9; "branch" points (frbjax takes a limiting branch: uniform rotation, the separatrix
formulas) are only required to give finite derivatives, their errors are reported.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import time

import mpmath
import numpy as np


HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

import _reference as ref  # noqa: E402


DPS = 32
STEP = "1e-10"
FINE_DPS = 60
FINE_STEP = "1e-28"
DIGITS = 22
OUTPUT = os.path.join(HERE, "gradient_references.json")

_Q = np.array([0.9, 0.1, -0.3, 0.2])
ATTITUDE = _Q / np.linalg.norm(_Q)
GENERIC_L = (0.3, 0.5, 0.8)


def _point(inertia, momentum, t=1.7, attitude=ATTITUDE):
    return [float(v) for v in np.concatenate([inertia, momentum, attitude, [t]])]


def points():
    """(name, kind, x) of every reference point."""
    out = [
        # Both regimes, both signs of time, moments in and out of order, |L| != 1, a long time.
        ("major", "generic", _point([1.0, 2.0, 3.0], [0.9, 0.3, 0.2], t=1.3)),
        ("minor", "generic", _point([1.0, 2.0, 3.0], [0.2, 0.3, 0.9], t=2.1)),
        ("major negative", "generic", _point([1.0, 2.0, 3.0], [-0.9, 0.25, -0.3], t=-0.8)),
        ("minor unsorted", "generic", _point([2.5, 0.7, 1.4], [-0.4, 0.7, 0.5], t=0.9)),
        ("major unsorted", "generic", _point([1.4, 2.5, 0.7], [0.2, -0.5, 0.9], t=3.0)),
        ("scaled |L|", "generic", _point([0.3, 0.45, 0.5], [1.5, -2.0, 0.7], t=0.6)),
        ("long time", "generic", _point([1.0, 1.5, 2.2], [0.5, 0.5, 0.7], t=25.0)),
        ("asteroid", "generic", _point([0.97, 1.0, 0.64], [0.35, -0.45, 0.82], t=4.0)),
    ]
    # Near the separatrix: d I2 - 1 = +-1e-3, +-1e-6 (I2 the middle moment).
    for offset, l2, signs, inertia in (
        (1e-3, 0.3, (1, 1, -1), (1.0, 2.0, 3.0)),
        (-1e-3, -0.5, (-1, 1, 1), (1.0, 2.0, 3.0)),
        (1e-6, 0.1, (1, -1, 1), (1.0, 2.0, 3.0)),
        (-1e-6, 0.2, (1, 1, 1), (1.0, 2.0, 3.0)),
    ):
        momentum = ref.separatrix_momentum(inertia, offset, l2, signs)
        out.append((f"separatrix {offset:+.0e}", "generic", _point(inertia, momentum, t=1.1)))
    # Special but smooth points of the formulas: equal moments (the elliptic parameter is 0), a zero
    # component of L, t = 0, L = 0 (uniform rotation: exact to first order).
    out += [
        ("I1=I2", "smooth", _point([2.0, 2.0, 3.0], GENERIC_L)),
        ("I2=I3", "smooth", _point([1.0, 3.0, 3.0], GENERIC_L)),
        ("I2=I3 unsorted", "smooth", _point([3.0, 1.0, 3.0], GENERIC_L)),
        ("L2 = 0", "smooth", _point([1.0, 2.0, 3.0], [0.6, 0.0, 0.8])),
        ("L1 = 0", "smooth", _point([1.0, 2.0, 3.0], [0.0, 0.6, 0.8])),
        ("L3 = 0", "smooth", _point([1.0, 2.0, 3.0], [0.8, 0.6, 0.0])),
        ("L1 = 0 unsorted", "smooth", _point([2.0, 3.0, 1.0], [0.6, 0.8, 0.0])),
        ("t = 0", "smooth", _point([1.0, 2.0, 3.0], GENERIC_L, t=0.0)),
        ("L = 0", "smooth", _point([1.0, 2.0, 3.0], [0.0, 0.0, 0.0])),
    ]
    # Symmetric bodies whose L is e . n = 1e-4 ... 1e-8 from the plane of their equal moments, not in it
    # (frbjax takes the regular precession with its first-order neighbours there, frbjax._precession):
    # both orders of the moments, |L| != 1, negative and long times.
    out += [
        ("I1=I2 near plane 1e-4", "smooth", _point([1.2, 1.2, 2.1], [0.6, 0.8, 1e-4])),
        ("I1=I2 near plane 1e-8", "smooth", _point([1.2, 1.2, 2.1], [0.6, 0.8, 1e-8])),
        ("I1=I3 near plane 1e-6 unsorted", "smooth", _point([2.1, 1.2, 2.1], [1.2, -1e-6, -1.6], t=-2.3)),
        ("I2=I3 near plane 1e-3 long", "smooth", _point([0.7, 1.9, 1.9], [-2e-3, 0.5, 0.9], t=40.0)),
    ]
    # Branch points: frbjax uses a limiting formula there (documented); finite derivatives only.
    separatrix = ref.separatrix_momentum((1.0, 2.0, 3.0), 0.0, 0.0)
    out += [
        ("sphere", "branch", _point([2.0, 2.0, 2.0], GENERIC_L)),
        ("spin axis 1", "branch", _point([1.0, 2.0, 3.0], [1.0, 0.0, 0.0])),
        ("spin axis 2", "branch", _point([1.0, 2.0, 3.0], [0.0, 1.0, 0.0])),
        ("spin axis 3", "branch", _point([1.0, 2.0, 3.0], [0.0, 0.0, -1.0])),
        ("spin axis 2 unsorted", "branch", _point([3.0, 1.0, 2.0], [0.0, 0.0, 1.0])),
        ("I1=I2 spin axis 3", "branch", _point([2.0, 2.0, 3.0], [0.0, 0.0, 1.0])),
        ("I1=I2 spin in plane", "branch", _point([2.0, 2.0, 3.0], [0.6, 0.8, 0.0])),
        ("separatrix", "branch", _point([1.0, 2.0, 3.0], separatrix)),
    ]
    return out


def _hamilton(p, q):
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return [
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    ]


def _matrix_bilinear(p, q):
    """B(p, q) with R(q) = B(q, q) the rotation matrix of a unit q (x_space = R x_body), row-major."""
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return [
        pw * qw + px * qx - py * qy - pz * qz,
        px * qy + py * qx - pw * qz - pz * qw,
        px * qz + pz * qx + pw * qy + py * qw,
        px * qy + py * qx + pw * qz + pz * qw,
        pw * qw - px * qx + py * qy - pz * qz,
        py * qz + pz * qy - pw * qx - px * qw,
        px * qz + pz * qx - pw * qy - py * qw,
        py * qz + pz * qy + pw * qx + px * qw,
        pw * qw - px * qx - py * qy + pz * qz,
    ]


def _solve(inertia, momentum, q0, t):
    """(L(t), q(t)) as mpf lists; inputs mpf; q0 unit."""
    field = ref.mp_field(inertia)
    if t == 0:
        return list(momentum), list(q0)
    sign = 1 if t > 0 else -1
    rhs = field if sign > 0 else (lambda s, y: [-v for v in field(-s, y)])
    y = mpmath.odefun(rhs, 0, list(momentum) + list(q0))(sign * t)
    return y[:3], y[3:]


def _outputs(inertia, momentum, q0, t):
    L, q = _solve(inertia, momentum, q0, t)
    omega = [a / b for a, b in zip(L, inertia)]
    return L + omega + q + _matrix_bilinear(q, q), (L, q, omega)


def precision(name):
    """(digits, difference step) of the point ``name`` (module docstring)."""
    return (FINE_DPS, FINE_STEP) if "near plane" in name else (DPS, STEP)


def reference(x, dps=DPS, step=STEP):
    """(values (19,), Jacobian (19, 11)) as mpf, at x (11 floats)."""
    with mpmath.workdps(dps):
        x = [mpmath.mpf(v) for v in x]
        h = mpmath.mpf(step)
        inertia, momentum, q_raw, t = x[:3], x[3:6], x[6:10], x[10]
        norm = mpmath.sqrt(sum(v * v for v in q_raw))
        q0 = [v / norm for v in q_raw]
        values, (L, q, omega) = _outputs(inertia, momentum, q0, t)
        columns = []
        for j in range(6):  # I and L: central differences
            shifted = []
            for s in (1, -1):
                y = list(x)
                y[j] += s * h
                shifted.append(_outputs(y[:3], y[3:6], q0, t)[0])
            columns.append([(a - b) / (2 * h) for a, b in zip(*shifted)])
        # q(t) = q0n ⊗ r(t): d q(t) = d q0n ⊗ r(t), d q0n / d q0_j = (e_j - q0n q0n_j) / |q0|.
        r = _hamilton([q0[0], -q0[1], -q0[2], -q0[3]], q)
        for j in range(4):
            dq0 = [((1 if k == j else 0) - q0[k] * q0[j]) / norm for k in range(4)]
            dq = _hamilton(dq0, r)
            dR = [2 * v for v in _matrix_bilinear(q, dq)]
            columns.append([mpmath.mpf(0)] * 6 + dq + dR)
        # d/dt: the equations themselves.
        dL = [L[1] * omega[2] - L[2] * omega[1], L[2] * omega[0] - L[0] * omega[2], L[0] * omega[1] - L[1] * omega[0]]
        dq = [v / 2 for v in _hamilton(q, [mpmath.mpf(0)] + omega)]
        dR = [2 * v for v in _matrix_bilinear(q, dq)]
        columns.append(dL + [a / b for a, b in zip(dL, inertia)] + dq + dR)
        jacobian = [[columns[j][i] for j in range(11)] for i in range(19)]
        return values, jacobian


def _task(item):
    name, kind, x = item
    values, jacobian = timed(name, reference, x, *precision(name))
    return dict(
        name=name,
        kind=kind,
        x=x,
        values=[text(v) for v in values],
        jacobian=[[text(v) for v in row] for row in jacobian],
    )


def text(value):
    """An mpf as a string of DIGITS significant digits (the JSON files keep the references as text)."""
    return mpmath.nstr(value, DIGITS, strip_zeros=False)


def timed(name, compute, *arguments):
    """compute(*arguments), printing how long it took (the generators run for minutes per point)."""
    start = time.perf_counter()
    result = compute(*arguments)
    print(f"{name}: {time.perf_counter() - start:.0f} s", flush=True)
    return result


def write_references(description, task, items, output, default_processes, **metadata):
    """Map ``task`` over ``items`` on a process pool (--processes) and write the records with metadata;
    with --only NAME ..., recompute those points and keep the existing file's others."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--processes", type=int, default=default_processes)
    parser.add_argument("--only", nargs="+", metavar="NAME")
    arguments = parser.parse_args()
    kept, listed = {}, [item[0] for item in items]
    if arguments.only:
        with open(output) as handle:
            kept = {record["name"]: record for record in json.load(handle)["points"]}
        unknown = set(arguments.only) - set(listed)
        if unknown:
            parser.error(f"no such points: {sorted(unknown)}")
        items = [item for item in items if item[0] in arguments.only or item[0] not in kept]
    with multiprocessing.Pool(arguments.processes) as pool:
        computed = {record["name"]: record for record in pool.map(task, items, chunksize=1)}
    # In the order of ``items``; kept points that ``items`` no longer lists are dropped.
    records = [computed[name] if name in computed else kept[name] for name in listed]
    with open(output, "w") as handle:
        json.dump(dict(metadata, points=records), handle, indent=1)
    print("wrote", output)


def main():
    write_references(
        __doc__.splitlines()[0],
        _task,
        points(),
        OUTPUT,
        2,
        dps=DPS,
        step=STEP,
        fine=dict(dps=FINE_DPS, step=FINE_STEP, points="near plane"),
        outputs="L(3), Omega(3), q(4), R(9) row-major",
        inputs="I(3), L(3), q0(4), t",
    )


if __name__ == "__main__":
    main()
