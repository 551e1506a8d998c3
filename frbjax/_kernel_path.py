"""The kernels' path as a key of the library's compiled programs.

Whether the compiled kernels or the JAX formulas evaluate a function is decided when it is traced, from
``FRBJAX_KERNELS`` (the special functions and the motion) and ``FRBJAX_MOTION_KERNEL`` (the motion
alone).  ``jax.jit`` keys its cache by the arguments' types only: a program traced under one setting
was reused after the variable changed (a body's methods, compiled on the kernels, then ran them under
``FRBJAX_KERNELS=jax``).  Each compiled program of the library is therefore made once per path
(``special._compiled.keyed_jit``, as the special functions' ``one_program`` is), so that a change of
either variable takes effect at the next call.
"""

from __future__ import annotations

import functools
import os

import jax

from . import _compiled_motion
from .special import _compiled


def current() -> tuple[str, str]:
    """The path that a function traced now takes: the two variables' values (their defaults if unset)."""
    return os.environ.get(_compiled._SWITCH, "auto"), os.environ.get(_compiled_motion._SWITCH, "compiled")


def keyed_by_path(function=None, *, jit=jax.jit, **jit_options):
    """``jit(function, **jit_options)`` made once per path (``current()``) and called for the current
    one: a decorator, with or without options; ``jit`` is ``jax.jit`` or ``equinox.filter_jit``."""
    if function is None:
        return functools.partial(keyed_by_path, jit=jit, **jit_options)
    return _compiled.keyed_jit(function, current, jit=jit, **jit_options)
