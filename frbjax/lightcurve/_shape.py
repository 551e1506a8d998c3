"""Convex shapes as Gaussian images: facet normals and areas in the body's principal frame.

For a convex body the disk-integrated brightness under any scattering law that depends only on the
local angles (mu, mu0) is a sum over the facets that are both lit and seen, so the brightness depends
on the shape only through its Gaussian image: the outward unit normals n_i and the areas A_i
(Kaasalainen & Torppa 2001, Icarus 153, 24).  A Gaussian image closes, sum_i A_i n_i = 0, and by
Minkowski's theorem determines the convex polyhedron up to a translation; :meth:`ConvexShape.polyhedron`
builds it back (Little 1983; Lamberg 1993): the support heights h minimise

    Phi(h) = sum_i A_i h_i - log V(h),

a convex function (V^(1/3) is concave in h by the Brunn-Minkowski inequality), whose stationarity
condition dV/dh_i = a_i(h) = A_i V says that the actual facet areas a_i(h) are proportional to the
given ones.  V(h) and a_i(h) come from the half-space intersection {x : n_i . x <= h_i} (qhull, on
the host); optimistix's BFGS does the minimisation in log h (the origin stays inside).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, Int

from .. import _checks as checks
from .._cpu_options import cpu_jit


__all__ = ["ConvexShape", "mesh_inertia", "icosphere"]


def icosphere(subdivisions: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """A triangulated unit sphere: (vertices (V, 3), faces (F, 3) counter-clockwise seen from outside).

    The icosahedron with each triangle split into four ``subdivisions`` times and the new vertices
    pushed onto the sphere: F = 20 * 4**subdivisions facets of nearly equal size.  ``subdivisions``:
    an integer >= 0.
    """
    checks.integer("subdivisions", subdivisions, minimum=0)
    golden = (1 + 5**0.5) / 2
    vertices = [
        (-1, golden, 0),
        (1, golden, 0),
        (-1, -golden, 0),
        (1, -golden, 0),
        (0, -1, golden),
        (0, 1, golden),
        (0, -1, -golden),
        (0, 1, -golden),
        (golden, 0, -1),
        (golden, 0, 1),
        (-golden, 0, -1),
        (-golden, 0, 1),
    ]
    faces = [
        (0, 11, 5),
        (0, 5, 1),
        (0, 1, 7),
        (0, 7, 10),
        (0, 10, 11),
        (1, 5, 9),
        (5, 11, 4),
        (11, 10, 2),
        (10, 7, 6),
        (7, 1, 8),
        (3, 9, 4),
        (3, 4, 2),
        (3, 2, 6),
        (3, 6, 8),
        (3, 8, 9),
        (4, 9, 5),
        (2, 4, 11),
        (6, 2, 10),
        (8, 6, 7),
        (9, 8, 1),
    ]
    vertices = [np.asarray(v, float) / np.linalg.norm(v) for v in vertices]
    for _ in range(subdivisions):
        midpoints: dict[tuple[int, int], int] = {}

        def midpoint(i, j):
            key = (min(i, j), max(i, j))
            if key not in midpoints:
                middle = vertices[i] + vertices[j]
                vertices.append(middle / np.linalg.norm(middle))
                midpoints[key] = len(vertices) - 1
            return midpoints[key]

        refined = []
        for i, j, k in faces:
            ij, jk, ki = midpoint(i, j), midpoint(j, k), midpoint(k, i)
            refined += [(i, ij, ki), (j, jk, ij), (k, ki, jk), (ij, jk, ki)]
        faces = refined
    return np.asarray(vertices), np.asarray(faces, dtype=np.int32)


def _checked_mesh(vertices, faces):
    """(vertices as a JAX array, faces as numpy) of a triangulated surface; ValueError for a mesh that
    is not one (vertices (..., V, 3), finite when concrete; faces (F, 3) integers in [0, V), F >= 4)."""
    if checks.is_concrete(vertices):
        checks.check_finite("vertices", checks.real_array("vertices", vertices))
    vertices = jnp.asarray(vertices)
    checks.check_trailing_shape("vertices", vertices, (3,))
    if vertices.ndim < 2:
        raise ValueError(f"vertices must have shape (..., V, 3), got shape {vertices.shape}")
    faces = np.asarray(faces)
    if faces.dtype.kind not in "iu" or faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(
            f"faces must be integer vertex indices of shape (F, 3), got {faces.dtype} of shape {faces.shape}"
        )
    if len(faces) < 4:
        raise ValueError(f"faces: a closed surface has at least 4 triangles, got {len(faces)}")
    outside = (faces < 0) | (faces >= vertices.shape[-2])
    if np.any(outside):
        row, column = np.argwhere(outside)[0]
        raise ValueError(
            f"faces must index the {vertices.shape[-2]} vertices: faces[{row}, {column}] is {faces[row, column]}"
        )
    return vertices, faces


@functools.cache
def _icosphere_area_vectors(subdivisions):
    """The area vectors (F, 3) of the icosphere's triangles (e1 x e2 / 2, outward), float64 numpy."""
    vertices, faces = icosphere(subdivisions)
    corners = vertices[faces]
    area_vectors = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]) / 2
    outward = np.sum(area_vectors * corners.mean(1), -1) > 0
    return np.where(outward[:, None], area_vectors, -area_vectors)


