"""One-kernel regions (frbjax._kernel, frbjax._kernel_constants): which program ran, and that both agree.

One body's free flow and one body's splitting trajectory are compiled as one kernel where the
backend supports it, and as XLA's ordinary kernels otherwise (``FRBJAX_ONE_KERNEL=0``, a batch, or a
region holding an operation without a single-kernel emitter).  Both give the same values to rounding.

The regions belong to the one-time motion's JAX formulas, which the CPU runs where the compiled
motion kernel is not selected: this module runs them with ``FRBJAX_MOTION_KERNEL=jax``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from frbjax import _kernel


INERTIA = np.array([1.0, 2.0, 3.0])
MOMENTUM = np.array([0.3, 1.0, 0.2])
ATTITUDE = np.array([0.9, 0.1, -0.3, 0.2]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2])


def _one_body_program(*args):
    from frbjax._free_flow import _state_once

    return jax.jit(lambda *a: _state_once(*a)).lower(*args).compile()


def _has_region(compiled_text):
    """Whether a program holds a one-kernel region: a call carrying both of frbjax's attributes.

    ``xla_cpu_small_call`` alone is not enough: XLA puts it on the small while loops it hoists itself
    (the rolled iterations of one body)."""
    return 'inlineable="false"' in compiled_text and "xla_cpu_small_call" in compiled_text


def _forget_library_traces():
    """The library's jitted free flows forget their traces (they hold the switch's value of the trace
    that made them); the tests' own programs are new functions, traced anew without any cache cleared."""
    from frbjax import _free_flow

    _free_flow._free_flow.clear_cache()
    _free_flow._tensor_free_flow.clear_cache()


@pytest.fixture(autouse=True, scope="module")
def _jax_motion():
    """The one-time motion's JAX formulas for this module (``FRBJAX_MOTION_KERNEL=jax``), read when a
    program is traced; the library's traces made under it are forgotten before and after."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("FRBJAX_MOTION_KERNEL", "jax")
        _forget_library_traces()
        yield
    _forget_library_traces()


@pytest.fixture
def switch(monkeypatch):
    """``switch("0")`` sets FRBJAX_ONE_KERNEL, read when a program is traced; after the test the
    environment is restored and the library's traces made under the switch are forgotten."""

    def set_switch(value):
        monkeypatch.setenv("FRBJAX_ONE_KERNEL", value)
        _forget_library_traces()

    yield set_switch
    monkeypatch.undo()
    _forget_library_traces()


def _one_body_args(batch=()):
    return tuple(jnp.asarray(np.broadcast_to(a, batch + a.shape)) for a in (INERTIA, MOMENTUM, ATTITUDE)) + (
        jnp.full(batch, 3.7),
    )


@pytest.fixture(scope="module")
def one_body_program_text():
    """The optimised HLO of the one-body free flow, with the regions on (compiled once for the file)."""
    return _one_body_program(*_one_body_args()).as_text()


def test_the_backend_says_which_program_runs(switch, one_body_program_text):
    """On CPU with this JAX the region is compiled (the probe), and switched off by the environment."""
    if jax.default_backend() != "cpu":
        assert not _kernel.available()
    region = _has_region(one_body_program_text)
    assert region == (_kernel.available() and _kernel.enabled())
    if jax.default_backend() == "cpu":
        # jax 0.10.2 on CPU: the probe compiles, so a one-body free flow is one kernel.
        assert _kernel.available() and region
    switch("0")
    assert not _kernel.enabled()
    assert not _has_region(_one_body_program(*_one_body_args()).as_text())


def test_a_batch_is_not_a_region():
    args = _one_body_args((_kernel.MAX_ELEMENTS,))
    assert not _has_region(_one_body_program(*args).as_text())


def test_both_programs_agree(switch):
    """Values to rounding and derivatives of the one-body free flow, with and without the region.

    Measured: 2.2e-16 in the state, 4.4e-16 relative in the Jacobian."""
    from frbjax._free_flow import _state_once

    def programs(x):
        """The value and both Jacobians as one program, traced anew (a new function: no trace of the
        other switch's)."""

        def state(x):
            momentum, attitude = _state_once(x[:3], x[3:6], x[6:10], x[10])
            return jnp.concatenate([momentum, attitude])

        program = jax.jit(lambda x: (state(x), jax.jacrev(state)(x), jax.jacfwd(state)(x))).lower(x).compile()
        return _has_region(program.as_text()), program(x)

    x = jnp.concatenate([*_one_body_args()[:3], jnp.asarray([3.7])])
    region, one_kernel = programs(x)
    assert region == _kernel.available()
    switch("0")
    region, ordinary = programs(x)
    assert not region
    np.testing.assert_allclose(one_kernel[0], ordinary[0], rtol=0, atol=1e-15)
    for got, want in zip(one_kernel[1:], ordinary[1:]):
        assert np.isfinite(got).all()
        np.testing.assert_allclose(got, want, rtol=0, atol=2e-15 * np.abs(want).max())


