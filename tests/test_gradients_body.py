"""Derivatives of FreeRigidBody's outputs with respect to inertia, angular momentum, attitude and time.

Reference: tests/data/gradient_references.json (tests/data/make_gradient_references.py), the Jacobian
of y = (L(t), Omega(t), q(t), R(t)) with respect to x = (I, L, q0, t) from mpmath.odefun at 32 digits
(central differences with h = 1e-10 for I and L, exact for q0 and t), at

* "generic" points: both regimes, moments in any order, negative components and times, |L| != 1, a
  long time, the asteroid of the fitting notebook, |d I2 - 1| = 1e-3 and 1e-6 next to the separatrix;
* "smooth" points where some formula of frbjax degenerates but the motion and the formulas stay
  smooth: I1 = I2, I2 = I3, a zero component of L, t = 0, L = 0, and symmetric bodies whose unit L is
  1e-3 .. 1e-8 from the plane of their equal moments (frbjax._precession; 60-digit references);
* "branch" points where frbjax switches to a limiting formula (see CONVENTION below).

Error measure per point and input coordinate j (the accuracy target is 1e-9; TOL below):

    |J_ad[:, j] - J_ref[:, j]|_inf / |J_ref[:, j]|_inf

(over the 19 outputs; a column that vanishes, e.g. d/dI at L = 0, is measured against |J_ref|_inf).

CONVENTION at the branch points (documented here and checked: finite everywhere).  frbjax evaluates
uniform rotation q0 ⊗ exp(Omega t / 2) whenever Omega is parallel to L (L = 0, L along a principal
axis, in the plane of two equal moments, a sphere) and the separatrix formulas when d I2 = 1 exactly.

* uniform rotation: every first derivative is exact, those that start a nutation (a transverse
  component of L, unequal changes of the moments) included: the derivative rule of the uniform formula
  solves the variational equations in closed form (frbjax._uniform, docs/theory.md §6), so these
  points are checked in every column;
* on the separatrix: derivatives that keep d I2 = 1 are exact, the others miss the (finite) change of
  the elliptic parameter; the t and q0 columns keep the branch and are checked there at TOL.

Second derivatives: d^2 y/dt^2 (forward over forward) at every point against the equations of motion
applied to the 32-digit values; the Hessian of (L(t), q(t)) in (I, L, t) at four points against
32-digit second differences (tests/data/hessian_references.json, make_hessian_references.py); the
second derivative of R_J at a zero argument (which the constructor's complete Pi has) against mpmath.

Cost: compilation dominates (the attitude is a large program), so there are a few programs, each
jitted and vmapped over all the points at once and compiled once per session: the values with the forward-mode
Jacobian, the reverse-mode Jacobian, the second
derivatives in t, the Hessians.  On CPU they are compiled with XLA:CPU's fusion emitters off (as frbjax.fit does), the
reverse and second-order ones also at XLA backend optimisation level 0: 2-4x less compile time
(reverse mode: 140 s -> 40 s under load), the same mathematics: with XLA's default options the worst
errors are of the same size (jacfwd 3.9e-13, jacrev 5.0e-13, same point; benchmarks/gradients.py).  y contains R(t) as
_quaternion.as_matrix(q(t)), which is what FreeRigidBody.rotation_matrix returns, so that the
attitude is traced once per program.
"""

from __future__ import annotations

import functools
import json
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _compile_options import FAST_COMPILE_OPTIONS

from frbjax import _quaternion as quaternion, FreeRigidBody


# Worst measured relative column errors (generic and smooth points): jacfwd 3.9e-13, jacrev 2.1e-13
# (both at "separatrix +1e-03", d/dI2; the derivatives there are ill-conditioned), every other point
# <= 4e-15.  The accuracy target is 1e-9.
TOL = 1e-12
# At |d I2 - 1| = 1e-6 (the points "separatrix +1e-06" and "separatrix -1e-06") the derivatives in I2 are
# ill-conditioned (they grow like 1/|d I2 - 1|): measured 5.4e-12 (+1e-6) and 8.6e-11 (-1e-6, d/dI2)
# since the complementary-nome series (0a9be7b) replaced the Carlson/Landen evaluation there (which
# measured 3.9e-13).  Still far below the target 1e-9.
TOL_NEXT_TO_SEPARATRIX = 1.5e-10
# d^2 y/dt^2 against the equations of motion: worst measured 1.1e-15.
TOL_SECOND = 1e-14
# Hessians against 32-digit second differences (tests/data/hessian_references.json), worst measured
# relative error per point: 2.9e-12 (major), 4.8e-12 (minor), 1.1e-10 (separatrix -1e-3, where the
# second derivatives in I2 are ill-conditioned), 5.9e-16 (a symmetric body at e . n = 0.01 from the
# plane of its equal moments, all but the second derivative twice in I1 - I2).  The accuracy target
# is 1e-9.
TOL_HESSIAN = {"major": 1e-11, "minor unsorted": 1e-11, "separatrix -1e-03": 2e-10, "I1=I2 near plane 1e-02": 1e-15}
DATA = pathlib.Path(__file__).resolve().parent / "data" / "gradient_references.json"
INPUTS = ["I1", "I2", "I3", "L1", "L2", "L3", "qw", "qx", "qy", "qz", "t"]
BRANCH_COLUMNS = slice(6, 11)  # q0 and t: exact at the branch points too (CONVENTION)
# The branch point whose derivatives are one-sided (checked in the q0 and t columns only): the
# separatrix.  Every other branch point (the uniform rotations) is checked in every column (CONVENTION).
ONE_SIDED_BRANCH_POINTS = ("separatrix",)

