"""FreeRigidBody: invariants, the flow's group property, time reversal, long times, shapes, jit/vmap.

No reference solution is needed here: the exact motion conserves |L|, the energy 1/2 sum L_i^2 / I_i and
the spatial angular momentum R(t) L(t) = q ⊗ L ⊗ q*; |q| = 1; the flow is a one-parameter group
(evolving by t1 and then by t2 is evolving by t1 + t2) and is reversible; q is continuous in t with
|dq/dt| = |Omega| / 2.  Relative errors are relative to |L| (or to the energy).  The bodies are seeded
random ones (moments in [0.3, 3] in any order, random directions of L, |L| from 1e-3 to 1e3, random
attitudes) plus the special families of ``special_bodies``.
"""

from __future__ import annotations

import functools

import _reference as ref
import numpy as np
import pytest


EPS = np.finfo(np.float64).eps
SEED = 31415


def random_bodies(rng, n, log_magnitude=(-3.0, 3.0)):
    inertia = rng.uniform(0.3, 3.0, (n, 3))
    norm = 10.0 ** rng.uniform(*log_magnitude, (n, 1))
    return inertia, ref.random_directions(rng, n) * norm, ref.random_attitudes(rng, n)


def invariant_errors(inertia, momentum, attitude, L, q, R):
    """Worst errors (over bodies and times) of each invariant, relative to |L| or to the energy."""
    norm = np.linalg.norm(momentum, axis=-1)[:, None]
    energy = 0.5 * np.sum(momentum**2 / inertia, -1)[:, None]
    spatial = ref.rotate(attitude / np.linalg.norm(attitude, axis=-1, keepdims=True), momentum)[:, None]
    return dict(
        quaternion_norm=np.abs(np.linalg.norm(q, axis=-1) - 1).max(),
        momentum_norm=(np.abs(np.linalg.norm(L, axis=-1) - norm) / norm).max(),
        energy=(np.abs(0.5 * np.sum(L**2 / inertia[:, None], -1) - energy) / energy).max(),
        spatial_momentum_R=(np.abs(np.einsum("nkij,nkj->nki", R, L) - spatial).max(-1) / norm).max(),
        spatial_momentum_q=(np.abs(ref.rotate(q, L) - spatial).max(-1) / norm).max(),
        matrix_of_quaternion=np.abs(R - ref.matrix_of(q)).max(),
        orthogonality=np.abs(np.einsum("nkji,nkjl->nkil", R, R) - np.eye(3)).max(),
    )


# --------------------------------------------------------------------------------------------------
# Invariants: random bodies at random times with |L| |t| from 1e-3 to 1e4.

# Measured worst (seed 31415, 64 bodies x 32 times) and tolerances.  The accuracy target for |q| = 1,
# energy, |L| and R(t) L(t) constant is 1e-14; the tolerances are ~2x the measured worst, all below it.
ACCURACY_TARGET = 1e-14
TARGETED_INVARIANTS = ("quaternion_norm", "momentum_norm", "energy", "spatial_momentum_R", "spatial_momentum_q")
RANDOM_TOLERANCE = dict(
    quaternion_norm=4.5e-16,  # measured 2.2e-16 (q is renormalised once per evaluation)
    momentum_norm=1e-15,  # measured 4.8e-16
    energy=1.6e-15,  # measured 8.1e-16
    spatial_momentum_R=3.5e-15,  # measured 1.7e-15
    spatial_momentum_q=3.5e-15,  # measured 1.6e-15 (q ⊗ L ⊗ q*)
    matrix_of_quaternion=1.2e-15,  # measured 5.6e-16 (rotation_matrix against the matrix of quaternion)
    orthogonality=4e-15,  # measured 2.0e-15 (R^T R - 1; not a targeted invariant)
)
# The one-time path (addition theorems, docs/theory.md §11) over the same bodies and times: the
# energy and the spatial momentum come out a few tenths of an ulp less exact than from the series
# (measured 1.9e-15, 4.3e-15 and 4.3e-15); the other invariants within the tolerances above.
ONE_TIME_TOLERANCE_CHANGES = dict(energy=2.5e-15, spatial_momentum_R=5.5e-15, spatial_momentum_q=5.5e-15)


