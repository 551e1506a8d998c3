"""frbjax.lightcurve.tumbler_periodogram: period ranges for fit_lightcurve from the light curves.

A pure two-period Fourier series's lattice basis is recovered to a fraction of the resolution 1 / T; members of the
synthetic family of benchmarks/_tumbler_family.py at the size of CI (12 nights, every second sample)
have their true periods inside the proposals, from the light curves alone and with the geometric
ranking (``sun``, ``observer``); the proposals pass fit_lightcurve's option check (a fit
itself takes minutes: benchmarks/lightcurve_periodogram.py and the fit's own tests cover that); bad
input is refused naming the argument.
"""

from __future__ import annotations

import importlib.util
import inspect
import pathlib
import sys

import jax
import numpy as np
import pytest

from frbjax.lightcurve import fit_lightcurve, tumbler_periodogram, TumblerPeriodogram
from frbjax.lightcurve._fit import _check_options
from frbjax.lightcurve._periodogram import _Data, _fibonacci_sphere, _geometric_fit, _pole_angles, _reading_indices


jax.config.update("jax_enable_x64", True)

ROOT = pathlib.Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("_tumbler_family", ROOT / "benchmarks" / "_tumbler_family.py")
family = importlib.util.module_from_spec(_spec)
sys.modules["_tumbler_family"] = family  # dataclasses look their module up
_spec.loader.exec_module(family)

# fit_lightcurve's defaults of the options its check takes (read from its signature, so that a new
# option or a changed default is checked as the fit gets it).
FIT_DEFAULTS = {
    name: parameter.default
    for name, parameter in inspect.signature(fit_lightcurve).parameters.items()
    if name in inspect.signature(_check_options).parameters and name != "periods"
}


def nights(count, per_night, span, seed):
    rng = np.random.default_rng(seed)
    days = np.sort(rng.choice(int(span), count, replace=False)) + 0.2
    times = (days[:, None] + np.sort(rng.uniform(0, 0.3, (count, per_night)), -1)).reshape(-1)
    return times, np.repeat(np.arange(count), per_night), rng


def rank(result, periods):
    """Index of the first (tumbler) proposal whose ranges hold ``periods``, or None."""
    for k, (proposal, mode) in enumerate(zip(result.proposals, result.modes)):
        if mode != "PA" and all(low <= p <= high for (low, high), p in zip(proposal, periods)):
            return k
    return None


def two_period_signal():
    """Log flux of a SAM-like tumbler's series: f_psi - f_phi dominant (and its harmonic), f_psi, f_phi."""
    f_psi, f_phi = 1.7, 0.41
    times, night, rng = nights(16, 24, 60, seed=1)
    f1 = f_psi - f_phi
    signal = (
        0.3 * np.cos(2 * np.pi * 2 * f1 * times)
        + 0.1 * np.sin(2 * np.pi * f1 * times + 0.4)
        + 0.08 * np.cos(2 * np.pi * f_psi * times + 1.0)
        + 0.05 * np.cos(2 * np.pi * (2 * f1 + f_phi) * times + 2.0)
        + 0.04 * np.cos(2 * np.pi * f_phi * times + 0.3)
    )
    values = signal + 0.005 * rng.normal(size=len(times)) + rng.normal(size=16)[night]
    return times, np.exp(values), night, (1 / f_psi, 1 / f_phi)


def test_two_period_series_recovered():
    times, flux, night, periods = two_period_signal()
    result = tumbler_periodogram(times, flux, lightcurve=night, period_range=(0.2, 5.0))
    assert isinstance(result, TumblerPeriodogram)
    span = result.span
    # The best lattice basis is the SAM's (f_psi - f_phi, f_phi), within a fraction of 1 / T.  Its
    # readings as (P_psi, P_phi) all fit this clean five-term series to the noise, and the drifting
    # series ranks other bases of the lattice first: the truth's own reading is not among the 12
    # proposals here (a known weakness, docs/lightcurves.md).
    f_psi, f_phi = 1 / np.array(periods)
    error = np.abs(result.bases[0] - (f_psi - f_phi, f_phi)) * span
    print("best basis", result.bases[0], "error in units of 1/T", error, "modes", result.modes)
    assert np.all(error < 0.05)  # measured: 0.00005 and 0.020
    assert 1 <= len(result.proposals) <= 12
    assert set(result.modes) <= {"SAM", "LAM", "PA"}


