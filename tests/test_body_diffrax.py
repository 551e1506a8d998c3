"""FreeRigidBody against diffrax (Dopri8, rtol = atol = 1e-16) integrating the equations of motion.

All bodies of all case families form one batch: the reference is one vmapped, jit-compiled
``diffeqsolve`` for (L, q) and one for (L, R) (tests/_reference.py ``diffrax_references``), and frbjax
is evaluated one body at a time under vmap.  The references are computed by
tests/data/make_diffrax_references.py and stored in tests/data/diffrax_references.npz (the default seed
and seed 1), which saves each test run the compilation of both integrations; the tests check that the
file's bodies are still those ``build_cases`` draws (``test_stored_inputs_are_the_cases``) and integrate
a few of them live at a modest tolerance (``test_live_diffrax_cross_check``).  Each body has 20 times,
evenly spaced from 1/20 of its end time to its end time;
end times alternate in sign from body to body, so that every family covers negative times.  End times
are given in unit-|L| time tau = |L(0)| t (t = tau / |L|).

Errors are absolute: |L_frbjax - L_ref| / |L(0)| (componentwise max), |q_frbjax - q_ref| (q itself,
not up to sign: the quaternion is the continuous lift starting at the attitude) and
|R_frbjax - R_ref| (entrywise max).

The reference's own accuracy: against mpmath at 30 digits (tests/_reference.py ``mpmath_solution``)
on generic bodies at tau = 13 .. 54, the rtol = 1e-16 reference is within ~1e-13 and the 1e-15 one
within ~1e-12, while frbjax is within ~2e-15; so the measured errors below are the reference's.  Next
to the separatrix small errors grow like exp(lambda tau), lambda = sqrt((1/I1 - 1/I2)(1/I2 - 1/I3)) the
instability rate of rotation about the middle axis (a perturbation of the input in its last bit
moves the answer by ~1e-16 exp(lambda tau), for the reference and for any float64 method alike), so
those bodies end at lambda tau <= 10 (near the separatrix: tau <= min(30, 10 / lambda); on it and
next to the middle axis: tau = 20, lambda tau ~ 7).  Generic bodies end at tau = 50.

Run ``python tests/test_body_diffrax.py`` to print the measured worst error per family.
"""

from __future__ import annotations

import functools
import itertools
import os

import _reference as ref
import numpy as np
import pytest
from scipy.spatial.transform import Rotation


RTOL = ATOL = 1e-16
TIMES = 20
SEED = 20240617
DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "diffrax_references.npz")
# The seeds whose references tests/data/make_diffrax_references.py stores.
STORED_SEEDS = (SEED, 1)


# --------------------------------------------------------------------------------------------------
# The case families.


def saddle_rate(inertia):
    """lambda = sqrt((1/I1 - 1/I2)(1/I2 - 1/I3)) (sorted moments): the growth rate, per unit |L| t, of
    small deviations from rotation about the middle axis (linearised Euler equations)."""
    i1, i2, i3 = np.sort(inertia)
    return np.sqrt((1 / i1 - 1 / i2) * (1 / i2 - 1 / i3))


def _d_times_middle_minus_one(inertia, momentum):
    """d I2 - 1 in float64 (for classifying random bodies away from the separatrix only)."""
    l = momentum / np.linalg.norm(momentum)
    return np.sum(l * l / inertia) * np.sort(inertia)[1] - 1


def axis_change(permutation):
    """Rotation M (det +1) with L' = M L for the body whose axis i is the old axis permutation[i].

    M is the permutation matrix M[i, permutation[i]] = 1 with its first row negated for an odd
    permutation.  Then I' = I[permutation], L'(t) = M L(t), R'(t) = R(t) M^T, q'(t) = q(t) ⊗ p with
    R(p) = M^T (the same motion described in the new body axes).
    """
    matrix = np.zeros((3, 3))
    matrix[np.arange(3), list(permutation)] = 1
    matrix[0] *= np.linalg.det(matrix)
    x, y, z, w = Rotation.from_matrix(matrix.T).as_quat()
    return matrix, np.array([w, x, y, z])


def permute_body(inertia, momentum, attitude, permutation):
    matrix, p = axis_change(permutation)
    return inertia[list(permutation)], matrix @ momentum, ref.hamilton(attitude, p)


