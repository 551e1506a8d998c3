"""The compiled kernel of the whole free flow (csrc/free_flow.hpp, ``_compiled_motion.free_flow``), which
``free_flow`` evaluates on the CPU, against the composite it replaces (``_body._motion_once``: the
checks, working frame, classification, uniform rotation and quaternion products in JAX around the
working-frame kernel) and against the JAX formulas (``FRBJAX_MOTION_KERNEL=jax``).

- The working frame, |L| and the regime are those of ``_body._prepare`` bit for bit, on both sides of
  the separatrix and on it, on symmetric bodies next to and in the plane of their equal moments, for
  axis spins and L = 0, moments in any order: the kernel's classification takes the same decisions.
- Against the composite with the working-frame kernel (the default path before) L(t) is the same to
  the bit (the same working motion, the same frame) and q(t) differs by its normalisation alone
  (XLA's x rsqrt(|x|^2) against the kernel's x (1 / |x|)): measured 1.0 eps (2026-12), allowed 4.
- Against the JAX formulas both evaluate the same formulas, so they agree to rounding times the
  conditioning of the motion in |L| t: measured (2026-12-01) at most 1.2 eps (1 + |L t|) for L / |L|
  and 1.5 eps (1 + |L t|) for q in float64, 0.8 and 1.0 in float32; allowed 4.
- The kernel forms bodies in blocks (csrc/motion.hpp's vectorised stages): a body's result is the same
  bit for bit whatever its place in the batch and the batch's size.  (In float32 symmetric
  bodies within 1e-6 of the plane of their equal moments are left out: there both paths lose digits.)
- The derivatives are the composite's, from the flow kernels' partial derivatives
  (csrc/flow_jacobian.hpp) with its conventions at the degenerate points: first derivatives forward and
  reverse, second ones in full and along a direction, to rounding.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _compile_options import FAST_COMPILE_OPTIONS

import frbjax
from frbjax import _body, _compiled_motion
from frbjax._free_flow import _free_flow


# The compiled kernels are built by the install and selected on the CPU (tests/special/test_kernels.py
# asserts it): every test here runs the kernel.

# The JAX formulas' whole flow compiles in a third of the time without XLA:CPU's fusion emitters (the
# same arithmetic).  Not with LLVM's optimisations off too: at xla_backend_optimization_level 0
# (jaxlib 0.10.2) that program gave wrong values at large |L t| and next to the separatrix (errors of
# 1e-4 in L), which the optimised program does not.
VALUE_COMPILE_OPTIONS = {"xla_cpu_use_fusion_emitters": False}
AGREEMENT = 4.0  # eps (1 + |L t|) against the JAX formulas; measured 1.2 (see the module docstring)
ATTITUDE_NORMALISATION = 4.0  # eps against the composite's q(t); measured 1.0


def _permuted(inertia, momentum, rng):
    """The same bodies with their axes relabelled (moments in any order, L's components along)."""
    order = np.array([rng.permutation(3) for _ in range(len(inertia))])
    rows = np.arange(len(inertia))[:, None]
    return inertia[rows, order], momentum[rows, order]


def _bodies(dtype=np.float64, seed=11):
    """Bodies in every regime: random ones, on the separatrix and within rounding of it (both sides),
    next to it, symmetric bodies (oblate, prolate) in and next to the plane of their equal moments,
    spheres, spin about each principal axis, L = 0; moments in any order, any |L|, attitudes of any
    norm, times of both signs up to |L t| = 1e4."""
    rng = np.random.default_rng(seed)
    inertia, momentum = [], []
    # Random bodies.
    inertia.append(rng.uniform(0.3, 3.0, (120, 3)))
    momentum.append(rng.normal(size=(120, 3)))
    # On the separatrix level of random bodies: l1^2 (1/J1 - 1/J2) = l3^2 (1/J2 - 1/J3), l2 = 0 or not;
    # rounding puts g2 on either side of 0 or on it.
    sorted_inertia = np.sort(rng.uniform(0.3, 3.0, (120, 3)), axis=-1)
    j1, j2, j3 = sorted_inertia.T
    first = np.sqrt((1 / j2 - 1 / j3) / (1 / j1 - 1 / j3))
    middle = np.where(np.arange(120) % 2 == 0, 0.0, rng.uniform(-0.5, 0.5, 120))
    scale = np.sqrt(1 - middle**2)
    inertia.append(sorted_inertia)
    momentum.append(
        np.stack([first * scale, middle, np.sqrt(1 - first**2) * scale], -1) * rng.choice([-1, 1], (120, 3))
    )
    # (1, 2, 3): exactly on the separatrix (l1^2 = 1/4, l3^2 = 3/4) and 1e-14 to 1e-2 off it, both sides.
    offsets = np.concatenate([[0.0], np.geomspace(1e-14, 1e-2, 13), -np.geomspace(1e-14, 1e-2, 13)])
    inertia.append(np.tile([1.0, 2.0, 3.0], (len(offsets), 1)))
    momentum.append(np.stack([0.5 + offsets, np.zeros_like(offsets), np.full_like(offsets, np.sqrt(0.75))], -1))
    # Symmetric bodies: L in the plane of the equal moments (a fixed point) and 1e-12 to 0.1 off it.
    off_plane = np.concatenate([[0.0], np.geomspace(1e-12, 0.1, 8)])
    for moments, odd in (([1.0, 1.0, 2.0], 2), ([1.0, 2.0, 2.0], 0), ([2.0, 2.0, 0.5], 2)):
        rows = np.tile([0.6, 0.8, 0.6], (len(off_plane), 1))
        rows[:, odd] = off_plane
        inertia.append(np.tile(moments, (len(off_plane), 1)))
        momentum.append(rows)
    # Spheres, spin about each principal axis (the middle one too), L = 0.
    inertia.append(np.array([[1.5, 1.5, 1.5]] * 2 + [[1.0, 2.0, 3.0]] * 7))
    momentum.append(np.array([[0.3, -0.4, 1.2], [0, 0, 0], *np.eye(3), *-np.eye(3), [0, 0, 0]]))
    inertia, momentum = np.concatenate(inertia), np.concatenate(momentum)
    inertia, momentum = _permuted(inertia, momentum, rng)
    n = len(inertia)
    momentum = momentum * 10.0 ** rng.uniform(-2, 2, (n, 1))
    attitude = rng.normal(size=(n, 4)) * 10.0 ** rng.uniform(-1, 1, (n, 1))
    size = np.linalg.norm(momentum, axis=-1)
    t = rng.choice([-1.0, 1.0], n) * 10.0 ** rng.uniform(-3, 4, n) / np.where(size > 0, size, 1)
    return tuple(np.asarray(a, dtype) for a in (inertia, momentum, attitude, t))


_prepare = jax.jit(lambda inertia, momentum, attitude: _body._prepare(inertia, momentum, attitude))
_composite = jax.jit(lambda *arguments: _body._motion_once(*arguments))
_kernel = jax.jit(_compiled_motion.free_flow)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_the_working_frame_and_the_regimes_are_prepares_bit_for_bit(dtype):
    inertia, momentum, attitude, _ = _bodies(dtype)
    ours = _compiled_motion.free_flow_frame(jnp.asarray(inertia), jnp.asarray(momentum))
    theirs = _prepare(inertia, momentum, attitude)[5:]
    for a, b in zip(ours, theirs):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    regimes = np.asarray(theirs[3])
    assert set(np.unique(regimes)) == {0, 1, 2, 3}
    # The separatrix level of the random bodies falls on both sides and on it.
    assert {0, 1, 2} <= set(np.unique(regimes[120:240]))


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_the_state_is_the_composites(dtype):
    """L(t) to the bit; q(t) to its normalisation's rounding."""
    arguments = _bodies(dtype)
    momentum, attitude = (np.asarray(a) for a in _kernel(*arguments))
    expected_momentum, expected_attitude = (np.asarray(a) for a in _composite(*arguments))
    np.testing.assert_array_equal(momentum, expected_momentum)
    eps = np.finfo(dtype).eps
    assert np.abs(attitude - expected_attitude).max() <= ATTITUDE_NORMALISATION * eps


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_the_values_agree_with_the_jax_formulas(dtype, monkeypatch):
    arguments = _bodies(dtype)
    momentum, attitude = (np.asarray(a, np.float64) for a in _kernel(*arguments))
    monkeypatch.setenv("FRBJAX_MOTION_KERNEL", "jax")
    jax_path = jax.jit(lambda *a: _body._motion_once(*a)).lower(*arguments).compile(VALUE_COMPILE_OPTIONS)
    expected_momentum, expected_attitude = (np.asarray(a, np.float64) for a in jax_path(*arguments))
    size = np.linalg.norm(np.asarray(arguments[1], np.float64), axis=-1)
    scale = np.finfo(dtype).eps * (1 + size * np.abs(np.asarray(arguments[3], np.float64)))
    momentum_error = np.abs(momentum - expected_momentum).max(-1) / np.where(size > 0, size, 1)
    attitude_error = np.abs(attitude - expected_attitude).max(-1)
    compared = np.ones(len(size), bool)
    if dtype == np.float32:
        # Symmetric bodies within 1e-6 of the plane of their equal moments (but not in it) are beyond
        # float32's formulas: both paths lose digits there (errors up to 0.5 against float64, the
        # kernel's mostly smaller), and float64 keeps them (above).
        compared = ~_next_to_the_plane_of_equal_moments(*arguments[:2], 1e-6)
        assert compared.sum() >= len(compared) - 16
    assert (momentum_error / scale)[compared].max() <= AGREEMENT
    assert (attitude_error / scale)[compared].max() <= AGREEMENT


def _next_to_the_plane_of_equal_moments(inertia, momentum, band):
    """Bodies with exactly two equal moments whose L is within ``band`` |L| of their plane, not in it."""
    inertia, momentum = np.asarray(inertia, np.float64), np.asarray(momentum, np.float64)
    equal_to_others = (inertia[:, :, None] == inertia[:, None, :]).sum(-1)  # 1 for the odd moment
    symmetric = (equal_to_others == 2).sum(-1) == 2
    along_odd = np.abs(np.where(equal_to_others == 1, momentum, 0)).sum(-1)
    return symmetric & (along_odd > 0) & (along_odd < band * np.linalg.norm(momentum, axis=-1))


def test_free_flow_takes_the_kernel_and_the_switches_keep_the_jax_formulas(monkeypatch):
    arguments = tuple(jnp.asarray(a) for a in (np.ones(3), np.ones(3), np.ones(4), np.ones(())))

    def calls(name):
        # Traced through a new function object (make_jaxpr of one function reuses its first trace);
        # _free_flow's own program is the current path's (tests/test_kernel_path.py).
        return name in str(jax.make_jaxpr(lambda *a: _free_flow(*a))(*arguments))

    assert calls("frbjax_free_flow")
    for switch in ("FRBJAX_MOTION_KERNEL", "FRBJAX_KERNELS"):
        monkeypatch.setenv(switch, "jax")
        assert not calls("frbjax_free_flow") and not calls("frbjax_motion")
        monkeypatch.delenv(switch)


def test_invalid_bodies_give_nan_under_jit_and_raise_eagerly():
    inertia, momentum, attitude, t = (np.asarray(a)[:8] for a in _bodies())
    bad = [
        ("inertia", 1, 0, 0.0),
        ("inertia", 2, 1, -1.0),
        ("inertia", 3, 2, np.inf),
        ("angular_momentum", 4, 0, np.nan),
        ("attitude", 5, 3, np.inf),
    ]
    arrays = {"inertia": inertia.copy(), "angular_momentum": momentum.copy(), "attitude": attitude.copy()}
    for name, row, column, value in bad:
        arrays[name][row, column] = value
    arrays["attitude"][6] = 0.0
    flow = jax.jit(frbjax.free_flow)
    momentum_out, attitude_out = (
        np.asarray(a) for a in flow(arrays["inertia"], arrays["angular_momentum"], arrays["attitude"], t)
    )
    invalid = np.isin(np.arange(8), [1, 2, 3, 4, 5, 6])
    assert np.isnan(momentum_out[invalid]).all() and np.isnan(attitude_out[invalid]).all()
    assert np.isfinite(momentum_out[~invalid]).all() and np.isfinite(attitude_out[~invalid]).all()
    expected = _composite(inertia[~invalid], momentum[~invalid], attitude[~invalid], t[~invalid])
    np.testing.assert_array_equal(momentum_out[~invalid], np.asarray(expected[0]))
    with pytest.raises(ValueError, match="inertia"):
        frbjax.free_flow(arrays["inertia"], momentum, attitude, t)
    with pytest.raises(ValueError, match="attitude"):
        frbjax.free_flow(inertia, momentum, arrays["attitude"], t)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_a_bodys_result_does_not_depend_on_its_neighbours(dtype):
    """Every body takes the blocks' vectorised code (no scalar remainder, whose products and sums the
    compiler may fuse differently): slices of 1 to 37 bodies at any offset give the whole batch's
    values bit for bit."""
    arguments = [np.asarray(a)[:120] for a in _bodies(dtype)]
    whole = [np.asarray(a) for a in _kernel(*arguments)]
    for size in (1, 2, 3, 5, 8, 13, 37):
        for start in (0, 7, 50, 83):
            part = _kernel(*(a[start : start + size] for a in arguments))
            for ours, expected in zip(part, whole):
                np.testing.assert_array_equal(np.asarray(ours), expected[start : start + size])


def test_odd_shapes_broadcasts_and_empty_batches():
    inertia, momentum, attitude, t = (np.asarray(a)[:12] for a in _bodies())
    whole = [np.asarray(a) for a in frbjax.free_flow(inertia, momentum, attitude, t)]
    # Strided views, a grid of bodies x times, one body at many times, zero-size batches.
    strided = frbjax.free_flow(inertia[::3], momentum[::3], attitude[::3], t[::3])
    for a, b in zip(strided, whole):
        np.testing.assert_array_equal(np.asarray(a), b[::3])
    times = np.array([0.0, -0.7, 2.5])
    grid = frbjax.free_flow(inertia[:, None], momentum[:, None], attitude[:, None], times)
    assert grid[0].shape == (12, 3, 3) and grid[1].shape == (12, 3, 4)
    one_body = frbjax.free_flow(inertia[4], momentum[4], attitude[4], times)
    for a, b in zip(one_body, grid):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b)[4])
    shared = frbjax.free_flow(inertia[4], momentum[:5], attitude[0], t[:5])
    expected = _composite(
        np.broadcast_to(inertia[4], (5, 3)), momentum[:5], np.broadcast_to(attitude[0], (5, 4)), t[:5]
    )
    np.testing.assert_array_equal(np.asarray(shared[0]), np.asarray(expected[0]))
    for shape in ((0,), (2, 0)):
        empty = frbjax.free_flow(np.ones(shape + (3,)), np.ones(shape + (3,)), np.ones(shape + (4,)), np.ones(shape))
        assert empty[0].shape == shape + (3,) and empty[1].shape == shape + (4,)
    mapped = jax.vmap(frbjax.free_flow, in_axes=(None, None, None, 0))(inertia[4], momentum[4], attitude[4], times)
    for a, b in zip(mapped, one_body):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    shapes = jax.eval_shape(frbjax.free_flow, inertia[:, None], momentum[:, None], attitude[:, None], times)
    assert [s.shape for s in shapes] == [(12, 3, 3), (12, 3, 4)]


