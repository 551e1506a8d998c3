"""Bodies built from an inertia tensor in their own body frame, against independent references.

The reference integrates the full-tensor equations written in the body frame,

    Omega = T^-1 L (a linear solve at every stage),   dL/dt = L x Omega,   dq/dt = q ⊗ (0, Omega) / 2,

with diffrax's Dopri8 at rtol = atol = 1e-13 (state l = L / |L(0)|, as tests/_reference.py does),
stepping to every output time (``step_ts``): Dopri8's dense output between steps is less accurate
(~1e-11 here) than its steps.
Nothing here uses a formula of frbjax: the tensors are built as R diag(m) R^T from moments m and a
rotation R drawn here (so that a "symmetric" or "spherical" tensor is so only to rounding), the
angular momenta in the principal frame of that construction (to place a body on either side of the
separatrix), and derivatives with respect to the tensor are compared with a 4-point central
difference stencil of the same integration.

Errors are absolute: |L - L_ref| / |L(0)|, |q - q_ref| (the continuous lift, not up to sign),
|R - R_ref| entrywise, |Omega - T^-1 L_ref| / (|L(0)| / lambda_min).  The reference at rtol = 1e-13 is
itself accurate to ~1e-11 (tests/_reference.py: ~1e-10 at tau ~ 50), so the tolerances below
measure the reference; each states the measured worst error (seed SEED) and is ~1.5x that.

The integrations are stored in tests/data/tensor_references.npz (tests/data/make_tensor_references.py
runs this file's ``integrate``, ``integrate_both_ways`` and ``stencil_derivatives``); the tests check
that the stored inputs are still the bodies built here, bit for bit, and integrate a few of them live
(``test_live_diffrax_cross_check``).

Cost: compilation dominates.  The four derivative programs (FreeRigidBody and free_flow, jacfwd and
jacrev, each vmapped over the 19 bodies of ``derivative_bodies``) take 3-8 s each on the CPU, where
the motion's derivatives are the compiled flow kernels' (2026-11-28; 45-105 s each with the JAX rules,
which is why they were in the slow tier); each is compiled once, by the parametrization of
test_derivatives_against_stencil that checks it, with XLA's default options.

Run ``python tests/test_inertia_tensor.py`` to print every measured figure.
"""

from __future__ import annotations

import functools
import os

import _reference as ref
import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from frbjax import free_flow, FreeRigidBody, InertiaTensor


SEED = 20261125
RTOL = ATOL = 1e-13
DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "tensor_references.npz")

# --------------------------------------------------------------------------------------------------
# The reference: diffrax Dopri8 on the full-tensor equations in the body frame.


def _tensor_field(t, y, args):
    tensor, scale = args
    l, q = y[:3], y[3:]
    omega = scale * jnp.linalg.solve(tensor, l)
    dq = 0.5 * ref.hamilton(q, jnp.concatenate([jnp.zeros(1, y.dtype), omega]))
    return jnp.concatenate([jnp.cross(l, omega), dq])


@functools.partial(jax.jit, static_argnames=("rtol", "atol"))
def _integrate(tensor, momentum, attitude, times, rtol, atol):
    def one(tensor, momentum, attitude, times):
        norm = jnp.linalg.norm(momentum)
        scale = jnp.where(norm > 0, norm, 1.0)
        solution = diffrax.diffeqsolve(
            diffrax.ODETerm(_tensor_field),
            diffrax.Dopri8(),
            t0=jnp.zeros_like(times[-1]),
            t1=times[-1],
            dt0=None,
            y0=jnp.concatenate([momentum / scale, attitude]),
            args=(tensor, scale),
            saveat=diffrax.SaveAt(ts=times),
            stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol, step_ts=times),
            max_steps=100_000,
            throw=False,
        )
        return scale * solution.ys[:, :3], solution.ys[:, 3:], solution.result == diffrax.RESULTS.successful

    return jax.vmap(one)(tensor, momentum, attitude, times)


def integrate(tensor, momentum, attitude, times, rtol=RTOL, atol=ATOL):
    """(L, q) (N, K, 3), (N, K, 4) at ``times`` (N, K), each row monotone away from 0."""
    args = [jnp.asarray(np.asarray(a, np.float64)) for a in (tensor, momentum, attitude, times)]
    L, q, ok = _integrate(*args, rtol=rtol, atol=atol)
    assert np.all(np.asarray(ok)), np.flatnonzero(~np.asarray(ok))
    return np.asarray(L), np.asarray(q)


def integrate_both_ways(tensor, momentum, attitude, times):
    """The reference at common ``times`` (K,) that hold negative and positive values (none 0):
    (L (K, N, 3), q (K, N, 4)) as frbjax returns them for times of shape (K, 1)."""
    n = len(tensor)
    negative, positive = times[times < 0][::-1], times[times > 0]
    assert len(negative) == len(positive)
    grid = np.concatenate(
        [np.broadcast_to(negative, (n, len(negative))), np.broadcast_to(positive, (n, len(positive)))]
    )
    L, q = integrate(np.concatenate([tensor] * 2), np.concatenate([momentum] * 2), np.concatenate([attitude] * 2), grid)
    L = np.concatenate([L[:n, ::-1], L[n:]], axis=1)
    q = np.concatenate([q[:n, ::-1], q[n:]], axis=1)
    return np.swapaxes(L, 0, 1), np.swapaxes(q, 0, 1)


# --------------------------------------------------------------------------------------------------
# The stored references (tests/data/make_tensor_references.py).