# Compiler options on CPU (module docstring); other backends compile with their defaults.
FORWARD_OPTIONS = {"xla_cpu_use_fusion_emitters": False}


# FreeRigidBody's two paths (both checked at every point): a body at one time (the one-time path)
# and at an array of times (the per-body series), here the one time as an array of shape (1,).
PATHS = ("one_time", "series")


def _at(method, t, path):
    return method(t) if path == "one_time" else method(t[None])[0]


def outputs(x, path="one_time"):
    """y = (L, Omega, q, R row-major) at time t from x = (I (3), L (3), q0 (4), t)."""
    body = FreeRigidBody(x[:3], x[3:6], x[6:10])
    t = x[10]
    q = _at(body.quaternion, t, path)
    return jnp.concatenate(
        [
            _at(body.angular_momentum, t, path),
            _at(body.angular_velocity, t, path),
            q,
            quaternion.as_matrix(q).reshape(-1),
        ]
    )


@functools.cache
def references():
    data = json.loads(DATA.read_text())
    points = data["points"]
    names = [p["name"] for p in points]
    kinds = [p["kind"] for p in points]
    x = np.array([p["x"] for p in points])
    values = np.array([[float(v) for v in p["values"]] for p in points])
    jacobian = np.array([[[float(v) for v in row] for row in p["jacobian"]] for p in points])
    return names, kinds, x, values, jacobian


def _compile(function, options, *args):
    lowered = jax.jit(function).lower(*args)
    return lowered.compile(compiler_options=options) if jax.default_backend() == "cpu" else lowered.compile()


def _forward_one(x, path):
    jacobian, values = jax.jacfwd(lambda y: (lambda out: (out, out))(outputs(y, path)), has_aux=True)(x)
    return values, jacobian


@functools.cache
def forward_program(path="one_time"):
    """(values (P, 19), Jacobian (P, 19, 11)) of points x (P, 11), by forward mode."""
    x = jnp.asarray(references()[2])
    return _compile(jax.vmap(functools.partial(_forward_one, path=path)), FORWARD_OPTIONS, x)


@functools.cache
def forward(path="one_time"):
    values, jacobian = forward_program(path)(jnp.asarray(references()[2]))
    return np.asarray(values), np.asarray(jacobian)


@functools.cache
def reverse(path="one_time"):
    x = jnp.asarray(references()[2])
    return np.asarray(_compile(jax.vmap(jax.jacrev(functools.partial(outputs, path=path))), FAST_COMPILE_OPTIONS, x)(x))


def column_errors(automatic, reference):
    """(P, 11) relative errors per point and input column (module docstring)."""
    difference = np.max(np.abs(automatic - reference), axis=-2)
    column = np.max(np.abs(reference), axis=-2)
    whole = np.max(np.abs(reference), axis=(-2, -1))[:, None]
    return difference / np.where(column > 0, column, whole)


def _report(mode, names, kinds, errors):
    print(f"\n{mode}: worst relative column error per point (branch points: the q0 and t columns)")
    for name, kind, row in zip(names, kinds, errors):
        if kind == "branch" and name in ONE_SIDED_BRANCH_POINTS:
            row = np.where(np.arange(11) >= 6, row, 0.0)
        worst = int(np.argmax(row))
        print(f"  {name:22s} {kind:8s} {row[worst]:.1e} ({INPUTS[worst]})")