# One body of each kind for the derivatives: random (major, minor), on the separatrix, a symmetric body
# next to the plane of its equal moments (the regular precession's derivatives), one in it (uniform),
# spin about an axis, L = 0.
DERIVATIVE_BODIES = (
    ([1.0, 2.0, 3.5], [0.3, -0.7, 0.5], 1.7),
    ([2.5, 0.7, 1.2], [0.9, 0.2, -0.3], -0.8),
    ([3.0, 1.0, 2.0], [np.sqrt(0.75), 0.0, 0.5], 0.9),
    ([1.0, 1.0, 2.0], [0.6, 0.8, 0.05], 1.3),
    ([2.0, 1.0, 1.0], [0.0, 0.6, 0.8], 0.6),
    ([1.0, 2.0, 3.0], [0.0, 0.0, 1.4], -2.0),
    ([1.0, 2.0, 3.0], [0.0, 0.0, 0.0], 1.1),
)


def _derivative_points():
    """The bodies as rows of (I, L, q, t): 11 numbers."""
    attitude = [0.9, 0.1, -0.2, 0.3]
    return jnp.asarray([[*inertia, *momentum, *attitude, t] for inertia, momentum, t in DERIVATIVE_BODIES])


def _state_of(function):
    return lambda x: jnp.concatenate(function(x[:3], x[3:6], x[6:10], x[10]), -1)


