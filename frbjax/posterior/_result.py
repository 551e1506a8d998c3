"""The result of a posterior: draws as arrays, convergence diagnostics, summaries, mode probabilities."""

from __future__ import annotations

import statistics

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int
from numpyro.diagnostics import effective_sample_size, split_gelman_rubin

from ..fit import AttitudeFit
from ..lightcurve import ConvexShape
from ..lightcurve._fit import _ellipsoid_shape, _SEARCH_SUBDIVISIONS


__all__ = [
    "AttitudePosterior",
    "LightcurvePosterior",
    "PosteriorSummary",
    "PosteriorWarning",
    "bulk_ess",
    "split_r_hat",
    "tail_ess",
]

# Convergence thresholds of the warning (Vehtari et al. 2021: R-hat below 1.01).
R_HAT_LIMIT = 1.01
# The central intervals that summary() reports.
_QUANTILES = (0.05, 0.5, 0.95)


class PosteriorWarning(UserWarning):
    """The sampler's diagnostics failed (split R-hat above 1.01, or divergent transitions): the draws
    may not represent the posterior.  Run longer chains, or look for several modes."""


def split_r_hat(chains: np.ndarray) -> np.ndarray:
    """Split R-hat (numpy's ``numpyro.diagnostics.split_gelman_rubin``) of draws (chains, draws, ...)."""
    return np.asarray(split_gelman_rubin(np.asarray(chains, float)))


def _rank_normalised(chains):
    """Draws replaced by the normal quantiles of their pooled ranks (Vehtari et al. 2021, eq. 14)."""
    chains = np.asarray(chains, float)
    flat = chains.reshape(-1, *chains.shape[2:])
    ranks = np.argsort(np.argsort(flat, axis=0, kind="stable"), axis=0) + 1
    size = flat.shape[0]
    inverse_cdf = np.vectorize(statistics.NormalDist().inv_cdf)
    return inverse_cdf((ranks - 0.375) / (size + 0.25)).reshape(chains.shape)


def bulk_ess(chains: np.ndarray) -> np.ndarray:
    """Bulk effective sample size: ``numpyro.diagnostics.effective_sample_size`` of the rank-normalised
    draws (chains, draws, ...) (Vehtari et al. 2021)."""
    return np.asarray(effective_sample_size(_rank_normalised(chains)))


def tail_ess(chains: np.ndarray) -> np.ndarray:
    """Tail effective sample size: the smaller of the effective sample sizes of the indicators of the
    5% and 95% quantiles (Vehtari et al. 2021), by ``numpyro.diagnostics.effective_sample_size``."""
    chains = np.asarray(chains, float)
    flat = chains.reshape(-1, *chains.shape[2:])
    sizes = []
    for quantile, below in ((0.05, True), (0.95, False)):
        cut = np.quantile(flat, quantile, axis=0)
        indicator = (chains <= cut) if below else (chains >= cut)
        sizes.append(np.asarray(effective_sample_size(indicator.astype(float))))
    return np.minimum(*sizes)


def long_axis_mode(inertia: np.ndarray, angular_velocity: np.ndarray) -> np.ndarray:
    r"""Whether each motion is in long-axis mode: $|L|^2 < 2 E I_\text{mid}$ (as ``tumbler_periods``).

    With principal moments $I_i$ and body rates $\Omega_i$ along their axes, $|L|^2 - 2E I_\text{mid} =
    \sum_i I_i \Omega_i^2 (I_i - I_\text{mid})$, a sum without cancellation between large terms.
    """
    middle = np.median(inertia, axis=-1, keepdims=True)
    return np.sum(inertia * angular_velocity**2 * (inertia - middle), axis=-1) < 0


def _by_chain(draws, num_chains) -> np.ndarray:
    """Draws (S, ...), chain after chain, as (chains, draws per chain, ...)."""
    draws = np.asarray(draws)
    return draws.reshape((num_chains, -1) + draws.shape[1:])


