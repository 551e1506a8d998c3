"""Carlson's stopping rule (R_F, R_D, R_J) and the AGM's last level (ellipj), taken per point.

The duplication stops at each point once its spread is below the threshold, and the Landen ascent
starts at each point's own last AGM level; over an array the later blocks of steps (levels) are
skipped when no point needs them, and the last block, for batches with far-apart arguments, steps
every point.  A point's value must then be the same bits alone and in a batch that skips the last
block, and agree to rounding in a batch that needs it.
Accuracy against mpmath is checked by test_carlson.py, test_jacobi.py and test_legendre.py.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import frbjax.special as special
from frbjax.special._carlson import _duplicate, _lambda, _plan
from frbjax.special._jacobi import _agm_levels, _agm_steps


EASY = 200  # more than _common.ROLLED_MAX_POINTS: the unrolled path with its skipped blocks


def _easy_and_hard(rng):
    """Arguments close together (a few duplication steps, a few AGM levels) and far apart (all)."""
    easy = dict(
        x=rng.uniform(0.9, 1.1, EASY),
        y=rng.uniform(0.9, 1.1, EASY),
        z=rng.uniform(0.9, 1.1, EASY),
        p=rng.uniform(1.1, 1.3, EASY),
        u=rng.uniform(-2, 2, EASY),
        m=rng.uniform(0.0, 0.5, EASY),
    )
    hard = dict(
        x=np.array([1e-300, 0.0]),
        y=np.array([1.0, 1e-200]),
        z=np.array([1e3, 1.0]),
        p=np.array([2e3, 1e-250]),
        u=np.array([3.0, -1.0]),
        m=np.array([1 - 1e-15, 1 - 1e-12]),
    )
    return easy, hard


FUNCTIONS = {
    "elliprf": (lambda a: special.elliprf(a["x"], a["y"], a["z"])),
    "elliprd": (lambda a: special.elliprd(a["x"], a["y"], a["z"])),
    "elliprj": (lambda a: special.elliprj(a["x"], a["y"], a["z"], a["p"])),
    # sn, cn, dn (am is XLA's arctangent of them, whose scalar and vectorised code differ by an ulp).
    "ellipj": (lambda a: jnp.stack(special.ellipj(a["u"], a["m"])[:3], -1)),
    "ellippiinc": (lambda a: special.ellippiinc(-a["p"], a["u"] / 3, a["m"])),
}


@pytest.mark.parametrize("name", sorted(FUNCTIONS))
def test_value_of_a_point_depends_on_its_batch_by_rounding_at_most(name):
    assert jax.config.jax_enable_x64
    easy, hard = _easy_and_hard(np.random.default_rng(11))
    function = jax.jit(FUNCTIONS[name])
    alone_batch = np.asarray(function(easy))
    mixed = {key: np.concatenate([easy[key], hard[key]]) for key in easy}
    with_hard = np.asarray(function(mixed))
    assert np.all(np.isfinite(with_hard[:EASY]))
    # Measured relative: R_F 5.8e-16, R_D 4.5e-16, R_J 3.9e-16, ellippiinc 1.6e-16; ellipj absolute
    # 3.3e-16 (sn, cn, dn are at most 1).
    eps = np.finfo(float).eps
    np.testing.assert_allclose(with_hard[:EASY], alone_batch, rtol=4 * eps, atol=3 * eps if name == "ellipj" else 0)
    # One point at a time: the rolled loops of a small array.
    for i in range(0, EASY, 41):
        one = np.asarray(function({key: value[i : i + 1] for key, value in easy.items()}))
        np.testing.assert_array_equal(one[0], alone_batch[i])


def test_duplication_stops_at_each_points_own_spread():
    """R_F's duplication of arguments within 3% of each other stops after at most 2 steps (spread
    below 1/16, 4^-2/16 = 2^-8), of (1e-300, 1, 1) after 5 (the spread 4^-k (A_0 - x_0)/A_k with
    A_k -> R_F^-2 = 4/pi^2), of (1e-300, 1e-300, 1) after all 12 (A_k -> 1/346^2), each point at its
    own count in a rolled loop (8 points); over an array that needs the last block every point takes
    all 12; the later blocks of the unrolled steps are a conditional."""
    assert jax.config.jax_enable_x64
    near = jnp.asarray(np.random.default_rng(3).uniform(0.97, 1.03, (3, EASY)))

    def steps_taken(x, y, z):
        mean0 = (x + y + z) / 3
        spread = jnp.maximum(jnp.maximum(jnp.abs(mean0 - x), jnp.abs(mean0 - y)), jnp.abs(mean0 - z))

        def step(state, _):
            x, y, z, mean = state
            lam, _ = _lambda(x, y, z, jnp.sqrt)
            return (x + lam) / 4, (y + lam) / 4, (z + lam) / 4, (mean + lam) / 4

        _, quarter = _duplicate(step, (x, y, z, mean0), x, False, lambda state: ((spread, state[3]),))
        return jnp.round(-jnp.log(quarter) / jnp.log(4.0))

    counts = np.asarray(jax.jit(steps_taken)(*near))
    assert counts.max() <= 2
    few = jnp.asarray([[1e-300] * 4 + [1e-300] * 4, [1.0] * 4 + [1e-300] * 4, [1.0] * 8])
    np.testing.assert_array_equal(np.asarray(jax.jit(steps_taken)(*few)), [5] * 4 + [_plan(few)[0]] * 4)
    one_small = jnp.asarray([[1e-300] * EASY, [1.0] * EASY, [1.0] * EASY])
    np.testing.assert_array_equal(np.asarray(jax.jit(steps_taken)(*one_small)), _plan(one_small)[0])
    assert "cond" in str(jax.make_jaxpr(steps_taken)(*near))


def test_agm_uses_levels_up_to_its_own_convergence():
    """mc = 0.5 uses 4 levels (gap below 2^-26 at the fourth), mc = 1e-4 6, mc = 1e-300 12 of the 13;
    the top mean is the AGM (DLMF 22.20.1: pi / (2 K))."""
    assert jax.config.jax_enable_x64
    mc = jnp.asarray([0.5, 1e-4, 1e-300] + [0.5] * EASY)
    _, _, used, mean = jax.jit(_agm_levels)(mc)
    counts = np.asarray(used).sum(-1)
    np.testing.assert_array_equal(counts[:3], [4, 6, 12])
    assert counts.max() < _agm_steps(mc)
    quarter = np.asarray(special.ellipk(1 - mc[:2], mc=mc[:2]))
    np.testing.assert_allclose(np.asarray(mean[:2]), np.pi / (2 * quarter), rtol=2e-16)
