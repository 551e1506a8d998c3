"""frbjax.lightcurve: shapes, the brightness forward model and the periods, against independent references.

- A box spinning about z, lit along x and seen along y: the flux by hand, 4 b c S(sin wt, cos wt)
  (the conventions: body to space, mu = n . e_obs, mu0 = n . e_sun).
- A triaxial ellipsoid: the faceted sum converges, as the facets are refined, to the integral over
  the smooth surface computed another way: over the Gauss map (int S(mu, mu0) / K(n) dOmega,
  1/K = (abc)^2 / h(n)^4) on the lune lit and seen, by a Gauss-Legendre product rule (converged to
  1e-14 at 40 nodes; it agrees with scipy's dblquad over the surface to the latter's 3e-7), with the
  attitude from scipy's Rotation.
- Gradients against central finite differences; float32 against float64; batches against loops.
- The uniform-density inertia against closed forms (box, ellipsoid); Minkowski's reconstruction
  against the polytope whose Gaussian image it was given.
- The periods against the motion itself (frbjax's FreeRigidBody: L returns after P_phi, and the
  attitude has turned by 2 pi P_phi / P_psi about L) and against Apophis's published spin state
  (Pravec et al. 2014, Icarus 233, 48).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _compile_options import FAST_COMPILE_OPTIONS
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from frbjax import FreeRigidBody
from frbjax.lightcurve import brightness, ConvexShape, icosphere, mesh_inertia, tumbler_periods
from frbjax.lightcurve._periods import momentum_from_periods


LAWS = ("lambert", "lommel_seeliger", "lommel_seeliger_lambert")


def scattering(mu, mu0, law, c=0.1):
    return {
        "lambert": mu * mu0,
        "lommel_seeliger": mu * mu0 / (mu + mu0),
        "lommel_seeliger_lambert": mu * mu0 / (mu + mu0) + c * mu * mu0,
    }[law]


def box_mesh(a, b, c):
    """The box [-a, a] x [-b, b] x [-c, c] as 12 triangles (scipy's hull of its corners)."""
    corners = np.array([[x, y, z] for x in (-a, a) for y in (-b, b) for z in (-c, c)], float)
    return corners, ConvexHull(corners).simplices


def ellipsoid_flux_reference(axes, rotation, sun, observer, law, nodes=80):
    """The smooth ellipsoid's flux over its Gauss map (module docstring); ``rotation`` body to space."""
    sun_body, observer_body = rotation.inv().apply(sun), rotation.inv().apply(observer)
    z = np.cross(sun_body, observer_body)
    z /= np.linalg.norm(z)
    x, y = sun_body, np.cross(z, sun_body)
    alpha = np.arctan2(observer_body @ y, observer_body @ x)
    g, w = np.polynomial.legendre.leggauss(nodes)
    low, high = alpha - np.pi / 2, np.pi / 2
    phi, w_phi = (high - low) / 2 * g + (high + low) / 2, w * (high - low) / 2
    theta, w_theta = np.pi / 2 * (g + 1), w * np.pi / 2
    t, p = np.meshgrid(theta, phi, indexing="ij")
    normal = (np.sin(t) * np.cos(p))[..., None] * x + (np.sin(t) * np.sin(p))[..., None] * y + np.cos(t)[..., None] * z
    mu, mu0 = normal @ observer_body, normal @ sun_body
    support_squared = np.sum(np.asarray(axes) ** 2 * normal**2, -1)
    weights = np.outer(w_theta, w_phi) * np.sin(t)
    return np.sum(weights * scattering(mu, mu0, law) * np.prod(axes) ** 2 / support_squared**2)


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# ------------------------------------------------------------------------------------ conventions


@pytest.mark.parametrize("law", LAWS)
def test_box_spinning_about_z_by_hand(law):
    a, b, c, omega = 1.0, 2.0, 0.5, 0.7
    body = FreeRigidBody(np.array([1.0, 2.0, 3.0]), np.array([0.0, 0.0, 3.0 * omega]))
    shape = ConvexShape.from_mesh(*box_mesh(a, b, c))
    times = np.linspace(0.1, 2.1, 9)  # omega t in (0, pi / 2)
    sun, observer = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    flux = np.asarray(brightness(body, shape, times, sun, observer, law=law))
    angle = omega * times
    expected = 4 * b * c * scattering(np.sin(angle), np.cos(angle), law)
    np.testing.assert_allclose(flux, expected, rtol=1e-14, atol=1e-15)
    # Seen the other way round (the attitude transposed) the -y face, of another area, would shine.
    mirrored = 4 * a * c * scattering(np.sin(angle), np.cos(angle), law)
    assert np.all(np.abs(flux - mirrored) > 0.1)


def test_gradient_finite_where_no_facet_is_lit_and_seen():
    body_args = (jnp.array([1.0, 2.0, 3.0]), jnp.array([0.0, 0.0, 2.1]))
    vertices, faces = box_mesh(1.0, 2.0, 0.5)

    def flux(t, inertia, momentum, vertices):
        shape = ConvexShape.from_mesh(vertices, faces)
        return brightness(
            FreeRigidBody(inertia, momentum), shape, t, jnp.array([1.0, 0.0, 0.0]), jnp.array([0.0, 1.0, 0.0])
        )[0]

    # At t = 0 every facet has mu = 0 or mu0 = 0: the kink of max(mu, 0).  One compiled program
    # (called eagerly, the gradient's hundreds of operations were compiled one by one).
    value_and_gradients = jax.jit(jax.value_and_grad(flux, argnums=(0, 1, 2, 3)))
    value, gradients = value_and_gradients(jnp.zeros(1), *body_args, jnp.asarray(vertices))
    assert all(bool(jnp.all(jnp.isfinite(g))) for g in gradients)
    assert float(value) == 0.0


# ------------------------------------------------------------------------------------ ellipsoid


GEOMETRIES = [  # (sun, observer): phase angles 18, 62 and 110 degrees
    (unit([1.0, 0.2, 0.1]), unit([0.9, 0.5, 0.05])),
    (unit([0.3, -1.0, 0.4]), unit([0.9, -0.4, -0.3])),
    (unit([0.0, 0.3, 1.0]), unit([1.0, 0.2, -0.3])),
]
ATTITUDE = unit([0.8, 0.3, -0.4, 0.33])  # w x y z, body to space


def test_ellipsoid_reference_is_converged():
    rotation = Rotation.from_quat(np.roll(ATTITUDE, -1))
    sun, observer = GEOMETRIES[1]
    values = [
        ellipsoid_flux_reference((1.3, 1.0, 0.7), rotation, sun, observer, "lommel_seeliger", n) for n in (40, 80, 160)
    ]
    assert abs(values[0] - values[2]) < 1e-14 * values[2] and abs(values[1] - values[2]) < 1e-14 * values[2]


# Relative error of the faceted ellipsoid (20 * 4**s facets) against the smooth one, worst over the
# geometries and laws (measured: 3.46e-2, 5.01e-3, 1.30e-3, 3.32e-4 for s = 2..5: second order).
FACET_ERRORS = {2: 3.6e-2, 3: 5.2e-3, 4: 1.35e-3, 5: 3.4e-4}


def test_faceted_ellipsoid_converges_to_the_smooth_one():
    axes = (1.3, 1.0, 0.7)
    body = FreeRigidBody(np.array([0.6, 0.9, 1.0]), np.array([0.1, 0.2, 0.9]), ATTITUDE)
    rotation = Rotation.from_quat(np.roll(ATTITUDE, -1))
    # The geometries as three samples at t = 0, the shape and the laws in one compiled program per
    # facet count (called eagerly, each facet count compiled the operations one by one).
    suns, observers = (np.stack(directions) for directions in zip(*GEOMETRIES))

    def fluxes(subdivisions):
        shape = ConvexShape.ellipsoid(*axes, subdivisions=subdivisions)
        return jnp.stack([brightness(body, shape, jnp.zeros(len(suns)), suns, observers, law) for law in LAWS])

    expected = np.array(
        [[ellipsoid_flux_reference(axes, rotation, sun, observer, law) for sun, observer in GEOMETRIES] for law in LAWS]
    )
    worst = {}
    for subdivisions in FACET_ERRORS:
        flux = np.asarray(jax.jit(fluxes, static_argnums=0)(subdivisions))
        worst[subdivisions] = np.max(np.abs(flux / expected - 1))
    for subdivisions, bound in FACET_ERRORS.items():
        assert worst[subdivisions] < bound, worst
    # Second order: each refinement divides the error by about 4.
    assert 3.5 < worst[4] / worst[5] < 4.5, worst


def test_ellipsoid_is_the_stretched_icosphere():
    """``ConvexShape.ellipsoid`` (the icosphere's area vectors scaled by (b c, a c, a b)) against the
    Gaussian image of the stretched mesh itself (``from_mesh``), values and derivatives in (a, b, c).
    Measured (the worst of the three meshes, 1280 facets): areas 1.1e-15 relative, normals 1.4e-15,
    the Jacobian of the areas 8.3e-16 relative to its largest entry; allowed 4e-15."""
    for subdivisions, axes in ((0, (1.0, 0.7, 0.4)), (1, (2.0, 1.0, 0.05)), (3, (1.3, 1.0, 0.7))):
        vertices, faces = icosphere(subdivisions)

        def image(axes, subdivisions=subdivisions, vertices=vertices, faces=faces):
            ours = ConvexShape.ellipsoid(*axes, subdivisions)
            theirs = ConvexShape.from_mesh(jnp.asarray(vertices) * axes[None, :], faces)
            return ours.areas, ours.normals, theirs.areas, theirs.normals

        # One program (eagerly, each operation and its derivative were compiled in turn: 7 s).
        values, jacobians = jax.jit(lambda axes: (image(axes), jax.jacfwd(image)(axes)))(jnp.asarray(axes))
        ours_areas, ours_normals, areas, normals = values
        assert np.max(np.abs(ours_areas / areas - 1)) < 4e-15
        assert np.max(np.abs(ours_normals - normals)) < 4e-15
        ours_jacobian, _, jacobian, _ = jacobians
        assert np.max(np.abs(ours_jacobian - jacobian)) < 4e-15 * np.max(np.abs(jacobian))


# ------------------------------------------------------------------------------------ derivatives


def _flux_sum(inertia, momentum, attitude, areas, normals, sun, observer, times, law):
    body = FreeRigidBody(inertia, momentum, attitude)
    sun = sun / jnp.linalg.norm(sun, axis=-1, keepdims=True)
    observer = observer / jnp.linalg.norm(observer, axis=-1, keepdims=True)
    flux = brightness(body, ConvexShape(normals, areas), times, sun, observer, law=law)
    return jnp.sum(flux * jnp.cos(jnp.arange(flux.size)))


def test_gradients_against_finite_differences():
    # Forward mode in everything (the mode the fit uses) and reverse mode in the shape and the
    # directions; one law, whose two terms cover the others (compiling derivatives of the motion
    # takes most of the time).
    law = "lommel_seeliger_lambert"
    rng = np.random.default_rng(3)
    shape = ConvexShape.ellipsoid(1.2, 1.0, 0.8, subdivisions=1)
    times = np.linspace(0.0, 12.0, 7)
    sun = unit(rng.normal(size=(7, 3)))
    observer = unit(sun + 0.5 * rng.normal(size=(7, 3)))
    args = [
        np.array([0.62, 0.95, 1.0]),
        np.array([0.2, 0.1, 0.9]),
        ATTITUDE,
        np.asarray(shape.areas),
        np.asarray(shape.normals),
        sun,
        observer,
        times,
    ]
    # The finite differences' reference values by a program compiled without XLA's optimisations
    # (tests/_compile_options.py); both modes of the derivatives in one program, compiled as users'.
    function = jax.jit(functools.partial(_flux_sum, law=law)).lower(*args).compile(FAST_COMPILE_OPTIONS)

    @jax.jit
    def derivatives(*args):
        forward = jax.jacfwd(_flux_sum, argnums=tuple(range(8)))(*args, law=law)
        return forward, jax.grad(_flux_sum, argnums=(3, 4, 5, 6))(*args, law=law)

    gradients, reverse = derivatives(*args)
    for forward, backward in zip(gradients[3:7], reverse):
        np.testing.assert_allclose(np.asarray(backward), np.asarray(forward), rtol=1e-12, atol=1e-13)
    step = 1e-6
    worst = 0.0
    for index in range(8):
        flat = args[index].reshape(-1)
        picks = rng.choice(flat.size, size=min(flat.size, 4), replace=False)
        for k in picks:
            plus, minus = flat.copy(), flat.copy()
            plus[k] += step
            minus[k] -= step
            shifted = lambda v: [
                v.reshape(args[index].shape) if i == index else a  # noqa: E731
                for i, a in enumerate(args)
            ]
            numeric = (float(function(*shifted(plus))) - float(function(*shifted(minus)))) / (2 * step)
            analytic = float(np.asarray(gradients[index]).reshape(-1)[k])
            worst = max(worst, abs(analytic - numeric) / max(1.0, abs(numeric)))
    # Measured 4.4e-10 (5.6e-10 with the reference compiled with XLA's optimisations): finite-difference
    # truncation and rounding; a facet crossing the terminator within +-step would show as an O(1) error.
    assert worst < 1e-9


def _flux_of_arrays(inertia, momentum, attitude, normals, areas, times, sun, observer):
    return brightness(FreeRigidBody(inertia, momentum, attitude), ConvexShape(normals, areas), times, sun, observer)


def test_float32_and_batches():
    """Two bodies and two shapes in one batch against each alone, and float32 against float64: one
    compiled program per batch shape and dtype (the bodies built inside it; built eagerly, each of
    their operations was compiled one by one)."""
    times = np.linspace(0.0, 20.0, 11)
    sun = unit(np.stack([np.cos(times / 50), np.sin(times / 50), 0.1 + 0 * times], -1))
    observer = unit(sun + np.array([0.0, 0.3, 0.1]))
    inertia = np.array([[0.6, 0.9, 1.0], [0.5, 1.0, 0.8]])
    momentum = np.array([[0.2, 0.1, 0.9], [0.7, 0.1, -0.2]])
    attitude = np.stack([ATTITUDE, [1.0, 0, 0, 0]])
    pair = (ConvexShape.ellipsoid(1.3, 1.0, 0.7, 2), ConvexShape.ellipsoid(1.0, 0.9, 0.5, 2))
    normals, areas = (np.stack([np.asarray(getattr(s, name)) for s in pair]) for name in ("normals", "areas"))
    # A batch of ellipsoids from arrays of semi-axes (rank-safe: the suite raises on rank promotion).
    batch = jax.jit(lambda a, b, c: ConvexShape.ellipsoid(a, b, c, 2))(
        np.array([1.3, 1.0]), np.array([1.0, 0.9]), np.array([0.7, 0.5])
    )
    np.testing.assert_allclose(np.asarray(batch.normals), normals, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(batch.areas), areas, rtol=1e-15)
    flux = jax.jit(_flux_of_arrays)
    batched = np.asarray(flux(inertia, momentum, attitude, normals, areas, times, sun, observer))
    assert batched.shape == (2, 11)
    for k in range(2):
        one = flux(inertia[k], momentum[k], attitude[k], normals[k], areas[k], times, sun, observer)
        np.testing.assert_allclose(batched[k], np.asarray(one), rtol=1e-13)
    single = (inertia[0], momentum[0], ATTITUDE, normals[0], areas[0], times, sun, observer)
    flux32 = flux(*(np.asarray(x, np.float32) for x in single))
    assert flux32.dtype == jnp.float32
    # Measured 7.1e-7: float32 rounding of the motion over 20 time units and of the sums.
    np.testing.assert_allclose(np.asarray(flux32), batched[0], rtol=2e-6)


def test_bad_directions_name_the_argument():
    body = FreeRigidBody(np.array([0.6, 0.9, 1.0]), np.array([0.2, 0.1, 0.9]))
    shape = ConvexShape.ellipsoid(1.0, 0.9, 0.8, 1)
    times = np.zeros(3)
    good = np.tile([1.0, 0.0, 0.0], (3, 1))
    with pytest.raises(ValueError, match="sun must be unit"):
        brightness(body, shape, times, 2 * good, good)
    with pytest.raises(ValueError, match="observer must be finite"):
        brightness(body, shape, times, good, np.where(good > 0, np.nan, 0.0))
    with pytest.raises(ValueError, match="observer must have shape"):
        brightness(body, shape, times, good, good[:2])
    with pytest.raises(ValueError, match="law must be one of"):
        brightness(body, shape, times, good, good, law="hapke")


# ------------------------------------------------------------------------------------ shapes


def test_inertia_of_box_and_ellipsoid():
    a, b, c = 1.0, 2.0, 0.5
    volume, centre, inertia = (np.asarray(x) for x in mesh_inertia(*box_mesh(a, b, c)))
    mass = 8 * a * b * c
    expected = mass / 3 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    np.testing.assert_allclose(volume, mass, rtol=1e-14)
    np.testing.assert_allclose(centre, 0.0, atol=1e-15)
    np.testing.assert_allclose(inertia, expected, rtol=1e-14, atol=1e-14)
    # The inscribed polyhedron of the ellipsoid: volume and moments converge to 4/3 pi abc and
    # m/5 (b^2 + c^2), ... (measured relative errors 2.2e-3 and 3.6e-3 at 5120 facets).
    axes = np.array([1.3, 1.0, 0.7])
    vertices, faces = icosphere(4)
    volume, _, inertia = (np.asarray(x) for x in mesh_inertia(vertices * axes, faces))
    exact_volume = 4 / 3 * np.pi * np.prod(axes)
    exact = (
        exact_volume
        / 5
        * np.array([axes[1] ** 2 + axes[2] ** 2, axes[0] ** 2 + axes[2] ** 2, axes[0] ** 2 + axes[1] ** 2])
    )
    assert abs(volume / exact_volume - 1) < 2.4e-3
    assert np.max(np.abs(np.diag(inertia) / exact - 1)) < 4e-3
    assert np.max(np.abs(inertia - np.diag(np.diag(inertia)))) < 1e-12


def test_minkowski_reconstruction_recovers_the_polytope():
    rng = np.random.default_rng(5)
    points = rng.normal(size=(40, 3)) * np.array([1.4, 1.0, 0.7])
    hull = ConvexHull(points)
    original = ConvexShape.from_mesh(points, hull.simplices)
    vertices, faces = original.polyhedron()
    rebuilt = ConvexShape.from_mesh(vertices, faces)
    v0, _, i0 = (np.asarray(x) for x in mesh_inertia(points, hull.simplices))
    v1, c1, i1 = (np.asarray(x) for x in mesh_inertia(vertices, faces))
    # Measured: volume 2.5e-10, inertia 1.7e-9 relative, centroid at the origin to 1.4e-16.
    assert abs(v1 / v0 - 1) < 1e-9
    assert np.max(np.abs(i1 - i0)) < 5e-9 * np.max(np.abs(i0))
    assert np.max(np.abs(c1)) < 1e-12
    np.testing.assert_allclose(float(rebuilt.total_area), float(original.total_area), rtol=1e-12)
    assert np.max(np.abs(np.asarray(original.closure()))) < 1e-14
    volume, inertia = original.inertia()
    np.testing.assert_allclose(volume, v0, rtol=1e-9)


def test_minkowski_reconstruction_of_an_image_that_is_not_closed():
    """A fitted Gaussian image is closed only as far as its regularisation holds it: the polyhedron
    of the nearest closed image.  This image (an ellipsoid's on the 320 normals of the fit's model,
    log-areas perturbed by 0.4 N(0, 1), closure 0.8% of its area) made qhull fail before."""
    model = ConvexShape.from_mesh(*icosphere(2))
    normals = np.asarray(model.normals)
    axes = np.array([1.35, 1.0, 0.8])
    # The ellipsoid's area per solid angle is (abc)^2 / h(n)^4, h its support function.
    solid_angles = np.asarray(model.areas) / np.asarray(model.areas).sum() * 4 * np.pi
    areas = solid_angles * np.prod(axes) ** 2 / np.sum(axes**2 * normals**2, -1) ** 2
    areas = areas * np.exp(0.4 * np.random.default_rng(1).normal(size=areas.shape))
    image = ConvexShape(normals, areas)
    assert np.max(np.abs(np.asarray(image.closure()))) > 5e-3
    vertices, faces = image.polyhedron()
    rebuilt = ConvexShape.from_mesh(vertices, faces)
    # Each of the polyhedron's triangles lies on a face of one of the image's normals: the areas per
    # normal against the image's (measured: rms 2.2%, largest 3.9% of the mean area), the total the
    # image's, the polyhedron's image closed (3.5e-17).
    owner = np.argmax(np.asarray(rebuilt.normals) @ normals.T, 1)
    assert np.min(np.sum(np.asarray(rebuilt.normals) * normals[owner], 1)) > 1 - 1e-12
    rebuilt_areas = np.bincount(owner, np.asarray(rebuilt.areas), minlength=len(normals))
    difference = (rebuilt_areas - areas) / areas.mean()
    assert np.sqrt(np.mean(difference**2)) < 0.025
    assert np.max(np.abs(difference)) < 0.045
    np.testing.assert_allclose(rebuilt_areas.sum(), areas.sum(), rtol=1e-12)
    assert np.max(np.abs(np.asarray(rebuilt.closure()))) < 1e-15


# ------------------------------------------------------------------------------------ periods


def test_periods_against_the_motion():
    for inertia, momentum in [
        ((0.61, 0.965, 1.0), (0.19, 0.05, 0.98)),  # SAM
        ((0.4, 0.8, 1.0), (0.9, 0.3, 0.3)),  # LAM
        ((1.0, 0.5, 0.8), (0.2, 0.95, -0.1)),
    ]:  # LAM, axes in any order
        inertia, momentum = np.asarray(inertia), 2.3 * unit(momentum)
        p_psi, p_phi, long_axis = (np.asarray(x) for x in tumbler_periods(inertia, momentum))
        body = FreeRigidBody(inertia, momentum, ATTITUDE)
        momentum_after = np.asarray(body.angular_momentum(np.array([float(p_phi)])))[0]
        np.testing.assert_allclose(momentum_after, momentum, atol=1e-12)
        # After P_phi the attitude has turned about L by 2 pi P_phi / P_psi (mod 2 pi).
        r0, r1 = (np.asarray(body.rotation_matrix(np.array([t])))[0] for t in (0.0, float(p_phi)))
        turn = Rotation.from_matrix(r1 @ r0.T).as_rotvec()
        axis = r0 @ momentum / np.linalg.norm(momentum)
        angle = np.dot(turn, axis)
        expected = np.angle(np.exp(2j * np.pi * p_phi / p_psi))
        assert abs(np.angle(np.exp(1j * (angle - expected)))) < 1e-12
        np.testing.assert_allclose(np.cross(turn, axis), 0.0, atol=1e-12)
        energy = 0.5 * np.sum(momentum**2 / inertia)
        assert bool(long_axis) == (np.sum(momentum**2) < 2 * energy * np.sort(inertia)[1])


def test_apophis_periods_from_its_published_spin_state():
    # Pravec et al. (2014), Icarus 233, 48: I1/I3 = 0.61, I2/I3 = 0.965, E/E0 = 1.024 (SAM),
    # P_psi = 27.38 +- 0.07 h, P_phi = 263 +- 6 h.  E0 = L^2 / (2 I3).  |L| set by P_psi.
    inertia = np.array([0.61, 0.965, 1.0])
    energy_ratio = 1.024
    l1_squared = (energy_ratio - 1) / (1 / inertia[0] - 1)  # l2 = 0: a point of the orbit
    direction = np.array([np.sqrt(l1_squared), 0.0, np.sqrt(1 - l1_squared)])
    p_psi, p_phi, long_axis = tumbler_periods(inertia, direction)
    scale = float(p_psi) / 27.38  # |L| in 1/h
    p_psi, p_phi, _ = tumbler_periods(inertia, scale * direction)
    assert not bool(long_axis)
    assert abs(float(p_phi) - 263.0) < 6.0  # 264.6 h
    np.testing.assert_allclose(float(p_psi), 27.38, rtol=1e-12)
    # The published P_phi / P_psi = 9.61 +- 0.22 against 9.664 here.
    assert abs(float(p_phi / p_psi) - 263 / 27.38) < 263 / 27.38 * np.hypot(6 / 263, 0.07 / 27.38)


def test_momentum_from_periods_round_trip():
    inertia = jnp.array([[0.61, 0.965, 1.0], [0.4, 0.8, 1.0]])
    targets = jnp.array([[1.1, 11.0], [3.0, 10.0]])

    # One compiled program (eagerly, the bisection's loops and the periods' operations were each
    # compiled on their own).
    @jax.jit
    def round_trip(inertia, targets):
        momentum, exists = momentum_from_periods(
            inertia, targets[:, 0], targets[:, 1], jnp.array([False, True]), jnp.array([0.3, 1.0])
        )
        return exists, tumbler_periods(inertia, momentum)

    exists, (p_psi, p_phi, long_axis) = round_trip(inertia, targets)
    assert bool(jnp.all(exists))
    np.testing.assert_allclose(np.asarray(p_psi), targets[:, 0], rtol=1e-10)
    np.testing.assert_allclose(np.asarray(p_phi), targets[:, 1], rtol=1e-10)
    np.testing.assert_array_equal(np.asarray(long_axis), [False, True])


def convex_fit_data(times, sun, observer, log_brightness, curves, subdivisions):
    """fit_lightcurve's data of the convex model (sigma 0.01, the former default weights (10, 1)) on the
    normals of the icosphere of ``subdivisions``, and those normals' solid angles."""
    from frbjax.lightcurve import _fit

    normals, solid_angles, faces = _fit._unit_normals(subdivisions)
    data = {
        key: jnp.asarray(value, float)
        for key, value in dict(
            times=times,
            sun=sun,
            observer=observer,
            log_brightness=log_brightness,
            curves=curves,
            sigma=0.01,
            normals=normals,
            laplacian=_fit._laplacian(faces),
            regularisation=(10.0, 1.0),
            free=np.ones(8 + len(normals)),
        ).items()
    }
    return data, solid_angles


def test_convex_fit_jacobian_against_finite_differences():
    """The convex model's hand-assembled Jacobian (forward mode through the motion, the areas'
    columns, the regularisation and period-prior rows written out) against central differences of
    its residuals."""
    from frbjax.lightcurve import _fit

    rng = np.random.default_rng(8)
    times = np.linspace(-2.0, 2.0, 12)
    sun = unit(np.tile([1.0, 0.1, 0.0], (12, 1)) + 0.1 * rng.normal(size=(12, 3)))
    observer = unit(sun + np.array([0.0, 0.4, 0.1]))
    curves = np.repeat(np.eye(2), 6, axis=0)
    data, _ = convex_fit_data(times, sun, observer, rng.normal(scale=0.1, size=12), curves, 0)
    normals = data["normals"]
    direction = unit([0.2, 0.1, 0.95])
    reference = tuple(jnp.asarray(x) for x in (ATTITUDE, direction, _fit._tangent_basis(direction)))
    parameters = np.concatenate(
        [[np.log(0.6), np.log(0.9), 1.5, 0.1, -0.2, 0.05, 0.03, -0.02], 0.2 * rng.normal(size=len(normals))]
    )
    weights = jnp.asarray(np.r_[np.ones(10), 0.0, 1.0])
    # The continuation's period prior on too: log P_psi, log P_phi about centres off the motion's.
    prior = (jnp.log(jnp.array([2.0, 9.0])), jnp.array([40.0, 25.0]))
    window = (weights, prior, jnp.asarray(1.0))
    function = jax.jit(
        lambda p: _fit._residuals_and_jacobian(
            p, reference, data, window, ("convex", "lommel_seeliger_lambert", 0.1, 1, False)
        )
    )
    _, jacobian = function(jnp.asarray(parameters))
    step = 1e-6
    columns = [0, 1, 2, 4, 7, 8, 15, 27]
    numeric = np.stack(
        [
            (
                np.asarray(function(jnp.asarray(parameters + step * np.eye(parameters.size)[k]))[0])
                - np.asarray(function(jnp.asarray(parameters - step * np.eye(parameters.size)[k]))[0])
            )
            / (2 * step)
            for k in columns
        ],
        1,
    )
    error = np.max(np.abs(np.asarray(jacobian)[:, columns] - numeric)) / np.max(np.abs(numeric))
    # Measured 2.7e-10 (relative to the largest entry; 2.9e-10 without the prior rows, which are
    # -23.5 and -11.2 here): finite-difference truncation and rounding.
    assert error < 1e-9


def test_marquardt_scaling_lets_the_convex_solve_reach_its_minimum():
    """``x_scale="jac"``: the convex shape's Levenberg-Marquardt continued, for the parameters times
    the Jacobian's column norms, from where the unscaled solve stops.  From the Gaussian image of an
    ellipsoid near the body's and a motion slightly off (|L| by 1e-4, the attitude by a degree), 16
    nights over 60 days of an ellipsoid (80 facets fitted): the unscaled solve reports convergence at
    cost 54.33, its steps below rtol; continued scaled it ends at 43.90 (128 samples), where a further
    scaled solve moves it by 6e-10 (measured)."""
    from frbjax.lightcurve import _fit

    rng = np.random.default_rng(3)
    nights, per_night = 16, 8
    times = (np.sort(rng.uniform(0, 60, nights))[:, None] + np.linspace(0, 0.25, per_night)).reshape(-1)
    longitude = np.deg2rad(30 + 0.5 * times)
    sun = unit(np.stack([np.cos(longitude), np.sin(longitude), 0.1 * np.sin(times / 40)], -1))
    observer = unit(sun + np.stack([0 * times, 0.3 + 0 * times, 0.2 * np.cos(times / 30)], -1))
    times = times - np.median(times)
    momentum = 30.0 * unit([0.15, 0.0, 1.0])
    body = FreeRigidBody(np.array([0.61, 0.965, 1.0]), momentum, ATTITUDE)
    flux = np.asarray(brightness(body, ConvexShape.ellipsoid(1.35, 1.0, 0.8, subdivisions=3), times, sun, observer))
    flux = flux * np.exp(0.01 * rng.normal(size=times.size))
    curves = np.eye(nights)[np.repeat(np.arange(nights), per_night)]
    data, solid_angles = convex_fit_data(times, sun, observer, np.log(flux), curves, 1)
    normals = np.asarray(data["normals"])
    direction = unit(momentum)
    reference = tuple(jnp.asarray(x)[None] for x in (ATTITUDE, direction, _fit._tangent_basis(direction)))
    areas = _fit._gaussian_image_areas(np.array([1.2, 1.0, 0.9]), normals, solid_angles)
    log_areas = np.log(areas) - np.log(areas).mean()
    motion = [np.log(0.61), np.log(0.965), np.log(30.0) + 1e-4, 0.02, -0.012, 0.008, 0.01, -0.01]
    start = jnp.asarray(np.concatenate([motion, log_areas]))[None]
    config = ("convex", "lommel_seeliger_lambert", 0.1, 1, False)
    solve = functools.partial(
        _fit._refine,
        references=reference,
        priors=None,
        data=data,
        masks=jnp.ones((1, 1, times.size)),
        prior_weights=None,
        config=config,
        rtol=1e-8,
        atol=1e-8,
        max_steps=100,
    )
    unscaled = solve(start)
    scaled = solve(start, x_scale="jac")
    again = solve(scaled[0], x_scale="jac")
    costs = [float(out[1][0]) for out in (unscaled, scaled, again)]
    print(f"unscaled {costs[0]:.4f} (converged: {bool(unscaled[2][0])}), scaled {costs[1]:.6f}")
    print(f"a further scaled solve moves it by {abs(costs[2] - costs[1]):.1e}")
    assert bool(unscaled[2][0]) and costs[0] > 50
    assert bool(scaled[2][0]) and costs[1] < 44.5
    assert abs(costs[2] - costs[1]) < 1e-8
