"""The time budget of tests/_time_budget.py, on a throwaway suite run in a subprocess with the limits
lowered to fractions of a second, under pytest-xdist as `make test` runs it and without it.  The
throwaway tests spin for given CPU times (the budget counts CPU time, which a loaded machine does not
lengthen); what must pass is far under its limit."""

import os
import subprocess
import sys
from pathlib import Path

import pytest


_LIMIT = 0.5

_FILES = {
    "pytest.ini": "[pytest]\nmarkers =\n    slow: over the per-test limit\n",
    # CPU time, spent in a busy loop (the budget counts the lesser of CPU and wall time).
    "spin.py": (
        "import time\n\n"
        "def spin(seconds):\n"
        "    start = time.process_time()\n"
        "    while time.process_time() - start < seconds:\n"
        "        pass\n"
    ),
    "test_unmarked.py": (
        "import pytest\n"
        "from spin import spin\n\n"
        "@pytest.fixture(scope='module')\n"
        "def shared():\n"
        "    spin(0.4)\n\n"
        "def test_quick():\n"
        "    pass\n\n"
        "def test_setup_and_call_over(shared):\n"
        "    spin(0.4)\n"
    ),
    "test_marked.py": (
        "import pytest\n"
        "from spin import spin\n\n"
        "@pytest.mark.slow\n"
        "def test_first():\n"
        "    spin(0.7)\n\n"
        "@pytest.mark.slow\n"
        "def test_second():\n"
        "    spin(0.7)\n"
    ),
}


@pytest.fixture(scope="module")
def suite(tmp_path_factory):
    directory = tmp_path_factory.mktemp("budget")
    for name, text in _FILES.items():
        (directory / name).write_text(text)
    return directory


def _run(directory, *arguments, slow_total):
    # Only the plugins the run needs (the others' imports would take most of its time).
    environment = dict(
        os.environ,
        FRBJAX_TEST_TIME_LIMIT=str(_LIMIT),
        FRBJAX_SLOW_TOTAL_LIMIT=str(slow_total),
        PYTEST_DISABLE_PLUGIN_AUTOLOAD="1",
        PYTHONPATH=os.pathsep.join([str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")]),
    )
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-p",
            "xdist.plugin",
            "-p",
            "_time_budget",
            "-p",
            "no:cacheprovider",
            "-rA",
            *arguments,
        ],
        check=False,
        cwd=directory,
        env=environment,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_unmarked_test_over_the_limit_fails_with_its_setup_counted(suite):
    """Setup (0.4 s) and call (0.4 s) are each under the 0.5 s limit, together over it."""
    run = _run(suite, "-n", "2", "--dist", "loadfile", slow_total=10)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "FAILED test_unmarked.py::test_setup_and_call_over" in run.stdout
    assert "over the limit of 0.5 s (FRBJAX_TEST_TIME_LIMIT)" in run.stdout
    assert "PASSED test_unmarked.py::test_quick" in run.stdout
    assert "1 failed, 3 passed" in run.stdout


def test_slow_tests_over_their_total_fail_the_run_under_xdist(suite):
    """Two slow tests of 0.7 s each pass one by one, but their 1.4 s exceed a total of 1 s."""
    run = _run(suite, "-n", "2", "--dist", "loadfile", "test_marked.py", slow_total=1)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "2 passed" in run.stdout
    assert "tests marked slow: 2," in run.stdout and "over the limit" in run.stdout


def test_slow_tests_within_their_total_pass_without_xdist(suite):
    run = _run(suite, "test_marked.py", slow_total=10)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "tests marked slow: 2," in run.stdout and "over the limit" not in run.stdout


def test_the_schedule_names_files_that_exist():
    """tests/_schedule.py's table orders the files by name: a renamed or removed file would silently
    drop to the end of the order."""
    from _schedule import FILE_SECONDS

    root = Path(__file__).resolve().parents[1]
    assert [name for name in FILE_SECONDS if not (root / name).is_file()] == []
    assert list(FILE_SECONDS.values()) == sorted(FILE_SECONDS.values(), reverse=True)
