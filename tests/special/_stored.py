"""mpmath references computed once and stored: tests/data/special_references.npz.

The grids of the special-function tests hold mpmath values and finite-difference derivatives at 70
digits: about 27 s of one core to compute, every run.  A function decorated with ``stored(calls)``
is cached like ``functools.cache``, and its results for ``calls`` (the argument tuples the tests use)
are read from the file that tests/data/make_special_references.py writes, where they were computed by
the same function.

Each stored result carries a fingerprint: the source of the module that defines the function and of
_mpmath_reference.py, and mpmath's version.  A result whose fingerprint differs (the grid or the
reference changed since the file was written) is computed afresh instead, so a stale file never gives
a wrong reference, only a slower run; tests/special/test_stored_references.py fails until the file is
written again.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import json
from pathlib import Path

import mpmath
import numpy as np

from . import _mpmath_reference


STORE = Path(__file__).resolve().parents[1] / "data" / "special_references.npz"

REGISTRY = []
"""Every stored function (its ``wrapper``), for the writing script and the currency test."""


def key(function, args):
    """The name of one result in the file: module file, function and arguments."""
    return f"{Path(inspect.getfile(function)).stem}.{function.__name__}{tuple(args)!r}"


def fingerprint(function):
    """What the result of ``function`` depends on, as far as the tests change it: its module's source
    and the reference module's, and mpmath's version."""
    digest = hashlib.sha256()
    for path in (inspect.getfile(function), inspect.getfile(_mpmath_reference)):
        # Line ends as git stores them: a checkout that writes CRLF holds the same code.
        digest.update(Path(path).read_bytes().replace(b"\r\n", b"\n"))
    digest.update(mpmath.__version__.encode())
    return digest.hexdigest()


@functools.cache
def _contents():
    """{key: (fingerprint, value)} of the file, or {} where there is none."""
    if not STORE.exists():
        return {}
    with np.load(STORE, allow_pickle=False) as data:
        index = json.loads(str(data["index"]))
        return {name: (entry["fingerprint"], _decode(entry["structure"], data)) for name, entry in index.items()}


def stored(calls=((),)):
    """Decorator: ``functools.cache`` whose results for the argument tuples ``calls`` come from the file
    when their fingerprint is current (computed afresh otherwise)."""

    def decorate(function):
        @functools.cache
        def wrapper(*args):
            found = _contents().get(key(function, args))
            if found is not None and found[0] == fingerprint(function):
                return found[1]
            return function(*args)

        wrapper.compute = function
        wrapper.calls = [tuple(call) for call in calls]
        functools.update_wrapper(wrapper, function)
        REGISTRY.append(wrapper)
        return wrapper

    return decorate


def read(wrapper, args):
    """The result of ``wrapper(*args)`` as the file holds it (KeyError where it holds none)."""
    return _contents()[key(wrapper.compute, args)][1]


def current(wrapper, args):
    """Whether the file holds the result of ``wrapper(*args)`` with the current fingerprint."""
    found = _contents().get(key(wrapper.compute, args))
    return found is not None and found[0] == fingerprint(wrapper.compute)


# -------------------------------------------------------------------- the file's format (no pickle)


def encode(value, arrays, prefix):
    """A JSON description of ``value`` (dicts with string keys, tuples, lists, None, numbers, numpy
    arrays), its arrays appended to ``arrays`` as {name: array} under ``prefix``."""
    if value is None:
        return None
    if isinstance(value, dict):
        return {"dict": [[name, encode(item, arrays, prefix)] for name, item in value.items()]}
    if isinstance(value, (tuple, list)):
        return {type(value).__name__: [encode(item, arrays, prefix) for item in value]}
    array = np.asarray(value)
    if array.dtype == object:
        raise TypeError(f"cannot store a value of type {type(value).__name__}")
    name = f"{prefix}_{len(arrays)}"
    arrays[name] = array
    if isinstance(value, np.generic):
        scalar = "numpy"
    elif isinstance(value, (bool, int, float)):
        scalar = type(value).__name__
    else:
        scalar = None
    return {"array": name, "scalar": scalar}


def _decode(structure, data):
    if structure is None:
        return None
    if "dict" in structure:
        return {name: _decode(item, data) for name, item in structure["dict"]}
    if "tuple" in structure:
        return tuple(_decode(item, data) for item in structure["tuple"])
    if "list" in structure:
        return [_decode(item, data) for item in structure["list"]]
    array = data[structure["array"]]
    scalar = structure["scalar"]
    if scalar is None:
        return array
    return array[()] if scalar == "numpy" else {"bool": bool, "int": int, "float": float}[scalar](array[()])
