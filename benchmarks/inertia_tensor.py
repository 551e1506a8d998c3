"""Bodies built from an inertia tensor: cost against principal moments, accuracy against diffrax, Orekit.

Rows (float64, one core: the process pins itself to one CPU and runs XLA single-threaded):

* ``cost``: the same bodies built from a tilted inertia tensor (``FreeRigidBody.from_inertia_tensor``)
  and from their principal moments (``FreeRigidBody(moments, R^T L, q ⊗ q(R))``, the same motion
  described in the principal frame), evaluated with ``quaternion`` and ``angular_momentum`` at
  N bodies x K times (times (K, 1)) and at one scalar time for the batch.  The two are timed
  interleaved (tensor, moments, tensor, ...), ``--repeats`` pairs, each the best of a few calls; the
  row reports the median ratio tensor / moments (target <= 1.05).
* ``accuracy``: many seeded tilted tensors (half with arbitrary principal axes, half tilted by up to
  20 degrees; moments in [0.5, 3], a quarter of them nearly or exactly axisymmetric) against diffrax
  Dopri8 at rtol = atol = 1e-13 on the full-tensor equations in the body frame
  (tests/test_inertia_tensor.py's reference), |L| t up to 20, both signs of t: worst and median errors
  of L / |L| and q, through FreeRigidBody and free_flow.
* ``orekit``: Orekit's ``TorqueFree`` attitude provider (``orekit-jpype``, a JVM) on the same tilted
  body: its error against the diffrax reference and its time per evaluation (one ``getAttitude``
  call from Python), next to frbjax's per-evaluation time for one body at one time (``free_flow``)
  and per body-time in a batch.  Skipped (and recorded as skipped, with how to install it) when
  ``import orekit_jpype`` fails or with ``--no-orekit``:
  ``pip install orekit-jpype`` and a JDK (Debian: ``apt-get install -y default-jdk-headless``).

Usage: python benchmarks/inertia_tensor.py [--quick] [--no-orekit] [--output-dir DIR]
Writes inertia_tensor.json into benchmarks/results/ (or --output-dir).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path


# One core: the first allowed CPU (``taskset -c N python benchmarks/inertia_tensor.py`` picks N).
if hasattr(os, "sched_setaffinity"):
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")

import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402


HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "tests"))
import _reference as ref  # noqa: E402
from test_inertia_tensor import integrate  # noqa: E402  (the diffrax full-tensor reference)

from frbjax import free_flow, FreeRigidBody, InertiaTensor  # noqa: E402


SEED = 22
TARGET_RATIO = 1.05


def tilted_bodies(count, rng, axisymmetric_fraction=0.25):
    """(tensor (N, 3, 3), L (N, 3), q (N, 4), moments (N, 3), rotation (N, 3, 3))."""
    moments = np.sort(rng.uniform(0.5, 3.0, (count, 3)), axis=-1)
    special = rng.random(count) < axisymmetric_fraction
    kind = rng.integers(0, 4, count)
    gap = np.where(kind == 0, 0.0, np.where(kind == 1, 1e-9, 1e-6))
    # Oblate-like (I1 ~ I2) for even bodies, prolate-like (I2 ~ I3) for odd ones.
    oblate = np.arange(count) % 2 == 0
    moments[:, 1] = np.where(special & oblate, moments[:, 0] * (1 + gap), moments[:, 1])
    moments[:, 1] = np.where(special & ~oblate, moments[:, 2] * (1 - gap), moments[:, 1])
    moments[:, :] = np.where((special & (kind == 3))[:, None], moments[:, :1], moments)  # spheres
    arbitrary = Rotation.random(count, random_state=rng).as_matrix()
    axis = ref.random_directions(rng, count)
    small = Rotation.from_rotvec(np.radians(rng.uniform(0, 20, count))[:, None] * axis).as_matrix()
    rotation = np.where((np.arange(count) % 4 < 2)[:, None, None], arbitrary, small)
    tensor = np.einsum("nij,nj,nkj->nik", rotation, moments, rotation)
    momentum = ref.random_directions(rng, count) * rng.uniform(0.5, 2.0, (count, 1))
    attitude = ref.random_attitudes(rng, count)
    return tensor, momentum, attitude, moments, rotation


def principal_description(momentum, attitude, rotation):
    """The same motion in the principal frame: L_p = R^T L, q_p = q ⊗ q(R)."""
    x, y, z, w = Rotation.from_matrix(rotation).as_quat().T
    return np.einsum("nji,nj->ni", rotation, momentum), ref.hamilton(attitude, np.stack([w, x, y, z], -1))


def _best(function, calls):
    best = np.inf
    for _ in range(calls):
        start = time.perf_counter()
        jax.block_until_ready(function())
        best = min(best, time.perf_counter() - start)
    return best


def cost_row(bodies, times_count, repeats, calls):
    rng = np.random.default_rng(SEED)
    tensor, momentum, attitude, moments, rotation = tilted_bodies(bodies, rng)
    momentum_p, attitude_p = principal_description(momentum, attitude, rotation)
    from_tensor = FreeRigidBody.from_inertia_tensor(tensor, momentum, attitude)
    from_moments = FreeRigidBody(moments, momentum_p, attitude_p)
    times = jnp.asarray(np.linspace(-20.0, 20.0, times_count)[:, None])
    scalar = jnp.asarray(3.7)
    row = dict(bodies=bodies, times=times_count, repeats=repeats, calls_per_timing=calls)
    for label, t in (("times_axis", times), ("scalar_time", scalar)):
        for method in ("quaternion", "angular_momentum"):
            tensor_call = lambda: getattr(from_tensor, method)(t)  # noqa: E731
            moments_call = lambda: getattr(from_moments, method)(t)  # noqa: E731
            jax.block_until_ready((tensor_call(), moments_call()))  # compile both
            ratios, tensor_times, moments_times = [], [], []
            for _ in range(repeats):
                a, b = _best(tensor_call, calls), _best(moments_call, calls)
                tensor_times.append(a)
                moments_times.append(b)
                ratios.append(a / b)
            row[f"{label}_{method}"] = dict(
                ratio_median=statistics.median(ratios),
                ratio_min=min(ratios),
                ratio_max=max(ratios),
                tensor_seconds_median=statistics.median(tensor_times),
                moments_seconds_median=statistics.median(moments_times),
            )
    # The same motion: outputs agree after the change of frame (a check that the comparison is fair).
    q_t, q_m = np.asarray(from_tensor.quaternion(times)), np.asarray(from_moments.quaternion(times))
    x, y, z, w = Rotation.from_matrix(rotation).as_quat().T
    back = ref.hamilton(q_m, np.stack([w, -x, -y, -z], -1))
    row["same_motion_max_difference_q"] = float(np.abs(q_t - back).max())
    ratios = [row[k]["ratio_median"] for k in row if isinstance(row[k], dict)]
    row["worst_median_ratio"] = max(ratios)
    row["target"] = TARGET_RATIO
    row["met"] = bool(row["worst_median_ratio"] <= TARGET_RATIO)
    return row


def accuracy_row(bodies, times_count):
    rng = np.random.default_rng(SEED + 1)
    tensor, momentum, attitude, moments, _ = tilted_bodies(bodies, rng)
    norm = np.linalg.norm(momentum, axis=-1)
    sign = np.where(np.arange(bodies) % 2 == 0, 1.0, -1.0)
    times = sign[:, None] * np.linspace(20.0 / times_count, 20.0, times_count) / norm[:, None]
    start = time.perf_counter()
    L_ref, q_ref = integrate(tensor, momentum, attitude, times)
    reference_seconds = time.perf_counter() - start
    body = FreeRigidBody.from_inertia_tensor(tensor, momentum, attitude)
    L = np.swapaxes(np.asarray(body.angular_momentum(times.T)), 0, 1)
    q = np.swapaxes(np.asarray(body.quaternion(times.T)), 0, 1)
    L_flow, q_flow = (np.asarray(v) for v in free_flow(InertiaTensor(tensor), momentum, attitude, times[:, -1]))
    error_L = np.abs(L - L_ref).max((1, 2)) / norm
    error_q = np.abs(q - q_ref).max((1, 2))
    flow_L = np.abs(L_flow - L_ref[:, -1]).max(-1) / norm
    flow_q = np.abs(q_flow - q_ref[:, -1]).max(-1)
    gaps = np.minimum(moments[:, 1] - moments[:, 0], moments[:, 2] - moments[:, 1]) / moments[:, 2]
    worst = int(np.argmax(np.maximum(error_L, error_q)))
    return dict(
        bodies=bodies,
        times_per_body=times_count,
        max_abs_tau=20.0,
        reference="diffrax Dopri8 rtol=atol=1e-13",
        reference_seconds=reference_seconds,
        axisymmetric_or_sphere=int(np.sum(gaps < 1e-5)),
        FreeRigidBody=dict(
            max_L=float(error_L.max()),
            max_q=float(error_q.max()),
            median_L=float(np.median(error_L)),
            median_q=float(np.median(error_q)),
        ),
        free_flow=dict(
            max_L=float(flow_L.max()),
            max_q=float(flow_q.max()),
            median_L=float(np.median(flow_L)),
            median_q=float(np.median(flow_q)),
        ),
        worst_body=dict(
            tensor=tensor[worst].tolist(),
            angular_momentum=momentum[worst].tolist(),
            attitude=attitude[worst].tolist(),
            moments=moments[worst].tolist(),
        ),
    )


def orekit_row(quick):
    """Orekit TorqueFree on one tilted body: error against diffrax and time per getAttitude."""
    how = (
        "pip install orekit-jpype (with a JDK: apt-get install -y default-jdk-headless), then rerun without --no-orekit"
    )
    try:
        import orekit_jpype
    except ImportError as error:
        return dict(skipped=True, reason=f"import orekit_jpype failed: {error}", how=how)
    orekit_jpype.initVM()  # TAI and GCRF need no orekit-data
    from org.hipparchus.geometry.euclidean.threed import Rotation as JRotation, Vector3D
    from org.orekit.attitudes import Attitude, Inertia, InertiaAxis, TorqueFree
    from org.orekit.frames import FramesFactory
    from org.orekit.time import AbsoluteDate, TimeScalesFactory
    from org.orekit.utils import AngularCoordinates

    rng = np.random.default_rng(SEED + 2)
    tensor, momentum, attitude, moments, rotation = (a[0] for a in tilted_bodies(1, rng, 0.0))
    count = 20 if quick else 200
    times = np.linspace(0.5, 20.0, count) / np.linalg.norm(momentum)
    L_ref, q_ref = integrate(tensor[None], momentum[None], attitude[None], times[None])
    L_ref, q_ref = L_ref[0], q_ref[0]

    tai = TimeScalesFactory.getTAI()
    epoch = AbsoluteDate(2026, 1, 1, 0, 0, 0.0, tai)
    frame = FramesFactory.getGCRF()
    # Orekit's attitude maps reference (space) frame vectors to satellite (body) frame ones, v_body =
    # conj(q) v_space q for frbjax's body-to-space q; Hipparchus' Rotation(q0, q1, q2, q3).applyTo(u)
    # is conj(q) u q (its "frame transform" convention): the same four numbers.
    w, x, y, z = attitude
    space_to_body = JRotation(float(w), float(x), float(y), float(z), True)
    omega = np.linalg.solve(tensor, momentum)
    initial = Attitude(epoch, frame, AngularCoordinates(space_to_body, Vector3D(*map(float, omega))))
    axes = [InertiaAxis(float(moments[k]), Vector3D(*map(float, rotation[:, k]))) for k in range(3)]
    provider = TorqueFree(initial, Inertia(*axes))
    errors_q, errors_L = [], []
    start = time.perf_counter()
    results = [provider.getAttitude(None, epoch.shiftedBy(float(t)), frame) for t in times]
    seconds = (time.perf_counter() - start) / count
    for k, result in enumerate(results):
        r = result.getRotation()
        q = np.array([r.getQ0(), r.getQ1(), r.getQ2(), r.getQ3()])  # body to space
        q = q if np.dot(q, q_ref[k]) >= 0 else -q
        spin = result.getSpin()
        L = tensor @ np.array([spin.getX(), spin.getY(), spin.getZ()])
        errors_q.append(np.abs(q - q_ref[k]).max())
        errors_L.append(np.abs(L - L_ref[k]).max() / np.linalg.norm(momentum))
    one = jax.jit(lambda T, L, q, t: free_flow(InertiaTensor(T), L, q, t))
    args = [jnp.asarray(a) for a in (tensor, momentum, attitude, times[-1])]
    jax.block_until_ready(one(*args))
    frbjax_seconds = _best(lambda: one(*args), 200)
    L_f, q_f = (np.asarray(v) for v in one(*args))
    return dict(
        skipped=False,
        orekit_version=getattr(orekit_jpype, "__version__", "unknown"),
        evaluations=count,
        max_abs_tau=20.0,
        orekit_max_error_q=float(max(errors_q)),
        orekit_max_error_L=float(max(errors_L)),
        orekit_seconds_per_evaluation=seconds,
        frbjax_free_flow_seconds_one_body_one_time=frbjax_seconds,
        frbjax_free_flow_error_q_at_last_time=float(np.abs(q_f - q_ref[-1]).max()),
        frbjax_free_flow_error_L_at_last_time=float(np.abs(L_f - L_ref[-1]).max() / np.linalg.norm(momentum)),
        note="quaternions compared up to sign (Orekit's rotation is not a continuous lift)",
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="tiny sizes (a smoke run)")
    parser.add_argument("--no-orekit", action="store_true")
    parser.add_argument(
        "--cost-only",
        action="store_true",
        help="measure the cost row again and keep the other rows of the existing JSON",
    )
    parser.add_argument("--output-dir", type=Path, default=HERE / "results")
    args = parser.parse_args()
    if args.quick:
        sizes = dict(bodies=64, times=16, repeats=3, calls=2, sweep=16, sweep_times=4)
    else:
        sizes = dict(bodies=4096, times=256, repeats=15, calls=3, sweep=1024, sweep_times=16)
    result = dict(
        machine=dict(
            platform=platform.platform(),
            processor=platform.processor(),
            jax=jax.__version__,
            backend=jax.default_backend(),
            cpus=sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        ),
        quick=args.quick,
    )
    start = time.perf_counter()
    if args.cost_only:
        path = args.output_dir / "inertia_tensor.json"
        result = json.loads(path.read_text())
        result["cost"] = cost_row(sizes["bodies"], sizes["times"], sizes["repeats"], sizes["calls"])
        print("cost", json.dumps(result["cost"], indent=1), flush=True)
        path.write_text(json.dumps(result, indent=2) + "\n")
        return
    result["cost"] = cost_row(sizes["bodies"], sizes["times"], sizes["repeats"], sizes["calls"])
    print("cost", json.dumps(result["cost"], indent=1), flush=True)
    result["accuracy"] = accuracy_row(sizes["sweep"], sizes["sweep_times"])
    print("accuracy", json.dumps(result["accuracy"], indent=1), flush=True)
    if args.no_orekit:
        result["orekit"] = dict(
            skipped=True,
            reason="--no-orekit",
            how="pip install orekit-jpype and a JDK (apt-get install -y default-jdk-headless)",
        )
    else:
        result["orekit"] = orekit_row(args.quick)
    print("orekit", json.dumps(result["orekit"], indent=1), flush=True)
    result["seconds"] = time.perf_counter() - start
    args.output_dir.mkdir(parents=True, exist_ok=True)
    (args.output_dir / "inertia_tensor.json").write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
