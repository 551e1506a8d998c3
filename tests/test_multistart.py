"""frbjax._multistart: starts solved one after another (lax.map, CPU) and batched (vmap, accelerators)
give the same solutions.

The fits use the sequential path on CPU; the batched one is what they run on a GPU, so both are run
here on a small least-squares problem with optimistix's Levenberg-Marquardt (the fits' solver, whose
loops vmap batches), an absent (None) argument included.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from frbjax._multistart import solve_each, starts_in_sequence


TIMES = jnp.linspace(0.0, 3.0, 40)
DATA = 1.7 * jnp.exp(-0.8 * TIMES) * jnp.cos(2.3 * TIMES)


def _residuals(parameters, _):
    amplitude, decay, frequency = parameters
    return amplitude * jnp.exp(-decay * TIMES) * jnp.cos(frequency * TIMES) - DATA


def _solve(start, offset, absent):
    assert absent is None
    solution = optx.least_squares(
        _residuals, optx.LevenbergMarquardt(rtol=1e-12, atol=1e-12), start + offset, max_steps=200, throw=False
    )
    return solution.value, optx.RESULTS.successful == solution.result


@jax.jit
def _both(starts, offsets):
    return (
        solve_each(_solve, (starts, offsets, None), in_sequence=True),
        solve_each(_solve, (starts, offsets, None), in_sequence=False),
    )


def test_sequence_and_batch_agree():
    starts = jnp.array([[1.0, 1.0, 2.0], [2.0, 0.5, 2.5], [1.5, 0.9, 2.2], [0.5, 1.5, 1.0]])
    offsets = jnp.zeros_like(starts).at[:, 0].set(0.1)
    (sequence, sequence_ok), (batch, batch_ok) = _both(starts, offsets)
    assert sequence.shape == batch.shape == starts.shape
    assert np.all(np.asarray(sequence_ok)) and np.all(np.asarray(batch_ok))
    # Measured: every start converges to the truth to 2.2e-16, and the two paths agree bit for bit
    # (batched linear algebra could round differently elsewhere: the bound allows a few ulp).
    np.testing.assert_allclose(np.asarray(sequence), np.tile([1.7, 0.8, 2.3], (4, 1)), rtol=1e-14)
    np.testing.assert_allclose(np.asarray(sequence), np.asarray(batch), rtol=1e-14)


def test_default_follows_the_backend():
    """Without ``in_sequence`` the backend chooses: sequential on CPU (what the fits use here)."""
    starts = jnp.array([[1.0, 1.0, 2.0], [2.0, 0.5, 2.5]])
    values, ok = jax.jit(lambda s: solve_each(_solve, (s, jnp.zeros_like(s), None)))(starts)
    assert np.all(np.asarray(ok))
    np.testing.assert_allclose(np.asarray(values), np.tile([1.7, 0.8, 2.3], (2, 1)), rtol=1e-14)


def test_cpu_solves_in_sequence():
    assert starts_in_sequence() == (jax.default_backend() == "cpu")
