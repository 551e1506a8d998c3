"""The exact free rigid body in numpy + scipy.special: the closed form a user would write by hand.

This is the peer that benchmarks/work_precision.py and benchmarks/throughput.py time frbjax against.
It follows docs/theory.md line by line, with nothing from frbjax's code:

* working frame: sort the moments (J1 <= J2 <= J3) with a signed permutation P of determinant +1 and
  flip two axes so that l1 >= 0 and l3 >= 0 (the body's symmetry under a rotation by pi about a
  principal axis); every orbit sign of the formulas is then +1;
* regime around the major axis (d J2 < 1): L = (A1 cn, A2 sn, A3 dn)(u|m),
  psi = tau/J1 + atan2(L2, L3) - alpha Pi(nu; am u|m), quaternion chart built on 1 + L1;
  regime around the minor axis (d J2 > 1): L = (A1 dn, A2 sn, A3 cn)(u|m),
  psi = tau/J3 - atan2(L2, L1) + alpha Pi(nu; am u|m), chart built on 1 + L3;
* u = u0 + B tau with tau = |L| t, the phase u0 = F(am0|m) matching the initial angular momentum;
* q(t) = q0 ⊗ P ⊗ conj(q̂(u0)) ⊗ q̂(u) ⊗ conj(P)  (docs/theory.md §8).

Special functions: scipy.special.ellipj for sn, cn, dn, am (after reducing u modulo the period 4K, so
that its accuracy does not decay with time), Carlson's elliprf / elliprj for K, F and Pi:

    Pi(n; phi|m) = sin(phi) R_F(c, D, 1) + n/3 sin(phi)^3 R_J(c, D, 1, 1 - n sin(phi)^2)   (DLMF 19.25.14)

with c = cos(phi)^2 and D = 1 - m sin(phi)^2, valid for |phi| <= pi/2; for any real phi
Pi(n; phi|m) = 2k Pi(n|m) + Pi(n; phi - k pi|m), k = round(phi/pi) (DLMF 19.2.10).  Here
sin(phi - k pi) = (-1)^k sn, cos(phi - k pi)^2 = cn^2 and D = dn^2, so no extra sin/cos is evaluated.

Scope: generic triaxial bodies (J1 < J2 < J3, L not on the separatrix d J2 = 1 and not along a
principal axis).  The separatrix, uniform rotations and symmetric bodies are not handled (the formulas
divide by zero there); frbjax handles them, this peer does not need to.

Everything is vectorised numpy: the per-body constants are computed once in the constructor
(arrays of the batch shape), evaluations broadcast the times against them like frbjax does.
"""

from __future__ import annotations

import numpy as np
import scipy.special as sc


