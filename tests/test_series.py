"""The theta-function series of frbjax._series against mpmath at 40 to 60 digits.

Checks the nome, sn/cn/dn and the third-kind integral along the orbit, as the body evaluates them
(coefficients once per parameter, then ``evaluate_series``): the direct series (nome q) for
parameters up to the largest nome it serves (q = 0.45, m ~ 0.99993), characteristics from -1e-12 to
-1e10, m = 0 exactly, and arguments over several half-periods (the quasi-periodic continuation); the
complementary series (nome q') from m = 0.999 to m = 1 - 1e-30, and its separatrix limit m = 1.

The expanded integral is Pi(chi; am u|m) - u for chi >= -1 and Pi(chi; am u|m) for chi < -1 (the
convention of ``special._legendre.pi_without_first_kind``); the body adds 2 turns times the complete
one to the series' integral over the reduced argument.
"""

from __future__ import annotations

import json
import pathlib

import jax
import jax.numpy as jnp
import mpmath
import numpy as np
import pytest
from _series_reference import CHARACTERISTICS, COMPLEMENTS, complete, expanded, reference

from frbjax import _series


jax.config.update("jax_enable_x64", True)
mpmath.mp.dps = 40

# (m, chi): both ends of the range of m the direct series serves, a symmetric body (m = 0), tiny and
# extreme characteristics.
CASES = [
    (0.5, -0.3),
    (0.2, -1.0),
    (0.9, -1.0),
    (0.9995, -1.0),
    (0.9995, -0.01),
    (0.3, -1e-8),
    (0.0, -0.5),
    (1e-12, -0.7),
    (0.7, -1e-12),
    (0.5, -50.0),
    (0.9, -1e4),
    (0.0, -30.0),
]

SERIES_DATA = pathlib.Path(__file__).parent / "data" / "series_references.json"

# The series as the body runs them: compiled once (per argument shape) and shared by every case.  Run
# eagerly, each call re-traced and compiled the series' loops (about 6 s per test).  The forced
# complementary series is its own program, traced while ``_largest_nome`` is patched (see
# test_complementary_series_against_mpmath).
_coefficients = {False: jax.jit(lambda m, mc, chi: _series.coefficients(m, mc, chi))}
_evaluate_series = jax.jit(_series.evaluate_series)
_at_separatrix = jax.jit(_series.at_separatrix)


def coefficients(m, mc, chi, forced=False):
    """``_series.coefficients`` at float64 scalars, compiled (``forced``: the program traced with
    the complementary series forced, under the test's patch)."""
    if forced not in _coefficients:
        _coefficients[forced] = jax.jit(lambda m, mc, chi: _series.coefficients(m, mc, chi))
    return _coefficients[forced](jnp.float64(m), jnp.float64(mc), jnp.float64(chi))


def evaluate(data, mc, chi, u, whole_integral=None):
    """(sn, cn, dn, expanded integral) from the series, continued as the body continues them."""
    sn_r, cn_r, dn, reduced, turns = _evaluate_series(data, jnp.float64(mc), jnp.asarray(u))
    turns = np.asarray(turns)
    parity = 1 - 2 * np.mod(turns, 2)
    if np.any(turns):
        whole_integral = complete(mc, chi) if whole_integral is None else whole_integral
        whole = np.where(turns == 0, 0, 2 * turns * whole_integral)
    else:
        whole = 0
    third = whole + np.asarray(reduced)
    return np.stack([parity * np.asarray(sn_r), parity * np.asarray(cn_r), np.asarray(dn), third], -1)


def errors(mc, chi, data, u, theirs, whole_integral=None):
    """Worst errors of the Jacobi functions and of the integral; ``whole_integral``: the expanded
    integral at u = K (mpmath's, computed here when not given)."""
    whole_integral = complete(mc, chi) if whole_integral is None else whole_integral
    ours = evaluate(data, mc, chi, u, whole_integral)
    quarter = float(data.quarter)
    # Errors relative to the argument's size in half-periods (the reduction u - 2jK rounds like u),
    # the integral's relative to its scale (its value at u = K).
    scale = 1 + np.abs(u) / quarter
    jacobi = (np.abs(ours[:, :3] - theirs[:, :3]) / scale[:, None]).max()
    third = (np.abs(ours[:, 3] - theirs[:, 3]) / scale / abs(whole_integral)).max()
    return jacobi, third