@functools.cache
def stored(prefix):
    """{name: array} of the stored solutions whose keys start with ``prefix`` ("motion", "derivative")."""
    with np.load(DATA) as data:
        assert float(data["rtol"]) == RTOL and float(data["atol"]) == ATOL and float(data["step"]) == STEP
        return {key[len(prefix) + 1 :]: data[key] for key in data.files if key.startswith(prefix + "_")}


def check_stored_inputs(prefix, **inputs):
    for name, value in inputs.items():
        np.testing.assert_array_equal(
            stored(prefix)[name], value, err_msg=f"{prefix} {name}; rerun tests/data/make_tensor_references.py"
        )


# --------------------------------------------------------------------------------------------------
# Test bodies: T = R diag(m) R^T, L = R l (l given in the principal frame of the construction).


def tilt(rng, degrees=None):
    """A rotation matrix: uniform on SO(3), or by ``degrees`` about a random axis."""
    if degrees is None:
        return Rotation.random(random_state=rng).as_matrix()
    axis = ref.random_directions(rng, 1)[0]
    return Rotation.from_rotvec(np.radians(degrees) * axis).as_matrix()


def tensor_of(moments, rotation):
    """R diag(m) R^T in float64 as numpy rounds it (symmetric to rounding only)."""
    return rotation @ np.diag(moments) @ rotation.T


def separatrix_side(moments, principal_momentum):
    """d I2 - 1 with d = sum(l_i^2 / m_i) / |l|^2 (> 0: rotation about the smallest moment's axis)."""
    l = principal_momentum / np.linalg.norm(principal_momentum)
    return np.sum(l * l / moments) * np.sort(moments)[1] - 1


def build_bodies(seed=SEED):
    """dict name -> (tensor (3, 3), momentum (3,), attitude (4,), moments, rotation); names are families."""
    rng = np.random.default_rng(seed)
    bodies = {}

    def add(name, moments, rotation, principal_momentum):
        moments = np.asarray(moments, float)
        momentum = rotation @ np.asarray(principal_momentum, float)
        bodies[name] = (tensor_of(moments, rotation), momentum, ref.random_attitudes(rng, 1)[0], moments, rotation)

    def generic(side, degrees=None):
        while True:
            moments = np.sort(rng.uniform(1.0, 3.0, 3))
            if min(moments[1] / moments[0], moments[2] / moments[1]) < 1.15:
                continue
            l = ref.random_directions(rng, 1)[0] * rng.uniform(0.5, 2.0)
            g = separatrix_side(moments, l)
            if abs(g) > 0.03 and np.sign(g) == side:
                return moments, tilt(rng, degrees), l

    # Arbitrary tilts (products of inertia as large as the moments' differences), both regimes.
    for k in range(2):
        add(f"tilted_minor_axis_{k}", *generic(+1))
        add(f"tilted_major_axis_{k}", *generic(-1))
    # Principal axes tilted by 3 and 8 degrees: products of inertia of a few percent.
    add("slightly_tilted_minor_axis", *generic(+1, degrees=3.0))
    add("slightly_tilted_major_axis", *generic(-1, degrees=8.0))
    # Within 1e-6 of the separatrix (d I2 - 1 = +-1e-6), both sides.
    for side in (1, -1):
        moments = np.array([1.0, 1.7, 2.6])
        l = ref.separatrix_momentum(moments, side * 1e-6, rng.uniform(-0.8, 0.8))
        add(f"near_separatrix_{'minor' if side > 0 else 'major'}", moments, tilt(rng), l)
    # Nearly axisymmetric: two moments 1e-9 and 1e-6 apart (relative), both pairs.
    for gap in (1e-9, 1e-6):
        add(f"near_axisymmetric_oblate_{gap:.0e}", (1.0, 1.0 + gap, 2.0), tilt(rng), ref.random_directions(rng, 1)[0])
        add(
            f"near_axisymmetric_prolate_{gap:.0e}",
            (1.0, 2.0 * (1 - gap), 2.0),
            tilt(rng),
            ref.random_directions(rng, 1)[0] * 1.3,
        )
    # Exactly axisymmetric moments (I1 = I2 < I3 and I1 < I2 = I3), tilted: symmetric to rounding only.
    add("axisymmetric_oblate", (1.2, 1.2, 2.1), tilt(rng), ref.random_directions(rng, 1)[0] * 0.8)
    add("axisymmetric_prolate", (0.9, 1.6, 1.6), tilt(rng), ref.random_directions(rng, 1)[0] * 1.5)
    add("sphere", (1.4, 1.4, 1.4), tilt(rng), ref.random_directions(rng, 1)[0])
    # Not a physical body: lambda1 + lambda2 < lambda3 (allowed for the motion).
    add("triangle_violating", (1.0, 1.5, 3.2), tilt(rng), ref.random_directions(rng, 1)[0] * 0.7)
    return bodies


def stack(bodies):
    names = list(bodies)
    tensor, momentum, attitude = (np.stack([bodies[n][i] for n in names]) for i in range(3))
    return names, tensor, momentum, attitude


# Common times for the whole batch, both signs: |L| <= 2 so |L| t <= 14.
TIMES = np.array([-7.0, -4.5, -2.0, -0.6, 0.6, 2.0, 4.5, 7.0])


# --------------------------------------------------------------------------------------------------
# Motion: FreeRigidBody at many times and free_flow at one time per body.


