"""The disk-integrated brightness of a convex body in torque-free motion (the forward model).

For a convex body every facet is either fully visible or not (no shadowing), so the flux towards the
observer is (Kaasalainen & Torppa 2001, Icarus 153, 24, eq. 1)

    L(t) = sum_i A_i S(mu_i, mu0_i) 1(mu_i > 0 and mu0_i > 0),
    mu_i = n_i . R(t)^T e_obs(t),   mu0_i = n_i . R(t)^T e_sun(t),

with n_i, A_i the Gaussian image (:class:`ConvexShape`, principal frame), R(t) the attitude of the
body (body to space: :meth:`frbjax.FreeRigidBody.rotation_matrix`) and e_sun, e_obs the unit vectors
from the body to the Sun and to the observer in the inertial frame.  Scattering laws S:

- ``"lambert"``: S = mu mu0;
- ``"lommel_seeliger"``: S = mu mu0 / (mu + mu0);
- ``"lommel_seeliger_lambert"``: S = mu mu0 / (mu + mu0) + c mu mu0 (c = 0.1: Kaasalainen, Torppa &
  Muinonen 2001, Icarus 153, 37, the combination that models asteroids' light curves well at
  moderate phase angles).

The absolute scale (albedo, distances, the 1/pi of Lambert) is left out: relative photometry fits it
per light curve.  Light-time correction is the caller's: give each sample the time at which the
light left the body.

The indicator 1(mu > 0 and mu0 > 0) has a kink where a facet crosses the terminator or the limb; S
vanishes there for every law, so the flux is continuous and its derivative is that of the facets
lit and seen.  The laws are evaluated at safe values (where(mask, mu, 1)) so that no 0/0 appears in
the gradient of the masked branch.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from .. import _checks as checks
from .._body import FreeRigidBody
from .._cpu_options import cpu_jit
from ._shape import ConvexShape


__all__ = ["LAWS", "brightness", "facet_brightness"]

LAWS = ("lambert", "lommel_seeliger", "lommel_seeliger_lambert")


def _scattering(mu, mu0, law, c):
    if law == "lambert":
        return mu * mu0
    lommel_seeliger = mu * mu0 / (mu + mu0)
    if law == "lommel_seeliger":
        return lommel_seeliger
    return lommel_seeliger + c * mu * mu0


def _check_law(law, c):
    """Refused (ValueError): an unknown ``law``, a non-finite or negative ``c`` (a concrete one)."""
    checks.choice("law", law, LAWS)
    if checks.is_concrete(c):
        checks.scalar("c", c, positive=True, allow_zero=True)


def facet_brightness(normals, sun_body, observer_body, law="lommel_seeliger_lambert", c=0.1):
    """S(mu, mu0) 1(mu > 0 and mu0 > 0) per facet: (..., T, F) for normals (..., F, 3) and body-frame
    directions (..., T, 3).  The brightness is this contracted with the areas; it is linear in them.
    Refused (ValueError): an unknown ``law``, a non-finite or negative ``c``, trailing axes other than 3."""
    _check_law(law, c)
    for name, value in (("normals", normals), ("sun_body", sun_body), ("observer_body", observer_body)):
        if checks.is_concrete(value):
            checks.check_finite(name, checks.real_array(name, value))
        checks.check_trailing_shape(name, value, (3,))
    mu = jnp.einsum("...tk,...fk->...tf", observer_body, normals)
    mu0 = jnp.einsum("...tk,...fk->...tf", sun_body, normals)
    lit_and_seen = (mu > 0) & (mu0 > 0)
    safe_mu = jnp.where(lit_and_seen, mu, 1)
    safe_mu0 = jnp.where(lit_and_seen, mu0, 1)
    return jnp.where(lit_and_seen, _scattering(safe_mu, safe_mu0, law, c), 0)


def check_directions(name, directions, n_times):
    """Raise ValueError unless ``directions`` is (T, 3) (or (3,)), finite, unit (concrete inputs)."""
    if (
        directions.shape[-1:] != (3,)
        or directions.ndim > 2
        or (directions.ndim == 2 and n_times is not None and directions.shape[0] != n_times)
    ):
        raise ValueError(
            f"{name} must have shape (T, 3) with T = len(times) = {n_times}, or (3,), got {directions.shape}"
        )
    if checks.is_concrete(directions):
        values = checks.real_array(name, directions)
        checks.check_finite(name, values)
        checks.check_unit_rows(name, values, what="unit vectors")


def brightness(
    body: FreeRigidBody,
    shape: ConvexShape,
    times: Float[Array, " T"],
    sun: Float[Array, "T 3"],
    observer: Float[Array, "T 3"],
    law: str = "lommel_seeliger_lambert",
    c: float = 0.1,
) -> Float[Array, "... T"]:
    """The flux sum_i A_i S(mu_i, mu0_i) over the facets lit and seen, at each time (module docstring).

    ``body``: a :class:`frbjax.FreeRigidBody` (batch shape B, possibly ()); ``shape``: a
    :class:`ConvexShape` in the body's principal frame (batch shape Bs, broadcast with B);
    ``times`` (T,); ``sun``, ``observer``: (T, 3) or (3,) unit vectors from the body to the Sun and
    to the observer, inertial frame; ``law``: ``"lambert"``, ``"lommel_seeliger"`` or
    ``"lommel_seeliger_lambert"`` (weight ``c`` of its Lambert part).  Returns broadcast(B, Bs) + (T,).

    Differentiable in everything (the body's parameters, the shape, the times, the directions);
    jit/vmap compatible; the dtype is that of the inputs.  With concrete (non-traced) inputs the
    directions are checked: finite, unit, one per time; and the times finite.  ``body`` must be a
    `FreeRigidBody` and ``shape`` a `ConvexShape` (ValueError otherwise).
    """
    if not isinstance(body, FreeRigidBody):
        raise ValueError(f"body must be a FreeRigidBody, got {type(body).__name__}")
    if not isinstance(shape, ConvexShape):
        raise ValueError(f"shape must be a ConvexShape, got {type(shape).__name__}")
    if checks.is_concrete(times):
        checks.check_finite("times", checks.real_array("times", times))
    times = jnp.asarray(times)
    if times.ndim != 1:
        raise ValueError(f"times must be one-dimensional (T,), got shape {times.shape}")
    sun = jnp.asarray(sun)
    observer = jnp.asarray(observer)
    check_directions("sun", sun, times.shape[0])
    check_directions("observer", observer, times.shape[0])
    _check_law(law, c)  # here, where c is still concrete (the shape checked its normals when made)
    return _flux(body, shape, times, sun, observer, law, c)


# One program for the evaluation: called eagerly (a fit's result, its `predict`), each of its
# operations was otherwise compiled in turn (about twenty small programs on a first call).
@cpu_jit(static_argnames="law")
def _flux(body, shape, times, sun, observer, law, c):
    sun = jnp.broadcast_to(sun, times.shape + (3,))
    observer = jnp.broadcast_to(observer, times.shape + (3,))
    batch = body.inertia.shape[:-1]
    # The body's batch and the times broadcast together: times along a new leading axis.
    matrices = body.rotation_matrix(times.reshape(times.shape + (1,) * len(batch)))  # (T, *B, 3, 3)
    matrices = jnp.moveaxis(matrices, 0, -3)  # (*B, T, 3, 3)
    # Body-frame directions R^T e.
    sun_body = jnp.einsum("...tji,tj->...ti", matrices, sun.astype(matrices.dtype))
    observer_body = jnp.einsum("...tji,tj->...ti", matrices, observer.astype(matrices.dtype))
    per_facet = facet_brightness(shape.normals, sun_body, observer_body, law, c)
    return jnp.einsum("...tf,...f->...t", per_facet, shape.areas)
