"""A file lock shared by the xdist workers (and the notebook kernels they start) around a first compilation.

Compiling frbjax.fit_attitude's solver takes about a minute of CPU.  Whoever fits first (a test of
tests/test_fit.py on either worker, or notebooks/fit_inertia.ipynb run by tests/test_notebooks.py)
holds the lock while it compiles and stores the program in JAX's persistent cache (tests/conftest.py;
the notebook kernel gets the same cache folder); the others wait and then load it instead of
compiling it again.  POSIX only (elsewhere a no-op).
"""

from __future__ import annotations

import contextlib

FIT = "frbjax-fit-compilation.lock"


def path(tmp_path_factory, name=FIT):
    """The lock file of this pytest session: beside the workers' base temporary folders."""
    return tmp_path_factory.getbasetemp().parent / name


@contextlib.contextmanager
def held(lock_path):
    """Hold an exclusive lock on ``lock_path`` for the duration of the block."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover
        yield
        return
    with open(lock_path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def first_call_locked(lock_path, function):
    """``function`` whose first call in this process holds the lock (the compilation); later calls
    run as they are (the program is compiled, or loaded from the persistent cache)."""
    compiled = False

    def call(*args, **kwargs):
        nonlocal compiled
        if compiled:
            return function(*args, **kwargs)
        with held(lock_path):
            result = function(*args, **kwargs)
        compiled = True
        return result

    return call
