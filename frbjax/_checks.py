"""Checks of the arguments of the public entry points.

Every public callable refuses what it cannot use with a ``ValueError`` that names the argument and,
for a value, the first offending entry (its index and value), so that a caller can find the bad row
of a telemetry file.  Values are checked only when they are concrete: under ``jax.jit``, ``vmap`` or
``grad`` an argument is a tracer without a value, only its shape can be checked, and a body or sample
with invalid values gives NaN (as documented per entry point).  The checks are numpy on the host:
they compile nothing.
"""

from __future__ import annotations

import numbers
import operator

import jax
import numpy as np


# Row indices listed in a message (the count of all of them follows).
_LISTED_ROWS = 10


def is_concrete(*values) -> bool:
    """True when no leaf of ``values`` is a JAX tracer (the values can be read)."""
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves(values))


def on_host(value) -> bool:
    """True when ``value`` can be read without a transfer: concrete, and not a JAX array that lives
    on an accelerator (copying a large batch back to check it would cost more than evaluating it)."""
    if not is_concrete(value):
        return False
    if isinstance(value, jax.Array):
        return all(device.platform == "cpu" for device in value.devices())
    return True


def _index(position) -> str:
    return "[" + ", ".join(str(int(i)) for i in position) + "]" if len(position) else ""


def real_array(name: str, value) -> np.ndarray:
    """``value`` as a numpy array of real numbers (booleans and integers become floats).

    Raises ValueError naming ``name`` for anything that is not an array of real numbers: strings,
    objects, complex numbers, ragged nested lists.
    """
    try:
        array = np.asarray(value)
    except (ValueError, TypeError) as error:  # ragged nested sequences
        raise ValueError(f"{name} must be an array of real numbers: {error}") from None
    if array.dtype.kind not in "biuf":
        raise ValueError(
            f"{name} must be an array of real numbers, got dtype {array.dtype}"
            + (f" ({type(value).__name__})" if array.dtype == object else "")
        )
    return array


def check_finite(name: str, array) -> None:
    """Raise unless every entry is finite; the message gives the first offending entry."""
    array = np.asarray(array)
    bad = ~np.isfinite(array)
    if np.any(bad):
        position = np.argwhere(bad)[0]
        raise ValueError(f"{name} must be finite: {name}{_index(position)} is {array[tuple(position)].item()!r}")


def check_positive(name: str, array, *, allow_zero: bool = False) -> None:
    """Raise unless every entry is finite and > 0 (>= 0 with ``allow_zero``)."""
    check_finite(name, array)
    array = np.asarray(array)
    bad = array < 0 if allow_zero else array <= 0
    if np.any(bad):
        position = np.argwhere(bad)[0]
        relation = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be {relation}: {name}{_index(position)} is {array[tuple(position)].item()!r}")


def check_trailing_shape(name: str, array, trailing: tuple[int, ...]) -> None:
    """Raise unless ``array.shape`` ends with ``trailing`` (the leading axes are a batch)."""
    shape = tuple(np.shape(array))
    if len(shape) < len(trailing) or shape[len(shape) - len(trailing) :] != tuple(trailing):
        pattern = ", ".join(["..."] + [str(size) for size in trailing])
        raise ValueError(f"{name} must have shape ({pattern}), got shape {shape}")


def check_nonzero_rows(name: str, array, *, what: str = "a non-zero quaternion") -> None:
    """Raise unless every row (last axis) has a non-zero entry."""
    array = np.asarray(array)
    bad = ~np.any(array != 0, axis=-1)
    if np.any(bad):
        position = np.argwhere(bad)[0]
        raise ValueError(f"{name} must be {what}: {name}{_index(position)} is zero")


def unit_tolerance(dtype) -> float:
    """How far from 1 the norm of a unit vector or quaternion may be: rounding of data stored in
    ``dtype``, with room for data normalised in single precision and stored in double."""
    return 1e-3 if np.dtype(dtype) in (np.float16, np.float32) else 1e-6


def check_unit_rows(name: str, array, *, what: str = "unit quaternions") -> None:
    """Raise unless every row (last axis) has norm 1 to the rounding of its dtype (``unit_tolerance``)."""
    array = np.asarray(array)
    deviation = np.abs(np.linalg.norm(array.astype(float), axis=-1) - 1)
    bad = deviation > unit_tolerance(array.dtype)
    if np.any(bad):
        position = np.argwhere(bad)[0]
        raise ValueError(f"{name} must be {what}: |{name}{_index(position)}| - 1 is {deviation[tuple(position)]:.3g}")


