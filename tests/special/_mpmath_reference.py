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
* Derivatives (gradients and Hessians) come from central finite differences at 70 digits with a
  step of 1e-25 times a per-argument scale on which the function varies (|x| for phi, u and the
  Carlson arguments, 1 - m for m, |1 - n| for n); the truncation error is O(1e-50) relative and the
  cancellation costs 25 (gradient) or 50 (Hessian) of the 70 digits, far below the 1e-12
  derivative tolerances (the Hessians only set condition numbers).
"""

from __future__ import annotations

import itertools
import json
import os

import mpmath
import numpy as np


DPS = 40
"""Digits for reference values."""

STENCIL_DPS = 70
"""Digits for finite-difference derivatives."""

STEP = "1e-25"
"""Finite-difference step, relative to each argument's step scale."""

mp = mpmath.mp


def mpf(x):
    """The exact binary value of a float (float32 values are exactly representable in float64);
    an mpf is returned unchanged (never rounded through a float)."""
    if isinstance(x, mpmath.mpf):
        return x
    return mpmath.mpf(float(x))


def parameter(m, mc=None):
    """The parameter as an exact mpf: ``1 - mc`` (in mpmath) when ``mc`` is given, else ``m``."""
    if mc is None:
        return mpf(m)
    mc = mpf(mc)
    # Exact: enough bits for 1 and for the last bit of mc (mpmath rounds to the working precision;
    # mc may be a float64 value or a finite-difference point carrying the working precision).
    bits = max(mp.prec, 64) + (max(0, -mpmath.mag(mc)) if mc else 0) + 10
    with mpmath.workprec(bits):
        return 1 - mc


# --------------------------------------------------------------------------------------------------
# Scalar references.  Arguments are mpf; they work at the current mpmath precision (so that the
# finite-difference driver below can raise it).


def _near_one(fn):
    """Evaluate ``fn`` with enough extra digits that 1 - m keeps 40+ significant digits.

    With an explicit complement, m = 1 - mc is stored exactly (it may need hundreds of digits for
    mc ~ 1e-300); mpmath forms 1 - m and m sin^2(phi) internally at the working precision, so that
    precision is raised by the number of digits cancelled in 1 - m.
    """

    def wrapped(*args):
        m = args[-1]
        extra = 0
        if 0.5 < m < 1:
            extra = int(-mpmath.log10(1 - m)) + 5
        with mpmath.workdps(mp.dps + extra):
            out = fn(*args)
        return tuple(+v for v in out) if isinstance(out, tuple) else +out

    wrapped.__name__ = fn.__name__
    wrapped.__doc__ = fn.__doc__
    return wrapped


@_near_one
def ellipk(m):
    if m == 1:
        return mpmath.inf
    return mpmath.ellipk(m)


@_near_one
def ellipe(m):
    return mpmath.ellipe(m)


def _reduce_phi(phi):
    """phi = r + k pi with |r| <= pi/2, at the working precision."""
    k = mpmath.nint(phi / mpmath.pi)
    return phi - k * mpmath.pi, k


@_near_one
def ellipkinc(phi, m):
    """F(phi|m) for any real phi: F(r|m) + 2 k K(m)."""
    r, k = _reduce_phi(phi)
    value = mpmath.ellipf(r, m)
    if k:
        value += 2 * k * mpmath.ellipk(m)
    return value


@_near_one
def ellippi(n, m):
    return mpmath.ellippi(n, m)


@_near_one
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
    if x == y == z and p != x:
        # mpmath's elliprj returns inf at (1, 1, 1, 1e-100); the closed form (DLMF 19.20.15 with
        # 19.2.17) R_J(x, x, x, p) = 3 (R_C(x, p) - 1/sqrt x)/(x - p) is used instead.
        x, p = mpmath.mpf(x), mpmath.mpf(p)
        return 3 * (mpmath.elliprc(x, p) - 1 / mpmath.sqrt(x)) / (x - p)
    return mpmath.elliprj(x, y, z, p)


def elliprc(x, y):
    return mpmath.elliprc(x, y)


def _ellipj(u, m):
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


