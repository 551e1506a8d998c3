"""Shared pytest configuration for the frbjax test suite.

* The library never enables 64-bit mode by itself; the tests do, at import of this file (before any
  test module creates an array), so that float64 inputs stay float64.  float32 behaviour is tested
  by passing float32 arrays explicitly.
* No persistent compilation cache: in CI a worker died with a segmentation fault inside
  `executable.serialize()` while writing a program to the cache (jaxlib 0.10.2, CPU), and the run then
  hung until CI's limit.  Each worker compiles what it runs.
"""

import jax

jax.config.update("jax_enable_x64", True)

