"""Shared pytest configuration for the frbjax test suite.

* The library never enables 64-bit mode by itself; the tests do, at import of this file (before any
  test module creates an array), so that float64 inputs stay float64.  float32 behaviour is tested
  by passing float32 arrays explicitly.
* Compiled XLA programs are cached on disk under pytest's cache directory (.pytest_cache, removed by
  `make clean`), so that the two xdist workers, and later runs, do not compile the same large
  programs (the elliptic integrals take seconds to compile) twice.
"""

import jax

jax.config.update("jax_enable_x64", True)


def pytest_configure(config):
    cache = getattr(config, "cache", None)
    if cache is None:  # -p no:cacheprovider
        return
    path = cache.mkdir("jax-compilation-cache")
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
