"""Jacobi elliptic functions sn, cn, dn and the continuous amplitude am against mpmath.

Target (issue): absolute error <= 4e-15 * max(1, |u| / K(m)) for each of sn, cn, dn, am, for
0 <= m <= 1 - 1e-15 (and explicit mc down to 1e-17), |u| up to 1e6, both signs.  The allowance grows
with the number of quarter periods |u|/K because the phase u/K cannot be known better than its
float64 rounding (K is rounded, and so is u); sn, cn, dn are bounded by 1 and am by |u|/K * pi/2, so
the measure is an absolute error on the natural scale of each component.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import mpmath
import numpy as np
import pytest
import scipy.special

import frbjax.special as special

from . import _mpmath_reference as ref


# Every test here runs on both paths (conftest.py): the compiled kernels and the JAX code.
pytestmark = pytest.mark.usefixtures("special_path")


COMPONENTS = ("sn", "cn", "dn", "am")
# Issue target: 4e-15 max(1, |u|/K) in float64, 1e-5 in float32.  The tolerances are the measured worst
# errors on these grids (FRBJAX_ERROR_LOG, 2026-11-24) with a margin of about 2: float64 6.3e-16 with
# m given, 1.2e-15 with mc given (m up to 1 - 1e-15); float32 1.1e-7 to 2.6e-7.
TOL64 = {"sn": 2.5e-15, "cn": 2.5e-15, "dn": 2.5e-15, "am": 2.5e-15}
TOL32 = {"sn": 5e-7, "cn": 5e-7, "dn": 5e-7, "am": 5e-7}
TOL_SCIPY = 1e-13  # frbjax vs scipy on moderate points (scipy's own error there is ~1e-15)
TOL_IDENTITY = 1e-15  # sn^2 + cn^2 = 1, dn^2 + m sn^2 = 1 (no mpmath)

SCIPY_FAILURE = (50.0, 0.99999999997**2)
"""scipy.special.ellipj(50, 0.99999999997**2) returns cn ~ -3.9e10 (scipy 1.17); the true values at
the float64 m = 0.99999999994000000... are sn = -0.98942450106078750, cn = 0.14504880799445290,
dn = 0.14504880819692838, am = 4.8579512823911850."""


def reference_with_k(u, m):
    return (*ref.ellipj(u, m), ref.ellipk(m))


def _reference(u, m, mc):
    """((sn, cn, dn, am) hi, lo, K) at the exact inputs; m = 1 - mc when mc is given."""
    if mc is None:
        hi, lo = ref.values(lambda a, b: reference_with_k(a, b), u, m)
    else:
        hi, lo = ref.values(lambda a, c: reference_with_k(a, ref.parameter(None, c)), u, mc)
    return hi[:4], lo[:4], hi[4]


@functools.cache
def grids():
    rng = np.random.default_rng(2024)
    uni = rng.uniform
    k_scipy = 1 - ref.log_uniform(rng, -12, -4, 30)
    blocks = [
        (ref.signed(rng, ref.log_uniform(rng, -3, 1.5, 100)), uni(0, 1, 100)),  # ordinary
        (ref.signed(rng, ref.log_uniform(rng, 2, 6, 50)), uni(0, 1, 50)),  # |u| to 1e6
        (ref.signed(rng, ref.log_uniform(rng, -2, 6, 40)), 1 - ref.log_uniform(rng, -15, -1, 40)),
        (uni(5, 100, 30), k_scipy**2),  # scipy's trouble
        (
            np.array(
                [
                    0.0,
                    0.0,
                    0.0,
                    1.0,
                    1e-300,
                    1e6,
                    -1e6,
                    1e6,
                    -1e6,
                    1.0,
                    SCIPY_FAILURE[0],
                    1.8540746773013719,
                    3.7081493546027438,
                    -1.0,
                ]
            ),
            np.array(
                [
                    0.5,
                    0.0,
                    1 - 1e-15,
                    1e-300,
                    0.5,
                    0.5,
                    0.5,
                    1 - 1e-15,
                    1e-12,
                    1 - 1e-15,
                    SCIPY_FAILURE[1],
                    0.5,
                    0.5,
                    0.0,
                ]
            ),
        ),
    ]
    u = np.concatenate([b[0] for b in blocks])
    m = np.concatenate([b[1] for b in blocks])
    u_c = np.concatenate([ref.signed(rng, ref.log_uniform(rng, -2, 6, 40)), [50.0, 1e6, -1e3, 30.0]])
    mc = np.concatenate(
        [ref.log_uniform(rng, -17, 0, 20), ref.log_uniform(rng, -17, -13, 20), [1e-17, 1e-17, 1e-17, 1e-300]]
    )
    return {
        "plain": ((u, m), None, _reference(u, m, None)),
        "mc": ((u_c, 1 - mc), mc, _reference(u_c, None, mc)),
    }


@functools.cache
def jitted(with_mc=False):
    if with_mc:
        return jax.jit(lambda u, m, mc: special.ellipj(u, m, mc=mc))
    return jax.jit(special.ellipj)


def evaluate(u, m, mc=None):
    """frbjax on a grid, jit-compiled once per (mc given, dtype, padded size)."""
    if mc is None:
        out = ref.call_padded(jitted(), u, m)
    else:
        out = ref.call_padded(jitted(True), u, m, mc)
    assert len(out) == 4
    return out


def periods(u, quarter):
    """max(1, |u| / K): the allowance factor of the target (K = inf at m = 1 gives 1)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.maximum(1.0, np.abs(u) / quarter)


