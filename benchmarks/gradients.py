"""Derivatives of FreeRigidBody with XLA's default compiler options, and the full jax.hessian (too slow for CI).

1. jax.jacfwd and jax.jacrev of y = (L, Omega, q, R) at time t with respect to x = (I, L, q0, t) at
   every point of tests/data/gradient_references.json (32-digit mpmath Jacobians), compiled with
   XLA's default options (tests/test_gradients_body.py compiles them with faster-compiling options):
   worst relative column error per kind of point (the measure of the test; target 1e-9), and
   finiteness at every point.
2. jax.hessian (forward over reverse) of the scalar s(x) = sum_k w_k y_k(x)^2 + sum_k sin(y_k(x)) at
   the generic points: compile time (wall and CPU), the process's peak resident memory, finiteness,
   symmetry, and (where finite) agreement with 4th-order central differences (Richardson over h and
   h/2) of jax.grad(s), itself checked by part 1.

Prints and writes benchmarks/results/gradients.json.

Last measured (frbjax with ``_fusion.anywhere``, 2 CPU cores, nothing else running): part 1
compiles jax.vmap(jax.jacfwd) in 20 s and jax.vmap(jax.jacrev) in 27 s; both are finite everywhere,
with worst errors 4.6e-15 (generic and smooth points), 6.3e-13 at 1e-3 from the separatrix and
8.6e-11 at 1e-6 from it (d/dI2), 9.8e-16 in the q0 and t columns at the branch points (uniform
rotations are now checked in every column: 1e-15 in tests/test_gradients_body.py).  Part 2
compiles jax.vmap(jax.hessian(s)) over the 12 generic points in 123 s wall (185 s CPU) with XLA's
default options, peak resident memory 2.8 GiB; every Hessian is finite and symmetric to 5e-16 (3e-11
next to the separatrix), and it agrees with the differences of jax.grad(s) to 1.1e-12 at the
points away from the separatrix (2.8e-11 at "scaled |L|", 1.3e-11 at "long time"), 1.1e-10 at
1e-3 from it and 1.7e-8 at 1e-6 (where the differences themselves lose digits).  Before
``_fusion.anywhere`` the vmap turned the library's fusion boundaries into selects, and the same
compilation was stopped after 8 minutes at 17 GB.  The test (tests/test_gradients_body.py,
test_hessian_matches_mpmath) compiles jax.vmap(jax.hessian) with faster-compiling options in about
25 s and checks it against 32-digit second differences.

    .venv/bin/python benchmarks/gradients.py [--parts first,hessian]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import pathlib
import platform
import resource
import time

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from frbjax import FreeRigidBody  # noqa: E402


ROOT = pathlib.Path(__file__).resolve().parents[1]
OUTPUT = ROOT / "benchmarks" / "results" / "gradients.json"
_spec = importlib.util.spec_from_file_location("_gradient_tests", ROOT / "tests" / "test_gradients_body.py")
_tests = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_tests)
STEP = 1e-3
INPUTS = ["I1", "I2", "I3", "L1", "L2", "L3", "qw", "qx", "qy", "qz", "t"]


def outputs(x):
    body = FreeRigidBody(x[:3], x[3:6], x[6:10])
    t = x[10]
    return jnp.concatenate(
        [body.angular_momentum(t), body.angular_velocity(t), body.quaternion(t), body.rotation_matrix(t).reshape(-1)]
    )


def scalar(x):
    y = outputs(x)
    return jnp.sum(jnp.linspace(0.3, 1.7, y.size, dtype=x.dtype) * y**2) + jnp.sum(jnp.sin(y))


def _cpu():
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _peak_rss_gib():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # Linux: KiB


def compiled(function, *args):
    start_wall, start_cpu = time.perf_counter(), _cpu()
    program = jax.jit(function).lower(*args).compile()
    return program, dict(
        wall_s=time.perf_counter() - start_wall, cpu_s=_cpu() - start_cpu, peak_rss_gib_after=_peak_rss_gib()
    )


def load():
    """(names, kinds, x, jacobian) of the mpmath references, read as the tests read them."""
    names, kinds, x, _, jacobian = _tests.references()
    return names, kinds, x, jacobian


# The tests' error measure per input column (see tests/test_gradients_body.py).
column_errors = _tests.column_errors


def first_derivatives():
    names, kinds, x, reference = load()
    summary = {}
    for mode, transform in (("jacfwd", jax.jacfwd), ("jacrev", jax.jacrev)):
        program, timing = compiled(jax.vmap(transform(outputs)), jnp.asarray(x))
        jacobian = np.asarray(program(jnp.asarray(x)))
        errors = column_errors(jacobian, reference)
        finite = np.all(np.isfinite(jacobian), axis=(-2, -1))
        per_point = []
        for k, name in enumerate(names):
            partial = kinds[k] == "branch" and name in _tests.ONE_SIDED_BRANCH_POINTS
            row = np.where(np.arange(11) >= 6, errors[k], 0) if partial else errors[k]
            worst = int(np.argmax(row))
            per_point.append(
                dict(
                    name=name,
                    kind=kinds[k],
                    finite=bool(finite[k]),
                    worst_relative_error=float(row[worst]),
                    input=INPUTS[worst],
                )
            )
        near = [p for p in per_point if p["name"].startswith("separatrix ")]
        away = [p for p in per_point if p["kind"] in ("generic", "smooth") and not p["name"].startswith("separatrix ")]
        summary[mode] = dict(
            compile=timing,
            all_finite=bool(finite.all()),
            worst_generic_and_smooth=max(p["worst_relative_error"] for p in away),
            worst_near_separatrix=max(p["worst_relative_error"] for p in near),
            worst_uniform_rotation=max(
                p["worst_relative_error"]
                for p in per_point
                if p["kind"] == "branch" and p["name"] not in _tests.ONE_SIDED_BRANCH_POINTS
            ),
            worst_separatrix_q0_t_columns=max(
                p["worst_relative_error"] for p in per_point if p["name"] in _tests.ONE_SIDED_BRANCH_POINTS
            ),
            points=per_point,
        )
        print(
            f"{mode}: compile {timing['wall_s']:.0f} s; finite everywhere {finite.all()}; worst relative "
            f"error: generic/smooth {summary[mode]['worst_generic_and_smooth']:.1e}, near the separatrix "
            f"{summary[mode]['worst_near_separatrix']:.1e}, uniform rotations (every column) "
            f"{summary[mode]['worst_uniform_rotation']:.1e}, on the separatrix (q0, t) "
            f"{summary[mode]['worst_separatrix_q0_t_columns']:.1e}",
            flush=True,
        )
    return summary


def hessian():
    names, kinds, x, _ = load()
    generic = [k for k, kind in enumerate(kinds) if kind == "generic"]
    names = [names[k] for k in generic]
    x = jnp.asarray(x[generic])
    n = x.shape[1]
    rss_before = _peak_rss_gib()
    program, timing = compiled(jax.vmap(jax.hessian(scalar)), x)
    print(
        f"jax.hessian: compile {timing['wall_s']:.0f} s wall, {timing['cpu_s']:.0f} s CPU, peak RSS "
        f"{timing['peak_rss_gib_after']:.1f} GiB (before: {rss_before:.1f} GiB)",
        flush=True,
    )
    start = time.perf_counter()
    h = np.asarray(program(x))
    run_seconds = time.perf_counter() - start
    gradient, gradient_time = compiled(jax.vmap(jax.grad(scalar)), x)

    def central(step):
        columns = []
        for j in range(n):
            shift = np.zeros(n)
            shift[j] = step
            plus, minus = np.asarray(gradient(x + shift)), np.asarray(gradient(x - shift))
            plus2, minus2 = np.asarray(gradient(x + 2 * shift)), np.asarray(gradient(x - 2 * shift))
            columns.append((8 * (plus - minus) - (plus2 - minus2)) / (12 * step))
        return np.stack(columns, -1)

    coarse, fine = central(STEP), central(STEP / 2)
    reference = (16 * fine - coarse) / 15
    records = []
    for k, name in enumerate(names):
        finite = bool(np.all(np.isfinite(h[k])))
        error = float(np.max(np.abs(h[k] - reference[k])) / np.max(np.abs(reference[k]))) if finite else None
        asymmetry = float(np.max(np.abs(h[k] - h[k].T)) / np.max(np.abs(h[k]))) if finite else None
        records.append(
            dict(
                name=name,
                finite=finite,
                relative_error=error,
                asymmetry=asymmetry,
                non_finite_entries=int(np.sum(~np.isfinite(h[k]))),
            )
        )
        print(f"  {name:22s} finite {finite}  |H - H_fd| / |H| = {error}  asymmetry {asymmetry}")
    errors = [r["relative_error"] for r in records if r["relative_error"] is not None]
    return dict(
        compile=timing,
        run_s=run_seconds,
        grad_compile=gradient_time,
        points=records,
        all_finite=all(r["finite"] for r in records),
        worst_relative_error=max(errors) if errors else None,
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", default="first,hessian")
    parts = parser.parse_args().parts.split(",")
    summary = json.loads(OUTPUT.read_text()) if OUTPUT.exists() else {}
    summary.update(
        machine=f"{platform.machine()} {platform.processor()}".strip(),
        jax=jax.__version__,
        cpu_count=__import__("os").cpu_count(),
    )
    if "first" in parts:
        summary["first_derivatives"] = first_derivatives()
        OUTPUT.parent.mkdir(parents=True, exist_ok=True)
        OUTPUT.write_text(json.dumps(summary, indent=1))
    if "hessian" in parts:
        summary["hessian"] = hessian()
        OUTPUT.write_text(json.dumps(summary, indent=1))
    print(f"written to {OUTPUT}")


if __name__ == "__main__":
    main()
