"""Stress tests of numerical stability: frbjax's error against a high-precision reference, next to the
problem's own conditioning floor.

For every case (a body and a time) the script measures

* the **error**: |q_frbjax - q_ref| and |L_frbjax - L_ref| / |L| (componentwise max), where the
  reference is evaluated at 60 digits from the exact binary values of the float64 inputs;
* the **conditioning floor**: how far the reference itself moves when the inputs move by one ulp.
  The reference is evaluated again at PERTURBATIONS copies of the inputs in which every one of the 11
  scalars (3 moments, 3 components of L, 4 of the attitude, the time) is moved by one ulp up or down
  (random signs, fixed seed); the floor is the largest distance (same norms) from the unperturbed
  reference.  No float64 algorithm can be expected to beat this by much: its inputs are only known to
  half an ulp, and evaluating the motion in float64 makes rounding errors of that size.

and reports the ratio error / floor (the target: <= 10 everywhere) per sweep:

(a) ``separatrix``: |d I2 - 1| from 1e-1 down to 1e-16 on both sides (d = 2E/|L|^2), I = (1, 2, 3);
    the x axis is the exact d I2 - 1 of the float64 inputs; plus one body exactly on the separatrix.
(a') ``saddle``: L at a distance 1e-1 ... 1e-15 from the middle axis (where the separatrices cross; d I2 - 1
    ~ distance^2, and the phase u0 ~ K(m) is large), on both sides, |L| t from 0.1 to 100.
(b) ``gaps``: the relative inertia gaps (I2 - I1)/I1 and (I3 - I2)/I2 from 1e-1 down to one ulp, for
    a generic L and for L near the plane of the two close axes.
(c) ``time``: |L| t from 1 to 1e6 (four bodies), error growth per period of L.
(d) ``ratios``: I3/I1 from 10^0.5 to 1e6 (I = (1, sqrt r, r) and (1, 2, r)), and |L| from 1e-6 to 1e6
    (at fixed |L| t).

The reference (``Reference`` below) is an independent closed form written for this script in mpmath
(not frbjax's formulas, not the attitude of docs/theory.md): L(t) from the textbook Jacobi
solution of Euler's equations (mpmath.ellipfun, ellipf), and the attitude as

    q(t) = q0 ⊗ r(0)* ⊗ exp(chi(t)/2 about p) ⊗ r(t),

where p = ±e_k is the principal axis that L circles (sign of L_k, which never changes), r(t) is the
minimal rotation taking l(t) = L(t)/|L| to p, and chi obeys, with x = |l_k| = A dn(u):

    dchi/dt = |L| (d + x/I_k)/(1 + x) = |L| (1/I_k + (d - 1/I_k)/(1 + A dn(u))),

derived here from dq/dt = 1/2 q ⊗ (0, Omega) (the twist of the minimal rotation is p.(l x dl/dt)/(1+x)).
Its integral is int du/(1 + A dn u) = Pi(n; am u|m)/(1 - A^2) - A/sqrt((1-A^2)(1-A^2+A^2 m))
atan2(sqrt(1-A^2+A^2 m) sn, sqrt(1-A^2) cn) with n = -A^2 m/(1 - A^2) (mpmath.ellippi), reduced by
whole half periods 2K of u, which makes |L| t = 1e6 cost no more than t = 1.  On the separatrix it is
elementary.  ``check_reference`` compares this closed form with the 30-digit Taylor integration of the
equations of motion (mpmath.odefun, tests/_reference.py) on both regimes and orbit signs, the exact
separatrix and a symmetric body; the agreement is recorded in the JSON.

Usage: python benchmarks/stability.py [--quick] [--jobs 2] [--output-dir benchmarks/results]
Writes benchmarks/results/stability.json and stability.png (stability_quick.* with --quick).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from fractions import Fraction
from pathlib import Path

import mpmath
import numpy as np


ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
DPS = 60  # digits of the reference (sweeps lose up to ~16 digits to cancellation, ~6 to period reduction)
PERTURBATIONS = 6  # perturbed inputs per case for the conditioning floor (--quick: 3)
EPS = float(np.finfo(np.float64).eps)

# --------------------------------------------------------------------------------------------------
# The reference: an independent closed form in mpmath (no jax here: worker processes import only this).


def _qmul(p, q):
    """Hamilton product of (w, x, y, z) lists."""
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return [
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    ]


def _qconj(q):
    return [q[0], -q[1], -q[2], -q[3]]


def _minimal_rotation(l, p):
    """Unit quaternion of the smallest rotation taking unit l to unit p (needs l.p > -1)."""
    c = sum(a * b for a, b in zip(l, p))
    cross = [l[1] * p[2] - l[2] * p[1], l[2] * p[0] - l[0] * p[2], l[0] * p[1] - l[1] * p[0]]
    norm = mpmath.sqrt(2 * (1 + c))
    return [(1 + c) / norm] + [x / norm for x in cross]


def _sign(x):
    return -1 if x < 0 else 1


class Reference:
    """Exact motion of one body at DPS digits from the exact values of float64 inputs (any moment order)."""

    def __init__(self, inertia, momentum, attitude, dps=DPS):
        inertia, momentum, attitude = (list(map(float, a)) for a in (inertia, momentum, attitude))
        # Working precision: ``dps`` digits beyond what the body needs.  Within 10^-k of the saddle
        # (mc = 1 - m ~ 10^-k) m itself needs k digits, and within 10^-k of a uniform rotation about the
        # pole (1 - A^2 ~ 10^-k) the two terms of H cancel to k digits; a one-ulp perturbation of a zero
        # component (5e-324) makes k ~ 650, so the precision is raised to fit rather than fixed.
        self.dps, self._requested = dps, dps
        while True:
            with mpmath.workdps(self.dps):
                self._setup(inertia, momentum, attitude)
            if self._needed() <= self.dps:
                break
            self.dps = self._needed()

    def _needed(self):
        return self._requested + max(0, self._digits_lost - 20)  # dps covers 20 lost digits by itself

    def _setup(self, inertia, momentum, attitude):
        mpf = mpmath.mpf
        I = [mpf(x) for x in inertia]
        L = [mpf(x) for x in momentum]
        q0 = [mpf(x) for x in attitude]
        qn = mpmath.sqrt(sum(x * x for x in q0))
        self.q0 = [x / qn for x in q0]
        self.I, self.L = I, L
        self.norm = mpmath.sqrt(sum(x * x for x in L))
        # Uniform rotation (Omega parallel to L, L = 0 included), decided exactly in rationals.
        exact_I, exact_L = [Fraction(x) for x in inertia], [Fraction(x) for x in momentum]
        w = [a / b for a, b in zip(exact_L, exact_I)]
        cross = [
            exact_L[1] * w[2] - exact_L[2] * w[1],
            exact_L[2] * w[0] - exact_L[0] * w[2],
            exact_L[0] * w[1] - exact_L[1] * w[0],
        ]
        self._digits_lost = 0
        if all(x == 0 for x in cross):
            self.regime = "uniform"
            return
        # Working frame: sorted moments; an odd permutation flips the middle axis (a proper rotation).
        order = sorted(range(3), key=lambda i: (inertia[i], i))
        inversions = sum(order[i] > order[j] for i in range(3) for j in range(i + 1, 3))
        self.order, self.flip = order, (-1 if inversions % 2 else 1)
        j1, j2, j3 = (I[i] for i in order)
        l = [x / self.norm for x in L]
        w1, w2, w3 = l[order[0]], self.flip * l[order[1]], l[order[2]]
        a, b, c = j2 - j1, j3 - j2, j3 - j1
        g1 = w2 * w2 * a / j2 + w3 * w3 * c / j3  # 1 - d J1 >= 0
        g3 = w1 * w1 * c / j1 + w2 * w2 * b / j2  # d J3 - 1 >= 0
        self.d = w1 * w1 / j1 + w2 * w2 / j2 + w3 * w3 / j3
        e1, e2, e3 = (exact_I[i] for i in order)
        el1, el3 = exact_L[order[0]], exact_L[order[2]]
        side = el1 * el1 * (e2 - e1) * e3 - el3 * el3 * (e3 - e2) * e1  # sign of d J2 - 1, exactly
        self.l_initial = l
        # d J2 - 1 to full relative precision from the exact side (no cancellation at any distance).
        g2 = mpf(side.numerator) / mpf(side.denominator) / (j1 * j3 * sum(x * x for x in L))
        if side < 0:  # around the major axis J3
            self.regime = "major"
            mc = c * (-g2) / (g1 * b)
            self.m = 1 - mc if mc < mpf("0.5") else g3 * a / (g1 * b)
            self.rate = mpmath.sqrt(g1 * b / (j1 * j2 * j3))
            self.amp = [mpmath.sqrt(j1 * g3 / c), mpmath.sqrt(j2 * g3 / b), mpmath.sqrt(j3 * g1 / c)]
            self.s = _sign(w3)
            am0 = mpmath.atan2(w2 * self.amp[0], self.s * w1 * self.amp[1])
            self.pole, self.A, alpha = order[2], self.amp[2], j1 * g3 / c  # alpha = 1 - A^2
        elif side > 0:  # around the minor axis J1
            self.regime = "minor"
            mc = c * g2 / (g3 * a)
            self.m = 1 - mc if mc < mpf("0.5") else g1 * b / (g3 * a)
            self.rate = mpmath.sqrt(g3 * a / (j1 * j2 * j3))
            self.amp = [mpmath.sqrt(j1 * g3 / c), mpmath.sqrt(j2 * g1 / a), mpmath.sqrt(j3 * g1 / c)]
            self.s = _sign(w1)
            am0 = mpmath.atan2(w2 * self.amp[2], self.s * w3 * self.amp[1])
            self.pole, self.A, alpha = order[0], self.amp[0], j3 * g1 / c
        else:  # exactly on the separatrix
            self.regime = "separatrix"
            self.s1, self.s3 = _sign(w1), _sign(w3)
            self.rate = mpmath.sqrt(a * b / (j1 * j3)) / j2
            self.amp = [mpmath.sqrt(j1 * b / (j2 * c)), mpf(1), mpmath.sqrt(j3 * a / (j2 * c))]
            self.u0 = mpmath.atanh(self.s1 * self.s3 * w2)
            self.pole, self.A = order[2], self.amp[2]
        self.pole_sign = _sign(l[self.pole])
        self.pole_inertia = I[self.pole]
        if self.regime != "separatrix":
            small = min(mc, alpha)
            self._digits_lost = max(0, int(-mpmath.log10(small)) + 1) if small > 0 else 0
            if self._needed() > mpmath.mp.dps:
                return  # __init__ retries at a higher precision
            self.u0 = mpmath.ellipf(am0, self.m)
            self.K = mpmath.ellipk(self.m)
            self.alpha, self.beta = alpha, self.A**2 * self.m
            self.n = -j3 * a / (j1 * b) if self.regime == "major" else -j1 * b / (j3 * a)  # = -beta/alpha
            self.arc = self.A / mpmath.sqrt(alpha * (alpha + self.beta))
            self.H_half_period = 2 * mpmath.ellippi(self.n, self.m) / alpha - mpmath.pi * self.arc
        self.H0 = self._jacobi(self.u0)[1]
        p = [mpf(0)] * 3
        p[self.pole] = mpf(self.pole_sign)
        self.p = p
        # q(t) = q0 ⊗ r(0)* ⊗ exp(chi/2 about p) ⊗ r(t)
        self.left = _qmul(self.q0, _qconj(_minimal_rotation(l, p)))

    def _jacobi(self, u):
        """(unit L in body coordinates, H(u) = int_0^u du'/(1 + A dn u')) at phase u."""
        if self.regime == "separatrix":
            sech, tanh = 1 / mpmath.cosh(u), mpmath.tanh(u)
            working = [self.s1 * self.amp[0] * sech, self.s1 * self.s3 * tanh, self.s3 * self.amp[2] * sech]
            A = self.A
            H = u - 2 * A / mpmath.sqrt(1 - A * A) * mpmath.atan(mpmath.sqrt((1 - A) / (1 + A)) * mpmath.tanh(u / 2))
        else:
            turns = mpmath.nint(u / (2 * self.K))
            reduced = u - 2 * turns * self.K
            sn, cn, dn = (mpmath.ellipfun(kind, reduced, m=self.m) for kind in ("sn", "cn", "dn"))
            phi = mpmath.atan2(sn, cn)
            H = (
                turns * self.H_half_period
                + mpmath.ellippi(self.n, phi, self.m) / self.alpha
                - self.arc * mpmath.atan2(mpmath.sqrt(self.alpha + self.beta) * sn, mpmath.sqrt(self.alpha) * cn)
            )
            parity = -1 if int(turns) % 2 else 1
            sn, cn = parity * sn, parity * cn
            s = self.s
            if self.regime == "major":
                working = [s * self.amp[0] * cn, self.amp[1] * sn, s * self.amp[2] * dn]
            else:
                working = [s * self.amp[0] * dn, self.amp[1] * sn, s * self.amp[2] * cn]
        body = [None] * 3
        body[self.order[0]], body[self.order[1]], body[self.order[2]] = working[0], self.flip * working[1], working[2]
        return body, H

    def at(self, t):
        """(L, q) at time t (a float64 value, taken exactly) as lists of mpf at self.dps digits."""
        with mpmath.workdps(self.dps):
            t = mpmath.mpf(float(t))
            if self.regime == "uniform":
                omega = [a / b for a, b in zip(self.L, self.I)]
                speed = mpmath.sqrt(sum(x * x for x in omega))
                if speed == 0:
                    return list(self.L), list(self.q0)
                half = speed * t / 2
                spin = [mpmath.cos(half)] + [mpmath.sin(half) * x / speed for x in omega]
                return list(self.L), _qmul(self.q0, spin)
            tau = self.norm * t
            l, H = self._jacobi(self.u0 + self.rate * tau)
            chi = tau / self.pole_inertia + (self.d - 1 / self.pole_inertia) / self.rate * (H - self.H0)
            turn = [mpmath.cos(chi / 2)] + [mpmath.sin(chi / 2) * x for x in self.p]
            q = _qmul(_qmul(self.left, turn), _minimal_rotation(l, self.p))
            return [self.norm * x for x in l], q


# --------------------------------------------------------------------------------------------------
# Conditioning floor and errors of one body at its times (runs in a worker process).


def perturbations(count, seed):
    """(count, 11) signs +-1: which way each scalar input (I, L, q0, t) moves by one ulp."""
    return np.random.default_rng(seed).choice([-1.0, 1.0], size=(count, 11))


def _ulp_step(values, signs):
    values = np.asarray(values, np.float64)
    return np.nextafter(values, np.where(np.asarray(signs) > 0, np.inf, -np.inf))


def _distance(a, b, scale=1):
    return float(max(abs(x - y) for x, y in zip(a, b)) / scale)


def measure(inertia, momentum, attitude, times, L_frbjax, q_frbjax, signs, dps=DPS):
    """Errors of frbjax and the conditioning floor of one body at each of its times.

    ``L_frbjax`` (K, 3) and ``q_frbjax`` (K, 4) are frbjax's float64 values at ``times`` (K,); ``signs``
    is (P, 11) from ``perturbations``.  Returns a dict of lists over the K times: error_L, error_q
    (|L - L_ref|/|L|, |q - q_ref|, componentwise max), floor_L, floor_q (largest distance of a perturbed
    reference from the reference, same norms), error_q_flipped (|q + q_ref|: a sign error of the lift
    shows up as error_q ~ 1 with this ~ 0), and the reference's period of L in |L| t (None where none).
    """
    inertia, momentum, attitude = (np.asarray(a, np.float64) for a in (inertia, momentum, attitude))
    times = np.asarray(times, np.float64)
    nominal = Reference(inertia, momentum, attitude, dps)
    perturbed = []
    for s in signs:
        body = Reference(_ulp_step(inertia, s[0:3]), _ulp_step(momentum, s[3:6]), _ulp_step(attitude, s[6:10]), dps)
        perturbed.append((body, _ulp_step(times, np.full(times.shape, s[10]))))
    out = {key: [] for key in ("error_L", "error_q", "error_q_flipped", "floor_L", "floor_q")}
    with mpmath.workdps(dps):
        norm = nominal.norm if nominal.norm > 0 else mpmath.mpf(1)
        for k, t in enumerate(times):
            L_ref, q_ref = nominal.at(t)
            L_f = [mpmath.mpf(float(x)) for x in L_frbjax[k]]
            q_f = [mpmath.mpf(float(x)) for x in q_frbjax[k]]
            out["error_L"].append(_distance(L_f, L_ref, norm))
            out["error_q"].append(_distance(q_f, q_ref))
            out["error_q_flipped"].append(_distance(q_f, [-x for x in q_ref]))
            floor_L = floor_q = 0.0
            for body, perturbed_times in perturbed:
                L_p, q_p = body.at(perturbed_times[k])
                floor_L = max(floor_L, _distance(L_p, L_ref, norm))
                floor_q = max(floor_q, _distance(q_p, q_ref))
            out["floor_L"].append(floor_L)
            out["floor_q"].append(floor_q)
        period = None
        if nominal.regime in ("major", "minor"):
            period = float(4 * nominal.K / nominal.rate)
    out["period"] = period
    out["regime"] = nominal.regime
    return out


def _measure_task(args):
    return measure(*args)


def check_reference(inertia, momentum, attitude, times, dps=30):
    """Largest |difference| between ``Reference`` and mpmath.odefun (tests/_reference.py) at ``times``."""
    sys.path.insert(0, str(ROOT / "tests"))
    import _reference

    L_text, q_text = _reference.mpmath_solution(inertia, momentum, attitude, times, dps=dps, digits=dps - 2)
    body = Reference(inertia, momentum, attitude)
    worst_L = worst_q = mpmath.mpf(0)
    with mpmath.workdps(DPS):
        for k, t in enumerate(times):
            L_ref, q_ref = body.at(t)
            worst_L = max(worst_L, max(abs(mpmath.mpf(a) - b) for a, b in zip(L_text[k], L_ref)) / body.norm)
            worst_q = max(worst_q, max(abs(mpmath.mpf(a) - b) for a, b in zip(q_text[k], q_ref)))
    return dict(
        regime=body.regime,
        inertia=list(map(float, inertia)),
        momentum=list(map(float, momentum)),
        times=list(map(float, times)),
        difference_L=float(worst_L),
        difference_q=float(worst_q),
    )


def _check_task(args):
    return check_reference(*args)


# --------------------------------------------------------------------------------------------------
# The sweeps: bodies (float64 inputs) with their times.


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def separatrix_offset(inertia, momentum):
    """d I2 - 1 (I2 the middle moment) of the exact binary values of sorted float64 inputs."""
    i1, i2, i3 = (Fraction(float(x)) for x in inertia)
    l1, l2, l3 = (Fraction(float(x)) for x in momentum)
    return float((l1 * l1 * (i2 - i1) / i1 - l3 * l3 * (i3 - i2) / i3) / (l1 * l1 + l2 * l2 + l3 * l3))


def near_separatrix(inertia, offset, l2, signs=(1, 1, 1), search=3):
    """Unit-ish float64 L with d I2 - 1 as close to ``offset`` as float64 allows (same sign).

    Starts from the rounded exact solution (l1^2 = ((1 - l2^2) b + offset)/(a + b), l3^2 = ((1 - l2^2) a
    - offset)/(a + b), a = (I2 - I1)/I1, b = (I3 - I2)/I3) and tries l1, l3 within ``search`` ulps.
    """
    with mpmath.workdps(50):
        i1, i2, i3 = (mpmath.mpf(float(x)) for x in inertia)
        a, b = (i2 - i1) / i1, (i3 - i2) / i3
        rest = 1 - mpmath.mpf(float(l2)) ** 2
        l1 = float(mpmath.sqrt((rest * b + offset) / (a + b)))
        l3 = float(mpmath.sqrt((rest * a - offset) / (a + b)))
    best, best_score = None, math.inf
    for i in range(-search, search + 1):
        for j in range(-search, search + 1):
            c1 = l1 + i * np.spacing(l1)
            c3 = l3 + j * np.spacing(l3)
            candidate = np.array([signs[0] * c1, signs[1] * float(l2), signs[2] * c3])
            actual = separatrix_offset(inertia, candidate)
            score = abs(math.log(actual / offset)) if actual * offset > 0 else math.inf
            if score < best_score:
                best, best_score = candidate, score
    return best


GENERIC = (0.48, 0.6, 0.64)


def build_cases(quick=False, seed=0):
    """The bodies of every sweep: list of dicts (sweep, series, x, inertia, momentum, attitude, times)."""
    rng = np.random.default_rng(seed)
    cases = []

    def add(sweep, series, x, inertia, momentum, taus):
        momentum = np.asarray(momentum, np.float64)
        norm = float(np.linalg.norm(momentum))
        attitude = _unit(rng.normal(size=4))
        times = [float(tau / norm) for tau in taus]
        cases.append(
            dict(
                sweep=sweep,
                series=series,
                x=float(x),
                inertia=[float(v) for v in inertia],
                momentum=momentum.tolist(),
                attitude=attitude.tolist(),
                times=times,
                taus=[float(tau) for tau in taus],
            )
        )

    taus = (1.0, -10.0, 100.0, -1000.0)
    # (a) |d I2 - 1| from 1e-1 to 1e-16 on both sides of the separatrix, I = (1, 2, 3), L2 = 0.3.
    exponents = (1, 4, 8, 12, 16) if quick else range(1, 17)
    inertia = (1.0, 2.0, 3.0)
    for k in exponents:
        for side in (1, -1):
            signs = tuple(rng.choice([-1, 1], 3))
            momentum = near_separatrix(inertia, side * 10.0**-k, 0.3, signs)
            offset = separatrix_offset(inertia, momentum)
            add(
                "separatrix",
                "d I2 > 1 (around I1)" if side > 0 else "d I2 < 1 (around I3)",
                abs(offset),
                inertia,
                momentum,
                taus,
            )
    # exactly on the separatrix: I = (1, 1.5, 3), L = (1, 0.3, 1) has d I2 - 1 = 0 exactly.
    add("separatrix", "d I2 = 1 exactly", 0.0, (1.0, 1.5, 3.0), (1.0, 0.3, 1.0), taus)

    # (a') L near the middle axis (the saddle, where the separatrices cross): distance 1e-1 .. 1e-15,
    # so d I2 - 1 ~ distance^2 and the phase u0 ~ K(m) is large; short and long times.
    exponents = (1, 8, 15) if quick else range(1, 16)
    for k in exponents:
        for direction, series in (
            ((0.6, 0.0, 0.8), "d I2 > 1 (around I1)"),
            ((0.3, 0.0, 0.95), "d I2 < 1 (around I3)"),
        ):
            signs = rng.choice([-1.0, 1.0], 3)
            momentum = signs * (np.array([0.0, 1.0, 0.0]) + 10.0**-k * _unit(direction))
            add(
                "saddle",
                series,
                math.hypot(momentum[0], momentum[2]) / np.linalg.norm(momentum),
                inertia,
                momentum,
                (0.1, -1.0, 10.0, -100.0),
            )

    # (b) relative gaps (I2 - I1)/I1 and (I3 - I2)/I2 from 1e-1 down to one ulp.
    exponents = (1, 8, 16) if quick else range(1, 17)
    for k in exponents:
        if k < 16:
            lower = (1.0, float(1 + 10.0**-k), 3.0)
            upper = (1.0, 2.0, float(2 * (1 + 10.0**-k)))
        else:  # one ulp
            lower = (1.0 - 2.0**-53, 1.0, 3.0)
            upper = (1.0, 2.0 - 2.0**-52, 2.0)
        gap_lower = float((Fraction(lower[1]) - Fraction(lower[0])) / Fraction(lower[0]))
        gap_upper = float((Fraction(upper[2]) - Fraction(upper[1])) / Fraction(upper[1]))
        add("gaps", "(I2-I1)/I1, generic L", gap_lower, lower, _unit(GENERIC), taus)
        add("gaps", "(I2-I1)/I1, L near the 1-2 plane", gap_lower, lower, _unit((0.6, 0.79, 0.12)), taus)
        add("gaps", "(I3-I2)/I2, generic L", gap_upper, upper, _unit(GENERIC), taus)
        add("gaps", "(I3-I2)/I2, L near the 2-3 plane", gap_upper, upper, _unit((0.12, 0.6, 0.79)), taus)

    # (c) |L| t from 1 to 1e6.
    long_taus = [10.0 ** (i / (1 if quick else 4)) for i in range(0, 7 if quick else 25)]
    add("time", "generic, around I3", 0, (1.0, 2.0, 3.0), _unit((0.3, 0.2, 0.93)), long_taus)
    add("time", "generic, around I1", 0, (1.0, 2.0, 3.0), _unit((0.93, 0.2, 0.3)), long_taus)
    if not quick:
        add("time", "|d I2 - 1| = 1e-6", 0, (1.0, 2.0, 3.0), near_separatrix((1.0, 2.0, 3.0), -1e-6, 0.3), long_taus)
        add("time", "(I2-I1)/I1 = 1e-9", 0, (1.0, float(1 + 1e-9), 3.0), _unit(GENERIC), long_taus)

    # (d) extreme ratios I3/I1 up to 1e6, and |L| from 1e-6 to 1e6.
    short_taus = (1.0, -10.0, 100.0)
    exponents = (1, 6, 12) if quick else range(1, 13)
    for k in exponents:
        r = 10.0 ** (k / 2)
        add("ratios", "I = (1, sqrt r, r)", r, (1.0, math.sqrt(r), r), _unit(GENERIC), short_taus)
        add("ratios", "I = (1, 2, r)", r, (1.0, 2.0, r), _unit(GENERIC), short_taus)
    exponents = (-6, 0, 6) if quick else range(-6, 7)
    for k in exponents:
        add("momentum", "I = (1, 2, 3), |L| t fixed", 10.0**k, (1.0, 2.0, 3.0), 10.0**k * _unit(GENERIC), short_taus)
    return cases


# The reference checks against mpmath.odefun: (inertia, momentum, times); attitudes drawn in main.
CHECKS = [
    ((1.0, 2.0, 3.0), (0.3, -0.2, -0.93), (3.0, 20.0)),  # around I3, L3 < 0, past a half period of u
    ((3.0, 1.0, 2.0), (0.2, 0.93, -0.3), (-3.0, -20.0)),  # around I1, moments unsorted, backwards
    ((1.0, 1.5, 3.0), (-1.0, 0.3, 1.0), (5.0, 15.0)),  # exactly on the separatrix
    ((1.0, 2.0, 3.0), (0.5469389154354, 0.3, -0.7815228398549), (10.0,)),  # |d I2 - 1| ~ 1e-3
    ((1.0, 1.0, 3.0), (0.3, 0.4, 0.8), (10.0,)),  # symmetric, m = 0
    ((1.0, 1e3, 1e6), (0.48, 0.6, 0.64), (10.0,)),  # I3/I1 = 1e6
]


# --------------------------------------------------------------------------------------------------
# frbjax's values (jax is imported here only: the worker processes never load it).

CHUNK = 1024  # pairs (body, time) per jit call: one compilation for the whole run


def frbjax_values(cases):
    """frbjax's (L, q) for every case at its times, float64, jit-compiled in chunks of CHUNK pairs."""
    import jax
    import jax.numpy as jnp

    from frbjax import FreeRigidBody

    @jax.jit
    def evaluate(inertia, momentum, attitude, t):
        body = FreeRigidBody(inertia, momentum, attitude)
        return body.angular_momentum(t), body.quaternion(t)

    pairs = [(c["inertia"], c["momentum"], c["attitude"], t) for c in cases for t in c["times"]]
    columns = [np.array([p[i] for p in pairs], np.float64) for i in range(4)]
    total = len(pairs)
    padded = -(-total // CHUNK) * CHUNK
    columns = [np.concatenate([a, np.repeat(a[:1], padded - total, axis=0)]) for a in columns]
    L, q = [], []
    for start in range(0, padded, CHUNK):
        values = evaluate(*(jnp.asarray(a[start : start + CHUNK]) for a in columns))
        L.append(np.asarray(values[0]))
        q.append(np.asarray(values[1]))
    L, q = np.concatenate(L)[:total], np.concatenate(q)[:total]
    out, k = [], 0
    for c in cases:
        n = len(c["times"])
        out.append((L[k : k + n], q[k : k + n]))
        k += n
    return out


# --------------------------------------------------------------------------------------------------
# Summary, plots, main.

SWEEPS = ("separatrix", "saddle", "gaps", "time", "ratios", "momentum")
X_LABELS = dict(
    separatrix="|d I2 - 1| (exact, of the float64 inputs)",
    saddle="distance of L/|L| from the middle axis",
    gaps="relative inertia gap",
    time="|L| t",
    ratios="I3 / I1",
    momentum="|L|",
)


def summarize(cases):
    """Worst ratios error/floor per sweep (and error / max(floor, eps)), with the case that gives each."""
    summary = {}
    for sweep in SWEEPS:
        rows = [(c, k) for c in cases if c["sweep"] == sweep for k in range(len(c["times"]))]
        entry = {}
        for quantity in ("q", "L"):
            worst = {}
            for name, floor_of in (("ratio", lambda f: f), ("ratio_eps", lambda f: max(f, EPS))):
                best = None
                for c, k in rows:
                    error, floor = c[f"error_{quantity}"][k], c[f"floor_{quantity}"][k]
                    ratio = error / floor_of(floor) if floor_of(floor) > 0 else (0.0 if error == 0 else math.inf)
                    if best is None or ratio > best[0]:
                        best = (ratio, c, k)
                ratio, c, k = best
                worst[name] = dict(
                    value=ratio,
                    series=c["series"],
                    x=c["x"],
                    tau=c["taus"][k],
                    error=c[f"error_{quantity}"][k],
                    floor=c[f"floor_{quantity}"][k],
                )
            worst["max_error"] = max(c[f"error_{quantity}"][k] for c, k in rows)
            entry[quantity] = worst
        entry["lift_sign_errors"] = sum(1 for c, k in rows if c["error_q"][k] > 0.5 and c["error_q_flipped"][k] < 1e-6)
        summary[sweep] = entry
    growth = {}
    for c in cases:
        if c["sweep"] != "time":
            continue
        taus, errors, floors = np.array(c["taus"]), np.array(c["error_q"]), np.array(c["floor_q"])
        late = taus >= 1e2
        slope = float(np.polyfit(np.log10(taus[late]), np.log10(np.maximum(errors[late], 1e-18)), 1)[0])
        periods = taus[-1] / c["period"] if c["period"] else None
        growth[c["series"]] = dict(
            period=c["period"],
            periods_at_end=periods,
            error_q_at_end=float(errors[-1]),
            floor_q_at_end=float(floors[-1]),
            error_q_per_period=float(errors[-1] / periods) if periods else None,
            loglog_slope_of_error_q_beyond_tau_100=slope,
        )
    summary["time"]["growth"] = growth
    return summary


def plot(cases, summary, path, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(SWEEPS), figsize=(4.2 * len(SWEEPS), 8), squeeze=False)
    for column, sweep in enumerate(SWEEPS):
        top, bottom = axes[0, column], axes[1, column]
        chosen = [c for c in cases if c["sweep"] == sweep]
        series = list(dict.fromkeys(c["series"] for c in chosen))
        for index, name in enumerate(series):
            color = f"C{index}"
            rows = [c for c in chosen if c["series"] == name]
            if sweep == "time":
                c = rows[0]
                x = np.array(c["taus"])
                error_q, floor_q = np.array(c["error_q"]), np.array(c["floor_q"])
                error_L = np.array(c["error_L"])
                ratio = error_q / np.maximum(floor_q, EPS)
            else:
                rows = [c for c in rows if c["x"] > 0]  # the exact-separatrix point has no place on a log axis
                if not rows:
                    continue
                x = np.array([c["x"] for c in rows])
                error_q = np.array([max(c["error_q"]) for c in rows])
                floor_q = np.array([max(c["floor_q"]) for c in rows])
                error_L = np.array([max(c["error_L"]) for c in rows])
                ratio = np.array([max(e / max(f, EPS) for e, f in zip(c["error_q"], c["floor_q"])) for c in rows])
            top.loglog(x, np.maximum(error_q, 1e-18), "o-", color=color, ms=4, label=f"{name}: q error")
            top.loglog(x, np.maximum(floor_q, 1e-18), "--", color=color, lw=1, label="q floor")
            top.loglog(x, np.maximum(error_L, 1e-18), "x:", color=color, ms=4, lw=0.8, label="L error")
            bottom.semilogx(x, ratio, "o-", color=color, ms=4, label=name)
        bottom.axhline(10, color="k", lw=0.8, ls="--")
        top.set_title(sweep)
        top.set_xlabel(X_LABELS[sweep])
        bottom.set_xlabel(X_LABELS[sweep])
        top.set_ylabel("error, floor (max over the body's times)" if sweep != "time" else "error, floor")
        bottom.set_ylabel("q error / max(floor, eps)")
        bottom.set_yscale("log")
        top.legend(fontsize=6)
        bottom.legend(fontsize=6)
        if sweep in ("separatrix", "saddle", "gaps"):
            top.invert_xaxis()
            bottom.invert_xaxis()
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="CI sizes (a few points per sweep)")
    parser.add_argument("--jobs", type=int, default=2, help="processes for the mpmath references")
    parser.add_argument("--output-dir", type=Path, default=RESULTS)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)  # a script: the library itself never does this
    start = time.perf_counter()
    cases = build_cases(args.quick, args.seed)
    values = frbjax_values(cases)
    frbjax_seconds = time.perf_counter() - start
    print(
        f"{len(cases)} bodies, {sum(len(c['times']) for c in cases)} (body, time) pairs; "
        f"frbjax {frbjax_seconds:.1f} s (with compilation)",
        flush=True,
    )

    count = 3 if args.quick else PERTURBATIONS
    rng = np.random.default_rng(args.seed + 1)
    tasks = [
        (c["inertia"], c["momentum"], c["attitude"], c["times"], L, q, perturbations(count, i))
        for i, (c, (L, q)) in enumerate(zip(cases, values))
    ]
    checks = CHECKS[:2] if args.quick else CHECKS
    check_tasks = [(i, m, _unit(rng.normal(size=4)), t) for i, m, t in checks]
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=args.jobs, mp_context=context) as pool:
        check_futures = [pool.submit(_check_task, t) for t in check_tasks]
        results = list(pool.map(_measure_task, tasks, chunksize=1))
        check_results = [f.result() for f in check_futures]
    for c, r in zip(cases, results):
        c.update(r)
    summary = summarize(cases)
    elapsed = time.perf_counter() - start

    print(
        f"reference checks against mpmath.odefun (30 digits): worst "
        f"{max(max(r['difference_L'], r['difference_q']) for r in check_results):.1e}"
    )
    print(
        f"{'sweep':<11} {'q: err/floor':>12} {'err/max(floor,eps)':>19} {'max err':>9}   "
        f"{'L: err/floor':>12} {'err/max(floor,eps)':>19} {'max err':>9}"
    )
    for sweep in SWEEPS:
        s = summary[sweep]
        print(
            f"{sweep:<11} {s['q']['ratio']['value']:12.3g} {s['q']['ratio_eps']['value']:19.3g} "
            f"{s['q']['max_error']:9.2g}   {s['L']['ratio']['value']:12.3g} "
            f"{s['L']['ratio_eps']['value']:19.3g} {s['L']['max_error']:9.2g}"
        )
    for name, g in summary["time"]["growth"].items():
        per = g["error_q_per_period"]
        print(
            f"  time, {name}: q error {g['error_q_at_end']:.2g} (floor {g['floor_q_at_end']:.2g}) at |L| t = 1e6"
            + (f", {g['periods_at_end']:.3g} periods, {per:.2g} per period" if per else "")
            + f", slope {g['loglog_slope_of_error_q_beyond_tau_100']:.2f}"
        )
    print(f"total {elapsed:.0f} s")

    stem = "stability_quick" if args.quick else "stability"
    args.output_dir.mkdir(parents=True, exist_ok=True)
    result = dict(
        quick=args.quick,
        perturbations=count,
        reference_digits=DPS,
        seconds=elapsed,
        frbjax_seconds_with_compilation=frbjax_seconds,
        jax_version=jax.__version__,
        reference_checks=check_results,
        summary=summary,
        cases=cases,
    )
    (args.output_dir / f"{stem}.json").write_text(json.dumps(result, indent=1))
    plot(
        cases,
        summary,
        args.output_dir / f"{stem}.png",
        f"frbjax float64: error against a {DPS}-digit reference and the 1-ulp conditioning floor",
    )
    return result


if __name__ == "__main__":
    main()
