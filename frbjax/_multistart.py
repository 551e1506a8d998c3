"""Solving a batch of independent starting points: one after another on CPU, batched elsewhere.

``jax.vmap`` of a solver batches its ``while`` loops: every start then runs until the slowest has
converged, with every carry selected at every step, and the batching rules of the loops and of the
linear algebra make the traced program larger.  ``jax.lax.map`` runs the same unbatched solve once
per start, inside one compiled program.  On CPU, where each start's work (its residuals over all
samples) is already vectorised, that is the cheaper one: ``fit_attitude``'s first call (12 starts,
200 samples, one core) 18 s against 22.5 s, and a compiled fit 0.06 s against 0.11 s.  Accelerators
keep the batch (``jax.vmap``), whose parallel starts they can run at once.
"""

from __future__ import annotations

import jax


def starts_in_sequence() -> bool:
    """Whether the default backend solves starts one after another (CPU) rather than batched."""
    return jax.default_backend() == "cpu"


def solve_each(solve, starts, in_sequence: bool | None = None):
    """``solve(*start)`` for every start (the leading axis of every leaf of the tuple ``starts``; a
    ``None`` is an absent argument), stacked: by ``jax.lax.map`` when ``in_sequence``, else by
    ``jax.vmap``; by default as the backend prefers (``starts_in_sequence``)."""
    if in_sequence is None:
        in_sequence = starts_in_sequence()
    if in_sequence:
        return jax.lax.map(lambda start: solve(*start), starts)
    return jax.vmap(solve)(*starts)
