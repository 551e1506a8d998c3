"""Shared pytest configuration for the frbjax test suite.

* The library never enables 64-bit mode by itself; the tests do, at import of this file (before any
  test module creates an array), so that float64 inputs stay float64.  float32 behaviour is tested
  by passing float32 arrays explicitly.
* Implicit rank promotion is an error (``jax_numpy_rank_promotion = "raise"``, as in diffrax's
  tests): the library broadcasts arrays of different ranks explicitly, so that a user's shape mistake
  is not silently broadcast inside it.  The library never sets this itself either.
* No persistent compilation cache: in CI a worker died with a segmentation fault inside
  `executable.serialize()` while writing a program to the cache (jaxlib 0.10.2, CPU), and the run then
  hung until CI's limit.  Each worker compiles what it runs.
* Compiled programs are dropped when a worker's memory mappings reach half of Linux's
  ``vm.max_map_count``: XLA:CPU maps the code of every program it compiles into mappings of its own
  (about 150 for one body's evaluation), JAX keeps every program it compiled, and a worker that ran
  several hundred tests passed the limit of 65530, where the next compilation aborted the process
  (CI, 2026-11-27: "Fatal Python error: Aborted" and segmentation faults inside
  ``backend_compile_and_load``).  ``jax.clear_caches()`` and a garbage collection give them back;
  the programs of later tests are compiled again.
* The time budget (tests/_time_budget.py): a test over 60 s fails unless it is marked ``slow``, and
  the slow tests together must stay under 180 s.
* The test files are collected longest first (tests/_schedule.py), so that with `make test`'s
  ``--no-loadscope-reorder`` the two xdist workers finish together.
"""

import gc
import os

import jax
import pytest
from _schedule import longest_first
from _time_budget import (  # noqa: F401  (pytest finds the hooks among this module's names)
    pytest_runtest_call,
    pytest_runtest_logreport,
    pytest_runtest_makereport,
    pytest_runtest_setup,
    pytest_sessionfinish,
    pytest_terminal_summary,
)


# The CLI (called in process by test_cli.py, and by the subprocesses that inherit this environment)
# turns on the persistent compilation cache unless FRBJAX_CACHE_DIR is empty: a worker whose later
# compilations wrote to it died in executable.serialize() (see above).
os.environ["FRBJAX_CACHE_DIR"] = ""

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")


def _map_limit():
    try:
        with open("/proc/sys/vm/max_map_count") as limit:
            return int(limit.read()) // 2
    except (OSError, ValueError):
        return None  # not Linux: no such limit to keep under


_MAP_LIMIT = _map_limit()


def _mappings():
    with open("/proc/self/maps", "rb") as maps:
        return sum(1 for _ in maps)


@pytest.hookimpl(trylast=True)
def pytest_runtest_teardown(item, nextitem):
    if _MAP_LIMIT is not None and _mappings() > _MAP_LIMIT:
        jax.clear_caches()
        gc.collect()


def pytest_collection_modifyitems(config, items):
    longest_first(items, config.rootpath)