def test_operations_without_a_single_kernel_emitter_fall_back():
    """A sort (XLA:CPU calls its runtime) inside a region: the ordinary program, the right values."""
    sorted_twice = _kernel.one_kernel(lambda x: 2 * jnp.sort(x))
    x = jnp.asarray([3.0, 1.0, 2.0])
    program = jax.jit(sorted_twice).lower(x).compile()
    assert not _has_region(program.as_text())
    np.testing.assert_array_equal(program(x), [2.0, 4.0, 6.0])
    roots = _kernel.one_kernel(lambda x: jnp.sqrt(x) + jnp.dot(x[:3], x[:3]))
    assert _has_region(jax.jit(roots).lower(x).compile().as_text()) == _kernel.available()


def test_splitting_trajectory_either_way(switch):
    """A heavy top's trajectory of one body, with and without the region (each program compiled once,
    the region's first): the same states.

    Measured: 2.2e-16 after 50 steps between the two programs."""
    from frbjax import RigidBodyTerm, splitting_trajectory

    term = RigidBodyTerm(INERTIA, potential=lambda t, q, args: q[0] * q[2] + q[1] * q[3])
    y0 = (jnp.asarray(MOMENTUM), jnp.asarray(ATTITUDE))
    programs = {}
    for value in ("1", "0"):
        switch(value)
        program = jax.jit(lambda y0: splitting_trajectory(term, y0, dt=0.05, steps=50)[1]).lower(y0).compile()
        assert _has_region(program.as_text()) == (value == "1" and _kernel.available())
        programs[value] = program(y0)
    for got, want in zip(programs["1"], programs["0"]):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-14)


def _constants(compiled_text):
    """The constant instructions of an optimised HLO program outside its fused computations (those
    are compiled into their kernels; the others are buffers that the runtime handles at each call)."""
    count, fused = 0, False
    for line in compiled_text.splitlines():
        if line.endswith("{") and not line.startswith(" "):
            fused = "fused_computation" in line or "wrapped_" in line
        count += " constant(" in line and not fused
    return count


def test_a_region_reads_its_constants_from_arrays(one_body_program_text):
    """The one-body free flow's region keeps a handful of constants (the packed arrays, one per dtype),
    where its jaxpr has 87 distinct literals and arrays; the ordinary program folds its constants
    into its fused loops.

    Measured (jax 0.10.2): 4 constants in the region's program (a float64 array of 89 values, two
    integer arrays and one 1.0 that XLA makes itself), against 94 before the constants were lifted
    and 31 in the ordinary program."""
    text = one_body_program_text
    if not _kernel.available():  # no region on this backend: nothing to lift
        assert jax.default_backend() != "cpu" and not _has_region(text)
        return
    assert _has_region(text)
    assert _constants(text) <= 6


def _lifted_outputs(function, *args):
    """``function``'s outputs through frbjax._kernel_constants.lift_constants, and the constants left
    in the lowered program."""
    from frbjax._kernel_constants import lift_constants

    traced = jax.jit(function).trace(*args)
    lifted = lift_constants(traced)
    assert lifted is not None
    lowered = jax.jit(lifted).lower(*args).as_text()
    return lifted(*args), lowered.count("stablehlo.constant")


def test_lifted_constants_give_the_same_values():
    """Every construct the evaluator rewrites: cond, while, small scans (carried, over arrays, stacked,
    reversed), reductions, exp2, nested jit, custom_jvp, integer and boolean literals, a closed-over
    array.  Values equal the plain program's bit for bit, and no constant is left in the lowered program
    except the packed arrays (one per dtype)."""
    table = np.array([0.5, 1.5, -2.0])

    @jax.custom_jvp
    def scaled(x):
        return 3.0 * x

    scaled.defjvp(lambda primals, tangents: (scaled(primals[0]), 3.0 * tangents[0]))

    def function(x, n):
        y = jax.lax.cond(x[0] > 0.25, lambda v: v * 2.0, lambda v: v - 1.0, x)
        y = jax.lax.while_loop(lambda v: v[0] < 10.0, lambda v: v * 1.5 + 0.25, y)
        y = jax.lax.fori_loop(0, 4, lambda k, v: v + k * 0.5, y)
        y, stacked = jax.lax.scan(lambda c, row: (c * row + 1.0, c.sum()), y, jnp.asarray(table)[:, None] * y[None, :])
        _, backwards = jax.lax.scan(lambda c, row: (c + row, c), 0.0, stacked, reverse=True)
        total = jnp.sum(y) + jnp.max(y) * jnp.prod(y[:2]) + jnp.exp2(y[0] / 8.0)
        flags = jnp.any(y > 100.0) | jnp.all(y < -100.0)
        return jax.jit(scaled)(total) + jnp.where(flags, 1.0, 0.0) + (n * 2 + 1), backwards

    args = (jnp.asarray([0.7, -0.2, 1.1]), jnp.asarray(3, jnp.int32))
    want = jax.jit(function)(*args)
    got, constants = _lifted_outputs(function, *args)
    for g, w in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(want)):
        np.testing.assert_array_equal(g, w)
    assert constants <= 3  # measured 3: the float64, int32 and bool arrays


