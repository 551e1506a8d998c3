"""Independent references for the FreeRigidBody tests: numerical integration of the equations of motion.

Nothing here uses a formula of frbjax.  The references integrate the defining differential equations

    Omega = L / I (componentwise),   dL/dt = L x Omega,
    dq/dt = 1/2 q ⊗ (0, Omega)   (Hamilton product, q = (w, x, y, z), body to space),
    dR/dt = R hat(Omega)          (x_space = R x_body),

either with diffrax's 8th-order Dormand-Prince method in float64 (jit-compiled, vmapped over a batch of
bodies) or with mpmath's arbitrary-precision Taylor-series solver ``mpmath.odefun``.

Conventions
-----------
* The diffrax state carries l = L / s with s = |L(0)| (s = 1 when L(0) = 0), so that the absolute
  tolerance means the same thing for every |L|: dl/dt = l x (s l / I).  This is only a change of unit
  of the state; time is the physical time t.
* Every body has its own time grid ``times[k]`` (shape (K,)), monotone away from 0 (all >= 0 or all
  <= 0); diffrax integrates from 0 to ``times[k, -1]``, backwards when that is negative.
* The helpers that build test bodies (`separatrix_momentum`, `random_attitudes`, ...) work in numpy /
  mpmath on the definition d = 2E/|L|^2 = sum(l_i^2 / I_i) only.
* `evaluate` (at the end) is not a reference: it is the shared harness that evaluates frbjax for a
  batch of bodies, each at its own times.
"""

from __future__ import annotations

import functools

import diffrax
import jax
import jax.numpy as jnp
import mpmath
import numpy as np


# --------------------------------------------------------------------------------------------------
# Quaternion algebra (written out from the definition of the Hamilton product).


def hamilton(p, q):
    """Hamilton product p ⊗ q of (..., 4) arrays (jax or numpy), q = (w, x, y, z)."""
    xp = jnp if isinstance(p, jax.Array) or isinstance(q, jax.Array) else np
    pw, pv = p[..., :1], p[..., 1:]
    qw, qv = q[..., :1], q[..., 1:]
    w = pw * qw - xp.sum(pv * qv, axis=-1, keepdims=True)
    v = pw * qv + qw * pv + xp.cross(pv, qv)
    return xp.concatenate([w, v], axis=-1)


