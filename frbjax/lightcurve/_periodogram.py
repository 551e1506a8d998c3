"""Period ranges from the data: a two-period Fourier periodogram of a tumbler's light curves.

The brightness of a torque-free body depends on its attitude R(t) = R_L Rz(psi(t)) B(t), where R_L
takes the z axis to L, psi is the precession angle about L (advancing at the mean rate 2 pi / P_psi
with a part periodic in P_phi) and B(t), the body's orientation relative to L, is periodic with the
period P_phi of the body-frame motion (``tumbler_periods``).  Over a few nights, while the Sun and the
observer stay put, the light curve is therefore a doubly periodic function of (t / P_psi, t / P_phi):
a two-dimensional Fourier series whose frequencies are the lattice {j f_psi + k f_phi}, f = 1 / P
(Kaasalainen 2001; Pravec et al. 2005, Icarus 173, 108, their eq. 1):

    F(t) = C0 + sum_{j=1..m} [C_j0 cos 2 pi j f1 t + S_j0 sin 2 pi j f1 t]
              + sum_{k=1..m} sum_{j=-m..m} [C_jk cos 2 pi (j f1 + k f2) t + S_jk sin 2 pi (j f1 + k f2) t].

Pravec et al. fit this series by linear least squares over a grid of (f1, f2) and read the periods off
the minimum of the residuals.  Any integer basis of the lattice gives the same frequencies, so the
basis (f1, f2) the fit finds is not necessarily (f_psi, f_phi), and Pravec et al. relate them by mode:

- long-axis mode (LAM): the long axis circulates L with the precession, the light curve is dominated
  by 2 f_psi, and (f1, f2) = (f_psi, f_phi);
- short-axis mode (SAM): the long axis turns about L at the rate of psi + phi, phi running backwards
  (a near-principal-axis SAM has dphi/dt = -|L| (1/I1 - 1/I3)-ish): the light curve is dominated by
  2 (f_psi - f_phi), and the strongest basis is f1 = f_psi - f_phi, with f_psi = f1 + f_phi (Apophis,
  Pravec et al. 2014: P1 = 30.56 h, P_psi = 27.38 h, P_phi = 263 h).

Relative photometry: each light curve (``lightcurve`` label, e.g. a night) has its own unknown scale,
an additive offset in log flux (or magnitudes), fitted with the series (eliminated exactly by
subtracting each curve's mean from the data and from every column).

The search (all linear least squares, numpy, vectorised over frequencies):

1. One-period scan: a Fourier series of the base frequency f with harmonics 1 and 2 over the band
   1 / p_max <= f <= 1 / p_min, on a grid of step 1 / (``oversampling`` T), T the span of the data:
   the full span's resolution (the minima are 1 / T wide).  Its deepest ``peaks`` local minima are the
   candidate fundamentals f_a: the strongest lattice frequency and its aliases, among them those of
   the 1 / day sampling of nights at the same hour (f_a +- 1 / day).  All are kept, and each is also
   tried halved (f_a / 2: a dominant second harmonic read as a fundamental).
2. Second frequency: for each candidate f1, the two-period series of ``order`` m is fitted on a grid
   of f2 over (2 / T, f1 - 2 / T) (the lattice modulo f1: f2 and f2 + n f1 span the same lattice), and
   its deepest minima are refined jointly in (f1, f2) on local grids shrinking to a twentieth of
   1 / T (coarse-to-fine: the one-period scan is the coarse search, since a lattice is found from its
   strongest frequency at the full resolution).
3. The refined bases are ranked by their RMS and bases of one lattice (each one's vectors small
   integer combinations of the other's) are merged.
4. Each of the best ``lattices_kept`` lattices gives candidate period pairs, (f_psi, f_phi) =
   (f1 + c, c) (the SAM reading) and (f1, c) (the LAM reading), for c among f2, f1 - f2, f1 + f2 and
   their halves (a lattice found through its even harmonics), and (f1 - c, c) for c = f2, f1 - f2
   (a LAM's lattice found through f_psi + f_phi, as the family's long-axis tumblers often are).
   Each reading is scored in its own basis by a series with the few psi harmonics a body's attitude
   about L gives (|j| <= ``psi_order``) and more phi harmonics (|k| <= ``phi_order``), its
   coefficients drifting slowly over the span (each column times the Legendre polynomials of time up
   to degree ``drift``: the months of changing geometry, the synodic drift of the psi phase among
   them), after a local refinement; the best ``refined_readings`` of the unrefined scores are
   refined, and the readings are ranked by their RMS.
   With the Sun's and the observer's directions (``sun``, ``observer``: the geometric ranking) the
   basis scan of step 2 drifts alike, and each refined reading is rescored by the series the
   geometry prescribes.  With the attitude R = R_L Rz(psi) B(t) (``tumbler_periods``), the body-frame
   direction of the phase-angle bisector b is B^T Rz(-psi) R_L^T b: in the frame of L its azimuth
   alpha(t) enters only as psi - alpha, so that each psi harmonic j carries exp(-i j alpha(t)) (the
   synodic correction: over months the bisector's azimuth about L moves by tens of degrees), and the
   coefficients vary with the aspect theta(t), cos theta = b . L: the brightness, a function of the
   bisector's direction in the frame of L, expands in the spherical harmonics Y_l^j(theta, alpha -
   psi), whose order-j terms all carry sin^|j| theta times a polynomial in cos theta (DLMF 14.30.1
   with 14.7.10), here of first degree.  For a trial pole L the columns are cos and sin of
   2 pi (j f_psi + k f_phi) t - j alpha(t), each times sin^|j| theta(t) and sin^|j| theta(t) cos theta(t)
   (|j| <= psi, |k| <= phi of ``geometric_orders``, (2, 2)), fitted by linear least squares as
   above; the reading's score is the best over ``poles`` trial poles spread over the sphere (a
   Fibonacci lattice: 400 are about 10 degrees apart), the frequencies refined locally at the best
   three, then each of those poles to about a degree.  The sense of rotation is the pole's: L and -L
   differ.  Fewer free coefficients than the drifting series (48 against 68), and a drift the
   geometry fixes: on the family the truth's own reading ranks higher among the aliases
   (docs/lightcurve-search.md).
5. Principal-axis comparison: the best single period with 2 (psi_order + phi_order) harmonics,
   drifting alike, halved (at most twice) while its half fits as well, within three standard
   deviations of the two series' chi-square difference, 3 sqrt(2 C) units of the noise's variance
   for C coefficients each (a period's double fits as well as it does: its harmonics are the
   double's).  With the geometry the comparison is then made in the geometric series, the period's
   harmonics up to 2 (psi + phi) of ``geometric_orders`` turning with the bisector's azimuth like
   psi's.  When no reading lowers its chi-square below the single period's by more than the
   tumbling test's allowance (five units of the noise's variance per extra coefficient), the period,
   its double and its half are proposed first as a principal-axis rotator's; otherwise the single
   period follows the readings, in a full list in the last reading's slot unless it fits worse than
   that reading by more than the same allowance (a clear tumbler's list keeps its readings; on the
   family that recovers two truths ranked last).  Each centre becomes a range of +- ``tolerance`` / T in
   frequency (the periods' uncertainty at the full span), at most +- ``max_width`` relative, and the
   list is cut at ``max_proposals``.

The ranges are for :func:`fit_lightcurve`'s ``periods``; ``mode`` tells which mode the reading assumed
(fit with ``mode="both"`` to let the fit decide).  The lattice the light curves determine is only as
good as the data's cover of it: with few nights aliases (+-1 / day, +-1 / T) of the true lattice may
rank first, and the SAM and LAM readings of one lattice score alike (the periodogram cannot tell the
mode: the full fit does); hence several ranked proposals.  The changing geometry over months shifts
the observed psi frequency by the synodic rate (the phase angle bisector's motion, a fraction of
1 / T for a few degrees a week), inside the ranges, and the drifting coefficients absorb it.

How far this goes (``benchmarks/lightcurve_periodogram.py``, docs/lightcurves.md): for the slower
tumblers of a one-site campaign (frequencies within a few times 1 / day of 0) many lattices, the
truth's sub- and superlattices and their 1 / day aliases, fit the data to the noise; the ranking among
them is then close to chance and the truth may fall outside the list.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .. import _checks as checks


__all__ = ["tumbler_periodogram", "TumblerPeriodogram"]


@dataclasses.dataclass(frozen=True)
class TumblerPeriodogram:
    """Result of :func:`tumbler_periodogram` (numpy arrays; frequencies in 1 / the time unit).

    - ``proposals``: ranked list of period ranges for :func:`fit_lightcurve`'s ``periods``:
      ((P_psi_min, P_psi_max), (P_phi_min, P_phi_max)) for a tumbler, (P_min, P_max) for a
      principal-axis rotator (``modes[i] == "PA"``: pass ``principal_axis=True``);
    - ``modes``: the reading behind each proposal, "SAM", "LAM" or "PA";
    - ``centres``: (P_psi, P_phi) at the centre of each proposal (P_phi infinite for "PA");
    - ``scores``: the RMS of the residuals of the proposal's series (log flux; lower is better): the
      reading's series with drifting coefficients (module docstring, step 4), or the geometric series
      when ``sun`` and ``observer`` were given; the single period's for "PA";
    - ``bases``, ``basis_rms``: the refined lattice bases (f1, f2), best first, and their RMS;
      ``rms_one_period``: the RMS of the best single-period series (the principal-axis comparison);
    - ``frequencies``, ``rms``: the one-period scan (step 1); ``span``: T;
    - ``map_f1``, ``map_f2``, ``map_rms``: the two-period RMS on a grid around the best basis
      (+- ``map_halfwidth`` / T), for a figure.

    ``fit_options(i)``: the keyword arguments of :func:`fit_lightcurve` for proposal ``i``.
    """

    proposals: list
    modes: list
    centres: np.ndarray
    scores: np.ndarray
    bases: np.ndarray
    basis_rms: np.ndarray
    rms_one_period: float
    frequencies: np.ndarray
    rms: np.ndarray
    span: float
    map_f1: np.ndarray
    map_f2: np.ndarray
    map_rms: np.ndarray

    def fit_options(self, index: int = 0) -> dict:
        """``periods``, ``principal_axis`` and ``mode`` for :func:`fit_lightcurve` from proposal ``index``."""
        mode = self.modes[index]
        if mode == "PA":
            return dict(periods=self.proposals[index], principal_axis=True)
        return dict(periods=self.proposals[index], mode="both")


class _Data:
    """Centred log brightness, the curves of the samples, and the residual sums of squares of series
    fitted to them."""

    def __init__(self, times, values, labels, drift=0):
        self.origin = 0.5 * (times.min() + times.max())
        self.times = times - self.origin
        # Slow drift of the coefficients: each column times the Legendre polynomials 0..drift of the
        # time over the span (the changing geometry over months), fitted with the series.
        x = self.times / max(0.5 * float(np.ptp(times)), 1e-300)
        self.drift = np.stack([np.polynomial.legendre.legval(x, np.eye(drift + 1)[d]) for d in range(drift + 1)])
        _, index = np.unique(labels, return_inverse=True)
        self.counts = np.bincount(index).astype(float)
        self.indicator = np.eye(len(self.counts))[index]  # (N, C): 1 where a sample is in a curve
        self.values = values - (values @ self.indicator / self.counts)[index]
        self.total = float(self.values @ self.values)
        self.dof = len(values) - len(self.counts)

    def columns(self, bases, indices):
        """cos and sin of 2 pi f t for the frequencies f = indices @ basis of each basis (G, B) (the
        integer ``indices`` (K, B)), each times the drift's polynomials: (G, 2 K (drift + 1), N).

        The phases are products of the powers of exp(2 pi i f_b t), one per basis frequency: a complex
        product per element instead of an exponential (the powers' rounding, |j| eps, is far below
        the noise's)."""
        count, samples = len(bases), len(self.times)
        units = np.exp(2j * np.pi * bases[:, :, None] * self.times)  # (G, B, N)
        powers = []
        for b in range(bases.shape[1]):
            table = [np.ones((count, samples), complex)]
            for _ in range(int(np.abs(indices[:, b]).max())):
                table.append(table[-1] * units[:, b])
            powers.append(table)
        phase = np.empty((count, len(indices), samples), complex)
        for k, orders in enumerate(indices):
            product = np.ones((count, samples), complex)
            for b, order in enumerate(orders):
                if order:
                    power = powers[b][abs(order)]
                    product = product * (power if order > 0 else power.conj())
            phase[:, k] = product
        if len(self.drift) > 1:
            phase = (phase[:, :, None, :] * self.drift).reshape(count, -1, samples)
        return np.concatenate([phase.real, phase.imag], 1)

    def rss(self, bases, indices, chunk=128):
        """Residual sum of squares of the series with the frequencies ``indices`` (K, B) @ basis for each
        basis of ``bases`` (G, B) (a cosine and a sine each, every curve's offset free): (G,)."""
        bases = np.asarray(bases, float).reshape(len(bases), -1)
        indices = np.asarray(indices, int).reshape(-1, bases.shape[1])
        out = np.empty(len(bases))
        for start in range(0, len(bases), chunk):
            out[start : start + chunk] = self.rss_of(self.columns(bases[start : start + chunk], indices))
        return out

    def rss_of(self, columns):
        """Residual sum of squares of the least-squares fit of the columns (G, P, N) and every curve's
        offset to the data, for each of the G sets: (G,)."""
        # Each curve's offset is fitted with the series: the normal equations of the columns less
        # their curves' means, X_c X_c^T = X X^T - S diag(1 / n) S^T (S: the columns' sums over each
        # curve, n: the curves' counts), and X_c v = X v for the centred data v.
        sums = columns @ self.indicator  # (G, P, C)
        gram = columns @ np.swapaxes(columns, 1, 2) - (sums / self.counts) @ np.swapaxes(sums, 1, 2)
        moment = columns @ self.values
        scale = np.trace(gram, axis1=1, axis2=2)[:, None, None] / gram.shape[1]
        gram = gram + (1e-10 * scale + 1e-300) * np.eye(gram.shape[1])
        coefficients = np.linalg.solve(gram, moment[..., None])[..., 0]
        return np.maximum(self.total - np.sum(coefficients * moment, -1), 0.0)

    def geometric_columns(self, frequencies, indices, turns, cos_theta):
        """Columns of the geometric series (module docstring, step 4 with ``sun`` and ``observer``) for
        the frequencies (G, 2) = (f_psi, f_phi) and a pole's ``turns`` sin^j theta exp(-i j azimuth)
        (j = 0, 1, ..., (G, J, N) or (J, N): ``_pole_angles``) and cos theta ((G, N) or (N,)): cos and
        sin of 2 pi (j f_psi + k f_phi) t - j azimuth for the ``indices`` (j, k) (K, 2), each times
        sin^|j| theta and sin^|j| theta cos theta: (G, 4 K, N)."""
        j, k = indices[:, 0], indices[:, 1]
        rates = frequencies[:, :1] * j + frequencies[:, 1:] * k  # (G, K)
        unit = np.exp(2j * np.pi * rates[:, :, None] * self.times) * np.asarray(turns)[..., j, :]
        unit = np.concatenate([unit, unit * np.asarray(cos_theta)[..., None, :]], 1)
        return np.concatenate([unit.real, unit.imag], 1)


def _lattice_indices(order):
    """(j, k) of the series of ``order`` m: (j, 0) for j = 1..m, (j, k) for k = 1..m, j = -m..m."""
    return np.array(
        [(j, 0) for j in range(1, order + 1)] + [(j, k) for k in range(1, order + 1) for j in range(-order, order + 1)]
    )


def _local_minima(values, count, separation):
    """Indices of the ``count`` deepest local minima of ``values`` at least ``separation`` apart."""
    inner = np.flatnonzero((values[1:-1] <= values[:-2]) & (values[1:-1] <= values[2:])) + 1
    candidates = inner[np.argsort(values[inner])]
    chosen = []
    for i in candidates:
        if all(abs(i - c) >= separation for c in chosen):
            chosen.append(i)
        if len(chosen) == count:
            break
    return chosen


def _refine(data, indices, f1, f2, step, levels=3, points=7):
    """(f1, f2, rss) at the minimum of local grids around (f1, f2) shrinking by 3 each level."""
    best = (f1, f2, np.inf)
    for _ in range(levels):
        offsets = (np.arange(points) - points // 2) * step
        g1, g2 = np.meshgrid(best[0] + offsets, best[1] + offsets, indexing="ij")
        rss = data.rss(np.stack([g1.reshape(-1), g2.reshape(-1)], -1), indices)
        k = int(np.argmin(rss))
        if rss[k] < best[2]:
            best = (float(g1.reshape(-1)[k]), float(g2.reshape(-1)[k]), float(rss[k]))
        step /= 3
    return best


def _same_lattice(a, b, tolerance, largest=4):
    """True when the vectors of basis ``b`` are integer combinations (|coefficients| <= largest) of ``a``'s,
    and the two lattices have the same density (|det| = 1), within ``tolerance`` in frequency."""
    coefficients = np.arange(-largest, largest + 1)
    combos = coefficients[:, None] * a[0] + coefficients[None, :] * a[1]
    pairs = []
    for v in b:
        hits = np.argwhere(np.abs(combos - v) < tolerance)
        if len(hits) == 0:
            return False
        pairs.append(coefficients[hits[0]])
    return abs(round(np.linalg.det(np.array(pairs, float)))) == 1


def _reading_indices(psi_order, phi_order):
    """(j, k) of a reading's series: |j| <= psi_order, |k| <= phi_order, one of each +- pair."""
    return np.array(
        [(j, k) for j in range(0, psi_order + 1) for k in range(-phi_order, phi_order + 1) if j > 0 or k > 0]
    )


def _fibonacci_sphere(count):
    """``count`` nearly uniformly spread unit vectors: the Fibonacci lattice on the sphere."""
    k = np.arange(count) + 0.5
    z = 1 - 2 * k / count
    azimuth = np.pi * (1 + np.sqrt(5.0)) * k
    ring = np.sqrt(1 - z * z)
    return np.stack([ring * np.cos(azimuth), ring * np.sin(azimuth), z], -1)


def _tangent_frames(poles):
    """Two unit vectors (G, 3) each, orthogonal to each pole (G, 3) and to each other: the x and y axes
    of a frame whose z axis is the pole."""
    helper = np.where(np.abs(poles[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    first = helper - np.sum(helper * poles, -1, keepdims=True) * poles
    first /= np.linalg.norm(first, axis=-1, keepdims=True)
    return first, np.cross(poles, first)


def _pole_angles(bisector, poles, harmonics):
    """The turns sin^j theta exp(-i j azimuth) for j = 0..``harmonics`` ((G, harmonics + 1, N): computed
    once for every reading) and cos(theta) ((G, N)) of the unit bisectors (N, 3) in frames whose z axis
    is each pole (G, 3) (the azimuth's origin is arbitrary: a constant phase the coefficients absorb).

    The factor sin^j theta is that of every spherical harmonic of order j about the pole (DLMF
    14.30.1, 14.7.10): a psi harmonic fades as the bisector nears the pole, and the aspect's changes
    over months follow it.  sin theta exp(-i azimuth) is the bisector's component across the pole,
    x - i y in the pole's frame: the turns are its powers."""
    first, second = _tangent_frames(poles)
    across = first @ bisector.T - 1j * (second @ bisector.T)  # (G, N)
    turns = [np.ones_like(across)]
    for _ in range(harmonics):
        turns.append(turns[-1] * across)
    return np.stack(turns, 1), poles @ bisector.T


def _pole_neighbours(pole, size):
    """The pole (3,) and its eight neighbours on a square of half-side ``size`` radians about it: (9, 3)."""
    first, second = _tangent_frames(pole[None])
    steps = np.array([(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1)], float) * size
    neighbours = pole + steps[:, :1] * first + steps[:, 1:] * second
    return neighbours / np.linalg.norm(neighbours, axis=-1, keepdims=True)


def _geometric_fit(
    data, f_psi, f_phi, indices, poles, angles, bisector, step, levels=2, points=5, best_poles=3, chunk=100
):
    """The residual sum of squares of the geometric series (``_Data.geometric_columns``) at its best
    pole and frequencies near (f_psi, f_phi): every pole at the given frequencies, then at each of the
    ``best_poles`` best poles local grids of the frequencies shrinking by 3 each level (of f_psi alone
    for a single-period series, ``indices[:, 1] == 0``), then the pole itself on local grids shrinking
    by 2 from half the poles' spacing (three levels, to about a degree: the grid's 10 degrees limit
    how well the true reading fits); ``angles``: ``_pole_angles`` of the ``poles``, ``bisector``
    (N, 3) the phase-angle bisectors."""
    turns, cos_theta = angles
    here = np.array([[f_psi, f_phi]])
    rss = np.concatenate(
        [
            data.rss_of(data.geometric_columns(here, indices, turns[g : g + chunk], cos_theta[g : g + chunk]))
            for g in range(0, len(poles), chunk)
        ]
    )
    single = not np.any(indices[:, 1])
    harmonics = int(indices[:, 0].max())  # the turns the series uses (``angles`` may hold more)
    best = np.inf
    for g in np.argsort(rss)[:best_poles]:
        centre, size = (float(rss[g]), f_psi, f_phi), step
        for _ in range(levels):
            offsets = (np.arange(points) - points // 2) * size
            grid = np.stack(
                [centre[1] + offsets, np.full(points, centre[2])]
                if single
                else [a.reshape(-1) for a in np.meshgrid(centre[1] + offsets, centre[2] + offsets, indexing="ij")],
                -1,
            )
            trial = data.rss_of(data.geometric_columns(grid, indices, turns[g], cos_theta[g]))
            i = int(np.argmin(trial))
            if trial[i] < centre[0]:
                centre = (float(trial[i]), float(grid[i, 0]), float(grid[i, 1]))
            size /= 3
        pole, size = poles[g], 0.5 * np.sqrt(4 * np.pi / len(poles))
        frequencies = np.array([centre[1:]] * 9)
        for _ in range(3):
            neighbours = _pole_neighbours(pole, size)
            local_turns, local_cos = _pole_angles(bisector, neighbours, harmonics)
            trial = data.rss_of(data.geometric_columns(frequencies, indices, local_turns, local_cos))
            i = int(np.argmin(trial))
            if trial[i] < centre[0]:
                centre, pole = (float(trial[i]), centre[1], centre[2]), neighbours[i]
            size /= 2
        best = min(best, centre[0])
    return best


def tumbler_periodogram(
    times,
    brightness,
    *,
    sun=None,
    observer=None,
    lightcurve=None,
    magnitudes: bool = False,
    period_range=None,
    order: int = 2,
    oversampling: float = 5.0,
    peaks: int = 6,
    tolerance: float = 1.0,
    max_proposals: int = 12,
    map_halfwidth: float = 6.0,
    lattices_kept: int = 8,
    second_minima: int = 4,
    psi_order: int = 2,
    phi_order: int = 3,
    drift: int = 1,
    max_width: float = 0.1,
    refined_readings: int = 32,
    poles: int = 400,
    geometric_orders=(2, 2),
) -> TumblerPeriodogram:
    """Candidate ranges of a tumbler's two periods (P_psi, P_phi) from its light curves (module
    docstring): a two-period Fourier periodogram after Pravec et al. (2005, Icarus 173, 108).

    Arguments: ``times`` (N,); ``brightness`` (N,) fluxes (> 0), or magnitudes with ``magnitudes=True``;
    ``sun``, ``observer`` (N, 3) or (3,): unit vectors from the body to the Sun and to the observer, as
    for :func:`fit_lightcurve` (optional, both or neither: they turn on the geometric ranking, module
    docstring, step 4; ``poles`` trial directions of L, ``geometric_orders`` its series' (psi, phi)
    orders); ``lightcurve`` (N,) label of each sample's light curve (one unknown additive offset in
    log flux each, e.g. a night of relative photometry; default: one curve).  ``period_range`` = (p_min, p_max):
    the band searched for the light curve's basis periods 1 / f1 and 1 / f2 (the time unit of
    ``times``); P_phi may come out longer (f_phi is a difference of lattice frequencies).

    ``order``: m of the two-period series (2: 2 m^2 + 2 m = 12 frequencies, Pravec et al.'s usual
    choice); ``oversampling``: grid points per 1 / T in the scans (T the data's span); ``peaks``: the
    one-period minima followed up; ``tolerance``: the half-width of each period's range in frequency,
    in units of 1 / T (1: a full resolution element, several times the error of the minima on the
    synthetic family of ``benchmarks/lightcurve_periodogram.py``), capped at ``max_width`` (relative
    half-width of each range, < 1); ``max_proposals``: the length of the list; ``map_halfwidth``: the
    extent of the RMS map around the best basis, in units of 1 / T; ``lattices_kept``: the lattices
    read as periods; ``second_minima``: the minima of each second-frequency scan refined;
    ``psi_order``, ``phi_order``, ``drift``: the readings' series (harmonics of psi and of phi, the
    degree of the coefficients' polynomial drift over the span; module docstring, step 4);
    ``refined_readings``: the readings refined locally.

    Returns a :class:`TumblerPeriodogram`: ``proposals`` (ranked, each ready for
    ``fit_lightcurve(..., periods=proposal)``; a principal-axis one with ``principal_axis=True``:
    ``result.fit_options(i)``), their ``modes``, ``centres`` and ``scores``, and the scans.

    Refused with a ValueError naming the argument: times not one-dimensional, not finite or all
    equal, brightness not finite, of another shape, or <= 0 without ``magnitudes``, labels of another
    shape, only one of ``sun`` and ``observer``, either of another shape, not finite or not unit
    vectors, the two opposite (phase angle 180 degrees), ``poles`` below 1, ``geometric_orders`` not
    two orders >= 1, a ``period_range`` that is missing or not positive and increasing, fewer samples
    than the series has parameters, counts or orders below 1 (``drift`` below 0), non-positive ``oversampling``
    or ``tolerance``, ``max_width`` outside (0, 1).  numpy
    only (float64); for a thousand samples on one core 3 to 12 seconds, 14 to 28 with the geometric
    ranking (benchmarks/lightcurve_periodogram.py).
    """
    times = checks.real_array("times", times)
    if times.ndim != 1:
        raise ValueError(f"times must be one-dimensional (N,), got shape {times.shape}")
    checks.check_finite("times", times)
    n = len(times)
    values = checks.real_array("brightness", brightness)
    if values.shape != (n,):
        raise ValueError(f"brightness must have shape (N,) = ({n},) like times, got {values.shape}")
    if magnitudes:
        checks.check_finite("brightness", values)
        values = -0.4 * np.log(10.0) * values.astype(float)
    else:
        checks.check_positive("brightness", values)
        values = np.log(values.astype(float))
    if (sun is None) != (observer is None):
        raise ValueError("sun and observer: give both (the geometric ranking) or neither")
    bisector = None
    if sun is not None:
        directions = []
        for name, value in (("sun", sun), ("observer", observer)):
            value = checks.real_array(name, value)
            if value.shape not in ((3,), (n, 3)):
                raise ValueError(f"{name} must have shape (N, 3) = ({n}, 3) like times, or (3,), got {value.shape}")
            value = np.broadcast_to(value, (n, 3)).astype(float)
            checks.check_finite(name, value)
            checks.check_unit_rows(name, value, what="unit vectors")
            directions.append(value)
        bisector = directions[0] + directions[1]
        length = np.linalg.norm(bisector, axis=-1)
        if np.any(length < 1e-6):
            raise ValueError(
                f"sun and observer are opposite at sample {int(np.argmin(length))} (phase angle 180 degrees)"
            )
        bisector = bisector / length[:, None]
    labels = np.zeros(n, int) if lightcurve is None else np.asarray(lightcurve)
    if labels.shape != (n,):
        raise ValueError(f"lightcurve must have shape (N,) = ({n},) like times, got {labels.shape}")
    if period_range is None:
        raise ValueError("period_range: give the band (p_min, p_max) of periods to search, in the unit of times")
    p_min, p_max = checks.interval("period_range", period_range)
    order = checks.integer("order", order, minimum=1)
    peaks = checks.integer("peaks", peaks, minimum=1)
    max_proposals = checks.integer("max_proposals", max_proposals, minimum=1)
    oversampling = checks.scalar("oversampling", oversampling, positive=True)
    tolerance = checks.scalar("tolerance", tolerance, positive=True)
    max_width = checks.scalar("max_width", max_width, positive=True)
    if max_width >= 1:
        raise ValueError(f"max_width must be < 1 (a relative half-width), got {max_width}")
    psi_order = checks.integer("psi_order", psi_order, minimum=1)
    phi_order = checks.integer("phi_order", phi_order, minimum=1)
    drift = checks.integer("drift", drift, minimum=0)
    lattices_kept = checks.integer("lattices_kept", lattices_kept, minimum=1)
    second_minima = checks.integer("second_minima", second_minima, minimum=1)
    refined_readings = checks.integer("refined_readings", refined_readings, minimum=1)
    map_halfwidth = checks.scalar("map_halfwidth", map_halfwidth, positive=True, allow_zero=True)
    poles = checks.integer("poles", poles, minimum=1)
    if np.shape(geometric_orders) != (2,):
        raise ValueError(f"geometric_orders must be (psi_order, phi_order), got {geometric_orders!r}")
    geometric_orders = tuple(checks.integer("geometric_orders", order, minimum=1) for order in geometric_orders)
    times = times.astype(float)
    span = float(times.max() - times.min())
    if span <= 0:
        raise ValueError("times must span an interval: all are equal")
    indices = _lattice_indices(order)
    curves = len(np.unique(labels))
    parameters = max(2 * len(indices), 2 * len(_reading_indices(psi_order, phi_order)) * (drift + 1))
    if bisector is not None:
        parameters = max(parameters, 4 * len(_reading_indices(*geometric_orders)))
    parameters += curves
    if n <= parameters:
        raise ValueError(
            f"times: {n} samples cannot fit a two-period series of order {order} (psi_order {psi_order}, "
            f"phi_order {phi_order}, drift {drift}) and {curves} offsets ({parameters} parameters)"
        )
    data = _Data(times, values, labels)
    resolution = 1 / span
    step = resolution / oversampling

    # ---- 1. one-period scan (harmonics 1 and 2) at the full resolution
    f_low, f_high = 1 / p_max, 1 / p_min
    frequencies = np.arange(f_low, f_high + step, step)
    harmonics = np.arange(1, 3)
    rss_one = data.rss(frequencies[:, None], harmonics[:, None])
    separation = max(int(round(2 * oversampling)), 1)
    fundamentals = [frequencies[i] for i in _local_minima(rss_one, peaks, separation)]
    if not fundamentals:
        fundamentals = [frequencies[int(np.argmin(rss_one))]]
    # Each fundamental to a fiftieth of 1 / T: at a high signal-to-noise ratio the second scan's
    # landscape (f1 held) changes over a small fraction of the grid step.
    fine = np.linspace(-1, 1, 21) * step
    fundamentals = [
        float(fa + fine[int(np.argmin(data.rss((fa + fine)[:, None], harmonics[:, None])))]) for fa in fundamentals
    ]

    # ---- 2. the second frequency for each candidate f1, then joint refinement (with the geometry,
    # the series' coefficients drift as the readings' do: the lattice of a tumbler seen over months
    # at a changing aspect fits a fixed series worse than some of its aliases).
    basis_data = data if bisector is None else _Data(times, values, labels, drift=drift)
    basis_terms = 2 * len(indices) * (1 if bisector is None else drift + 1)
    found = []
    for fa in fundamentals:
        for f1 in (fa, fa / 2):
            if f1 <= 4 * resolution:
                continue
            grid = np.arange(2 * resolution, f1 - 2 * resolution, step * oversampling / 3)
            if len(grid) < 3:
                continue
            rss_two = basis_data.rss(np.stack([np.full_like(grid, f1), grid], -1), indices)
            for i in _local_minima(rss_two, second_minima, 3):
                found.append(_refine(basis_data, indices, f1, float(grid[i]), step, levels=2, points=5))
    found.sort(key=lambda item: item[2])
    lattices = []  # distinct lattices, best first
    for item in found:
        if not any(_same_lattice(np.array(item[:2]), np.array(kept[:2]), 0.3 * resolution) for kept in lattices):
            lattices.append(item)

    # ---- 3. readings of the best lattices as (f_psi, f_phi), each scored in its own basis by the
    # reading's series (psi harmonics |j| <= psi_order, phi harmonics |k| <= phi_order) with
    # coefficients drifting over the span (Legendre polynomials of time up to ``drift``).
    rich = _Data(times, values, labels, drift=drift)
    reading_indices = _reading_indices(psi_order, phi_order)
    reading_dof = rich.dof - 2 * len(reading_indices) * (drift + 1)

    def rms(rss, dof):
        return float(np.sqrt(rss / max(dof, 1)))

    candidates = []
    for f1, f2, _ in lattices[:lattices_kept]:
        for c, basis_vector in (
            (f2, True),
            (f1 - f2, True),
            (f1 + f2, False),
            (f2 / 2, False),
            ((f1 - f2) / 2, False),
            ((f1 + f2) / 2, False),
        ):
            if c <= 2 * resolution:
                continue
            readings_of_c = [(f1 + c, c, "SAM"), (f1, c, "LAM")]
            if basis_vector and f1 - c > 2 * resolution:
                # The long-axis mode's lattice found through f_psi + f_phi (f1) and f_phi (c).
                readings_of_c.append((f1 - c, c, "LAM"))
            for f_psi, f_phi, mode in readings_of_c:
                near = [r for r in candidates if max(abs(f_psi - r[0]), abs(f_phi - r[1])) < 0.5 * resolution]
                if not near:
                    candidates.append((f_psi, f_phi, mode))
    if candidates:
        first = rich.rss(np.array([(fp, fq) for fp, fq, _ in candidates]), reading_indices)
        order_first = np.argsort(first)[:refined_readings]
    else:
        order_first = []
    readings = []
    for k in order_first:
        f_psi, f_phi, mode = candidates[k]
        best = _refine(rich, reading_indices, f_psi, f_phi, 0.15 * resolution, levels=2, points=5)
        if any(max(abs(best[0] - r[0]), abs(best[1] - r[1])) < 0.5 * resolution for r in readings):
            continue
        readings.append((best[0], best[1], mode, best[2]))
    readings.sort(key=lambda item: item[3])

    # Principal-axis comparison: the best single period with 2 (psi_order + phi_order) harmonics,
    # drifting alike.
    best_one = frequencies[int(np.argmin(rss_one))]
    pa_harmonics = np.arange(1, 2 * (psi_order + phi_order) + 1)
    one_period = []
    for f in [f for fa in fundamentals for f in (fa, fa / 2) if f > 2 * resolution]:
        offsets = (np.arange(9) - 4) * step / 2
        trial = rich.rss((f + offsets)[:, None], pa_harmonics[:, None])
        one_period.append((float(np.min(trial)), float(f + offsets[int(np.argmin(trial))])))
    rss_pa, f_pa = min(one_period) if one_period else (float(rss_one.min()), float(best_one))
    coefficients = 2 * len(pa_harmonics) * (drift + 1)
    pa_dof = rich.dof - coefficients
    # A period's multiples fit as well as it does (its harmonics are theirs): the period is halved
    # while its half fits as well, within three standard deviations of the chi-square difference of
    # the two series (C coefficients each, half of each's not the other's: a variance of 2 C in units
    # of the noise's variance).  The bound is the noise's, not a share of the signal: a faint
    # rotator's whole light curve may stand only a few such deviations above the noise.
    for _ in range(2):
        offsets = (np.arange(9) - 4) * step / 2
        trial = rich.rss((2 * f_pa + offsets)[:, None], pa_harmonics[:, None])
        allowance = 3 * np.sqrt(2 * coefficients) * rss_pa / max(pa_dof, 1)
        if 2 * f_pa > f_high or float(np.min(trial)) > rss_pa + allowance:
            break
        rss_pa, f_pa = float(np.min(trial)), float(2 * f_pa + offsets[int(np.argmin(trial))])
    if bisector is None:
        extra = 2 * (len(reading_indices) - len(pa_harmonics)) * (drift + 1)
    else:
        # ---- 3b. the geometric ranking: each reading (and the single period) rescored by the series
        # whose psi harmonics turn with the bisector's azimuth about a trial pole, at its best pole
        # and frequencies near the reading's.  The centres stay the drifting series' refinements: the
        # azimuth's rate about a pole trades with f_psi, and on the grid of poles (about 10 degrees
        # apart) the geometric fit's frequencies can move by a resolution element.
        pole_grid = _fibonacci_sphere(poles)
        pa_harmonics = np.arange(1, 2 * sum(geometric_orders) + 1)
        angles = _pole_angles(bisector, pole_grid, len(pa_harmonics))
        geometric_indices = _reading_indices(*geometric_orders)
        rescored = []
        for f_psi, f_phi, mode, _ in readings:
            rss = _geometric_fit(
                data, f_psi, f_phi, geometric_indices, pole_grid, angles, bisector, 0.4 * resolution, levels=3
            )
            rescored.append((f_psi, f_phi, mode, rss))
        readings = sorted(rescored, key=lambda item: item[3])
        reading_dof = data.dof - 4 * len(geometric_indices)
        single = np.stack([pa_harmonics, 0 * pa_harmonics], -1)
        rss_pa = _geometric_fit(data, f_pa, 0.0, single, pole_grid, angles, bisector, step / 2)
        pa_dof = data.dof - 4 * len(pa_harmonics)
        extra = 4 * (len(geometric_indices) - len(pa_harmonics))
    noise = (readings[0][3] if readings else rss_pa) / max(reading_dof, 1)
    # The single period's allowance: the chi-square a tumbling reading's extra coefficients may gain
    # on a rotator's light curve (five per coefficient).
    allowance = 5 * max(extra, 1) * noise
    tumbling = bool(readings) and rss_pa - readings[0][3] > allowance

    # ---- 4. ranges: +- tolerance / T in frequency, at most +- max_width relative
    proposals, modes, centres, scores = [], [], [], []

    def interval(f):
        width = min(tolerance * resolution, max_width * f)
        return (1 / (f + width), 1 / (f - width))

    def add(f_psi, f_phi, mode, score):
        proposals.append((interval(f_psi), interval(f_phi)))
        modes.append(mode)
        centres.append((1 / f_psi, 1 / f_phi))
        scores.append(score)

    def add_principal(f, score):
        proposals.append(interval(f))
        modes.append("PA")
        centres.append((1 / f, np.inf))
        scores.append(score)

    # A tumbler's list ends with the best single period, as a principal-axis rotator's; in a full list
    # it takes the last reading's slot unless it fits worse than that reading by more than the
    # allowance (the tumbling test's, against the last reading instead of the first).
    principal_last = (
        tumbling
        and max_proposals >= 4
        and (len(readings) < max_proposals or rss_pa - readings[max_proposals - 1][3] <= allowance)
    )
    if not tumbling:
        add_principal(f_pa, rms(rss_pa, pa_dof))
        add_principal(f_pa / 2, rms(rss_pa, pa_dof))
        if 2 * f_pa <= f_high:
            add_principal(2 * f_pa, rms(rss_pa, pa_dof))
    for f_psi, f_phi, mode, rss in readings:
        add(f_psi, f_phi, mode, rms(rss, reading_dof))
    kept = max_proposals - 1 if principal_last else max_proposals
    proposals, modes, centres, scores = (x[:kept] for x in (proposals, modes, centres, scores))
    if principal_last:
        add_principal(f_pa, rms(rss_pa, pa_dof))
    best = lattices[0] if lattices else (f_pa, f_pa / 2, rss_pa)
    basis_dof = data.dof - basis_terms
    if map_halfwidth > 0:
        offsets = np.linspace(-map_halfwidth, map_halfwidth, 41) * resolution
        map_f1, map_f2 = np.meshgrid(best[0] + offsets, best[1] + offsets, indexing="ij")
        map_rss = basis_data.rss(np.stack([map_f1.reshape(-1), map_f2.reshape(-1)], -1), indices)
        map_rms = np.sqrt(map_rss / max(basis_dof, 1)).reshape(map_f1.shape)
    else:
        map_f1 = map_f2 = map_rms = np.zeros((0, 0))
    return TumblerPeriodogram(
        proposals=proposals,
        modes=modes,
        centres=np.array(centres, float).reshape(-1, 2),
        scores=np.array(scores, float),
        bases=np.array([item[:2] for item in lattices], float).reshape(-1, 2),
        basis_rms=np.array([rms(item[2], basis_dof) for item in lattices], float),
        rms_one_period=rms(rss_pa, pa_dof),
        frequencies=frequencies,
        rms=np.sqrt(rss_one / max(data.dof - 4, 1)),
        span=span,
        map_f1=map_f1,
        map_f2=map_f2,
        map_rms=map_rms,
    )
