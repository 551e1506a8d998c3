"""The compiled kernel of the one-time motion (frbjax/_compiled_motion.py, csrc/motion.hpp) against the
JAX formulas it replaces on the CPU (``_regimes.orbit_constants`` + ``evaluate_once``), in the working
frame: values, Jacobians and Hessians, every regime, float64 and float32, odd shapes.

Both paths evaluate the same formulas, so they agree to rounding times the conditioning of the motion
in tau (errors grow like |tau|): measured over the bodies below (2026-11-28) at most 1.7e-16 (1 + |tau|)
for the values, 4.2e-14 (1 + |tau|)(1 + |entry|) for the Jacobians' entries (next to the separatrix,
where they grow like 1/mc; 6.4e-15 elsewhere), and 2e-13 relative for the Hessians; the tolerances
hold those with a margin.  Accuracy against independent references (mpmath, diffrax, CALGO 903) is
tested through ``free_flow`` by test_paths.py, test_body_mpmath.py, test_gradients_body.py and the
others on the motion's default path, which is this kernel on the CPU (FRBJAX_MOTION_KERNEL=jax
selects the JAX formulas).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _compile_options import FAST_COMPILE_OPTIONS

from frbjax import _compiled_motion, _regimes, FreeRigidBody
from frbjax._body import working_frame


VALUE_TOLERANCE = {np.float64: 4e-16, np.float32: 3e-7}  # times 1 + |tau|; measured 1.7e-16, see below
JACOBIAN_TOLERANCE = 6e-14  # times (1 + |tau|)(1 + |entry|); measured 4.2e-14 (next to the separatrix)


def _bodies(n, dtype=np.float64, seed=5):
    """Sorted moments, unit working-frame L, regimes and times: random bodies with symmetric ones,
    bodies on and next to the separatrix, axis spins and L = 0 among them."""
    rng = np.random.default_rng(seed)
    size = max(n, 48)
    inertia = rng.uniform(0.3, 3.0, (size, 3))
    momentum = rng.normal(size=(size, 3))
    inertia[:24] = [1.0, 2.0, 3.0]
    # On the separatrix of (1, 2, 3): l1^2 = (1/2 - 1/3)/(1 - 1/3) = 1/4 with l2 = 0, l3^2 = 3/4;
    # then next to it on both sides.
    momentum[:8] = [0.5, 0.0, np.sqrt(0.75)]
    momentum[8:24] = [0.5, 0.0, np.sqrt(0.75)] + np.outer(
        np.geomspace(1e-12, 1e-2, 16) * (-1) ** np.arange(16), [1, 0, 0]
    )
    inertia[24:32] = [1.0, 1.0, 2.0]
    inertia[32:40] = [1.0, 2.0, 2.0]
    momentum[40:44] = [[0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0], [0, 0, 0]]
    _, sorted_inertia, working = working_frame(jnp.asarray(inertia), jnp.asarray(momentum))
    norm = jnp.linalg.norm(working, axis=-1)
    unit = working / jnp.where(norm > 0, norm, 1)[:, None]
    regime = _regimes.classify(sorted_inertia, unit, norm)
    tau = 10.0 ** rng.uniform(-3, 3, size) * rng.choice([-1.0, 1.0], size)
    tau[:8] = np.linspace(-30, 30, 8)
    order = np.r_[np.arange(40, size), np.arange(40)][:n] if n < size else np.arange(n)
    return sorted_inertia[order].astype(dtype), unit[order].astype(dtype), regime[order], jnp.asarray(tau[order], dtype)


def _jax_path(inertia, unit_momentum, regime, tau):
    return _regimes.evaluate_once(_regimes.orbit_constants(inertia, unit_momentum, regime), unit_momentum, tau)


# The JAX path's batch as one compiled program (called eagerly, its operations ran one by one).
_jax_path_program = jax.jit(_jax_path)


@jax.jit
def _jax_series(inertia, unit, regime, tau):
    """The JAX series' (conj(q̂(0)) ⊗ q̂(tau), L(tau)) in the working frame, one compiled program."""
    from frbjax import _quaternion as quaternion

    consts = _regimes.constants(inertia, unit, regime)
    q, momentum = _regimes.evaluate(consts, tau)
    return quaternion.multiply(quaternion.conjugate(_regimes.reference(consts, unit)), q), momentum


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_the_values_agree_in_every_regime(dtype):
    inertia, unit, regime, tau = _bodies(512, dtype)
    regimes = np.asarray(regime)
    assert set(np.unique(regimes)) == {0, 1, 2, 3}
    compiled = _compiled_motion.working_motion(inertia, unit, regime, tau)
    reference = _jax_path_program(inertia, unit, regime, tau)
    moving = regimes != _regimes.UNIFORM
    scale = 1 + np.abs(np.asarray(tau, np.float64))[moving]
    for ours, theirs in zip(compiled, reference):
        assert ours.dtype == dtype
        error = np.abs(np.asarray(ours, np.float64) - np.asarray(theirs, np.float64)).max(-1)[moving]
        assert error.max() <= VALUE_TOLERANCE[dtype] * scale.max() and (error / scale).max() <= VALUE_TOLERANCE[dtype]
    # A uniform rotation's L is the given one (its motion is formed in JAX around the kernel).
    np.testing.assert_array_equal(np.asarray(compiled[0])[~moving], np.asarray(unit)[~moving])


