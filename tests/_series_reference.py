"""mpmath references of the theta-function series (tests/test_series.py and its committed data).

Nothing here uses a formula of frbjax: sn, cn, dn and the third-kind integral along the orbit, from
mpmath's ``ellipfun``, ``ellipk`` and ``ellippi`` at the working precision of the caller
(``mpmath.workdps``).
"""

from __future__ import annotations

import mpmath


def expanded(chi, value, u):
    """The series' form of the integral: Pi - u for chi >= -1, Pi itself for chi < -1."""
    return value - u if chi >= -1 else value


def reference(mc, chi, u):
    """(sn, cn, dn, the expanded integral) for m = 1 - mc; am continued through whole half-periods."""
    mc, chi, u = mpmath.mpf(mc), mpmath.mpf(chi), mpmath.mpf(u)
    m = 1 - mc
    quarter = mpmath.ellipk(m)
    turns = mpmath.nint(u / (2 * quarter))
    reduced = u - 2 * quarter * turns
    sn = mpmath.ellipfun("sn", u, m=m)
    cn = mpmath.ellipfun("cn", u, m=m)
    dn = mpmath.ellipfun("dn", u, m=m)
    # From sn and cn (>= 0) of the reduced argument: asin(sn) would lose half the digits where sn ~ 1.
    amplitude = mpmath.atan2(mpmath.ellipfun("sn", reduced, m=m), mpmath.ellipfun("cn", reduced, m=m))
    third = mpmath.ellippi(chi, amplitude, m) + 2 * turns * mpmath.ellippi(chi, m)
    return [float(v) for v in (sn, cn, dn, expanded(chi, third, u))]


def complete(mc, chi):
    """The expanded integral at u = K."""
    m = 1 - mpmath.mpf(mc)
    return float(expanded(chi, mpmath.ellippi(chi, m), mpmath.ellipk(m)))


def quarter_period(mc):
    """K(m) for m = 1 - mc, rounded to float64."""
    return float(mpmath.ellipk(1 - mpmath.mpf(mc)))


# Next to the separatrix: mc = 1 - m (exact in binary64) and characteristics over the whole range.
COMPLEMENTS = [1e-3, 1e-4, 7e-5, 1e-5, 1e-8, 1e-12, 1e-16, 1e-30]
CHARACTERISTICS = [-1e-12, -1e-6, -0.3, -1.0, -1.5, -30.0, -1e4, -1e10]


def separatrix_arguments(quarter):
    """The arguments of the complementary-series test: several half-periods, u within 1e-9 of 0 and
    of K (the zeros of sn and cn), and a few between."""
    return [x * quarter for x in (-2.6 + 5.2 * k / 12 for k in range(13))] + [
        1e-9,
        -3e-4,
        0.3,
        quarter - 1e-9,
        quarter * (1 - 1e-5),
        -0.7 * quarter,
    ]
