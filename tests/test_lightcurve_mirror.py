"""The pole's mirror image (frbjax/lightcurve/_fit.py, ``_mirror_image``): a torque-free motion and a
convex shape mirrored through a plane give the same light curves as the original wherever the Sun and
the observer lie in that plane (Kaasalainen & Lamberg 2006), with the same periods and the pole at
-M L (longitude + 180 degrees, the same latitude).  fit_lightcurve solves the winner's mirror image
and reports the other pole (tests/test_lightcurve_nan_policy.py: a fit)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from frbjax.lightcurve import ConvexShape, tumbler_periods
from frbjax.lightcurve._brightness import brightness
from frbjax.lightcurve._fit import _body, _mirror_image, _mirrored_normals, _tangent_basis, _unit_normals


def _in_plane(normal, count, rng):
    """``count`` unit vectors in the plane of ``normal``, spread over it."""
    basis = _tangent_basis(normal)
    angles = rng.uniform(0, 2 * np.pi, count)
    return np.cos(angles)[:, None] * basis[0] + np.sin(angles)[:, None] * basis[1]


def _pole(body):
    momentum = np.asarray(body.rotation_matrix(0.0)) @ np.asarray(body.angular_momentum(0.0))
    return momentum / np.linalg.norm(momentum)


@pytest.mark.parametrize("subdivisions", [1, 2])
def test_the_icospheres_normals_are_their_own_mirror_image(subdivisions):
    normals, _, _ = _unit_normals(subdivisions)
    index = _mirrored_normals(normals)
    np.testing.assert_allclose(normals[index], normals * [1, 1, -1], atol=1e-12)
    np.testing.assert_array_equal(index[index], np.arange(len(normals)))


def test_the_mirror_image_gives_the_same_light_curves_in_its_plane():
    rng = np.random.default_rng(7)
    normals, _, _ = _unit_normals(2)
    plane = np.array([0.1, -0.3, 0.95])
    plane /= np.linalg.norm(plane)
    # A tumbler (SAM, moments 0.61 : 0.965 : 1) away from any symmetry, its shape bumpy log-areas.
    parameters = np.concatenate(
        [[np.log(0.61), np.log(0.965), np.log(9.0)], rng.normal(0, 0.5, 5), rng.normal(0, 0.3, len(normals))]
    )
    direction = np.array([0.3, 0.2, 0.93])
    direction /= np.linalg.norm(direction)
    attitude = rng.normal(size=4)
    reference = (attitude / np.linalg.norm(attitude), direction, _tangent_basis(direction))
    mirrored, mirrored_reference = _mirror_image(parameters, reference, plane, _mirrored_normals(normals))

    body, image = _body(jnp.asarray(parameters[:8]), reference), _body(jnp.asarray(mirrored[:8]), mirrored_reference)
    shape = ConvexShape(jnp.asarray(normals), jnp.exp(jnp.asarray(parameters[8:])))
    mirrored_shape = ConvexShape(jnp.asarray(normals), jnp.exp(jnp.asarray(mirrored[8:])))
    times = np.sort(rng.uniform(-20, 20, 200))
    sun = _in_plane(plane, len(times), rng)
    observer = _in_plane(plane, len(times), rng)
    flux = np.asarray(brightness(body, shape, times, sun, observer))
    mirrored_flux = np.asarray(brightness(image, mirrored_shape, times, sun, observer))
    # Measured: 1.4e-14 relative over 40 days (58 precession cycles), one sample dark in both.
    np.testing.assert_allclose(mirrored_flux, flux, rtol=3e-14)

    # Off the plane the two differ (measured: up to 26%): the observations there tell the poles apart.
    lifted = (sun + 0.3 * plane) / np.linalg.norm(sun + 0.3 * plane, axis=-1, keepdims=True)
    assert (
        np.max(
            np.abs(
                np.asarray(brightness(image, mirrored_shape, times, lifted, observer))
                / np.asarray(brightness(body, shape, times, lifted, observer))
                - 1
            )
        )
        > 0.01
    )

    # The same periods, and the pole at -M L.
    np.testing.assert_allclose(
        np.asarray(tumbler_periods(image.inertia, image.initial_angular_momentum)[:2]),
        np.asarray(tumbler_periods(body.inertia, body.initial_angular_momentum)[:2]),
        rtol=1e-13,
    )
    reflection = np.eye(3) - 2 * np.outer(plane, plane)
    np.testing.assert_allclose(_pole(image), -reflection @ _pole(body), atol=1e-13)
