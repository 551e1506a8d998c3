"""The suite's time budget, as a pytest plugin (tests/conftest.py imports its hooks).

Time here is the lesser of a test's wall time and its CPU time (``time.process_time``, all the
threads of the process running it, and the subprocesses it ran).  A loaded machine (the other test
worker, a developer's builds) lengthens the wall time and XLA's threads multiply the CPU time, but a
test that takes long on a core of its own takes long both ways.

* A test whose setup and call together take longer than ``FRBJAX_TEST_TIME_LIMIT`` seconds (60
  by default) fails, unless it is marked ``slow``: its fixtures count, since a module's shared fixture
  is paid by whichever test asks for it first.  The check runs where the test runs (an xdist worker),
  on the call phase's report, so the failure is reported like any other.
* The tests marked ``slow`` must together stay under ``FRBJAX_SLOW_TOTAL_LIMIT`` seconds (240 by
  default; `make test` sets the figure in force): their total is printed at the end of the run, and
  a run over it exits non-zero.  That sum is taken from the reports where they are gathered (the
  xdist controller, or the only process).
"""

import os
import time

import pytest


_SETUP_SECONDS = pytest.StashKey[float]()
_PHASE_START = pytest.StashKey[float]()
_SLOW_PROPERTY = "frbjax_slow_seconds"


def _cpu_seconds():
    """CPU time of this process (all its threads) and of its children that have ended: a test that
    runs a benchmark or the CLI in a subprocess pays for it too."""
    times = os.times()
    return time.process_time() + times.children_user + times.children_system


def _seconds():
    """(CPU seconds, wall seconds) now."""
    return _cpu_seconds(), time.perf_counter()


def _start_phase(item):
    item.stash[_PHASE_START] = _seconds()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_setup(item):
    _start_phase(item)
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item):
    _start_phase(item)
    yield


def _limit(name, default):
    return float(os.environ.get(name, default))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    # The lesser of the phase's CPU and wall time: a loaded machine lengthens the wall time and XLA's
    # threads multiply the CPU time, but a test that is slow on a core of its own is slow both ways.
    start = item.stash.get(_PHASE_START, None)
    seconds = 0.0 if start is None else min(now - then for now, then in zip(_seconds(), start))
    outcome = yield
    report = outcome.get_result()
    slow = item.get_closest_marker("slow") is not None
    if report.when == "setup":
        item.stash[_SETUP_SECONDS] = seconds
    if report.when in ("setup", "call") and slow:
        report.user_properties.append((_SLOW_PROPERTY, seconds))
    if report.when != "call" or slow:
        return
    limit = _limit("FRBJAX_TEST_TIME_LIMIT", 60)
    setup = item.stash.get(_SETUP_SECONDS, 0.0)
    total = setup + seconds
    if total <= limit:
        return
    message = (
        f"{item.nodeid} took {total:.1f} s, the lesser of CPU and wall time "
        f"(setup {setup:.1f} s, call {seconds:.1f} s), "
        f"over the limit of {limit:g} s (FRBJAX_TEST_TIME_LIMIT) for a test not marked slow: make "
        "it smaller, or mark it @pytest.mark.slow with the reason."
    )
    if report.passed:
        report.outcome = "failed"
        report.longrepr = message
    else:
        report.sections.append(("time budget", message))


def _is_worker(config):
    return hasattr(config, "workerinput")


# Seconds of setup and call per slow test, from the reports this process gathers.
_slow_seconds = {}
_SUMMARY = pytest.StashKey[str]()


def pytest_runtest_logreport(report):
    seconds = sum(value for name, value in report.user_properties if name == _SLOW_PROPERTY)
    if seconds:
        _slow_seconds[report.nodeid] = _slow_seconds.get(report.nodeid, 0.0) + seconds


def pytest_sessionfinish(session):
    if _is_worker(session.config) or not _slow_seconds:
        return
    limit = _limit("FRBJAX_SLOW_TOTAL_LIMIT", 240)
    total = sum(_slow_seconds.values())
    summary = (
        f"tests marked slow: {len(_slow_seconds)}, {total:.1f} s in all (limit {limit:g} s, FRBJAX_SLOW_TOTAL_LIMIT)"
    )
    if total > limit:
        summary += ": over the limit"
        if session.exitstatus == pytest.ExitCode.OK:
            session.exitstatus = pytest.ExitCode.TESTS_FAILED
    session.config.stash[_SUMMARY] = summary


def pytest_terminal_summary(terminalreporter, config):
    summary = config.stash.get(_SUMMARY, None)
    if summary is not None:
        terminalreporter.write_line(summary, red="over the limit" in summary)