def long_axis_signal():
    """Log flux of a LAM-like tumbler's series dominated by f_psi + f_phi (and its harmonic)."""
    f_psi, f_phi = 1.3, 0.37
    times, night, rng = nights(16, 24, 60, seed=2)
    f1 = f_psi + f_phi
    signal = (
        0.3 * np.cos(2 * np.pi * 2 * f1 * times)
        + 0.1 * np.sin(2 * np.pi * f1 * times + 0.4)
        + 0.06 * np.cos(2 * np.pi * f_phi * times + 1.0)
        + 0.05 * np.cos(2 * np.pi * (f1 + f_phi) * times + 2.0)
        + 0.03 * np.cos(2 * np.pi * 2 * f_psi * times + 0.3)
    )
    values = signal + 0.005 * rng.normal(size=len(times)) + rng.normal(size=16)[night]
    return times, np.exp(values), night, (1 / f_psi, 1 / f_phi)


def test_long_axis_lattice_read_through_the_sum():
    # The lattice is found with f1 = f_psi + f_phi, and the truth is the reading (f1 - c, c).  Without
    # that reading the truth is not among the proposals on seeds 0 to 3 of this sampling (measured:
    # with it, ranks 5, 5, 2, 3).
    times, flux, night, periods = long_axis_signal()
    result = tumbler_periodogram(times, flux, lightcurve=night, period_range=(0.2, 5.0))
    found = rank(result, periods)
    print("rank", found, result.modes)
    assert found is not None and found <= 3  # measured: rank 2
    assert result.modes[found] == "LAM"


def test_clear_tumbler_keeps_its_last_reading():
    # The single period (RMS 0.026 here, the readings 0.005) does not take the last slot of a full
    # list from a reading that fits far better (it did until 2026-12-05: a family member's truth,
    # ranked last, was dropped so).
    times, flux, night, periods = long_axis_signal()
    result = tumbler_periodogram(times, flux, lightcurve=night, period_range=(0.2, 5.0), max_proposals=4)
    print("rank", rank(result, periods), result.modes, result.scores, result.rms_one_period)
    assert len(result.modes) == 4 and "PA" not in result.modes
    assert rank(result, periods) == 2


def test_principal_axis_rotator_proposed_first():
    # One period's harmonics only: the period, then its double, as a principal-axis rotator's.
    period = 0.37
    times, night, rng = nights(16, 24, 60, seed=3)
    phase = 2 * np.pi * times / period
    signal = 0.3 * np.cos(2 * phase + 0.2) + 0.1 * np.sin(phase + 0.4) + 0.05 * np.cos(3 * phase + 1.0)
    values = signal + 0.005 * rng.normal(size=len(times)) + rng.normal(size=16)[night]
    result = tumbler_periodogram(times, np.exp(values), lightcurve=night, period_range=(0.2, 5.0))
    print(result.modes, result.proposals[:2])
    assert result.modes[:2] == ["PA", "PA"]
    assert result.proposals[0][0] <= period <= result.proposals[0][1]
    assert result.proposals[1][0] <= 2 * period <= result.proposals[1][1]
    assert result.fit_options(0) == dict(periods=result.proposals[0], principal_axis=True)


