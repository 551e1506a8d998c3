"""Posteriors, not only fits: Bayesian inertia ratios and spin state through the exact motion.

- :func:`attitude_posterior`: the posterior of the parameters of :func:`frbjax.fit_attitude`
  (inertia ratios, angular velocity and attitude; the principal axes for an inertia tensor) from
  attitude (and gyro) data, sampled by numpyro's NUTS with the exact motion's gradients.
- :class:`AttitudePosterior`: its draws as arrays, split R-hat, bulk and tail effective sample
  sizes, divergences, ``summary()``, ``mode_probabilities()`` (short- or long-axis mode) and
  ``to_arviz()``; :class:`PosteriorWarning` when the diagnostics fail.
- :func:`lightcurve_posterior`: the posterior of a :func:`frbjax.lightcurve.fit_lightcurve` fit's spin
  state, inertia ratios and periods (the shape at its fitted values), as :class:`LightcurvePosterior`.
- :class:`TriangleLogUniform`, :class:`IsotropicRotation`: the default prior's distributions (numpyro
  distributions, usable in a prior of your own).

Imported on first use (``frbjax.posterior``); it needs numpyro (and optimistix, for the fit).
"""

from ._attitude import attitude_posterior
from ._lightcurve import lightcurve_posterior
from ._prior import IsotropicRotation, TriangleLogUniform
from ._result import AttitudePosterior, LightcurvePosterior, PosteriorSummary, PosteriorWarning


__all__ = [
    "AttitudePosterior",
    "IsotropicRotation",
    "LightcurvePosterior",
    "PosteriorSummary",
    "PosteriorWarning",
    "TriangleLogUniform",
    "attitude_posterior",
    "lightcurve_posterior",
]