@pytest.fixture(scope="module", params=ref.PATHS)
def random_motion(request):
    rng = np.random.default_rng(SEED)
    inertia, momentum, attitude = random_bodies(rng, 64)
    tau = 10.0 ** rng.uniform(-3, 4, (64, 32)) * rng.choice([-1.0, 1.0], (64, 32))
    times = tau / np.linalg.norm(momentum, axis=-1)[:, None]
    L, q, R = ref.evaluate(
        inertia, momentum, attitude, times, ("angular_momentum", "quaternion", "rotation_matrix"), request.param
    )
    return inertia, momentum, attitude, L, q, R, request.param


@pytest.mark.parametrize("invariant", sorted(RANDOM_TOLERANCE))
def test_invariants_random_bodies(random_motion, invariant):
    *motion, path = random_motion
    errors = invariant_errors(*motion)
    assert np.isfinite(motion[4]).all()
    tolerance = RANDOM_TOLERANCE[invariant]
    if path == "one_time":
        tolerance = ONE_TIME_TOLERANCE_CHANGES.get(invariant, tolerance)
    assert errors[invariant] <= tolerance, f"{invariant}: {errors[invariant]:.2e}"


# --------------------------------------------------------------------------------------------------
# Invariants of special bodies (symmetric, spherical, on and next to the separatrix, principal axes).


def special_bodies():
    """dict family -> (inertia, momentum) lists; attitudes and times are drawn in the fixture."""
    ulp = EPS
    sep = lambda inertia, offset, l2: ref.separatrix_momentum(inertia, offset, l2)  # noqa: E731
    return {
        "symmetric": [
            ((1.0, 1.0, 2.0), (0.3, -0.5, 0.8)),
            ((2.0, 1.0, 1.0), (0.6, 0.6, -0.5)),
            ((0.7, 1.4, 1.4), (-0.2, 0.9, 0.4)),
        ],
        "sphere": [((1.5, 1.5, 1.5), (0.3, -0.5, 0.8)), ((0.4, 0.4, 0.4), (-2.0, 1.0, 0.5))],
        "near_sphere": [
            ((1.0, 1.0 + 1e-10, 1.0 + 2e-10), (0.3, -0.5, 0.8)),
            ((1.0, 1.0 + ulp, 1.0 + 2 * ulp), (-0.29, 0.85, -0.44)),
            ((2.0 + 6 * ulp, 2.0, 2.0 + 2 * ulp), (0.27, -0.75, 0.6)),
        ],
        "on_separatrix": [
            ((1.0, 3.0, 6.0), (1.0, 2.0, 2.0)),
            ((6.0, 1.0, 3.0), (2.0, -1.0, 2.0)),
            ((1.0, 2.0, 4.0), (1.0, 0.5, np.sqrt(2.0))),
        ],
        "near_separatrix": [
            ((1.0, 2.0, 3.0), sep((1.0, 2.0, 3.0), 1e-12, 0.3)),
            ((1.0, 2.0, 3.0), sep((1.0, 2.0, 3.0), -1e-12, -0.6)),
        ],
        "principal_axis": [
            ((2.0, 0.8, 1.3), (1.0, 0.0, 0.0)),
            ((2.0, 0.8, 1.3), (0.0, -3.0, 0.0)),
            ((2.0, 0.8, 1.3), (0.0, 0.0, 0.5)),
        ],
        "near_middle_axis": [((2.0, 0.8, 1.3), (1e-10, -2e-10, 1.0)), ((2.0, 0.8, 1.3), (3e-7, 1e-7, -1.0))],
    }


