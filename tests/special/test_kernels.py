"""The compiled CPU kernels of the special functions (frbjax/special/_compiled.py, csrc/): built,
selected on the CPU, in agreement with the JAX path, and safe with any shapes.

Agreement: both paths run the same algorithms (the kernels stop each point at its own convergence,
the JAX path per block of points), so they agree to a few ulp: measured on this grid at most 8.1e-16
relative in float64 and 3.6e-7 in float32 (3 ulp; 2026-11-28); the tolerances hold those with a margin
of about 1.5.  Accuracy against mpmath is tested on both paths by test_carlson.py, test_gradients.py and
test_second_derivatives.py.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import frbjax.special as special
from frbjax.special import _compiled


ARITY = {"elliprf": 3, "elliprd": 3, "elliprj": 4, "elliprc": 2}
TOLERANCE = {np.float64: 1.2e-15, np.float32: 5.4e-7}
JACOBI_TOLERANCE = {np.float64: 5e-16, np.float32: 2.7e-7}  # times 1 + |u|; measured 3.3e-16, 1.8e-7


def test_the_kernels_are_built_and_selected_on_the_cpu():
    """`make test` installs with a C++ compiler: the kernels must be there, not silently missing."""
    assert _compiled._module() is not None
    assert _compiled.selected(jnp.ones(2))
    assert not _compiled.selected(jnp.ones(2, jnp.bfloat16))


def test_an_unknown_switch_is_refused(monkeypatch):
    monkeypatch.setenv("FRBJAX_KERNELS", "fortran")
    with pytest.raises(ValueError, match="FRBJAX_KERNELS must be"):
        special.elliprf(1.0, 2.0, 3.0)


def _arguments(rng, arity, dtype, n=4000):
    """Arguments over 16 decades, with zeros, equal pairs and (for R_J, R_C) non-positive last ones."""
    arguments = [10 ** rng.uniform(-8, 8, n) for _ in range(arity)]
    arguments[0][:50] = 0
    arguments[1][50:100] = arguments[0][50:100]
    arguments[-1][100:150] = -arguments[-1][100:150]
    return [a.astype(dtype) for a in arguments]


def _on_path(path, name, arguments, monkeypatch):
    monkeypatch.setenv("FRBJAX_KERNELS", path)
    return np.asarray(getattr(special, name)(*arguments))


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("name", list(ARITY))
def test_the_paths_agree(name, dtype, monkeypatch):
    arguments = _arguments(np.random.default_rng(1), ARITY[name], dtype)
    compiled = _on_path("compiled", name, arguments, monkeypatch)
    reference = _on_path("jax", name, arguments, monkeypatch)
    assert compiled.dtype == reference.dtype == dtype
    # The same NaN (outside the domain) and infinities; elsewhere a few ulp.
    np.testing.assert_array_equal(np.isnan(compiled), np.isnan(reference))
    finite = np.isfinite(reference)
    np.testing.assert_array_equal(compiled[~finite & ~np.isnan(reference)], reference[~finite & ~np.isnan(reference)])
    np.testing.assert_allclose(compiled[finite], reference[finite], rtol=TOLERANCE[dtype], atol=0)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_the_jacobi_functions_agree(dtype, monkeypatch):
    """sn, cn, dn, am over m in [-1, 1] (with m = 0, m = 1 and mc down to 1e-300) and |u| up to 1e4."""
    rng = np.random.default_rng(2)
    u = rng.uniform(-1e4, 1e4, 4000) * 10.0 ** rng.uniform(-6, 0, 4000)
    mc = np.concatenate([10 ** rng.uniform(-300 if dtype == np.float64 else -30, 0.3, 3990), [0, 1] * 5])
    arguments = [a.astype(dtype) for a in (u, 1 - mc, mc)]
    results = {}
    for path in ("compiled", "jax"):
        monkeypatch.setenv("FRBJAX_KERNELS", path)
        results[path] = [np.asarray(v) for v in special.ellipj(arguments[0], arguments[1], mc=arguments[2])]
    # Absolute error of a few ulp of u: |d/du| <= 1 for sn, cn, dn and am, so the rounding of u (and its
    # reduction modulo the period at that precision) costs eps |u| whatever m.  The number of periods,
    # |u| / K, understates that next to m = 1, where the functions turn over a width of order 1 however
    # long the period: at u = 6804, mc = 5e-155 the paths differ by 1.3e-13 (each within 3e-13 of mpmath,
    # eps |u| = 1.5e-12), 1.8e-13 of one "period" where K(1 - mc) rounds to K(1) = inf.
    scale = 1 + np.abs(u)
    for compiled, reference in zip(results["compiled"], results["jax"]):
        assert np.all(np.isfinite(compiled))
        assert np.max(np.abs(compiled - reference) / scale) <= JACOBI_TOLERANCE[dtype]


def test_the_paths_agree_on_first_derivatives(monkeypatch):
    """R_J's gradient at a few points (each path against mpmath: the modules above; the paths'
    Hessians against each other: tests/special/test_second_derivatives.py, where the JAX path's
    Hessian is compiled once for both checks)."""
    points = jnp.array([[0.5, 1.0, 2.0, 3.0], [0.0, 1e-3, 1.0, 0.2], [1.0, 2.0, 3.0, 1e3]])
    results = {}
    for path in ("compiled", "jax"):
        monkeypatch.setenv("FRBJAX_KERNELS", path)
        jax.clear_caches()
        function = lambda v: special.elliprj(*v)  # noqa: E731
        results[path] = np.asarray(jax.jit(jax.vmap(jax.grad(function)))(points))
    jax.clear_caches()
    np.testing.assert_allclose(results["compiled"], results["jax"], rtol=1e-13)


def test_odd_shapes_stay_inside_their_buffers():
    """Zero-size batches, scalars, broadcasting, non-contiguous inputs, vmap, jit and eval_shape."""
    assert special.elliprf(jnp.zeros((0, 3)), 1.0, 2.0).shape == (0, 3)
    assert special.elliprj(1.0, 2.0, 3.0, 4.0).shape == ()
    grid = np.arange(1, 13, dtype=np.float64).reshape(3, 4)
    transposed = grid.T  # non-contiguous in numpy: copied into XLA's layout before the call
    np.testing.assert_array_equal(
        special.elliprd(transposed, 1.0, 2.0), special.elliprd(np.ascontiguousarray(transposed), 1.0, 2.0)
    )
    row = special.elliprc(grid[:, :1], grid[0])  # (3, 1) with (4,) -> (3, 4)
    assert row.shape == (3, 4)
    mapped = jax.jit(jax.vmap(special.elliprf, in_axes=(0, None, 0)))(grid, 2.0, grid)
    np.testing.assert_allclose(mapped, special.elliprf(grid, 2.0, grid), rtol=0)
    shape = jax.eval_shape(special.elliprj, jnp.ones((5, 1)), 1.0, 2.0, jnp.ones(7))
    assert shape.shape == (5, 7)


def test_large_batches_split_over_the_thread_pool_give_the_same_bits():
    """A batch above a chunk (csrc/parallel.hpp: 1024 points for values, 256 for first derivatives)
    is split over XLA's intra-op thread pool where it has more than one thread (as on the two-core
    machines of CI): each point's result is the one computed alone, to the bit, with none missed or
    written twice, for values, their partials, and Jacobi's functions."""
    assert _compiled._module() is not None  # registers the handlers
    rng = np.random.default_rng(7)
    arguments = _arguments(rng, 3, np.float64, 3000)
    whole = np.asarray(_compiled.call("elliprf", 0, [jnp.asarray(a) for a in arguments]))
    partials = np.asarray(_compiled.call("elliprf", 1, [jnp.asarray(a) for a in arguments]))
    # Pieces of 100 points run on the calling thread alone.
    for start in range(0, 3000, 100):
        piece = [jnp.asarray(a[start : start + 100]) for a in arguments]
        assert np.array_equal(
            np.asarray(_compiled.call("elliprf", 0, piece)), whole[start : start + 100], equal_nan=True
        )
        assert np.array_equal(
            np.asarray(_compiled.call("elliprf", 1, piece)), partials[start : start + 100], equal_nan=True
        )
    u, m = rng.uniform(-50, 50, 5000), rng.uniform(0, 1, 5000)
    jacobi = lambda k: _compiled.call("ellipj", 0, [jnp.asarray(a[k]) for a in (u, m, 1 - m)], width=4)  # noqa: E731
    alone = np.concatenate([np.asarray(jacobi(slice(k, k + 500))) for k in range(0, 5000, 500)])
    assert np.array_equal(np.asarray(jacobi(slice(None))), alone, equal_nan=True)
