"""Derivatives of frbjax.special (custom JVP rules) against mpmath, in forward and reverse mode.

References are central finite differences of mpmath's functions at 70 digits (see
_mpmath_reference), never frbjax's formulas.

Error measures (target: 1e-12, issue)
-------------------------------------
* Carlson functions: plain relative error.  Each partial derivative of R_F, R_D, R_J, R_C at
  positive arguments is again (minus) an integral of a positive, monotone, homogeneous integrand,
  so its relative condition number is bounded by a small constant on the whole domain.
* K, E, ellipkm1: plain relative error (same argument as for the values, test_legendre).
* F(phi|m), Pi(n; phi|m), Pi(n|m) (and the Jacobi functions): relative error divided by the
  condition number of the *derivative* where that exceeds 1: for g = df/dx_i,
      measure = |g - g_ref| / (|g_ref| max(1, kappa_g)),  kappa_g = sum_j s_j |d g/dx_j| / |g|,
  with the input sizes s_j of test_legendre (|phi|, min(m, 1 - m), min(|n|, |1 - n|)), and the
  second derivatives from mpmath.  At well-conditioned points this is the plain relative error.
* Jacobi functions: the same conditioned relative error in the inputs (u, m), s_u = |u|.  The
  u-term of kappa grows with |u| like the number of periods (the phase error of the values does
  too), and near m = 1 the m-derivatives are genuinely ill-conditioned: e.g. d cn/dm at u ~ K
  involves d F/dm at am ~ pi/2, i.e. 1/(mc + m cos^2 am)^(3/2), so an error of one ulp in am
  changes it by ~1e-11 relative at mc ~ 1e-11.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _compile_options import fast_jit
from jax.test_util import check_grads

import frbjax.special as special

from . import _mpmath_reference as ref
from ._stored import stored


HALF_PI = np.pi / 2
TOL = 1e-12  # issue target for every derivative (float64); tightened per function below
# The measured worst errors on these grids (FRBJAX_ERROR_LOG, 2026-11-24) with a margin of about 2-3:
# R_J 1.1e-13 (d/dx, the tangent of its duplication loop next to x = 0), every other <= 1e-15.
TOL_D = {
    "elliprf": 2e-15,
    "elliprd": 2.5e-15,
    "elliprj": 3e-13,
    "elliprc": 1.5e-15,
    "ellipk": 1.5e-15,
    "ellipe": 2e-15,
    "ellipkm1": 1.5e-15,
    "ellipkinc": 1.2e-15,
    "ellippiinc": 2.5e-15,
    "ellippi": 2.5e-15,
    "ellipj_u": 2.5e-15,
    "ellipj_m": 3e-15,
}
assert max(TOL_D.values()) <= TOL
TOL_D32 = 1e-5  # float32 derivatives (no issue target; measured worst 2.7e-6, dcn/dm)

ARGNAMES = {
    "elliprf": ("x", "y", "z"),
    "elliprd": ("x", "y", "z"),
    "elliprj": ("x", "y", "z", "p"),
    "elliprc": ("x", "y"),
    "ellipk": ("m",),
    "ellipe": ("m",),
    "ellipkm1": ("p",),
    "ellipkinc": ("phi", "m"),
    "ellippiinc": ("n", "phi", "m"),
    "ellippi": ("n", "m"),
    "ellipj": ("u", "m"),
}
PARAMETRISED = {"ellipk", "ellipe", "ellipkinc", "ellippiinc", "ellippi", "ellipj"}  # accept mc


# ------------------------------------------------------------------------------ jax derivatives


def _function(name, with_mc):
    fn = getattr(special, name)
    if with_mc:
        return lambda *args: fn(*args[:-1], mc=args[-1])
    return fn


@functools.cache
def _jvp_jit(name, with_mc):
    fn = _function(name, with_mc)
    k = len(ARGNAMES[name]) + with_mc

    def tangent(*flat):
        return jax.jvp(fn, tuple(flat[:k]), tuple(flat[k:]))[1]

    return fast_jit(tangent)


@functools.cache
def _vjp_jit(name, with_mc):
    fn = _function(name, with_mc)
    k = len(ARGNAMES[name]) + with_mc

    def cotangent(*flat):
        out, pullback = jax.vjp(fn, *flat[:k])
        return pullback(tuple(flat[k:]) if isinstance(out, tuple) else flat[k])

    return fast_jit(cotangent)


def partials(name, args, mode, mc=None):
    """Element-wise partial derivatives d out_c / d arg_i as an array (ncomp, nargs, npoints).

    Forward mode: one jvp per argument with a unit tangent; reverse mode: one vjp per output
    component with a unit cotangent (the functions are element-wise, so both give all partials at
    every point in one vectorised call).  With ``mc`` given, the parameter column holds the
    derivative along (dm, dmc) = (1, -1), which by the contract is the ordinary d/dm.
    """
    with_mc = mc is not None
    primals = [np.asarray(a) for a in np.broadcast_arrays(*args, *([mc] if with_mc else []))]
    k = len(primals)
    ones, zeros = np.ones_like(primals[0]), np.zeros_like(primals[0])
    ncomp = 4 if name == "ellipj" else 1
    nargs = len(ARGNAMES[name])
    out = np.empty((ncomp, nargs, primals[0].size), dtype=primals[0].dtype)
    if mode == "fwd":
        for i in range(nargs):
            tangents = [zeros] * k
            tangents[i] = ones
            if with_mc and i == nargs - 1:
                tangents[k - 1] = -ones
            t = ref.call_padded(_jvp_jit(name, with_mc), *primals, *tangents)
            t = t if isinstance(t, list) else [t]
            for c in range(ncomp):
                out[c, i] = t[c].ravel()
    else:
        for c in range(ncomp):
            cot = [zeros] * ncomp
            cot[c] = ones
            g = ref.call_padded(_vjp_jit(name, with_mc), *primals, *cot)
            for i in range(nargs):
                out[c, i] = g[i].ravel()
            if with_mc:
                out[c, nargs - 1] = (g[nargs - 1] - g[nargs]).ravel()
    return out


def _mc_halves(name, args, mc):
    """Reverse-mode d/dm and d/dmc separately (contract: each carries half of the derivative)."""
    primals = [np.asarray(a) for a in np.broadcast_arrays(*args, mc)]
    ones = np.ones_like(primals[0])
    ncomp = 4 if name == "ellipj" else 1
    cot = [ones] + [np.zeros_like(ones)] * (ncomp - 1)
    g = ref.call_padded(_vjp_jit(name, True), *primals, *cot)
    return g[len(args) - 1], g[len(args)]


# ---------------------------------------------------------------------------------- references


def _steps_abs(*xs):
    return tuple(ref.step(abs(x)) for x in xs)


@stored([(name,) for name in ARGNAMES if name.startswith("ellipr")])
def carlson_grid(name):
    rng = np.random.default_rng(300 + list(ARGNAMES).index(name))
    nargs = len(ARGNAMES[name])
    pts = np.concatenate(
        [ref.log_uniform(rng, -3, 3, (40, nargs)), ref.log_uniform(rng, -10, 10, (12, nargs))]
    ).T.copy()
    fn = getattr(ref, name)
    _, _, grad, _ = ref.taylor_table(fn, list(pts), _steps_abs, order=1)
    return pts, grad


def _param(m, mc):
    return [ref.parameter(a, b) for a, b in zip(m, mc if mc is not None else [None] * len(m))]


@stored()
def complete_grid():
    rng = np.random.default_rng(310)
    m = np.concatenate([rng.uniform(0, 1, 40), 1 - ref.log_uniform(rng, -15, -1, 15), [0.0, 1e-300, 0.5, 1 - 1e-15]])
    mc = np.concatenate([ref.log_uniform(rng, -17, 0, 15), [1e-17, 1e-300]])
    out = {"m": m, "mc": mc}
    for name in ("ellipk", "ellipe"):
        fn = getattr(ref, name)
        out[name] = ref.taylor_table(fn, [_param(m, None)], lambda a: (ref.m_step(a),))[2][0, 0]
        out[name + "_mc"] = ref.taylor_table(fn, [_param(1 - mc, mc)], lambda a: (ref.m_step(a),))[2][0, 0]
    # ellipkm1(p) = K(1 - p): d/dp = -K'(1 - p); reference differentiates in p directly.
    out["ellipkm1"] = ref.taylor_table(
        lambda p: ref.ellipk(ref.parameter(None, p)), [mc], lambda a: (ref.step(abs(a)),)
    )[2][0, 0]
    return out


@stored([(name, kind) for name in ("ellipkinc", "ellippiinc", "ellippi") for kind in ("plain", "mc")])
def legendre_grid(name, kind):
    """Points (no phi = 0: zero derivatives are checked in the finiteness test), and the value,
    gradient and Hessian of the reference there."""
    rng = np.random.default_rng(320 + ["ellipkinc", "ellippiinc", "ellippi"].index(name))
    uni = rng.uniform
    size = 36 if name == "ellippiinc" else 50
    m = np.concatenate([uni(0, 1, size), 1 - ref.log_uniform(rng, -15, -1, size // 4)])
    total = m.size
    phi = np.concatenate(
        [uni(-HALF_PI, HALF_PI, size - 10), ref.signed(rng, ref.log_uniform(rng, 0, 3, 10)), uni(-3, 3, size // 4)]
    )
    n = np.concatenate(
        [
            uni(-1, 0.9, size - 8),
            -ref.log_uniform(rng, 0, 6, 4),
            1 - ref.log_uniform(rng, -4, -1, 4),
            uni(-1, 0.99, size // 4),
        ]
    )
    mc = None
    if kind == "mc":
        mc = ref.log_uniform(rng, -17, 0, total)
        m = 1 - mc
    columns = {"ellipkinc": [phi, m], "ellippiinc": [n, phi, m], "ellippi": [n, m]}[name]
    steps = {
        "ellipkinc": lambda a, b: (ref.step(abs(a)), ref.m_step(b)),
        "ellippiinc": lambda x, y, z: (ref.n_step(x), ref.step(abs(y)), ref.m_step(z)),
        "ellippi": lambda x, z: (ref.n_step(x), ref.m_step(z)),
    }[name]
    table = ref.taylor_table(getattr(ref, name), columns[:-1] + [_param(m, mc)], steps, order=2)
    return columns, mc, table


def _sizes(name, columns, mc):
    m = columns[-1]
    s_m = mc if mc is not None else np.minimum(m, 1 - m)
    if name == "ellipkinc":
        return [np.abs(columns[0]), s_m]
    s_n = np.minimum(np.abs(columns[0]), np.abs(1 - columns[0]))
    if name == "ellippiinc":
        return [s_n, np.abs(columns[1]), s_m]
    return [s_n, s_m]


@stored([("plain",), ("mc",)])
def jacobi_grid(kind):
    """(u, m, mc, reference value/gradient/Hessian in (u, m) of (sn, cn, dn, am))."""
    rng = np.random.default_rng(330)
    size = 60
    u = np.concatenate(
        [
            ref.signed(rng, ref.log_uniform(rng, -2, 1.5, size)),
            ref.signed(rng, ref.log_uniform(rng, 1.5, 4, 15)),
            [1e6, -1e6 + 0.5],
        ]
    )
    total = u.size
    if kind == "plain":
        m = np.concatenate([rng.uniform(0, 1, size), 1 - ref.log_uniform(rng, -15, -1, 15), [0.3, 0.9]])
        mc = None
    else:
        mc = np.concatenate([ref.log_uniform(rng, -17, 0, total - 2), [1e-17, 1e-12]])
        m = 1 - mc
    table = ref.taylor_table(ref.ellipj, [u, _param(m, mc)], lambda a, b: (ref.step(abs(a)), ref.m_step(b)), order=2)
    return u, m, mc, table


# ------------------------------------------------------------------------------------- Carlson


@pytest.mark.usefixtures("special_path")
@pytest.mark.parametrize("mode", ["fwd", "rev"])
@pytest.mark.parametrize("name", ["elliprf", "elliprd", "elliprj", "elliprc"])
def test_carlson_partials(name, mode):
    pts, grad = carlson_grid(name)
    ours = partials(name, list(pts), mode)
    inputs = dict(zip(ARGNAMES[name], pts))
    for i, arg in enumerate(ARGNAMES[name]):
        rel = ref.ratio(np.abs(ours[0, i] - grad[0, i]), np.abs(grad[0, i]))
        ref.check(
            f"d{name}/d{arg} ({mode}) relative error",
            rel,
            TOL_D[name],
            inputs,
            {"derivative": ours[0, i], "reference": grad[0, i]},
        )


# ----------------------------------------------------------------------------- complete K and E


@pytest.mark.parametrize("mode", ["fwd", "rev"])
@pytest.mark.parametrize("name", ["ellipk", "ellipe"])
def test_complete_derivatives(name, mode):
    g = complete_grid()
    m, mc = g["m"], g["mc"]
    ours = partials(name, [m], mode)[0, 0]
    ref.check(
        f"d{name}/dm ({mode}) relative error",
        ref.ratio(np.abs(ours - g[name]), np.abs(g[name])),
        TOL_D[name],
        {"m": m},
        {"derivative": ours, "reference": g[name]},
    )
    ours = partials(name, [1 - mc], mode, mc=mc)[0, 0]
    want = g[name + "_mc"]
    ref.check(
        f"d{name}/dm with mc ({mode}) relative error",
        ref.ratio(np.abs(ours - want), np.abs(want)),
        TOL_D[name],
        {"mc": mc},
        {"derivative": ours, "reference": want},
    )


@pytest.mark.parametrize("mode", ["fwd", "rev"])
def test_ellipkm1_derivative(mode):
    g = complete_grid()
    p = g["mc"]
    ours = partials("ellipkm1", [p], mode)[0, 0]
    ref.check(
        f"dellipkm1/dp ({mode}) relative error",
        ref.ratio(np.abs(ours - g["ellipkm1"]), np.abs(g["ellipkm1"])),
        TOL_D["ellipkm1"],
        {"p": p},
        {"derivative": ours, "reference": g["ellipkm1"]},
    )


def test_mc_tangent_convention():
    """With mc given, d/dm and d/dmc each carry half the derivative: grad_m = f'/2, grad_mc = -f'/2."""
    g = complete_grid()
    mc = g["mc"]
    dm, dmc = _mc_halves("ellipk", [1 - mc], mc)
    want = g["ellipk_mc"]
    ref.check(
        "dK/dm with mc given = K'/2", ref.ratio(np.abs(dm - want / 2), np.abs(want / 2)), TOL_D["ellipk"], {"mc": mc}
    )
    ref.check(
        "dK/dmc with mc given = -K'/2", ref.ratio(np.abs(dmc + want / 2), np.abs(want / 2)), TOL_D["ellipk"], {"mc": mc}
    )
    u = np.linspace(-3, 3, 7)
    dm, dmc = _mc_halves("ellipj", [u, np.full(7, 0.75)], np.full(7, 0.25))
    plain = partials("ellipj", [u, np.full(7, 0.75)], "rev")[0, 1]
    np.testing.assert_allclose(dm, plain / 2, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(dmc, -plain / 2, rtol=1e-14, atol=1e-15)


# ----------------------------------------------------------------------- incomplete F, Pi and Pi


@pytest.mark.parametrize("mode", ["fwd", "rev"])
@pytest.mark.parametrize("kind", ["plain", "mc"])
@pytest.mark.parametrize("name", ["ellipkinc", "ellippiinc", "ellippi"])
def test_legendre_partials(name, kind, mode):
    columns, mc, (_, _, grad, hess) = legendre_grid(name, kind)
    ours = partials(name, columns, mode, mc=mc)
    sizes = _sizes(name, columns, mc)
    inputs = dict(zip(ARGNAMES[name], columns))
    if mc is not None:
        inputs["mc"] = mc
    for i, arg in enumerate(ARGNAMES[name]):
        want = grad[0, i]
        spread = sum(s * np.abs(hess[0, i, j]) for j, s in enumerate(sizes))
        scale = np.maximum(np.abs(want), spread)
        measure = ref.ratio(np.abs(ours[0, i] - want), scale)
        ref.check(
            f"d{name}/d{arg} ({kind}, {mode}) conditioned relative error",
            measure,
            TOL_D[name],
            inputs,
            {"derivative": ours[0, i], "reference": want, "kappa": ref.ratio(spread, np.abs(want))},
        )


# -------------------------------------------------------------------------------------- Jacobi


@pytest.mark.usefixtures("special_path")
@pytest.mark.parametrize("mode", ["fwd", "rev"])
@pytest.mark.parametrize("kind", ["plain", "mc"])
def test_jacobi_partials(kind, mode):
    """d/du and d/dm of sn, cn, dn, am: conditioned relative error (module docstring)."""
    u, m, mc, (_, _, grad, hess) = jacobi_grid(kind)
    ours = partials("ellipj", [u, m], mode, mc=mc)
    inputs = {"u": u, "m": m} if mc is None else {"u": u, "mc": mc}
    sizes = [np.abs(u), mc if mc is not None else np.minimum(m, 1 - m)]
    for c, name in enumerate(("sn", "cn", "dn", "am")):
        for i, arg in enumerate(("u", "m")):
            want = grad[c, i]
            spread = sum(s * np.abs(hess[c, i, j]) for j, s in enumerate(sizes))
            measure = ref.ratio(np.abs(ours[c, i] - want), np.maximum(np.abs(want), spread))
            ref.check(
                f"d{name}/d{arg} ({kind}, {mode}) conditioned relative error",
                measure,
                TOL_D[f"ellipj_{arg}"],
                inputs,
                {"derivative": ours[c, i], "reference": want, "kappa": ref.ratio(spread, np.abs(want))},
            )


# ------------------------------------------------------------------------------------- float32


@stored([(name,) for name in ("elliprf", "elliprj", "ellipk", "ellipkinc", "ellippiinc", "ellipj")])
def grid32(name):
    rng = np.random.default_rng(340)
    size = 40
    cols = {
        "elliprf": [ref.log_uniform(rng, -2, 2, size) for _ in range(3)],
        "elliprj": [ref.log_uniform(rng, -2, 2, size) for _ in range(4)],
        "ellipk": [rng.uniform(0, 0.95, size)],
        "ellipkinc": [rng.uniform(-3, 3, size), rng.uniform(0, 0.95, size)],
        "ellippiinc": [rng.uniform(-2, 0.9, size), rng.uniform(-3, 3, size), rng.uniform(0, 0.95, size)],
        "ellipj": [rng.uniform(-8, 8, size), rng.uniform(0, 0.95, size)],
    }[name]
    cols = [c.astype(np.float32) for c in cols]
    fn = getattr(ref, name) if name != "ellipj" else (lambda a, b: ref.ellipj(a, b))
    _, _, grad, _ = ref.taylor_table(
        fn, cols, _steps_abs if name.startswith("ellipr") else (lambda *a: tuple(ref.step(abs(x)) for x in a)), order=1
    )
    return cols, grad


@pytest.mark.parametrize("name", ["elliprf", "elliprj", "ellipk", "ellipkinc", "ellippiinc", "ellipj"])
def test_float32_derivatives(name):
    """float32 partials at ordinary points: error relative to max(|g|, 1) per partial (the
    derivatives here are O(1) or larger; sn, cn derivatives pass through zero)."""
    cols, grad = grid32(name)
    ours = partials(name, cols, "fwd")
    assert ours.dtype == np.float32
    for c in range(ours.shape[0]):
        for i, arg in enumerate(ARGNAMES[name]):
            want = grad[c, i]
            err = np.abs(ours[c, i].astype(np.float64) - want) / np.maximum(np.abs(want), 1.0)
            ref.check(
                f"d{name}[{c}]/d{arg} float32 error / max(1, |g|)",
                err,
                TOL_D32,
                dict(zip(ARGNAMES[name], cols)),
                {"derivative": ours[c, i], "reference": want},
            )


# ------------------------------------------------------------------------ finite at domain edges


def _all_partials_finite(name, args, mc=None):
    for mode in ("fwd", "rev"):
        d = partials(name, args, mode, mc=mc)
        bad = ~np.isfinite(d)
        if bad.any():
            c, i, p = np.argwhere(bad)[0]
            point = {k: np.broadcast_to(a, d.shape[-1:])[p] for k, a in zip(ARGNAMES[name], args)}
            raise AssertionError(f"{name} ({mode}): d out[{c}]/d {ARGNAMES[name][i]} = {d[c, i, p]} at {point}")


def test_no_nan_at_domain_edges():
    """Values and all partials finite at m = 0, m = 1, n = 0, phi = 0, and |u| up to 1e6 (for d/du;
    d/dm at m = 1 only for moderate u, where it is finite)."""
    grid = lambda *axes: [a.ravel() for a in np.meshgrid(*axes, indexing="ij")]
    # ellipj: d/du at huge u (values and d/du only; d/dm there overflows in truth)
    u, m = grid(np.array([0.0, 1e-300, -1.0, 7.0, 1e3, -1e6, 1e6]), np.array([0.0, 1e-300, 0.5, 1 - 1e-15, 1.0]))
    d = partials("ellipj", [u, m], "fwd")[:, 0]
    assert np.all(np.isfinite(d)), ("ellipj d/du", u[~np.isfinite(d).all(0)], m[~np.isfinite(d).all(0)])
    d = partials("ellipj", [u, m], "rev")[:, 0]
    assert np.all(np.isfinite(d)), ("ellipj d/du (rev)", u[~np.isfinite(d).all(0)], m[~np.isfinite(d).all(0)])
    u, m = grid(np.array([0.0, 1e-300, -1.0, 3.0, 10.0]), np.array([0.0, 1e-300, 0.5, 1 - 1e-15, 1.0]))
    _all_partials_finite("ellipj", [u, m])
    _all_partials_finite("ellipj", [u, np.ones_like(u)], mc=np.zeros_like(u))
    # F and Pi at m in {0, 1}, n = 0, phi = 0 (|phi| < pi/2 at m = 1)
    n, phi, m = grid(
        np.array([0.0, -1e3, 0.5, 0.999]),
        np.array([0.0, 1e-300, -0.7, 1.5]),
        np.array([0.0, 1e-300, 0.5, 1 - 1e-15, 1.0]),
    )
    _all_partials_finite("ellipkinc", [phi, m])
    _all_partials_finite("ellippiinc", [n, phi, m])
    n, m = grid(np.array([0.0, -1e3, 0.5, 0.999]), np.array([0.0, 1e-300, 0.5, 1 - 1e-15]))
    _all_partials_finite("ellippi", [n, m])
    _all_partials_finite("ellipk", [m])
    _all_partials_finite("ellipe", [m])


@pytest.mark.usefixtures("special_path")
def test_carlson_zero_argument_tangent_is_finite():
    """At a zero argument the partial in that argument is infinite; a zero tangent there must not
    produce NaN (and the other partials are finite)."""
    cases = {
        "elliprf": [(0.0, 1.0, 2.0), (1.0, 0.0, 2.0), (1.0, 2.0, 0.0), (0.0, 1e-12, 1.0)],
        "elliprd": [(0.0, 1.0, 2.0), (1.0, 0.0, 2.0)],
        "elliprj": [(0.0, 1.0, 2.0, 3.0), (1.0, 0.0, 2.0, 3.0), (1.0, 2.0, 0.0, 3.0)],
        "elliprc": [(0.0, 1.0)],
    }
    for name, points in cases.items():
        fn = getattr(special, name)
        # One compiled JVP per function (eagerly, the JAX path's operations ran one by one: 23 s).
        jvp = fast_jit(lambda point, tangents, fn=fn: jax.jvp(fn, point, tangents)[1])
        for point in points:
            for i, x in enumerate(point):
                if x == 0:
                    continue
                tangents = [0.0] * len(point)
                tangents[i] = 1.0
                t = jvp(tuple(map(jnp.asarray, point)), tuple(map(jnp.asarray, tangents)))
                assert np.isfinite(float(t)), (name, point, ARGNAMES[name][i], float(t))


# ------------------------------------------------------------------------------- check_grads


CHECK_POINTS = {
    "elliprf": [(0.5, 1.2, 2.0), (3.0, 0.1, 0.7)],
    "elliprd": [(0.5, 1.2, 2.0), (3.0, 0.1, 0.7)],
    "elliprj": [(0.5, 1.2, 2.0, 0.8), (3.0, 0.1, 0.7, 2.5)],
    "elliprc": [(0.5, 1.2), (3.0, 0.1)],
    "ellipk": [(0.3,), (0.9,)],
    "ellipe": [(0.3,), (0.9,)],
    "ellipkm1": [(0.3,), (0.01,)],
    "ellipkinc": [(0.7, 0.3), (4.0, 0.9)],
    "ellippi": [(0.4, 0.3), (-2.0, 0.8)],
    "ellippiinc": [(0.4, 0.7, 0.3), (-2.0, 4.0, 0.8)],
    "ellipj": [(0.7, 0.3), (-5.0, 0.9)],
}


@pytest.mark.parametrize("name", list(CHECK_POINTS))
def test_check_grads(name):
    # Jitted: check_grads' JVPs and VJPs then compile once, where eagerly the JAX operations ran one
    # by one (13 s for elliprj).
    fn = jax.jit(getattr(special, name))
    for point in CHECK_POINTS[name]:
        # A finite-difference step below the default 1e-4: at ellipkm1(0.01) the third derivative
        # (~ 1/p^3) makes the default step's truncation error 1e-4 relative.
        check_grads(fn, tuple(jnp.asarray(x) for x in point), order=1, modes=("fwd", "rev"), eps=1e-6)


def test_check_grads_with_mc():
    # The parameter tangent is (dm - dmc)/2 (module notes): the derivative along mc = 1 - m, so the
    # finite differences must move m and mc together.
    point = tuple(jnp.asarray(x) for x in (1.3, 0.8))
    check_grads(jax.jit(lambda u, m: special.ellipj(u, m, mc=1 - m)), point, order=1, modes=("fwd", "rev"))
    point = tuple(jnp.asarray(x) for x in (0.3, 1.1, 0.6))
    check_grads(
        jax.jit(lambda n, phi, m: special.ellippiinc(n, phi, m, mc=1 - m)), point, order=1, modes=("fwd", "rev")
    )


def test_grad_under_jit_and_vmap():
    f = fast_jit(jax.vmap(jax.grad(lambda u, m: special.ellipj(u, m)[0], argnums=(0, 1))))
    u = np.linspace(-3, 3, 5)
    m = np.full(5, 0.4)
    du, dm = f(u, m)
    sn, cn, dn, _ = special.ellipj(u, m)
    np.testing.assert_allclose(np.asarray(du), np.asarray(cn * dn), rtol=1e-14, atol=1e-15)
    assert np.all(np.isfinite(np.asarray(dm)))
