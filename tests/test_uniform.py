"""The functions of kappa t^2 in the derivative rule of a uniform rotation (frbjax._uniform) against mpmath.

f1 = sin x / x, f2 = (1 - cos x) / x^2, f3 = (x - sin x) / x^3 at x = sqrt(y) (sinh and cosh of
sqrt(-y) for y < 0: the unstable spin), by their Taylor series for |y| < 1 (f3: 4) and in closed form beyond,
at 40 digits.  The derivatives they give are checked in tests/test_gradients_body.py (32-digit
Jacobians at every uniform rotation) and tests/test_inertia_tensor.py (tensor bodies, both branches).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mpmath
import numpy as np

from frbjax._uniform import response_functions


# Both signs, both sides of the series limit |y| = 1, up to the overflow guard (sqrt(-y) = 700).
ARGUMENTS = np.array(
    [
        -4.0e5,
        -400.0,
        -9.0,
        -1.0000001,
        -1.0,
        -0.9999999,
        -0.5,
        -1e-3,
        -3.99,
        -4.01,
        -1e-20,
        0.0,
        1e-20,
        1e-3,
        0.5,
        3.99,
        4.01,
        0.9999999,
        1.0,
        1.0000001,
        2.0,
        30.0,
        1e4,
        1e8,
    ]
)
# The error measure: |f - f_ref| / max(|f_ref|, envelope), envelope 1/x, 1/x^2, 1/x^2 for y > 1 (where
# the functions oscillate through 0), in units of the conditioning of x = sqrt|y| itself,
# eps max(1, x) (sin, cos, sinh of an x that carries an ulp of rounding).  Worst measured 0.88 units
# (y = -4e5); the bound is 2.
UNITS = 2.0


def reference(y):
    with mpmath.workdps(80):
        y = mpmath.mpf(float(y))
        if y == 0:
            return 1.0, 0.5, 1.0 / 6.0
        x = mpmath.sqrt(abs(y))
        if y > 0:
            values = (mpmath.sin(x) / x, (1 - mpmath.cos(x)) / x**2, (x - mpmath.sin(x)) / x**3)
        else:
            values = (mpmath.sinh(x) / x, (mpmath.cosh(x) - 1) / x**2, (mpmath.sinh(x) - x) / x**3)
        return tuple(float(v) for v in values)


def test_response_functions_match_mpmath():
    jax.config.update("jax_enable_x64", True)
    values = np.asarray(response_functions(jnp.asarray(ARGUMENTS)))
    expected = np.array([reference(y) for y in ARGUMENTS]).T
    x = np.sqrt(np.abs(ARGUMENTS))
    oscillating = ARGUMENTS > 1
    inverse = 1 / np.maximum(x, 1)
    envelope = np.stack(
        [np.where(oscillating, inverse, 0), np.where(oscillating, inverse**2, 0), np.where(oscillating, inverse**2, 0)]
    )
    error = np.abs(values - expected) / np.maximum(np.abs(expected), envelope)
    units = error / (np.finfo(float).eps * np.maximum(1, x))
    print(f"\nworst error {units.max():.2f} units of eps max(1, sqrt|y|)")
    assert units.max() <= UNITS, dict(zip(ARGUMENTS, units.max(0)))


def test_unstable_growth_saturates_finite():
    """Beyond sqrt(-y) = 700 (an unstable spin's e^700) the functions stop growing: finite, never inf."""
    jax.config.update("jax_enable_x64", True)
    values = np.asarray(response_functions(jnp.asarray([-1e6, -1e12])))
    assert np.all(np.isfinite(values))
    np.testing.assert_allclose(values[:, 0], values[:, 1], rtol=0)
