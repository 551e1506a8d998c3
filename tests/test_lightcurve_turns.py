"""The search's turns about the line of sight (frbjax/lightcurve/_fit.py, ``_turned_attitudes``): a
torque-free motion turned as a whole about an inertial axis has the same periods and its pole turned
about that axis, and where the Sun and the observer lie along the axis (zero phase angle) it gives the
same light curve for every turn: the first nights, seen from one direction, do not fix the pole's
angle about the line of sight, which is why the search tries the turns before each wider window."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from scipy.spatial.transform import Rotation

from frbjax.lightcurve import ConvexShape, tumbler_periods
from frbjax.lightcurve._brightness import brightness
from frbjax.lightcurve._fit import _body, _line_of_sight, _tangent_basis, _turned_attitudes, _unit_normals


def _pole(body):
    momentum = np.asarray(body.rotation_matrix(0.0)) @ np.asarray(body.angular_momentum(0.0))
    return momentum / np.linalg.norm(momentum)


def test_a_turned_motion_is_the_motion_rotated_about_the_axis():
    rng = np.random.default_rng(3)
    normals, _, _ = _unit_normals(2)
    # A tumbler (SAM, moments 0.61 : 0.965 : 1), a bumpy convex shape.
    parameters = np.concatenate([[np.log(0.61), np.log(0.965), np.log(9.0)], rng.normal(0, 0.5, 5)])
    shape = ConvexShape(jnp.asarray(normals), jnp.exp(jnp.asarray(rng.normal(0, 0.3, len(normals)))))
    direction = np.array([0.3, 0.2, 0.93]) / np.linalg.norm([0.3, 0.2, 0.93])
    attitude = rng.normal(size=4)
    attitude /= np.linalg.norm(attitude)
    axis = np.array([0.6, -0.64, 0.48])
    turns = 8
    turned = _turned_attitudes(attitude, axis, turns)
    assert turned.shape == (turns - 1, 4)

    body = _body(jnp.asarray(parameters), (attitude, direction, _tangent_basis(direction)))
    times = np.linspace(-3.0, 3.0, 120)
    sun = np.broadcast_to(axis, (len(times), 3))
    flux = np.asarray(brightness(body, shape, times, sun, sun))
    lifted = np.broadcast_to(Rotation.from_rotvec([0.0, 0.0, 0.5]).apply(axis), (len(times), 3))
    for k, quaternion in enumerate(turned, 1):
        image = _body(jnp.asarray(parameters), (quaternion, direction, _tangent_basis(direction)))
        rotation = Rotation.from_rotvec(axis * 2 * np.pi * k / turns).as_matrix()
        np.testing.assert_allclose(_pole(image), rotation @ _pole(body), atol=1e-13)
        np.testing.assert_allclose(
            np.asarray(tumbler_periods(image.inertia, image.initial_angular_momentum)[:2]),
            np.asarray(tumbler_periods(body.inertia, body.initial_angular_momentum)[:2]),
            rtol=1e-13,
        )
        # Seen and lit along the axis, the same light curve (measured: 1.1e-15 relative) ...
        np.testing.assert_allclose(np.asarray(brightness(image, shape, times, sun, sun)), flux, rtol=1e-14)
        # ... and lit from elsewhere (25 degrees of phase), another (measured: 1.6% to 4.0% at the most).
        changed = np.asarray(brightness(image, shape, times, lifted, sun)) / np.asarray(
            brightness(body, shape, times, lifted, sun)
        )
        assert np.max(np.abs(changed - 1)) > 0.01


def test_the_line_of_sight_is_the_mean_bisector_of_the_windows_samples():
    sun = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    observer = np.array([[0, 1.0, 0], [1.0, 0, 0], [1.0, 0, 0]])
    np.testing.assert_allclose(
        _line_of_sight(sun, observer, np.array([1.0, 1.0, 0.0])), np.array([1, 1, 0]) / np.sqrt(2)
    )
    np.testing.assert_allclose(
        _line_of_sight(sun, observer, np.array([0.0, 0.0, 1.0])), np.array([1, 0, 1]) / np.sqrt(2)
    )