@pytest.fixture(scope="module")
def motion():
    names, tensor, momentum, attitude = stack(build_bodies())
    check_stored_inputs("motion", tensor=tensor, momentum=momentum, attitude=attitude, times=TIMES)
    L_ref, q_ref = stored("motion")["L"], stored("motion")["q"]
    body = FreeRigidBody.from_inertia_tensor(tensor, momentum, attitude)
    times = TIMES[:, None]
    values = dict(
        L=np.asarray(body.angular_momentum(times)),
        q=np.asarray(body.quaternion(times)),
        R=np.asarray(body.rotation_matrix(times)),
        omega=np.asarray(body.angular_velocity(times)),
    )
    # free_flow at one time per body: the last positive time for even bodies, the first for odd.
    pick = np.where(np.arange(len(names)) % 2 == 0, len(TIMES) - 1, 0)
    L_flow, q_flow = free_flow(InertiaTensor(tensor), momentum, attitude, TIMES[pick])
    norm = np.linalg.norm(momentum, axis=-1)
    smallest = np.linalg.eigvalsh(tensor)[:, 0]
    omega_ref = np.linalg.solve(tensor, L_ref[..., None])[..., 0]
    errors = dict(
        L=np.abs(values["L"] - L_ref).max(-1) / norm,
        q=np.abs(values["q"] - q_ref).max(-1),
        R=np.abs(values["R"] - ref.matrix_of(q_ref)).max((-1, -2)),
        omega=np.abs(values["omega"] - omega_ref).max(-1) / (norm / smallest),
    )
    columns = np.arange(len(names))
    flow_errors = dict(
        L=np.abs(np.asarray(L_flow) - L_ref[pick, columns]).max(-1) / norm,
        q=np.abs(np.asarray(q_flow) - q_ref[pick, columns]).max(-1),
    )
    return dict(
        names=names,
        tensor=tensor,
        momentum=momentum,
        attitude=attitude,
        body=body,
        values=values,
        L_ref=L_ref,
        q_ref=q_ref,
        errors=errors,
        flow_errors=flow_errors,
        flow=(np.asarray(L_flow), np.asarray(q_flow)),
        pick=pick,
    )


def test_bodies_are_as_intended():
    """Each family is where its name says; the tensors are symmetric only to rounding."""
    bodies = build_bodies()
    for name, (tensor, momentum, _, moments, rotation) in bodies.items():
        principal = rotation.T @ momentum
        side = separatrix_side(moments, principal)
        if "minor" in name:
            assert side > 0, name
        if "major" in name:
            assert side < 0, name
        if name.startswith("near_separatrix"):
            assert 0.5e-6 < abs(side) < 2e-6, name
        if name.startswith("slightly_tilted"):
            products = np.abs(tensor - np.diag(np.diag(tensor))).max() / moments.max()
            assert 0.01 < products < 0.1, (name, products)
    sphere, prolate = bodies["sphere"][0], bodies["axisymmetric_prolate"][0]
    assert np.any(sphere != sphere.T) or np.any(prolate != prolate.T)
    assert np.any(sphere != np.diag(np.diag(sphere)))
    moments = bodies["triangle_violating"][3]
    assert moments[0] + moments[1] < moments[2]


# --------------------------------------------------------------------------------------------------
# Derivatives with respect to the tensor.

# The 6 independent entries; an off-diagonal one is perturbed in T_ij and T_ji together.
ENTRIES = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
DIRECTIONS = np.stack(
    [np.eye(3)[:, [i]] @ np.eye(3)[[j]] + (np.eye(3)[:, [j]] @ np.eye(3)[[i]] if i != j else 0) for i, j in ENTRIES]
)
# 4-point stencil (f(-2h) - 8 f(-h) + 8 f(h) - f(2h)) / (12 h).
STENCIL = np.array([-2.0, -1.0, 1.0, 2.0])
WEIGHTS = np.array([1.0, -8.0, 8.0, -1.0]) / 12.0
STEP = 1e-3

# Checked against the stencil: families of build_bodies, then uniform rotations (L along the smallest
# moment's axis, along an axisymmetric body's symmetry axis, in the plane of its equal moments), whose
# change under a tilt of the tensor is a nutation (the derivative rule of frbjax._uniform); at L = 0
# the exact zero is asserted.
DERIVATIVE_BODIES = (
    "tilted_minor_axis_0",
    "tilted_major_axis_0",
    "slightly_tilted_minor_axis",
    "near_axisymmetric_oblate_1e-09",
    "near_axisymmetric_prolate_1e-09",
    "near_axisymmetric_oblate_1e-06",
    "axisymmetric_oblate",
    "axisymmetric_prolate",
    "sphere",
)
UNIFORM_BODIES = ("principal_axis", "symmetry_axis", "equal_moments_plane")
# L in a principal plane of a tilted tensor: its component across the plane is rounding in value, a
# zero whose tangent the tilt of the axes sets.
# Spins about the smallest and the middle (unstable) axis to unit-|L| times 20 and 40, where the
# nutation's functions of kappa t^2 take their closed forms (|kappa t^2| up to 19 and 9).
LONG_BODIES = ("principal_axis_long", "middle_axis_long")
LONG_TAU = np.array([20.0, 40.0])
# Axisymmetric tensors whose unit L is e . n = 1e-6 and 1e-3 from the plane of the equal moments
# (frbjax._precession).  The motion bends on the scale of 1 there too (only the elliptic parameter
# moves as dT / (e . n)^2): the stencil agreed with the variational equations integrated alongside the
# motion (Dopri8, the same tolerances) to 7e-13 (dL) and 1.7e-12 (dq).
NEAR_PLANE_BODIES = ("near_plane_oblate_1e-06", "near_plane_prolate_1e-03")
STENCIL_BODIES = DERIVATIVE_BODIES + UNIFORM_BODIES + ("principal_plane",) + LONG_BODIES + NEAR_PLANE_BODIES
SPECIAL_BODIES = ("zero_momentum", "zero_momentum_sphere")
# Unit-|L| times of the derivative checks; the sign alternates from body to body.
DERIVATIVE_TAU = np.array([1.5, 4.0])


