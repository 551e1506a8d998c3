"""The two paths of the special functions: the compiled CPU kernels and the JAX code.

``special_path`` (module scope, parametrized) runs a test under ``FRBJAX_KERNELS=compiled`` and under
``FRBJAX_KERNELS=jax``.  The choice is read when a function is traced, so the programs of one path are
dropped when the module switches to the other (JAX's caches, cleared at the switch: once per module and
path, not per test).
"""

import jax
import pytest


@pytest.fixture(scope="module", params=["compiled", "jax"])
def special_path(request):
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("FRBJAX_KERNELS", request.param)
        jax.clear_caches()
        yield request.param
    jax.clear_caches()
