"""High-precision references (mpmath) and error bookkeeping for the frbjax.special tests.

Everything here is independent of frbjax: the references are mpmath's own functions evaluated at the
exact binary values of the float64/float32 test inputs, at 40 significant digits (60 for the
finite-difference derivatives).  Nothing here uses a formula from frbjax.

Conventions
-----------
* A parameter ``m`` given together with an explicit complement ``mc`` is represented exactly as
  ``m = 1 - mc`` in mpmath (``m = 1 - 1e-17`` is representable there, not in float64).
* Quasi-periodic continuations in ``phi`` (F, Pi) and in ``u`` (Jacobi functions) are built here by
  explicit reduction at high precision (phi modulo pi, u modulo 2K), then mpmath's function on the
  principal range, so the reference does not depend on mpmath's own continuation.
* Reference values are returned as double-double pairs ``(hi, lo)`` with ``hi + lo`` the value to
  ~32 digits, so that the error of a float64 result is measured without the 0.5 ulp rounding of the
  reference itself.
* Derivatives (gradients and Hessians) come from central finite differences at 60 digits with a
  step of 1e-15 times a per-argument scale; truncation error is O(1e-30) relative and the
  cancellation costs at most 30 of the 60 digits, so they are good to ~25 digits, far below the
  1e-12 derivative tolerances.  Closed forms are used where they are trivial (d sn/du = cn dn, ...).
"""

from __future__ import annotations

import itertools
import json
import os

import mpmath
import numpy as np

DPS = 40
"""Digits for reference values."""

STENCIL_DPS = 60
"""Digits for finite-difference derivatives."""

mp = mpmath.mp


def mpf(x):
    """The exact binary value of a float (float32 values are exactly representable in float64)."""
    return mpmath.mpf(float(x))


def parameter(m, mc=None):
    """The parameter as an exact mpf: ``1 - mc`` (in mpmath) when ``mc`` is given, else ``m``."""
    if mc is None or (isinstance(mc, float) and np.isnan(mc)):
        return mpf(m)
    return 1 - mpf(mc)


# --------------------------------------------------------------------------------------------------
# Scalar references.  Arguments are mpf; they work at the current mpmath precision (so that the
# finite-difference driver below can raise it).


def ellipk(m):
    if m == 1:
        return mpmath.inf
    return mpmath.ellipk(m)


def ellipe(m):
    return mpmath.ellipe(m)


def _reduce_phi(phi):
    """phi = r + k pi with |r| <= pi/2, at the working precision."""
    k = mpmath.nint(phi / mpmath.pi)
    return phi - k * mpmath.pi, k


def ellipkinc(phi, m):
    """F(phi|m) for any real phi: F(r|m) + 2 k K(m)."""
    r, k = _reduce_phi(phi)
    value = mpmath.ellipf(r, m)
    if k:
        value += 2 * k * ellipk(m)
    return value


def ellippi(n, m):
    return mpmath.ellippi(n, m)


def ellippiinc(n, phi, m):
    """Pi(n; phi|m) for any real phi: Pi(n; r|m) + 2 k Pi(n|m)."""
    r, k = _reduce_phi(phi)
    value = mpmath.ellippi(n, r, m)
    if k:
        value += 2 * k * mpmath.ellippi(n, m)
    return value


def elliprf(x, y, z):
    return mpmath.elliprf(x, y, z)


def elliprd(x, y, z):
    return mpmath.elliprd(x, y, z)


def elliprj(x, y, z, p):
    if p <= 0:
        return mpmath.nan
    return mpmath.elliprj(x, y, z, p)


def elliprc(x, y):
    return mpmath.elliprc(x, y)


def ellipj(u, m):
    """(sn, cn, dn, am) with the continuous amplitude, by reduction of u modulo 2K."""
    if m == 1:
        t = mpmath.tanh(u)
        s = mpmath.sech(u)
        return t, s, s, 2 * mpmath.atan(mpmath.tanh(u / 2))
    quarter = mpmath.ellipk(m)
    j = mpmath.nint(u / (2 * quarter))
    r = u - 2 * j * quarter
    sn = mpmath.ellipfun("sn", r, m=m)
    cn = mpmath.ellipfun("cn", r, m=m)
    dn = mpmath.ellipfun("dn", r, m=m)
    am = mpmath.atan2(sn, cn) + j * mpmath.pi  # |r| <= K, so cn >= 0 and atan2 is the amplitude
    sign = -1 if int(j) % 2 else 1
    return sign * sn, sign * cn, dn, am


