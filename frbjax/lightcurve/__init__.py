"""Light curves of tumbling bodies: convex shapes, the brightness forward model and its inversion.

- :class:`ConvexShape`: a convex body as its Gaussian image (facet normals and areas in the principal
  frame), from a mesh or a triaxial ellipsoid, with its polyhedron (Minkowski's problem) and inertia.
- :func:`brightness`: the flux of a :class:`frbjax.FreeRigidBody` of a given shape lit by the Sun and
  seen by an observer (Lambert, Lommel-Seeliger and their combination; Kaasalainen & Torppa 2001).
- :func:`tumbler_periods`: the two periods (precession P_psi, rotation P_phi) of a free motion.
- :func:`tumbler_periodogram`: candidate ranges of the two periods from the light curves themselves
  (a two-period Fourier periodogram, Pravec et al. 2005), for :func:`fit_lightcurve`'s ``periods``.
- :func:`fit_lightcurve`: the spin state, inertia ratios and shape from relative photometry.

Imported on first use (``frbjax.lightcurve``); it needs optimistix and scipy.
"""

from ._brightness import brightness, facet_brightness, LAWS
from ._fit import AmbiguousFitWarning, CompetingBasins, fit_lightcurve, LightcurveFit, MisfitWarning
from ._periodogram import tumbler_periodogram, TumblerPeriodogram
from ._periods import tumbler_periods
from ._shape import ConvexShape, icosphere, mesh_inertia


__all__ = [
    "LAWS",
    "AmbiguousFitWarning",
    "CompetingBasins",
    "ConvexShape",
    "LightcurveFit",
    "MisfitWarning",
    "TumblerPeriodogram",
    "brightness",
    "facet_brightness",
    "fit_lightcurve",
    "icosphere",
    "mesh_inertia",
    "tumbler_periodogram",
    "tumbler_periods",
]
