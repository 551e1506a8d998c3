"""The order in which the test files go to the xdist workers: the longest first.

`make test` runs ``pytest -n 2 --dist loadfile --no-loadscope-reorder``: each file goes whole to one
worker, in the order of the collection, as a worker frees up.  pytest-xdist's default reordering
(``--loadscope-reorder``) sends the files with the most tests first, which put the files of one or a
few long tests (a benchmark's smoke run, the notebooks, the posteriors) at the end, where one worker
ran them while the other waited.  Ordered by their measured seconds instead (longest processing time
first), the two workers finish together: on the durations below, a simulation of the scheduler gives
523 s for the run against 535 s with the default order (the sum over both workers being 1046 s);
measured on fresh clones run back to back (2026-12-03), 523 s against 560 s.

``FILE_SECONDS``: each file's tests' seconds (setup, call and teardown) in a full run of the suite
(2026-12-03, `make test`'s command with ``--junitxml``, summed per file); files under 4 s are left
out and keep their collection order after the others (tests/test_kernel_path.py's figure is its run
alone).  A stale figure only makes the order less good, never a test different.
"""

FILE_SECONDS = {
    "tests/test_compiled_motion.py": 88,
    "tests/special/test_gradients.py": 73,
    "tests/test_splitting.py": 67,
    "tests/test_compiled_free_flow.py": 63,
    "tests/test_posterior.py": 62,
    "tests/special/test_second_derivatives.py": 57,
    "tests/test_lightcurve_posterior.py": 57,
    "tests/test_notebooks.py": 45,
    "tests/test_docs.py": 43,
    "tests/test_inertia_tensor.py": 35,
    "tests/test_benchmark_scripts_torqued.py": 35,
    "tests/test_benchmark_scripts_torques.py": 35,
    "tests/test_torques.py": 32,
    "tests/test_fusion.py": 28,
    "tests/test_cli.py": 27,
    "tests/test_work_precision_and_throughput_scripts.py": 24,
    "tests/special/test_benchmark_script.py": 24,
    "tests/test_series.py": 21,
    "tests/test_lightcurve.py": 19,
    "tests/test_lightcurve_nan_policy.py": 19,
    "tests/special/test_kernels.py": 18,
    "tests/special/test_legendre.py": 18,
    "tests/test_fit_tensor.py": 14,
    "tests/special/test_jacobi.py": 14,
    "tests/test_inertia_tensor_script.py": 13,
    "tests/special/test_carlson.py": 12,
    "tests/test_kernel_path.py": 11,
    "tests/special/test_stopping.py": 10,
    "tests/test_fit.py": 9,
    "tests/test_public_inputs.py": 9,
    "tests/test_time_budget.py": 8,
    "tests/test_lightcurve_periodogram.py": 7,
    "tests/test_body_diffrax.py": 6,
    "tests/test_gradients_body.py": 5,
    "tests/test_body_mpmath.py": 5,
    "tests/test_sharding.py": 5,
    "tests/test_torques_tensor.py": 5,
    "tests/test_paths.py": 4,
}


def longest_first(items, root):
    """Sort the collected ``items`` in place by their file's seconds, longest first (stable: each
    file's tests stay together and in their order; files without a figure follow in theirs)."""

    def seconds(item):
        try:
            path = item.path.relative_to(root).as_posix()
        except ValueError:
            return 0
        return FILE_SECONDS.get(path, 0)

    items.sort(key=lambda item: -seconds(item))