def derivative_bodies(seed=SEED):
    bodies = build_bodies(seed)
    rows = [bodies[name][:3] for name in DERIVATIVE_BODIES]
    tensor, _, attitude, moments, rotation = bodies["tilted_minor_axis_1"]
    oblate, _, _, oblate_moments, oblate_rotation = bodies["axisymmetric_oblate"]
    rows += [
        (tensor, 1.1 * rotation[:, 0], attitude),
        (oblate, -0.9 * oblate_rotation[:, 2], attitude),
        (oblate, 0.8 * oblate_rotation[:, 0] + 0.6 * oblate_rotation[:, 1], attitude),
        (tensor, 0.66 * rotation[:, 0] + 0.88 * rotation[:, 2], attitude),
        (tensor, 1.1 * rotation[:, 0], attitude),
        (tensor, -rotation[:, 1], attitude),
        (oblate, 0.8 * oblate_rotation @ np.array([0.6, 0.8, 1e-6]), attitude),
    ]
    prolate, _, _, _, prolate_rotation = bodies["axisymmetric_prolate"]
    rows += [
        (prolate, 1.3 * prolate_rotation @ np.array([-1e-3, 0.6, -0.8]), attitude),
        (tensor, np.zeros(3), attitude),
        (bodies["sphere"][0], np.zeros(3), attitude),
    ]
    tensor, momentum, attitude = (np.stack([r[i] for r in rows]) for i in range(3))
    norm = np.linalg.norm(momentum, axis=-1)
    sign = np.where(np.arange(len(rows)) % 2 == 0, 1.0, -1.0)
    tau = np.array([LONG_TAU if name in LONG_BODIES else DERIVATIVE_TAU for name in STENCIL_BODIES + SPECIAL_BODIES])
    times = sign[:, None] * tau / np.where(norm > 0, norm, 1.0)[:, None]
    return STENCIL_BODIES + SPECIAL_BODIES, tensor, momentum, attitude, times


def symmetric_derivative(jacobian):
    """(..., 3, 3) derivatives with respect to T's entries -> (..., 6) along DIRECTIONS."""
    return np.stack([jacobian[..., i, j] + (jacobian[..., j, i] if i != j else 0) for i, j in ENTRIES], -1)


def stencil_derivatives(tensor, momentum, attitude, times, step=STEP):
    """d(L, q)/d(entry) (N, K, 3, 6), (N, K, 4, 6) by the 4-point stencil of the diffrax reference."""
    n, k = times.shape
    points = tensor[:, None, None] + step * STENCIL[:, None, None] * DIRECTIONS[:, None]  # (N, 6, 4, 3, 3)

    def repeat(a):
        return np.broadcast_to(a[:, None, None], (n, 6, 4) + a.shape[1:]).reshape((-1,) + a.shape[1:])

    L, q = integrate(points.reshape(-1, 3, 3), repeat(momentum), repeat(attitude), repeat(times))
    L, q = L.reshape(n, 6, 4, k, 3), q.reshape(n, 6, 4, k, 4)
    dL = np.einsum("nesko,s->nkoe", L, WEIGHTS) / step
    dq = np.einsum("nesko,s->nkoe", q, WEIGHTS) / step
    return dL, dq


def _body_outputs(tensor, momentum, attitude, times):
    body = FreeRigidBody.from_inertia_tensor(tensor, momentum, attitude)
    outputs = (body.angular_momentum(times), body.quaternion(times))
    return outputs, outputs


def _flow_outputs(tensor, momentum, attitude, time):
    outputs = free_flow(InertiaTensor(tensor), momentum, attitude, time)
    return outputs, outputs


# One program each (vmapped over the bodies: also the check that vmap over tensors works).
_PROGRAMS = {
    ("FreeRigidBody", "jacfwd"): jax.vmap(jax.jacfwd(_body_outputs, has_aux=True)),
    ("FreeRigidBody", "jacrev"): jax.vmap(jax.jacrev(_body_outputs, has_aux=True)),
    ("free_flow", "jacfwd"): jax.vmap(jax.jacfwd(_flow_outputs, has_aux=True)),
    ("free_flow", "jacrev"): jax.vmap(jax.jacrev(_flow_outputs, has_aux=True)),
}


def library_derivatives(path, mode, tensor, momentum, attitude, times):
    """((L, q) values, (dL, dq) along DIRECTIONS) from frbjax; free_flow at each body's last time."""
    arguments = [
        jnp.asarray(a) for a in (tensor, momentum, attitude, times if path == "FreeRigidBody" else times[:, -1])
    ]
    (dL, dq), (L, q) = jax.jit(_PROGRAMS[(path, mode)])(*arguments)
    return (np.asarray(L), np.asarray(q)), (symmetric_derivative(np.asarray(dL)), symmetric_derivative(np.asarray(dq)))


@functools.cache
def derivative_reference():
    """The stored values and derivatives at the bodies of ``derivative_bodies``.

    The derivatives are Richardson's (16 D(h/2) - D(h)) / 15 of the stencil at h and h/2: the
    stencil's own error (h^4) is up to 1e-11 at the generic bodies and 8e-6 at the long times;
    Richardson's, against the same from h/2 and h/4, 6.4e-10 at the middle axis at tau = 40
    (derivatives up to 26), 6.3e-11 below."""
    names, tensor, momentum, attitude, times = derivative_bodies()
    check_stored_inputs("derivative", tensor=tensor, momentum=momentum, attitude=attitude, times=times)
    data = stored("derivative")
    return dict(
        names=names,
        inputs=(tensor, momentum, attitude, times),
        values=(data["L"], data["q"]),
        derivatives=(data["dL"], data["dq"]),
    )


