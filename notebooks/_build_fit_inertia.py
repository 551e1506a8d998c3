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
    code(
        """# Number of times at which the fitted and true motions are drawn; the tests run with fewer.
N_SAMPLES = 20000
# Number of observed attitudes.  The fit compiles once per number of samples (and of starts); 64 and
# 6 starts are the sizes of tests/test_fit.py, so that CI compiles the fit once for both.
N_OBS = 64""",
        metadata={"tags": ["parameters"]},
    ),
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
    md("""## A tilted spacecraft: the whole inertia tensor

A spacecraft's principal axes are rarely its body axes: its mass properties come as a tensor with
products of inertia, and its star tracker measures attitudes of the body frame.  With
`inertia="tensor"` the fit finds the tensor up to scale (its principal moments and axes in the body
frame).  The data below come from a body whose principal axes are tilted by 15 degrees, observed
with 1e-4 rad of noise; they are made from the motion of the principal frame turned back to the body
frame, as an independent check of the tensor code path."""),
    code("""def rotation(vector):
    \"\"\"Rodrigues' formula: the rotation by |vector| about vector.\"\"\"
    angle = np.linalg.norm(vector)
    k = vector / angle
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


axes_true = rotation(np.radians(15) * np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8]))
moments_true = np.array([0.62, 0.85, 1.0])
tensor_true = axes_true @ np.diag(moments_true) @ axes_true.T
omega0 = np.array([0.1, 0.6, 0.25])
attitude0 = np.array([0.9, -0.2, 0.3, 0.2]) / np.linalg.norm([0.9, -0.2, 0.3, 0.2])
w = np.sqrt(1 + np.trace(axes_true)) / 2                       # the axes as a quaternion
frame = np.array([w, (axes_true[2, 1] - axes_true[1, 2]) / (4 * w), (axes_true[0, 2] - axes_true[2, 0]) / (4 * w),
                  (axes_true[1, 0] - axes_true[0, 1]) / (4 * w)])
principal_attitude = np.asarray(quaternion.multiply(jnp.asarray(attitude0), jnp.asarray(frame)))
craft_period = 2 * np.pi / np.linalg.norm(omega0)
craft_times = np.sort(rng.uniform(0, 5 * craft_period, N_OBS))
craft_times[0] = 0.0
q_principal, _ = motion(moments_true, axes_true.T @ (tensor_true @ omega0), principal_attitude,
                        np.concatenate([craft_times, dense]))
q_craft = np.asarray(quaternion.multiply(q_principal[:N_OBS], quaternion.conjugate(jnp.asarray(frame))))
kicks = np.asarray(quaternion.exp_pure(jnp.asarray(rng.normal(scale=1e-4, size=(N_OBS, 3)))))
q_craft = np.asarray(quaternion.multiply(jnp.asarray(q_craft), jnp.asarray(kicks)))

start = time.perf_counter()
craft = fit_attitude(craft_times, q_craft, inertia="tensor", attitude_sigma=1e-4, n_starts=6, seed=0)
print(f"tensor fit in {time.perf_counter() - start:.1f} s (including compilation)")
np.set_printoptions(precision=5, suppress=True)
print("fitted tensor (largest principal moment 1):")
print(np.asarray(craft.inertia_tensor))
print("true tensor:")
print(tensor_true)
tilt = np.degrees(np.arccos(np.clip(np.abs(np.diag(np.asarray(craft.principal_axes).T @ axes_true)), 0, 1)))
print("principal moments", np.asarray(craft.inertia), "; axes within", np.round(tilt, 4), "degrees of the truth")
print("axes identifiable:", bool(craft.axes_identifiable))
assert np.max(np.abs(np.asarray(craft.inertia_tensor) - tensor_true)) < 1e-3"""),
    code("""sigma = np.sqrt(np.einsum("ijij->ij", np.asarray(craft.inertia_tensor_covariance)))
error = np.asarray(craft.inertia_tensor) - tensor_true
labels = [f"$T_{{{i + 1}{j + 1}}}$" for i in range(3) for j in range(i, 3)]
pairs = [(i, j) for i in range(3) for j in range(i, 3)]
fig, axis = plt.subplots(figsize=(8, 3.5), constrained_layout=True)
axis.errorbar(range(6), [error[i, j] for i, j in pairs], yerr=[3 * sigma[i, j] for i, j in pairs], fmt="o",
              capsize=4, color="tab:blue", label="fitted - true (bars: 3 sigma)")
axis.axhline(0, color="k", lw=0.8)
axis.set_xticks(range(6), labels)
axis.set(ylabel="error of the scaled tensor", title="tilted spacecraft: every tensor entry within its error bar")
axis.legend(frameon=False)
plt.show()"""),
]

notebook = nbformat.v4.new_notebook(cells=cells)
notebook.metadata["kernelspec"] = {"display_name": "Python 3", "language": "python", "name": "python3"}
notebook.metadata["language_info"] = {"name": "python"}
path = pathlib.Path(__file__).with_name("fit_inertia.ipynb")
nbformat.write(notebook, path)
print("wrote", path)