# Tolerance on the worst of all invariants (as in RANDOM_TOLERANCE) of each family, 16 times with |L| |t|
# from 1e-2 to 1e3: ~2x the measured worst (always R^T R - 1 here); in addition the targeted invariants
# must be within the target 1e-14.
SPECIAL_TOLERANCE = {
    # measured 4.2e-14; FAILS the target: q ⊗ L ⊗ q* off by 1.1e-14 and R L by 1.0e-14 for
    # I = (0.7, 1.4, 1.4), L = (-0.2, 0.9, 0.4) at |L| t = 250, where |q| - 1 = 5.6e-15.
    "symmetric": 8e-14,
    "sphere": 4e-15,  # measured 1.8e-15
    "near_sphere": 5e-15,  # measured 2.2e-15 (q is wrong there, about L: test_body_diffrax)
    "on_separatrix": 5e-15,  # measured 2.2e-15
    "near_separatrix": 6e-15,  # measured 2.9e-15
    "principal_axis": 4e-15,  # measured 2.0e-15
    "near_middle_axis": 6e-15,  # measured 1.8e-15 (2.7e-15 with the bodies batched differently)
}


@pytest.fixture(scope="module", params=ref.PATHS)
def special_motion(request):
    rng = np.random.default_rng(SEED + 1)
    rows = [
        (family, np.array(i, float), np.array(l, float)) for family, items in special_bodies().items() for i, l in items
    ]
    families = np.array([r[0] for r in rows])
    inertia, momentum = np.stack([r[1] for r in rows]), np.stack([r[2] for r in rows])
    attitude = ref.random_attitudes(rng, len(rows))
    tau = 10.0 ** rng.uniform(-2, 3, (len(rows), 16)) * rng.choice([-1.0, 1.0], (len(rows), 16))
    times = tau / np.linalg.norm(momentum, axis=-1)[:, None]
    L, q, R = ref.evaluate(
        inertia, momentum, attitude, times, ("angular_momentum", "quaternion", "rotation_matrix"), request.param
    )
    return families, (inertia, momentum, attitude, L, q, R)


def measure_special(special_motion, family):
    families, arrays = special_motion
    rows = families == family
    errors = invariant_errors(*(a[rows] for a in arrays))
    return max(errors.values()), errors


@pytest.mark.parametrize("family", sorted(SPECIAL_TOLERANCE))
def test_invariants_special_bodies(special_motion, family):
    worst, errors = measure_special(special_motion, family)
    assert np.isfinite(special_motion[1][4]).all()
    assert worst <= SPECIAL_TOLERANCE[family], f"{family}: {errors}"
    for name in TARGETED_INVARIANTS:
        assert errors[name] <= ACCURACY_TARGET, f"{family}: {name} {errors[name]:.2e}"


def test_zero_momentum():
    """L = 0: L(t) = 0 and q(t) = the normalised attitude, exactly (uniform rotation at rate 0)."""
    inertia = np.array([[1.0, 2.0, 3.0], [0.5, 0.5, 0.9], [1.0, 1.0, 1.0]])
    attitude = np.array([[0.5, -0.5, 0.5, 0.5], [2.0, 0.0, 0.0, 0.0], [0.1, 0.2, -0.3, 0.4]])
    times = np.array([[-1e6, -1.0, 0.0, 1e-3, 7.0, 1e6]] * 3)
    L, q = ref.evaluate(inertia, np.zeros((3, 3)), attitude, times)
    unit = attitude / np.linalg.norm(attitude, axis=-1, keepdims=True)
    assert (L == 0).all()
    assert np.abs(q - unit[:, None]).max() <= 2 * EPS  # measured: 0 (q(t) is the normalised attitude)


# --------------------------------------------------------------------------------------------------
# t = 0, the group property, time reversal.


def measure_initial_values():
    """q(0) against attitude / |attitude| (attitudes scaled by 1e-3 .. 1e3) and L(0) against L0, in eps."""
    rng = np.random.default_rng(SEED + 2)
    inertia, momentum, attitude = random_bodies(rng, 32)
    attitude = attitude * 10.0 ** rng.uniform(-3, 3, (32, 1))
    special = special_bodies()
    families = ("symmetric", "on_separatrix", "near_separatrix", "principal_axis")
    extra = [b for family in families for b in special[family]]
    inertia = np.concatenate([inertia, [b[0] for b in extra]])
    momentum = np.concatenate([momentum, [b[1] for b in extra]])
    attitude = np.concatenate([attitude, ref.random_attitudes(rng, len(extra))])
    L, q = ref.evaluate(inertia, momentum, attitude, np.zeros((len(inertia), 1)))
    unit = attitude / np.linalg.norm(attitude, axis=-1, keepdims=True)
    error_q = np.abs(q[:, 0] - unit).max() / EPS
    error_L = (np.abs(L[:, 0] - momentum).max(-1) / np.linalg.norm(momentum, axis=-1)).max() / EPS
    return error_L, error_q


