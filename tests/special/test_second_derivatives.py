"""Second derivatives of frbjax.special (the custom JVP rules differentiated again) against mpmath.

Every rule must be differentiable again in each composition of the modes: forward over forward
(jacfwd of jacfwd), reverse over forward (jacrev of jacfwd) and forward over reverse (jacfwd of
jacrev, i.e. ``jax.hessian``), with finite values where an argument is zero (x = 0 for the Carlson
functions, phi = 0, n = 0, m = 0) and the right values elsewhere.

References: Hessians of mpmath's functions by central differences at 70 digits
(``_mpmath_reference.taylor``, order 2; error ~1e-20).  A Carlson argument that is zero is not
differentiated (the partial derivatives in it are infinite; the library's convention gives 0 there,
only required to be finite).

Error measure: per point, the largest error of the Hessian entries (over the differentiated
arguments) divided by the largest reference entry there (a normwise relative error: second
derivatives of F and Pi pass through zero, at phi = 0 all of them are zero).  The tolerances are
the worst errors measured on these points (printed by ``pytest -s``) with a small margin.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _compile_options import fast_jit

import frbjax.special as special

from . import _mpmath_reference as ref
from ._stored import stored


ARGNAMES = {
    "elliprf": ("x", "y", "z"),
    "elliprd": ("x", "y", "z"),
    "elliprj": ("x", "y", "z", "p"),
    "elliprc": ("x", "y"),
    "ellipk": ("m",),
    "ellipe": ("m",),
    "ellipkinc": ("phi", "m"),
    "ellippi": ("n", "m"),
    "ellippiinc": ("n", "phi", "m"),
}
PARAMETRISED = ("ellipk", "ellipe", "ellipkinc", "ellippi", "ellippiinc")  # accept mc

# Generic points first, then points with a zero argument.
POINTS = {
    "elliprf": [(0.5, 1.2, 2.0), (3.0, 0.1, 0.7), (1e-3, 2.0, 50.0), (0.0, 0.5, 1.0), (2.0, 0.0, 0.3)],
    "elliprd": [(0.5, 1.2, 2.0), (3.0, 0.1, 0.7), (20.0, 1e-2, 0.5), (0.0, 0.5, 1.0), (0.5, 0.0, 2.0)],
    "elliprj": [
        (0.5, 1.2, 2.0, 0.8),
        (3.0, 0.1, 0.7, 2.5),
        (0.2, 0.3, 0.4, 50.0),
        (2.0, 3.0, 4.0, 0.1),
        (0.0, 0.5, 1.0, 0.7),
        (0.0, 0.5, 1.0, 40.0),
        (1.5, 0.0, 1.0, 0.2),
    ],
    "elliprc": [(0.5, 1.2), (3.0, 0.1), (1.0, 1.0000001), (0.0, 0.5)],
    "ellipk": [(0.3,), (0.9,), (1 - 1e-6,), (0.0,)],
    "ellipe": [(0.3,), (0.9,), (1 - 1e-6,), (0.0,)],
    "ellipkinc": [(0.7, 0.3), (4.0, 0.9), (-2.5, 0.6), (0.0, 0.5), (1.2, 0.0), (0.0, 0.0)],
    "ellippi": [(0.4, 0.3), (-2.0, 0.8), (-0.5, 0.99), (0.0, 0.5), (0.3, 0.0), (0.0, 0.0)],
    "ellippiinc": [
        (0.4, 0.7, 0.3),
        (-2.0, 4.0, 0.8),
        (-0.5, 1.5, 0.9),
        (0.3, 0.0, 0.5),
        (0.0, 1.2, 0.6),
        (0.5, 1.0, 0.0),
        (0.0, 2.0, 0.0),
    ],
}
MODES = {
    "fwd-fwd": lambda f: jax.jacfwd(jax.jacfwd(f)),
    "rev-fwd": lambda f: jax.jacrev(jax.jacfwd(f)),
    "fwd-rev": lambda f: jax.jacfwd(jax.jacrev(f)),
}
# Worst normwise relative errors measured on POINTS over the three modes (and with mc), the programs
# compiled with tests/_compile_options.py's options (with XLA's defaults in brackets):
# R_F 7.9e-16 (5.4e-16), R_D 3.7e-16 (3.6e-16), R_J 7.8e-16 (5.1e-16), R_C 6.4e-16 (5.1e-16), K 2.9e-16,
# E 3.5e-16, F 4.4e-16, Pi(n|m) 8.2e-16 (6.8e-16), Pi(n; phi|m) 9.6e-16 (8.0e-16); tolerances 1.3 to 3 times
# that.
TOL = {
    "elliprf": 1e-15,
    "elliprd": 1e-15,
    "elliprj": 1e-15,
    "elliprc": 1e-15,
    "ellipk": 1e-15,
    "ellipe": 1e-15,
    "ellipkinc": 1e-15,
    "ellippi": 1.5e-15,
    "ellippiinc": 1.5e-15,
}


def _reference_function(name):
    fn = getattr(ref, name)
    if name in PARAMETRISED:
        return lambda *args: fn(*args[:-1], args[-1])
    return fn


def _steps(name):
    """Step scales of the reference differences: |x| for the Carlson arguments (None, no
    derivative, at 0), 1 - m for m, |1 - n| for n, |phi| (1 at 0) for phi."""
    if name.startswith("ellipr"):
        return lambda *a: tuple(abs(x) if x != 0 else None for x in a)
    kinds = {"m": ref.m_step, "n": ref.n_step, "phi": lambda x: ref.step(abs(x))}
    return lambda *a: tuple(kinds[arg](x) for arg, x in zip(ARGNAMES[name], a))


@stored([(name,) for name in POINTS])
def reference(name):
    points = np.array(POINTS[name], dtype=np.float64)
    _, _, _, hessian = ref.taylor_table(_reference_function(name), list(points.T), _steps(name), order=2)
    return points, np.moveaxis(hessian[0], -1, 0)  # (npoints, nargs, nargs), NaN where not differentiated


@functools.cache
def _hessian_program(name, mode, with_mc):
    fn = getattr(special, name)
    if with_mc:
        scalar = lambda v: fn(*v, mc=1 - v[-1])  # noqa: E731  d/dm moves m and mc together
    else:
        scalar = lambda v: fn(*v)  # noqa: E731
    return fast_jit(jax.vmap(MODES[mode](scalar)))


def hessians(name, mode, with_mc=False):
    points, _ = reference(name)
    return np.asarray(_hessian_program(name, mode, with_mc)(jnp.asarray(points)))


def _normwise_errors(ours, want):
    active = np.isfinite(want)
    difference = np.where(active, np.abs(ours - want), 0).reshape(len(want), -1).max(-1)
    scale = np.where(active, np.abs(want), 0).reshape(len(want), -1).max(-1)
    return ref.ratio(difference, scale)


CASES = [(name, mode, False) for name in POINTS for mode in MODES if not name.startswith("ellipr")]
CASES += [(name, "fwd-rev", True) for name in PARAMETRISED]
CARLSON_CASES = [(name, mode, False) for name in POINTS for mode in MODES if name.startswith("ellipr")]


@pytest.mark.parametrize("name, mode, with_mc", CASES)
def test_second_derivatives(name, mode, with_mc):
    check_second_derivatives(name, mode, with_mc)


# The compiled kernels in every mode; the JAX code (the cross-check) in one mode that composes
# reverse with forward mode (its three modes took 45 s together, R_J's rev-fwd 23 s of it).
CARLSON_PATH_CASES = [("compiled", *case) for case in CARLSON_CASES]
CARLSON_PATH_CASES += [("jax", name, mode, with_mc) for name, mode, with_mc in CARLSON_CASES if mode == "fwd-rev"]


# Hessians computed by the Carlson cases, by (path, name, mode): the JAX path's are also compared with
# the compiled kernels' (computed here when that case has not run first).
_CARLSON_HESSIANS = {}


@pytest.mark.parametrize("special_path, name, mode, with_mc", CARLSON_PATH_CASES, indirect=["special_path"])
def test_carlson_second_derivatives(special_path, name, mode, with_mc):
    """The Carlson integrals' Hessians on both paths (the compiled kernels and the JAX code), each
    against mpmath, and the two paths against each other, entry by entry: largest relative difference
    measured 2.7e-15 (R_J; R_F 2.3e-15, R_D and R_C 4e-16), allowed 1e-14."""
    ours = check_second_derivatives(name, mode, with_mc)
    _CARLSON_HESSIANS[special_path, name, mode] = ours
    if special_path == "jax":
        compiled = _CARLSON_HESSIANS.get(("compiled", name, mode))
        if compiled is None:
            with pytest.MonkeyPatch.context() as patch:
                patch.setenv("FRBJAX_KERNELS", "compiled")
                jax.clear_caches()
                compiled = hessians(name, mode, with_mc)
            jax.clear_caches()
        np.testing.assert_allclose(compiled, ours, rtol=1e-14, atol=1e-300)


def check_second_derivatives(name, mode, with_mc):
    points, want = reference(name)
    ours = hessians(name, mode, with_mc)
    assert np.all(np.isfinite(ours)), (name, mode, points[~np.isfinite(ours).reshape(len(points), -1).all(-1)])
    np.testing.assert_allclose(ours, np.swapaxes(ours, 1, 2), rtol=1e-12, atol=1e-300)  # symmetric
    errors = _normwise_errors(ours, want)
    print(f"\n{name} {mode}{' (mc)' if with_mc else ''}: worst normwise relative error {errors.max():.1e}")
    ref.check(
        f"{name} Hessian ({mode}{', mc' if with_mc else ''}) normwise relative error",
        errors,
        TOL[name],
        {"point": [str(tuple(p)) for p in points]},
    )
    return ours


def test_hessian_of_a_composite():
    """jax.hessian of a small composite through several rules: finite and right (mpmath)."""

    def composite(v):
        n, m = v[0], v[1]
        return special.ellippi(n, m) * special.ellipkinc(1 - n, m) + special.elliprj(0.0, m, 1.0, 1 - n)

    def composite_reference(n, m):
        return ref.ellippi(n, m) * ref.ellipkinc(1 - n, m) + ref.elliprj(ref.mpf(0), m, ref.mpf(1), 1 - n)

    point = np.array([0.3, 0.6])
    ours = np.asarray(fast_jit(jax.hessian(composite))(jnp.asarray(point)))
    _, _, _, want = ref.taylor_table(
        composite_reference, [point[:1], point[1:]], lambda n, m: (ref.n_step(n), ref.m_step(m)), order=2
    )
    want = want[0, :, :, 0]
    error = float(_normwise_errors(ours[None], want[None])[0])
    print(f"\nhessian of the composite: normwise relative error {error:.1e}")
    assert error < 1e-15, (ours, want)  # measured 1.9e-16