def test_the_derivatives_are_the_composites():
    """Forward mode along random directions, both paths in one program (XLA merges the identical
    computations of the composite's derivative), and reverse mode through the identity
    <cotangent, J direction> = <J^T cotangent, direction> (the composite's reverse mode is not
    compiled again)."""
    points = _derivative_points()
    rng = np.random.default_rng(2)
    directions = jnp.asarray(rng.normal(size=points.shape))
    cotangents = jnp.asarray(rng.normal(size=(len(points), 7)))

    def derivatives(point, direction, cotangent):
        ours, theirs = (jax.jvp(_state_of(f), (point,), (direction,)) for f in (frbjax.free_flow, _body.motion_once))
        pulled_back = jax.vjp(_state_of(frbjax.free_flow), point)[1](cotangent)[0]
        return ours, theirs, pulled_back

    program = jax.jit(jax.vmap(derivatives)).lower(points, directions, cotangents).compile(FAST_COMPILE_OPTIONS)
    (value, tangent), (expected_value, expected_tangent), pulled_back = program(points, directions, cotangents)
    tangent, expected_tangent = np.asarray(tangent), np.asarray(expected_tangent)
    assert np.isfinite(tangent).all()
    np.testing.assert_array_equal(
        np.asarray(value), np.asarray(jax.vmap(_state_of(_compiled_motion.free_flow))(points))
    )
    np.testing.assert_allclose(tangent, expected_tangent, rtol=0, atol=4e-16 * (1 + np.abs(expected_tangent).max()))
    np.testing.assert_allclose(
        np.sum(np.asarray(pulled_back) * np.asarray(directions), -1),
        np.sum(np.asarray(cotangents) * expected_tangent, -1),
        rtol=1e-13,
    )


