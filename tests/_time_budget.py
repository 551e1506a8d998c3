"""The suite's time budget, as a pytest plugin (tests/conftest.py imports its hooks).

Time here is the CPU time of the process running the test (``time.process_time``, all its threads,
and the subprocesses it ran), not the wall clock: a test's cost is what it computes and compiles, and a machine shared with other
work (another test worker, a developer's editor and builds) would otherwise fail tests that are well
within it.  On a dedicated core the two agree for this suite, whose time is mostly XLA compiling on
one thread.

* A test whose setup and call together take longer than ``FRBJAX_TEST_TIME_LIMIT`` CPU seconds (60
  by default) fails, unless it is marked ``slow``: its fixtures count, since a module's shared fixture
  is paid by whichever test asks for it first.  The check runs where the test runs (an xdist worker),
  on the call phase's report, so the failure is reported like any other.
* The tests marked ``slow`` must together stay under ``FRBJAX_SLOW_TOTAL_LIMIT`` CPU seconds (180 by
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


def _start_phase(item):
    item.stash[_PHASE_START] = _cpu_seconds()


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
    seconds = _cpu_seconds() - item.stash[_PHASE_START] if _PHASE_START in item.stash else 0.0
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
    message = (f"{item.nodeid} took {total:.1f} CPU s (setup {setup:.1f} s, call {seconds:.1f} s), "
               f"over the limit of {limit:g} s (FRBJAX_TEST_TIME_LIMIT) for a test not marked slow: make "
               "it smaller, or mark it @pytest.mark.slow with the reason.")
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
    limit = _limit("FRBJAX_SLOW_TOTAL_LIMIT", 180)
    total = sum(_slow_seconds.values())
    summary = (f"tests marked slow: {len(_slow_seconds)}, {total:.1f} CPU s in all (limit {limit:g} s, "
               "FRBJAX_SLOW_TOTAL_LIMIT)")
    if total > limit:
        summary += ": over the limit"
        if session.exitstatus == pytest.ExitCode.OK:
            session.exitstatus = pytest.ExitCode.TESTS_FAILED
    session.config.stash[_SUMMARY] = summary


def pytest_terminal_summary(terminalreporter, config):
    summary = config.stash.get(_SUMMARY, None)
    if summary is not None:
        terminalreporter.write_line(summary, red="over the limit" in summary)
