"""frbjax on an accelerator (GPU): the same motion as on the CPU, and evaluations per second.

Nothing in frbjax depends on an accelerator; this script checks one where there is one.  On the
default JAX device (a GPU if JAX has one) and on the CPU, in float64:

* agreement: quaternion, angular momentum and the gradient of a scalar loss for 1000 random bodies
  (moments in [1, 4]) plus hard ones (next to the separatrix on both sides, nearly symmetric, spin
  near an axis, uniform rotation, L = 0) at 100 times in [-1000, 1000]: the largest difference
  between the two devices (each device's libm rounds differently; the motion is the same to a few
  ulp times the conditioning);
* throughput: ns per quaternion and per angular-momentum evaluation for 1000 bodies times 10^3 to
  10^5 times each, and body construction per body (jit, block_until_ready, best of 5).

    python benchmarks/accelerator_check.py [--output benchmarks/results/accelerator_check.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from frbjax import FreeRigidBody  # noqa: E402


sys.path.insert(0, str(Path(__file__).resolve().parent))
from throughput import (
    best_time as throughput_best_time,  # noqa: E402
    bodies as random_bodies,  # noqa: E402
)


OUTPUT = Path(__file__).resolve().parent / "results" / "accelerator_check.json"


def bodies(rng, n):
    """The throughput benchmark's n random bodies, then the hard ones below."""
    inertia, momentum, attitude = random_bodies(rng, n)
    hard_inertia = np.array(
        [[1.0, 2.0, 3.0]] * 4
        + [[1.0, 1.0 + 1e-12, 3.0], [1.0, 2.0, 3.0], [2.0, 2.0, 2.0], [1.0, 2.0, 3.0], [1.2, 1.2, 2.1], [0.7, 1.9, 1.9]]
    )
    # For I = (1, 2, 3) the separatrix is L3 = sqrt(3) L1: relative 1e-10 off it on both sides, on it
    # (within rounding), then spin near the major axis, a nearly symmetric body, uniform rotation
    # about an axis, a sphere, L = 0, and two symmetric bodies next to the plane of their equal
    # moments (their derivatives are the precession's, frbjax._precession).
    on = 0.5 * np.sqrt(3.0)
    hard_momentum = np.array(
        [
            [0.5, 1.0, on * (1 + 1e-10)],
            [0.5, 1.0, on * (1 - 1e-10)],
            [0.5, 1.0, on],
            [1.0, 1e-9, 1e-9],
            [0.3, 0.4, 0.5],
            [0.0, 1.0, 0.0],
            [0.3, 0.4, 0.5],
            [0.0, 0.0, 0.0],
            [0.6, 0.8, 1e-3],
            [-2e-3, 0.5, 0.9],
        ]
    )
    hard_attitude = np.tile([1.0, 0.0, 0.0, 0.0], (len(hard_inertia), 1))
    return (
        np.concatenate([inertia, hard_inertia]),
        np.concatenate([momentum, hard_momentum]),
        np.concatenate([attitude, hard_attitude]),
    )


def outputs(inertia, momentum, attitude, t):
    body = FreeRigidBody(inertia, momentum, attitude)

    def loss(inertia, momentum):
        return jnp.sum(FreeRigidBody(inertia, momentum, attitude).quaternion(t) ** 2 * jnp.arange(1.0, 5.0))

    gradient = jax.grad(loss, argnums=(0, 1))(inertia, momentum)
    return body.quaternion(t), body.angular_momentum(t), gradient[0], gradient[1]


def best_time(call):
    """Best of the throughput benchmark's repeats, after a warm-up call (compilation) left out."""
    jax.block_until_ready(call())
    return throughput_best_time(call, repeats=5)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output", type=Path, default=OUTPUT)
    options = parser.parse_args()
    device, cpu = jax.devices()[0], jax.devices("cpu")[0]
    print(f"default device: {device} ({device.platform}); jax {jax.__version__}", flush=True)
    rng = np.random.default_rng(0)
    inertia, momentum, attitude = bodies(rng, 1000)
    t = rng.uniform(-1000, 1000, (100, 1))
    results = {}
    for name, where in (("device", device), ("cpu", cpu)):
        args = [jax.device_put(jnp.asarray(a), where) for a in (inertia, momentum, attitude, t)]
        start = time.perf_counter()
        results[name] = [np.asarray(a) for a in jax.jit(outputs)(*args)]
        print(f"  {name}: compiled and ran in {time.perf_counter() - start:.1f} s", flush=True)
    labels = ("quaternion", "angular_momentum", "gradient_inertia", "gradient_momentum")
    agreement = {}
    for label, on_device, on_cpu in zip(labels, results["device"], results["cpu"]):
        scale = max(np.max(np.abs(on_cpu)), 1e-300)
        agreement[label] = dict(
            max_abs_difference=float(np.max(np.abs(on_device - on_cpu))),
            max_relative_to_largest=float(np.max(np.abs(on_device - on_cpu)) / scale),
            finite=bool(np.all(np.isfinite(on_device))),
        )
        print(
            f"  {label}: device - cpu max |difference| {agreement[label]['max_abs_difference']:.2e} "
            f"(relative to the largest value {agreement[label]['max_relative_to_largest']:.2e}), "
            f"finite {agreement[label]['finite']}",
            flush=True,
        )

    body_args = [jnp.asarray(a[:1000]) for a in (inertia, momentum, attitude)]
    construct = jax.jit(lambda i, l, q: FreeRigidBody(i, l, q))
    construction = best_time(lambda: construct(*body_args)) / 1000 * 1e9
    body = construct(*body_args)
    throughput = []
    for times_per_body in (1000, 10_000, 100_000):
        times = jnp.asarray(rng.uniform(0, 100, (times_per_body, 1)))
        row = {"evaluations": 1000 * times_per_body}
        for method in ("quaternion", "angular_momentum"):
            program = jax.jit(lambda b, t, method=method: getattr(b, method)(t))
            row[f"{method}_ns_per_eval"] = best_time(lambda: program(body, times)) / row["evaluations"] * 1e9
        throughput.append(row)
        print(
            f"  {row['evaluations']:>10d} evaluations: quaternion {row['quaternion_ns_per_eval']:.3f} ns/eval, "
            f"angular momentum {row['angular_momentum_ns_per_eval']:.3f} ns/eval",
            flush=True,
        )
    print(f"  construction: {construction:.0f} ns per body (1000 bodies)", flush=True)
    summary = dict(
        device=str(device),
        platform=device.platform,
        jax=jax.__version__,
        host=platform.machine(),
        bodies=len(inertia),
        times=t.shape[0],
        agreement=agreement,
        throughput=throughput,
        construction_ns_per_body=construction,
    )
    options.output.parent.mkdir(parents=True, exist_ok=True)
    options.output.write_text(json.dumps(summary, indent=1) + "\n")
    print(f"wrote {options.output}")


if __name__ == "__main__":
    main()