@cpu_jit  # one program per mesh size: eagerly, a new shape compiled each of its operations in turn
def _facets(vertices, faces):
    """(normals, areas) of the triangles of a closed convex mesh, normals turned outward."""
    corners = vertices[..., faces, :]  # (..., F, 3, 3)
    cross = jnp.cross(corners[..., 1, :] - corners[..., 0, :], corners[..., 2, :] - corners[..., 0, :])
    twice_area = jnp.linalg.norm(cross, axis=-1)
    normals = cross / jnp.where(twice_area > 0, twice_area, 1.0)[..., None]
    # Faces may come in either orientation: a convex body's outward normal points away from its
    # centroid (any interior point; the vertex mean is one).
    outward = jnp.sum(normals * (jnp.mean(corners, -2) - jnp.mean(vertices, -2, keepdims=True)), -1)
    normals = jnp.where(outward[..., None] < 0, -normals, normals)
    return normals, twice_area / 2


def mesh_inertia(vertices: Float[Array, "... V 3"], faces: Int[Array, "F 3"]) -> tuple[Array, Array, Array]:
    """(volume, centre of mass (3,), inertia tensor (3, 3) about the centre of mass) of a closed mesh
    at unit density.

    Exact for the polyhedron: the sum over the tetrahedra (c, v0, v1, v2) from an interior point c,
    each with volume det/6 and second moment integral int x x^T dV = V/20 (sum_i v_i v_i^T +
    (sum_i v_i)(sum_i v_i)^T) (vertices relative to c, c itself among them at 0); I = tr(C) 1 - C.
    Faces may be in either orientation (convex meshes: each is turned outward).
    """
    return _mesh_inertia(*_checked_mesh(vertices, faces))


@cpu_jit  # one program per mesh size (see _facets)
def _mesh_inertia(vertices, faces):
    centre = jnp.mean(vertices, -2, keepdims=True)
    corners = (vertices - centre)[..., faces, :]  # (..., F, 3, 3)
    volumes = jnp.linalg.det(corners) / 6
    # The orientation of each face: its tetrahedron's volume is positive for an outward face.
    volumes = jnp.abs(volumes)
    total = jnp.sum(volumes, -1)
    corner_sum = jnp.sum(corners, -2)  # (..., F, 3)
    centroid = jnp.sum(volumes[..., None] * corner_sum / 4, -2) / total[..., None]
    second = jnp.einsum("...fi,...fj->...fij", corner_sum, corner_sum) + jnp.einsum(
        "...fki,...fkj->...fij", corners, corners
    )
    second_moment = jnp.sum(volumes[..., None, None] * second / 20, -3)
    # About the centre of mass (parallel axis theorem on the second moment).
    second_moment = second_moment - total[..., None, None] * jnp.einsum("...i,...j->...ij", centroid, centroid)
    eye = jnp.eye(3, dtype=second_moment.dtype)
    inertia = jnp.trace(second_moment, axis1=-2, axis2=-1)[..., None, None] * eye - second_moment
    return total, centroid + centre[..., 0, :], inertia