def build_cases(seed=SEED):
    """dict family -> list of (inertia, momentum, attitude, end time tau_max (signed, unit |L|))."""
    rng = np.random.default_rng(seed)
    cases = {}
    sign = itertools.cycle([1.0, -1.0])

    def attitude():
        return ref.random_attitudes(rng, 1)[0]

    def add(family, inertia, momentum, tau):
        cases.setdefault(family, []).append(
            (np.asarray(inertia, float), np.asarray(momentum, float), attitude(), next(sign) * tau)
        )

    # Generic bodies, moments in random order, |L| in [0.5, 2], well inside each regime.
    for family, want_minor in (("major_axis_regime", False), ("minor_axis_regime", True)):
        count = 0
        while count < 16:
            inertia = rng.uniform(0.3, 3.0, 3)
            momentum = ref.random_directions(rng, 1)[0] * rng.uniform(0.5, 2.0)
            g2 = _d_times_middle_minus_one(inertia, momentum)
            if abs(g2) < 0.02 or (g2 > 0) != want_minor or np.ptp(inertia) < 0.2:
                continue
            add(family, inertia, momentum, 50.0)
            count += 1

    # Within 1e-6 .. 1e-12 (relative, d I2 - 1) of the separatrix, both sides; moments permuted.
    for offset in (1e-6, 1e-8, 1e-10, 1e-12):
        for side in (1, -1):
            for _ in range(2):
                inertia = np.sort(rng.uniform(0.3, 3.0, 3))
                momentum = ref.separatrix_momentum(
                    inertia, side * offset, rng.uniform(-0.9, 0.9), signs=rng.choice([-1, 1], 3)
                )
                momentum = momentum * rng.uniform(0.5, 2.0)
                permutation = tuple(rng.permutation(3))
                inertia, momentum, _ = permute_body(inertia, momentum, np.array([1.0, 0, 0, 0]), permutation)
                add("near_separatrix", inertia, momentum, min(30.0, 10 / saddle_rate(inertia)))

    # Exactly on the separatrix: I = (1, 3, 6) has a = (I2 - I1)/I1 = 2, b = (I3 - I2)/I3 = 1/2, so
    # d I2 - 1 = a l1^2 - b l3^2 = 0 for l3 = 2 l1 exactly (and the unit vector (1, 2, 2)/3 has
    # l3^2 = 4 l1^2 in floating point too).  I = (1, 2, 4) with l3 = fl(sqrt(2) l1) is off by ~1e-16.
    for inertia, momentum in (
        ((1.0, 3.0, 6.0), (1.0, 2.0, 2.0)),
        ((1.0, 3.0, 6.0), (-3.0, 2.0, 6.0)),
        ((1.0, 3.0, 6.0), (1.0, 0.0, -2.0)),
        ((1.0, 3.0, 6.0), (3.0, -22.0, 6.0)),  # l2 = -22/23: starts next to the saddle
        ((6.0, 1.0, 3.0), (2.0, -1.0, 2.0)),  # (1, 3, 6) with axes reordered
        ((1.0, 2.0, 4.0), (1.0, 0.5, np.sqrt(2.0))),
        ((1.0, 2.0, 4.0), (-0.3, -0.1, 0.3 * np.sqrt(2.0))),
        ((4.0, 2.0, 1.0), (np.sqrt(2.0), 0.0, 1.0)),
    ):
        add("on_separatrix", inertia, momentum, 20.0)

    # Symmetric bodies (I1 = I2, I2 = I3, in any position) and spheres.
    for inertia in (
        (1.0, 1.0, 2.0),
        (2.0, 1.0, 1.0),
        (1.0, 2.0, 2.0),
        (2.0, 1.0, 2.0),
        (0.7, 0.7, 0.3),
        (3.0, 1.5, 3.0),
        (1.5, 1.5, 1.5),
        (0.4, 0.4, 0.4),
    ):
        add("symmetric", inertia, ref.random_directions(rng, 1)[0] * rng.uniform(0.5, 2.0), 50.0)

    # Nearly symmetric: two moments within a relative gap of 1e-6, 1e-10 or one ulp (2.2e-16).
    for gap in (1e-6, 1e-10, np.finfo(float).eps):
        for inertia in ((1.0, 1.0 + gap, 2.0), (1.0, 2.0 * (1 - gap), 2.0), (1.0 + gap, 0.5, 1.0)):
            add("near_symmetric", inertia, ref.random_directions(rng, 1)[0], 50.0)

    # Nearly symmetric with L in or next to the plane of the two close axes (spin about a nearly
    # degenerate pair: alpha ~ 1/sqrt(gap) in the phase of the precession).
    for gap in (1e-6, 1e-10, np.finfo(float).eps):
        for offset in (0.0, 1e-10, 1e-5):
            angle = rng.uniform(0, 2 * np.pi)
            in_plane = np.array([np.cos(angle), np.sin(angle)])
            add("near_symmetric_plane", (1.0, 1.0 + gap, 2.0), (*in_plane, offset), 50.0)
            add("near_symmetric_plane", (2.0 * (1 - gap), 1.0, 2.0), (in_plane[0], offset, in_plane[1]), 50.0)

    # Nearly spherical: all three moments within a relative gap of each other.
    for gap in (1e-6, 1e-8, 1e-10, 1e-12, np.finfo(float).eps):
        add("near_sphere", (1.0, 1.0 + gap, 1.0 + 2 * gap), ref.random_directions(rng, 1)[0], 50.0)
        add("near_sphere", (2.0 + 6 * gap, 2.0, 2.0 + 2 * gap), ref.random_directions(rng, 1)[0], 50.0)

    # Spin about each principal axis, and slightly off the stable (largest, smallest moment) axes.
    inertia = np.array([2.0, 0.8, 1.3])  # largest, smallest, middle moment
    for axis in range(3):
        tau = 20.0 if axis == 2 else 50.0
        for magnitude in (1.0, -2.5):
            add("principal_axis", inertia, magnitude * np.eye(3)[axis], tau)
        if axis < 2:
            for offset in (1e-12, 1e-8, 1e-4):
                momentum = np.eye(3)[axis] + offset * ref.random_directions(rng, 1)[0]
                add("near_stable_axis", inertia, momentum, 50.0)

    # Slightly off the unstable middle axis: leaves it as exp(lambda tau), lambda tau <= 7 here.
    for offset in (1e-12, 1e-10, 1e-8, 1e-6, 1e-4):
        momentum = np.eye(3)[2] + offset * ref.random_directions(rng, 1)[0]
        add("near_middle_axis", inertia, momentum, 20.0)
    # Off by 1e-20 along one axis only (cn ~ 1e-20 at the start, the amplitude within rounding of
    # pi/2: which side of it the orbit is on must come from the sign of cn), both signs of time.
    for perturbed in (0, 1):
        for _ in range(2):
            add("near_middle_axis", inertia, np.eye(3)[2] + 1e-20 * np.eye(3)[perturbed], 20.0)

    # L = 0: the attitude stays put.
    for inertia in ((1.0, 2.0, 3.0), (0.5, 0.5, 0.9)):
        add("zero_momentum", inertia, np.zeros(3), 50.0)

    # |L| from 1e-3 to 1e3 (t = tau / |L|).
    for exponent in range(-3, 4):
        inertia = rng.uniform(0.3, 3.0, 3)
        add("momentum_magnitude", inertia, ref.random_directions(rng, 1)[0] * 10.0**exponent, 40.0)

    # One body of each kind in all six orders of the axes (permuted consistently with L and q).
    bases = [cases["major_axis_regime"][0], cases["minor_axis_regime"][0], cases["near_separatrix"][2]]
    for inertia, momentum, attitude_, tau in bases:
        for permutation in itertools.permutations(range(3)):
            cases.setdefault("axis_orders", []).append((*permute_body(inertia, momentum, attitude_, permutation), tau))
    return cases


