"""Errors of the fits."""

from __future__ import annotations


class FitError(RuntimeError):
    """A fit did not converge: its best start is not a solution.

    Raised by :func:`frbjax.fit_attitude` and :func:`frbjax.lightcurve.fit_lightcurve` (with their
    default ``throw=True``) instead of returning a result whose parameters are wherever the solver
    stopped, which may be the start itself.  ``result`` holds that unconverged result for inspection
    (its ``success`` is False); ``throw=False`` returns it instead of raising.
    """

    def __init__(self, message: str, result):
        super().__init__(message)
        self.result = result