def test_faint_rotator_period_halved_at_most_to_its_half():
    # A rotator whose light curve stands about 80 units of chi-square above 1% noise (harmonics 1 and
    # 2 of 0.6%, like the third family's rotator 1): its halves fit 19 and then 45 units worse in the
    # single-period series.  The period is halved while the half fits within three standard
    # deviations of the chi-square difference (27 units here), so once: P / 2, then P, are proposed.
    # A fixed allowance of 8 units per coefficient (160) halved it twice until 2026-12-07, proposing
    # P / 4 and P / 2 (P / 8 lies outside the band) and then the tumbling readings.
    period = 0.65
    times, night, rng = nights(16, 24, 60, seed=4)
    phase = 2 * np.pi * times / period
    signal = 0.006 * np.cos(2 * phase + 0.2) + 0.006 * np.sin(phase + 0.4)
    values = signal + 0.01 * rng.normal(size=len(times)) + rng.normal(size=16)[night]
    result = tumbler_periodogram(times, np.exp(values), lightcurve=night, period_range=(0.1, 5.0))
    print(result.modes[:3], result.proposals[:3])
    assert result.modes[:3] == ["PA", "PA", "PA"]
    assert result.proposals[0][0] <= period / 2 <= result.proposals[0][1]
    assert result.proposals[1][0] <= period <= result.proposals[1][1]


def test_psi_harmonics_fade_toward_the_pole():
    # Every spherical harmonic of azimuthal order j about L carries sin^|j| theta (DLMF 14.30.1,
    # 14.7.10): the geometric series' psi harmonic j at aspect theta (the pole's turns) is its equator-on column times
    # sin^|j| theta, and seen pole-on only the phi harmonics (j = 0) remain.
    times = np.linspace(0.0, 10.0, 50)
    data = _Data(times, np.zeros_like(times), np.zeros(len(times), int))
    indices = _reading_indices(2, 2)
    frequencies = np.array([[1.3, 0.37]])
    count = len(indices)
    pole = np.array([[0.0, 0.0, 1.0]])

    def columns_at(theta):
        # The bisector at the angle theta from the pole, its azimuth about it advancing with time.
        azimuth = 0.3 * times
        bisector = np.stack(
            [np.sin(theta) * np.cos(azimuth), np.sin(theta) * np.sin(azimuth), np.full_like(times, np.cos(theta))], -1
        )
        return data.geometric_columns(frequencies, indices, *_pole_angles(bisector, pole, 2))[0]

    equator = columns_at(np.pi / 2)
    for theta in (0.0, 0.4, 2.5):
        columns = columns_at(theta)
        fade = np.sin(theta) ** np.abs(indices[:, 0])[:, None]
        for part in (0, 2):  # the real and the imaginary parts' columns times 1 (those times cos theta follow each)
            plain = slice(part * count, (part + 1) * count)
            aspect = slice((part + 1) * count, (part + 2) * count)
            np.testing.assert_allclose(columns[plain], fade * equator[plain], atol=1e-15)
            np.testing.assert_allclose(columns[aspect], np.cos(theta) * columns[plain], atol=1e-15)