def _check(mode, automatic):
    """Finite everywhere; TOL at the generic and smooth points, and in the q0 and t columns at the
    branch points."""
    names, kinds, _, _, reference = references()
    assert automatic.shape == reference.shape
    finite = np.all(np.isfinite(automatic), axis=(-2, -1))
    assert finite.all(), f"{mode}: non-finite derivatives at {[n for n, f in zip(names, finite) if not f]}"
    errors = column_errors(automatic, reference)
    _report(mode, names, kinds, errors)
    bad = {}
    for k, (name, kind) in enumerate(zip(names, kinds)):
        partial = kind == "branch" and name in ONE_SIDED_BRANCH_POINTS
        worst = errors[k, BRANCH_COLUMNS].max() if partial else errors[k].max()
        tolerance = TOL_NEXT_TO_SEPARATRIX if name.endswith("e-06") else TOL
        if worst > tolerance:
            bad[name] = float(worst)
    assert not bad, (
        f"{mode}: relative column errors above {TOL} ({TOL_NEXT_TO_SEPARATRIX} at 1e-6 from the separatrix): {bad}"
    )


@pytest.mark.parametrize("path", PATHS)
def test_forward_mode_matches_mpmath(path):
    """jax.jacfwd (and the values) at every point against the 32-digit references."""
    _, _, _, values_reference, _ = references()
    values, jacobian = forward(path)
    error = np.max(np.abs(values - values_reference))
    print(f"\nvalues: worst absolute error {error:.1e}")
    assert error < 1e-14  # measured 2.1e-15
    _check("jacfwd", jacobian)


@pytest.mark.parametrize("path", PATHS)
def test_reverse_mode_matches_mpmath(path):
    """jax.jacrev: finite at every point (no NaN from untaken branches), right where smooth."""
    _check("jacrev", reverse(path))


# ------------------------------------------------------------------------------ second derivatives


def _time_second_derivative(x, path):
    """d^2 y/dt^2 by forward over forward in t."""
    body = FreeRigidBody(x[:3], x[3:6], x[6:10])

    def in_time(t):
        q = _at(body.quaternion, t, path)
        return jnp.concatenate(
            [
                _at(body.angular_momentum, t, path),
                _at(body.angular_velocity, t, path),
                q,
                quaternion.as_matrix(q).reshape(-1),
            ]
        )

    one = jnp.ones_like(x[10])
    return jax.jvp(lambda s: jax.jvp(in_time, (s,), (one,))[1], (x[10],), (one,))[1]


def _time_second_derivative_reference(values, inertia):
    """d^2 y/dt^2 from the 32-digit (L(t), q(t)) by the equations of motion: L' = L x Omega, Omega = L/I,
    q' = q ⊗ (0, Omega)/2, so L'' = L' x Omega + L x Omega', q'' = (q' ⊗ (0, Omega) + q ⊗ (0, Omega'))/2,
    and R'' = D^2R[q', q'] + DR[q''] (R quadratic in q)."""
    momentum, q = values[:, :3], values[:, 6:10]
    omega = momentum / inertia
    d_momentum = np.cross(momentum, omega)
    d_omega = d_momentum / inertia
    dd_momentum = np.cross(d_momentum, omega) + np.cross(momentum, d_omega)
    pure = lambda v: np.concatenate([np.zeros(v.shape[:-1] + (1,)), v], -1)  # noqa: E731
    hamilton = lambda a, b: np.asarray(quaternion.multiply(jnp.asarray(a), jnp.asarray(b)))  # noqa: E731
    dq = hamilton(q, pure(omega)) / 2
    ddq = (hamilton(dq, pure(omega)) + hamilton(q, pure(d_omega))) / 2
    matrix = quaternion.as_matrix
    second = jax.jvp(lambda a: jax.jvp(matrix, (a,), (jnp.asarray(dq),))[1], (jnp.asarray(q),), (jnp.asarray(dq),))[1]
    ddr = np.asarray(second + jax.jvp(matrix, (jnp.asarray(q),), (jnp.asarray(ddq),))[1]).reshape(-1, 9)
    return np.concatenate([dd_momentum, dd_momentum / inertia, ddq, ddr], -1)


@pytest.mark.parametrize("path", PATHS)
def test_second_derivatives(path):
    """d^2 y/dt^2 (forward over forward) at every point (the branch points' formulas are exact in t)
    against the equations of motion applied to the 32-digit values.

    The Hessian in I, L and t: test_hessian_matches_mpmath."""
    names, kinds, x, values, _ = references()
    program = _compile(jax.vmap(functools.partial(_time_second_derivative, path=path)), FAST_COMPILE_OPTIONS, x)
    second = np.asarray(program(jnp.asarray(x)))
    assert np.all(np.isfinite(second))
    reference = _time_second_derivative_reference(values, x[:, :3])
    scale = np.max(np.abs(reference), -1)
    errors = np.max(np.abs(second - reference), -1) / np.where(scale > 0, scale, 1)  # L = 0: absolute
    print("\nd^2 y/dt^2: relative error against the equations of motion")
    for name, error in zip(names, errors):
        print(f"  {name:22s} {error:.1e}")
    assert errors.max() < TOL_SECOND, dict(zip(names, errors))


