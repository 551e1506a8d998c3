"""XLA:CPU options for the test programs that compile JAX-path derivatives.

Without the fusion emitters and LLVM's optimisations the same arithmetic compiles in a fraction of
the time (tests/special/test_second_derivatives.py: 125 s with the defaults, 50 s without, on one
core).  Two kinds of program use them:

* reference programs (the JAX formulas a compiled kernel is compared with), whose programs under
  test (what users run) are compiled with the defaults;
* the derivative rules' checks against mpmath (tests/special/test_gradients.py,
  test_second_derivatives.py) and against differences of the function (the light-curve posterior's
  potential, tests/test_lightcurve_posterior.py), which test the mathematics of the rules: the
  values, what LLVM's optimisations could change, are tested with the default options
  (test_carlson.py, test_legendre.py, test_jacobi.py; the light-curve fits), and the derivative
  tests' worst errors are within the same tolerances either way.

Not for values at large |L t| next to the separatrix: there the JAX formulas' free flow compiled at
``xla_backend_optimization_level`` 0 gave errors of 1e-4 in L (jaxlib 0.10.2, found while testing
csrc/free_flow.hpp), so tests/test_compiled_free_flow.py keeps LLVM's optimisations for its values.
"""

import os

import jax


FAST_COMPILE_OPTIONS = {"xla_cpu_use_fusion_emitters": False, "xla_backend_optimization_level": 0}


def fast_jit(fn):
    """``jax.jit(fn)`` with each program compiled with FAST_COMPILE_OPTIONS, once per the structure
    and types (shapes, dtypes, weak types) of the arguments, which are all arrays (no static ones).

    The key holds ``FRBJAX_KERNELS`` too: the special functions choose their path (compiled kernels
    or JAX code) where they are traced, from that variable (tests/special/conftest.py switches it).
    """
    jitted = jax.jit(fn)
    programs = {}

    def call(*args):
        leaves, structure = jax.tree.flatten(args)
        key = (os.environ.get("FRBJAX_KERNELS"), structure, tuple(jax.typeof(x) for x in leaves))
        if key not in programs:
            programs[key] = jitted.lower(*args).compile(compiler_options=FAST_COMPILE_OPTIONS)
        return programs[key](*args)

    return call