def _check_components(label, out, hi, lo, quarter, u, tol, inputs):
    scale = periods(u, quarter)
    for c, name in enumerate(COMPONENTS):
        err = ref.error(out[c], hi[c], lo[c])
        ref.check(
            f"ellipj {name} {label}",
            err / scale,
            tol[name],
            inputs,
            {"value": out[c], "reference": hi[c], "K": quarter},
        )


@pytest.mark.parametrize("kind", ["plain", "mc"])
def test_float64_against_mpmath(kind):
    (u, m), mc, (hi, lo, quarter) = grids()[kind]
    out = evaluate(u, m, mc)
    assert all(o.dtype == np.float64 for o in out)
    inputs = {"u": u, "m": m} if mc is None else {"u": u, "mc": mc}
    _check_components(f"({kind}) float64 error / max(1, |u|/K)", out, hi, lo, quarter, u, TOL64, inputs)


def test_scipy_failure_case():
    """scipy.special.ellipj(50, 0.99999999997**2) is badly wrong (cn ~ -3.9e10); we are not."""
    u, m = SCIPY_FAILURE
    with mpmath.workdps(40):
        m_mp = ref.mpf(m)
        truth = [float(v) for v in ref.ellipj(ref.mpf(u), m_mp)]
        quarter = float(mpmath.ellipk(m_mp))
    # Sanity of the reference itself (m is the float64 nearest 0.99999999997**2).
    assert abs(truth[1] - 0.14504880799445290) < 1e-16
    out = [float(v) for v in special.ellipj(u, m)]
    tol = 4e-15 * max(1.0, u / quarter)
    for name, got, want in zip(COMPONENTS, out, truth):
        assert abs(got - want) <= tol, f"ellipj{SCIPY_FAILURE} {name}: got {got!r}, want {want!r}"


def test_m_equal_one_limits():
    """m = 1: sn = tanh u, cn = dn = sech u, am = gd u (closed forms, also with mc = 0)."""
    u = np.concatenate([-np.logspace(-300, 6, 30), [0.0], np.logspace(-300, 6, 30)])
    expect = [np.tanh(u), 1 / np.cosh(u), 1 / np.cosh(u), 2 * np.arctan(np.tanh(u / 2))]
    for label, out in [("m=1", evaluate(u, 1.0)), ("mc=0", evaluate(u, 1.0, 0.0))]:
        for name, got, want in zip(COMPONENTS, out, expect):
            ref.check(
                f"ellipj {name} at {label} vs closed form",
                np.abs(got - want),
                TOL64[name],
                {"u": u},
                {"value": got, "expected": want},
            )