@pytest.mark.parametrize("m, chi", CASES)
def test_series_against_mpmath(m, chi):
    mc = 1 - m  # exact for these m (and consistent with mpmath's 1 - m)
    data = coefficients(m, mc, chi)
    quarter = data.quarter
    # K(m) = R_F(0, mc, 1): measured two ulp (4.4e-16) at worst over these cases.
    assert abs(float(quarter) / float(mpmath.ellipk(m)) - 1) <= 6.7e-16
    assert float(data.nome) <= 0.45 and not bool(data.complementary)
    u = np.linspace(-3.3, 3.3, 23) * float(quarter)
    theirs = np.array([reference(mc, chi, x) for x in u])
    ours = evaluate(data, mc, chi, u)
    scale = 1 + np.abs(u) / float(quarter)
    jacobi = (np.abs(ours[:, :3] - theirs[:, :3]) / scale[:, None]).max()
    # Relative to max(1, |Pi|) of the whole integral (characteristics down to -1e4, where Pi is steep).
    whole = theirs[:, 3] + np.where(chi >= -1, u, 0)
    third_kind = (np.abs(ours[:, 3] - theirs[:, 3]) / np.maximum(1, np.abs(whole))).max()
    # Measured over these cases: Jacobi functions 5.5e-16 times (1 + |u|/K), third kind 6.5e-16.
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
    mc = 1 - m
    data = coefficients(m, mc, chi)
    quarter = data.quarter
    u = np.concatenate([[1e-12, 1e-8, 1e-5, 1e-3, -3e-4, 0.1], np.linspace(-1, 1, 9) * float(quarter)])
    ours = evaluate(data, mc, chi, u)[:, 3]
    theirs = np.array([reference(mc, chi, x)[3] for x in u])
    # Measured over these cases: 2.2e-16 relative to |Pi(chi|m)|.
    assert (np.abs(ours - theirs) / abs(complete(mc, chi))).max() <= 4e-16


@pytest.mark.parametrize("mc, forced", [(mc, False) for mc in COMPLEMENTS] + [(1e-3, True), (1e-4, True)])
def test_complementary_series_against_mpmath(mc, forced, monkeypatch):
    """sn, cn, dn and the third kind next to the separatrix, chi from -1e-12 to -1e10.

    ``forced``: every body with m > 1/2 takes the complementary series (down to m = 0.999, q' = 6e-5,
    beyond the range it serves in float64), otherwise each takes the series chosen for it (the
    complementary one from m = 0.99993).  Points include u within 1e-9 of 0 and of K (the zeros of
    sn and cn, formed by expm1) and several half-periods.  The references are committed
    (tests/data/series_references.json, 60 digits, from tests/data/make_series_references.py: 80 s
    of mpmath that every run recomputed before).
    """
    if forced:
        monkeypatch.setattr(_series, "_largest_nome", lambda x: 0.0)
    m = 1 - mc
    cases = [case for case in json.loads(SERIES_DATA.read_text())["cases"] if case["mc"] == mc]
    assert [case["chi"] for case in cases] == CHARACTERISTICS
    worst = [0.0, 0.0]
    for case in cases:
        chi = case["chi"]
        data = coefficients(m, mc, chi, forced)
        assert bool(data.complementary) == (forced or mc < 7e-5)
        # The committed arguments are multiples of mpmath's K: the series' own is the same to rounding.
        assert abs(float(data.quarter) - case["quarter"]) <= 4e-16 * case["quarter"]
        u = np.array(case["u"])
        theirs = np.array(case["sn_cn_dn_integral"])
        for k, error in enumerate(errors(mc, chi, data, u, theirs, case["complete"])):
            worst[k] = max(worst[k], error)
    # Measured over these cases: Jacobi functions 6.3e-16 times (1 + |u|/K) (mc = 1e-8), third kind
    # 4.7e-16 of the integral at u = K, times (1 + |u|/K) (mc = 1e-12).
    assert worst[0] <= 9e-16, worst
    assert worst[1] <= 7e-16, worst