def conjugate(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def rotate(q, v):
    """q ⊗ (0, v) ⊗ q* (the vector part), for unit q: the body-to-space image of v."""
    xp = jnp if isinstance(q, jax.Array) or isinstance(v, jax.Array) else np
    zero = xp.zeros(v.shape[:-1] + (1,), v.dtype)
    return hamilton(hamilton(q, xp.concatenate([zero, v], -1)), conjugate(q))[..., 1:]


def matrix_of(q):
    """Rotation matrix of a unit quaternion, column j = rotate(q, e_j) (numpy)."""
    q = np.asarray(q, float)
    eye = np.broadcast_to(np.eye(3), q.shape[:-1] + (3, 3))
    columns = [rotate(q, eye[..., :, j]) for j in range(3)]
    return np.stack(columns, axis=-1)


def random_attitudes(rng, n):
    """n unit quaternions, uniform on SO(3) (normalised Gaussian 4-vectors)."""
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def random_directions(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# --------------------------------------------------------------------------------------------------
# diffrax (float64) references.


def _hat(w):
    x, y, z = w[0], w[1], w[2]
    zero = jnp.zeros_like(x)
    return jnp.stack([jnp.stack([zero, -z, y]), jnp.stack([z, zero, -x]), jnp.stack([-y, x, zero])])


def _quaternion_field(t, y, args):
    inertia, scale = args
    l, q = y[:3], y[3:]
    omega = scale * l / inertia
    dl = jnp.cross(l, omega)
    dq = 0.5 * hamilton(q, jnp.concatenate([jnp.zeros(1, y.dtype), omega]))
    return jnp.concatenate([dl, dq])


def _matrix_field(t, y, args):
    inertia, scale = args
    l, r = y[:3], y[3:].reshape(3, 3)
    omega = scale * l / inertia
    return jnp.concatenate([jnp.cross(l, omega), (r @ _hat(omega)).reshape(9)])


def _solve(field, y0, inertia, scale, times, rtol, atol, max_steps):
    term = diffrax.ODETerm(field)
    solution = diffrax.diffeqsolve(
        term,
        diffrax.Dopri8(),
        t0=jnp.zeros_like(times[-1]),
        t1=times[-1],
        dt0=None,
        y0=y0,
        args=(inertia, scale),
        saveat=diffrax.SaveAt(ts=times),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        max_steps=max_steps,
        throw=False,
    )
    return solution.ys, solution.stats["num_accepted_steps"], solution.result == diffrax.RESULTS.successful


def _scale(momentum):
    norm = jnp.linalg.norm(momentum)
    return jnp.where(norm > 0, norm, 1.0)


@functools.partial(jax.jit, static_argnames=("rtol", "atol", "max_steps"))
def _integrate_quaternion(inertia, momentum, attitude, times, rtol, atol, max_steps):
    def one(inertia, momentum, attitude, times):
        scale = _scale(momentum)
        y0 = jnp.concatenate([momentum / scale, attitude])
        ys, steps, ok = _solve(_quaternion_field, y0, inertia, scale, times, rtol, atol, max_steps)
        return scale * ys[:, :3], ys[:, 3:], steps, ok

    return jax.vmap(one)(inertia, momentum, attitude, times)


@functools.partial(jax.jit, static_argnames=("rtol", "atol", "max_steps"))
def _integrate_matrix(inertia, momentum, matrix, times, rtol, atol, max_steps):
    def one(inertia, momentum, matrix, times):
        scale = _scale(momentum)
        y0 = jnp.concatenate([momentum / scale, matrix.reshape(9)])
        ys, steps, ok = _solve(_matrix_field, y0, inertia, scale, times, rtol, atol, max_steps)
        return scale * ys[:, :3], ys[:, 3:].reshape(-1, 3, 3), steps, ok

    return jax.vmap(one)(inertia, momentum, matrix, times)


# Against mpmath at 30 digits (generic bodies, |L| t up to 54): rtol = atol = 1e-16 gives ~1e-13,
# 1e-15 ~1e-12, 1e-13 ~1e-10 (Dopri8 still gains accuracy below rtol = eps here).
RTOL = 1e-16
ATOL = 1e-16
MAX_STEPS = 200_000


def _check(ok, steps):
    ok = np.asarray(ok)
    if not ok.all():
        failed = np.flatnonzero(~ok)
        raise RuntimeError(f"diffrax failed for bodies {failed} (steps {np.asarray(steps)[failed]})")


def integrate_quaternion(inertia, momentum, attitude, times, rtol=RTOL, atol=ATOL, max_steps=MAX_STEPS):
    """(L, q, accepted steps) at ``times`` for a batch of bodies: (N, 3), (N, 3), (N, 4), (N, K) arrays.

    Returns L of shape (N, K, 3), q of shape (N, K, 4) and the number of accepted steps per body.
    """
    args = [jnp.asarray(np.asarray(a, np.float64)) for a in (inertia, momentum, attitude, times)]
    L, q, steps, ok = _integrate_quaternion(*args, rtol=rtol, atol=atol, max_steps=max_steps)
    _check(ok, steps)
    return np.asarray(L), np.asarray(q), np.asarray(steps)


def integrate_matrix(inertia, momentum, matrix, times, rtol=RTOL, atol=ATOL, max_steps=MAX_STEPS):
    """(L, R, accepted steps) at ``times`` for a batch of bodies, integrating dR/dt = R hat(Omega)."""
    args = [jnp.asarray(np.asarray(a, np.float64)) for a in (inertia, momentum, matrix, times)]
    L, R, steps, ok = _integrate_matrix(*args, rtol=rtol, atol=atol, max_steps=max_steps)
    _check(ok, steps)
    return np.asarray(L), np.asarray(R), np.asarray(steps)


def diffrax_references(inertia, momentum, attitude, times, rtol=RTOL, atol=ATOL, max_steps=MAX_STEPS):
    """Both diffrax references for a batch of bodies, as tests/data/make_diffrax_references.py stores them.

    Returns a dict of arrays: ``L_quaternion`` (N, K, 3) and ``q`` (N, K, 4) from the (L, q) equations,
    ``L_matrix`` (N, K, 3) and ``R`` (N, K, 3, 3) from the (L, R) equations started at the matrix of
    the attitude, and the accepted steps of each (``steps_quaternion``, ``steps_matrix``, (N,)).
    """
    L_quaternion, q, steps_quaternion = integrate_quaternion(
        inertia, momentum, attitude, times, rtol=rtol, atol=atol, max_steps=max_steps
    )
    L_matrix, R, steps_matrix = integrate_matrix(
        inertia, momentum, matrix_of(attitude), times, rtol=rtol, atol=atol, max_steps=max_steps
    )
    return dict(
        L_quaternion=L_quaternion,
        q=q,
        L_matrix=L_matrix,
        R=R,
        steps_quaternion=steps_quaternion,
        steps_matrix=steps_matrix,
    )


# --------------------------------------------------------------------------------------------------
# mpmath references (arbitrary precision).


def mp_field(inertia):
    """The 7 equations (L, q) as a function for mpmath.odefun, moments given as mpf."""
    i1, i2, i3 = inertia

    def field(t, y):
        l1, l2, l3, qw, qx, qy, qz = y
        o1, o2, o3 = l1 / i1, l2 / i2, l3 / i3
        return [
            l2 * o3 - l3 * o2,
            l3 * o1 - l1 * o3,
            l1 * o2 - l2 * o1,
            (-qx * o1 - qy * o2 - qz * o3) / 2,
            (qw * o1 + qy * o3 - qz * o2) / 2,
            (qw * o2 - qx * o3 + qz * o1) / 2,
            (qw * o3 + qx * o2 - qy * o1) / 2,
        ]

    return field


def mpmath_solution(inertia, momentum, attitude, times, dps=30, digits=None):
    """(L, q) at ``times`` (all of one sign) from mpmath.odefun at ``dps`` digits.

    The initial values are the exact binary values of the float64 inputs (the attitude is normalised
    in mpmath).  Negative times are handled by integrating the time-reversed field in s = -t.
    Returns float64 arrays (K, 3) and (K, 4), or, with ``digits``, nested lists of decimal strings
    with that many significant digits.
    """
    times = [float(t) for t in times]
    sign = -1 if any(t < 0 for t in times) else 1
    assert all(sign * t >= 0 for t in times), "times must all have one sign"
    with mpmath.workdps(dps):
        inertia_mp = [mpmath.mpf(float(x)) for x in inertia]
        q0 = [mpmath.mpf(float(x)) for x in attitude]
        norm = mpmath.sqrt(sum(x * x for x in q0))
        y0 = [mpmath.mpf(float(x)) for x in momentum] + [x / norm for x in q0]
        forward = mp_field(inertia_mp)
        field = forward if sign > 0 else (lambda s, y: [-v for v in forward(-s, y)])
        solution = mpmath.odefun(field, 0, y0)
        values = {}
        for t in sorted(set(times), key=abs):  # odefun continues from its last point: go outwards
            y = solution(sign * mpmath.mpf(t))
            if digits:
                values[t] = [mpmath.nstr(v, digits, strip_zeros=False) for v in y]
            else:
                values[t] = [float(v) for v in y]
    rows = [values[t] for t in times]
    if digits:
        return [r[:3] for r in rows], [r[3:] for r in rows]
    array = np.array(rows)
    return array[:, :3], array[:, 3:]


# --------------------------------------------------------------------------------------------------
# Bodies at a prescribed distance from the separatrix.


def separatrix_momentum(inertia, offset, l2, signs=(1, 1, 1), dps=50):
    """Unit L with d I2 - 1 = ``offset`` exactly (before rounding to float64), d = sum(l_i^2 / I_i).

    ``inertia`` is sorted (I1 < I2 < I3) here; ``l2`` is the middle component (|l2| < 1).  With
    a = (I2 - I1)/I1 and b = (I3 - I2)/I3, d I2 - 1 = a l1^2 - b l3^2 on the unit sphere, so
    l1^2 = ((1 - l2^2) b + offset)/(a + b) and l3^2 = ((1 - l2^2) a - offset)/(a + b).
    The float64 result has d I2 - 1 = offset + O(1e-16).
    """
    with mpmath.workdps(dps):
        i1, i2, i3 = (mpmath.mpf(float(x)) for x in inertia)
        l2 = mpmath.mpf(float(l2))
        offset = mpmath.mpf(offset)
        a, b = (i2 - i1) / i1, (i3 - i2) / i3
        rest = 1 - l2 * l2
        l1 = mpmath.sqrt((rest * b + offset) / (a + b))
        l3 = mpmath.sqrt((rest * a - offset) / (a + b))
        return np.array([signs[0] * float(l1), signs[1] * float(l2), signs[2] * float(l3)])


def separatrix_distance(inertia, momentum, dps=50):
    """d I2 - 1 (I2 the middle moment) for the exact binary values of the inputs, d = 2E/|L|^2."""
    with mpmath.workdps(dps):
        inertia = [mpmath.mpf(float(x)) for x in inertia]
        l = [mpmath.mpf(float(x)) for x in momentum]
        middle = sorted(inertia)[1]
        d = sum(x * x / i for x, i in zip(l, inertia)) / sum(x * x for x in l)
        return float(d * middle - 1)


# --------------------------------------------------------------------------------------------------
# Evaluation of frbjax one body at a time.


CHUNK = 8192
# The series path's blocks: SERIES_BODIES bodies at SERIES_TIMES times each, padded to that size, so that
# a test session compiles each of FreeRigidBody's programs for one shape only (the compile costs
# seconds per program, evaluating a block milliseconds).
SERIES_BODIES, SERIES_TIMES = 64, 32


PATHS = ("one_time", "series")


def _pad_rows(a, size):
    """``a`` padded along its first axis to a multiple of ``size`` by repeating its first row."""
    padded = -(-len(a) // size) * size
    return np.concatenate([a, np.repeat(a[:1], padded - len(a), axis=0)])


def evaluate(inertia, momentum, attitude, times, quantities=("angular_momentum", "quaternion"), path="one_time"):
    """frbjax's values for a batch of N bodies, each at its own K times: arrays (N, K, ...).

    ``path="one_time"``: every (body, time) pair is evaluated as its own unbatched body at one time
    (the one-shot path, ``frbjax.free_flow``) inside ``jax.vmap``, op by op (no jit: a jit of the attitude
    takes over a minute to compile on CPU), in chunks of CHUNK pairs padded to that size, so that a
    test session compiles each op for one shape only.  ``path="series"``: every body is evaluated at
    its times at once (the per-body theta series), under ``jax.vmap`` over the bodies, in blocks of
    SERIES_BODIES bodies by SERIES_TIMES times (padded; a body's values at a time do not depend on its
    other times).
    """
    from frbjax import free_flow, FreeRigidBody, quaternion_to_matrix

    inertia, momentum, attitude, times = (np.asarray(a) for a in (inertia, momentum, attitude, times))
    n, k = times.shape
    if path == "series":

        def body_at_times(inertia, momentum, attitude, times):
            body = FreeRigidBody(inertia, momentum, attitude)
            return tuple(getattr(body, name)(times) for name in quantities)

        batched = jax.vmap(body_at_times)
        bodies = [_pad_rows(a, SERIES_BODIES) for a in (inertia, momentum, attitude)]
        padded_times = _pad_rows(_pad_rows(times, SERIES_BODIES).T, SERIES_TIMES).T
        rows = []
        for start in range(0, len(padded_times), SERIES_BODIES):
            block = slice(start, start + SERIES_BODIES)
            columns = [
                batched(
                    *(jnp.asarray(a[block]) for a in bodies),
                    jnp.asarray(padded_times[block, column : column + SERIES_TIMES]),
                )
                for column in range(0, padded_times.shape[1], SERIES_TIMES)
            ]
            rows.append([np.concatenate([np.asarray(c[i]) for c in columns], axis=1) for i in range(len(quantities))])
        return tuple(np.concatenate([r[i] for r in rows])[:n, :k] for i in range(len(quantities)))
    assert path == "one_time", path
    pairs = [np.repeat(a, k, axis=0) for a in (inertia, momentum, attitude)] + [times.reshape(-1)]
    total = n * k
    pairs = [_pad_rows(a, CHUNK) for a in pairs]

    def one(inertia, momentum, attitude, time):
        momentum_at, attitude_at = free_flow(inertia, momentum, attitude, time)
        values = dict(
            angular_momentum=momentum_at,
            angular_velocity=momentum_at / inertia,
            quaternion=attitude_at,
            rotation_matrix=quaternion_to_matrix(attitude_at),
        )
        return tuple(values[name] for name in quantities)

    batched = jax.vmap(one)
    chunks = [
        batched(*(jnp.asarray(a[start : start + CHUNK]) for a in pairs)) for start in range(0, len(pairs[0]), CHUNK)
    ]
    return tuple(
        np.concatenate([np.asarray(c[i]) for c in chunks])[:total].reshape((n, k) + chunks[0][i].shape[1:])
        for i in range(len(quantities))
    )