def test_initial_values():
    """Measured: L(0) within 1.34 eps of L0 (relative to |L|), q(0) within 2.0 eps of the normalised
    attitude (attitudes of norm 1e-3 .. 1e3); 1.25 and 1.5 eps with the bodies batched differently."""
    error_L, error_q = measure_initial_values()
    assert error_L <= 3.0
    assert error_q <= 4.0


LONG_TIMES = (1e2, 1e4, 1e6)


@functools.cache
def group_measurements(count=48, tau_max=50.0, seed=SEED + 3):
    """Evolve by t1, restart from (L(t1), q(t1)) and evolve by t2; compare with evolving by t1 + t2.

    Also evolve the restarted body by -t1 (time reversal: back to the initial state).  |L| t2 is uniform
    in [-tau_max, tau_max]; |L| t1 too for the set ``None``, and |L| |t1| = tau for each tau in
    LONG_TIMES.  Returns {set: ((L / |L|, q) errors of the group property, same for reversal, finite)}.
    """
    rng = np.random.default_rng(seed)
    sets = (None,) + LONG_TIMES
    inertia, momentum, attitude = random_bodies(rng, count, (-1.0, 1.0))
    norm = np.linalg.norm(momentum, axis=-1)
    t1 = [rng.uniform(-tau_max, tau_max, count) / norm] + [
        tau * rng.choice([-1.0, 1.0], count) / norm for tau in LONG_TIMES
    ]
    t2 = [rng.uniform(-tau_max, tau_max, count) / norm for _ in sets]
    t1, t2 = np.concatenate(t1), np.concatenate(t2)
    tile = lambda a: np.concatenate([a] * len(sets))  # noqa: E731
    inertia, momentum, attitude, norm = tile(inertia), tile(momentum), tile(attitude), tile(norm)
    L1, q1 = ref.evaluate(inertia, momentum, attitude, np.stack([t1, t1 + t2], 1))
    L2, q2 = ref.evaluate(inertia, L1[:, 0], q1[:, 0], np.stack([t2, -t1], 1))
    out = {}
    for k, key in enumerate(sets):
        rows = slice(k * count, (k + 1) * count)
        group = (
            (np.abs(L2[rows, 0] - L1[rows, 1]).max(-1) / norm[rows]).max(),
            np.abs(q2[rows, 0] - q1[rows, 1]).max(),
        )
        reverse = (
            (np.abs(L2[rows, 1] - momentum[rows]).max(-1) / norm[rows]).max(),
            np.abs(q2[rows, 1] - attitude[rows]).max(),
        )
        finite = all(np.isfinite(a[rows]).all() for a in (L1, q1, L2, q2))
        out[key] = group, reverse, finite
    return out


def test_group_property_and_time_reversal():
    """|L| t1, |L| t2 in [-50, 50].  Measured: group L 6.7e-15, q 1.1e-14; reversal L 1.5e-14, q 9.7e-15
    (another draw of 48 bodies: group L 3.5e-14, q 1.4e-14)."""
    (group_L, group_q), (reverse_L, reverse_q), finite = group_measurements()[None]
    assert finite
    assert group_L <= 6e-14
    assert group_q <= 3e-14
    assert reverse_L <= 3e-14
    assert reverse_q <= 2e-14


# --------------------------------------------------------------------------------------------------
# Long times: |L| t up to 1e6.  The time itself is known to eps |t|, and the phase of the motion with
# it, so the error of q(t) cannot be much better than eps |L| t: the tests bound the errors by a
# constant times eps |L| t (error growth at most linear in the number of periods).