# --------------------------------------------------------------------------------------------------
# Vectorised drivers.


def _components(value):
    return tuple(value) if isinstance(value, tuple) else (value,)


def _split(value):
    """(hi, lo) float64 pair of an mpf (hi = nearest double; lo = the rest), inf/nan passed through."""
    if mpmath.isnan(value):
        return np.nan, 0.0
    if mpmath.isinf(value):
        return float(value), 0.0
    hi = float(value)
    if not np.isfinite(hi):
        return hi, 0.0
    return hi, float(value - mpmath.mpf(hi))


def values(fn, *columns, dps=DPS):
    """Reference values of ``fn`` at each point.

    ``columns``: arrays (broadcast together) or ``None``; ``fn`` receives mpf arguments (or None)
    and returns an mpf or a tuple of mpf.  Returns ``(hi, lo)`` arrays of shape (ncomp, npoints).
    """
    arrays = [None if c is None else np.ravel(np.asarray(c, dtype=np.float64)) for c in columns]
    size = max(a.size for a in arrays if a is not None)
    arrays = [None if a is None else np.broadcast_to(a, (size,)) for a in arrays]
    rows = []
    with mpmath.workdps(dps):
        for i in range(size):
            args = [None if a is None else mpf(a[i]) for a in arrays]
            rows.append([_split(v) for v in _components(fn(*args))])
    table = np.array(rows, dtype=np.float64)  # (npoints, ncomp, 2)
    return table[..., 0].T.copy(), table[..., 1].T.copy()


def taylor(fn, point, steps, order=1, dps=STENCIL_DPS):
    """Value, gradient and (order 2) Hessian of ``fn`` at ``point`` by central differences.

    ``point``: mpf arguments; ``steps``: per-argument step scale (None: do not differentiate in
    that argument).  The step is 1e-15 times the scale, at ``dps`` digits.  Returns float64 arrays
    value (ncomp,), gradient (ncomp, nargs) and hessian (ncomp, nargs, nargs); entries for
    undifferentiated arguments are NaN.
    """
    nargs = len(point)
    with mpmath.workdps(dps):
        x = [mpmath.mpf(p) for p in point]
        h = [None if s is None else mpmath.mpf("1e-15") * mpmath.mpf(s) for s in steps]
        cache = {}

        def at(offset):
            key = tuple(offset)
            if key not in cache:
                shifted = [x[i] + offset[i] * h[i] if offset[i] else x[i] for i in range(nargs)]
                cache[key] = _components(fn(*shifted))
            return cache[key]

        zero = [0] * nargs
        f0 = at(zero)
        ncomp = len(f0)
        grad = np.full((ncomp, nargs), np.nan)
        hess = np.full((ncomp, nargs, nargs), np.nan)
        active = [i for i in range(nargs) if h[i] is not None]
        for i in active:
            plus, minus = list(zero), list(zero)
            plus[i], minus[i] = 1, -1
            fp, fm = at(plus), at(minus)
            for c in range(ncomp):
                grad[c, i] = float((fp[c] - fm[c]) / (2 * h[i]))
                if order >= 2:
                    hess[c, i, i] = float((fp[c] - 2 * f0[c] + fm[c]) / h[i] ** 2)
        if order >= 2:
            for i, j in itertools.combinations(active, 2):
                parts = []
                for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                    offset = list(zero)
                    offset[i], offset[j] = si, sj
                    parts.append(at(offset))
                for c in range(ncomp):
                    mixed = (parts[0][c] - parts[1][c] - parts[2][c] + parts[3][c]) / (4 * h[i] * h[j])
                    hess[c, i, j] = hess[c, j, i] = float(mixed)
        value = np.array([float(v) for v in f0])
    return value, grad, hess


