"""Regenerate tests/data/tensor_references.npz: diffrax solutions for tests/test_inertia_tensor.py and
tests/test_torques_tensor.py (bodies given by a full inertia tensor).

    .venv/bin/python tests/data/make_tensor_references.py      # about 9 minutes of CPU

Every solution is diffrax's 8th-order Dormand-Prince method at rtol = atol = 1e-13 on the equations
written in the body frame of the tensor, independent of frbjax (the integrators and the bodies are
those of the test files, imported from them):

* ``motion_*``: the bodies of ``build_bodies`` at the common times ``TIMES`` (both signs), as
  ``integrate_both_ways`` returns them;
* ``derivative_*``: the bodies of ``derivative_bodies`` at their times, the values and the derivatives
  with respect to the tensor's 6 independent entries, Richardson's (16 D(h/2) - D(h)) / 15 of the
  4-point stencil at h = STEP and h/2 (456 integrations per step size; this is the long part);
* ``torqued_*``: the damped tilted body of tests/test_torques_tensor.py at its final time.

The file holds the inputs of each (the tests check that they are still what the test files build, bit
for bit) and the solutions, in a binary .npz (float64 values round-trip exactly).
tests/test_inertia_tensor.py integrates a few bodies live (``test_live_diffrax_cross_check``) so that
the method stays exercised and the file is checked against it.
"""

from __future__ import annotations

import os
import sys
import time

import jax
import numpy as np


HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

import test_inertia_tensor as tensor_tests  # noqa: E402
import test_torques_tensor as torque_tests  # noqa: E402


OUTPUT = tensor_tests.DATA


def motion():
    names, tensor, momentum, attitude = tensor_tests.stack(tensor_tests.build_bodies())
    L, q = tensor_tests.integrate_both_ways(tensor, momentum, attitude, tensor_tests.TIMES)
    return dict(tensor=tensor, momentum=momentum, attitude=attitude, times=tensor_tests.TIMES, L=L, q=q)


def derivatives():
    _, tensor, momentum, attitude, times = tensor_tests.derivative_bodies()
    L, q = tensor_tests.integrate(tensor, momentum, attitude, times)
    coarse = tensor_tests.stencil_derivatives(tensor, momentum, attitude, times)
    fine = tensor_tests.stencil_derivatives(tensor, momentum, attitude, times, step=tensor_tests.STEP / 2)
    # The stencil's own error (h^4), printed for the record: up to ~1e-11 at the generic bodies and
    # ~8e-6 at the long times, which Richardson's extrapolation removes.
    for label, k in (("dL", 0), ("dq", 1)):
        print(f"stencil |D(h) - D(h/2)| {label}:", np.abs(fine[k] - coarse[k]).max((1, 2, 3)).round(12), flush=True)
    dL, dq = ((16 * f - c) / 15 for f, c in zip(fine, coarse))
    return dict(tensor=tensor, momentum=momentum, attitude=attitude, times=times, L=L, q=q, dL=dL, dq=dq)


def torqued():
    L, q = torque_tests.reference(torque_tests.MOMENTUM, torque_tests.ATTITUDE, torque_tests.FINAL_TIME)
    return dict(
        tensor=torque_tests.TENSOR,
        momentum=torque_tests.MOMENTUM,
        attitude=torque_tests.ATTITUDE,
        final_time=np.float64(torque_tests.FINAL_TIME),
        L=np.asarray(L),
        q=np.asarray(q),
    )


def main():
    jax.config.update("jax_enable_x64", True)  # as tests/conftest.py does
    arrays = dict(
        rtol=np.float64(tensor_tests.RTOL),
        atol=np.float64(tensor_tests.ATOL),
        step=np.float64(tensor_tests.STEP),
        solver=np.array("diffrax.Dopri8, PIDController"),
        generator=np.array(os.path.basename(__file__)),
    )
    for prefix, compute in (("torqued", torqued), ("motion", motion), ("derivative", derivatives)):
        start = time.process_time()
        arrays.update({f"{prefix}_{name}": value for name, value in compute().items()})
        print(f"{prefix}: {time.process_time() - start:.0f} s CPU", flush=True)
    np.savez_compressed(OUTPUT, **arrays)


if __name__ == "__main__":
    main()
