"""Builds notebooks/lightcurve.ipynb (without outputs): .venv/bin/python notebooks/_build_lightcurve.py"""

import pathlib

import nbformat


md, code = nbformat.v4.new_markdown_cell, nbformat.v4.new_code_cell

cells = [
    md("""# A tumbling asteroid from its light curves

`frbjax.lightcurve` computes the brightness of a body in exact torque-free motion and inverts light
curves for the spin state, the moments of inertia (ratios) and a convex shape.  Here: a synthetic
short-axis-mode tumbler with Apophis's moments (0.61 : 0.965 : 1, $E/E_0 = 1.024$) but a faster
spin (precession period 4.8 hours), its shape a bumpy convex hull (not the model's facets: no
inverse crime), observed 16 times a night on 24 nights over 90 days at changing geometry with 1%
noise and an unknown scale per night; four later nights are held out."""),
    code(
        """# Number of times at which the model light curves are drawn, and the inversion's settings (those of
# tests/test_lightcurve_fit.py, described below); the tests run smaller.
N_SAMPLES = 20000
FIT_SETTINGS = dict(shape="convex", convex_subdivisions=2, period_grid=(3, 3), starts_per_period=128, n_refine=16)""",
        metadata={"tags": ["parameters"]},
    ),
    code("""import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)  # the library leaves this to the application

import matplotlib.pyplot as plt
import numpy as np

from frbjax import FreeRigidBody
from frbjax.lightcurve import brightness, fit_lightcurve, tumbler_periods

import frbjax

# The synthetic problem of tests/test_lightcurve_fit.py (same sizes: its compiled solver is reused).
sys.path.insert(0, str(pathlib.Path(frbjax.__file__).resolve().parents[1] / "tests"))
import test_lightcurve_fit as problem"""),
    md("## The tumbler and its data"),
    code("""inertia = np.array([0.61, 0.965, 1.0])
direction = problem.momentum_with_energy(inertia, 1.024, 1.0)
p_psi, _, _ = tumbler_periods(inertia, direction)
momentum = direction * float(p_psi) / problem.PRECESSION_PERIOD          # P_psi = 0.2 days
truth = FreeRigidBody(inertia, momentum, problem.ATTITUDE)
periods = np.array([float(p) for p in tumbler_periods(inertia, momentum)[:2]])
print(f"true periods: P_psi = {periods[0] * 24:.2f} h, P_phi = {periods[1] * 24:.2f} h")

(times, flux, sun, observer, night), held_out = problem.observe(truth, seed=3, per_night=problem.SAMPLES_PER_NIGHT)
epoch = float(np.median(times))
fig, axes = plt.subplots(1, 3, figsize=(12, 3), constrained_layout=True)
for k, axis in enumerate(axes):
    chosen = night == 3 * k
    dense = np.linspace(times[chosen].min(), times[chosen].max(), max(N_SAMPLES // 100, 20))
    model = np.asarray(brightness(truth, problem.SHAPE, dense - epoch, np.tile(sun[chosen][0], (len(dense), 1)),
                                  np.tile(observer[chosen][0], (len(dense), 1))))
    scale = np.mean(flux[chosen]) / np.mean(model)
    axis.plot((dense - dense[0]) * 24, scale * model, color="0.6", label="true body")
    axis.plot((times[chosen] - dense[0]) * 24, flux[chosen], "o", ms=4, label="data")
    axis.set(xlabel="hours", title=f"night {3 * k + 1} (day {times[chosen][0]:.1f})")
axes[0].set_ylabel("relative flux")
axes[0].legend(frameon=False)
plt.show()"""),
    md("""## The inversion

The search: a grid of the two periods over $\\pm 0.5\\%$ around centres 0.23% off the truth (as a periodogram would
give), 3 x 3 period pairs with 128 random states each (inertia ratios, energy, phases, attitude), all
evaluated on the nights nearest the epoch in one vmapped program; the 16 best are refined by
Levenberg-Marquardt on growing windows of the data, each start held near its period cell until the
last window, then the convex shape (log-areas on 320 fixed normals) is fitted with the motion."""),
    code("""start = time.perf_counter()
result = fit_lightcurve(times, flux, sun, observer, lightcurve=night,
                        periods=tuple((p * (1 + problem.RANGE_OFFSET - 0.005), p * (1 + problem.RANGE_OFFSET + 0.005))
                                      for p in periods), mode="SAM",
                        **{**problem.FIT_OPTIONS, **FIT_SETTINGS})
print(f"fit in {time.perf_counter() - start:.1f} s (including compilation)")
print("periods (h):", np.asarray(result.periods) * 24, "+-", np.asarray(result.period_sigma) * 24,
      " true:", periods * 24)
print("moments:", np.asarray(result.inertia), "+-", np.asarray(result.inertia_sigma), " true:", inertia)
print(f"E/E0 = {result.energy_ratio:.4f} (true 1.024), long-axis mode: {result.long_axis_mode}")
print(f"rms residual {np.sqrt(np.mean(np.asarray(result.residuals) ** 2)):.4f}, "
      f"held-out nights {problem.held_out_rms(result, held_out):.4f} (noise {problem.NOISE})")"""),
    code("""search = np.asarray(result.search_periods)
costs = np.asarray(result.search_costs)
fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
finite = np.isfinite(costs)
points = left.scatter(search[finite, 0] * 24, search[finite, 1] * 24, c=np.log10(costs[finite]), s=12)
left.plot(*(periods * 24), "r+", ms=16, label="truth")
left.plot(*(np.asarray(result.periods) * 24), "kx", ms=10, label="fit")
left.set(xlabel="$P_\\\\psi$ (h)", ylabel="$P_\\\\phi$ (h)", title="search: every start's cost")
left.legend(frameon=False)
fig.colorbar(points, ax=left, label="log10 cost on the first window")
right.plot(times - epoch, np.asarray(result.residuals), ".", ms=3)
right.set(xlabel="days from the epoch", ylabel="log residual", title="residuals")
plt.show()"""),
    md("""## The shape

The fitted shape is a Gaussian image (facet normals and areas); its polyhedron comes back from
Minkowski's problem.  Beside it the true shape, and the moments of the fitted shape at uniform
density against the fitted (dynamical) moments."""),
    code("""from mpl_toolkits.mplot3d.art3d import Poly3DCollection
from scipy.spatial import ConvexHull

vertices, faces = result.shape.polyhedron()
# The true hull's points, as tests/test_lightcurve_fit.py draws them.
rng = np.random.default_rng(11)
directions = rng.normal(size=(2000, 3))
directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
bumps = 1 + 0.04 * np.sin(3 * directions[:, 0]) * np.cos(2 * directions[:, 1])
true_points = directions * np.array([1.35, 1.0, 0.8]) * bumps[:, None]
true_faces = ConvexHull(true_points).simplices
scale = (np.sum(np.asarray(problem.SHAPE.areas)) / np.sum(np.asarray(result.shape.areas))) ** 0.5
fig = plt.figure(figsize=(10, 4.5))
for index, (points, triangles, title) in enumerate([(true_points, true_faces, "true shape"),
                                                    (vertices * scale, faces, "fitted (same area)")]):
    axis = fig.add_subplot(1, 2, index + 1, projection="3d")
    axis.add_collection3d(Poly3DCollection(points[triangles], facecolor="tan", edgecolor="0.3", lw=0.2))
    axis.set(xlim=(-1.4, 1.4), ylim=(-1.4, 1.4), zlim=(-1.4, 1.4), title=title)
    axis.set_box_aspect((1, 1, 1))
plt.show()
shape_moments, _ = result.shape_inertia()
print("moments of the fitted shape at uniform density:", np.round(shape_moments, 3))
print("fitted (dynamical) moments:                    ", np.round(np.asarray(result.inertia), 3))"""),
]

notebook = nbformat.v4.new_notebook(cells=cells)
notebook.metadata["kernelspec"] = {"display_name": "Python 3", "language": "python", "name": "python3"}
notebook.metadata["language_info"] = {"name": "python"}
path = pathlib.Path(__file__).with_name("lightcurve.ipynb")
nbformat.write(notebook, path)
print("wrote", path)