def test_long_times_group_property():
    """|L| |t1| = 1e2, 1e4, 1e6, |L| t2 in [-50, 50]: worst error / (eps |L| |t1|) measured 1.43, 1.62,
    1.30 (1e2, 1e4, 1e6; the largest of group and reversal, L and q; 1.87 at 1e6 for another draw)."""
    measurements = group_measurements()
    for tau_long in LONG_TIMES:
        (group_L, group_q), (reverse_L, reverse_q), finite = measurements[tau_long]
        assert finite, tau_long
        worst = max(group_L, group_q, reverse_L, reverse_q)
        assert worst <= 3.0 * EPS * tau_long, f"|L| t1 = {tau_long:g}: {worst:.2e}"


@functools.cache
def composition_measurements(steps=8, count=16, seed=SEED + 4):
    """q(T) against the composition of ``steps`` exact steps of T / steps (restarting each time), for
    |L| |T| in LONG_TIMES, |L| from 1e-3 to 1e3.  Returns {tau: (L / |L| error, q error, finite)}."""
    rng = np.random.default_rng(seed)
    inertia, momentum, attitude = random_bodies(rng, count, (-3.0, 3.0))
    norm = np.linalg.norm(momentum, axis=-1)
    total = np.concatenate([tau * rng.choice([-1.0, 1.0], count) / norm for tau in LONG_TIMES])
    tile = lambda a: np.concatenate([a] * len(LONG_TIMES))  # noqa: E731
    inertia, momentum, attitude, norm = tile(inertia), tile(momentum), tile(attitude), tile(norm)
    step = total / steps
    L, q = ref.evaluate(inertia, momentum, attitude, np.stack([step, total], 1))
    L_direct, q_direct = L[:, 1:], q[:, 1:]
    L, q = L[:, 0], q[:, 0]
    for _ in range(steps - 1):
        L, q = ref.evaluate(inertia, L, q, step[:, None])
        L, q = L[:, 0], q[:, 0]
    out = {}
    for k, tau in enumerate(LONG_TIMES):
        rows = slice(k * count, (k + 1) * count)
        error_L = (np.abs(L[rows] - L_direct[rows, 0]).max(-1) / norm[rows]).max()
        error_q = np.abs(q[rows] - q_direct[rows, 0]).max()
        out[tau] = error_L, error_q, np.isfinite(q_direct[rows]).all() and np.isfinite(L_direct[rows]).all()
    return out


def test_long_times_composition():
    """Worst error / (eps |L| T) measured: 2.96, 1.62, 4.32 (1e2, 1e4, 1e6; 2.56, 1.62, 2.64 before
    the Jacobi functions stopped at each parameter's own AGM level, 2026-11-26).

    The difference is ulp-level errors of the state at each of the 7 restarts, carried over the rest
    of T by the phase they shift (the frequency depends on L): any ulp-level change of the
    evaluation moves the worst of 16 bodies by up to 1.7x either way.  Over six seeds the worst was
    4.32 (3.10 before), while the Jacobi functions themselves got more accurate (largest error
    1.5 ulp instead of 3.75, mean 0.24 instead of 0.26 on 3000 points against mpmath).
    """
    measurements = composition_measurements()
    for tau_long in LONG_TIMES:
        error_L, error_q, finite = measurements[tau_long]
        assert finite, tau_long
        worst = max(error_L, error_q)
        assert worst <= 6.0 * EPS * tau_long, f"|L| T = {tau_long:g}: {worst:.2e}"


CENTERS = (0.0, 1e4, -1e6)