def _diagonal_jacobians(path, inertia, unit, regime, tau, compiler_options=None):
    """Per point, the Jacobian of its 11 outputs in its own 7 inputs (vmap of jacfwd)."""

    def one(point, regime):
        return jnp.concatenate(path(point[:3], point[3:6], regime, point[6]), -1)

    points = jnp.concatenate([inertia, unit, tau[:, None]], -1)
    # Jitted: eagerly the JAX path's batched operations were dispatched one by one.
    program = jax.jit(jax.vmap(jax.jacfwd(one))).lower(points, regime).compile(compiler_options)
    return np.asarray(program(points, regime))


@pytest.fixture(scope="module")
def jacobian_reference():
    """The bodies of the Jacobian tests and the JAX path's Jacobians there, compiled once for both
    modes' tests.  With XLA's default optimisations, as users run the JAX path: without them (no
    fused multiply-adds) the paths differ by 8.4e-14 next to the separatrix instead of 4.2e-14."""
    bodies = _bodies(48)
    return bodies, _diagonal_jacobians(_jax_path, *bodies)


@pytest.mark.parametrize("mode", ["forward", "reverse"])
def test_the_jacobians_agree(mode, jacobian_reference):
    (inertia, unit, regime, tau), reference = jacobian_reference
    # Symmetric bodies next to the plane of their equal moments take the derivatives of the regular
    # precession (frbjax/_precession.py): there both paths' own derivatives lose 1e-16 / l_odd^2.
    j, l = np.asarray(inertia), np.asarray(unit)
    odd = np.where(j[:, 0] == j[:, 1], l[:, 2], np.where(j[:, 1] == j[:, 2], l[:, 0], 1.0))
    moving = (np.asarray(regime) != _regimes.UNIFORM) & (np.abs(odd) >= 1 / 8)
    if mode == "forward":
        compiled = _diagonal_jacobians(_compiled_motion.working_motion, inertia, unit, regime, tau)
    else:

        def one(point, regime):
            return jnp.concatenate(_compiled_motion.working_motion(point[:3], point[3:6], regime, point[6]), -1)

        points = jnp.concatenate([inertia, unit, tau[:, None]], -1)
        compiled = np.asarray(jax.jit(jax.vmap(jax.jacrev(one)))(points, regime))
    assert np.isfinite(compiled).all()
    scale = (1 + np.abs(np.asarray(tau)))[:, None, None] * (1 + np.abs(reference))
    assert (np.abs(compiled - reference) / scale)[moving].max() <= JACOBIAN_TOLERANCE


HESSIAN_POINTS = (0, 30, 50)


@pytest.fixture(scope="module")
def hessians():
    """{index: (compiled path's Hessian, JAX path's)} of the psi-carrying output at the bodies
    HESSIAN_POINTS: each path's Hessian compiled once (jit, the regime an argument) and evaluated at
    every point (eager ``jax.hessian`` of the JAX path dispatched its thousands of operations one by
    one: 65 s for the first point)."""
    inertia, unit, regime, tau = _bodies(64)

    def psi_carrying_output(path):
        return lambda x, regime: path(x[:3], x[3:6], regime, x[6])[2][1]

    points = {index: jnp.concatenate([inertia[index], unit[index], tau[index : index + 1]]) for index in HESSIAN_POINTS}
    programs = []
    for path in (_compiled_motion.working_motion, _jax_path):
        lowered = jax.jit(jax.hessian(psi_carrying_output(path))).lower(points[0], regime[0])
        # The JAX path's Hessian is a large program: with XLA:CPU's fusion emitters and LLVM's
        # optimisations off it compiles faster (the same arithmetic).
        programs.append(lowered.compile(compiler_options=FAST_COMPILE_OPTIONS))
    return {index: [np.asarray(program(points[index], regime[index])) for program in programs] for index in points}


