"""Elliptic special functions in JAX, with scipy.special names and argument order.

Every function is element-wise with numpy broadcasting, works under ``jit``, ``vmap``, ``grad`` and
``jvp`` with a fixed operation count, keeps the dtype it is given, and has a custom JVP rule built on
the analytic derivatives (see each module's notes).  Where accuracy near $m = 1$ depends on it, the
complementary parameter ``mc`` $= 1 - m$ can be passed directly.

- Jacobi: ``ellipj`` (sn, cn, dn, am; DLMF 22).
- Legendre: ``ellipk``, ``ellipkm1``, ``ellipe``, ``ellipkinc``, ``ellippi``, ``ellippiinc``
  (DLMF 19.2).
- Carlson: ``elliprf``, ``elliprd``, ``elliprj``, ``elliprc`` (DLMF 19.16).
"""

from ._carlson import elliprc, elliprd, elliprf, elliprj
from ._jacobi import ellipj
from ._legendre import ellipe, ellipk, ellipkinc, ellipkm1, ellippi, ellippiinc


__all__ = [
    "ellipe",
    "ellipj",
    "ellipk",
    "ellipkinc",
    "ellipkm1",
    "ellippi",
    "ellippiinc",
    "elliprc",
    "elliprd",
    "elliprf",
    "elliprj",
]