def stack(cases):
    """Flatten to arrays: families (N,), inertia (N, 3), momentum (N, 3), attitude (N, 4), times (N, K)."""
    rows = [(family, *case) for family, items in cases.items() for case in items]
    families = np.array([r[0] for r in rows])
    inertia, momentum, attitude = (np.stack([r[i] for r in rows]) for i in (1, 2, 3))
    tau = np.array([r[4] for r in rows])
    norm = np.linalg.norm(momentum, axis=-1)
    end = tau / np.where(norm > 0, norm, 1.0)
    times = end[:, None] * np.arange(1, TIMES + 1) / TIMES
    return families, inertia, momentum, attitude, times


# --------------------------------------------------------------------------------------------------
# Tolerances per family: (L / |L(0)|, q, R).  Measured worst errors against the rtol = atol = 1e-16
# reference, over the default seed and seeds 1..4 of build_cases (a check against mpmath at 30 digits
# puts frbjax within ~1e-15 of the exact motion on generic bodies, so these are the reference's own
# errors), and the tolerance ~1.5x the worst, rounded up.

TOLERANCE = {
    # measured worst L 2.4e-13, q 4.6e-13, R 1.4e-12
    "major_axis_regime": (4e-13, 7e-13, 2e-12),
    # measured worst L 7.4e-13, q 5.1e-13, R 1.3e-12
    "minor_axis_regime": (1.2e-12, 8e-13, 2e-12),
    # measured worst L 5.2e-12, q 3.2e-12, R 5.9e-12 (reference error grows with exp(lambda tau))
    "near_separatrix": (8e-12, 5e-12, 9e-12),
    # measured worst L 1.9e-13, q 4.5e-13, R 4.8e-13
    "on_separatrix": (3e-13, 7e-13, 7e-13),
    # measured worst L 2.0e-13, q 4.9e-13, R 1.6e-12
    "symmetric": (3e-13, 7e-13, 2.5e-12),
    # measured worst L 1.6e-13, q 4.8e-13, R 1.9e-12
    "near_symmetric": (2.5e-13, 7e-13, 3e-12),
    # measured worst L 2.0e-14, q 5.4e-13, R 5.0e-13 (q 2.7e-8, R 5.7e-8 before alpha Pi was split
    # into alpha u + alpha (Pi - F), see frbjax/_regimes.py)
    "near_symmetric_plane": (2.5e-13, 7e-13, 3e-12),
    # measured worst L 3.2e-14, q 5.6e-13, R 6.0e-13 (q 0.25 for one-ulp gaps before psi was counted
    # from t = 0 and the complete Pi computed once per body)
    "near_sphere": (2.5e-13, 8e-13, 3e-12),
    # measured worst L 0 (exact), q 5.2e-13, R 5.4e-13
    "principal_axis": (1e-15, 8e-13, 8e-13),
    # measured worst L 2.4e-15, q 6.3e-13, R 5.0e-13
    "near_stable_axis": (4e-15, 1e-12, 8e-13),
    # measured worst L 9.7e-15, q 4.7e-13, R 4.8e-13 (q 5e-5 at offset 1e-12 before the phase was
    # computed from the ratios of the L components; O(1) at offset 1e-20 before the side of the
    # saddle was taken from the sign of cn)
    "near_middle_axis": (2e-14, 1e-12, 1e-12),
    # measured worst L 0, q 2.2e-16, R 1.0e-15
    "zero_momentum": (0.0, 4.5e-16, 2e-15),
    # measured worst L 3.2e-13, q 4.8e-13, R 1.7e-12
    "momentum_magnitude": (5e-13, 8e-13, 2.5e-12),
    # measured worst L 2.5e-12, q 1.0e-12, R 1.4e-12
    "axis_orders": (4e-12, 1.5e-12, 2e-12),
}