@pytest.mark.parametrize("index", HESSIAN_POINTS)
def test_the_hessians_agree(hessians, index):
    """Second derivatives (the order-2 kernel) on the separatrix, a symmetric body and random bodies."""
    compiled, reference = hessians[index]
    assert np.isfinite(compiled).all()
    np.testing.assert_allclose(compiled, reference, rtol=0, atol=1e-12 * (1 + np.abs(reference).max()))


def test_odd_shapes():
    """Zero-size batches, broadcast and non-contiguous inputs, vmap: the kernel reads its buffers only."""
    inertia, unit, regime, tau = _bodies(12)
    empty = _compiled_motion.working_motion(inertia[:0], unit[:0], regime[:0], tau[:0])
    assert [a.shape for a in empty] == [(0, 3), (0, 4), (0, 4)]
    whole = _compiled_motion.working_motion(inertia, unit, regime, tau)
    # Every other body, from strided views; one time for all of them.
    strided = _compiled_motion.working_motion(inertia[::2], unit[::2], regime[::2], tau[::2])
    for a, b in zip(strided, whole):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b)[::2])
    grid = _compiled_motion.working_motion(inertia[:, None], unit[:, None], regime[:, None], jnp.array([0.5, 2.0]))
    assert grid[2].shape == (12, 2, 4)
    mapped = jax.vmap(lambda t: _compiled_motion.working_motion(inertia, unit, regime, t)[2])(jnp.array([0.5, 2.0]))
    np.testing.assert_array_equal(np.asarray(mapped), np.swapaxes(np.asarray(grid[2]), 0, 1))
    momentum, none, _ = _compiled_motion.working_motion(inertia, unit, regime, tau, attitude=False)
    assert none is None
    np.testing.assert_array_equal(np.asarray(momentum), np.asarray(whole[0]))


def test_nan_inputs_give_nan():
    inertia, unit, regime, tau = _bodies(4)
    out = _compiled_motion.working_motion(inertia, unit.at[1].set(jnp.nan), regime, tau.at[2].set(jnp.nan))
    moving = np.asarray(regime) != _regimes.UNIFORM
    for a in out[0], out[2]:
        assert np.isnan(np.asarray(a)[1:3][moving[1:3]]).any(-1).all()
        assert np.isfinite(np.asarray(a)[[0, 3]]).all()


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_the_series_kernel_agrees_with_the_jax_series(dtype):
    """A FreeRigidBody's theta series in C++ (csrc/series.hpp) against the JAX series
    (``_regimes.constants``, ``evaluate``, ``reference``) in the working frame, every regime: measured
    3.6e-16 (1 + |tau|) in float64 (2026-11-28).  The kernel counts psi from tau = 0, so q̂(tau) is
    compared as conj(q̂(0)) ⊗ q̂(tau), which both conventions share."""
    from frbjax import _quaternion as quaternion

    inertia, unit, regime, tau = _bodies(400, dtype)
    moving = np.asarray(regime) != _regimes.UNIFORM
    theirs_q, theirs_l = _jax_series(inertia, unit, regime, tau)
    record = _compiled_motion.series_record(inertia, unit, regime)
    ours_q, ours_l = _compiled_motion.series_motion(record, inertia, unit, regime, tau)
    start = _compiled_motion.working_motion(inertia, unit, regime, jnp.zeros_like(tau))[1]
    ours_q = quaternion.multiply(quaternion.conjugate(start), ours_q)
    scale = 1 + np.abs(np.asarray(tau, np.float64))[moving]
    for ours, theirs in ((ours_l, theirs_l), (ours_q, theirs_q)):
        error = np.abs(np.asarray(ours, np.float64) - np.asarray(theirs, np.float64)).max(-1)[moving]
        # Up to a sign of q̂ (both are rotations; the charts keep w >= 0 at tau = 0).
        assert (error / scale).max() <= 2 * VALUE_TOLERANCE[dtype]