def test_geometric_fit_refines_the_pole_between_the_grid_poles():
    # A light curve that is exactly the geometric series at the pole farthest from the trial poles
    # (100: about 20 degrees apart), seen as the bisector sweeps 200 degrees: the refined pole fits it
    # to near the noise, the best trial pole alone eight times worse.
    rng = np.random.default_rng(3)
    times, night, _ = nights(20, 30, 120, seed=3)
    longitude = 0.03 * times  # the bisector sweeps about 200 degrees: the azimuth about a pole depends on it
    sun = np.stack([np.cos(longitude), np.sin(longitude), 0.3 * np.sin(0.05 * times)], -1)
    sun /= np.linalg.norm(sun, axis=-1, keepdims=True)
    observer = np.stack([np.cos(longitude + 0.4), np.sin(longitude + 0.4), np.zeros_like(times)], -1)
    bisector = (sun + observer) / np.linalg.norm(sun + observer, axis=-1, keepdims=True)
    grid = _fibonacci_sphere(100)
    trial = rng.normal(size=(2000, 3))
    trial /= np.linalg.norm(trial, axis=-1, keepdims=True)
    pole = trial[np.argmax(np.min(np.arccos(np.clip(trial @ grid.T, -1, 1)), -1))]  # farthest from the grid
    indices = _reading_indices(2, 2)
    data = _Data(times, np.zeros_like(times), night)
    columns = data.geometric_columns(np.array([[1.3, 0.37]]), indices, *_pole_angles(bisector, pole[None], 2))[0]
    noise = 0.001
    values = 0.1 * rng.normal(size=len(columns)) @ columns + noise * rng.normal(size=len(times))
    data = _Data(times, values, night)
    angles = _pole_angles(bisector, grid, 2)
    resolution = 1 / np.ptp(times)
    refined = _geometric_fit(data, 1.3, 0.37, indices, grid, angles, bisector, 0.4 * resolution)
    turns, cos_theta = angles
    on_grid = min(
        data.rss_of(data.geometric_columns(np.array([[1.3, 0.37]]), indices, turns[g], cos_theta[g]))[0]
        for g in range(len(grid))
    )
    dof = data.dof - 4 * len(indices)
    print("rms refined", np.sqrt(refined / dof), "best grid pole", np.sqrt(on_grid / dof))
    assert np.sqrt(refined / dof) < 1.8 * noise  # measured: 1.62 times the noise
    assert np.sqrt(on_grid / dof) > 7 * noise  # measured: 7.99 times


@pytest.mark.parametrize("index", [8, 19])
def test_family_members_inside_proposals(index):
    case = family.tumbler(index, nights=12, per_night=0.5)
    result = tumbler_periodogram(case.times, case.flux, lightcurve=case.night, period_range=(0.1, 5.0))
    found = rank(result, case.periods)
    print(case.kind, case.periods, "rank", found, result.modes)
    assert found is not None and found <= 3  # measured: rank 1 (member 8) and 0 (member 19)


@pytest.mark.parametrize("index", [19, 20])
def test_family_members_inside_geometric_proposals(index):
    # With the Sun's and the observer's directions the readings are ranked by the geometric series
    # (the psi harmonics turning with the bisector's azimuth about a trial pole): member 20's truth,
    # outside the Fourier ranking's twelve at this size, comes first.
    case = family.tumbler(index, nights=12, per_night=0.5)
    result = tumbler_periodogram(
        case.times, case.flux, sun=case.sun, observer=case.observer, lightcurve=case.night, period_range=(0.1, 5.0)
    )
    found = rank(result, case.periods)
    print(case.kind, case.periods, "rank", found, result.modes)
    assert found is not None and found <= 1  # measured: rank 1 (member 19) and 0 (member 20)
    # The scores are the geometric series' RMS per degree of freedom (its 48 coefficients and the
    # nights' offsets taken off): the first reading's, recomputed at its centre.
    data = _Data(case.times, np.log(case.flux), case.night)
    bisector = case.sun + case.observer
    bisector /= np.linalg.norm(bisector, axis=-1, keepdims=True)
    indices, poles = _reading_indices(2, 2), _fibonacci_sphere(400)
    f_psi, f_phi = 1 / result.centres[0]
    angles = _pole_angles(bisector, poles, 2)
    rss = _geometric_fit(data, f_psi, f_phi, indices, poles, angles, bisector, 0.4 / result.span, levels=3)
    np.testing.assert_allclose(result.scores[0], np.sqrt(rss / (data.dof - 4 * len(indices))), rtol=1e-9)


def test_proposals_pass_fit_lightcurve_checks():
    times, flux, night, periods = two_period_signal()
    result = tumbler_periodogram(times, flux, lightcurve=night, period_range=(0.2, 5.0))
    for k in range(len(result.proposals)):
        options = dict(FIT_DEFAULTS)
        options.update(result.fit_options(k))
        _check_options(**options)


