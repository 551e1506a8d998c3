"""Regenerate tests/data/mpmath_references.json: 30-digit solutions of the free rigid body by mpmath.odefun.

    .venv/bin/python tests/data/make_mpmath_references.py      # about two minutes on one core

Each case integrates the 7 equations dL/dt = L x (L / I), dq/dt = 1/2 q ⊗ (0, L / I) with mpmath's
Taylor-series solver (tests/_reference.py, ``mpmath_solution``) at DPS digits from the exact binary
values of the float64 inputs, and stores the inputs (as JSON floats, which round-trip exactly) and the
solution at each time as 30-digit decimal strings.  tests/test_body_mpmath.py compares frbjax with these
values and recomputes one case live at 30 digits to check the file.
"""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np


HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

import _reference as ref  # noqa: E402


DPS = 34
DIGITS = 30
OUTPUT = os.path.join(HERE, "mpmath_references.json")


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def cases():
    """(name, kind, inertia, momentum, attitude, times); kind: generic or near_separatrix or seeds."""
    rng = np.random.default_rng(903)
    attitude = lambda: ref.random_attitudes(rng, 1)[0]  # noqa: E731
    taus = np.array([5.0, 10.0, 15.0, 20.0, 25.0, 30.0])  # |L| t
    out = []

    def add(name, kind, inertia, momentum, q0, sign):
        momentum = np.asarray(momentum, float)
        times = sign * taus / np.linalg.norm(momentum)
        out.append((name, kind, np.asarray(inertia, float), momentum, np.asarray(q0, float), times))

    # Generic bodies (d I2 - 1 printed by `separatrix_distance` in the file), both regimes, both signs
    # of time, moments in and out of order, |L| = 1 and |L| != 1.
    add("major_unit", "generic", (1.0, 2.0, 3.0), unit((0.2, 0.5, 0.84)), attitude(), 1)
    add("major_scaled", "generic", (2.7, 0.9, 1.6), 2.5 * unit((-0.85, 0.3, -0.4)), attitude(), -1)
    add("minor_unit", "generic", (1.0, 2.0, 3.0), unit((0.9, -0.4, 0.25)), attitude(), 1)
    add("minor_scaled", "generic", (0.6, 2.2, 1.3), 0.4 * unit((-0.9, 0.3, -0.3)), attitude(), -1)
    # |d I2 - 1| = 1e-8 on both sides.
    for name, inertia, offset, l2, signs, sign in (
        ("near_separatrix_minor", (1.0, 2.0, 3.0), 1e-8, 0.3, (1, 1, -1), 1),
        ("near_separatrix_major", (1.0, 2.0, 3.0), -1e-8, -0.5, (-1, 1, 1), -1),
        ("near_separatrix_permuted", (2.5, 0.8, 1.9), 1e-8, 0.1, (1, -1, 1), 1),
    ):
        sorted_inertia = np.sort(inertia)
        momentum = ref.separatrix_momentum(sorted_inertia, offset, l2, signs)
        order = np.argsort(np.argsort(inertia))  # position of each moment in the sorted list
        add(name, "near_separatrix", inertia, momentum[order], attitude(), sign)
    # The worked example's body ("seeds": Fortran reference q(10) with a semi-exact quadrature).
    out.append(
        (
            "seeds",
            "seeds",
            np.array([1.0, 1.012686988782515, 3.306237422473038]),
            np.array([-0.544332842491675, 0.729131780907662, -0.414811526666455]),
            np.array([1.0, 0.0, 0.0, 0.0]),
            np.array([2.5, 5.0, 7.5, 10.0]),
        )
    )
    return out


def main():
    records = []
    for name, kind, inertia, momentum, attitude, times in cases():
        start = time.time()
        L, q = ref.mpmath_solution(inertia, momentum, attitude, times, dps=DPS, digits=DIGITS)
        records.append(
            dict(
                name=name,
                kind=kind,
                inertia=inertia.tolist(),
                angular_momentum=momentum.tolist(),
                attitude=attitude.tolist(),
                separatrix_distance=ref.separatrix_distance(inertia, momentum),
                times=times.tolist(),
                L=L,
                q=q,
            )
        )
        print(f"{name}: {time.time() - start:.1f} s", flush=True)
    with open(OUTPUT, "w") as f:
        header = dict(dps=DPS, digits=DIGITS, generator=os.path.basename(__file__))
        json.dump(dict(header, cases=records), f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
