"""The theta-function series of frbjax._series against mpmath at 40 digits.

Checks the nome, sn/cn/dn and the third-kind integral along the orbit, as the body evaluates them
(coefficients once per parameter, then ``evaluate_series``), for parameters up to the largest nome the
series serves (q = 0.45, m ~ 0.9995), characteristics from -1e-12 to -1, m = 0 exactly, and arguments
over several half-periods (the quasi-periodic continuation).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mpmath
import numpy as np
import pytest

from frbjax import _series

jax.config.update("jax_enable_x64", True)
mpmath.mp.dps = 40

# (m, chi): both ends of the range of m the series serves, a symmetric body (m = 0), tiny and
# extreme characteristics.
CASES = [(0.5, -0.3), (0.2, -1.0), (0.9, -1.0), (0.9995, -1.0), (0.9995, -0.01), (0.3, -1e-8),
         (0.0, -0.5), (1e-12, -0.7), (0.7, -1e-12), (0.5, -50.0), (0.9, -1e4), (0.0, -30.0)]


def reference(m, chi, u):
    """(sn, cn, dn, Pi(chi; am u|m)) at 40 digits; am continued through whole half-periods."""
    m, chi, u = mpmath.mpf(m), mpmath.mpf(chi), mpmath.mpf(u)
    quarter = mpmath.ellipk(m)
    turns = mpmath.nint(u / (2 * quarter))
    reduced = u - 2 * quarter * turns
    sn = mpmath.ellipfun("sn", u, m=m)
    cn = mpmath.ellipfun("cn", u, m=m)
    dn = mpmath.ellipfun("dn", u, m=m)
    amplitude = mpmath.asin(mpmath.ellipfun("sn", reduced, m=m))
    third = mpmath.ellippi(chi, amplitude, m) + 2 * turns * mpmath.ellippi(chi, m)
    return [float(v) for v in (sn, cn, dn, third)]


@pytest.mark.parametrize("m, chi", CASES)
def test_series_against_mpmath(m, chi):
    m_, chi_ = jnp.float64(m), jnp.float64(chi)
    mc = jnp.float64(1 - m)  # exact for these m (and consistent with mpmath's 1 - m)
    data = _series.coefficients(m_, mc, chi_)
    quarter = data.quarter
    # K(m) = R_F(0, mc, 1): measured two ulp (4.4e-16) at worst over these cases.
    assert abs(float(quarter) / float(mpmath.ellipk(m)) - 1) <= 6.7e-16
    assert float(data.nome) <= 0.45
    u = np.linspace(-3.3, 3.3, 23) * float(quarter)
    sn_r, cn_r, dn, periodic, turns = _series.evaluate_series(data, mc, jnp.asarray(u))
    parity = 1 - 2 * np.mod(np.asarray(turns), 2)
    # Pi(chi; am u|m) = u Pi(chi|m)/K + A arg theta_4(v + i alpha') (module note).
    complete = float(mpmath.ellippi(chi, m))
    third = u * complete / float(quarter) + np.asarray(periodic)
    ours = np.stack([parity * np.asarray(sn_r), parity * np.asarray(cn_r), np.asarray(dn), third], -1)
    theirs = np.array([reference(m, chi, x) for x in u])
    # Errors relative to the argument's size in half-periods (the reduction u - 2jK rounds like u).
    scale = 1 + np.abs(u) / float(quarter)
    jacobi = (np.abs(ours[:, :3] - theirs[:, :3]) / scale[:, None]).max()
    third_kind = (np.abs(ours[:, 3] - theirs[:, 3]) / np.maximum(1, np.abs(theirs[:, 3]))).max()
    # Measured over these cases: Jacobi functions 5.5e-16 times (1 + |u|/K), third kind 6.5e-16
    # relative to max(1, |Pi|) (characteristics down to -1e4, where Pi is steep).
    assert jacobi <= 1e-15, jacobi
    assert third_kind <= 1e-15, third_kind


@pytest.mark.parametrize("m", [0.0, 0.3, 0.9, 0.999])
@pytest.mark.parametrize("chi", [-1e2, -1e4, -1.5e6, -1e8, -1e10])
def test_third_kind_relative_to_its_scale_for_large_characteristics(m, chi):
    """Pi(chi; am u|m) to an ulp of Pi(chi|m) ~ 1/sqrt(-chi) where -chi is large.

    The body multiplies Pi by alpha ~ sqrt(-chi) (L next to the axis its orbit circles) and subtracts
    an angle of the same size, so Pi is needed to an ulp of its own scale, not of max(1, |Pi|): near
    u = 0 the real part of theta_4(v + i alpha') is a difference of two numbers near 1 - rho -> 0
    unless it is formed as theta_4(i alpha') - 2 sum c_n sin^2(n v).  (The form 1 + sum c_n cos(2nv)
    gave 2.4e-14 at chi = -1.5e6, a 20-ulp attitude error at t = 0 for a body with moments (1, 1, 2).)
    """
    m_, mc = jnp.float64(m), jnp.float64(1 - m)
    data = _series.coefficients(m_, mc, jnp.float64(chi))
    quarter = data.quarter
    u = np.concatenate([[1e-12, 1e-8, 1e-5, 1e-3, -3e-4, 0.1], np.linspace(-1, 1, 9) * float(quarter)])
    _, _, _, periodic, _ = _series.evaluate_series(data, mc, jnp.asarray(u))
    complete = mpmath.ellippi(chi, m)
    ours = u * float(complete) / float(quarter) + np.asarray(periodic)
    theirs = np.array([reference(m, chi, x)[3] for x in u])
    # Measured over these cases: 2.2e-16 relative to |Pi(chi|m)|.
    assert (np.abs(ours - theirs) / float(abs(complete))).max() <= 4e-16


def test_nome_against_mpmath():
    m = np.array([0.0, 1e-200, 1e-8, 0.1, 0.5, 0.50000001, 0.9, 0.999, 0.9995])
    mc = 1 - m
    q, q_over_m = _series.nome(jnp.asarray(m), jnp.asarray(mc))
    with mpmath.workdps(400):  # 1 - m must not round to 1 for m = 1e-200
        expected = np.array([float(mpmath.qfrom(m=mpmath.mpf(x))) for x in m])
    relative = np.abs(np.asarray(q) - expected) / np.maximum(expected, 1e-300)
    # Measured: 2.6e-16 (Landen series below m = 1/2, and through ln q ln q' = pi^2 above).
    assert relative.max() <= 6e-16, relative
    # q/m is finite at m = 0 (limit 1/16) and agrees with q/m elsewhere.
    assert abs(float(q_over_m[0]) - 1 / 16) <= 1e-17
    assert np.allclose(np.asarray(q_over_m)[2:], expected[2:] / m[2:], rtol=2e-15, atol=0)


def test_coefficient_gradients_are_finite():
    """No NaN in the gradient of the series data at m = 0 (q = 0) or for a tiny characteristic."""

    def total(m, chi):
        mc = 1 - m
        data = _series.coefficients(m, mc, chi)
        return jnp.sum(data.rows) + data.amplitude + data.origin + data.quarter + data.nome

    for m, chi in [(0.0, -0.5), (0.3, -1e-12), (0.9, -1.0), (0.0, -30.0)]:
        grads = jax.grad(total, argnums=(0, 1))(jnp.float64(m), jnp.float64(chi))
        assert all(np.isfinite(np.asarray(g)).all() for g in grads), (m, chi, grads)