class ConvexShape(eqx.Module):
    """A convex body as its Gaussian image: unit outward facet normals and facet areas.

    ``ConvexShape(normals, areas)``: ``normals`` (..., F, 3) unit vectors in the body's principal
    frame (the frame of :class:`frbjax.FreeRigidBody`: x_space = R(t) x_body), ``areas`` (..., F) >= 0.
    Leading dimensions are a batch of shapes (sharing F).  Only (normals, areas) enter the brightness
    (:func:`frbjax.lightcurve.brightness`); the polyhedron itself, for drawing or for its inertia, is
    recovered by :meth:`polyhedron` (Minkowski's problem).
    """

    normals: Float[Array, "... F 3"]
    areas: Float[Array, "... F"]

    def __check_init__(self):
        checks.check_trailing_shape("normals", self.normals, (3,))
        if tuple(np.shape(self.areas)) != tuple(np.shape(self.normals))[:-1]:
            raise ValueError(
                f"areas must have the shape of normals without its last axis, "
                f"{tuple(np.shape(self.normals))[:-1]}, got {tuple(np.shape(self.areas))}"
            )
        if checks.is_concrete(self.normals, self.areas):
            normals, areas = checks.real_array("normals", self.normals), checks.real_array("areas", self.areas)
            checks.check_finite("normals", normals)
            checks.check_unit_rows("normals", normals, what="unit vectors")
            checks.check_positive("areas", areas, allow_zero=True)

    @classmethod
    def from_mesh(cls, vertices: Float[Array, "... V 3"], faces: Int[Array, "F 3"]) -> ConvexShape:
        """The Gaussian image of a closed convex triangulated surface (``faces`` index ``vertices``;
        either orientation): n = e1 x e2 / |e1 x e2|, A = |e1 x e2| / 2 per triangle.  Differentiable
        in the vertices.  Refused (ValueError): vertices not (..., V, 3) or not finite, faces not
        integer indices (F, 3) into the vertices, fewer than 4 faces."""
        vertices, faces = _checked_mesh(vertices, faces)
        normals, areas = _facets(vertices, faces)
        return cls(normals, areas)

    @classmethod
    def ellipsoid(cls, a, b, c, subdivisions: int = 3) -> ConvexShape:
        """The triaxial ellipsoid x^2/a^2 + y^2/b^2 + z^2/c^2 = 1 (semi-axes along principal axes 1, 2,
        3), triangulated: the icosphere of ``subdivisions`` (20 * 4**subdivisions facets) stretched by
        (a, b, c).  Differentiable in a, b, c; a batch of ellipsoids from arrays a, b, c.  Semi-axes
        that are not finite and > 0 are refused (ValueError) when concrete."""
        for name, value in (("a", a), ("b", b), ("c", c)):
            if checks.is_concrete(value):
                checks.check_positive(name, checks.real_array(name, value))
        checks.integer("subdivisions", subdivisions, minimum=0)
        axes = jnp.stack(jnp.broadcast_arrays(jnp.asarray(a), jnp.asarray(b), jnp.asarray(c)), -1)
        axes = axes.astype(jnp.result_type(axes, float))
        # A triangle's area vector e1 x e2 / 2 under the linear map D = diag(a, b, c) becomes
        # (D e1) x (D e2) / 2 = det(D) D^-T (e1 x e2) / 2: the icosphere's area vectors scaled by
        # (b c, a c, a b): the stretched mesh's Gaussian image without building the mesh (its gather
        # and cross products were most of the ellipsoid in the light-curve fit's programs).
        scale = jnp.stack([axes[..., 1] * axes[..., 2], axes[..., 0] * axes[..., 2], axes[..., 0] * axes[..., 1]], -1)
        # The icosphere's (F, 3) given the batch's leading axes explicitly (rank-safe broadcasting).
        unit_area_vectors = jnp.asarray(_icosphere_area_vectors(subdivisions), axes.dtype)
        unit_area_vectors = jnp.expand_dims(unit_area_vectors, tuple(range(axes.ndim - 1)))
        area_vectors = unit_area_vectors * scale[..., None, :]
        areas = jnp.sqrt(jnp.sum(area_vectors**2, -1))
        return cls(area_vectors / areas[..., None], areas)

    @property
    def total_area(self) -> Array:
        """Sum of the facet areas."""
        return jnp.sum(self.areas, -1)

    def closure(self) -> Array:
        """sum_i A_i n_i / sum_i A_i: zero for the Gaussian image of a closed surface."""
        return jnp.sum(self.areas[..., None] * self.normals, -2) / self.total_area[..., None]

    def polyhedron(self, *, rtol: float = 1e-10, atol: float = 1e-10, max_steps: int = 2000):
        """The convex polyhedron with this Gaussian image (Minkowski's problem): (vertices (V, 3), faces
        (T, 3)), a triangulated surface centred on its centroid, numpy.

        Solves min_h sum_i A_i h_i - log V(h) (module docstring) with optimistix's BFGS in log h, V(h)
        and its gradient a(h) from qhull's half-space intersection, then scales the polytope so that
        its total area is that of the image.  The problem has a solution only for a closed image
        (sum_i A_i n_i = 0; otherwise translating the polytope lowers the objective without end):
        an image that is not, such as a fitted one (closed only as far as its regularisation holds
        it), is first closed by the smallest change of its areas (least squares, areas kept
        positive).  Facets whose area is negligible may be absent.  One
        shape at a time (no batch dimension).
        """
        checks.scalar("rtol", rtol, positive=True)
        checks.scalar("atol", atol, positive=True)
        checks.integer("max_steps", max_steps, minimum=1)
        normals = np.asarray(self.normals, dtype=float)
        areas = np.asarray(self.areas, dtype=float)
        if normals.ndim != 2:
            raise ValueError("polyhedron: one shape at a time (normals (F, 3))")
        # A facet of (nearly) zero area would leave its height free to run off: a floor keeps it
        # just touching the polytope.
        weights = _closed_image(normals, np.maximum(areas / areas.sum(), 1e-9))
        log_heights = _minkowski_heights(normals, weights, rtol, atol, max_steps)
        vertices, faces, _, _ = _halfspace_polytope(normals, np.exp(log_heights))
        current = _triangle_areas(vertices, faces).sum()
        vertices = vertices * np.sqrt(areas.sum() / current)
        _, centroid, _ = (np.asarray(x) for x in mesh_inertia(vertices, faces))
        return vertices - centroid, faces

    def inertia(self, density: float = 1.0):
        """(volume, inertia tensor (3, 3) about the centroid) of the polyhedron of :meth:`polyhedron`
        at uniform ``density``, in the frame of the normals: compare its diagonal (or eigenvalues)
        with fitted moments (ratios)."""
        checks.scalar("density", density, positive=True)
        vertices, faces = self.polyhedron()
        volume, _, inertia = mesh_inertia(vertices, faces)
        return np.asarray(volume), density * np.asarray(inertia)


