"""frbjax.shard_bodies on 4 CPU devices (XLA_FLAGS=--xla_force_host_platform_device_count=4).

The device count is fixed when JAX starts, so the check runs in a subprocess with its own environment:
a batch of 10 bodies (not a multiple of 4: padded to 12) with hard cases among them, each at its own
time, evaluated by the same jitted functions on one device and sharded over 4.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path


ROOT = Path(__file__).resolve().parent.parent

SCRIPT = textwrap.dedent(
    """
    import json
    import math

    import jax
    import jax.numpy as jnp
    import numpy as np

    from frbjax import FreeRigidBody, batch_mesh, shard_batch, shard_bodies

    assert jax.config.jax_enable_x64
    rng = np.random.default_rng(0)
    n = 10
    inertia = rng.uniform(0.5, 3.0, (n, 3))
    momentum = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-2, 2, (n, 1))
    attitude = rng.normal(size=(n, 4))
    inertia[0] = (1.0, 2.0, 3.0); momentum[0] = (0.4769696007084727, 0.3, -0.8261355820929149)  # |d I2 - 1| ~ 1e-16
    inertia[1] = (1.0, 1.0, 3.0)  # symmetric
    inertia[2] = (2.0, 2.0, 2.0)  # sphere
    momentum[3] = (0.0, 0.0, 1.5)  # uniform rotation about a principal axis
    inertia[4] = (1.0, 1.0 + 2.0**-52, 3.0)  # one-ulp gap
    times = rng.uniform(-50, 50, n)

    body = FreeRigidBody(inertia, momentum, attitude)
    sharded = shard_bodies(body)
    t_sharded = shard_batch(jnp.asarray(times))
    quaternion = jax.jit(lambda b, t: b.quaternion(t))
    angular_momentum = jax.jit(lambda b, t: b.angular_momentum(t))
    results = {}
    for name, fn in (("quaternion", quaternion), ("angular_momentum", angular_momentum)):
        one = np.asarray(fn(body, jnp.asarray(times)))
        many = fn(sharded, t_sharded)
        shards = many.addressable_shards
        values = np.asarray(many)[:n]
        scale = np.spacing(np.maximum(np.abs(one), np.finfo(float).tiny))
        results[name] = dict(
            shape=list(many.shape),
            devices=len(many.sharding.device_set),
            replicated=bool(many.sharding.is_fully_replicated),
            shard_shapes=sorted({tuple(s.data.shape) for s in shards}),
            shard_devices=len({s.device for s in shards}),
            shards_match=all(np.array_equal(np.asarray(s.data), np.asarray(many)[s.index]) for s in shards),
            finite=bool(np.all(np.isfinite(values))),
            bit_equal=bool(np.array_equal(values, one)),
            max_ulps=float(np.max(np.abs(values - one) / scale)),
        )
    leaves = jax.tree_util.tree_leaves(sharded)
    results["body"] = dict(
        leaves=len(leaves),
        batch=int(sharded.momentum_norm.shape[0]),
        sharded_leaves=sum(len(leaf.sharding.device_set) == 4 and not leaf.sharding.is_fully_replicated
                           for leaf in leaves),
        devices=len(jax.devices()),
        mesh=list(batch_mesh().axis_names),
    )
    try:
        shard_bodies(body, pad=False)
        results["unpadded_raises"] = False
    except ValueError:
        results["unpadded_raises"] = True
    print("RESULT " + json.dumps(results))
    """
)


def test_sharded_over_4_devices_equals_one_device(tmp_path):
    """One test (one subprocess, ~40 s): sharding, padding and equality with one device.

    Measured: quaternion and angular_momentum bit-equal (0 ulp) to one device for every body, the hard
    cases included; every output and every leaf of the body split 3 + 3 + 3 + 3 over 4 devices.
    """
    script = tmp_path / "sharded.py"
    script.write_text(SCRIPT)
    env = dict(os.environ)
    env.update(XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_ENABLE_X64="1", JAX_PLATFORMS="cpu")
    process = subprocess.run(
        [sys.executable, str(script)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=900
    )
    assert process.returncode == 0, process.stderr[-4000:]
    line = [row for row in process.stdout.splitlines() if row.startswith("RESULT ")][-1]
    results = json.loads(line[len("RESULT ") :])

    body = results["body"]
    assert body["devices"] == 4
    assert body["batch"] == 12  # 10 bodies padded to a multiple of 4
    assert body["sharded_leaves"] == body["leaves"]
    assert results["unpadded_raises"]
    for name in ("quaternion", "angular_momentum"):
        result = results[name]
        assert result["devices"] == 4 and result["shard_devices"] == 4 and not result["replicated"], result
        assert result["shape"][0] == 12
        assert result["shard_shapes"] == [[3, result["shape"][1]]]
        assert result["shards_match"] and result["finite"]
        assert result["bit_equal"], f"{name}: sharded differs from one device by {result['max_ulps']} ulp"