@functools.cache
def stored_references(seed):
    """{name: array} of one stored seed (inputs and solutions, see tests/data/make_diffrax_references.py)."""
    with np.load(DATA) as data:
        assert float(data["rtol"]) == RTOL and float(data["atol"]) == ATOL
        prefix = f"seed{seed}_"
        return {key[len(prefix) :]: data[key] for key in data.files if key.startswith(prefix)}


def references(seed):
    """The file's references for a stored seed; for any other seed, the same integration live (~10 s)."""
    if seed in STORED_SEEDS:
        return stored_references(seed)
    _, inertia, momentum, attitude, times = stack(build_cases(seed))
    return ref.diffrax_references(inertia, momentum, attitude, times, rtol=RTOL, atol=ATOL)


def errors_against(solutions, inertia, momentum, attitude, times, path="one_time", reference_values=None):
    """Per-body errors (N, K) of frbjax's L (relative to |L(0)|), q and R against diffrax's solutions.

    With ``reference_values`` (a dict of solutions like ``solutions``) those take frbjax's place.
    """
    if reference_values is None:
        L, q, R = ref.evaluate(
            inertia, momentum, attitude, times, ("angular_momentum", "quaternion", "rotation_matrix"), path
        )
    else:
        L, q, R = reference_values["L_quaternion"], reference_values["q"], reference_values["R"]
    scale = np.linalg.norm(momentum, axis=-1)
    scale = np.where(scale > 0, scale, 1.0)[:, None]
    error_L = np.maximum(np.abs(L - solutions["L_quaternion"]).max(-1), np.abs(L - solutions["L_matrix"]).max(-1))
    error_q = np.abs(q - solutions["q"]).max(-1)
    error_R = np.abs(R - solutions["R"]).max((-1, -2))
    return error_L / scale, error_q, error_R


