"""The exact motion in the working frame: per-body constants of each regime and their evaluation.

Notation and formulas: ``shared/design/formulas.md`` (checked numerically on both signs of every branch).
The working frame has sorted moments J1 <= J2 <= J3 and a unit angular momentum l with l1 >= 0 and
l3 >= 0 (the body's symmetry under rotation by pi about a principal axis makes this free: see
``_body.working_frame``), so every orbit sign ``s`` of formulas.md is +1 here.

With g1 = 1 - d J1, g3 = d J3 - 1, g2 = d J2 - 1 computed without cancellation (formulas.md), and the
gaps a = J2 - J1, b = J3 - J2, c = J3 - J1:

- regime "around the major axis" (g2 < 0, parameter m = g3 a/(g1 b) < 1):
  L = (A1 cn, A2 sn, A3 dn)(u),  psi = t/J1 + atan2(L2, L3) - alpha Pi(nu; am u | m),
  quaternion chart built on 1 + L1;
- regime "around the minor axis" (g2 > 0, m = g1 b/(g3 a) < 1, the seeds' mu = 1/m):
  L = (A1 dn, A2 sn, A3 cn)(u),  psi = t/J3 - atan2(L2, L1) + alpha Pi(nu; am u | m),
  quaternion chart built on 1 + L3;
- separatrix (g2 = 0): L = (A1 sech, tanh, A3 sech)(u), psi = t/J2 + 2 atan(delta tanh(u/2)),
  chart built on 1 + L1;
- uniform rotation (L along a principal direction, a sphere, L = 0) is handled in ``_body``.

u = B (t0 + t) where the phase t0 matches the initial angular momentum.  The complement mc = 1 - m is
formed from g2 directly (mc = c |g2| / (g1 b) or c g2 / (g3 a)) so that it keeps full relative precision
next to the separatrix.
"""

from __future__ import annotations

import jax.numpy as jnp

from .special import ellipj, ellipkinc, ellippiinc

MAJOR, MINOR, SEPARATRIX, UNIFORM = 0, 1, 2, 3

# Harmless stand-in bodies for the branches not taken (safe-where pattern): each lies well inside the
# regime whose formulas it feeds, so no square root of zero or division by zero is ever evaluated.
_SAFE_INERTIA = (1.0, 2.0, 3.0)
_SAFE_MAJOR = (0.3, 0.0, 0.9539392014169456)
_SAFE_MINOR = (0.95, 0.0, 0.31224989991991997)


def _substitute(condition, inertia, unit_momentum, safe_momentum):
    safe_j = jnp.asarray(_SAFE_INERTIA, inertia.dtype)
    safe_l = jnp.asarray(safe_momentum, inertia.dtype)
    j = jnp.where(condition[..., None], inertia, safe_j)
    l = jnp.where(condition[..., None], unit_momentum, safe_l)
    return j, l


def energy_gaps(inertia, unit_momentum):
    """(g1, g2, g3) = (1 - d J1, d J2 - 1, d J3 - 1) without cancellation (formulas.md)."""
    j1, j2, j3 = inertia[..., 0], inertia[..., 1], inertia[..., 2]
    l1s, l2s, l3s = unit_momentum[..., 0] ** 2, unit_momentum[..., 1] ** 2, unit_momentum[..., 2] ** 2
    g1 = l2s * (j2 - j1) / j2 + l3s * (j3 - j1) / j3
    g3 = l1s * (j3 - j1) / j1 + l2s * (j3 - j2) / j2
    g2 = l1s * (j2 - j1) / j1 - l3s * (j3 - j2) / j3
    return g1, g2, g3


