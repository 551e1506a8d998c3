"""The vectorised cosine, sine and arctan2 of ``frbjax.special._circular`` against mpmath at 40 digits.

They replace XLA's scalar float64 calls in the motion's evaluation, so they must be as accurate as
the functions they replace: errors in units of the last place of the result (ulp), measured
2026-11-26 on these grids: cos_sin at most 0.65 ulp (numpy's 0.51), arctan2 at most 0.50 ulp
(numpy's 0.78: it is rounded correctly to within 0.001 ulp), both with a mean of 0.25 ulp like
numpy's.  The bounds below add a margin of about 10 percent; the means are bounded too, so that a
systematic bias cannot hide under the maximum.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import mpmath
import numpy as np
import pytest

from frbjax.special._circular import arctan2, cos_sin

COS_SIN_MAX_ULP, ARCTAN2_MAX_ULP, MEAN_ULP = 0.72, 0.55, 0.27


def _ulps(values, references):
    """|value - reference| in units of the last place of the value (40-digit references)."""
    values = np.asarray(values, dtype=np.float64)
    errors = [float(abs(mpmath.mpf(float(v)) - r)) for v, r in zip(values, references)]
    return np.asarray(errors) / np.spacing(np.abs(values))


@functools.lru_cache(maxsize=None)
def _angles():
    rng = np.random.default_rng(11)
    blocks = [rng.uniform(-1, 1, 600), rng.uniform(-10, 10, 600), rng.uniform(-1e3, 1e3, 600),
              rng.uniform(-8e5, 8e5, 600),
              # Next to multiples of pi/2, where the reduced argument is small and cancellation is worst.
              rng.integers(-100000, 100000, 600) * (np.pi / 2) + rng.normal(size=600) * 1e-9]
    return np.concatenate(blocks)


@functools.lru_cache(maxsize=None)
def _points():
    rng = np.random.default_rng(12)
    y, x = rng.normal(size=(2, 2400)) * np.repeat([1.0, 1e-150, 1e150], 800)
    # Ratios next to the reduction's interval ends 3/16, 7/16, 11/16 and 1, both sides.
    ends = np.repeat([3 / 16, 7 / 16, 11 / 16, 1.0], 50) * (1 + rng.uniform(-1e-9, 1e-9, 200))
    return np.concatenate([y, ends, -ends]), np.concatenate([x, np.ones(200), -np.ones(200)])


def test_cos_sin_against_mpmath():
    with mpmath.workdps(40):
        x = _angles()
        cosine, sine = jax.jit(cos_sin)(jnp.asarray(x))
        cos_errors = _ulps(cosine, [mpmath.cos(mpmath.mpf(v)) for v in x])
        sin_errors = _ulps(sine, [mpmath.sin(mpmath.mpf(v)) for v in x])
    assert cos_errors.max() <= COS_SIN_MAX_ULP and sin_errors.max() <= COS_SIN_MAX_ULP
    assert cos_errors.mean() <= MEAN_ULP and sin_errors.mean() <= MEAN_ULP


def test_arctan2_against_mpmath():
    with mpmath.workdps(40):
        y, x = _points()
        angle = jax.jit(arctan2)(jnp.asarray(y), jnp.asarray(x))
        errors = _ulps(angle, [mpmath.atan2(mpmath.mpf(a), mpmath.mpf(b)) for a, b in zip(y, x)])
    assert errors.max() <= ARCTAN2_MAX_ULP
    assert errors.mean() <= MEAN_ULP


def test_special_values_as_numpy():
    """Signed zeros, the origin, axes and NaN as IEEE 754 (numpy); arguments beyond the reduction's
    range, infinities and NaN through XLA's own cos and sin."""
    y = np.array([0.0, -0.0, 0.0, -0.0, 1.0, -1.0, 0.0, -0.0, 3.0, -3.0, np.nan, 1.0])
    x = np.array([0.0, 0.0, -0.0, -0.0, -0.0, -0.0, -1.0, -1.0, -4.0, 4.0, 1.0, np.nan])
    got = np.asarray(arctan2(jnp.asarray(y), jnp.asarray(x)))
    expected = np.arctan2(y, x)
    np.testing.assert_array_equal(np.signbit(got), np.signbit(expected))
    np.testing.assert_allclose(got, expected, rtol=3e-16, atol=0)
    far = np.array([1e6, -3.3e7, 1e300, np.inf, np.nan, 0.5])
    cosine, sine = cos_sin(jnp.asarray(far))
    np.testing.assert_allclose(np.asarray(cosine), np.cos(far), rtol=2e-16, atol=0)
    np.testing.assert_allclose(np.asarray(sine), np.sin(far), rtol=2e-16, atol=0)


def test_derivatives_and_float32():
    """Derivatives are the functions' (forward and reverse, second order through the rule itself);
    float32 takes XLA's functions unchanged."""
    x = jnp.asarray([0.3, -2.0, 40.0])
    np.testing.assert_allclose(jax.vmap(jax.grad(lambda v: cos_sin(v)[1]))(x), np.cos(np.asarray(x)), rtol=1e-15)
    np.testing.assert_allclose(jax.vmap(jax.hessian(lambda v: cos_sin(v)[0]))(x), -np.cos(np.asarray(x)),
                               rtol=1e-15)
    dy, dx = jax.grad(arctan2, argnums=(0, 1))(1.0, -2.0)
    np.testing.assert_allclose([dy, dx], [-2.0 / 5, -1.0 / 5], rtol=1e-15)
    _, tangent = jax.jvp(arctan2, (1.0, -2.0), (0.5, 0.25))
    np.testing.assert_allclose(tangent, (-2.0 * 0.5 - 0.25) / 5, rtol=1e-15)
    x32 = jnp.asarray([0.3, 2.0], jnp.float32)
    assert cos_sin(x32)[0].dtype == jnp.float32
    np.testing.assert_array_equal(np.asarray(cos_sin(x32)[1]), np.asarray(jnp.sin(x32)))
    np.testing.assert_array_equal(np.asarray(arctan2(x32, x32[::-1])), np.asarray(jnp.arctan2(x32, x32[::-1])))


@pytest.mark.parametrize("function", ["cos_sin", "arctan2"])
def test_no_scalar_library_calls(function):
    """Not a timing: the reason for the module is that XLA's float64 calls are scalar.  The compiled
    program must hold no call of XLA's sine, cosine or atan2 outside the conditional for far
    arguments."""
    x = jnp.linspace(-5.0, 5.0, 64)
    if function == "cos_sin":
        text = jax.jit(lambda v: cos_sin(v)).lower(x).as_text()
        # The far-argument branch keeps XLA's cos and sin: exactly one of each.
        assert text.count("stablehlo.cosine") == 1 and text.count("stablehlo.sine") == 1
    else:
        text = jax.jit(arctan2).lower(x, x[::-1]).as_text()
        assert "atan2" not in text
