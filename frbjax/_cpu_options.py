"""XLA:CPU compiler options for the programs that the fits and the light-curve inversion compile.

XLA:CPU compiles these programs faster, and runs them as fast, with its fusion emitters off
(``DEFAULT_COMPILER_OPTIONS``): ``fit_attitude``'s solver about a quarter faster
(benchmarks/fit_success.py); the light-curve inversion of tests/test_lightcurve_fit.py's LAM
tumbler, its refinement 13.8 -> 7.8 s of compilation and its other programs 7.0 -> 5.0 s, the first
call 34.5 -> 32.5 s and a second call as fast (one core, 2026-11-29).  And with its machine code split
into no more parts than the process has cores (XLA's default is 32 parts, compiled side by side, each
with its own fixed costs): the light-curve benchmark's first ``fit_lightcurve`` call (LAM, seed 0, one
core) 13% less XLA compilation (6.27 -> 5.45 s, both runs side by side) and a second call as fast; on
two cores 2 parts compiled no slower than 32 (2026-12-02).  Other backends do not know the options and
get none; an XLA that does not know them compiles without them.
"""

from __future__ import annotations

import functools
import os

import jax

from ._kernel_path import keyed_by_path


def _cores():
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity masks (macOS)
        return os.cpu_count() or 1


# More parts of machine code than cores only adds each part's fixed costs (module docstring).
DEFAULT_COMPILER_OPTIONS = {
    "xla_cpu_use_fusion_emitters": False,
    "xla_cpu_parallel_codegen_split_count": max(1, min(_cores(), 32)),
}


def call_with_options(compiled, options, *args, **static):
    """``compiled(options)(*args, **static)``, ``compiled`` a cached jit for a sorted tuple of XLA
    compiler options; compiled without them where this XLA does not know them."""
    try:
        return compiled(tuple(sorted(options.items())))(*args, **static)
    except jax.errors.JaxRuntimeError as error:  # an XLA without these options: compile without
        if not options or "compile option" not in str(error):
            raise
    return compiled(())(*args, **static)


def cpu_jit(function=None, **jit_options):
    """``jax.jit(function, **jit_options)``, compiled with ``DEFAULT_COMPILER_OPTIONS`` where the
    default backend is the CPU and it is called outside any trace (a decorator, with or without
    ``jit_options``).  Its ``compiled(options)`` is the jit for other options (a sorted tuple of
    items), one per options and kernels' path (``_kernel_path``), for ``call_with_options``."""
    if function is None:
        return functools.partial(cpu_jit, **jit_options)

    @functools.cache
    def compiled(options):
        return keyed_by_path(function, compiler_options=dict(options) or None, **jit_options)

    @functools.wraps(function)
    def call(*args, **kwargs):
        # Inside another trace it is part of that program, whose options are its own (JAX refuses
        # compiler options on a nested jit).
        traced = any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves((args, kwargs)))
        options = DEFAULT_COMPILER_OPTIONS if jax.default_backend() == "cpu" and not traced else {}
        return call_with_options(compiled, options, *args, **kwargs)

    call.compiled = compiled
    return call
