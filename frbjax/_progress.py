"""Progress bars for minutes-long work (a posterior's chains, a light-curve inversion), through tqdm.

A compiled program cannot print as it goes; it reports through ``jax.debug.callback(advance, name,
count)``, a host call that advances the bar registered under ``name`` while ``bar`` holds it, and does
nothing otherwise.  The callback is part of the program whether a bar is shown or not, so that showing
one compiles nothing more.
"""

from __future__ import annotations

import contextlib
import sys


# The bars shown now, by name (set by ``bar``; advanced by ``advance`` from the compiled programs).
_bars: dict = {}


def interactive() -> bool:
    """True in a terminal or an IPython/Jupyter session: where a progress bar is wanted by default."""
    if "IPython" in sys.modules:
        try:
            from IPython import get_ipython

            if get_ipython() is not None:
                return True
        except ImportError:  # pragma: no cover
            pass
    try:
        return sys.stdout.isatty()
    except (AttributeError, ValueError):
        return False


def check_option(progress):
    """``progress`` (True, False or None: interactive sessions only) as a bool; ValueError otherwise."""
    if progress is not None and not isinstance(progress, bool):
        raise ValueError(f"progress must be True, False or None, got {progress!r}")
    return interactive() if progress is None else progress


@contextlib.contextmanager
def bar(name, total, description, unit, shown=True):
    """A tqdm bar registered as ``name`` while the block runs (nothing when not ``shown``).  It reads
    ``description (compiling)`` until the first advance, and is completed when the block ends."""
    if not shown:
        yield None
        return
    from tqdm.auto import tqdm

    with tqdm(total=total, desc=f"{description} (compiling)", unit=unit) as progress:
        progress.frbjax_description = description
        _bars[name] = progress
        try:
            yield progress
        finally:
            _bars.pop(name, None)
        progress.set_description(description, refresh=False)
        progress.update(progress.total - progress.n)


def advance(name, count=1):
    """Advance the bar ``name`` by ``count`` (the host side of ``jax.debug.callback``)."""
    progress = _bars.get(str(name))
    if progress is not None:
        if progress.n == 0:
            progress.set_description(progress.frbjax_description, refresh=False)
        progress.update(int(count))