def test_the_second_derivatives_are_the_composites():
    """The flow kernels' partial derivatives (csrc/flow_jacobian.hpp: 7 x 11 first, 7 x 11 x 11 second,
    [a][b] the derivative in b of the first one in a) against jacfwd and jacfwd of jacfwd of the
    composite, at one body of each kind: random (major, minor), on the separatrix, a symmetric body next
    to the plane of its equal moments (the regular precession's expansion), one in it and an axis spin
    (the uniform rotation's variational solution, its coefficients frozen as ``_uniform``'s), L = 0.
    Measured (2026-11-28): first 1.0, second 1.4 eps (1 + their largest entry); allowed 4.  Over the
    303 bodies of ``_bodies`` the first agree to 8.6 eps (5.6 in float32), the second to the
    composite's own accuracy (its asymmetry, up to 1e16 next to the separatrix at |L t| = 84).  And
    free_flow's second derivative along a random direction (its JVP rules composed) is the
    contraction of the composite's."""
    points = _derivative_points()
    directions = jnp.asarray(np.random.default_rng(3).normal(size=points.shape))
    composite = _state_of(_body.motion_once)

    def kernels(point):
        return _compiled_motion._flow_kernel(2, (point[:3], point[3:6], point[6:10], point[10]))

    def along(point, direction):
        def tangent(x):
            return jax.jvp(_state_of(frbjax.free_flow), (x,), (direction,))[1]

        return jax.jvp(tangent, (point,), (direction,))[1]

    def both(point, direction):
        first, second = jax.jacfwd(composite), jax.jacfwd(jax.jacfwd(composite))
        return kernels(point), first(point), second(point), along(point, direction)

    program = jax.jit(jax.vmap(both)).lower(points, directions).compile(FAST_COMPILE_OPTIONS)
    out, first, second, second_along = (np.asarray(a) for a in program(points, directions))
    ours_first, ours_second = out[..., 1:12], out[..., 12:].reshape(second.shape)
    eps = np.finfo(np.float64).eps
    assert np.isfinite(out).all()
    for ours, theirs in ((ours_first, first), (ours_second, second)):
        scale = 1 + np.abs(theirs).max(axis=tuple(range(1, theirs.ndim)), keepdims=True)
        assert np.all(np.abs(ours - theirs) <= 4 * eps * scale), np.max(np.abs(ours - theirs) / scale) / eps
    # Measured 4.3 eps (1 + the largest entry of the result); allowed 8.
    expected = np.einsum("poab,pa,pb->po", second, np.asarray(directions), np.asarray(directions))
    scale = 1 + np.abs(expected).max(axis=-1, keepdims=True)
    assert np.all(np.abs(second_along - expected) <= 8 * eps * scale)


