"""tests/data/special_references.npz (tests/special/_stored.py): it holds the current result of every
stored grid, and a result read from it is, array for array and type for type, what its function
computes."""

from __future__ import annotations

import numpy as np

from . import _stored, test_gradients, test_legendre, test_second_derivatives  # noqa: F401  (their grids register)


def test_the_stored_references_are_current():
    """Every stored grid's result is in the file with the fingerprint of its code (a stale one is
    computed afresh: the tests stay right, only slower)."""
    assert len(_stored.REGISTRY) == 11  # test_legendre 5, test_gradients 5, test_second_derivatives 1
    stale = [
        _stored.key(wrapper.compute, args)
        for wrapper in _stored.REGISTRY
        for args in wrapper.calls
        if not _stored.current(wrapper, args)
    ]
    assert not stale, f"run tests/data/make_special_references.py: {len(stale)} stale or missing, {stale[:3]}"


def _assert_same(stored, computed, where="result"):
    assert type(stored) is type(computed), (where, type(stored), type(computed))
    if isinstance(computed, dict):
        assert list(stored) == list(computed), where
        for name in computed:
            _assert_same(stored[name], computed[name], f"{where}[{name!r}]")
    elif isinstance(computed, (tuple, list)):
        assert len(stored) == len(computed), where
        for i, (a, b) in enumerate(zip(stored, computed)):
            _assert_same(a, b, f"{where}[{i}]")
    elif computed is not None:
        assert np.shape(stored) == np.shape(computed) and np.asarray(stored).dtype == np.asarray(computed).dtype, where
        np.testing.assert_array_equal(stored, computed, err_msg=where)


def test_a_stored_reference_is_what_its_function_computes():
    """Two grids cheap to compute (0.1 s): R_C's derivatives and the complete integrals' (a dict of
    arrays), read back from the file and computed afresh."""
    for wrapper, args in ((test_gradients.carlson_grid, ("elliprc",)), (test_gradients.complete_grid, ())):
        _assert_same(_stored.read(wrapper, args), wrapper.compute(*args))