def derivative_errors(reference, path, mode):
    """Per body: value errors (L / |L|, q) and derivative errors (dL / |L|, dq), max over times and
    entries, and whether every derivative is finite; frbjax's values from the same program."""
    tensor, momentum, attitude, times = reference["inputs"]
    (L, q), (dL, dq) = library_derivatives(path, mode, tensor, momentum, attitude, times)
    L_ref, q_ref = reference["values"]
    dL_ref, dq_ref = reference["derivatives"]
    if path == "free_flow":
        L_ref, q_ref, dL_ref, dq_ref = L_ref[:, -1], q_ref[:, -1], dL_ref[:, -1], dq_ref[:, -1]
    norm = np.linalg.norm(momentum, axis=-1)
    norm = np.where(norm > 0, norm, 1.0)
    axes = tuple(range(1, L.ndim))
    daxes = tuple(range(1, dL.ndim))
    return dict(
        L=np.abs(L - L_ref).max(axes) / norm,
        q=np.abs(q - q_ref).max(axes),
        dL=np.abs(dL - dL_ref).max(daxes) / norm,
        dq=np.abs(dq - dq_ref).max(daxes),
        finite=np.isfinite(dL).all(daxes) & np.isfinite(dq).all(daxes),
        largest=np.maximum(np.abs(dL).max(daxes), np.abs(dq).max(daxes)),
        raw=(dL, dq),
    )


# Worst derivative errors against the Richardson-extrapolated stencil (STEP = 1e-3 and 1e-3 / 2, seed
# SEED), per body: (dL / |L|, dq), over both paths and both modes, and the tolerance ~1.5x that.  The
# reference's own error (the same extrapolation from h/2 and h/4) is 1e-12 .. 2e-12 in dL and
# 2e-12 .. 4e-11 in dq, 6.4e-10 (dL) at the unstable spin at tau = 40, so most dq figures are the
# reference's; at a gap of 1e-9 (below sqrt(eps): the moments count as equal) frbjax's derivative is
# off by ~1e-8 as documented.
DERIVATIVE_TOLERANCE = {
    "tilted_minor_axis_0": (1e-12, 8e-12),  # measured dL 5.8e-13, dq 5.3e-12
    "tilted_major_axis_0": (2e-12, 1.3e-11),  # measured dL 9.3e-13, dq 7.2e-12
    "slightly_tilted_minor_axis": (4.5e-12, 3e-11),  # measured dL 2.7e-12, dq 1.4e-11
    "near_axisymmetric_oblate_1e-09": (1.4e-8, 4e-9),  # measured dL 9.0e-9, dq 2.5e-9
    "near_axisymmetric_prolate_1e-09": (4e-10, 6e-10),  # measured dL 2.5e-10, dq 4.0e-10
    # measured dL 1.8e-10 (JAX path), 3.16e-10 (compiled kernels), dq 1.2e-10, 1.29e-10: rounding over the
    # gap g = 1e-6 between the two close moments, eps / g = 2.2e-10 (FORWARD_REVERSE_TOLERANCE below)
    "near_axisymmetric_oblate_1e-06": (4e-10, 3.5e-10),
    "axisymmetric_oblate": (1.3e-12, 3.2e-12),  # measured dL 3.6e-13, dq 1.9e-12
    "axisymmetric_prolate": (7e-13, 2.7e-12),  # measured dL 4.8e-13, dq 1.8e-12
    "sphere": (5.5e-13, 1.4e-12),  # measured dL 3.6e-13, dq 9.1e-13
    "principal_axis": (1e-12, 2.9e-12),  # measured dL 6.1e-13, dq 1.9e-12
    "symmetry_axis": (5.5e-13, 4.5e-12),  # measured dL 3.7e-13, dq 3.0e-12
    "equal_moments_plane": (1.3e-12, 2e-12),  # measured dL 6.6e-13, dq 1.3e-12
    "principal_plane": (1.4e-12, 1.6e-11),  # measured dL 9.0e-13, dq 6.6e-12
    "principal_axis_long": (1.8e-12, 6.6e-12),  # measured dL 1.2e-12, dq 4.4e-12
    "middle_axis_long": (1e-9, 1e-10),  # measured dL 6.6e-10, dq 6.5e-11: the reference's own error
    "near_plane_oblate_1e-06": (1e-12, 2.5e-12),  # measured dL 5.1e-13, dq 1.7e-12
    "near_plane_prolate_1e-03": (1e-12, 3.8e-12),  # measured dL 6.7e-13, dq 2.6e-12
}


@functools.cache
def errors_of(key):
    """Errors of one of the four programs, compiled and run once per test session."""
    return derivative_errors(derivative_reference(), *key)


class _Derivatives:
    """The four programs' errors by key, each computed when first asked for: each parametrization of
    test_derivatives_against_stencil pays for its own program's compilation (module docstring), and
    the tests that use all four come after them."""

    def __getitem__(self, key):
        return errors_of(key)

    def items(self):
        return ((key, errors_of(key)) for key in _PROGRAMS)


@pytest.fixture(scope="module")
def derivatives():
    return _Derivatives()


