"""Builds notebooks/fit_inertia.ipynb (without outputs): .venv/bin/python notebooks/_build_fit_inertia.py"""

import pathlib

import nbformat

md, code = nbformat.v4.new_markdown_cell, nbformat.v4.new_code_cell

cells = [
    md("""# Fitting a tumbling body's moments of inertia to attitude data

`frbjax.fit_attitude` finds the torque-free motion that best explains observed attitudes: the
moments of inertia (only their ratios are identifiable: $I \\to cI$, $L \\to cL$ gives the same
motion, so they come out scaled to a largest moment of 1), the body angular velocity and the attitude
at $t = 0$.  It runs optimistix's Levenberg-Marquardt solver from a batch of starting points under
`jax.vmap`, on growing time windows, and keeps the best.

Here: a body like a tumbling asteroid, $I = (0.64, 0.97, 1)$ in the data's body axes (in a shuffled
order), 64 uneven observation times over six rotation periods (about ten per period), 2 mrad
attitude noise, each quaternion reported with a random sign, and a few gross outliers."""),
    code("""# Number of times at which the fitted and true motions are drawn; the tests run with fewer.
N_SAMPLES = 20000
# Number of observed attitudes.  The fit compiles once per number of samples (and of starts); 64 and
# 6 starts are the sizes of tests/test_fit.py, so that CI compiles the fit once for both.
N_OBS = 64""", metadata={"tags": ["parameters"]}),
    code("""import time

import jax

jax.config.update("jax_enable_x64", True)  # the library leaves this to the application

import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

from frbjax import FreeRigidBody, fit_attitude
from frbjax import _quaternion as quaternion


@jax.jit
def motion(inertia, momentum, attitude, t):
    \"\"\"(q(t), Omega(t)) of a free rigid body, compiled once per shape of t (eager evaluation is slow).\"\"\"
    body = FreeRigidBody(inertia, momentum, attitude)
    return body.quaternion(t), body.angular_velocity(t)"""),
    md("## The data"),
    code("""rng = np.random.default_rng(7)
true_inertia = np.array([0.97, 1.0, 0.64])           # the data's body axes: any order
true_momentum = np.array([0.35, -0.45, 0.82])
true_momentum /= np.linalg.norm(true_momentum)
true_attitude = np.array([0.8, 0.2, -0.4, 0.4])
true_attitude /= np.linalg.norm(true_attitude)
true_omega = true_momentum / true_inertia
period = 2 * np.pi / np.linalg.norm(true_omega)

# N_OBS uneven times over 6 rotation periods; the motions are drawn at N_SAMPLES times (one array of
# both, so that `motion` compiles once).
times = np.sort(rng.uniform(0, 6 * period, N_OBS))
times[0] = 0.0
dense = np.linspace(times[0], times[-1], N_SAMPLES)
every_time = np.concatenate([times, dense])
q_true_all, omega_true_all = (np.asarray(a) for a in motion(true_inertia, true_momentum, true_attitude, every_time))
q_true, omega_true = q_true_all[:N_OBS], omega_true_all[N_OBS:]
noise = 2e-3
kicks = np.asarray(quaternion.exp_pure(jnp.asarray(rng.normal(scale=noise, size=(N_OBS, 3)))))
observed = np.asarray(quaternion.multiply(jnp.asarray(q_true), jnp.asarray(kicks)))
observed = observed * rng.choice([-1.0, 1.0], size=(N_OBS, 1))  # q and -q: the same attitude
outliers = rng.choice(np.arange(1, N_OBS), 5, replace=False)
junk = rng.normal(size=(5, 4))
observed[outliers] = junk / np.linalg.norm(junk, axis=-1, keepdims=True)
print(f"{N_OBS} observations over {times[-1]:.1f} time units ({times[-1] / period:.1f} rotation periods)")"""),
    md("""## The fit

A Huber loss keeps the outliers from pulling the fit; the robust scale defaults to 2.5 times the
median residual of the least-squares solution."""),
    code("""start = time.perf_counter()
fit = fit_attitude(times, observed, loss="huber", n_starts=6, seed=0)
jax.block_until_ready(fit.inertia)
print(f"fit in {time.perf_counter() - start:.1f} s (including compilation); solver success: {bool(fit.success)}")
sigma = np.sqrt(np.diag(np.asarray(fit.inertia_covariance)))
for name, fitted, true in [("moments", fit.inertia, true_inertia / true_inertia.max()),
                           ("Omega(0)", fit.angular_velocity, true_omega)]:
    print(f"{name:9s} fitted {np.round(np.asarray(fitted), 5)}  true {np.round(true, 5)}")
print("1-sigma of the moments:", np.round(sigma, 6))
inertia_error = np.max(np.abs(np.asarray(fit.inertia) - true_inertia / true_inertia.max()))
omega_error = np.linalg.norm(np.asarray(fit.angular_velocity) - true_omega) / np.linalg.norm(true_omega)
print(f"largest moment error {inertia_error:.1e}, relative Omega error {omega_error:.1e}")
assert inertia_error < 0.01 and omega_error < 0.01"""),
    md("""## Data against the fitted motion

The observed quaternions are plotted with the sign that best matches the fitted motion (the data
themselves carry random signs); the outliers are marked."""),
    code("""# The fitted motion: fit.body is a FreeRigidBody (here evaluated through `motion`, compiled above).
body = fit.body
q_fit_all, omega_fit_all = (np.asarray(a) for a in motion(
    body.inertia, body.initial_angular_momentum, body.initial_attitude, every_time))
q_fit_at_data, q_fit, omega_fit = q_fit_all[:N_OBS], q_fit_all[N_OBS:], omega_fit_all[N_OBS:]
aligned = observed * np.sign(np.sum(observed * q_fit_at_data, -1))[:, None]

fig, axes = plt.subplots(4, 1, sharex=True, figsize=(10, 8), constrained_layout=True)
for k, axis in enumerate(axes):
    axis.plot(dense, q_fit[:, k], color="tab:blue", lw=1, label="fitted motion")
    axis.plot(times, aligned[:, k], ".", color="k", ms=3, label="observations")
    axis.plot(times[outliers], aligned[outliers, k], "x", color="tab:red", ms=7, label="outliers")
    axis.set_ylabel(f"$q_{k}$")
    axis.grid(alpha=0.3)
axes[0].legend(loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
axes[-1].set_xlabel("time")
fig.suptitle("attitude quaternion: data vs fit")
plt.show()"""),
    code("""residual = np.linalg.norm(np.asarray(fit.residuals), axis=-1)

fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 6), constrained_layout=True)
for k in range(3):
    top.plot(dense, omega_true[:, k], color=f"C{k}", lw=3, alpha=0.3)
    top.plot(dense, omega_fit[:, k], color=f"C{k}", lw=1, label=f"$\\\\Omega_{k + 1}$ fitted (true: wide)")
top.set(ylabel="body angular velocity", title="angular velocity: fitted (thin) and true (wide)")
top.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
bottom.semilogy(times, residual, ".", ms=3, color="k")
bottom.semilogy(times[outliers], residual[outliers], "x", color="tab:red", ms=7)
bottom.axhline(noise * np.sqrt(3), color="tab:blue", ls="--", label="noise level")
bottom.set(xlabel="time", ylabel="|residual| (rad)", title="attitude residuals")
bottom.legend(frameon=False)
plt.show()
inliers = np.setdiff1d(np.arange(N_OBS), outliers)
print(f"rms inlier residual {np.sqrt(np.mean(residual[inliers] ** 2)):.2e} rad "
      f"(noise {noise * np.sqrt(3):.2e} rad per sample)")"""),
]

notebook = nbformat.v4.new_notebook(cells=cells)
notebook.metadata["kernelspec"] = {"display_name": "Python 3", "language": "python", "name": "python3"}
notebook.metadata["language_info"] = {"name": "python"}
path = pathlib.Path(__file__).with_name("fit_inertia.ipynb")
nbformat.write(notebook, path)
print("wrote", path)