def test_values_known_when_traced_enter_as_constants():
    """A region called with a Python float and a concrete array inside a scan (a splitting step with a
    constant step size): traced arguments only cross the region's boundary (XLA:CPU aborted on the
    constant arguments of a region inside a loop that it emits as one kernel).  Same values as the
    ordinary program evaluated op by op (measured: 1.4e-17)."""
    from frbjax import free_flow

    inertia = jnp.asarray(INERTIA)

    def step(momentum, scale):
        return free_flow(inertia, momentum, ATTITUDE, 0.25)[0] * scale, None

    run = jax.jit(lambda m: jax.lax.scan(step, m, jnp.asarray([1.0, 0.5, 2.0]))[0])
    got = run(jnp.asarray(MOMENTUM))
    with jax.disable_jit():
        want = jnp.asarray(MOMENTUM)
        for c in (1.0, 0.5, 2.0):
            want = free_flow(inertia, want, ATTITUDE, 0.25)[0] * c
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)


def _loss(momentum, t):
    """A scalar of a one-body free flow's attitude: what the derivatives are taken of."""
    from frbjax import free_flow

    attitude = free_flow(jnp.asarray(INERTIA), momentum, jnp.asarray(ATTITUDE), t)[1]
    return jnp.sum(attitude * jnp.arange(1.0, 5.0))


def _agree(results, ordinary):
    for got, want in zip(results, ordinary):
        assert np.isfinite(got).all()
        np.testing.assert_allclose(got, want, rtol=0, atol=2e-15 * np.abs(want).max())


def test_derivative_programs_are_regions_too(switch):
    """The gradient of a one-body free flow evaluates one region of the values and their forward-mode
    Jacobian; the gradient and a vmap of gradients agree with the ordinary program.

    Measured: gradients 8.1e-16 relative to the largest entry; vmap of gradients over 3 bodies 8.0e-16."""
    momentum, t = jnp.asarray(MOMENTUM), jnp.asarray(3.7)
    gradient = jax.jit(jax.grad(_loss)).lower(momentum, t).compile()
    assert _has_region(gradient.as_text()) == _kernel.available()
    many = jnp.asarray(MOMENTUM)[None, :] * jnp.asarray([[1.0], [1.5], [0.7]])
    results = (gradient(momentum, t), jax.jit(jax.vmap(jax.grad(_loss), in_axes=(0, None)))(many, t))
    switch("0")
    _agree(
        results, (jax.jit(jax.grad(_loss))(momentum, t), jax.jit(jax.vmap(jax.grad(_loss), in_axes=(0, None)))(many, t))
    )


# Slow: the Hessian's program holds the region of the Jacobian of the region's own forward-mode
# Jacobian (11 inputs each, through jit's _free_flow), compiled as one kernel, and the ordinary
# Hessian besides.  Measured on the loaded 2-core machine: 129 s of CPU for this test and the one
# above together (one test then), most of it here.
@pytest.mark.slow
def test_second_derivatives_agree(switch):
    """Second derivatives of a one-body free flow (the derivative of the derivative region) agree with
    the ordinary program's.  Measured: Hessian 1.7e-16 relative to the largest entry."""
    momentum, t = jnp.asarray(MOMENTUM), jnp.asarray(3.7)
    results = (jax.jit(jax.hessian(_loss))(momentum, t),)
    switch("0")
    _agree(results, (jax.jit(jax.hessian(_loss))(momentum, t),))


def test_eager_calls_reuse_their_region():
    """Called eagerly, a one-kernel function is traced once per structure and types of its arguments
    (every eager call traced and compiled it anew, 1.1 s each, before), and so is the trajectory of
    ``splitting_trajectory`` once per (method, steps, dtype)."""
    from frbjax import RigidBodyTerm, splitting_trajectory
    from frbjax._splitting import _trajectory_region

    traces = []

    def function(x, y):
        traces.append(1)
        return jnp.sin(x) * y + 0.5

    region = _kernel.one_kernel(function)
    region(jnp.asarray([0.3, 0.4]), jnp.asarray(2.0))
    traced = len(traces)
    second = region(jnp.asarray([0.5, 0.6]), jnp.asarray(3.0))
    assert len(traces) == traced
    np.testing.assert_allclose(second, np.sin([0.5, 0.6]) * 3.0 + 0.5, rtol=1e-15)

    term = RigidBodyTerm(INERTIA, potential=lambda t, q, args: q[0] * q[2])
    y0 = (jnp.asarray(MOMENTUM), jnp.asarray(ATTITUDE))
    splitting_trajectory(term, y0, dt=0.05, steps=7)
    hits = _trajectory_region.cache_info().hits
    splitting_trajectory(term, (2 * y0[0], y0[1]), dt=0.05, steps=7)
    assert _trajectory_region.cache_info().hits == hits + 1