def test_bad_input_names_the_argument():
    times, flux, night, _ = two_period_signal()
    band = (0.2, 5.0)
    with pytest.raises(ValueError, match="brightness must be > 0"):
        tumbler_periodogram(times, -flux, period_range=band)
    with pytest.raises(ValueError, match="brightness must be finite"):
        tumbler_periodogram(times, np.where(np.arange(len(flux)) == 3, np.nan, flux), period_range=band)
    with pytest.raises(ValueError, match="brightness must have shape"):
        tumbler_periodogram(times, flux[:-1], period_range=band)
    with pytest.raises(ValueError, match="times must be finite"):
        tumbler_periodogram(np.where(np.arange(len(times)) == 5, np.inf, times), flux, period_range=band)
    with pytest.raises(ValueError, match="times must be one-dimensional"):
        tumbler_periodogram(times[:, None], flux, period_range=band)
    with pytest.raises(ValueError, match="lightcurve must have shape"):
        tumbler_periodogram(times, flux, lightcurve=night[:-1], period_range=band)
    with pytest.raises(ValueError, match="period_range"):
        tumbler_periodogram(times, flux)
    with pytest.raises(ValueError, match="upside down"):
        tumbler_periodogram(times, flux, period_range=(5.0, 0.2))
    with pytest.raises(ValueError, match="period_range must be > 0"):
        tumbler_periodogram(times, flux, period_range=(-1.0, 2.0))
    with pytest.raises(ValueError, match="order must be >= 1"):
        tumbler_periodogram(times, flux, period_range=band, order=0)
    with pytest.raises(ValueError, match="tolerance must be > 0"):
        tumbler_periodogram(times, flux, period_range=band, tolerance=0.0)
    with pytest.raises(ValueError, match="max_width must be < 1"):
        tumbler_periodogram(times, flux, period_range=band, max_width=1.5)
    with pytest.raises(ValueError, match="psi_order must be >= 1"):
        tumbler_periodogram(times, flux, period_range=band, psi_order=0)
    with pytest.raises(ValueError, match="drift must be >= 0"):
        tumbler_periodogram(times, flux, period_range=band, drift=-1)
    with pytest.raises(ValueError, match="cannot fit"):
        tumbler_periodogram(times[:20], flux[:20], period_range=band)
    sun = np.tile([1.0, 0.0, 0.0], (len(times), 1))
    observer = np.tile([0.0, 1.0, 0.0], (len(times), 1))
    with pytest.raises(ValueError, match="give both"):
        tumbler_periodogram(times, flux, sun=sun, period_range=band)
    with pytest.raises(ValueError, match="observer must have shape"):
        tumbler_periodogram(times, flux, sun=sun, observer=observer[:-1], period_range=band)
    with pytest.raises(ValueError, match="sun must be unit vectors"):
        tumbler_periodogram(times, flux, sun=2 * sun, observer=observer, period_range=band)
    with pytest.raises(ValueError, match="sun must be finite"):
        tumbler_periodogram(
            times,
            flux,
            sun=np.where(np.arange(len(times))[:, None] == 2, np.nan, sun),
            observer=observer,
            period_range=band,
        )
    with pytest.raises(ValueError, match="opposite at sample 0"):
        tumbler_periodogram(times, flux, sun=sun, observer=-sun, period_range=band)
    with pytest.raises(ValueError, match="poles must be >= 1"):
        tumbler_periodogram(times, flux, sun=sun, observer=observer, period_range=band, poles=0)
    with pytest.raises(ValueError, match="geometric_orders must be"):
        tumbler_periodogram(times, flux, sun=sun, observer=observer, period_range=band, geometric_orders=2)
    # Magnitudes may be negative.
    result = tumbler_periodogram(times, -2.5 * np.log10(flux), magnitudes=True, lightcurve=night, period_range=band)
    assert len(result.proposals) >= 1
