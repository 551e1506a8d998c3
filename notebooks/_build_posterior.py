"""Builds notebooks/posterior.ipynb (without outputs): .venv/bin/python notebooks/_build_posterior.py"""

import pathlib

import nbformat


md, code = nbformat.v4.new_markdown_cell, nbformat.v4.new_code_cell

cells = [
    md("""# Which way is it tumbling? The posterior of a body next to the separatrix

A best fit gives one motion and a Gaussian around it.  Next to the separatrix the data may not say
on which side of it the body is: in short-axis mode (SAM) the angular momentum circulates about the
axis of the largest moment, in long-axis mode (LAM) about the smallest, and the two motions drift
apart over time.  `frbjax.posterior.attitude_posterior` samples the posterior of the inertia ratios,
the angular velocity and the attitude with NUTS (numpyro), on the exact motion and its exact
gradients, and reports the probability of each mode.

Here: moments $0.6 : 0.8 : 1$, started $1.4\\times10^{-4}$ from the separatrix on the long-axis side
($2 E I_2 / |L|^2 = 1.00014$), 40 attitudes over 20 s (three rotations) with 10 mrad of noise."""),
    code(
        """# Number of times at which the predicted motions are drawn; the tests run with fewer.
N_SAMPLES = 2000
# The sampler's sizes: chains, warmup steps and draws per chain (the tests run smaller ones).
CHAINS, WARMUP, DRAWS = 4, 500, 1000""",
        metadata={"tags": ["parameters"]},
    ),
    code("""import jax

jax.config.update("jax_enable_x64", True)  # the library leaves this to the application

import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

from frbjax import fit_attitude, FreeRigidBody
from frbjax import _quaternion as quaternion
from frbjax.posterior import attitude_posterior


@jax.jit
def attitudes(inertia, momentum, attitude, t):
    \"\"\"q(t) of free rigid bodies: one body at times (K,), or bodies (S,) at times (K, 1); compiled once per shape.\"\"\"
    return FreeRigidBody(inertia, momentum, attitude).quaternion(t)


def angle_between(p, q):
    \"\"\"The rotation angle (rad) between attitudes p and q (either sign of either).\"\"\"
    return 2 * np.arccos(np.clip(np.abs(np.sum(np.asarray(p) * np.asarray(q), axis=-1)), 0.0, 1.0))"""),
    md("## The data"),
    code("""rng = np.random.default_rng(5)  # the noise
true_inertia = np.array([0.6, 0.8, 1.0])
true_omega = np.array([0.6, 0.05, 0.4645])
true_momentum = true_inertia * true_omega
true_attitude = np.array([1.0, 0.0, 0.0, 0.0])
noise = 1e-2
energy_ratio = np.sum(true_inertia * true_omega**2) * true_inertia[1] / np.sum(true_momentum**2)
print(f"2 E I2 / |L|^2 = {energy_ratio:.5f}  (> 1: long-axis mode)")

times = np.concatenate([[0.0], np.sort(np.random.default_rng(2018).uniform(0.0, 20.0, 39))])
clean = np.asarray(attitudes(jnp.asarray(true_inertia), jnp.asarray(true_momentum), jnp.asarray(true_attitude), jnp.asarray(times)))
# Isotropic noise of 10 mrad per axis, q_k = q(t_k) exp(n_k / 2), and a random sign per attitude.
perturbation = np.asarray(quaternion.exp_pure(jnp.asarray(rng.normal(scale=noise, size=(len(times), 3)))))
observed = np.array(quaternion.multiply(jnp.asarray(clean), jnp.asarray(perturbation)))
observed *= rng.choice([-1.0, 1.0], size=(len(times), 1))"""),
    md("""## The best fit

`fit_attitude` returns one motion: its inertia ratios, angular velocity and covariance say nothing
about the other mode."""),
    code("""fit = fit_attitude(times, observed, attitude_sigma=noise)
print("fit inertia   ", np.round(np.asarray(fit.inertia), 4), "  truth", true_inertia / true_inertia.max())
print("fit sigma     ", np.round(np.sqrt(np.diag(np.asarray(fit.inertia_covariance))), 4))
omega_fit = np.asarray(fit.angular_velocity)
fit_energy_ratio = np.sum(np.asarray(fit.inertia) * omega_fit**2) * np.asarray(fit.inertia)[1] / np.sum((np.asarray(fit.inertia) * omega_fit) ** 2)
print(f"fit 2 E I2 / |L|^2 = {fit_energy_ratio:.5f}:", "long-axis mode" if fit_energy_ratio > 1 else "short-axis mode")"""),
    md("""## The posterior

Four chains of NUTS, whitened by the fit's covariance and started at the fit (and at its runner-up
basins, if any).  The summary gives each quantity's mean, standard deviation, 90% central interval,
split R-hat and effective sample sizes."""),
    code("""posterior = attitude_posterior(
    times, observed, attitude_sigma=noise, initial=fit,
    num_chains=CHAINS, num_warmup=WARMUP, num_samples=DRAWS, progress=False,
)
print(posterior.summary())
modes = posterior.mode_probabilities()
print(f"P(short-axis mode) = {modes['short_axis']:.3f}, P(long-axis mode) = {modes['long_axis']:.3f}")
print("long-axis fraction per chain:", np.round(modes["long_axis_by_chain"], 3))"""),
    md("""## A corner plot, coloured by mode

The draws of the moments and the angular velocity at $t = 0$, short-axis draws in one colour and
long-axis draws in the other, the truth in black and the fit as a cross: the separatrix runs through
the posterior, which the chains cross."""),
    code("""names = ["I_1", "I_2", "omega0_1", "omega0_2", "omega0_3"]
labels = ["$I_1$", "$I_2$", "$\\\\Omega_1(0)$", "$\\\\Omega_2(0)$", "$\\\\Omega_3(0)$"]
draws = posterior.quantities()
truth = dict(zip(names, [*(true_inertia / true_inertia.max())[:2], *true_omega]))
fitted = dict(zip(names, [*np.asarray(fit.inertia)[:2], *omega_fit]))
long_axis = np.asarray(posterior.long_axis_mode)
# Long-axis draws first, so that the short-axis ones show on top.
colours = {"long-axis mode": ("tab:blue", long_axis), "short-axis mode": ("tab:orange", ~long_axis)}

figure, axes = plt.subplots(len(names), len(names), figsize=(10, 10))
for i, row in enumerate(names):
    for j, column in enumerate(names):
        axis = axes[i, j]
        if j > i:
            axis.set_visible(False)
            continue
        if i == j:
            bins = np.histogram_bin_edges(draws[row], bins=40)
            for label, (colour, chosen) in colours.items():
                axis.hist(draws[row][chosen], bins=bins, color=colour, alpha=0.6, label=label)
            axis.axvline(truth[row], color="black")
            axis.set_yticks([])
        else:
            for label, (colour, chosen) in colours.items():
                axis.scatter(draws[column][chosen], draws[row][chosen], s=2, color=colour, alpha=0.3)
            axis.scatter(truth[column], truth[row], marker="*", s=120, color="black", zorder=3)
            axis.scatter(fitted[column], fitted[row], marker="x", s=60, color="crimson", zorder=3)
        axis.xaxis.set_major_locator(plt.MaxNLocator(3))
        if i != j:
            axis.yaxis.set_major_locator(plt.MaxNLocator(3))
        if i == len(names) - 1:
            axis.set_xlabel(labels[j])
        if j == 0 and i > 0:
            axis.set_ylabel(labels[i])
axes[0, 0].legend(loc="upper left", fontsize=8, frameon=False)
figure.suptitle("Posterior draws by rotation mode (star: truth, cross: best fit)")
figure.tight_layout()"""),
    md("""## Which side of the separatrix

The separatrix is the level $2 E I_2 / |L|^2 = 1$; long-axis mode lies above it.  The draws of this
ratio (less 1) show how the posterior straddles it: the mode probabilities above are the two areas."""),
    code("""inertia_draws, omega_draws = np.asarray(posterior.inertia), np.asarray(posterior.angular_velocity)
momentum_draws = inertia_draws * omega_draws
ratio_draws = np.sum(inertia_draws * omega_draws**2, axis=1) * inertia_draws[:, 1] / np.sum(momentum_draws**2, axis=1)
figure, axis = plt.subplots(figsize=(8, 3.5))
bins = np.histogram_bin_edges(ratio_draws - 1, bins=60)
for label, (colour, chosen) in colours.items():
    axis.hist(ratio_draws[chosen] - 1, bins=bins, color=colour, alpha=0.7, label=f"{label}: {chosen.mean():.1%}")
axis.axvline(0.0, color="grey", linestyle="--", label="separatrix")
axis.axvline(energy_ratio - 1, color="black", label="truth")
axis.axvline(fit_energy_ratio - 1, color="crimson", label="best fit")
axis.set_xlabel("$2 E I_2 / |L|^2 - 1$")
axis.set_yticks([])
axis.legend(frameon=False, fontsize=8);"""),
    md("""## What the two modes predict

Each draw is a whole motion.  Propagated past the data (to 60 s), the draws of each mode stay
together while the two modes drift apart: the angle between each draw's attitude and the true one.
The posterior's prediction is a mixture of the two, weighted by the modes' probabilities."""),
    code("""later = np.linspace(0.0, 60.0, N_SAMPLES)
chosen = rng.choice(len(long_axis), size=min(200, len(long_axis)), replace=False)
inertia, omega = np.asarray(posterior.inertia)[chosen], np.asarray(posterior.angular_velocity)[chosen]
predicted = np.asarray(attitudes(
    jnp.asarray(inertia), jnp.asarray(inertia * omega), jnp.asarray(posterior.attitude)[chosen], jnp.asarray(later)[:, None]
))  # (times, draws, 4)
true_later = np.asarray(attitudes(jnp.asarray(true_inertia), jnp.asarray(true_momentum), jnp.asarray(true_attitude), jnp.asarray(later)))
error = np.degrees(angle_between(predicted, true_later[:, None, :]))

figure, axis = plt.subplots(figsize=(9, 4))
for label, (colour, mode) in colours.items():
    mask = mode[chosen]
    if mask.any():
        axis.plot(later, error[:, mask], color=colour, alpha=0.15, linewidth=0.7)
        axis.plot([], [], color=colour, label=f"{label} ({mask.sum()} draws)")
axis.axvspan(0.0, times[-1], color="grey", alpha=0.15, label="observed")
axis.set_xlabel("t (s)")
axis.set_ylabel("attitude error (deg)")
axis.set_yscale("log")
axis.legend(frameon=False)
axis.set_title("Posterior draws propagated beyond the data, against the true attitude");"""),
    md("""## With ten times less noise

At 1 mrad the data tell the modes apart: every draw is in long-axis mode.  (The sampler's compiled
program serves this second posterior: same sizes.)"""),
    code("""precise = np.asarray(quaternion.multiply(
    jnp.asarray(clean), quaternion.exp_pure(jnp.asarray(rng.normal(scale=1e-3, size=(len(times), 3))))
))
sharp = attitude_posterior(
    times, precise, attitude_sigma=1e-3,
    num_chains=CHAINS, num_warmup=WARMUP, num_samples=DRAWS, progress=False,
)
print(sharp.mode_probabilities())
for name in ("I_1", "I_2"):
    wide, narrow = posterior.quantities()[name], sharp.quantities()[name]
    print(f"{name}: sd {wide.std():.2e} at 10 mrad, {narrow.std():.2e} at 1 mrad")"""),
]

notebook = nbformat.v4.new_notebook(cells=cells)
notebook.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
path = pathlib.Path(__file__).with_name("posterior.ipynb")
nbformat.write(notebook, path)
print(f"wrote {path}")