def measure(seed=SEED, path="one_time"):
    """Per-body errors (N, K) of L (relative to |L(0)|), q and R, and the per-body data."""
    families, inertia, momentum, attitude, times = stack(build_cases(seed))
    error_L, error_q, error_R = errors_against(references(seed), inertia, momentum, attitude, times, path)
    data = dict(families=families, inertia=inertia, momentum=momentum, attitude=attitude, times=times)
    return data, error_L, error_q, error_R


@pytest.fixture(scope="module", params=ref.PATHS)
def measured(request):
    return measure(path=request.param)


def test_families_are_as_intended():
    """The builders put each body where its family says (distance to the separatrix in mpmath)."""
    cases = build_cases()
    for inertia, momentum, _, _ in cases["near_separatrix"]:
        offset = abs(ref.separatrix_distance(inertia, momentum))
        assert 0.9e-12 < offset < 1.1e-6
    for inertia, momentum, _, _ in cases["on_separatrix"]:
        assert abs(ref.separatrix_distance(inertia, momentum)) < 3e-16
    for family in ("major_axis_regime", "minor_axis_regime"):
        for inertia, momentum, _, _ in cases[family]:
            g2 = ref.separatrix_distance(inertia, momentum)
            assert (g2 > 0) == (family == "minor_axis_regime") and abs(g2) > 0.01
    families, *_, times = stack(cases)
    assert (times < 0).any(axis=1).sum() > len(families) // 3


def check_families(data, error_L, error_q, error_R, families):
    """Assert each family's worst errors against TOLERANCE; the message names the worst body."""
    failures = []
    for family in families:
        rows = np.flatnonzero(data["families"] == family)
        for name, errors, bound in zip(("L/|L|", "q", "R"), (error_L, error_q, error_R), TOLERANCE[family]):
            body, time = np.unravel_index(np.argmax(errors[rows]), errors[rows].shape)
            value, body = errors[rows][body, time], rows[body]
            if not value <= bound:
                failures.append(
                    f"{family}: {name} error {value:.2e} > {bound:.1e} for "
                    f"I = {data['inertia'][body].tolist()}, "
                    f"L = {data['momentum'][body].tolist()}, q0 = {data['attitude'][body].tolist()}, "
                    f"t = {float(data['times'][body, time])!r}"
                )
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("family", sorted(TOLERANCE))
def test_against_diffrax(measured, family):
    check_families(*measured, [family])


def test_against_diffrax_other_seeds():
    """The same families drawn with other seeds (FRBJAX_SLOW_SEEDS, comma-separated; default 1).

    The tolerances were set from the default seed and seeds 1..4 (near_symmetric_plane: seeds 1, 2).
    Seed 1's references are stored; any other seed is integrated live (~10 s of CPU).
    """
    seeds = [int(s) for s in os.environ.get("FRBJAX_SLOW_SEEDS", "1").split(",")]
    families = list(TOLERANCE)
    for seed in seeds:
        check_families(*measure(seed=seed), families)


def test_stored_inputs_are_the_cases():
    """The stored references are those of the bodies ``build_cases`` draws today, bit for bit, and
    the integration that wrote them succeeded for every body (a failed one raises in the generator)."""
    for seed in STORED_SEEDS:
        stored = stored_references(seed)
        _, *inputs = stack(build_cases(seed))
        for name, value in zip(("inertia", "momentum", "attitude", "times"), inputs):
            np.testing.assert_array_equal(
                stored[name], value, err_msg=f"seed {seed}: {name}; rerun tests/data/make_diffrax_references.py"
            )
        count, times = inputs[-1].shape
        assert stored["q"].shape == (count, times, 4) and stored["R"].shape == (count, times, 3, 3)
        for name in ("L_quaternion", "q", "L_matrix", "R"):
            assert np.isfinite(stored[name]).all(), name
        assert (stored["steps_quaternion"] > 0).all() and (stored["steps_matrix"] > 0).all()