def test_second_derivative_at_a_zero_carlson_argument():
    """d^2/dy^2 R_J(0, y, 1, 0.7) at y = 0.5 (forward over forward) against mpmath.diff (30 digits).

    The constructor's complete Pi(nu|m) is an R_J with x = 0: before the Carlson JVP rules were made
    differentiable again at a zero argument (special/_carlson.py) this was NaN, and with it every second
    derivative of q(t) with respect to I, L or q0."""
    from frbjax.special import elliprj

    @jax.jit
    def second(y):
        zero, one = jnp.zeros_like(y), jnp.ones_like(y)
        rj = lambda y: elliprj(zero, y, one, 0.7 * one)  # noqa: E731
        return jax.jvp(lambda z: jax.jvp(rj, (z,), (one,))[1], (y,), (one,))[1]

    assert float(second(jnp.float64(0.5))) == pytest.approx(6.8063002406807005996, rel=1e-12)


# ------------------------------------------------------------------------------ full Hessian

HESSIAN_DATA = DATA.parent / "hessian_references.json"


def _hessian_references():
    """(names, x (P, 7) = (I, L, t), attitude (4,), values (P, 7), Hessians (P, 7, 7, 7)) from
    tests/data/make_hessian_references.py (second differences of 32-digit mpmath.odefun solutions)."""
    data = json.loads(HESSIAN_DATA.read_text())
    points = data["points"]
    names = [p["name"] for p in points]
    x = np.array([p["x"] for p in points])
    values = np.array([[float(v) for v in p["values"]] for p in points])
    hessians = np.array([[[[float(v) for v in row] for row in block] for block in p["hessian"]] for p in points])
    return names, x, np.array(data["attitude"]), values, hessians


# Each path's Hessian program compiled for about a minute with the JAX rules (CI's tier, 2026-11-28:
# 57.6 s and 62.6 s); with the compiled flow kernels' second derivatives, 0.2 s.
@pytest.mark.parametrize("path", PATHS)
def test_hessian_matches_mpmath(path):
    """The Hessian of (L(t), q(t)) with respect to (I, L, t) at generic points of both regimes and next
    to the separatrix, against 32-digit second differences; error per output k:
    max |H_k - H_k,ref| / max |H_k,ref| over the 7 x 7 block.

    jax.hessian itself (forward over reverse), one program for one point, compiled once and called at
    each of the four points: unbatched, the library's branches stay branches, and tracing and
    compiling it took 51 s of CPU (15 s tracing, 36 s XLA) where the program vmapped over the points
    took 88-95 s per path.  (A vmap once turned the library's fusion boundaries into selects and the
    compilation took 13 GB and three minutes: ``frbjax._fusion.anywhere``.)"""
    names, x, attitude, values, reference = _hessian_references()

    def motion(point):
        body = FreeRigidBody(point[:3], point[3:6], jnp.asarray(attitude))
        return jnp.concatenate([_at(body.angular_momentum, point[6], path), _at(body.quaternion, point[6], path)])

    program = _compile(jax.hessian(motion), FAST_COMPILE_OPTIONS, x[0])
    hessian = np.stack([np.asarray(program(jnp.asarray(point))) for point in x])
    assert np.all(np.isfinite(hessian))
    # Next to the plane of equal moments, in the coordinates (I1 + I2, I1 - I2, I3, L, t): every
    # second derivative but the one twice in I1 - I2, which the first-order expansion there lacks
    # (frbjax._precession; its reference values are -0.28 .. 0.19 here).
    near_plane = np.array(["near plane" in name for name in names])
    basis = np.eye(7)
    basis[:2, :2] = [[0.5, 0.5], [0.5, -0.5]]
    hessian[near_plane] = np.einsum("pkij,ia,jb->pkab", hessian[near_plane], basis, basis)
    reference = reference.copy()
    reference[near_plane] = np.einsum("pkij,ia,jb->pkab", reference[near_plane], basis, basis)
    hessian[near_plane, :, 1, 1] = reference[near_plane, :, 1, 1] = 0
    scale = np.max(np.abs(reference), axis=(-2, -1))
    errors = np.max(np.abs(hessian - reference), axis=(-2, -1)) / scale
    print("\nHessian: worst relative error per point (over the 7 outputs)")
    for name, row in zip(names, errors):
        print(f"  {name:22s} {row.max():.1e}")
    bad = {name: float(row.max()) for name, row in zip(names, errors) if row.max() > TOL_HESSIAN[name]}
    assert not bad, bad
