"""Domains of the special functions: values outside them are NaN as in scipy.special, and the corners
of the third kind's domain that the public-input harness found NaN are values (against mpmath).

Pi(n|m) with m <= n < -1 (both negative) was NaN: DLMF 19.7.8 moves n < -1 to omega = m / n, which
needs omega < 1; those points now keep n.  References: mpmath at 30 digits, computed here (a few
points, milliseconds).
"""

from __future__ import annotations

import mpmath
import numpy as np
import pytest
import scipy.special

from frbjax import special


mpmath.mp.dps = 30

# (n, m) with m <= n < -1, and neighbours on the other side of n = m.
THIRD_KIND = [
    (-2.0, -2.0),
    (-1.9, -2.0),
    (-2.0, -3.0),
    (-10.0, -50.0),
    (-1e3, -1e4),
    (-1e5, -1e5),
    (-2.5, -2.0),
    (-3.0, -2.0),
    (-1.5, 0.5),
]


@pytest.mark.parametrize("n, m", THIRD_KIND)
def test_complete_third_kind_with_negative_parameter(n, m):
    expected = float(mpmath.ellippi(n, m))
    # Measured: at most 1.3e-15 relative (n = -1e5), 4.4e-16 for |n| < 10.
    assert abs(float(special.ellippi(n, m)) / expected - 1) < 3e-15


@pytest.mark.parametrize("n, phi, m", [(-2.0, 0.7, -2.0), (-2.0, 1.2, -3.0), (-1.9, 0.5, -2.0), (-5.0, 1.0, -5.0)])
def test_incomplete_third_kind_with_negative_parameter(n, phi, m):
    expected = float(mpmath.ellippi(n, phi, m))
    # Measured: at most 4.7e-16 relative.
    assert abs(float(special.ellippiinc(n, phi, m)) / expected - 1) < 2e-15


@pytest.mark.parametrize(
    "name, arguments",
    [
        ("ellipe", (1.5,)),
        ("ellipe", (4.0,)),
        ("elliprc", (-1.0, 0.0)),
        ("elliprc", (-1.0, 2.0)),
        ("elliprc", (1.0, 0.0)),
    ],
)
def test_outside_the_domain_nan_as_scipy(name, arguments):
    assert np.isnan(getattr(scipy.special, name)(*arguments))
    assert np.isnan(float(getattr(special, name)(*arguments)))


def test_inside_the_domain_unchanged():
    """The points next to those edges keep scipy's values."""
    for name, arguments in [("ellipe", (1.0,)), ("ellipe", (-3.0,)), ("elliprc", (2.0, -1.0)), ("elliprc", (0.0, 1.0))]:
        np.testing.assert_allclose(
            float(getattr(special, name)(*arguments)), getattr(scipy.special, name)(*arguments), rtol=4e-16
        )