def check_rotation_matrices(name: str, array) -> None:
    """Raise unless every (3, 3) matrix is orthogonal with determinant +1 (to ``unit_tolerance``)."""
    array = np.asarray(array)
    matrices = array.astype(float)
    residual = np.abs(np.swapaxes(matrices, -1, -2) @ matrices - np.eye(3)).max(axis=(-2, -1))
    determinant = np.linalg.det(matrices)
    bad = (residual > unit_tolerance(array.dtype)) | (determinant <= 0)
    if np.any(bad):
        position = np.argwhere(bad)[0]
        detail = (
            "its determinant is negative (a reflection)"
            if determinant[tuple(position)] <= 0
            else f"|R^T R - 1| is {residual[tuple(position)]:.3g}"
        )
        raise ValueError(f"{name} must be rotation matrices: at {name}{_index(position) or '[...]'} {detail}")


def nonfinite_rows(*arrays) -> np.ndarray:
    """Boolean (N,) mask of the rows (first axis) with a non-finite entry in any of ``arrays``."""
    rows = np.zeros(len(arrays[0]), bool)
    for array in arrays:
        array = np.asarray(array, float)
        rows |= ~np.isfinite(array.reshape(len(array), -1)).all(axis=-1)
    return rows


def describe_rows(rows) -> str:
    """'3, 17 and 40 (3 of 200)'-style list of the True rows of a mask."""
    indices = np.flatnonzero(rows)
    listed = ", ".join(str(i) for i in indices[:_LISTED_ROWS])
    more = (
        f", ... ({len(indices)} of {len(rows)})" if len(indices) > _LISTED_ROWS else f" ({len(indices)} of {len(rows)})"
    )
    return listed + more


def check_distinct_times(name: str, times, indices=None) -> None:
    """Raise when two times are equal (a fit needs one observation per epoch); ``indices``: the input
    index of each entry, for the message, when ``times`` is a selection of the input."""
    times = np.asarray(times)
    indices = np.arange(len(times)) if indices is None else np.asarray(indices)
    order = np.argsort(times, kind="stable")
    repeated = np.flatnonzero(np.diff(times[order]) == 0)
    if repeated.size:
        first, second = sorted(indices[order[repeated[0] : repeated[0] + 2]])
        raise ValueError(
            f"{name} must be distinct: {name}[{first}] and {name}[{second}] are both "
            f"{times[order[repeated[0]]].item()!r}"
        )


def integer(name: str, value, *, minimum: int | None = None) -> int:
    """``value`` as a Python int (an integer of any kind, not a bool or a float); >= ``minimum``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Integral, np.integer)):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    value = operator.index(value)
    if minimum is not None and value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    return value


def scalar(name: str, value, *, positive: bool = False, allow_zero: bool = False) -> float:
    """``value`` as a finite Python float; > 0 with ``positive`` (>= 0 with ``allow_zero`` too)."""
    array = real_array(name, value)
    if array.shape != ():
        raise ValueError(f"{name} must be a scalar, got shape {array.shape}")
    if positive:
        check_positive(name, array, allow_zero=allow_zero)
    else:
        check_finite(name, array)
    return float(array)


def choice(name: str, value, options) -> None:
    """Raise unless ``value`` is one of ``options``."""
    if not isinstance(value, str) or value not in options:
        raise ValueError(f"{name} must be one of {sorted(options)}, got {value!r}")


def interval(name: str, value, *, positive: bool = True, upper: float | None = None) -> tuple[float, float]:
    """``value`` as a range (low, high) with finite low < high (> 0 when ``positive``; <= ``upper``)."""
    array = real_array(name, value)
    if array.shape != (2,):
        raise ValueError(f"{name} must be a range (low, high), got shape {array.shape}")
    if positive:
        check_positive(name, array)
    else:
        check_finite(name, array)
    low, high = (float(v) for v in array)
    if not low < high:
        raise ValueError(
            f"{name} must be a range (low, high) with low < high, got ({low!r}, {high!r})"
            + (" (given upside down?)" if low > high else "")
        )
    if upper is not None and high > upper:
        raise ValueError(f"{name} must lie within (0, {upper}], got ({low!r}, {high!r})")
    return low, high
