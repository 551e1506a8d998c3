"""Fuzz FreeRigidBody: N random bodies, no NaN, the invariants of the exact motion.

Bodies: two thirds generic (moments in [0.3, 3] in any order, random L direction and attitude), one
third degenerate or nearly degenerate (I1 = I2, I2 = I3, spheres, relative gaps from 1 ulp to 1e-3,
spin about a principal axis, L near the middle axis, L near the separatrix); |L| from 1e-3 to 1e3
(log-uniform); each body at TIMES times with |t| up to 1e3 (log-uniform in [1e-3, 1e3], random sign).
Evaluated jit-compiled in chunks of a fixed size (one compilation).  Checks: no NaN or inf; |q| = 1;
|L|, the energy and the spatial angular momentum R(t) L(t) conserved (relative to |L| or the energy).

Usage: python benchmarks/fuzz.py [--n 200000] [--seed 0] [--chunk 8192] [--output PATH]
Writes the worst values as JSON to benchmarks/results/fuzz.json (or --output).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np


DEFAULT_OUTPUT = Path(__file__).resolve().parent / "results" / "fuzz.json"
TIMES = 4
FAMILIES = (
    "generic",
    "symmetric",
    "sphere",
    "near_symmetric",
    "near_sphere",
    "principal_axis",
    "near_middle_axis",
    "near_separatrix",
)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def random_bodies(rng, n):
    """(inertia, momentum, attitude, times, family index) for n bodies (numpy float64)."""
    family = np.where(rng.random(n) < 2 / 3, 0, rng.integers(1, len(FAMILIES), n))
    inertia = np.sort(rng.uniform(0.3, 3.0, (n, 3)), axis=-1)
    a, c = inertia[:, 0].copy(), inertia[:, 2].copy()
    gap = rng.choice([np.finfo(float).eps, 4e-16, 1e-12, 1e-9, 1e-6, 1e-3], n)
    lower = rng.random(n) < 0.5
    direction = _unit(rng.normal(size=(n, 3)))
    momentum = direction.copy()

    sym = family == 1
    inertia[sym] = np.where(lower[sym, None], np.stack([a, a, c], -1)[sym], np.stack([a, c, c], -1)[sym])
    inertia[family == 2] = a[family == 2, None]
    near = family == 3
    inertia[near] = np.where(
        lower[near, None], np.stack([a, a * (1 + gap), c], -1)[near], np.stack([a, c, c * (1 + gap)], -1)[near]
    )
    sph = family == 4
    inertia[sph] = np.stack([a, a * (1 + gap), a * (1 + 2 * gap)], -1)[sph]
    axis = family == 5
    momentum[axis] = np.eye(3)[rng.integers(0, 3, n)][axis] * rng.choice([-1.0, 1.0], (n, 1))[axis]
    mid = family == 6
    offset = 10.0 ** rng.uniform(-12, -3, n)
    middle = np.array([0.0, 1.0, 0.0]) * rng.choice([-1.0, 1.0], (n, 1))
    momentum[mid] = _unit(middle + offset[:, None] * direction)[mid]
    # Near the separatrix: d I2 - 1 = h with |h| in [1e-12, 1e-4] (to rounding), moments spread apart.
    sep = family == 7
    inertia[sep] = np.stack([a, a * rng.uniform(1.2, 2.0, n), a * rng.uniform(2.2, 3.0, n)], -1)[sep]
    j1, j2, j3 = inertia[:, 0], inertia[:, 1], inertia[:, 2]
    h = rng.choice([-1.0, 1.0], n) * 10.0 ** rng.uniform(-12, -4, n)
    l2 = rng.uniform(-0.9, 0.9, n)
    ga, gb = (j2 - j1) / j1, (j3 - j2) / j3
    ga, gb = np.where(sep, ga, 1.0), np.where(sep, gb, 1.0)  # (other rows: unused, avoid 0 / 0)
    rest = 1 - l2 * l2
    l1 = np.sqrt(np.maximum((rest * gb + h) / (ga + gb), 0))
    l3 = np.sqrt(np.maximum((rest * ga - h) / (ga + gb), 0))
    signs = rng.choice([-1.0, 1.0], (n, 3))
    momentum[sep] = (signs * np.stack([l1, l2, l3], -1))[sep]

    # The moments in a random order (the same permutation for I and L).
    order = np.argsort(rng.random((n, 3)), axis=-1)
    inertia = np.take_along_axis(inertia, order, -1)
    momentum = np.take_along_axis(momentum, order, -1) * 10.0 ** rng.uniform(-3, 3, (n, 1))
    attitude = _unit(rng.normal(size=(n, 4)))
    times = 10.0 ** rng.uniform(-3, 3, (n, TIMES)) * rng.choice([-1.0, 1.0], (n, TIMES))
    return inertia, momentum, attitude, times, family


@jax.jit
def _evaluate(inertia, momentum, attitude, times):
    from frbjax import FreeRigidBody

    body = FreeRigidBody(inertia[:, None], momentum[:, None], attitude[:, None])
    L, q, R = body.angular_momentum(times), body.quaternion(times), body.rotation_matrix(times)
    norm = jnp.linalg.norm(momentum, axis=-1)[:, None]
    energy = 0.5 * jnp.sum(momentum**2 / inertia, -1)[:, None]
    initial = FreeRigidBody(inertia, momentum, attitude).rotation_matrix(0.0)
    spatial0 = jnp.einsum("nij,nj->ni", initial, momentum)
    finite = (
        jnp.all(jnp.isfinite(L), (-1, -2)) & jnp.all(jnp.isfinite(q), (-1, -2)) & jnp.all(jnp.isfinite(R), (-1, -2, -3))
    )
    errors = dict(
        quaternion_norm=jnp.abs(jnp.linalg.norm(q, axis=-1) - 1),
        momentum_norm=jnp.abs(jnp.linalg.norm(L, axis=-1) - norm) / norm,
        energy=jnp.abs(0.5 * jnp.sum(L**2 / inertia[:, None], -1) - energy) / energy,
        spatial_momentum=jnp.max(jnp.abs(jnp.einsum("nkij,nkj->nki", R, L) - spatial0[:, None]), -1) / norm,
    )
    return finite, {k: jnp.max(v, -1) for k, v in errors.items()}


def main(n=200_000, seed=0, chunk=8192, output=DEFAULT_OUTPUT, verbose=True):
    """Run the fuzz; returns the result dict (also written to ``output`` as JSON unless None)."""
    if not jax.config.jax_enable_x64:
        raise RuntimeError("enable float64 first: jax.config.update('jax_enable_x64', True)")
    rng = np.random.default_rng(seed)
    inertia, momentum, attitude, times, family = random_bodies(rng, n)
    padded = -(-n // chunk) * chunk
    pad = lambda a: np.concatenate([a, np.repeat(a[:1], padded - n, axis=0)])  # noqa: E731
    arrays = [pad(a) for a in (inertia, momentum, attitude, times)]
    start = time.perf_counter()
    finite, errors = [], {}
    for begin in range(0, padded, chunk):
        ok, err = _evaluate(*(jnp.asarray(a[begin : begin + chunk]) for a in arrays))
        finite.append(np.asarray(ok))
        for k, v in err.items():
            errors.setdefault(k, []).append(np.asarray(v))
    elapsed = time.perf_counter() - start
    finite = np.concatenate(finite)[:n]
    errors = {k: np.concatenate(v)[:n] for k, v in errors.items()}
    worst = {}
    for name, values in errors.items():
        values = np.where(np.isfinite(values), values, np.inf)
        i = int(np.argmax(values))
        worst[name] = dict(
            value=float(values[i]),
            family=FAMILIES[family[i]],
            inertia=inertia[i].tolist(),
            momentum=momentum[i].tolist(),
            times=times[i].tolist(),
        )
    per_family = {
        f: {
            name: float(np.max(np.where(np.isfinite(v[family == k]), v[family == k], np.inf), initial=0.0))
            for name, v in errors.items()
        }
        for k, f in enumerate(FAMILIES)
    }
    bad = np.flatnonzero(~finite)
    result = dict(
        n=n,
        seed=seed,
        chunk=chunk,
        times_per_body=TIMES,
        seconds_including_compile=elapsed,
        non_finite=int(bad.size),
        non_finite_examples=[
            dict(
                family=FAMILIES[family[i]],
                inertia=inertia[i].tolist(),
                momentum=momentum[i].tolist(),
                times=times[i].tolist(),
            )
            for i in bad[:10]
        ],
        worst=worst,
        worst_per_family=per_family,
    )
    if verbose:
        print(f"{n} bodies x {TIMES} times in {elapsed:.1f} s (with compilation); non-finite: {bad.size}")
        for name, w in worst.items():
            print(f"  {name:17s} {w['value']:.3g}  ({w['family']}, I = {np.round(w['inertia'], 6).tolist()})")
    if output is not None:
        output = Path(output)
        output.parent.mkdir(parents=True, exist_ok=True)
        output.write_text(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=200_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--chunk", type=int, default=8192)
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT)
    args = parser.parse_args()
    jax.config.update("jax_enable_x64", True)  # a script: the library itself never does this
    main(args.n, args.seed, args.chunk, args.output)