def classify(inertia, unit_momentum, momentum_norm):
    """Regime code per body (MAJOR, MINOR, SEPARATRIX or UNIFORM), from exact tests only."""
    j1, j2, j3 = inertia[..., 0], inertia[..., 1], inertia[..., 2]
    l1, l2, l3 = unit_momentum[..., 0], unit_momentum[..., 1], unit_momentum[..., 2]
    g1, g2, g3 = energy_gaps(inertia, unit_momentum)
    # L along a principal direction (including the degenerate planes of symmetric bodies): Omega || L.
    uniform = (
        (momentum_norm == 0)
        | (j1 == j3)
        | ((g2 < 0) & (g3 == 0))
        | ((g2 > 0) & (g1 == 0))
        | ((g2 == 0) & ((j1 == j2) | (j2 == j3) | ((l1 == 0) & (l3 == 0))))
    )
    code = jnp.where(g2 < 0, MAJOR, jnp.where(g2 > 0, MINOR, SEPARATRIX))
    return jnp.where(uniform, UNIFORM, code)


def constants(inertia, unit_momentum, regime):
    """Per-body constants of the regime's exact solution (formulas.md), as a dict of arrays."""
    is_major, is_minor, is_sep = regime == MAJOR, regime == MINOR, regime == SEPARATRIX

    # Around the major axis.
    j, l = _substitute(is_major, inertia, unit_momentum, _SAFE_MAJOR)
    j1, j2, j3 = j[..., 0], j[..., 1], j[..., 2]
    g1, g2, g3 = energy_gaps(j, l)
    a, b, c = j2 - j1, j3 - j2, j3 - j1
    major = dict(
        amplitude=jnp.stack([jnp.sqrt(j1 * g3 / c), jnp.sqrt(j2 * g3 / b), jnp.sqrt(j3 * g1 / c)], -1),
        rate=jnp.sqrt(g1 * b / (j1 * j2 * j3)),
        m=g3 * a / (g1 * b),
        mc=c * (-g2) / (g1 * b),
        alpha=c / jnp.sqrt(j1 * g1 * b * j3 / j2),
        nu=-j1 * g3 / (j3 * g1),
        precession=1 / j1,
    )
    major_amplitude = major["amplitude"]
    # Phase: sn = l2/A2, cn = l1/A1 (l1 >= 0, so the amplitude lies in [-pi/2, pi/2]).
    major_am0 = jnp.arctan2(l[..., 1] * major_amplitude[..., 0], l[..., 0] * major_amplitude[..., 1])

    # Around the minor axis.
    j, l = _substitute(is_minor, inertia, unit_momentum, _SAFE_MINOR)
    j1, j2, j3 = j[..., 0], j[..., 1], j[..., 2]
    g1, g2, g3 = energy_gaps(j, l)
    a, b, c = j2 - j1, j3 - j2, j3 - j1
    minor = dict(
        amplitude=jnp.stack([jnp.sqrt(j1 * g3 / c), jnp.sqrt(j2 * g1 / a), jnp.sqrt(j3 * g1 / c)], -1),
        rate=jnp.sqrt(g3 * a / (j1 * j2 * j3)),
        m=g1 * b / (g3 * a),
        mc=c * g2 / (g3 * a),
        alpha=c / jnp.sqrt(j1 * g3 * a * j3 / j2),
        nu=-j3 * g1 / (j1 * g3),
        precession=1 / j3,
    )
    minor_amplitude = minor["amplitude"]
    minor_am0 = jnp.arctan2(l[..., 1] * minor_amplitude[..., 2], l[..., 2] * minor_amplitude[..., 1])

    # Separatrix: constants depend on the moments alone.
    j, l = _substitute(is_sep, inertia, unit_momentum, (0.0, 0.0, 1.0))
    j1, j2, j3 = j[..., 0], j[..., 1], j[..., 2]
    a, b, c = j2 - j1, j3 - j2, j3 - j1
    one = jnp.ones_like(j1)
    separatrix = dict(
        amplitude=jnp.stack([jnp.sqrt(j1 * b / (j2 * c)), one, jnp.sqrt(j3 * a / (j2 * c))], -1),
        rate=jnp.sqrt(a * b / (j1 * j3)) / j2,
        m=one,
        mc=jnp.zeros_like(j1),
        # delta = (sqrt(J2 c) - sqrt(J1 b))/sqrt(J3 a) = sqrt(J3 a)/(sqrt(J2 c) + sqrt(J1 b)).
        alpha=jnp.sqrt(j3 * a) / (jnp.sqrt(j2 * c) + jnp.sqrt(j1 * b)),
        nu=jnp.zeros_like(j1),
        precession=1 / j2,
    )
    separatrix_u0 = jnp.arctanh(l[..., 1])

    def pick(key):
        mask = lambda x: x if x.ndim == regime.ndim else x[..., None]  # noqa: E731
        value = jnp.where(mask(is_minor), minor[key], major[key])
        return jnp.where(mask(is_sep), separatrix[key], value)

    out = {key: pick(key) for key in major}
    am0 = jnp.where(is_minor, minor_am0, major_am0)
    u0_elliptic = ellipkinc(am0, jnp.where(is_sep, 0.5, out["m"]), mc=jnp.where(is_sep, 0.5, out["mc"]))
    out["u0"] = jnp.where(is_sep, separatrix_u0, u0_elliptic)
    out["t0"] = out["u0"] / out["rate"]
    out["regime"] = regime
    return out