def _summary(quantities, by_chain) -> PosteriorSummary:
    """``summary()`` of named draws (S,), ``by_chain`` reshaping draws to (chains, draws)."""
    rows = PosteriorSummary()
    for name, draws in quantities.items():
        chains = by_chain(draws)
        low, median, high = np.quantile(draws, _QUANTILES)
        varies = bool(np.ptp(draws) > 0)  # the largest moment is 1 in every draw
        with np.errstate(invalid="ignore", divide="ignore"):
            r_hat, ess_bulk, ess_tail = (
                (float(split_r_hat(chains)), float(bulk_ess(chains)), float(tail_ess(chains)))
                if varies
                else (np.nan, np.nan, np.nan)
            )
        rows[name] = {
            "mean": float(np.mean(draws)),
            "sd": float(np.std(draws, ddof=1)),
            "5%": float(low),
            "50%": float(median),
            "95%": float(high),
            "r_hat": r_hat,
            "ess_bulk": ess_bulk,
            "ess_tail": ess_tail,
        }
    return rows


def _mode_probabilities(long_axis_mode, by_chain) -> dict:
    """``mode_probabilities()`` of the draws' long-axis flags."""
    long_axis = np.asarray(long_axis_mode, float)
    probability = float(np.mean(long_axis))
    return {
        "short_axis": 1.0 - probability,
        "long_axis": probability,
        "long_axis_by_chain": by_chain(long_axis).mean(axis=1),
    }


class PosteriorSummary(dict):
    """``{quantity: {statistic: value}}``; printed, a table (mean, sd, 5%, 50%, 95%, R-hat, ESS)."""

    def __str__(self) -> str:
        columns = ("mean", "sd", "5%", "50%", "95%", "r_hat", "ess_bulk", "ess_tail")
        width = max(len(name) for name in self) + 2
        lines = [" " * width + "".join(f"{column:>12}" for column in columns)]
        for name, row in self.items():
            cells = []
            for column in columns:
                value = row[column]
                cells.append(f"{value:12.1f}" if column.startswith("ess") else f"{value:12.5g}")
            lines.append(f"{name:<{width}}" + "".join(cells))
        return "\n".join(lines)


