"""tumbler_periods of symmetric bodies and of uniform rotations (found NaN by the public-input harness).

Symmetric bodies: the precession rate of a symmetric body about L is M / I_t, I_t the repeated
(transverse) moment (Landau & Lifshitz, Mechanics, section 33), so P_psi = 2 pi I_t / M in closed form,
and after P_phi the body-frame L is back and the attitude has turned about L by 2 pi P_phi / P_psi
(checked on FreeRigidBody's motion, as tests/test_lightcurve.py does for triaxial bodies).  Uniform
rotations (a sphere, L along a principal axis or in the plane of two equal moments): P_psi = 2 pi /
|Omega|, P_phi infinite.  Near-symmetric bodies tend to the symmetric values.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from frbjax import FreeRigidBody
from frbjax.lightcurve import tumbler_periods as _tumbler_periods


# One compiled program each (eagerly, every operation of the periods and their gradient would compile).
tumbler_periods = jax.jit(_tumbler_periods)
psi_gradient = jax.jit(jax.grad(lambda inertia, momentum: _tumbler_periods(inertia, momentum)[0]))

SYMMETRIC = {
    "oblate SAM": ((1.0, 1.0, 2.0), (0.3, 0.5, 0.8), 1.0),
    "prolate LAM": ((1.0, 2.0, 2.0), (0.6, 0.3, 0.74), 2.0),
    "oblate, axes in another order": ((2.0, 1.3, 1.3), (0.7, -0.2, 0.4), 1.3),
}


@pytest.mark.parametrize("case", SYMMETRIC)
def test_symmetric_bodies(case):
    inertia, momentum, transverse = (np.asarray(x, float) for x in SYMMETRIC[case])
    p_psi, p_phi, _ = (float(x) for x in tumbler_periods(inertia, momentum))
    norm = np.linalg.norm(momentum)
    # Measured: 0 and 1.4e-16 relative.
    assert abs(p_psi / (2 * np.pi * transverse / norm) - 1) < 1e-14
    body = FreeRigidBody(inertia, momentum, np.array([1.0, 0.0, 0.0, 0.0]))
    np.testing.assert_allclose(np.asarray(body.angular_momentum(np.array([p_phi])))[0], momentum, atol=1e-12)
    r0, r1 = (np.asarray(body.rotation_matrix(np.array([t])))[0] for t in (0.0, p_phi))
    turn = Rotation.from_matrix(r1 @ r0.T).as_rotvec()
    axis = r0 @ momentum / norm
    expected = np.angle(np.exp(2j * np.pi * p_phi / p_psi))
    assert abs(np.angle(np.exp(1j * (np.dot(turn, axis) - expected)))) < 1e-12


def test_near_symmetric_bodies_tend_to_the_symmetric_periods():
    momentum = np.array([0.3, 0.5, 0.8])
    symmetric = np.asarray(tumbler_periods(np.array([1.0, 1.0, 2.0]), momentum)[:2])
    for gap in (1e-4, 1e-7):
        near = np.asarray(tumbler_periods(np.array([1.0, 1.0 + gap, 2.0]), momentum)[:2])
        # First order in the gap (measured: 0.77 and 0.50 times the gap).
        assert np.all(np.abs(near / symmetric - 1) < 1.5 * gap), (gap, near / symmetric - 1)


UNIFORM = {
    "sphere": ((1.5, 1.5, 1.5), (0.3, 0.5, 0.8)),
    "largest axis": ((1.0, 1.5, 2.0), (0.0, 0.0, 0.8)),
    "smallest axis": ((1.0, 1.5, 2.0), (-0.7, 0.0, 0.0)),
    "plane of equal moments": ((1.0, 2.0, 2.0), (0.0, 0.6, 0.8)),
}


@pytest.mark.parametrize("case", UNIFORM)
def test_uniform_rotations(case):
    inertia, momentum = (np.asarray(x, float) for x in UNIFORM[case])
    p_psi, p_phi, long_axis = tumbler_periods(inertia, momentum)
    assert float(p_psi) == pytest.approx(2 * np.pi / np.linalg.norm(momentum / inertia), rel=1e-15)
    assert np.isinf(float(p_phi)) and not bool(long_axis)
    gradient = psi_gradient(jnp.asarray(inertia), jnp.asarray(momentum))
    assert np.all(np.isfinite(np.asarray(gradient)))