# The live cross-check: a few stored bodies (a generic one, one 1e-8 from the separatrix, one on it, a
# nearly symmetric one spinning next to the plane of its close moments) at their first LIVE_TIMES
# times (|L| |t| up to 10, both signs of time), integrated here by the generator's method at
# rtol = atol = LIVE_TOLERANCE (8 to 30 steps per body instead of 68 to 432: ~4 s of CPU, nearly all of
# it compiling the two integrations).
LIVE_BODIES = (("major_axis_regime", 0), ("near_separatrix", 5), ("on_separatrix", 3), ("near_symmetric_plane", 1))
LIVE_TIMES = 4
LIVE_TOLERANCE = 1e-12
# The live integration's own error, measured against the stored references and against frbjax alike
# (those two are within ~1e-13 of each other): L (relative to |L|) 2.5e-11, q 3.0e-10, R 3.7e-10
# (dense output between the few steps).  Tolerances ~1.6x.
LIVE_ERROR = dict(L=4e-11, q=5e-10, R=6e-10)


def test_live_diffrax_cross_check():
    """The generator's integration, run live on a few bodies at a modest tolerance, agrees with the
    stored references and with frbjax to its own accuracy, in fewer steps than the stored run."""
    stored = stored_references(SEED)
    families = stack(build_cases())[0]
    rows = np.array([np.flatnonzero(families == family)[k] for family, k in LIVE_BODIES])
    inertia, momentum, attitude = (stored[name][rows] for name in ("inertia", "momentum", "attitude"))
    times = stored["times"][rows, :LIVE_TIMES]
    assert (times < 0).any() and (times > 0).any()
    live = ref.diffrax_references(inertia, momentum, attitude, times, rtol=LIVE_TOLERANCE, atol=LIVE_TOLERANCE)
    assert (live["steps_quaternion"] < stored["steps_quaternion"][rows]).all()
    assert (live["steps_matrix"] < stored["steps_matrix"][rows]).all()
    stored_at = {name: stored[name][rows, :LIVE_TIMES] for name in ("L_quaternion", "q", "L_matrix", "R")}
    stored_errors = errors_against(live, inertia, momentum, attitude, times, reference_values=stored_at)
    frbjax_errors = errors_against(live, inertia, momentum, attitude, times, "one_time")
    for against, errors in (("stored", stored_errors), ("frbjax", frbjax_errors)):
        for (name, bound), error in zip(LIVE_ERROR.items(), errors):
            assert error.max() <= bound, f"live {name} against {against}: {error.max():.2e}"


def test_axis_order_is_a_change_of_coordinates():
    """Permuting the axes of a body, its L and its attitude describes the same motion (to rounding).

    For each base body, the six orders of the axes (the identity first) at 13 times in |L| t in
    [-30, 30]: L'(t) = M L(t) and q'(t) = q(t) ⊗ p exactly (see `axis_change`).  Measured worst over
    the default seed and seeds 1..3: L 6.2e-15 (relative to |L|), q 4.2e-15.
    """
    cases = build_cases()
    base = (
        cases["major_axis_regime"][1],
        cases["minor_axis_regime"][1],
        cases["near_separatrix"][5],
        cases["symmetric"][0],
        cases["on_separatrix"][0],
    )
    rows = []
    for inertia, momentum, attitude, _ in base:
        for permutation in itertools.permutations(range(3)):
            rows.append(permute_body(inertia, momentum, attitude, permutation) + (permutation,))
    inertia, momentum, attitude = (np.stack([r[i] for r in rows]) for i in range(3))
    norm = np.linalg.norm(momentum, axis=-1)[:, None]
    times = np.broadcast_to(np.linspace(-30, 30, 13), (len(rows), 13)) / norm
    L, q = ref.evaluate(inertia, momentum, attitude, times)
    worst_L = worst_q = 0.0
    for k, (*_, permutation) in enumerate(rows):
        first = k - k % 6
        matrix, p = axis_change(permutation)
        worst_L = max(worst_L, np.abs(L[k] - L[first] @ matrix.T).max() / norm[k, 0])
        worst_q = max(worst_q, np.abs(q[k] - ref.hamilton(q[first], p)).max())
    assert worst_L <= 1e-14
    assert worst_q <= 8e-15


if __name__ == "__main__":
    import jax

    jax.config.update("jax_enable_x64", True)  # as tests/conftest.py does
    data, error_L, error_q, error_R = measure()
    for family, bounds in TOLERANCE.items():
        rows = data["families"] == family
        worst = error_L[rows].max(), error_q[rows].max(), error_R[rows].max()
        flag = "" if all(w <= b for w, b in zip(worst, bounds)) else "   FAILS"
        values = "  ".join(f"{name} {w:.1e}" for name, w in zip(("L", "q", "R"), worst))
        print(f"{family:20s} {values}  ({rows.sum()} bodies){flag}")