@pytest.mark.parametrize("key", list(_PROGRAMS), ids="-".join)
def test_derivatives_against_stencil(derivatives, key):
    """d(L, q)/dT_ij (T_ij and T_ji together) of FreeRigidBody and free_flow, forward and reverse,
    against the 4-point stencil of the diffrax integration; the values of the same (vmapped) program
    against the integration itself."""
    errors = derivatives[key]
    failures = []
    for k, name in enumerate(STENCIL_BODIES):
        bound_L, bound_q = DERIVATIVE_TOLERANCE[name]
        if not (errors["dL"][k] <= bound_L and errors["dq"][k] <= bound_q):
            failures.append(
                f"{name}: dL {errors['dL'][k]:.2e} (<= {bound_L:.1e}), dq {errors['dq'][k]:.2e} (<= {bound_q:.1e})"
            )
    assert not failures, "\n".join(failures)
    # vmap over tensors: values as in the motion test (measured worst L 8.8e-15, q 5.4e-14).
    assert errors["L"].max() <= 1.5e-14 and errors["q"].max() <= 8e-14


def test_derivatives_finite_everywhere(derivatives):
    """Finite derivatives at every body: sphere, axisymmetric, L = 0, L along a principal axis (the
    smallest moment's; an axisymmetric body's symmetry axis) and in the plane of two equal moments.
    At L = 0 the motion is L(t) = 0, q(t) = q0 for every tensor: the derivatives are 0, to the rounding
    of the turn through the principal frame q0 ⊗ r ⊗ conj(r) that the compiled path differentiates
    (``_body.flow_state``: measured 1.1e-16, 2026-11-28; the JAX rules give exactly 0).  The motion is
    analytic in T and its derivatives are of the size of the others' (the largest, 26, is the growth of
    the unstable spin at tau = 40): a bound of 100 catches a division by a vanishing gap."""
    names = STENCIL_BODIES + SPECIAL_BODIES
    for key, errors in derivatives.items():
        for k, name in enumerate(names):
            assert errors["finite"][k], (key, name)
            assert errors["largest"][k] < 100, (key, name, errors["largest"][k])
            if name.startswith("zero_momentum"):
                assert errors["largest"][k] <= 2 * np.finfo(np.float64).eps, (key, name, errors["largest"][k])


# |jacfwd - jacrev|: rounding, measured worst 1.1e-13, except where a gap g between two moments that
# count as distinct (g > sqrt(eps)) divides: eps / g, measured 1.4e-10 .. 2.6e-10 at g = 1e-6 (it
# moves with the compiled program's rounding).
FORWARD_REVERSE_TOLERANCE = {"near_axisymmetric_oblate_1e-06": 4e-10}


def test_forward_and_reverse_agree(derivatives):
    """jacfwd and jacrev differentiate the same function: they agree to rounding at every body."""
    names = STENCIL_BODIES + SPECIAL_BODIES
    failures = []
    for path in ("FreeRigidBody", "free_flow"):
        forward, reverse = derivatives[(path, "jacfwd")]["raw"], derivatives[(path, "jacrev")]["raw"]
        for k, name in enumerate(names):
            difference = max(np.abs(forward[0][k] - reverse[0][k]).max(), np.abs(forward[1][k] - reverse[1][k]).max())
            if not difference <= FORWARD_REVERSE_TOLERANCE.get(name, 2e-13):
                failures.append(f"{path} {name}: |jacfwd - jacrev| = {difference:.2e}")
    assert not failures, "\n".join(failures)


# --------------------------------------------------------------------------------------------------
# Motion tests.

# Worst errors per family (seed SEED) of FreeRigidBody at TIMES and of free_flow at +-7:
# (L / |L|, q, R, Omega / (|L| / lambda_min), free_flow L / |L|, free_flow q).
MOTION_TOLERANCE = {
    # measured L 1.4e-14, q 7.6e-14, R 1.6e-13, Omega 8.0e-15; free_flow L 8.4e-15, q 7.6e-14
    "tilted": (2e-14, 1.2e-13, 2.5e-13, 1.2e-14, 1.3e-14, 1.2e-13),
    # measured L 1.9e-14, q 6.0e-14, R 1.4e-13, Omega 1.1e-14; free_flow L 7.3e-15, q 6.0e-14
    "near_separatrix": (3e-14, 9e-14, 2e-13, 1.7e-14, 1.1e-14, 9e-14),
    # measured L 1.8e-15, q 4.9e-14, R 1.1e-13, Omega 1.5e-15; free_flow L 1.8e-15, q 4.5e-14
    "near_axisymmetric": (3e-15, 7.5e-14, 1.7e-13, 2.5e-15, 3e-15, 7e-14),
    # measured L 7.4e-16, q 2.1e-14, R 4.9e-14, Omega 1.0e-15; free_flow L 6.2e-16, q 9.9e-15
    "axisymmetric": (1.2e-15, 3.2e-14, 7.5e-14, 1.5e-15, 1e-15, 1.5e-14),
    # measured L 2.2e-16, q 8.1e-15, R 1.9e-14, Omega 2.1e-16; free_flow L 1.9e-16, q 8.1e-15
    "sphere": (4e-16, 1.2e-14, 3e-14, 4e-16, 3e-16, 1.2e-14),
    # measured L 1.6e-14, q 2.5e-14, R 6.7e-14, Omega 1.1e-14; free_flow L 1.5e-14, q 2.5e-14
    "triangle_violating": (2.5e-14, 4e-14, 1e-13, 1.7e-14, 2.3e-14, 4e-14),
}


def family_of(name):
    for family in ("near_separatrix", "near_axisymmetric", "axisymmetric", "sphere", "triangle_violating"):
        if name.startswith(family):
            return family
    assert "tilted" in name, name
    return "tilted"


