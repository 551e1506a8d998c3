"""frbjax.lightcurve.fit_lightcurve on synthetic tumblers, without inverse crime.

The data come from a finer and different shape than the model's: a convex hull of 2000 points of a
bumpy ellipsoid (the model: log-areas on the 320 facet normals of an icosphere), lit and seen along
a changing geometry (phase angle 10 to 40 degrees, the Sun's direction moving 45 degrees), two dozen
nights over 90 days (8 samples in 6 hours each for the SAM), each night its own light curve (relative
photometry), 1% noise.  The tumblers have Apophis's moments (0.61 : 0.965 : 1; E/E0 = 1.024 for
the SAM, 1.2 for the LAM) but spin faster (P_psi = 4.8 hours): 450 precession cycles in 90 days,
where Apophis's own 1.14-day P_psi gives 79 and leaves P_phi a standard error of 8.7e-4, above the
1e-4 asked.  The fit gets ranges of +-0.5% around centres 0.23% off the true periods (a grid of the two
periods times random states: inertia ratios, energy, phases, attitude) and must find the periods,
the inertia ratios, and predict four later nights (held out).
"""

from __future__ import annotations

import jax
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from frbjax import FreeRigidBody
from frbjax.lightcurve import brightness, ConvexShape, fit_lightcurve, mesh_inertia, tumbler_periods


NOISE = 0.01

ATTITUDE = np.array([0.8, 0.3, -0.4, 0.33]) / np.linalg.norm([0.8, 0.3, -0.4, 0.33])


def geometry(nights, per_night=8, span=90.0, start=0.0, seed=0):
    """Times (days), Sun and observer directions, and the night of each sample."""
    rng = np.random.default_rng(seed)
    night_times = np.sort(rng.uniform(0, span, nights)) + start
    times = (night_times[:, None] + np.linspace(0, 0.25, per_night)[None]).reshape(-1)
    longitude = np.deg2rad(30 + 0.5 * times)
    sun = np.stack([np.cos(longitude), np.sin(longitude), 0.1 * np.sin(times / 40)], -1)
    sun /= np.linalg.norm(sun, axis=-1, keepdims=True)
    phase_angle = np.deg2rad(10 + 30 * np.sin(np.pi * times / 150) ** 2)
    axis = np.stack([np.zeros_like(times), 0.3 + 0 * times, 1 + 0 * times], -1)
    axis -= np.sum(axis * sun, -1, keepdims=True) * sun
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    observer = np.cos(phase_angle)[:, None] * sun + np.sin(phase_angle)[:, None] * np.cross(axis, sun)
    return times, sun, observer, np.repeat(np.arange(nights), per_night)


def true_shape():
    """A bumpy ellipsoid's convex hull (not an ellipsoid, not the model's facets), and the principal
    moments of the hull at uniform density (scaled to a largest of 1)."""
    rng = np.random.default_rng(11)
    directions = rng.normal(size=(2000, 3))
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    bumps = 1 + 0.04 * np.sin(3 * directions[:, 0]) * np.cos(2 * directions[:, 1])
    points = directions * np.array([1.35, 1.0, 0.8]) * bumps[:, None]
    faces = ConvexHull(points).simplices
    moments = np.diag(np.asarray(mesh_inertia(points, faces)[2]))
    return ConvexShape.from_mesh(points, faces), moments / moments.max()


SHAPE, SHAPE_MOMENTS = true_shape()


def observe(body, seed, per_night=8):
    times, sun, observer, night = geometry(24, per_night, seed=seed)
    later = geometry(4, per_night, span=20.0, start=100.0, seed=seed + 1)
    rng = np.random.default_rng(seed + 2)
    epoch = float(np.median(times))
    flux = np.asarray(
        brightness(
            body,
            SHAPE,
            np.concatenate([times, later[0]]) - epoch,
            np.concatenate([sun, later[1]]),
            np.concatenate([observer, later[2]]),
        )
    )
    flux = flux * np.exp(NOISE * rng.normal(size=flux.shape))
    # Relative photometry: each night its own unknown scale.
    scales = np.exp(rng.normal(size=28))
    nights = np.concatenate([night, 24 + later[3]])
    flux = flux * scales[nights]
    fit_part = slice(0, len(times))
    held_out = slice(len(times), None)
    return (times, flux[fit_part], sun, observer, night), (later[0], flux[held_out], later[1], later[2], later[3])


