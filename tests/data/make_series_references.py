"""Regenerate tests/data/series_references.json: 60-digit sn, cn, dn and third-kind integrals next to
the separatrix, for tests/test_series.py::test_complementary_series_against_mpmath.

    .venv/bin/python tests/data/make_series_references.py    # about 80 s on one core

For each mc = 1 - m of ``COMPLEMENTS`` and chi of ``CHARACTERISTICS`` (tests/_series_reference.py)
the file holds K(m) rounded to float64, the arguments u (``separatrix_arguments(K)``), mpmath's
(sn, cn, dn, expanded integral) at each u and the expanded integral at u = K, all at 60 digits
(``mpmath.workdps(60)``: ellippi next to the separatrix, and Pi - u for chi -> 0).  Floats are written
with ``repr`` (they read back exactly).  Nothing here uses a formula of frbjax.
"""

from __future__ import annotations

import json
import os
import sys
import time

import mpmath


HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from _series_reference import (  # noqa: E402
    CHARACTERISTICS,
    COMPLEMENTS,
    complete,
    quarter_period,
    reference,
    separatrix_arguments,
)


DIGITS = 60


def main():
    start = time.perf_counter()
    cases = []
    with mpmath.workdps(DIGITS):
        for mc in COMPLEMENTS:
            quarter = quarter_period(mc)
            arguments = separatrix_arguments(quarter)
            for chi in CHARACTERISTICS:
                cases.append(
                    {
                        "mc": mc,
                        "chi": chi,
                        "quarter": quarter,
                        "u": arguments,
                        "sn_cn_dn_integral": [reference(mc, chi, u) for u in arguments],
                        "complete": complete(mc, chi),
                    }
                )
    path = os.path.join(HERE, "series_references.json")
    with open(path, "w") as file:
        json.dump({"digits": DIGITS, "cases": cases}, file, indent=1)
        file.write("\n")
    print(f"{len(cases)} cases in {time.perf_counter() - start:.0f} s: {path}")


if __name__ == "__main__":
    main()
