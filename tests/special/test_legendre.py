"""Legendre-form elliptic integrals K, E, F, Pi (complete and incomplete) against mpmath.

Error measure
-------------
The float64 inputs are exact binary numbers, and mpmath evaluates the function at exactly those
numbers.  Where the function is well conditioned the measure is the plain relative error.  Where it
is not (F and Pi near phi = pi/2 with m near 1, Pi with n near 1 at large phi, ...), no
implementation can beat the error caused by perturbing the inputs by an ulp or so, and the measure
is the relative error divided by the condition number when that exceeds 1:

    measure = |f - f_ref| / (|f_ref| * max(1, kappa)),
    kappa   = sum_i s_i |df/dx_i| / |f|,

with s_i the size of the float64 uncertainty of input i:  s_phi = |phi|,  s_m = min(m, 1 - m) and
s_n = min(|n|, |1 - n|) (for m, n >= 1/2 the complement 1 - m, 1 - n is exact in float64, so an
implementation can be accurate relative to the complement), s_m = mc for an explicit complement.
So at well-conditioned points (kappa <= 1) the test is exactly the plain relative error target, and
elsewhere it asks for backward stability: the result must be the exact value at inputs perturbed by
at most tol/eps ~ 45 ulps (relative).  K, E, ellipkm1 and the complete Pi have kappa <= 1 on the
whole domain in this sense (their m-derivative blows up only as 1/mc near m = 1), and they are tested
with the plain relative error.  The derivatives d/dx_i are computed by mpmath (finite differences at
60 digits), never from frbjax.
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
from ._stored import stored


HALF_PI = np.pi / 2

# Tolerances: issue target 5e-15 (float64) and 1e-5 (float32); each is the measured worst error on
# these grids (FRBJAX_ERROR_LOG, 2026-11-24) with a margin of about 2-3: float64 K 1.7e-16, K(1 - p)
# 1.3e-16, E 1.7e-16, F 3.3e-16, Pi(n|m) 6.6e-16, Pi(n; phi|m) 4.8e-16; float32 0.9e-7 to 3.8e-7.
TOL64 = {
    "ellipk": 5e-16,
    "ellipkm1": 5e-16,
    "ellipe": 5e-16,
    "ellipkinc": 8e-16,
    "ellippi": 1.5e-15,
    "ellippiinc": 1.2e-15,
}
TOL32 = {
    "ellipk": 4e-7,
    "ellipkm1": 4e-7,
    "ellipe": 4e-7,
    "ellipkinc": 6e-7,
    "ellippi": 6e-7,
    "ellippiinc": 1e-6,
}
TOL_SCIPY = 1e-14


@functools.cache
def jitted(name, with_mc=False):
    fn = getattr(special, name)
    if with_mc:
        return jax.jit(lambda *args: fn(*args[:-1], mc=args[-1]))
    return jax.jit(fn)


def evaluate(name, args, mc=None):
    """frbjax on a grid, jit-compiled once per (function, mc given, dtype, padded size)."""
    if mc is None:
        return ref.call_padded(jitted(name), *args)
    return ref.call_padded(jitted(name, True), *args, mc)


# ---------------------------------------------------------------------------------------- grids


def m_grid(rng, n_uniform=100, n_near_one=40):
    edges = [0.0, 1e-300, 1e-16, 1e-8, 0.1, 0.5, 0.9, 1 - 1e-15, 1 - 2.0**-52, 1 - 2.0**-53]
    return np.concatenate(
        [
            rng.uniform(0, 1, n_uniform),
            1 - ref.log_uniform(rng, -15, -1, n_near_one),
            edges,
        ]
    )


def mc_grid(rng, n=40):
    """Explicit complements down to 1e-300 (m = 1 - mc rounds to 1 below 1.1e-16)."""
    return np.concatenate(
        [
            ref.log_uniform(rng, -300, 0, n),
            [1e-17, 1e-16, 2.0**-60, 1e-300, 1e-30, 0.5],
        ]
    )


@stored()
def complete_grids():
    rng = np.random.default_rng(21)
    m = m_grid(rng)
    mc = mc_grid(rng)
    p = np.concatenate([mc, [1.0, 0.25]])
    out = {"m": m, "mc": mc, "p": p}
    out["K_m"] = ref.values(ref.ellipk, m)
    out["E_m"] = ref.values(ref.ellipe, m)
    out["K_mc"] = ref.values(lambda c: ref.ellipk(ref.parameter(None, c)), mc)
    out["E_mc"] = ref.values(lambda c: ref.ellipe(ref.parameter(None, c)), mc)
    out["K_p"] = ref.values(lambda c: ref.ellipk(ref.parameter(None, c)), p)
    return out


@pytest.mark.parametrize("name", ["ellipk", "ellipe"])
def test_complete_float64(name):
    g = complete_grids()
    key = "K" if name == "ellipk" else "E"
    out = evaluate(name, [g["m"]])
    hi, lo = g[f"{key}_m"]
    ref.check(
        f"{name}(m) float64 relative error",
        ref.ratio(ref.error(out, hi[0], lo[0]), np.abs(hi[0])),
        TOL64[name],
        {"m": g["m"]},
        {"value": out, "reference": hi[0]},
    )
    mc = g["mc"]
    out = evaluate(name, [1 - mc], mc=mc)
    hi, lo = g[f"{key}_mc"]
    ref.check(
        f"{name}(m, mc=mc) float64 relative error",
        ref.ratio(ref.error(out, hi[0], lo[0]), np.abs(hi[0])),
        TOL64[name],
        {"mc": mc},
        {"value": out, "reference": hi[0]},
    )


def test_ellipkm1_float64():
    g = complete_grids()
    out = evaluate("ellipkm1", [g["p"]])
    hi, lo = g["K_p"]
    ref.check(
        "ellipkm1 float64 relative error",
        ref.ratio(ref.error(out, hi[0], lo[0]), np.abs(hi[0])),
        TOL64["ellipkm1"],
        {"p": g["p"]},
        {"value": out, "reference": hi[0]},
    )


def test_complete_limits():
    assert float(special.ellipk(0.0)) == pytest.approx(HALF_PI, rel=2.3e-16, abs=0)
    assert float(special.ellipe(0.0)) == pytest.approx(HALF_PI, rel=2.3e-16, abs=0)
    assert float(special.ellipe(1.0)) == 1.0
    assert float(special.ellipe(1.0, mc=0.0)) == 1.0
    assert np.isposinf(float(special.ellipk(1.0))), "K(1) = +inf (scipy convention)"
    assert np.isposinf(float(special.ellipkm1(0.0))), "ellipkm1(0) = K(1) = +inf"
    # Pi(0|m) = K(m) and Pi(n|0) = pi / (2 sqrt(1 - n)).
    m = np.array([0.0, 0.3, 0.9, 1 - 1e-12])
    np.testing.assert_allclose(evaluate("ellippi", [np.zeros_like(m), m]), evaluate("ellipk", [m]), rtol=4e-16)
    n = np.array([-1e6, -1.0, 0.0, 0.5, 0.999])
    np.testing.assert_allclose(evaluate("ellippi", [n, np.zeros_like(n)]), HALF_PI / np.sqrt(1 - n), rtol=1e-15)


# --------------------------------------------------------------------- incomplete F and Pi grids


def _near_half_pi(rng, n):
    """phi just below pi/2: pi/2 - 10^U(-15, -1), rounded to float64."""
    return HALF_PI - ref.log_uniform(rng, -15, -1, n)


def _param_column(m, mc):
    return [ref.parameter(a, b) for a, b in zip(m, mc if mc is not None else [None] * len(m))]


def conditioned_measure(err, value, grad, scales):
    """(measure, kappa): |err| / (|f| max(1, kappa)) with kappa = sum_i s_i |df/dx_i| / |f|."""
    value = np.abs(np.asarray(value))
    spread = np.zeros_like(value)
    for s, g in zip(scales, grad):
        spread = spread + np.abs(s) * np.where(np.isnan(g), 0.0, np.abs(g))
    return ref.ratio(err, np.maximum(value, spread)), ref.ratio(spread, value)


def n_scale(n):
    return np.minimum(np.abs(n), np.abs(1 - n))


def m_scale(m, mc=None):
    return mc if mc is not None else np.minimum(m, 1 - m)


@stored()
def f_grids():
    """F(phi|m): {'plain': (args, mc, reference), 'mc': ...}; args = (phi, m)."""
    rng = np.random.default_rng(31)
    uni = rng.uniform
    blocks = [
        (uni(-HALF_PI, HALF_PI, 110), uni(0, 1, 110)),  # principal range
        (ref.signed(rng, ref.log_uniform(rng, 0, 3, 50)), uni(0, 1, 50)),  # |phi| up to 1e3
        (uni(-HALF_PI, HALF_PI, 30), 1 - ref.log_uniform(rng, -15, -1, 30)),  # m near 1
        (_near_half_pi(rng, 30), np.concatenate([uni(0, 1, 15), 1 - ref.log_uniform(rng, -15, -1, 15)])),
        (
            np.array(
                [
                    0.0,
                    0.0,
                    0.0,
                    1.0,
                    -1.0,
                    HALF_PI,
                    -HALF_PI,
                    HALF_PI,
                    1e3,
                    -1e3,
                    3.0,
                    1.2,
                    1e-300,
                    1e-8,
                    HALF_PI,
                    2 * np.pi,
                    0.5,
                ]
            ),
            np.array(
                [0.0, 0.5, 1.0, 0.0, 0.0, 0.5, 0.5, 1 - 1e-15, 0.0, 0.99, 1e-300, 1.0, 0.5, 0.5, 0.0, 0.3, 1 - 1e-15]
            ),
        ),
    ]
    phi = np.concatenate([b[0] for b in blocks])
    m = np.concatenate([b[1] for b in blocks])
    phi_c = np.concatenate([uni(-3, 3, 25), _near_half_pi(rng, 10), [HALF_PI, 1e3, 0.7, -2.0]])
    mc = np.concatenate(
        [ref.log_uniform(rng, -17, 0, 25), ref.log_uniform(rng, -17, -5, 10), [1e-17, 1e-17, 1e-300, 1e-17]]
    )
    out = {}
    for key, (p, mm, c) in {"plain": (phi, m, None), "mc": (phi_c, 1 - mc, mc)}.items():
        table = ref.taylor_table(
            ref.ellipkinc, [p, _param_column(mm, c)], lambda a, b: (ref.step(abs(a)), ref.m_step(b)), order=0
        )
        out[key] = ((p, mm), c, table)
    return out


@stored()
def pi_grids():
    """Pi(n; phi|m): {'plain': ((n, phi, m), mc, reference), 'mc': ...}."""
    rng = np.random.default_rng(41)
    uni = rng.uniform
    blocks = [
        (uni(-1, 0.9, 80), uni(-HALF_PI, HALF_PI, 80), uni(0, 1, 80)),
        (uni(-1, 0.9, 35), ref.signed(rng, ref.log_uniform(rng, 0, 3, 35)), uni(0, 1, 35)),
        (-ref.log_uniform(rng, 0, 8, 20), uni(-3, 3, 20), uni(0, 1, 20)),  # n << 0
        (1 - ref.log_uniform(rng, -6, -1, 20), uni(-3, 3, 20), uni(0, 1, 20)),  # n -> 1
        (uni(-1, 0.999, 20), _near_half_pi(rng, 20), 1 - ref.log_uniform(rng, -15, 0, 20)),
        (
            np.array(
                [0.0, 0.0, 0.5, 0.3, 0.3, -1.0, 0.999, 0.999, 0.999, -1e8, 0.999, 0.5, 0.0, 0.0, 0.999, -1e8, 0.5]
            ),
            np.array(
                [1.0, 1e3, 0.0, 1.0, 1.0, 1.2, 1.5, HALF_PI, 1e3, 1.0, 1e3, 1.5, HALF_PI, -1e3, 1e-8, 1e3, -HALF_PI]
            ),
            np.array(
                [0.5, 0.3, 0.5, 0.0, 1.0, 1.0, 0.5, 0.5, 0.9, 0.5, 1 - 1e-15, 1.0, 1 - 1e-15, 0.0, 0.3, 0.999, 0.7]
            ),
        ),
    ]
    n, phi, m = (np.concatenate([b[i] for b in blocks]) for i in range(3))
    k = 25
    n_c = np.concatenate([uni(-1, 0.99, k), [0.999, 0.0, -1e6]])
    phi_c = np.concatenate([uni(-3, 3, k), [HALF_PI, 1.0, 1e3]])
    mc = np.concatenate([ref.log_uniform(rng, -17, 0, k), [1e-17, 1e-17, 1e-300]])
    out = {}
    for key, (a, b, mm, c) in {"plain": (n, phi, m, None), "mc": (n_c, phi_c, 1 - mc, mc)}.items():
        table = ref.taylor_table(
            ref.ellippiinc,
            [a, b, _param_column(mm, c)],
            lambda x, y, z: (ref.n_step(x), ref.step(abs(y)), ref.m_step(z)),
            order=0,
        )
        out[key] = ((a, b, mm), c, table)
    return out


@stored()
def pi_complete_grids():
    rng = np.random.default_rng(51)
    uni = rng.uniform
    blocks = [
        (uni(-1, 1, 60), uni(0, 1, 60)),
        (-ref.log_uniform(rng, 0, 8, 20), uni(0, 1, 20)),
        (1 - ref.log_uniform(rng, -8, -1, 20), uni(0, 1, 20)),
        (uni(-1, 1, 20), 1 - ref.log_uniform(rng, -15, -1, 20)),
        (
            np.array([0.0, 0.0, 0.999, -1e8, 0.5, 1 - 1e-12, 0.999, 0.3, -1e6, 0.0]),
            np.array([0.5, 0.0, 0.5, 0.5, 0.0, 0.3, 1 - 1e-15, 1 - 2.0**-52, 1e-300, 1 - 1e-15]),
        ),
    ]
    n, m = (np.concatenate([b[i] for b in blocks]) for i in range(2))
    n_c = np.concatenate([uni(-1, 0.99, 20), [0.999, 0.0, -1e6]])
    mc = np.concatenate([ref.log_uniform(rng, -17, 0, 20), [1e-17, 1e-300, 1e-17]])
    out = {}
    for key, (a, mm, c) in {"plain": (n, m, None), "mc": (n_c, 1 - mc, mc)}.items():
        table = ref.taylor_table(
            ref.ellippi, [a, _param_column(mm, c)], lambda x, z: (ref.n_step(x), ref.m_step(z)), order=0
        )
        out[key] = ((a, mm), c, table)
    return out


def _scales(name, args, mc):
    if name == "ellipkinc":
        phi, m = args
        return [np.abs(phi), m_scale(m, mc)]
    if name == "ellippiinc":
        n, phi, m = args
        return [n_scale(n), np.abs(phi), m_scale(m, mc)]
    n, m = args
    return [n_scale(n), m_scale(m, mc)]


GRIDS = {"ellipkinc": f_grids, "ellippiinc": pi_grids, "ellippi": pi_complete_grids}
ARGNAMES = {"ellipkinc": ("phi", "m"), "ellippiinc": ("n", "phi", "m"), "ellippi": ("n", "m")}


@pytest.mark.parametrize("kind", ["plain", "mc"])
@pytest.mark.parametrize("name", ["ellipkinc", "ellippiinc", "ellippi"])
def test_incomplete_float64(name, kind):
    """Relative error, divided by the condition number where it exceeds 1 (module docstring)."""
    args, mc, (hi, lo, grad, _) = GRIDS[name]()[kind]
    out = evaluate(name, args, mc=mc)
    assert out.dtype == np.float64
    err = ref.error(out, hi[0], lo[0])
    measure, kappa = conditioned_measure(err, hi[0], grad[0], _scales(name, args, mc))
    inputs = dict(zip(ARGNAMES[name], args))
    if mc is not None:
        inputs["mc"] = mc
    ref.check(
        f"{name} ({kind}) float64 conditioned relative error",
        measure,
        TOL64[name],
        inputs,
        {"value": out, "reference": hi[0], "kappa": kappa},
    )
    # Report (and bound) the plain relative error at the well-conditioned points separately.
    good = kappa <= 1
    ref.check(
        f"{name} ({kind}) float64 relative error where kappa <= 1",
        ref.ratio(err, np.abs(hi[0]))[good],
        TOL64[name],
        {k: np.asarray(v)[good] for k, v in inputs.items()},
    )


# ------------------------------------------------------------------------------------- float32


@stored()
def grid32():
    rng = np.random.default_rng(61)
    size = 120
    n = rng.uniform(-2, 0.9, size).astype(np.float32)
    phi = rng.uniform(-4, 4, size).astype(np.float32)
    m = rng.uniform(0, 0.95, size).astype(np.float32)
    p = ref.log_uniform(rng, -6, 0, size).astype(np.float32)
    refs = {
        "ellipk": ((m,), ref.values(ref.ellipk, m)),
        "ellipe": ((m,), ref.values(ref.ellipe, m)),
        "ellipkm1": ((p,), ref.values(lambda x: ref.ellipk(ref.parameter(None, x)), p)),
        "ellipkinc": ((phi, m), ref.values(ref.ellipkinc, phi, m)),
        "ellippi": ((n, m), ref.values(ref.ellippi, n, m)),
        "ellippiinc": ((n, phi, m), ref.values(ref.ellippiinc, n, phi, m)),
    }
    return refs


@pytest.mark.parametrize("name", list(TOL32))
def test_float32(name):
    args, (hi, lo) = grid32()[name]
    out = evaluate(name, args)
    assert out.dtype == np.float32, out.dtype
    rel = ref.ratio(ref.error(out, hi[0], lo[0]), np.abs(hi[0]))
    names = {"ellipk": ("m",), "ellipe": ("m",), "ellipkm1": ("p",)}.get(name, ARGNAMES.get(name))
    ref.check(
        f"{name} float32 relative error", rel, TOL32[name], dict(zip(names, args)), {"value": out, "reference": hi[0]}
    )


# ------------------------------------------------------------------------- limits and identities


def test_incomplete_special_values():
    phi = np.array([-1.5, -0.3, 0.0, 1e-300, 0.2, 1.0, 1.5])
    # m = 0: F(phi|0) = phi; m = 1: F(phi|1) = artanh(sin phi) for |phi| < pi/2.
    np.testing.assert_allclose(evaluate("ellipkinc", [phi, 0.0]), phi, rtol=6e-16, atol=0)
    np.testing.assert_allclose(evaluate("ellipkinc", [phi, 1.0]), np.arctanh(np.sin(phi)), rtol=4e-15, atol=0)
    # Pi(0; phi|m) = F(phi|m); phi = 0 gives exactly 0.
    phis = np.array([-1e3, -2.0, 0.0, 0.7, 1.5, 10.0])
    for m in [0.0, 0.5, 1 - 1e-12]:
        np.testing.assert_allclose(
            evaluate("ellippiinc", [0.0, phis, m]), evaluate("ellipkinc", [phis, m]), rtol=4e-15, atol=0
        )
    assert float(special.ellipkinc(0.0, 0.7)) == 0.0
    assert float(special.ellippiinc(0.4, 0.0, 0.7)) == 0.0
    # Values are finite at the edges of the domain (phi < pi/2 for m = 1).
    n = np.array([0.0, -1e8, 0.999, 0.5])[:, None, None]
    ph = np.array([0.0, 1e-300, 1.0, 1.5])[None, :, None]
    mm = np.array([0.0, 1e-300, 0.5, 1 - 1e-15, 1.0])[None, None, :]
    assert np.all(np.isfinite(evaluate("ellippiinc", [n, ph, mm])))
    assert np.all(np.isfinite(evaluate("ellipkinc", [ph, mm])))


def test_quasi_periodicity_and_oddness():
    """F(phi + k pi) = F(phi) + 2 k K and Pi likewise, F(-phi) = -F(phi) (frbjax only)."""
    rng = np.random.default_rng(71)
    phi = rng.uniform(-HALF_PI, HALF_PI, 40)
    m = rng.uniform(0, 0.99, 40)
    n = rng.uniform(-1, 0.9, 40)
    k = rng.integers(-50, 50, 40).astype(np.float64)
    shifted = phi + k * np.pi
    f = evaluate("ellipkinc", [shifted, m])
    expect = evaluate("ellipkinc", [phi, m]) + 2 * k * evaluate("ellipk", [m])
    # The shifted phi is rounded (error <= ulp(|phi|) ~ 2e-16 |phi|); allow for it via dF/dphi.
    allowance = 4e-15 * (np.abs(expect) + np.abs(shifted) / np.sqrt(1 - m))
    assert np.all(np.abs(f - expect) <= allowance), np.max(np.abs(f - expect) / allowance)
    p = evaluate("ellippiinc", [n, shifted, m])
    expect = evaluate("ellippiinc", [n, phi, m]) + 2 * k * evaluate("ellippi", [n, m])
    allowance = 4e-15 * (np.abs(expect) + np.abs(shifted) / ((1 - np.maximum(n, 0)) * np.sqrt(1 - m)))
    assert np.all(np.abs(p - expect) <= allowance), np.max(np.abs(p - expect) / allowance)
    for name, args in [("ellipkinc", [phi, m]), ("ellippiinc", [n, phi, m])]:
        neg = list(args)
        neg[-2] = -phi
        np.testing.assert_allclose(evaluate(name, neg), -evaluate(name, args), rtol=1e-15, atol=0)


def test_mc_matches_implicit_complement():
    """For m >= 1/2, 1 - m is exact, so passing mc = 1 - m must give the same answer."""
    rng = np.random.default_rng(81)
    m = rng.uniform(0.5, 1, 50)
    phi = rng.uniform(-5, 5, 50)
    n = rng.uniform(-2, 0.9, 50)
    for name, args in [
        ("ellipk", [m]),
        ("ellipe", [m]),
        ("ellipkinc", [phi, m]),
        ("ellippi", [n, m]),
        ("ellippiinc", [n, phi, m]),
    ]:
        a = evaluate(name, args)
        b = evaluate(name, args, mc=1 - m)
        np.testing.assert_allclose(a, b, rtol=1e-15, atol=0, err_msg=name)


# --------------------------------------------------------------------------------- scipy opinion


@pytest.mark.parametrize("name", ["ellipk", "ellipe", "ellipkm1", "ellipkinc"])
def test_agrees_with_scipy(name):
    """Second opinion on moderate points, where scipy.special is accurate to ~1e-15."""
    rng = np.random.default_rng(91)
    m = rng.uniform(0, 0.99, 200)
    phi = rng.uniform(-10, 10, 200)
    args = {"ellipk": [m], "ellipe": [m], "ellipkm1": [1 - m], "ellipkinc": [phi, m]}[name]
    ours = evaluate(name, args)
    theirs = getattr(scipy.special, name)(*args)
    ref.check(
        f"{name} vs scipy",
        ref.ratio(np.abs(ours - theirs), np.abs(theirs)),
        TOL_SCIPY,
        dict(zip(["phi", "m"] if name == "ellipkinc" else ["m"], args)),
    )


def test_broadcasting_and_vmap():
    phi = np.linspace(-3, 3, 7)
    m = np.linspace(0, 0.9, 3)
    out = special.ellipkinc(phi[:, None], m[None, :])
    assert out.shape == (7, 3)
    out = special.ellippiinc(np.array([0.1, 0.2])[:, None, None], phi[None, :, None], m)
    assert out.shape == (2, 7, 3)
    mapped = jax.vmap(special.ellippiinc)(np.full(7, 0.3), phi, np.full(7, 0.6))
    np.testing.assert_allclose(np.asarray(mapped), evaluate("ellippiinc", [0.3, phi, 0.6]), rtol=1e-15)
    assert special.ellipk(jnp.float32(0.5)).dtype == jnp.float32
    assert special.ellipkinc(jnp.float32(0.5), jnp.float32(0.5)).dtype == jnp.float32


# ----------------------------------------------------------------------- huge negative parameter


# The parameters (down to -DBL_MAX, where 1 - m sin^2 phi and mc = 1 - m reach the overflow
# threshold) and amplitudes in, at the edges of and beyond the principal range.
HUGE_NEGATIVE_M = np.array([-1e300, -1e305, -1e307, -1.5e308, -1.7976931348623157e308])
HUGE_NEGATIVE_PHI = np.array([1e-3, 0.3, 1.0, HALF_PI - 1e-9, HALF_PI, 2.0, 10.0, -1e-3, -1.0, -HALF_PI, -2.0, -10.0])


def _huge_negative_grid(m):
    phi, m = np.meshgrid(HUGE_NEGATIVE_PHI, m)
    return phi.ravel(), m.ravel()


def _f_derivatives(phi, m):
    """(dF/dphi, dF/dm) at 40 digits: the integrand 1/Delta (DLMF 19.2.4) and DLMF 19.4.4 in the
    parameter, dF/dm = E/(2 m mc) - F/(2m) - sin(phi) cos(phi)/(2 mc Delta), mc = 1 - m."""
    delta = mpmath.sqrt(1 - m * mpmath.sin(phi) ** 2)
    mc = 1 - m
    d_m = (
        mpmath.ellipe(phi, m) / (2 * m * mc)
        - mpmath.ellipf(phi, m) / (2 * m)
        - mpmath.sin(phi) * mpmath.cos(phi) / (2 * mc * delta)
    )
    return 1 / delta, d_m


def test_huge_negative_parameter_float64():
    """F(phi|m) for m <= -1e300 against mpmath at 40 digits (issue: 1.9e-6 for m <= -1e307).

    R_F's last duplication scale 4^-12/A_12 was subnormal for 1 - m sin^2 phi >~ 1e306, and XLA
    flushes it to zero; and K(m) for m < 0 (phi beyond pi/2) was NaN.  Measured worst relative error
    before the fix 1.9e-6 (NaN beyond pi/2), after it 3.4e-16 (scipy 2.2e-16): tolerance 5e-16.
    """
    phi, m = _huge_negative_grid(HUGE_NEGATIVE_M)
    out = evaluate("ellipkinc", [phi, m])
    hi, lo = ref.values(ref.ellipkinc, phi, m)
    ref.check(
        "ellipkinc huge negative m float64 relative error",
        ref.ratio(ref.error(out, hi[0], lo[0]), np.abs(hi[0])),
        5e-16,
        {"phi": phi, "m": m},
        {"value": out, "reference": hi[0]},
    )


def test_huge_negative_parameter_float32():
    """float32 from m = -1e20 to -FLT_MAX: K(m < 0) was NaN, R_F's scale flushed for m <~ -1e34.
    Measured worst relative error 1.7e-7: tolerance 3e-7 (TOL32["ellipkinc"] is 6e-7)."""
    phi, m = _huge_negative_grid([-1e20, -1e30, -1e36, -3.4028235e38])
    phi, m = phi.astype(np.float32), m.astype(np.float32)
    out = evaluate("ellipkinc", [phi, m])
    assert out.dtype == np.float32
    hi, lo = ref.values(ref.ellipkinc, phi, m)
    ref.check(
        "ellipkinc huge negative m float32 relative error",
        ref.ratio(ref.error(out, hi[0], lo[0]), np.abs(hi[0])),
        3e-7,
        {"phi": phi, "m": m},
        {"value": out, "reference": hi[0]},
    )


@functools.cache
def _ellipkinc_gradient():
    return jax.jit(jax.vmap(jax.grad(special.ellipkinc, argnums=(0, 1))))


def test_huge_negative_parameter_gradients():
    """jax.grad in phi and m against mpmath (``_f_derivatives``), m down to -DBL_MAX.

    Before the fix the phi-derivative was 0 (1/Delta^2 flushed to zero in reverse mode) and the
    m-derivative NaN (R_D's (3/5) Delta^2 overflowed) for m <= -1.5e308.  Measured worst relative
    errors: dF/dphi 5.7e-16 (at phi = 10: the rounding of 10 - 3 pi, times cot), dF/dm 5.7e-16;
    tolerance 8e-16.  |dF/dm| < 1e-440 for m <= -1e300, whose float64 value is 0; -1e100 and -1e200
    check the m-derivative where it is representable.
    """
    phi, m = _huge_negative_grid(np.concatenate([[-1e100, -1e200], HUGE_NEGATIVE_M]))
    d_phi, d_m = (np.asarray(g) for g in _ellipkinc_gradient()(phi, m))
    with mpmath.workdps(ref.DPS):
        exact = [_f_derivatives(mpmath.mpf(p), mpmath.mpf(x)) for p, x in zip(phi, m)]
    hi_phi = np.array([float(e[0]) for e in exact])
    hi_m = np.array([float(e[1]) for e in exact])
    inputs = {"phi": phi, "m": m}
    ref.check(
        "ellipkinc huge negative m: dF/dphi relative error",
        ref.ratio(np.abs(d_phi - hi_phi), np.abs(hi_phi)),
        8e-16,
        inputs,
    )
    ref.check(
        "ellipkinc huge negative m: dF/dm relative error",
        ref.ratio(np.abs(d_m - hi_m), np.abs(hi_m)),
        8e-16,
        inputs,
        {"value": d_m, "reference": hi_m},
    )
    assert np.all(hi_m[m <= -1e300] == 0) and np.all(np.isfinite(d_m))


# ------------------------------------------------------------------------ E(m) for negative m


# The parameters (E(-10) was 56270 for 3.6391: the fit on 0 <= mc <= 1 taken at mc = 1 - m),
# a few more down to -DBL_MAX (where 1/mc is subnormal), and random ones.
NEGATIVE_M = np.array(
    [
        -1e-300,
        -1e-10,
        -0.5,
        -1.0,
        -10.0,
        -1e3,
        -1e10,
        -1e100,
        -1e300,
        -1.7976931348623157e308,
        -1e-5,
        -0.1,
        -2.5,
        -123.4,
        -1e20,
        -(2.0**501),
        -1e305,
        -1.5e308,
    ]
)
NEGATIVE_M32 = np.array([-1e-30, -1e-10, -0.5, -1, -10, -1e3, -1e10, -1e20, -1e30, -1e36, -3.4028235e38], np.float32)


@functools.cache
def negative_m_grids():
    rng = np.random.default_rng(101)
    m64 = np.concatenate([NEGATIVE_M, -ref.log_uniform(rng, -300, 308.25, 150), -rng.uniform(0, 10, 100)])
    m32 = np.concatenate([NEGATIVE_M32, -ref.log_uniform(rng, -37, 38.5, 100), -rng.uniform(0, 10, 50)]).astype(
        np.float32
    )
    return m64, m32


def _ellipe_derivative(m):
    """dE/dm = (E - K)/(2m) (DLMF 19.4.1), with the digits that E - K cancels near m = 0 added."""
    m = mpmath.mpf(float(m))
    with mpmath.workdps(ref.DPS + max(0, -int(mpmath.log10(abs(m)))) + 5):
        return (mpmath.ellipe(m) - mpmath.ellipk(m)) / (2 * m)


def test_ellipe_negative_parameter_float64():
    """E(m) for m < 0 against mpmath.ellipe at 40 digits; the explicit complement mc = 1 - m too.

    Measured worst relative error before the fix 1.5e4 at m = -10 (inf for m <= -1e50), after it
    2.3e-16 on this grid (3.2e-16 on 2300 random points): tolerance 4e-16.
    """
    m, _ = negative_m_grids()
    hi, lo = ref.values(ref.ellipe, m)
    for out, label in [(evaluate("ellipe", [m]), "m"), (evaluate("ellipe", [m], mc=1 - m), "mc")]:
        ref.check(
            f"ellipe negative m ({label}) float64 relative error",
            ref.ratio(ref.error(out, hi[0], lo[0]), np.abs(hi[0])),
            4e-16,
            {"m": m},
            {"value": out, "reference": hi[0]},
        )
    # E ~ sqrt(1 - m) as m -> -inf (DLMF 19.12.2): +inf at m = -inf, as scipy.special.ellipe.
    assert np.isposinf(float(special.ellipe(-np.inf)))


def test_ellipe_negative_parameter_float32():
    """float32 down to -FLT_MAX (before the fix 1.5e4 at m = -10, inf from m = -1e10).  Measured worst
    relative error 1.3e-7 (1.5e-7 on 1500 random points): tolerance 2e-7 (TOL32["ellipe"] is 4e-7)."""
    _, m = negative_m_grids()
    out = evaluate("ellipe", [m])
    assert out.dtype == np.float32
    hi, lo = ref.values(ref.ellipe, m)
    ref.check(
        "ellipe negative m float32 relative error",
        ref.ratio(ref.error(out, hi[0], lo[0]), np.abs(hi[0])),
        2e-7,
        {"m": m},
        {"value": out, "reference": hi[0]},
    )


@functools.cache
def _ellipe_gradient():
    return jax.jit(jax.vmap(jax.grad(special.ellipe)))


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_ellipe_negative_parameter_gradient(dtype):
    """jax.grad of E for m < 0 against (E - K)/(2m) at 40 digits.

    The rule's -R_D(0, mc, 1)/6 needs no rescaling up to mc = DBL_MAX: the small argument z = 1
    carries the result, and the overflowing mean^(3/2) only drops a term below 1e-450 of it.
    Measured worst relative error float64 5.2e-16 (7.0e-16 on 2300 random points; 2.2e-16 at
    -DBL_MAX), float32 2.3e-7 (3.0e-7 on 1500 random points): tolerances 8e-16 and 4e-7.
    """
    m = negative_m_grids()[dtype == "float32"]
    out = np.asarray(_ellipe_gradient()(m))
    assert out.dtype == m.dtype and np.all(np.isfinite(out))
    exact = np.array([float(_ellipe_derivative(x)) for x in m])
    ref.check(
        f"ellipe negative m: dE/dm {dtype} relative error",
        ref.ratio(np.abs(out - exact), np.abs(exact)),
        {"float64": 8e-16, "float32": 4e-7}[dtype],
        {"m": m},
        {"value": out, "reference": exact},
    )