@functools.cache
def continuity_measurements(span=30.0, points=601):
    """Largest |q(t + h) - q(t)| / (h max|Omega| / 2) on a fine grid of |L| t in center +- span/2.

    |dq/dt| = |Omega| / 2 exactly, so the ratio is <= 1 (up to the curvature of the path, O(h^2));
    a sign flip of the lift or a jump of the phase gives a ratio of order 1 / h.  Bodies of both
    regimes, on and next to the separatrix and symmetric, |L| = 1.
    """
    bodies = [
        ((1.0, 2.0, 3.0), (0.2, 0.5, 0.84)),
        ((1.0, 2.0, 3.0), (0.9, -0.4, 0.25)),
        ((1.0, 3.0, 6.0), (1.0, 2.0, 2.0)),
        ((1.0, 2.0, 3.0), tuple(ref.separatrix_momentum((1.0, 2.0, 3.0), 1e-10, 0.2))),
        ((1.0, 2.0, 3.0), tuple(ref.separatrix_momentum((1.0, 2.0, 3.0), -1e-10, 0.2))),
        ((1.0, 1.0, 2.0), (0.3, -0.5, 0.8)),
        ((0.6, 2.2, 1.3), (-0.9, 0.3, -0.3)),
    ]
    inertia = np.array([b[0] for b in bodies] * len(CENTERS))
    momentum = np.array([b[1] for b in bodies] * len(CENTERS), float)
    momentum /= np.linalg.norm(momentum, axis=-1, keepdims=True)
    attitude = ref.random_attitudes(np.random.default_rng(SEED + 5), len(inertia))
    offsets = np.linspace(-span / 2, span / 2, points)
    times = np.repeat(np.array(CENTERS), len(bodies))[:, None] + offsets
    L, q = ref.evaluate(inertia, momentum, attitude, times)
    h = offsets[1] - offsets[0]
    speed = 0.5 * np.linalg.norm(L / inertia[:, None], axis=-1)
    ratio = np.linalg.norm(np.diff(q, axis=1), axis=-1) / (h * np.maximum(speed[:, 1:], speed[:, :-1]))
    return {c: ratio[k * len(bodies) : (k + 1) * len(bodies)].max() for k, c in enumerate(CENTERS)}


def test_quaternion_is_continuous():
    """|L| t in [-15, 15] around 0, 1e4 and -1e6 (steps of 0.05).  Measured ratio: 0.999997 at each."""
    for center, ratio in continuity_measurements().items():
        assert ratio <= 1.001, f"around |L| t = {center:g}: {ratio}"


# --------------------------------------------------------------------------------------------------
# Shapes and transformations.


# Batched evaluation against single bodies: the same bodies evaluated one at a time under vmap
# (tests/_reference.py, the series path: each body unbatched at its own times; its programs are those
# the random bodies above compiled).  The batched layouts are evaluated eagerly as a user calls the
# methods; each call compiles a program per method and shape, so the bodies are SHAPE_COUNT = 3, one
# size for all the layouts.  Measured differences here: 0 for the two layouts at T times, 2.2e-16 at one
# time per body; with other batches (5 bodies, vmap against a loop) up to 5e-16 (L, |L| < 7), 1.8e-15
# (q) and 2.9e-15 (R), as XLA vectorises differently by shape: the tolerances allow ~2x those (L:
# absolute, |L| <= 10).
SHAPE_ATOL = dict(angular_momentum=4e-15, quaternion=4e-15, rotation_matrix=6e-15)
NAMES = ("angular_momentum", "quaternion", "rotation_matrix")
# N = 3, the length of the vector axis of L, with T = 7 times: a batch axis mixed up with the vector
# axis keeps the shapes (3, 7, 3) but not the values, and any other mix-up changes the shapes.
SHAPE_COUNT = 3


@functools.cache
def _single_bodies():
    """Bodies, times (T = 7) and their L, q, R one body at a time: (N, T, ...) arrays."""
    rng = np.random.default_rng(SEED + 6)
    inertia, momentum, attitude = random_bodies(rng, SHAPE_COUNT, (-1.0, 1.0))
    times = np.linspace(-7.0, 11.0, 7)
    values = ref.evaluate(inertia, momentum, attitude, np.tile(times, (SHAPE_COUNT, 1)), NAMES, "series")
    return (inertia, momentum, attitude, times), list(values)


def _compare(got, expected, shape):
    for value, want, name in zip(got, expected, NAMES):
        assert value.shape == shape + want.shape[len(shape) :], name
        np.testing.assert_allclose(np.asarray(value), want, rtol=0, atol=SHAPE_ATOL[name], err_msg=name)