def working_momentum(consts, tau):
    """Unit angular momentum in the working frame at unit-|L| time tau (any broadcastable shape)."""
    u = consts["u0"] + consts["rate"] * tau
    sn, cn, dn, am = ellipj(u, consts["m"], mc=consts["mc"])
    minor = consts["regime"] == MINOR
    first = jnp.where(minor, dn, cn)
    third = jnp.where(minor, cn, dn)
    return consts["amplitude"] * jnp.stack([first, sn, third], -1), u, am


def working_quaternion(consts, tau):
    """The particular solution q̂ at unit-|L| time t0 + tau (formulas.md), with its momentum."""
    momentum, u, am = working_momentum(consts, tau)
    regime = consts["regime"]
    minor, separatrix = regime == MINOR, regime == SEPARATRIX
    l1, l2, l3 = momentum[..., 0], momentum[..., 1], momentum[..., 2]
    elapsed = consts["t0"] + tau

    # Pi is not needed on the separatrix (and diverges there as u grows): feed it a harmless point.
    nu = jnp.where(separatrix, 0, consts["nu"])
    m = jnp.where(separatrix, 0.5, consts["m"])
    mc = jnp.where(separatrix, 0.5, consts["mc"])
    third_kind = ellippiinc(nu, am, m, mc=mc)
    orientation = jnp.where(minor, -1, 1)
    partner = jnp.where(minor, l1, l3)
    psi_elliptic = orientation * (jnp.arctan2(l2, partner) - consts["alpha"] * third_kind)
    psi_separatrix = 2 * jnp.arctan(consts["alpha"] * jnp.tanh(u / 2))
    psi = consts["precession"] * elapsed + jnp.where(separatrix, psi_separatrix, psi_elliptic)

    half_cos, half_sin = jnp.cos(psi / 2), jnp.sin(psi / 2)
    # Chart on 1 + L1 (major axis regime and separatrix): 1 + L1 >= 1 - A1 > 0.
    base = 1 + l1
    root, inverse = jnp.sqrt(base / 2), 1 / jnp.sqrt(2 * base)
    chart_major = jnp.stack(
        [
            half_cos * root,
            half_sin * root,
            (l3 * half_cos + l2 * half_sin) * inverse,
            (-l2 * half_cos + l3 * half_sin) * inverse,
        ],
        -1,
    )
    # Chart on 1 + L3 (minor axis regime): 1 + L3 >= 1 - A3 > 0.
    base = 1 + l3
    root, inverse = jnp.sqrt(base / 2), 1 / jnp.sqrt(2 * base)
    chart_minor = jnp.stack(
        [
            root * half_cos,
            (l2 * half_cos + l1 * half_sin) * inverse,
            (l2 * half_sin - l1 * half_cos) * inverse,
            root * half_sin,
        ],
        -1,
    )
    return jnp.where(minor[..., None], chart_minor, chart_major), momentum