def test_bodies_with_principal_axes_take_the_kernels_through_the_principal_frame():
    """A body whose principal axes R are not its body axes (a tensor's) is evaluated through the
    principal frame (``_body.flow_state``: L_p = R^T L0, q_p = q0 ⊗ r, then back): its values, first
    derivatives and second derivatives (along two random directions) in the moments, the axes
    (R exp(hat w) at w = 0), L0, q0 and t against ``motion_once`` with those axes (the JAX rules,
    ``_uniform``'s and ``_precession``'s with axes), at a random body, a symmetric one next to the
    plane of its equal moments, an axis spin and L = 0 (their L given in the principal frame and
    turned to the body's).  Measured (2026-11-28): values 1.3 eps, first derivatives 1.0 eps, second
    1.8 eps (1 + the largest entry); allowed 4.  (This test found the JAX rule of the uniform rotation
    missing, in its second derivatives in the axes, the nutation that a turn of the axes starts:
    d2 L_y / dw_y dw_z of the axis spin was 0.299 where the kernels give -1.98306709, as do central
    differences of either path's first derivatives off the uniform rotation, h = 1e-5.  ``_uniform``
    is fixed.)"""
    rng = np.random.default_rng(7)
    axes = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    axes = axes * np.linalg.det(axes)
    bodies = [DERIVATIVE_BODIES[k] for k in (0, 3, 5, 6)]
    points = jnp.asarray(
        [[*inertia, *(axes @ np.asarray(momentum)), 0.9, 0.1, -0.2, 0.3, t] for inertia, momentum, t in bodies]
    )

    def turned(w):
        # R exp(hat w) to second order in w (all the derivatives at w = 0 use).
        hat = jnp.asarray([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
        return jnp.asarray(axes) @ (jnp.eye(3) + hat + hat @ hat / 2)

    def of(function):
        def state(x):
            inertia, w, momentum, attitude, t = x[:3], x[3:6], x[6:9], x[9:13], x[13]
            return jnp.concatenate(function(inertia, turned(w), momentum, attitude, t), -1)

        return state

    ours = of(_body.flow_state)
    theirs = of(
        lambda inertia, axes, momentum, attitude, t: _body.motion_once(inertia, momentum, attitude, t, True, axes)
    )
    x = jnp.concatenate([points[:, :3], jnp.zeros((len(points), 3)), points[:, 3:]], -1)

    directions = jnp.asarray(np.random.default_rng(8).normal(size=(2,) + x.shape))

    def all_orders(x, u, v):
        def second(f):
            return jax.jvp(lambda y: jax.jvp(f, (y,), (u,))[1], (x,), (v,))[1]

        return [(f(x), jax.jacfwd(f)(x), second(f)) for f in (ours, theirs)]

    # The second derivatives along two random directions (a full Hessian of the JAX rules with axes
    # compiles for 20 s).
    results = jax.jit(jax.vmap(all_orders)).lower(x, *directions).compile(FAST_COMPILE_OPTIONS)(x, *directions)
    eps = np.finfo(np.float64).eps
    for mine, expected in zip(*results):
        mine, expected = np.asarray(mine), np.asarray(expected)
        assert np.isfinite(mine).all()
        scale = 1 + np.abs(expected).max(axis=tuple(range(1, expected.ndim)), keepdims=True)
        assert np.all(np.abs(mine - expected) <= 4 * eps * scale), np.max(np.abs(mine - expected) / scale) / eps