def ellipj(u, m):
    """(sn, cn, dn, am) at parameter m (an exact mpf; see ``parameter``)."""
    # The reduction u - 2jK cancels log10(|u|/K) digits: add them too.
    extra = int(mpmath.log10(abs(u))) if abs(u) > 1 else 0
    with mpmath.workdps(mp.dps + extra):
        return tuple(+v for v in _near_one(_ellipj)(u, m))


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

    ``order=0`` gives a cheaper gradient by forward differences (relative error ~1e-25, used for
    condition numbers only); ``order=1`` central differences (~1e-30); ``order=2`` adds the Hessian.

    ``point``: mpf arguments; ``steps``: per-argument step scale (None: do not differentiate in
    that argument).  The step is STEP times the scale, at ``dps`` digits (plus what x_i +- h_i needs).  Returns
    float64 arrays
    value_hi (ncomp,), value_lo (ncomp,), gradient (ncomp, nargs) and hessian (ncomp, nargs, nargs)
    (order 1: NaN); entries for undifferentiated arguments are NaN.
    """
    nargs = len(point)
    # x_i +- h_i must be exact: add the digits by which the step is below the argument.
    extra = 0
    for p, s in zip(point, steps):
        if s is not None and p != 0:
            extra = max(extra, int(mpmath.log10(abs(mpmath.mpf(p)) / mpmath.mpf(s))) + 1)
    with mpmath.workdps(dps + extra):
        x = [mpmath.mpf(p) for p in point]
        h = [None if s is None else mpmath.mpf(STEP) * mpmath.mpf(s) for s in steps]
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
            fp = at(plus)
            if order == 0:
                # Forward difference: relative error ~ STEP, plenty for condition numbers.
                for c in range(ncomp):
                    grad[c, i] = float((fp[c] - f0[c]) / h[i])
                continue
            fm = at(minus)
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
        split = np.array([_split(v) for v in f0], dtype=np.float64)
    return split[:, 0], split[:, 1], grad, hess


def taylor_table(fn, columns, steps_fn, order=1, dps=STENCIL_DPS):
    """``taylor`` at every point of a grid.

    ``columns``: sequences of point coordinates, floats (converted exactly) or mpf (e.g. a parameter
    ``1 - mc`` built by ``parameter``); ``steps_fn(*mp_args)`` gives the step scales at a point.
    Returns value_hi (ncomp, n), value_lo (ncomp, n), gradient (ncomp, nargs, n) and hessian
    (ncomp, nargs, nargs, n).
    """
    size = len(columns[0])
    his, los, grads, hesss = [], [], [], []
    for i in range(size):
        with mpmath.workdps(dps):
            point = [c[i] if isinstance(c[i], mpmath.mpf) else mpf(c[i]) for c in columns]
            steps = steps_fn(*point)
        hi, lo, g, h = taylor(fn, point, steps, order=order, dps=dps)
        his.append(hi)
        los.append(lo)
        grads.append(g)
        hesss.append(h)
    return (
        np.moveaxis(np.array(his), 0, -1),
        np.moveaxis(np.array(los), 0, -1),
        np.moveaxis(np.array(grads), 0, -1),
        np.moveaxis(np.array(hesss), 0, -1),
    )


def param_scale(m):
    """How precisely a float64 parameter m in [0, 1] pins the problem down: min(m, 1 - m).

    For m >= 1/2 the complement 1 - m is exact in float64, so an implementation can (and must) be
    accurate relative to 1 - m, not merely to m.  Used as the perturbation size in condition numbers.
    """
    return min(abs(m), abs(1 - m))


def step(scale):
    """A positive finite-difference step scale from a perturbation scale (1 where it is 0)."""
    return scale if scale > 0 else mpmath.mpf(1)


def m_step(m):
    """Step scale for the parameter: the functions vary in m on the scale 1 - m (None at m = 1,
    where they are not differentiable from both sides)."""
    return 1 - m if m < 1 else None


def n_step(n):
    """Step scale for the characteristic n < 1: |1 - n| (the distance to the singularity)."""
    return abs(1 - n)


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
                json.dumps(
                    {
                        "check": name,
                        "worst": worst_value,
                        "tol": tol,
                        "n": int(flat.size),
                        "at": {k: float(v) if isinstance(v, (int, float)) else str(v) for k, v in at.items()},
                    }
                )
                + "\n"
            )
    failing = int(np.sum(flat > tol))
    where = ", ".join(f"{k}={_fmt(v)}" for k, v in at.items())
    assert worst_value <= tol, (
        f"{name}: worst {worst_value:.3e} > tolerance {tol:.1e} at {where} ({failing} of {flat.size} points fail)"
    )
    return worst_value


def log_uniform(rng, low_exp, high_exp, size):
    """10**U(low_exp, high_exp)."""
    return 10.0 ** rng.uniform(low_exp, high_exp, size)


def signed(rng, values):
    return values * rng.choice([-1.0, 1.0], size=np.shape(values))


# --------------------------------------------------------------------------------------------------
# Evaluation of the function under test on a grid.


def _bucket(size):
    """Grid sizes are padded to 256 (or the next power of two) so that one compilation serves all
    the grids of a function: compiling the larger functions takes seconds, evaluating microseconds."""
    return max(256, 1 << max(0, size - 1).bit_length())


def call_padded(jitted, *arrays):
    """``jitted(*arrays)`` on broadcast, flattened arrays padded to a bucket size; dtype preserved.

    Returns a numpy array, or a list of arrays for a tuple result, in the broadcast shape.
    """
    arrays = np.broadcast_arrays(*[np.asarray(a) for a in arrays])
    shape = arrays[0].shape
    flat = [np.ravel(a) for a in arrays]
    size = flat[0].size
    pad = _bucket(size) - size
    padded = [np.concatenate([a, np.repeat(a[:1], pad)]) if pad else a for a in flat]
    out = jitted(*padded)
    if isinstance(out, (tuple, list)):
        return [np.asarray(o)[:size].reshape(shape) for o in out]
    return np.asarray(out)[:size].reshape(shape)