def test_bodies_n_by_1_at_times_t():
    """Bodies of batch shape (N, 1) at t of shape (T,) give (N, T, ...), equal to the bodies one at a time."""
    from frbjax import FreeRigidBody

    (inertia, momentum, attitude, times), expected = _single_bodies()
    body = FreeRigidBody(inertia[:, None], momentum[:, None], attitude[:, None])
    got = [getattr(body, name)(times) for name in NAMES]
    _compare(got, expected, (SHAPE_COUNT, len(times)))


def test_bodies_n_at_times_t_by_1():
    """Bodies of batch shape (N,) at t of shape (T, 1) give (T, N, ...), equal to the bodies one at a time."""
    from frbjax import FreeRigidBody

    (inertia, momentum, attitude, times), expected = _single_bodies()
    body = FreeRigidBody(inertia, momentum, attitude)
    got = [getattr(body, name)(times[:, None]) for name in NAMES]
    _compare(got, [np.swapaxes(e, 0, 1) for e in expected], (len(times), SHAPE_COUNT))


# One time per body (t of shape (N,)) and single bodies (t of shape (T,)) both evaluate the bodies' series
# (a FreeRigidBody never takes the one-shot path); the broadcast differs, so the two agree to rounding.
ONE_TIME_TOLERANCE = 3e-15


def test_one_time_per_body():
    """Bodies of batch shape (N,) at t of shape (N,): body i at times[i] only, shape (N, ...)."""
    from frbjax import FreeRigidBody

    (inertia, momentum, attitude, times), expected = _single_bodies()
    body = FreeRigidBody(inertia, momentum, attitude)
    got = [np.asarray(getattr(body, name)(times[:SHAPE_COUNT])) for name in NAMES]
    scales = (np.linalg.norm(momentum, axis=-1)[:, None], 1.0, 1.0)
    diagonal = np.arange(SHAPE_COUNT)
    for value, want, name, scale in zip(got, expected, NAMES, scales):
        assert value.shape == (SHAPE_COUNT,) + want.shape[2:], name
        error = np.abs(value - want[diagonal, diagonal]).reshape(SHAPE_COUNT, -1).max(-1) / np.ravel(scale)
        assert error.max() <= ONE_TIME_TOLERANCE, (name, error.max())


def test_jit_and_vmap():
    """The body built inside jax.jit(jax.vmap(...)) gives the values of the op-by-op evaluation.

    (One compilation: 45 to 70 s on CPU.)
    Measured: 2.2e-15 (L / |L|), 2.9e-15 (q).
    """
    import jax

    from frbjax import FreeRigidBody

    def one(inertia, momentum, attitude, times):
        body = FreeRigidBody(inertia, momentum, attitude)
        return body.angular_momentum(times), body.quaternion(times)

    rng = np.random.default_rng(SEED + 7)
    inertia, momentum, attitude = random_bodies(rng, 6, (-1.0, 1.0))
    times = rng.uniform(-30, 30, (6, 5)) / np.linalg.norm(momentum, axis=-1)[:, None]
    L, q = (np.asarray(v) for v in jax.jit(jax.vmap(one))(inertia, momentum, attitude, times))
    L_eager, q_eager = ref.evaluate(inertia, momentum, attitude, times)
    assert L.shape == (6, 5, 3) and q.shape == (6, 5, 4)
    assert (np.abs(L - L_eager).max(-1) / np.linalg.norm(momentum, axis=-1)[:, None]).max() <= 5e-15
    assert np.abs(q - q_eager).max() <= 6e-15


if __name__ == "__main__":
    import jax

    jax.config.update("jax_enable_x64", True)  # as tests/conftest.py does
    print("initial values (eps):", measure_initial_values())
    for key, (group, reverse, finite) in group_measurements().items():
        scale = 1.0 if key is None else EPS * key
        group, reverse = [f"L {a / scale:.3g} q {b / scale:.3g}" for a, b in (group, reverse)]
        print(f"group {key} (/ eps tau for long times): group {group}, reverse {reverse}, finite {finite}")
    for tau, (error_L, error_q, finite) in composition_measurements().items():
        error_L, error_q = error_L / EPS / tau, error_q / EPS / tau
        print(f"composition {tau:g} / (eps tau): L {error_L:.3g} q {error_q:.3g} finite {finite}")
    print("continuity", continuity_measurements())