def held_out_rms(result, held_out):
    """RMS of log(data / model) over the held-out nights, each night's scale fitted."""
    times, flux, sun, observer, night = held_out
    difference = np.log(flux) - np.log(np.asarray(result.predict(times, sun, observer)))
    for k in np.unique(night):
        difference[night == k] -= difference[night == k].mean()
    return float(np.sqrt(np.mean(difference**2)))


def momentum_with_energy(inertia, energy_ratio, magnitude):
    """Body-frame L (l2 = 0) with 2 E I3 / |L|^2 = energy_ratio, I3 the largest."""
    i1, _, i3 = inertia
    l1_squared = (energy_ratio - 1) / (i3 / i1 - 1)
    return magnitude * np.array([np.sqrt(l1_squared), 0.0, np.sqrt(1 - l1_squared)])


# One round where it fits within the noise (stop_at_noise): these tests measure the fit's accuracy,
# not the search's later rounds (tests/test_lightcurve_nan_policy.py runs those).
FIT_OPTIONS = dict(shape="convex", convex_subdivisions=2, period_grid=(3, 3), stop_at_noise=True)
PRECESSION_PERIOD = 0.2  # days
# The search's ranges: +-0.5% around centres 0.23% from the true periods, so that no point of the
# search's grid of periods is the truth.
RANGE_OFFSET = 0.0023
# The sizes of the tests (benchmarks/lightcurve.py runs the full-size inversions, 16 samples a night,
# 128 starts per cell of the period grid, 16 refined).  The SAM at half the samples and starts: 192
# samples still give periods to 1e-4 and the inertia ratios to 0.2%, and 64 starts in each of the 9
# cells still find the basin.  The LAM keeps the full samples and starts: with 64 starts (16 samples,
# 8 refined) it ended in a neighbouring basin, moments 2.6% off (2026-11-29).  Both refine 4
# candidates: the search must rank the true basin among its best four, which is what the test asks of
# it; 8 and 16 refined found the same basin (LAM: the same digits; 47 s and 79 s on one core against
# 41 s), and the refinement's time grows with their number.
SAMPLES_PER_NIGHT = 16  # the full size, which benchmarks/lightcurve.py and the notebook observe
SIZES = {
    "SAM": dict(samples_per_night=SAMPLES_PER_NIGHT // 2, starts_per_period=64, n_refine=4),
    "LAM": dict(samples_per_night=SAMPLES_PER_NIGHT, starts_per_period=128, n_refine=4),
}


# Measured at the sizes above and the default shape weights (100, 4) (relative errors; the issue asks
# periods to 1e-4; 2026-12-07): SAM P_psi 3.6e-6, P_phi 9.3e-6 (relative standard errors 1.6e-5,
# 1.2e-4), moments 0.12% and 0.15%, held-out nights 1.09% rms, the fitted shape's uniform-density
# moments against the true hull's (0.582 : 0.873 : 1), in the fitted body's axes, 2.8% and 0.63%.  LAM:
# P_psi 2.1e-6, P_phi 4.0e-6 (standard errors 2.5e-6, 1.3e-5), moments 1.9% and 1.8%, held-out 0.97%
# rms, shape 0.41% and 0.14%.  The true motion and shape give 0.90% on the same held-out nights (the
# noise).  (At the former weights (10, 1), 2026-11-29: SAM periods 8.1e-6 and 8.0e-5, moments 0.005%
# and 0.16%, held-out 1.11%, shape 4.0%; LAM periods 2.6e-6 and 3.9e-6, moments 2.1% and 1.9%,
# held-out 1.04%, shape 0.52%.)  The search's random states are seed 0 (fit_lightcurve's default);
# benchmarks/lightcurve.py recovers both tumblers with four seeds each over wider ranges.
BOUNDS = {
    "SAM": dict(periods=(4.5e-6, 1.2e-5), inertia=0.0018, held_out=0.0115, shape=0.032),
    "LAM": dict(periods=(2.6e-6, 4.6e-6), inertia=0.022, held_out=0.0103, shape=0.005),
}


# Slow: a light-curve inversion, its programs compiled (the search, the Levenberg-Marquardt refinement
# with the ellipsoid and with the convex shape: about 20 s of XLA's compilation) and run.  Measured on
# one core (2026-11-29): SAM 26 s, LAM 41 s; the SAM with the shape's resolution error (one more solve, at
# 1280 normals: its compilation and run) 78 s (2026-12-05).
@pytest.mark.parametrize(
    "energy_ratio,long_axis",
    [pytest.param(1.024, False, marks=pytest.mark.slow), pytest.param(1.2, True, marks=pytest.mark.slow)],
    ids=["SAM", "LAM"],
)
def test_tumbler_recovered(energy_ratio, long_axis):
    inertia = np.array([0.61, 0.965, 1.0])  # Apophis-like
    direction = momentum_with_energy(inertia, energy_ratio, 1.0)
    p_psi, _, _ = tumbler_periods(inertia, direction)
    momentum = direction * float(p_psi) / PRECESSION_PERIOD
    body = FreeRigidBody(inertia, momentum, ATTITUDE)
    periods = np.array([float(p) for p in tumbler_periods(inertia, momentum)[:2]])
    size = SIZES["LAM" if long_axis else "SAM"]
    data, held_out = observe(body, seed=3, per_night=size["samples_per_night"])
    times, flux, sun, observer, night = data
    ranges = tuple((p * (1 + RANGE_OFFSET - 0.005), p * (1 + RANGE_OFFSET + 0.005)) for p in periods)
    result = fit_lightcurve(
        times,
        flux,
        sun,
        observer,
        lightcurve=night,
        periods=ranges,
        mode="LAM" if long_axis else "SAM",
        starts_per_period=size["starts_per_period"],
        n_refine=size["n_refine"],
        # The shape's resolution error (one more solve, at 1280 normals) is checked on the SAM alone.
        resolution_error=not long_axis,
        **FIT_OPTIONS,
    )
    period_error = np.abs(np.asarray(result.periods) / periods - 1)
    inertia_error = np.abs(np.sort(np.asarray(result.inertia)) / inertia - 1)
    print(
        f"{'LAM' if long_axis else 'SAM'}: periods {np.asarray(result.periods)} (true {periods}), "
        f"relative error {period_error}, sigma {np.asarray(result.period_sigma)}; inertia "
        f"{np.asarray(result.inertia)} error {inertia_error}; held-out rms {held_out_rms(result, held_out):.4f}; "
        f"fit rms {np.sqrt(np.mean(np.asarray(result.residuals) ** 2)):.4f}"
    )
    # The fit may order the body's axes differently from the truth's: compare axis by axis in the
    # order of the fitted moments.
    shape_moments = result.shape_inertia()[0][np.argsort(np.asarray(result.inertia))]
    shape_error = np.abs(shape_moments / SHAPE_MOMENTS - 1)
    print(f"shape moments {shape_moments} (true hull {SHAPE_MOMENTS}), error {shape_error}")
    bounds = BOUNDS["LAM" if long_axis else "SAM"]
    if not long_axis:
        inertia_z = (
            np.abs(np.sort(np.asarray(result.inertia)) - inertia)[:2]
            / np.asarray(result.inertia_sigma)[np.argsort(np.asarray(result.inertia))][:2]
        )
        print(
            f"finer shape: periods {np.asarray(result.resolution_periods)} "
            f"+- {np.asarray(result.resolution_period_sigma)}, "
            f"moments {np.asarray(result.resolution_inertia)}; sigmas {np.asarray(result.basin_period_sigma)} "
            f"(the model's {result.standard_errors(result.covariance)[0]}); moments' |z| {inertia_z}"
        )
        # Measured (2026-12-07, weights (100, 4)): the finer shape's periods 7.5e-6 and 2.7e-5 relative
        # from the coarser's, sigmas 3.2e-6 and 2.3e-4 days (the model's 2.4e-6 and 2.0e-4), the moments
        # 0.06 and 1.06 of their sigmas from the truth (at (10, 1): 0.02 and 0.85).
        assert np.all(np.isfinite(np.asarray(result.resolution_periods)))
        assert np.all(np.asarray(result.basin_period_sigma) >= np.asarray(result.resolution_period_sigma))
        assert np.all(np.asarray(result.basin_period_sigma) > result.standard_errors(result.covariance)[0])
        assert np.all(inertia_z < 1.2)

    assert np.all(shape_error < bounds["shape"])
    assert np.all(period_error < np.array(bounds["periods"]))
    assert np.all(inertia_error < bounds["inertia"])
    assert held_out_rms(result, held_out) < bounds["held_out"]


@pytest.mark.slow  # a light-curve inversion: compiling it takes about a minute (68 s in CI's tier, 2026-11-28)
def test_principal_axis_rotator_recovered():
    period = 0.3  # days
    inertia = np.array([0.6, 0.8, 1.0])
    # L along the largest axis: its inertial direction is R(q0) e3.
    body = FreeRigidBody(inertia, np.array([0.0, 0.0, 2 * np.pi / period]), ATTITUDE)
    data, held_out = observe(body, seed=4)
    times, flux, sun, observer, night = data
    result = fit_lightcurve(
        times,
        flux,
        sun,
        observer,
        lightcurve=night,
        periods=(0.2985, 0.3015),
        principal_axis=True,
        shape="ellipsoid",
        period_grid=(9,),
        starts_per_period=32,
        n_refine=8,
    )
    axis = np.asarray(body.rotation_matrix(np.zeros(1)))[0] @ np.array([0.0, 0.0, 1.0])
    print(
        f"PA: period {float(result.periods[0])} (true {period}), axis {np.asarray(result.momentum_direction)} "
        f"(true {axis}), held-out rms {held_out_rms(result, held_out):.4f}"
    )
    # Measured: period 1.0e-5 relative, spin axis 4.0 degrees off, held-out nights 1.21% rms.
    assert abs(float(result.periods[0]) / period - 1) < 1.3e-5
    assert np.degrees(np.arccos(abs(np.dot(np.asarray(result.momentum_direction), axis)))) < 4.5
    assert held_out_rms(result, held_out) < 0.0125


# Slow: compiling the inversion's programs (the search and the ellipsoid's refinement) takes about
# 65 s of CPU at any size (measured 65.5 s).
@pytest.mark.slow
def test_initial_motion_is_refined_on_all_the_data():
    """``initial=`` (an earlier fit) is refined beside the search's starts, on all the data from the
    start.  Through the continuation windows a start at the true motion left it (cost 79, periods
    6.5% and 9.3% off).  A small problem: 8 nights of 8 samples over 30 days, the model's own ellipsoid."""
    rng = np.random.default_rng(0)
    times = (np.sort(rng.uniform(0.0, 30.0, 8))[:, None] + np.linspace(0.0, 0.25, 8)).reshape(-1)
    night = np.repeat(np.arange(8), 8)
    longitude = np.deg2rad(30 + 0.5 * times)
    sun = np.stack([np.cos(longitude), np.sin(longitude), 0 * times], -1)
    observer = np.stack([np.cos(longitude + 0.3), np.sin(longitude + 0.3), 0.1 + 0 * times], -1)
    observer /= np.linalg.norm(observer, axis=-1, keepdims=True)
    tumbler = FreeRigidBody(np.array([0.61, 0.965, 1.0]), np.array([1.5, 0.0, 6.0]), np.array([0.9, 0.2, -0.3, 0.2]))
    periods = np.array([float(p) for p in tumbler_periods(tumbler.inertia, tumbler.initial_angular_momentum)[:2]])
    shape = ConvexShape.ellipsoid(1.3, 1.0, 0.8, subdivisions=1)
    flux = np.asarray(brightness(tumbler, shape, times - np.median(times), sun, observer))
    flux = flux * np.exp(NOISE * rng.normal(size=len(times)))
    result = fit_lightcurve(
        times,
        flux,
        sun,
        observer,
        lightcurve=night,
        shape="ellipsoid",
        initial=tumbler,
        periods=tuple((p * 0.99, p * 1.01) for p in periods),
        period_grid=(2, 2),
        starts_per_period=4,
        n_refine=2,
    )
    costs = np.asarray(result.refine_costs)
    period_error = np.abs(np.asarray(result.periods) / periods - 1)
    print(f"initial: refined costs {costs}, periods' error {period_error}")
    # Measured: cost 20.6 (the other start 107.2), periods 6.4e-5 and 8.3e-4 off.
    assert result.cost == costs.min()
    assert result.cost < 25
    assert np.all(period_error < np.array([1e-4, 1e-3]))


def test_bad_input_names_the_argument():
    times, sun, observer, night = geometry(4)
    flux = np.ones(len(times))
    ranges = ((1.0, 1.1), (10.0, 11.0))
    with pytest.raises(ValueError, match="brightness must be > 0"):
        fit_lightcurve(times, flux - 2, sun, observer, periods=ranges)
    with pytest.raises(ValueError, match="brightness must have shape"):
        fit_lightcurve(times, flux[:-1], sun, observer, periods=ranges)
    with pytest.raises(ValueError, match="sun must be unit"):
        fit_lightcurve(times, flux, 2 * sun, observer, periods=ranges)
    with pytest.raises(ValueError, match="no facet is both lit and seen"):
        fit_lightcurve(times, flux, sun, -sun, periods=ranges)
    with pytest.raises(ValueError, match="lightcurve must have shape"):
        fit_lightcurve(times, flux, sun, observer, lightcurve=night[:-1], periods=ranges)
    with pytest.raises(ValueError, match="periods"):
        fit_lightcurve(times, flux, sun, observer)
    with pytest.raises(ValueError, match="x_scale must be 1.0"):
        fit_lightcurve(times, flux, sun, observer, periods=ranges, x_scale="jacobian")
    assert jax.config.jax_enable_x64  # the tests run in float64 (conftest.py)


def test_the_misfit_bound_is_a_chi_square_tail():
    """fit_lightcurve searches again where the residual variance over the data's degrees of freedom
    (``_misfit``: N less the curves' scales and the hat matrix's trace) exceeds 1 + 3 sqrt(2 / dof).
    For least squares with unit noise (the fit's rows are over sigma) that variance is chi-square over
    its dof: its mean is 1 and the bound is passed at the chi-square's tail probability (0.33% at 110
    degrees of freedom; measured 0.37%, mean 1.0023).  Checked on 4000 noise draws, each of 120
    samples in 4 curves (their means eliminated, as the fit eliminates the scales) fitted by 6
    parameters."""
    from scipy import stats

    from frbjax.lightcurve._fit import _misfit

    rng = np.random.default_rng(0)
    samples, curve_count, parameters, draws = 120, 4, 6, 4000
    curves = np.eye(curve_count)[np.arange(samples) % curve_count]
    off_means = np.eye(samples) - curves @ np.linalg.pinv(curves)  # removes each curve's mean
    jacobian = off_means @ rng.normal(size=(samples, parameters))
    noise = rng.normal(size=(draws, samples)) @ off_means
    residuals = noise - noise @ np.linalg.pinv(jacobian).T @ jacobian.T
    fits = [_misfit(r, jacobian, samples, curve_count) for r in residuals]
    variances = np.array([f.variance for f in fits])
    dof = samples - curve_count - parameters
    assert fits[0].threshold == pytest.approx(1 + 3 * np.sqrt(2 / dof), rel=1e-12)
    tail = stats.chi2.sf(dof * fits[0].threshold, dof)
    passed = np.mean(variances > fits[0].threshold)
    print(f"mean variance {variances.mean():.4f}, bound passed {passed:.4f} (chi-square tail {tail:.4f})")
    assert abs(variances.mean() - 1) < 4 * np.sqrt(2 / dof / draws)
    assert abs(passed - tail) < 4 * np.sqrt(tail * (1 - tail) / draws)


def test_the_finer_shape_starts_where_the_coarser_ends():
    """The shape's resolution error (fit_lightcurve's ``resolution_error``) solves the winner again on
    the icosphere subdivided once more, each child facet starting at its parent's area per solid angle:
    a start whose light curves are the coarser shape's to a fraction of the data's 1% noise.  Measured
    on a bumpy ellipsoid's Gaussian image at 320 normals, 200 random geometries of a tumbler: the
    log-brightness differs by 0.34% rms (0.023 peak to peak) after the common scale; each parent's
    four children sum to its area within 0.3% (the flat triangles' solid angles)."""
    from frbjax.lightcurve._fit import _gaussian_image_areas, _subdivided_log_areas, _unit_normals

    normals, solid_angles, _ = _unit_normals(2)
    finer_normals, finer_solid_angles, _ = _unit_normals(3)
    rng = np.random.default_rng(0)
    log_areas = np.log(_gaussian_image_areas(np.array([1.0, 0.7, 0.5]), normals, solid_angles))
    log_areas += 0.2 * rng.normal(size=len(normals))
    finer = _subdivided_log_areas(log_areas, solid_angles, finer_solid_angles)
    assert finer.shape == (4 * len(normals),) and abs(finer.mean()) < 1e-12
    ratio = np.exp(finer).reshape(-1, 4).sum(1) / np.exp(log_areas)
    assert np.ptp(ratio / ratio.mean()) < 0.004
    body = FreeRigidBody(np.array([0.61, 0.965, 1.0]), np.array([1.0, 0.3, 6.0]), np.array([0.9, 0.2, -0.3, 0.2]))
    times = np.linspace(0.0, 3.0, 200)
    sun = rng.normal(size=(200, 3))
    sun /= np.linalg.norm(sun, axis=-1, keepdims=True)
    observer = sun + 0.5 * rng.normal(size=(200, 3))
    observer /= np.linalg.norm(observer, axis=-1, keepdims=True)
    coarse = brightness(body, ConvexShape(normals, np.exp(log_areas)), times, sun, observer)
    fine = brightness(body, ConvexShape(finer_normals, np.exp(finer)), times, sun, observer)
    difference = np.log(np.asarray(fine)) - np.log(np.asarray(coarse))
    print(f"log-brightness: {np.std(difference):.5f} rms, {np.ptp(difference):.4f} peak to peak")
    assert np.std(difference) < 0.004


def test_the_same_smoothness_weight_is_about_the_same_prior_on_finer_facets():
    """The finer solve keeps the regularisation weights: on the icosphere's graph the Laplacian's rows of
    a smooth function shrink about as fast as their number grows (the facets' irregular neighbourhoods
    leave a first-order term), so that the smoothness rows' sum of squares is nearly the same on 320
    and 1280 normals: measured ratios 1.08 to 1.83 (coarser over finer) for spherical harmonics of
    degree 1 to 3, where a second-order stencil (rows as the square of the spacing) would give 4."""
    from frbjax.lightcurve._fit import _laplacian, _unit_normals

    harmonics = (
        lambda n: n[:, 2],
        lambda n: n[:, 0] * n[:, 1],
        lambda n: 3 * n[:, 2] ** 2 - 1,
        lambda n: n[:, 0] ** 3 - 3 * n[:, 0] * n[:, 1] ** 2,
    )
    sums = []
    for subdivisions in (2, 3):
        normals, _, faces = _unit_normals(subdivisions)
        laplacian = _laplacian(faces)
        sums.append([np.sum((laplacian @ harmonic(normals)) ** 2) for harmonic in harmonics])
    ratios = np.array(sums[0]) / np.array(sums[1])
    print("coarser over finer:", np.round(ratios, 3))
    assert np.all((ratios > 1.0) & (ratios < 1.9))


def test_resolution_error_widens_the_sigmas():
    """The basin's sigmas with the shape's resolution error: the larger of the two shapes' sigmas and
    the change of the value in quadrature; where the finer solution is not finite (an unconverged
    solve, a rotator's second period), the coarser sigma as it is."""
    from frbjax.lightcurve._fit import _with_resolution_error

    sigma = np.array([1.0, 2.0, 1.0, 1.0])
    finer_sigma = np.array([3.0, 1.0, np.nan, 1.0])
    values = np.array([10.0, 10.0, 10.0, np.inf])
    finer_values = np.array([14.0, 10.0, 11.0, np.inf])
    widened = _with_resolution_error(sigma, finer_sigma, values, finer_values)
    np.testing.assert_array_equal(widened, [5.0, 2.0, 1.0, 1.0])