def test_the_series_kernel_at_long_times_within_one_block():
    """Times whose half angle psi/2 lies beyond 2^19 pi/2, where csrc/circular.hpp's reduction stops
    and the C library's cosine and sine take over, interleaved with times short of it in the same
    blocks of points (csrc/series.hpp), against the JAX series, whose cos_sin takes XLA's functions
    beyond the same bound (for a whole batch holding such an argument): measured 6.9e-17 (1 + |tau|)
    (2026-11-29), held to the bound of the test above."""
    from frbjax import _quaternion as quaternion

    inertia, unit, regime, _ = _bodies(48, np.float64)
    chosen = np.array([4, 30, 46])  # on the separatrix, a symmetric body, a random one
    inertia, unit, regime = inertia[chosen], unit[chosen], regime[chosen]
    # psi ~ tau / J2 with J2 = 2 for the first two: psi/2 crosses 823550 near |tau| = 3.3e6.
    magnitudes = np.geomspace(1e5, 3e7, 40)
    tau = jnp.asarray(np.stack([magnitudes * (-1) ** np.arange(40), magnitudes[::-1]], -1).reshape(-1))
    tau = jnp.broadcast_to(tau, (3, 80))
    theirs_q, theirs_l = _jax_series(inertia[:, None], unit[:, None], regime[:, None], tau)
    record = _compiled_motion.series_record(inertia, unit, regime)
    ours_q, ours_l = _compiled_motion.series_motion(
        record[:, None], inertia[:, None], unit[:, None], regime[:, None], tau
    )
    start = _compiled_motion.working_motion(inertia, unit, regime, jnp.zeros(3))[1]
    ours_q = quaternion.multiply(quaternion.conjugate(start)[:, None], ours_q)
    scale = 1 + np.abs(np.asarray(tau))
    for ours, theirs in ((ours_l, theirs_l), (ours_q, theirs_q)):
        error = np.abs(np.asarray(ours) - np.asarray(theirs)).max(-1)
        assert (error / scale).max() <= 2 * VALUE_TOLERANCE[np.float64]


def test_the_series_kernel_reads_one_record_per_body():
    """Records (bodies, size) with each body's times contiguous: bodies (3, 1) at times (3, 5), one
    body at times (2, 5), bodies (3, 1, 1) at times (4, 5) broadcast against each other, under
    ``jax.vmap`` over bodies and over times, and zero bodies or zero times, all equal to the same
    points evaluated one record per point (the values to the bit: the same kernel)."""
    inertia, unit, regime, tau = _bodies(48, np.float64)
    chosen = np.array([4, 30, 46])  # on the separatrix, a symmetric body, a random one
    inertia, unit, regime = inertia[chosen], unit[chosen], regime[chosen]
    record = _compiled_motion.series_record(inertia, unit, regime)
    times = np.asarray(tau)[:15].reshape(3, 5)

    def pointwise(rows, tau_points):
        # One record per point, broadcast explicitly: the layout the kernel read before.
        shape = tau_points.shape
        return _compiled_motion.series_motion(
            jnp.broadcast_to(record[rows], shape + record.shape[-1:]),
            jnp.broadcast_to(inertia[rows], shape + (3,)),
            jnp.broadcast_to(unit[rows], shape + (3,)),
            jnp.broadcast_to(regime[rows], shape),
            tau_points,
        )

    def same(ours, theirs):
        for a, b in zip(ours, theirs):
            assert a.shape == b.shape
            assert np.array_equal(np.asarray(a), np.asarray(b))

    rows = np.arange(3)[:, None]
    same(
        _compiled_motion.series_motion(record[:, None], inertia[:, None], unit[:, None], regime[:, None], times),
        pointwise(np.broadcast_to(rows, (3, 5)), times),
    )
    same(
        _compiled_motion.series_motion(record[1], inertia[1], unit[1], regime[1], times[:2]),
        pointwise(np.full((2, 5), 1), times[:2]),
    )
    grid = np.broadcast_to(times[:1].reshape(1, 1, 5), (1, 4, 5)) * np.arange(1, 5)[None, :, None]
    same(
        _compiled_motion.series_motion(
            record[:, None, None], inertia[:, None, None], unit[:, None, None], regime[:, None, None], grid
        ),
        pointwise(np.broadcast_to(np.arange(3)[:, None, None], (3, 4, 5)), np.broadcast_to(grid, (3, 4, 5))),
    )
    by_body = jax.vmap(_compiled_motion.series_motion, in_axes=(0, 0, 0, 0, 0))(record, inertia, unit, regime, times)
    same(by_body, pointwise(np.broadcast_to(rows, (3, 5)), times))
    by_time = jax.vmap(_compiled_motion.series_motion, in_axes=(None, None, None, None, 1), out_axes=1)(
        record, inertia, unit, regime, times
    )
    same(by_time, pointwise(np.broadcast_to(rows, (3, 5)), times))
    for empty_rows, empty_times in ((slice(0, 0), times[:0]), (slice(0, 3), times[:, :0])):
        out = _compiled_motion.series_motion(
            record[empty_rows, None],
            inertia[empty_rows, None],
            unit[empty_rows, None],
            regime[empty_rows, None],
            empty_times,
        )
        assert out[0].shape == empty_times.shape + (4,) and out[1].shape == empty_times.shape + (3,)