def taylor_table(fn, columns, steps_fn, order=1, dps=STENCIL_DPS):
    """``taylor`` at every point of a grid.

    ``columns``: sequences of point coordinates, floats (converted exactly) or mpf (e.g. a parameter
    ``1 - mc`` built by ``parameter``); ``steps_fn(*mp_args)`` gives the step scales at a point.
    Returns value (ncomp, n), gradient (ncomp, nargs, n), hessian (ncomp, nargs, nargs, n).
    """
    size = len(columns[0])
    vals, grads, hesss = [], [], []
    for i in range(size):
        with mpmath.workdps(dps):
            point = [c[i] if isinstance(c[i], mpmath.mpf) else mpf(c[i]) for c in columns]
            steps = steps_fn(*point)
        v, g, h = taylor(fn, point, steps, order=order, dps=dps)
        vals.append(v)
        grads.append(g)
        hesss.append(h)
    return (
        np.moveaxis(np.array(vals), 0, -1),
        np.moveaxis(np.array(grads), 0, -1),
        np.moveaxis(np.array(hesss), 0, -1),
    )


def param_scale(m):
    """How precisely a float64 parameter m in [0, 1] pins the problem down: min(m, 1 - m).

    For m >= 1/2 the complement 1 - m is exact in float64, so an implementation can (and must) be
    accurate relative to 1 - m, not merely to m.  Used as the perturbation size for conditioning and
    as the finite-difference step scale (exactly 0 at m = 0 or 1: then an absolute step of 1 is used
    for differencing, i.e. 1e-15 absolute).
    """
    return min(abs(m), abs(1 - m))


def step(scale):
    """A positive finite-difference step scale from a perturbation scale (1 where it is 0)."""
    return scale if scale > 0 else mpmath.mpf(1)


# --------------------------------------------------------------------------------------------------
# Errors and assertions.


def error(computed, hi, lo=0.0):
    """|computed - (hi + lo)| in float64, exact up to rounding of the (small) difference.

    Equal infinities give 0; NaN anywhere gives NaN (which fails every check below).
    """
    c = np.asarray(computed, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        err = np.abs((c - hi) - lo)
    same_inf = np.isinf(c) & (c == hi)
    return np.where(same_inf, 0.0, err)


def ratio(err, scale):
    """err / scale, with 0/0 = 0 (exact zero where the reference is zero) and x/0 = inf."""
    err = np.asarray(err, dtype=np.float64)
    scale = np.broadcast_to(np.asarray(scale, dtype=np.float64), err.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = err / scale
    out = np.where((scale == 0) & (err == 0), 0.0, out)
    out = np.where((scale == 0) & (err != 0), np.inf, out)
    return out


def _fmt(v):
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    return repr(v)


def check(name, measure, tol, inputs, extra=None):
    """Assert ``max(measure) <= tol`` and report the worst point (NaN counts as a failure).

    ``inputs``/``extra``: dicts of arrays (broadcastable to ``measure``) printed at the worst point.
    When the environment variable FRBJAX_ERROR_LOG names a file, one JSON line per check is appended
    to it (used to measure the worst errors when choosing tolerances).
    """
    measure = np.asarray(measure, dtype=np.float64)
    flat = np.where(np.isnan(measure), np.inf, measure).ravel()
    if flat.size == 0:
        raise AssertionError(f"{name}: empty grid")
    worst = int(np.argmax(flat))
    worst_value = float(flat[worst])
    at = {}
    for key, arr in {**inputs, **(extra or {})}.items():
        if arr is None:
            continue
        a = np.broadcast_to(np.asarray(arr), measure.shape).ravel()
        at[key] = a[worst].item() if hasattr(a[worst], "item") else a[worst]
    log = os.environ.get("FRBJAX_ERROR_LOG")
    if log:
        with open(log, "a") as handle:
            handle.write(
                json.dumps({"check": name, "worst": worst_value, "tol": tol, "n": int(flat.size),
                            "at": {k: float(v) if isinstance(v, (int, float)) else str(v)
                                   for k, v in at.items()}}) + "\n"
            )
    failing = int(np.sum(flat > tol))
    where = ", ".join(f"{k}={_fmt(v)}" for k, v in at.items())
    assert worst_value <= tol, (
        f"{name}: worst {worst_value:.3e} > tolerance {tol:.1e} at {where} "
        f"({failing} of {flat.size} points fail)"
    )
    return worst_value


def log_uniform(rng, low_exp, high_exp, size):
    """10**U(low_exp, high_exp)."""
    return 10.0 ** rng.uniform(low_exp, high_exp, size)


def signed(rng, values):
    return values * rng.choice([-1.0, 1.0], size=np.shape(values))
