"""Regenerate tests/data/diffrax_references.npz: diffrax solutions for the bodies of tests/test_body_diffrax.py.

    .venv/bin/python tests/data/make_diffrax_references.py      # about 10 s of CPU

For each seed in SEEDS the bodies of ``build_cases(seed)`` (tests/test_body_diffrax.py: every case
family, 20 times per body) are integrated by diffrax's 8th-order Dormand-Prince method in float64 at
rtol = atol = 1e-16 (tests/_reference.py ``diffrax_references``): the equations of (L, q) and, from the
matrix of the attitude, those of (L, R), each jit-compiled and vmapped over the bodies.  The file holds,
per seed, the inputs (inertia, momentum, attitude, times: the test checks that they are still what
``build_cases`` draws) and the four solutions with the accepted steps of each.

A binary .npz rather than JSON: float64 values round-trip exactly and the ~120,000 of them take
about 0.8 MB instead of 3.  The test recomputes a few bodies live at a modest tolerance
(``test_live_diffrax_cross_check``) so that this method stays exercised.
"""

from __future__ import annotations

import os
import sys
import time

import jax
import numpy as np


HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

import _reference as ref  # noqa: E402
import test_body_diffrax as cases  # noqa: E402


SEEDS = cases.STORED_SEEDS
OUTPUT = cases.DATA
INPUTS = ("inertia", "momentum", "attitude", "times")


def references(seed):
    """{name: array} of one seed: the inputs and the solutions, keys prefixed with the seed."""
    _, inertia, momentum, attitude, times = cases.stack(cases.build_cases(seed))
    solutions = ref.diffrax_references(inertia, momentum, attitude, times, rtol=cases.RTOL, atol=cases.ATOL)
    arrays = dict(zip(INPUTS, (inertia, momentum, attitude, times)), **solutions)
    return {f"seed{seed}_{name}": value for name, value in arrays.items()}


def main():
    jax.config.update("jax_enable_x64", True)  # as tests/conftest.py does
    arrays = dict(
        rtol=np.float64(cases.RTOL),
        atol=np.float64(cases.ATOL),
        seeds=np.array(SEEDS),
        solver=np.array("diffrax.Dopri8, PIDController"),
        generator=np.array(os.path.basename(__file__)),
    )
    for seed in SEEDS:
        start = time.process_time()
        arrays.update(references(seed))
        steps = arrays[f"seed{seed}_steps_quaternion"]
        print(
            f"seed {seed}: {len(steps)} bodies, {time.process_time() - start:.0f} s CPU, "
            f"steps (L, q) up to {steps.max()}",
            flush=True,
        )
    np.savez_compressed(OUTPUT, **arrays)


if __name__ == "__main__":
    main()