class AttitudePosterior(eqx.Module):
    r"""Result of :func:`attitude_posterior`: posterior draws and the sampler's diagnostics.

    Draws (S = ``num_chains`` x draws per chain, chain after chain):

    - ``inertia`` (S, 3): principal moments, scaled so that the largest is 1 (in the data's body axes;
      ascending along ``principal_axes`` for ``inertia="tensor"``);
    - ``principal_axes`` (S, 3, 3): the principal axes as columns in the body frame (the identity for
      ``inertia="principal"``);
    - ``angular_velocity`` (S, 3): body angular velocity at t = 0;
    - ``attitude`` (S, 4): attitude (w, x, y, z; w >= 0) at t = 0;
    - ``parameters`` (S, P): theta of :func:`frbjax.fit_attitude` (log I2/I1, log I3/I1, Omega at the
      reference time, delta about the observed attitude at the reference time, and psi for a tensor);
      ``parameter_names`` names them;
    - ``long_axis_mode`` (S,): whether the draw rotates in long-axis mode, $|L|^2 < 2 E I_\text{mid}$
      (``mode_probabilities``);
    - ``chain`` (S,): the chain of each draw; ``diverging`` (S,): whether its transition diverged.

    Diagnostics: ``r_hat`` (P,), split R-hat of each parameter over the chains (1 when they agree);
    ``ess_bulk``, ``ess_tail`` (P,), the bulk and tail effective sample sizes (Vehtari et al. 2021,
    by ``numpyro.diagnostics``); per chain ``divergences`` (C,), ``step_size`` (C,) (in the whitened
    parameters: about 1 where the posterior is the fit's Gaussian), ``acceptance`` (C,) (mean
    acceptance probability) and ``mean_steps`` (C,) (leapfrog steps per draw).  ``fit``: the
    :class:`frbjax.AttitudeFit` about which the parameters were whitened and the chains started;
    ``reference_time``: its t_ref.
    """

    inertia: Float[Array, "S 3"]
    principal_axes: Float[Array, "S 3 3"]
    angular_velocity: Float[Array, "S 3"]
    attitude: Float[Array, "S 4"]
    parameters: Float[Array, "S P"]
    long_axis_mode: Bool[Array, " S"]
    chain: Int[Array, " S"]
    diverging: Bool[Array, " S"]
    r_hat: Float[Array, " P"]
    ess_bulk: Float[Array, " P"]
    ess_tail: Float[Array, " P"]
    divergences: Int[Array, " C"]
    step_size: Float[Array, " C"]
    acceptance: Float[Array, " C"]
    mean_steps: Float[Array, " C"]
    fit: AttitudeFit
    reference_time: Float[Array, ""]
    parameter_names: tuple[str, ...] = eqx.field(static=True)
    num_chains: int = eqx.field(static=True)

    def _by_chain(self, draws) -> np.ndarray:
        return _by_chain(draws, self.num_chains)

    def quantities(self) -> dict[str, np.ndarray]:
        """Every scalar quantity's draws (S,), by name: the moments ``I_1..3``, the angular velocity at
        t = 0 ``omega0_1..3``, and the parameters (``parameter_names``)."""
        named = {}
        for i in range(3):
            named[f"I_{i + 1}"] = np.asarray(self.inertia[:, i])
        for i in range(3):
            named[f"omega0_{i + 1}"] = np.asarray(self.angular_velocity[:, i])
        for i, name in enumerate(self.parameter_names):
            named[name] = np.asarray(self.parameters[:, i])
        return named

    def summary(self) -> PosteriorSummary:
        """Mean, standard deviation, 5%, 50% (median) and 95% quantiles (the 90% central interval), split
        R-hat and bulk and tail effective sample sizes of every quantity of ``quantities()``.

        A dict ``{name: {"mean", "sd", "5%", "50%", "95%", "r_hat", "ess_bulk", "ess_tail"}}``;
        ``print`` shows it as a table.
        """
        return _summary(self.quantities(), self._by_chain)

    def mode_probabilities(self) -> dict:
        """The posterior probability of each rotation mode: ``{"short_axis": p, "long_axis": 1 - p,
        "long_axis_by_chain": (C,) array}``.

        Short-axis mode (SAM): $|L|^2 > 2 E I_\\text{mid}$, the angular momentum circulates about the
        axis of the largest moment; long-axis mode (LAM): about the smallest (the convention of
        :func:`frbjax.lightcurve.tumbler_periods`).  The fractions of draws; chains that disagree
        (``long_axis_by_chain``) have found different modes, and the pooled fraction is then only
        as good as the chains' starts.
        """
        return _mode_probabilities(self.long_axis_mode, self._by_chain)

    def to_arviz(self):
        """The draws as an ``arviz`` InferenceData (groups posterior and sample_stats, dims (chain,
        draw, ...)); needs arviz (imported here, on first use)."""
        try:
            import arviz
        except ImportError as error:
            raise ImportError(
                "AttitudePosterior.to_arviz needs arviz, which is not installed: pip install arviz"
            ) from error
        posterior = {
            "inertia": self._by_chain(self.inertia),
            "angular_velocity": self._by_chain(self.angular_velocity),
            "attitude": self._by_chain(self.attitude),
            "long_axis_mode": self._by_chain(self.long_axis_mode),
        }
        for i, name in enumerate(self.parameter_names):
            posterior[name] = self._by_chain(self.parameters[:, i])
        sample_stats = {"diverging": self._by_chain(self.diverging)}
        try:
            return arviz.from_dict(posterior=posterior, sample_stats=sample_stats)
        except TypeError:  # arviz 1.0 takes one dict of groups
            return arviz.from_dict({"posterior": posterior, "sample_stats": sample_stats})