def _closed_image(normals, weights, floor=1e-9, iterations=50):
    """Weights (F,) summing to 1 with sum_i w_i n_i = 0, nearest to ``weights`` in least squares:
    the projection onto the closed images, alternated with the floor that keeps them positive."""
    gram = normals.T @ normals
    for _ in range(iterations):
        weights = np.maximum(weights - normals @ np.linalg.solve(gram, normals.T @ weights), floor)
        if np.linalg.norm(weights @ normals) <= 1e-14 * weights.sum():
            break
    return weights / weights.sum()


def _triangle_areas(vertices, faces):
    corners = vertices[faces]
    return np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=-1) / 2


def _halfspace_polytope(normals, heights):
    """(vertices, faces, volume, facet areas a_i) of {x : n_i . x <= h_i}, h > 0 (origin inside)."""
    from scipy.spatial import ConvexHull, HalfspaceIntersection

    halfspaces = np.concatenate([normals, -heights[:, None]], axis=1)
    points = HalfspaceIntersection(halfspaces, np.zeros(3)).intersections
    hull = ConvexHull(points)
    faces = hull.simplices
    triangle_areas = _triangle_areas(points, faces)
    # Each hull triangle lies in the plane of the half-space whose normal it shares.
    owner = np.argmax(hull.equations[:, :3] @ normals.T, axis=1)
    facet_areas = np.bincount(owner, weights=triangle_areas, minlength=len(normals))
    # Orient the triangles outward (qhull's simplices are unordered).
    corners = points[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    flip = np.sum(cross * hull.equations[:, :3], -1) < 0
    faces = np.where(flip[:, None], faces[:, ::-1], faces)
    return points, faces, hull.volume, facet_areas


def _volume_and_areas(log_heights, normals):
    # Trial points of the line search may be far out: heights are kept finite.
    heights = np.exp(np.clip(np.asarray(log_heights), -30.0, 30.0))
    _, _, volume, areas = _halfspace_polytope(np.asarray(normals), heights)
    return np.asarray(volume, log_heights.dtype), areas.astype(log_heights.dtype)


def _host_volume(log_heights, normals):
    shapes = (jax.ShapeDtypeStruct((), log_heights.dtype), jax.ShapeDtypeStruct(log_heights.shape, log_heights.dtype))
    return jax.pure_callback(_volume_and_areas, shapes, log_heights, normals)


@jax.custom_jvp
def _log_volume(log_heights, normals):
    volume, _ = _host_volume(log_heights, normals)
    return jnp.log(volume)


@_log_volume.defjvp
def _log_volume_jvp(primals, tangents):
    # dV/dh_i = a_i(h) (the facet areas): d log V / d log h_i = a_i h_i / V.
    log_heights, normals = primals
    volume, areas = _host_volume(log_heights, normals)
    gradient = areas * jnp.exp(log_heights) / volume
    return jnp.log(volume), jnp.dot(gradient, tangents[0])


@cpu_jit(static_argnames=("rtol", "atol", "max_steps"))
def _minkowski_solve(normals, weights, rtol, atol, max_steps):
    def objective(log_heights, args):
        return jnp.dot(weights, jnp.exp(log_heights)) - _log_volume(log_heights, normals)

    # At the minimum sum_i w_i h_i = sum_i a_i h_i / V = 3 (sum_i w_i = 1): start there, h_i = 3.
    start = jnp.full(weights.shape, jnp.log(3.0), weights.dtype)
    solution = optx.minimise(objective, optx.BFGS(rtol=rtol, atol=atol), start, max_steps=max_steps, throw=False)
    return solution.value


def _minkowski_heights(normals, weights, rtol, atol, max_steps):
    return np.asarray(_minkowski_solve(jnp.asarray(normals), jnp.asarray(weights), rtol, atol, max_steps))
