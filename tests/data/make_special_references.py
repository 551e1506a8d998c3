"""Write tests/data/special_references.npz: the mpmath grids of the special-function tests.

    .venv/bin/python tests/data/make_special_references.py      # about 30 s on one core

Every function of tests/special decorated with ``_stored.stored`` is evaluated (its own code, mpmath
at 40 to 70 digits: nothing of frbjax) at the argument tuples it declares, and its results are written
with their fingerprints (tests/special/_stored.py).  Run it after changing a grid, a reference, or a
test module that holds a stored grid: tests/special/test_stored_references.py says when.
"""

from __future__ import annotations

import importlib
import json
import sys
import time
from pathlib import Path

import numpy as np


TESTS = Path(__file__).resolve().parents[1]
MODULES = ("test_legendre", "test_gradients", "test_second_derivatives")


def main():
    sys.path.insert(0, str(TESTS))
    from special import _stored

    for module in MODULES:
        importlib.import_module(f"special.{module}")
    arrays, index = {}, {}
    start = time.perf_counter()
    for wrapper in _stored.REGISTRY:
        for args in wrapper.calls:
            name = _stored.key(wrapper.compute, args)
            value = wrapper.compute(*args)
            structure = _stored.encode(value, arrays, f"e{len(index)}")
            index[name] = {"fingerprint": _stored.fingerprint(wrapper.compute), "structure": structure}
            print(f"{name}: {time.perf_counter() - start:.1f} s", flush=True)
    np.savez_compressed(_stored.STORE, index=np.asarray(json.dumps(index)), **arrays)
    print(f"wrote {_stored.STORE} ({len(index)} results, {_stored.STORE.stat().st_size / 1e3:.0f} kB)")


if __name__ == "__main__":
    main()