def test_bodies_along_a_trailing_axis_are_one_record_each():
    """Bodies (3,) at times (5, 3), each body's times down a column (benchmarks/throughput.py's
    layout): the kernels read 3 records of 5 points each, not 15 records of one point (which had cost
    640 ns a point against 49 at 1000 bodies x 100 times), and give each body's points to the bit as
    a body alone does; for the series kernel, the evaluation of a FreeRigidBody and its momentum."""

    inertia, unit, regime, tau = _bodies(48, np.float64)
    chosen = np.array([4, 30, 46])  # on the separatrix, a symmetric body, a random one
    inertia, unit, regime = inertia[chosen], unit[chosen], regime[chosen]
    record = _compiled_motion.series_record(inertia, unit, regime)
    times = np.asarray(tau)[:15].reshape(5, 3)
    records, order = _compiled_motion._records_by_body(record, times.shape)
    assert order == (1, 0)
    assert records.shape == record.shape
    columns = _compiled_motion.series_motion(record, inertia, unit, regime, times)
    for k in range(3):
        alone = _compiled_motion.series_motion(record[k], inertia[k], unit[k], regime[k], times[:, k])
        for ours, theirs in zip(columns, alone):
            assert np.array_equal(np.asarray(ours)[:, k], np.asarray(theirs))

    rng = np.random.default_rng(5)
    bodies = FreeRigidBody(
        jnp.asarray(rng.uniform(0.5, 2.0, (3, 3))),
        jnp.asarray(rng.normal(size=(3, 3))),
        jnp.asarray(rng.normal(size=(3, 4))),
    )
    quaternions, momenta = bodies.quaternion(times), bodies.angular_momentum(times)
    assert quaternions.shape == (5, 3, 4) and momenta.shape == (5, 3, 3)
    # Row by row, one time per body: the same points through the same records.
    assert np.array_equal(np.asarray(quaternions), np.asarray(jax.vmap(bodies.quaternion)(times)))
    assert np.array_equal(np.asarray(momenta), np.asarray(jax.vmap(bodies.angular_momentum)(times)))


def test_large_batches_split_over_the_thread_pool_give_the_same_bits():
    """Batches of many chunks of the thread pool (csrc/parallel.hpp) against the same points one body
    (100 times) at a time, in fewer chunks or on the calling thread alone: the series motion (48
    bodies x 100 times), the one-time motion and its Jacobian, to the bit."""
    inertia, unit, regime, tau = _bodies(48, np.float64)
    record = _compiled_motion.series_record(inertia, unit, regime)
    times = jnp.asarray(np.random.default_rng(3).uniform(-30, 30, (48, 100)))
    together = _compiled_motion.series_motion(record[:, None], inertia[:, None], unit[:, None], regime[:, None], times)
    for body in range(48):
        alone = _compiled_motion.series_motion(record[body], inertia[body], unit[body], regime[body], times[body])
        for a, b in zip(alone, together):
            assert np.array_equal(np.asarray(a), np.asarray(b)[body])
    columns = [jnp.broadcast_to(c[:, None], times.shape) for c in (*inertia.T, *unit.T)] + [times]
    regimes = jnp.broadcast_to(regime[:, None], times.shape).astype(jnp.int32)
    for order in (0, 1):
        whole = np.asarray(_compiled_motion._call(order, True, columns, regimes))
        for body in range(0, 48, 6):
            piece = np.asarray(_compiled_motion._call(order, True, [c[body] for c in columns], regimes[body]))
            assert np.array_equal(piece, whole[body])