@pytest.mark.parametrize("chi", CHARACTERISTICS)
def test_separatrix_limit_against_mpmath(chi):
    """m = 1: sn = tanh, cn = dn = sech, Pi(chi; gd u|1) = (u + sqrt(-chi) arctan(sqrt(-chi) tanh u))/(1 - chi).

    The separatrix data are the stand-in body's (m = 1/2) with ``at_separatrix``; no reduction, and
    arguments up to 800 (where exp(-2u) underflows).
    """
    minus_chi = mpmath.mpf(-chi)
    gap = 1 + minus_chi
    data = coefficients(0.5, 0.5, chi)
    removed = chi >= -1
    separatrix = jnp.asarray(True)
    data = _at_separatrix(
        data,
        separatrix,
        jnp.float64(mpmath.sqrt(minus_chi / gap)),
        jnp.float64(1 / mpmath.sqrt(gap)),
        jnp.float64(mpmath.sqrt(minus_chi) / gap),
        jnp.float64((-minus_chi if removed else 1) / gap),
    )
    u = np.array([0.0, 1e-9, -3e-4, 0.2, -1.0, 3.0, 17.0, -40.0, 350.0, 800.0])
    sn, cn, dn, reduced, turns = (np.asarray(v) for v in _evaluate_series(data, jnp.float64(0.0), jnp.asarray(u)))
    assert np.all(turns == 0)
    theirs = []
    for x in u:
        x = mpmath.mpf(x)
        closed = (x + mpmath.sqrt(minus_chi) * mpmath.atan(mpmath.sqrt(minus_chi) * mpmath.tanh(x))) / gap
        if abs(x) <= 17:  # the closed form itself against mpmath's Pi(chi; gd u|1)
            direct = mpmath.ellippi(chi, mpmath.asin(mpmath.tanh(x)), 1)
            assert abs(closed - direct) <= mpmath.mpf(10) ** -25 * (1 + abs(direct))
        theirs.append([float(mpmath.tanh(x)), float(mpmath.sech(x)), float(expanded(chi, closed, x))])
    theirs = np.array(theirs)
    # Measured: tanh to 1.1e-16, sech to 2.2e-16 relative, the integral to 2.2e-16 of the scale below.
    assert np.abs(sn - theirs[:, 0]).max() <= 3.4e-16
    assert np.all(np.abs(cn - theirs[:, 1]) <= 3.4e-16 * theirs[:, 1])
    np.testing.assert_array_equal(dn, cn)
    # The integral relative to its linear part (slope |u|, rounded like a product) plus its value at u = 1.
    at_one = float(abs(expanded(chi, (1 + mpmath.sqrt(minus_chi) * mpmath.atan(mpmath.sqrt(minus_chi))) / gap, 1)))
    third = np.abs(reduced - theirs[:, 2]) / (abs(float(data.slope)) * np.abs(u) + at_one)
    assert third.max() <= 4e-16, third


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
    """No NaN in the gradient of the series data at m = 0 (q = 0), for a tiny characteristic, next to
    the separatrix, or in the values of both series at several arguments."""

    def total(m, chi, separatrix):
        mc = 1 - m
        data = _series.coefficients(m, mc, chi)
        data = _series.at_separatrix(data, separatrix, 0.6 + 0 * m, 0.8 + 0 * m, 2.0 + 0 * m, 0.1 * chi)
        values = _series.evaluate_series(data, mc, jnp.asarray([0.0, 1e-3, 0.7, -3.0, 40.0, 900.0]) * (1 + m))
        return (
            jnp.sum(data.rows)
            + jnp.sum(data.complementary_rows)
            + data.amplitude
            + data.origin
            + data.quarter
            + data.nome
            + data.slope
            + data.complementary_cn_factor
            + sum(jnp.sum(v) for v in values[:4])
        )

    gradient = jax.jit(jax.grad(total, argnums=(0, 1)))
    for m, chi in [(0.0, -0.5), (0.3, -1e-12), (0.9, -1.0), (0.0, -30.0), (1 - 1e-10, -1e-12), (1 - 1e-16, -1e6)]:
        for separatrix in (False, True):
            grads = gradient(jnp.float64(m), jnp.float64(chi), jnp.asarray(separatrix))
            assert all(np.isfinite(np.asarray(g)).all() for g in grads), (m, chi, separatrix, grads)
