"""The vectorised cosine and sine of ``frbjax.special._circular`` against mpmath at 40 digits.

They replace XLA's scalar float64 calls in the motion's evaluation, so they must be as accurate as
the functions they replace: errors in units of the last place of the result (ulp), measured
2026-11-26 on these grids: at most 0.65 ulp (numpy's 0.51), with a mean of 0.25 ulp like numpy's.
The bounds below add a margin of about 10 percent; the mean is bounded too, so that a systematic
bias cannot hide under the maximum.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import mpmath
import numpy as np

from frbjax.special._circular import cos_sin


MAX_ULP, MEAN_ULP = 0.72, 0.27


def _ulps(values, references):
    """|value - reference| in units of the last place of the value (40-digit references)."""
    values = np.asarray(values, dtype=np.float64)
    errors = [float(abs(mpmath.mpf(float(v)) - r)) for v, r in zip(values, references)]
    return np.asarray(errors) / np.spacing(np.abs(values))


@functools.cache
def _angles():
    rng = np.random.default_rng(11)
    blocks = [
        rng.uniform(-1, 1, 600),
        rng.uniform(-10, 10, 600),
        rng.uniform(-1e3, 1e3, 600),
        rng.uniform(-8e5, 8e5, 600),
        # Next to multiples of pi/2, where the reduced argument is small and cancellation is worst.
        rng.integers(-100000, 100000, 600) * (np.pi / 2) + rng.normal(size=600) * 1e-9,
    ]
    return np.concatenate(blocks)


def test_cos_sin_against_mpmath():
    with mpmath.workdps(40):
        x = _angles()
        cosine, sine = jax.jit(cos_sin)(jnp.asarray(x))
        cos_errors = _ulps(cosine, [mpmath.cos(mpmath.mpf(v)) for v in x])
        sin_errors = _ulps(sine, [mpmath.sin(mpmath.mpf(v)) for v in x])
    assert cos_errors.max() <= MAX_ULP and sin_errors.max() <= MAX_ULP
    assert cos_errors.mean() <= MEAN_ULP and sin_errors.mean() <= MEAN_ULP


def test_far_and_special_arguments_as_numpy():
    """Arguments beyond the reduction's range, infinities and NaN go through XLA's own cos and sin (the
    whole batch: a conditional); signed zeros keep their sign."""
    far = np.array([1e6, -3.3e7, 1e300, np.inf, np.nan, 0.5, -0.0])
    cosine, sine = cos_sin(jnp.asarray(far))
    np.testing.assert_allclose(np.asarray(cosine), np.cos(far), rtol=2e-16, atol=0)
    np.testing.assert_allclose(np.asarray(sine), np.sin(far), rtol=2e-16, atol=0)
    near = np.array([0.0, -0.0, 1e-300, -1e-20])
    cosine, sine = cos_sin(jnp.asarray(near))
    np.testing.assert_array_equal(np.asarray(sine), np.sin(near))
    np.testing.assert_array_equal(np.signbit(np.asarray(sine)), np.signbit(near))
    np.testing.assert_array_equal(np.asarray(cosine), np.ones(4))


def test_derivatives_and_float32():
    """Derivatives are the functions' (forward and reverse, second order through the rule itself);
    float32 takes XLA's functions unchanged."""
    x = jnp.asarray([0.3, -2.0, 40.0])
    np.testing.assert_allclose(jax.vmap(jax.grad(lambda v: cos_sin(v)[1]))(x), np.cos(np.asarray(x)), rtol=1e-15)
    np.testing.assert_allclose(jax.vmap(jax.hessian(lambda v: cos_sin(v)[0]))(x), -np.cos(np.asarray(x)), rtol=1e-15)
    _, tangent = jax.jvp(lambda v: cos_sin(v)[0], (x,), (jnp.full(3, 0.5),))
    np.testing.assert_allclose(tangent, -0.5 * np.sin(np.asarray(x)), rtol=1e-15)
    x32 = jnp.asarray([0.3, 2.0], jnp.float32)
    assert cos_sin(x32)[0].dtype == jnp.float32
    np.testing.assert_array_equal(np.asarray(cos_sin(x32)[1]), np.asarray(jnp.sin(x32)))


def test_no_scalar_library_calls_outside_the_far_branch():
    """The reason for the module: XLA's float64 sine and cosine are scalar calls.  The program holds one
    of each, in the conditional's branch for far arguments, and none elsewhere."""
    text = jax.jit(cos_sin).lower(jnp.linspace(-5.0, 5.0, 64)).as_text()
    assert text.count("stablehlo.cosine") == 1 and text.count("stablehlo.sine") == 1