def hamilton(p, q):
    """Hamilton product p ⊗ q of (..., 4) arrays, q = (w, x, y, z)."""
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def conjugate(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quaternion_of_matrix(r):
    """Unit quaternion of a rotation matrix (..., 3, 3) (Shepperd: the largest of the four squares)."""
    trace = r[..., 0, 0] + r[..., 1, 1] + r[..., 2, 2]
    squares = np.stack(
        [1 + trace, 1 + 2 * r[..., 0, 0] - trace, 1 + 2 * r[..., 1, 1] - trace, 1 + 2 * r[..., 2, 2] - trace], -1
    )
    choice = np.argmax(squares, axis=-1)
    big = np.sqrt(np.max(squares, axis=-1)) / 2
    f = 1 / (4 * big)
    candidates = np.stack(
        [
            np.stack(
                [
                    big,
                    (r[..., 2, 1] - r[..., 1, 2]) * f,
                    (r[..., 0, 2] - r[..., 2, 0]) * f,
                    (r[..., 1, 0] - r[..., 0, 1]) * f,
                ],
                -1,
            ),
            np.stack(
                [
                    (r[..., 2, 1] - r[..., 1, 2]) * f,
                    big,
                    (r[..., 0, 1] + r[..., 1, 0]) * f,
                    (r[..., 0, 2] + r[..., 2, 0]) * f,
                ],
                -1,
            ),
            np.stack(
                [
                    (r[..., 0, 2] - r[..., 2, 0]) * f,
                    (r[..., 0, 1] + r[..., 1, 0]) * f,
                    big,
                    (r[..., 1, 2] + r[..., 2, 1]) * f,
                ],
                -1,
            ),
            np.stack(
                [
                    (r[..., 1, 0] - r[..., 0, 1]) * f,
                    (r[..., 0, 2] + r[..., 2, 0]) * f,
                    (r[..., 1, 2] + r[..., 2, 1]) * f,
                    big,
                ],
                -1,
            ),
        ],
        -2,
    )
    return np.take_along_axis(candidates, choice[..., None, None], axis=-2)[..., 0, :]


def matrix_of_quaternion(q):
    """Rotation matrix (..., 3, 3) of unit quaternions q (..., 4), x_space = R x_body."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def _legendre_pi_reduced(n, s, c2, d2):
    """Pi(n; phi|m) for |phi| <= pi/2 from s = sin(phi), c2 = cos(phi)^2, d2 = 1 - m s^2 (DLMF 19.25.14)."""
    s2 = s * s
    return s * sc.elliprf(c2, d2, 1.0) + n / 3 * s * s2 * sc.elliprj(c2, d2, 1.0, 1 - n * s2)


class ScipyFreeRigidBody:
    """Exact torque-free motion, numpy/scipy, batched: inputs (..., 3), (..., 3), (..., 4) or None.

    ``angular_momentum(t)``, ``quaternion(t)`` and ``rotation_matrix(t)`` broadcast ``t`` against the
    batch shape (numpy rules), like frbjax.FreeRigidBody.  Generic triaxial bodies only (module docstring).
    """

    def __init__(self, inertia, angular_momentum, attitude=None):
        inertia = np.asarray(inertia, np.float64)
        momentum = np.asarray(angular_momentum, np.float64)
        if attitude is None:
            attitude = np.zeros(inertia.shape[:-1] + (4,))
            attitude[..., 0] = 1
        attitude = np.asarray(attitude, np.float64)
        batch = np.broadcast_shapes(inertia.shape[:-1], momentum.shape[:-1], attitude.shape[:-1])
        inertia = np.broadcast_to(inertia, batch + (3,))
        momentum = np.broadcast_to(momentum, batch + (3,))
        attitude = np.broadcast_to(attitude, batch + (4,))
        attitude = attitude / np.linalg.norm(attitude, axis=-1, keepdims=True)

        # Working frame: columns of P are the working axes in body coordinates, det P = +1.
        order = np.argsort(inertia, axis=-1, kind="stable")
        perm = np.swapaxes(np.eye(3)[order], -1, -2)
        i, j, k = order[..., 0], order[..., 1], order[..., 2]
        parity = np.where((j - i) * (k - i) * (k - j) > 0, 1.0, -1.0)
        perm = perm * np.stack([np.ones_like(parity), parity, np.ones_like(parity)], -1)[..., None, :]
        working = np.einsum("...ji,...j->...i", perm, momentum)  # P^T L
        s1 = np.where(working[..., 0] < 0, -1.0, 1.0)
        s3 = np.where(working[..., 2] < 0, -1.0, 1.0)
        flips = np.stack([s1, s1 * s3, s3], -1)
        perm = perm * flips[..., None, :]
        working = working * flips
        self.permutation = perm
        self.frame = quaternion_of_matrix(perm)

        norm = np.linalg.norm(working, axis=-1)
        l1, l2, l3 = np.moveaxis(working / norm[..., None], -1, 0)
        j1, j2, j3 = np.moveaxis(np.take_along_axis(inertia, order, axis=-1), -1, 0)
        a, b, c = j2 - j1, j3 - j2, j3 - j1
        # 1 - d J1, d J2 - 1, d J3 - 1 without cancellation (docs/theory.md §3).
        g1 = l2 * l2 * a / j2 + l3 * l3 * c / j3
        g2 = l1 * l1 * a / j1 - l3 * l3 * b / j3
        g3 = l1 * l1 * c / j1 + l2 * l2 * b / j2
        minor = g2 > 0
        self.minor = minor
        self.norm = norm
        # Both regimes at once (np.where); the other regime's values may be nan and are discarded.
        with np.errstate(divide="ignore", invalid="ignore"):
            self.amplitude = np.stack(
                [
                    np.sqrt(j1 * g3 / c),
                    np.where(minor, np.sqrt(j2 * g1 / a), np.sqrt(j2 * g3 / b)),
                    np.sqrt(j3 * g1 / c),
                ],
                -1,
            )
            self.rate = np.where(minor, np.sqrt(g3 * a / (j1 * j2 * j3)), np.sqrt(g1 * b / (j1 * j2 * j3)))
            self.m = np.where(minor, g1 * b / (g3 * a), g3 * a / (g1 * b))
            self.alpha = np.where(minor, c / np.sqrt(j1 * g3 * a * j3 / j2), c / np.sqrt(j1 * g1 * b * j3 / j2))
            self.nu = np.where(minor, -j3 * g1 / (j1 * g3), -j1 * g3 / (j3 * g1))
        self.precession = np.where(minor, 1 / j3, 1 / j1)
        mc = 1 - self.m
        quarter = sc.elliprf(0.0, mc, 1.0)  # K(m)
        self.period = 4 * quarter
        self.complete_pi = quarter + self.nu / 3 * sc.elliprj(0.0, mc, 1.0, 1 - self.nu)  # Pi(nu|m)
        # Phase: sn0 = l2/A2 and cn0 = l1/A1 (major) or l3/A3 (minor), cn0 >= 0 so |am0| <= pi/2 and
        # u0 = F(am0|m) = sn0 R_F(cn0^2, 1 - m sn0^2, 1).
        sn0 = l2 / self.amplitude[..., 1]
        cn0 = np.where(minor, l3 / self.amplitude[..., 2], l1 / self.amplitude[..., 0])
        am0 = np.arctan2(sn0, cn0)
        s, co = np.sin(am0), np.cos(am0)
        self.u0 = s * sc.elliprf(co * co, 1 - self.m * s * s, 1.0)
        reference, _ = self._particular(np.zeros_like(norm))
        self.offset = hamilton(hamilton(attitude, self.frame), conjugate(reference))

    def _jacobi(self, tau):
        u = self.u0 + self.rate * tau
        turns = np.round(u / self.period)
        sn, cn, dn, am = sc.ellipj(u - turns * self.period, self.m)
        return sn, cn, dn, am, turns

    def _unit_momentum(self, sn, cn, dn):
        first = np.where(self.minor, dn, cn)
        third = np.where(self.minor, cn, dn)
        return self.amplitude * np.stack([first, sn, third], -1)

    def _particular(self, tau):
        """(q̂, unit working-frame L) at unit-|L| time tau (psi counted from tau = 0)."""
        sn, cn, dn, am, periods = self._jacobi(tau)
        momentum = self._unit_momentum(sn, cn, dn)
        l1, l2, l3 = momentum[..., 0], momentum[..., 1], momentum[..., 2]
        k = np.round(am / np.pi)
        sign = 1 - 2 * np.mod(k, 2)  # (-1)^k
        third_kind = 2 * (k + 2 * periods) * self.complete_pi + _legendre_pi_reduced(
            self.nu, sign * sn, cn * cn, dn * dn
        )
        minor = self.minor
        psi = self.precession * tau + np.where(
            minor, -np.arctan2(l2, l1) + self.alpha * third_kind, np.arctan2(l2, l3) - self.alpha * third_kind
        )
        hc, hs = np.cos(psi / 2), np.sin(psi / 2)
        base = 1 + np.where(minor, l3, l1)
        root, inverse = np.sqrt(base / 2), 1 / np.sqrt(2 * base)
        chart = np.where(
            minor[..., None],
            np.stack([root * hc, (l2 * hc + l1 * hs) * inverse, (l2 * hs - l1 * hc) * inverse, root * hs], -1),
            np.stack([hc * root, hs * root, (l3 * hc + l2 * hs) * inverse, (-l2 * hc + l3 * hs) * inverse], -1),
        )
        return chart, momentum

    def angular_momentum(self, t):
        """Body-frame L(t), shape broadcast(batch, t.shape) + (3,)."""
        tau = self.norm * np.asarray(t, np.float64)
        sn, cn, dn, _, _ = self._jacobi(tau)
        working = self.norm[..., None] * self._unit_momentum(sn, cn, dn)
        return np.einsum("...ij,...j->...i", self.permutation, working)

    def quaternion(self, t):
        """Attitude q(t) = (w, x, y, z), body to space, equal to the given attitude at t = 0."""
        tau = self.norm * np.asarray(t, np.float64)
        chart, _ = self._particular(tau)
        return hamilton(hamilton(self.offset, chart), conjugate(self.frame))

    def rotation_matrix(self, t):
        return matrix_of_quaternion(self.quaternion(t))