def test_motion_against_diffrax(motion):
    """FreeRigidBody.from_inertia_tensor at 8 common times of both signs (times (K, 1): (K, N, ...)
    outputs) and free_flow at one time per body, against the diffrax integration."""
    assert motion["values"]["L"].shape == (len(TIMES), len(motion["names"]), 3)
    assert motion["values"]["R"].shape == (len(TIMES), len(motion["names"]), 3, 3)
    errors, flow = motion["errors"], motion["flow_errors"]
    failures = []
    for k, name in enumerate(motion["names"]):
        measured = (
            errors["L"][:, k].max(),
            errors["q"][:, k].max(),
            errors["R"][:, k].max(),
            errors["omega"][:, k].max(),
            flow["L"][k],
            flow["q"][k],
        )
        for label, value, bound in zip(
            ("L", "q", "R", "Omega", "free_flow L", "free_flow q"), measured, MOTION_TOLERANCE[family_of(name)]
        ):
            if not value <= bound:
                failures.append(f"{name}: {label} error {value:.2e} > {bound:.1e}")
    assert not failures, "\n".join(failures)


def test_inertia_tensor_fields(motion):
    """principal_moments ascending, principal_axes a rotation with T = R diag(lambda) R^T, and
    InertiaTensor.angular_velocity(L) = T^-1 L (numpy's eigvalsh and solve)."""
    tensor, momentum = motion["tensor"], motion["momentum"]
    inertia = InertiaTensor(tensor)
    moments, axes = np.asarray(inertia.principal_moments), np.asarray(inertia.principal_axes)
    assert np.all(np.diff(moments, axis=-1) >= 0)
    np.testing.assert_allclose(moments, np.linalg.eigvalsh(tensor), rtol=0, atol=3.5e-15)  # measured 2.2e-15
    np.testing.assert_allclose(np.linalg.det(axes), 1.0, rtol=0, atol=2.5e-15)  # measured 1.1e-15
    rebuilt = np.einsum("nij,nj,nkj->nik", axes, moments, axes)
    assert np.abs(rebuilt - tensor).max() <= 4.5e-15  # measured 3.1e-15
    omega = np.asarray(inertia.angular_velocity(momentum))
    np.testing.assert_allclose(
        omega, np.linalg.solve(tensor, momentum[..., None])[..., 0], rtol=0, atol=1e-15
    )  # measured 5.6e-16
    body = motion["body"]
    assert body.inertia_tensor is not None and body.inertia.shape == (len(tensor), 3)


# --------------------------------------------------------------------------------------------------
# Bad input.

GOOD = np.array([[2.0, 0.1, -0.2], [0.1, 1.5, 0.05], [-0.2, 0.05, 1.0]])
BAD = {
    "not symmetric": GOOD + np.array([[0, 1e-3, 0], [0, 0, 0], [0, 0, 0]]),
    "indefinite": np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
    "singular": np.diag([1.0, 0.0, 2.0]),
    "negative": -GOOD,
    "nan": np.where(np.eye(3, dtype=bool), GOOD, np.nan),
    "inf": GOOD + np.diag([np.inf, 0, 0]),
}


@pytest.mark.parametrize("kind", list(BAD))
def test_bad_tensor_raises_eagerly(kind):
    momentum, attitude = np.array([0.3, -0.2, 0.9]), np.array([1.0, 0, 0, 0])
    # Each message names the argument: InertiaTensor(matrix), from_inertia_tensor(inertia_tensor, ...).
    for argument, build in (
        ("matrix", lambda T: InertiaTensor(T)),
        ("inertia_tensor", lambda T: FreeRigidBody.from_inertia_tensor(T, momentum)),
        ("matrix", lambda T: free_flow(InertiaTensor(T), momentum, attitude, 1.0)),
    ):
        with pytest.raises(ValueError, match=argument):
            build(BAD[kind])


@pytest.mark.parametrize("shape", [(3,), (3, 4), (2, 2), (4, 4), (2, 3, 2)])
def test_wrong_shape_raises(shape):
    with pytest.raises(ValueError, match="matrix"):
        InertiaTensor(np.ones(shape))
    with pytest.raises(ValueError, match="inertia_tensor"):
        jax.jit(lambda T: FreeRigidBody.from_inertia_tensor(T, jnp.ones(3)).quaternion(1.0))(jnp.ones(shape))


def test_bad_tensor_under_jit_gives_nan():
    """Under jit every output of a body built from an invalid tensor is NaN; the valid body in the
    same batch is unaffected (against the eager evaluation of it alone)."""
    tensor = np.stack([GOOD] + list(BAD.values()))
    n = len(tensor)
    momentum = np.broadcast_to([0.3, -0.2, 0.9], (n, 3))
    attitude = np.broadcast_to([0.5, 0.5, -0.5, 0.5], (n, 4))

    @jax.jit
    def outputs(tensor, momentum, attitude):
        body = FreeRigidBody.from_inertia_tensor(tensor, momentum, attitude)
        flow = free_flow(InertiaTensor(tensor), momentum, attitude, jnp.full(n, 2.5))
        return (
            body.angular_momentum(2.5),
            body.quaternion(2.5),
            body.angular_velocity(2.5),
            body.rotation_matrix(2.5),
        ) + flow

    values = [np.asarray(v) for v in outputs(tensor, momentum, attitude)]
    for value in values:
        assert np.all(np.isfinite(value[0]))
        assert np.all(np.isnan(value[1:])), value
    L_ref, q_ref = integrate(GOOD[None], momentum[:1], attitude[:1], np.array([[1.0, 2.5]]))
    np.testing.assert_allclose(values[0][0], L_ref[0, -1], rtol=0, atol=1e-14)
    np.testing.assert_allclose(values[1][0], q_ref[0, -1], rtol=0, atol=1e-13)
    np.testing.assert_allclose(values[4][0], L_ref[0, -1], rtol=0, atol=1e-14)


