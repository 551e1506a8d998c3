"""A family of synthetic tumblers observed as users observe them: light curves to search for periods.

Each member (``tumbler(index)``, or ``family()`` for all of them) is a torque-free body of random
moments (I3 = 1) with a shape outside any model's family (the convex hull of 1000 points of a bumpy
ellipsoid with random axes and random low-order bumps, about 2000 facets, its long axis along the axis
of the smallest moment), in one of the kinds users meet (``KINDS``):

- ``"PA"``: a principal-axis rotator (L along the axis of the largest moment);
- ``"SAM near PA"``: short-axis mode with 2 E I3 / |L|^2 = 1.01 to 1.02 (a slight wobble);
- ``"SAM Apophis"``: short-axis mode at Apophis-like energies, 2 E I3 / |L|^2 = 1.02 to 1.05;
- ``"SAM separatrix"``, ``"LAM separatrix"``: either side of the separatrix, 2 E I2 / |L|^2 = 0.97 to
  0.99 and 1.01 to 1.03;
- ``"LAM"``: long-axis mode, 2 E I2 / |L|^2 = 1.05 to 1.4 (within the mode's bound I2 / I1).

The precession period P_psi is log-uniform from 3 hours to 2 days (|L| scaled to it).  Observation:
24 nights on distinct days over a span of 90 to 150 days, each night 36 to 44 samples over 6 to 8
hours starting at about the same hour (as from one site: the 1 / day alias of real data), a slowly
changing geometry (the Sun's longitude moving 0.3 to 0.7 degrees a day, the phase angle between 5 and
45 degrees), 1% noise (log flux), one unknown scale per night (relative photometry); and four later
nights, 5 to 30 days after the last, held out (with their own scales) for benchmarks that predict.
The scattering law is Lommel-Seeliger-Lambert (frbjax's default).  Deterministic by index and seed.

A plain module: numpy arrays and the true body and periods.

    from _tumbler_family import family
    for case in family():
        case.times, case.flux, case.sun, case.observer, case.night, case.periods, case.body
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
from scipy.spatial import ConvexHull

from frbjax import FreeRigidBody
from frbjax.lightcurve import brightness, ConvexShape, fit_lightcurve, tumbler_periods


NOISE = 0.01
NIGHTS = 24
HELD_OUT_NIGHTS = 4
HULL_POINTS = 1000
FACETS = 2 * HULL_POINTS - 4  # every point on the hull: the shapes are padded to this many facets
# The kinds and how many of each (24 in all).
KINDS = (
    ("PA", 2),
    ("SAM near PA", 5),
    ("SAM Apophis", 5),
    ("SAM separatrix", 3),
    ("LAM separatrix", 3),
    ("LAM", 6),
)
SIZE = sum(count for _, count in KINDS)


@dataclasses.dataclass(frozen=True)
class Tumbler:
    """One member: data (``times`` in days from the body's epoch, ``flux`` with its per-night scales,
    unit vectors ``sun`` and ``observer``, ``night`` labels), the held-out nights likewise
    (``held_out``: a dict of the same five arrays and ``noiseless``, the true flux without noise or
    scale), and the truth."""

    index: int
    kind: str
    times: np.ndarray
    flux: np.ndarray
    sun: np.ndarray
    observer: np.ndarray
    night: np.ndarray
    held_out: dict
    inertia: np.ndarray  # (I1, I2, I3), I3 = 1
    angular_momentum: np.ndarray  # body frame at t = 0
    attitude: np.ndarray  # quaternion at t = 0
    periods: tuple  # (P_psi, P_phi) in days (P_phi infinite for a principal-axis rotator)
    long_axis: bool
    energy_ratio: float  # 2 E I3 / |L|^2
    shape_axes: np.ndarray

    @property
    def body(self) -> FreeRigidBody:
        return FreeRigidBody(self.inertia, self.angular_momentum, self.attitude)

    @property
    def span(self) -> float:
        return float(self.times.max() - self.times.min())

    def held_out_data(self, noiseless: bool = True) -> tuple:
        """The held-out nights as ``(times, flux, sun, observer, night)`` (the held-out argument of
        benchmarks/lightcurve.py's ``problems.held_out_rms``), the flux the noiseless truth's or, with
        ``noiseless=False``, the data's."""
        flux = "noiseless" if noiseless else "flux"
        return tuple(self.held_out[key] for key in ("times", flux, "sun", "observer", "night"))

    def body_at(self, epoch: float) -> FreeRigidBody:
        """The true motion with its time counted from ``epoch`` (a fit's ``initial=``; fit_lightcurve's
        default epoch is the median time)."""
        body = self.body
        return FreeRigidBody(self.inertia, np.asarray(body.angular_momentum(epoch)), np.asarray(body.quaternion(epoch)))

    def refine_from_truth(self, width: float = 0.1, **options):
        """The same data refined from the true motion: ``fit_lightcurve`` from ``initial=`` the truth
        (its time from the fit's default epoch, the median time), one search round (and no more where
        the truth's own residuals are above the noise bound: ``max_search_rounds`` as many), the periods'
        ranges +-``width`` around the true ones, the principal-axis model for a rotator; ``options``
        (e.g. ``mirror_pole=False``: the truth's own basin, whatever its mirror's cost) pass on.  The
        reference cost the data allow in the truth's basin, for the benchmarks that compare a search
        with it."""
        rotator = self.kind == "PA"
        rounds = options.pop("search_rounds", 1)
        max_rounds = options.pop("max_search_rounds", rounds)
        ranges = tuple((p * (1 - width), p * (1 + width)) for p in (self.periods[:1] if rotator else self.periods))
        return fit_lightcurve(
            self.times,
            self.flux,
            self.sun,
            self.observer,
            lightcurve=self.night,
            periods=ranges[0] if rotator else ranges,
            principal_axis=rotator,
            initial=self.body_at(float(np.median(self.times))),
            throw=False,
            progress=False,
            search_rounds=rounds,
            max_search_rounds=max_rounds,
            **options,
        )

    def moments_z(self, moments, sigma) -> list:
        """|I - I_true| / sigma for a fit's two smaller moments (``moments`` scaled to a largest of 1,
        the true moments matched to them by rank; a rotator's are fixed: none)."""
        if self.kind == "PA":
            return []
        moments, sigma = np.asarray(moments, float), np.asarray(sigma, float)
        true = np.sort(self.inertia / np.max(self.inertia))[np.argsort(np.argsort(moments))]
        smaller = moments < 1
        return (np.abs(moments - true)[smaller] / sigma[smaller]).tolist()


def _kind(index):
    start = 0
    for kind, count in KINDS:
        if index < start + count:
            return kind
        start += count
    raise IndexError(f"the family has {SIZE} members, got index {index}")


def _shape(rng, inertia):
    """A bumpy ellipsoid's convex hull: axes from the moments (a uniform ellipsoid's, perturbed 10%),
    random bumps (three random low-order terms of 2% to 6% each)."""
    i1, i2, i3 = inertia
    axes = np.sqrt(np.maximum([i2 + i3 - i1, i1 + i3 - i2, i1 + i2 - i3], 0.05))
    axes = axes / axes[1] * rng.uniform(0.9, 1.1, 3)
    axes = np.sort(axes)[::-1]  # the longest along axis 1 (smallest moment)
    directions = rng.normal(size=(HULL_POINTS, 3))
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    bumps = np.ones(HULL_POINTS)
    for _ in range(3):
        frequency = rng.integers(1, 4, 3)
        phase = rng.uniform(0, 2 * np.pi, 3)
        bumps += rng.uniform(0.02, 0.06) * np.prod(np.sin(frequency * directions + phase), -1)
    points = directions * axes * bumps[:, None]
    hull = ConvexHull(points)
    shape = ConvexShape.from_mesh(points, hull.simplices)
    normals = np.zeros((FACETS, 3))
    normals[:, 2] = 1.0
    areas = np.zeros(FACETS)
    count = len(hull.simplices)
    normals[:count] = np.asarray(shape.normals)
    areas[:count] = np.asarray(shape.areas)
    return normals, areas, axes


def _moments(rng, kind):
    """Sorted moments (I3 = 1) and the energy ratio 2 E I3 / |L|^2 of the kind."""
    while True:
        i1 = rng.uniform(0.45, 0.85)
        i2 = rng.uniform(i1 + 0.05, 0.97)
        separatrix = 1 / i2  # 2 E I3 / |L|^2 on the separatrix
        if kind == "PA":
            return np.array([i1, i2, 1.0]), 1.0
        if kind == "SAM near PA":
            ratio = rng.uniform(1.01, 1.02)
        elif kind == "SAM Apophis":
            ratio = rng.uniform(1.02, 1.05)
        elif kind == "SAM separatrix":
            ratio = separatrix * rng.uniform(0.97, 0.99)
        elif kind == "LAM separatrix":
            ratio = separatrix * rng.uniform(1.01, 1.03)
        else:
            ratio = separatrix * rng.uniform(1.05, 1.4)
        # Within the mode: SAM 1 < ratio < 1/I2 (with a margin), LAM 1/I2 < ratio < 1/I1.
        if kind.startswith("SAM") and ratio < 0.995 * separatrix:
            return np.array([i1, i2, 1.0]), ratio
        if kind.startswith("LAM") and ratio < 0.95 / i1:
            return np.array([i1, i2, 1.0]), ratio


def _direction(rng, inertia, ratio):
    """A unit body-frame L with 2 E I3 / |L|^2 = ratio: on the energy ellipsoid's intersection with the
    sphere, at a random point of its polhode (the motion is periodic: any point of it will do)."""
    i1, i2, i3 = inertia
    d = ratio / i3  # sum l_i^2 / I_i = d, sum l_i^2 = 1
    # l2^2 = s in [0, s_max] free, then l1^2 and l3^2 from the two equations.
    s_max = (d - 1 / i3) / (1 / i2 - 1 / i3) if d < 1 / i2 else (1 / i1 - d) / (1 / i1 - 1 / i2)
    s = rng.uniform(0, min(s_max, 1.0)) if ratio > 1 else 0.0
    l1_squared = (d - 1 / i3 - s * (1 / i2 - 1 / i3)) / (1 / i1 - 1 / i3)
    l3_squared = 1 - s - l1_squared
    signs = rng.choice([-1.0, 1.0], 3)
    return signs * np.sqrt(np.maximum([l1_squared, s, l3_squared], 0.0))


def _geometry(rng, nights, span, start, hour):
    """Times (days), the Sun's and the observer's unit vectors, night labels."""
    days = np.sort(rng.choice(int(span), nights, replace=False)) + start
    times, labels = [], []
    for k, day in enumerate(days):
        count = rng.integers(36, 45)
        length = rng.uniform(0.25, 0.333)
        begin = day + hour + rng.uniform(-0.03, 0.03)
        times.append(begin + np.sort(rng.uniform(0, length, count)))
        labels.append(np.full(count, k))
    return np.concatenate(times), np.concatenate(labels)


def _directions(times, rate, phase_low, phase_high, tilt):
    longitude = np.deg2rad(30 + rate * times)
    sun = np.stack([np.cos(longitude), np.sin(longitude), tilt * np.sin(times / 40)], -1)
    sun /= np.linalg.norm(sun, axis=-1, keepdims=True)
    phase_angle = np.deg2rad(phase_low + (phase_high - phase_low) * np.sin(np.pi * times / 150) ** 2)
    axis = np.stack([np.zeros_like(times), 0.3 + 0 * times, 1 + 0 * times], -1)
    axis -= np.sum(axis * sun, -1, keepdims=True) * sun
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    observer = np.cos(phase_angle)[:, None] * sun + np.sin(phase_angle)[:, None] * np.cross(axis, sun)
    return sun, observer


@jax.jit
def _flux(inertia, momentum, attitude, normals, areas, times, sun, observer):
    body = FreeRigidBody(inertia, momentum, attitude)
    return brightness(body, ConvexShape(normals, areas), times, sun, observer)


def tumbler(index: int, seed: int = 0, nights: int = NIGHTS, per_night: float = 1.0) -> Tumbler:
    """The family's member ``index`` (0 to SIZE - 1) for ``seed``; ``nights`` and ``per_night`` (a
    fraction of each night's samples kept, evenly) shrink it for quick tests."""
    kind = _kind(index)
    rng = np.random.default_rng([seed, index])
    inertia, ratio = _moments(rng, kind)
    normals, areas, axes = _shape(rng, inertia)
    direction = np.array([0.0, 0.0, 1.0]) if kind == "PA" else _direction(rng, inertia, ratio)
    p_psi_unit = float(tumbler_periods(inertia, direction)[0])
    precession = float(np.exp(rng.uniform(np.log(0.125), np.log(2.0))))  # 3 hours to 2 days
    momentum = direction * p_psi_unit / precession
    attitude = rng.normal(size=4)
    attitude /= np.linalg.norm(attitude)
    p_psi, p_phi, long_axis = (np.asarray(x) for x in tumbler_periods(inertia, momentum))

    span = float(rng.uniform(90, 150))
    hour = rng.uniform(0.1, 0.5)
    times, night = _geometry(rng, NIGHTS, span, 0.0, hour)
    later, later_night = _geometry(rng, HELD_OUT_NIGHTS, 25, span + 5, hour)
    rate, low, high, tilt = rng.uniform(0.3, 0.7), rng.uniform(5, 15), rng.uniform(25, 45), rng.uniform(0, 0.2)
    all_times = np.concatenate([times, later])
    sun, observer = _directions(all_times, rate, low, high, tilt)
    noiseless = np.asarray(_flux(inertia, momentum, attitude, normals, areas, all_times, sun, observer))
    flux = noiseless * np.exp(NOISE * rng.normal(size=noiseless.shape))
    labels = np.concatenate([night, NIGHTS + later_night])
    flux = flux * np.exp(rng.normal(size=NIGHTS + HELD_OUT_NIGHTS))[labels]

    keep = np.ones(len(all_times), bool)
    keep[len(times) :] = True
    if nights < NIGHTS or per_night < 1.0:
        chosen = np.sort(rng.choice(NIGHTS, nights, replace=False)) if nights < NIGHTS else np.arange(NIGHTS)
        keep[: len(times)] = False
        for k in chosen:
            rows = np.flatnonzero(night == k)
            step = max(1, round(1 / per_night))
            keep[rows[::step]] = True
    fit = keep & (np.arange(len(all_times)) < len(times))
    held = np.arange(len(all_times)) >= len(times)
    return Tumbler(
        index=index,
        kind=kind,
        times=all_times[fit],
        flux=flux[fit],
        sun=sun[fit],
        observer=observer[fit],
        night=labels[fit],
        held_out=dict(
            times=all_times[held],
            flux=flux[held],
            sun=sun[held],
            observer=observer[held],
            night=labels[held],
            noiseless=noiseless[held],
        ),
        inertia=inertia,
        angular_momentum=momentum,
        attitude=attitude,
        periods=(float(p_psi), float(p_phi)),
        long_axis=bool(long_axis),
        energy_ratio=float(np.sum(momentum**2 / inertia) / np.sum(momentum**2)),
        shape_axes=axes,
    )


def family(seed: int = 0, **options) -> list[Tumbler]:
    """All SIZE members for ``seed`` (``options``: those of :func:`tumbler`)."""
    return [tumbler(index, seed, **options) for index in range(SIZE)]