def test_m_equal_zero_limits():
    """m = 0: sn = sin u, cn = cos u, dn = 1, am = u (allowance 4e-15 * max(1, |u|/(pi/2)))."""
    u = np.concatenate([-np.logspace(-300, 6, 30), [0.0], np.logspace(-300, 6, 30)])
    out = evaluate(u, 0.0)
    expect = [np.sin(u), np.cos(u), np.ones_like(u), u]
    scale = periods(u, np.pi / 2)
    for name, got, want in zip(COMPONENTS, out, expect):
        ref.check(
            f"ellipj {name} at m=0 vs closed form",
            np.abs(got - want) / scale,
            TOL64[name],
            {"u": u},
            {"value": got, "expected": want},
        )


def test_identities_and_symmetry():
    (u, m), _, _ = grids()["plain"]
    sn, cn, dn, am = evaluate(u, m)
    ref.check("sn^2 + cn^2 = 1", np.abs(sn**2 + cn**2 - 1), TOL_IDENTITY, {"u": u, "m": m})
    ref.check("dn^2 + m sn^2 = 1", np.abs(dn**2 + m * sn**2 - 1), TOL_IDENTITY, {"u": u, "m": m})
    neg = evaluate(-u, m)
    # The reduction of u is symmetric in a sensible implementation; allow a few ulps of the phase.
    scale = np.maximum(1.0, np.abs(u))
    for name, a, b in [
        ("sn odd", neg[0], -sn),
        ("cn even", neg[1], cn),
        ("dn even", neg[2], dn),
        ("am odd", neg[3], -am),
    ]:
        ref.check(name, np.abs(a - b) / scale, 1e-15, {"u": u, "m": m})


def test_mc_matches_implicit_complement():
    rng = np.random.default_rng(7)
    m = rng.uniform(0.5, 1, 60)
    u = ref.signed(rng, ref.log_uniform(rng, -2, 4, 60))
    a = evaluate(u, m)
    b = evaluate(u, m, 1 - m)
    for name, x, y in zip(COMPONENTS, a, b):
        np.testing.assert_allclose(x, y, rtol=1e-15, atol=1e-15, err_msg=name)


def test_finite_at_domain_edges():
    u = np.array([0.0, 1e-300, -1.0, 30.0, 1e6, -1e6])[:, None]
    m = np.array([0.0, 1e-300, 0.5, 1 - 1e-15, 1.0])[None, :]
    for out in (evaluate(u, m), evaluate(u, m, 1 - m), evaluate(u, 1.0, np.array([0.0, 1e-17, 1e-300]))):
        for name, o in zip(COMPONENTS, out):
            assert np.all(np.isfinite(o)), f"{name} not finite: {o}"


# ------------------------------------------------------------------------------------- float32


@functools.cache
def grid32():
    rng = np.random.default_rng(32)
    u = rng.uniform(-10, 10, 150).astype(np.float32)
    m = rng.uniform(0, 0.95, 150).astype(np.float32)
    return u, m, _reference(u, m, None)


def test_float32_against_mpmath():
    u, m, (hi, lo, quarter) = grid32()
    out = evaluate(u, m)
    assert all(o.dtype == np.float32 for o in out)
    _check_components("float32 error / max(1, |u|/K)", out, hi, lo, quarter, u, TOL32, {"u": u, "m": m})


# --------------------------------------------------------------------------------- scipy opinion


def test_agrees_with_scipy():
    rng = np.random.default_rng(77)
    u = rng.uniform(-10, 10, 300)
    m = rng.uniform(0, 0.9, 300)
    ours = evaluate(u, m)
    theirs = scipy.special.ellipj(u, m)
    for name, a, b in zip(COMPONENTS, ours, theirs):
        ref.check(f"ellipj {name} vs scipy", np.abs(a - b), TOL_SCIPY, {"u": u, "m": m})


def test_broadcasting_and_vmap():
    u = np.linspace(-5, 5, 7)
    m = np.array([0.0, 0.5, 0.99])
    out = special.ellipj(u[:, None], m[None, :])
    assert all(o.shape == (7, 3) for o in out)
    mapped = jax.vmap(special.ellipj)(u, np.full(7, 0.3))
    direct = evaluate(u, 0.3)
    for a, b in zip(mapped, direct):
        np.testing.assert_allclose(np.asarray(a), b, rtol=0, atol=4e-15)
    assert all(o.dtype == jnp.float32 for o in special.ellipj(jnp.float32(1.0), jnp.float32(0.5)))
