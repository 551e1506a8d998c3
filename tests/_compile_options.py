"""XLA:CPU options for the reference programs of the tests that compile JAX-path derivatives.

Without the fusion emitters and LLVM's optimisations the same arithmetic compiles in a fraction of
the time; the programs under test (what users run) are compiled with the defaults.  Not for values
at large |L t| next to the separatrix: there the JAX formulas' free flow compiled at
``xla_backend_optimization_level`` 0 gave errors of 1e-4 in L (jaxlib 0.10.2, found while testing
csrc/free_flow.hpp), so tests/test_compiled_free_flow.py keeps LLVM's optimisations for its values.
"""

FAST_COMPILE_OPTIONS = {"xla_cpu_use_fusion_emitters": False, "xla_backend_optimization_level": 0}