# The motion's parameters of a light-curve fit (frbjax.lightcurve's module docstring), by name.
LIGHTCURVE_PARAMETER_NAMES = (
    "log_I1",
    "log_I2",
    "log_L",
    "delta_1",
    "delta_2",
    "delta_3",
    "direction_1",
    "direction_2",
)


class LightcurvePosterior(eqx.Module):
    r"""Result of :func:`lightcurve_posterior`: posterior draws and the sampler's diagnostics.

    Draws (S = ``num_chains`` x draws per chain, chain after chain): ``periods`` (S, 2), (P_psi, P_phi)
    (principal axis: (P, inf)); ``inertia`` (S, 3), the moments (I1, I2, I3) scaled so that the largest
    is 1; ``long_axis_mode`` (S,); ``parameters`` (S, 8), the motion's parameters of
    :func:`frbjax.lightcurve.fit_lightcurve` at the epoch; ``shape_parameters`` (S, K), the
    shape's (a convex shape's log-areas on ``fit.shape.normals``, an ellipsoid's two log axis
    ratios; the fit's in every draw when ``shape_sampled`` is False: :meth:`shape` builds a
    draw's); ``chain``, ``diverging`` (S,).  Diagnostics of the sampled motion parameters
    (``parameter_names``): ``r_hat``, ``ess_bulk``, ``ess_tail``; ``divergences`` (C,) per chain.
    ``fit``: the :class:`frbjax.lightcurve.LightcurveFit` about which the chains ran.
    """

    inertia: Float[Array, "S 3"]
    periods: Float[Array, "S 2"]
    long_axis_mode: Bool[Array, " S"]
    parameters: Float[Array, "S 8"]
    shape_parameters: Float[Array, "S K"]
    chain: Int[Array, " S"]
    diverging: Bool[Array, " S"]
    r_hat: Float[Array, " F"]
    ess_bulk: Float[Array, " F"]
    ess_tail: Float[Array, " F"]
    divergences: Int[Array, " C"]
    fit: eqx.Module
    parameter_names: tuple[str, ...] = eqx.field(static=True)
    num_chains: int = eqx.field(static=True)
    shape_sampled: bool = eqx.field(static=True)

    def _by_chain(self, draws) -> np.ndarray:
        return _by_chain(draws, self.num_chains)

    def shape(self, draw: int) -> ConvexShape:
        """The :class:`frbjax.lightcurve.ConvexShape` of draw ``draw`` (an index into the S draws)."""
        values = self.shape_parameters[draw]
        if self.fit.shape_model == "convex":
            return ConvexShape(self.fit.shape.normals, jnp.exp(values))
        return _ellipsoid_shape(values, _SEARCH_SUBDIVISIONS)

    def quantities(self) -> dict[str, np.ndarray]:
        """Every scalar quantity's draws (S,): ``P_psi``, ``P_phi`` (finite ones), ``I_1..3`` and the
        sampled parameters."""
        named = {"P_psi": np.asarray(self.periods[:, 0])}
        if np.all(np.isfinite(np.asarray(self.periods[:, 1]))):
            named["P_phi"] = np.asarray(self.periods[:, 1])
        for i in range(3):
            named[f"I_{i + 1}"] = np.asarray(self.inertia[:, i])
        for name in self.parameter_names:
            named[name] = np.asarray(self.parameters[:, LIGHTCURVE_PARAMETER_NAMES.index(name)])
        return named

    def summary(self) -> PosteriorSummary:
        """As :meth:`AttitudePosterior.summary`, of ``quantities()``."""
        return _summary(self.quantities(), self._by_chain)

    def mode_probabilities(self) -> dict:
        """As :meth:`AttitudePosterior.mode_probabilities`, and ``"periods_by_chain"`` (C, 2): each
        chain's median periods, which differ when chains sit at different period aliases."""
        result = _mode_probabilities(self.long_axis_mode, self._by_chain)
        result["periods_by_chain"] = np.median(self._by_chain(self.periods), axis=1)
        return result