def test_three_by_three_moments_stay_a_batch():
    """A (3, 3) array passed as ``inertia`` is three bodies' principal moments, as before the tensor
    entry point; one with negative entries (a tensor's products) is refused as moments."""
    moments = np.array([[1.0, 2.0, 3.0], [2.0, 1.5, 0.5], [3.0, 0.5, 2.0]])
    momentum = np.array([0.3, -0.7, 0.5])
    body = FreeRigidBody(moments, momentum)
    assert body.inertia_tensor is None and body.inertia.shape == (3, 3)
    L = np.asarray(body.angular_momentum(np.array([2.0, 3.0])[:, None]))
    assert L.shape == (2, 3, 3)
    # The reference with diagonal tensors: the three bodies' principal moments (measured 2.5e-14).
    L_ref, _ = integrate(
        np.stack([np.diag(row) for row in moments]),
        np.broadcast_to(momentum, (3, 3)),
        np.broadcast_to([1.0, 0, 0, 0], (3, 4)),
        np.tile([2.0, 3.0], (3, 1)),
    )
    np.testing.assert_allclose(L, np.swapaxes(L_ref, 0, 1), rtol=0, atol=4e-14)
    with pytest.raises(ValueError, match="inertia"):
        FreeRigidBody(GOOD, momentum)


def test_triangle_inequality_not_required(motion):
    """lambda1 + lambda2 < lambda3 builds eagerly (no error) and moves as diffrax says (in
    test_motion_against_diffrax)."""
    k = motion["names"].index("triangle_violating")
    moments = np.asarray(InertiaTensor(motion["tensor"][k]).principal_moments)
    assert moments[0] + moments[1] < moments[2]
    assert np.all(np.isfinite(motion["values"]["q"][:, k]))


def test_live_diffrax_cross_check():
    """The generator's integration, run live at the stored tolerance on three stored bodies of the
    derivative checks (a tilted one, the unstable spin to tau = 40, a symmetric one next to the plane of
    its equal moments), reproduces the stored values: measured identical to the last bit; the bound
    allows a few ulp of another machine's rounding."""
    reference = derivative_reference()
    rows = [
        reference["names"].index(name)
        for name in ("tilted_minor_axis_0", "middle_axis_long", "near_plane_oblate_1e-06")
    ]
    tensor, momentum, attitude, times = (a[rows] for a in reference["inputs"])
    L, q = integrate(tensor, momentum, attitude, times)
    L_stored, q_stored = (a[rows] for a in reference["values"])
    assert np.abs(L - L_stored).max() <= 1e-14 and np.abs(q - q_stored).max() <= 1e-14


# --------------------------------------------------------------------------------------------------
# float32.


def test_float32_agrees_with_float64(motion):
    """The same bodies with float32 inputs (rounded) give float32 results within float32 accuracy of
    the float64 evaluation of the rounded inputs, |L| t <= 14: measured worst L 3.5e-6 (relative to
    |L|), q 1.4e-6, both at the 1e-6-gap oblate body (8 float32 ulp: equal to float32's rounding);
    elsewhere L <= 2.5e-6, q <= 1.2e-6."""
    tensor, momentum, attitude = (
        a.astype(np.float32) for a in (motion["tensor"], motion["momentum"], motion["attitude"])
    )
    times = TIMES[:, None].astype(np.float32)
    body32 = FreeRigidBody.from_inertia_tensor(tensor, momentum, attitude)
    body64 = FreeRigidBody.from_inertia_tensor(*(a.astype(np.float64) for a in (tensor, momentum, attitude)))
    L32, q32 = body32.angular_momentum(times), body32.quaternion(times)
    assert L32.dtype == q32.dtype == np.float32
    L64, q64 = body64.angular_momentum(times.astype(np.float64)), body64.quaternion(times.astype(np.float64))
    norm = np.linalg.norm(motion["momentum"], axis=-1)
    error_L = (np.abs(np.asarray(L32, np.float64) - np.asarray(L64)).max(-1) / norm).max()
    error_q = np.abs(np.asarray(q32, np.float64) - np.asarray(q64)).max()
    assert error_L <= FLOAT32_TOLERANCE[0] and error_q <= FLOAT32_TOLERANCE[1], (error_L, error_q)


FLOAT32_TOLERANCE = (5e-6, 2e-6)


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)  # as tests/conftest.py does
    result = motion.__wrapped__()
    for k, name in enumerate(result["names"]):
        e, f = result["errors"], result["flow_errors"]
        print(
            f"{name:34s} L {e['L'][:, k].max():.1e} q {e['q'][:, k].max():.1e} R {e['R'][:, k].max():.1e} "
            f"Omega {e['omega'][:, k].max():.1e} | free_flow L {f['L'][k]:.1e} q {f['q'][k]:.1e}"
        )
    reference = derivative_reference()
    names = reference["names"]
    for key in _PROGRAMS:
        errors = derivative_errors(reference, *key)
        print(*key)
        for k, name in enumerate(names):
            print(
                f"  {name:32s} L {errors['L'][k]:.1e} q {errors['q'][k]:.1e} dL {errors['dL'][k]:.1e} "
                f"dq {errors['dq'][k]:.1e} largest {errors['largest'][k]:.2g}"
            )