def test_a_bodys_derivatives_from_its_series_agree_with_the_one_time_kernel():
    """A FreeRigidBody's evaluations take their first derivatives from one record of dual numbers per
    body (``_compiled_motion.series_flow``, csrc/flow_jacobian.hpp's ``series_flow_derivatives``).
    They agree with the one-time kernel's (the same function) to rounding times the conditioning:
    measured (2026-11-29) 5.9e-16 (1 + |tau|) for the values and 2.4e-14 (1 + |tau|)(1 + |entry|) for
    the partial derivatives, next to the separatrix; the bodies the series does not serve (uniform
    rotations, the separatrix, L = 0, the precession's symmetric bodies) get the one-time kernel's
    output bit for bit; and a point's result does not depend on its neighbours (the record is kept
    only over a body's consecutive points)."""
    rng = np.random.default_rng(3)
    n, count = 64, 9
    inertia, momentum, attitude = rng.uniform(0.3, 3.0, (n, 3)), rng.normal(size=(n, 3)), rng.normal(size=(n, 4))
    # Next to the separatrix of (1, 2, 3) on both sides; on it; a symmetric body; an axis spin; L = 0.
    inertia[:6] = inertia[10] = [1.0, 2.0, 3.0]
    momentum[:6] = [0.5, 0.0, np.sqrt(0.75)] + np.outer([1e-9, -1e-9, 1e-5, -1e-5, 1e-2, -1e-2], [1, 0, 0])
    momentum[10] = [0.5, 0.0, np.sqrt(0.75)]
    inertia[6], inertia[7], momentum[8], momentum[9] = [1.0, 1.0, 2.0], [1.0, 2.0, 2.0], [0, 0, 1.0], 0
    t = np.concatenate([np.zeros((n, 1)), rng.uniform(-20, 20, (n, count - 1))], axis=1)
    arguments = [jnp.asarray(np.repeat(a[:, None, :], count, 1)) for a in (inertia, momentum, attitude)]
    arguments.append(jnp.asarray(t))
    one_time = np.asarray(_compiled_motion._flow_kernel(1, arguments))
    series = np.asarray(_compiled_motion._series_flow_kernel(1, arguments))
    tau = (np.abs(t) * np.linalg.norm(momentum, axis=-1)[:, None])[..., None]
    assert np.all(np.abs(series[..., 0] - one_time[..., 0]) <= 8e-16 * (1 + tau))
    partials, reference = series[..., 1:], one_time[..., 1:]
    assert np.all(np.abs(partials - reference) <= JACOBIAN_TOLERANCE * (1 + tau[..., None]) * (1 + np.abs(reference)))
    for body in (6, 8, 9, 10):
        np.testing.assert_array_equal(series[body], one_time[body])
    shuffled = rng.permutation(n * count)
    flat = [a.reshape((n * count,) + a.shape[2:])[shuffled] for a in arguments]
    np.testing.assert_array_equal(
        np.asarray(_compiled_motion._series_flow_kernel(1, flat)), series.reshape(n * count, 7, 12)[shuffled]
    )


def test_bodies_along_a_trailing_axis_differentiate_as_each_body_alone():
    """Bodies (N,) at times (K, 1) reach the series' derivative kernel bodies first (each body's points
    consecutive, ``_body._with_flow_jacobian``): their Jacobians are each body's alone, bit for bit."""
    rng = np.random.default_rng(4)
    inertia, momentum = jnp.asarray(rng.uniform(0.5, 2, (3, 3))), jnp.asarray(rng.normal(size=(3, 3)))
    attitude, times = jnp.asarray(rng.normal(size=(3, 4))), jnp.linspace(-5.0, 5.0, 4)
    jacobians = jax.jacrev(lambda i, l: FreeRigidBody(i, l, attitude).quaternion(times[:, None]), argnums=(0, 1))(
        inertia, momentum
    )
    for body in range(3):
        alone = jax.jacrev(lambda i, l: FreeRigidBody(i, l, attitude[body]).quaternion(times), argnums=(0, 1))(
            inertia[body], momentum[body]
        )
        for batched, single in zip(jacobians, alone):
            np.testing.assert_array_equal(np.asarray(batched)[:, body, :, body, :], np.asarray(single))
