"""A function that a solver calls in two trace contexts, traced once.

optimistix calls a least-squares function twice while tracing: to closure-convert it, and for its
JVP inside the solver's loop.  The second call happens where JAX's trace context names the (empty)
abstract mesh and the first where it names none, so that even a jitted function is traced twice
(jit's cache is keyed by that context): for the fits, whose residuals hold the forward-mode Jacobian
of the motion, that was a tenth of the first call.  :func:`traced_once` calls the jitted function
with the current abstract mesh named explicitly, which makes both contexts equal.
"""

from __future__ import annotations

import functools

import jax

from ._kernel_path import keyed_by_path


def traced_once(function, static_argnums=()):
    """``function`` under ``jax.jit`` (``static_argnums`` static; one program per kernels' path,
    ``_kernel_path``), its trace shared by every call with the same argument types, whichever abstract
    mesh JAX's context names (module docstring)."""
    jitted = keyed_by_path(function, static_argnums=static_argnums)

    @functools.wraps(function)
    def call(*args):
        with jax.sharding.use_abstract_mesh(jax.sharding.get_abstract_mesh()):
            return jitted(*args)

    return call
