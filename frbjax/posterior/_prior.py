r"""The prior distributions of the posteriors: moments within the triangle inequality, isotropic rotations.

Both are numpyro distributions (pytrees: a jitted sampler takes them as arguments, so another prior
of the same kinds and shapes reuses its compiled program).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpyro.distributions as dist
from numpyro.distributions import constraints


__all__ = ["PARAMETER_BLOCKS", "IsotropicRotation", "TriangleLogUniform", "default_prior"]

# The prior's keys, the parameters' entries each covers and their names (theta of frbjax.fit).
PARAMETER_BLOCKS = {
    "log_inertia_ratios": (slice(0, 2), ("log_I2_over_I1", "log_I3_over_I1")),
    "angular_velocity": (slice(2, 5), ("omega_1", "omega_2", "omega_3")),
    "attitude": (slice(5, 8), ("delta_1", "delta_2", "delta_3")),
    "principal_axes": (slice(8, 11), ("psi_1", "psi_2", "psi_3")),
}
# Default box of each log-ratio: moments within a factor 100 of each other.
DEFAULT_LOG_RATIO_BOUND = math.log(100.0)
# Width (in (I_a + I_b - I_c) / I_c) of the default prior's smooth triangle-inequality edge.
DEFAULT_TRIANGLE_SOFTNESS = 0.01
# The default angular-velocity prior's scale, in units of the data's finite-difference rate.
DEFAULT_RATE_SCALE = 10.0


def _log_sinc_half_squared(squared_angle):
    """log((sin(a/2) / (a/2))^2) of a = sqrt(squared_angle), its gradient finite at a = 0."""
    small = squared_angle < 1e-8
    angle = jnp.sqrt(jnp.where(small, 1.0, squared_angle))
    exact = 2 * jnp.log(jnp.sin(angle / 2) / (angle / 2))
    return jnp.where(small, -squared_angle / 12, exact)


class IsotropicRotation(dist.Distribution):
    r"""The uniform (Haar) distribution of rotations, as rotation vectors $\delta$ with $|\delta| < \pi$.

    In rotation-vector coordinates the Haar measure of SO(3) has the density

    $$p(\delta) = \frac{1}{8\pi^2}\, \frac{2(1 - \cos|\delta|)}{|\delta|^2}, \qquad |\delta| < \pi,$$

    (zero outside the ball, where the chart would cover rotations twice).  Being invariant, it is
    the same about any reference rotation: the posteriors' attitude $\delta$ about the observed
    attitude at the reference time has it as its isotropic prior.  Event shape (3,).
    """

    arg_constraints = {}
    support = constraints.real_vector
    pytree_data_fields = ()

    def __init__(self, *, validate_args=None):
        super().__init__(batch_shape=(), event_shape=(3,), validate_args=validate_args)

    def sample(self, key, sample_shape=()):
        # A uniform unit quaternion (w >= 0), then its rotation vector.
        q = jax.random.normal(key, tuple(sample_shape) + (4,))
        q = q / jnp.linalg.norm(q, axis=-1, keepdims=True)
        q = jnp.where(q[..., :1] < 0, -q, q)
        vector_norm = jnp.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
        angle = 2 * jnp.arctan2(vector_norm, q[..., :1])
        return q[..., 1:] * angle / jnp.where(vector_norm > 0, vector_norm, 1.0)

    def log_prob(self, value):
        squared = jnp.sum(value * value, axis=-1)
        density = _log_sinc_half_squared(squared) - math.log(8 * math.pi**2)
        return jnp.where(squared < math.pi**2, density, -jnp.inf)


class TriangleLogUniform(dist.Distribution):
    r"""Log-uniform moments within the triangle inequality: the default prior of the inertia ratios.

    The value is $(x, y) = (\log I_2/I_1, \log I_3/I_1)$, uniform in the box ``low`` $\le (x, y) \le$
    ``high`` (by default $|x|, |y| \le \log 100$: no moment 100 times another) and weighted by a
    smooth step at the triangle inequality $I_a + I_b \ge I_c$ of the sorted moments
    $I_a \le I_b \le I_c$ (which every body of matter obeys):

    $$p(x, y) \propto \sigma\!\left(\frac{I_a + I_b - I_c}{s\, I_c}\right), \qquad \sigma(u) = \frac{1}{1 + e^{-u}},$$

    with $s$ = ``softness``: inside the triangle by more than a few $s$ the density is flat, outside
    it falls as $e^{-g/s}$ in the relative excess $g$.  A smooth edge, rather than a wall, keeps
    Hamiltonian Monte Carlo's trajectories free of divergences next to flat bodies ($I_a + I_b
    \approx I_c$); the box's edges are walls.  ``log_prob`` is normalised over the box alone (the
    triangle's weight is not divided out); ``sample`` draws exactly, by rejection from the box.
    Event shape (2,).
    """

    arg_constraints = {
        "low": constraints.real_vector,
        "high": constraints.real_vector,
        "softness": constraints.positive,
    }
    pytree_data_fields = ("low", "high", "softness")

    def __init__(
        self,
        low=-DEFAULT_LOG_RATIO_BOUND,
        high=DEFAULT_LOG_RATIO_BOUND,
        softness=DEFAULT_TRIANGLE_SOFTNESS,
        *,
        validate_args=None,
    ):
        self.low = jnp.broadcast_to(jnp.asarray(low, float), (2,))
        self.high = jnp.broadcast_to(jnp.asarray(high, float), (2,))
        self.softness = jnp.asarray(softness, float)
        super().__init__(batch_shape=(), event_shape=(2,), validate_args=validate_args)

    @constraints.dependent_property(is_discrete=False, event_dim=1)
    def support(self):
        return constraints.independent(constraints.interval(self.low, self.high), 1)

    def _log_edge(self, value):
        moments = jnp.exp(jnp.concatenate([jnp.zeros(value.shape[:-1] + (1,), value.dtype), value], -1))
        largest = jnp.max(moments, axis=-1)
        excess = (jnp.sum(moments, axis=-1) - 2 * largest) / largest
        return jax.nn.log_sigmoid(excess / self.softness)

    def log_prob(self, value):
        low, high = jnp.broadcast_to(self.low, value.shape), jnp.broadcast_to(self.high, value.shape)
        inside = jnp.all((value >= low) & (value <= high), axis=-1)
        density = self._log_edge(value) - jnp.sum(jnp.log(self.high - self.low))
        return jnp.where(inside, density, -jnp.inf)

    def sample(self, key, sample_shape=()):
        shape = tuple(sample_shape) + (2,)
        key, subkey = jax.random.split(key)
        value, accepted = _triangle_draw(self, subkey, shape)
        # The loop's functions are module-level and its operands carry the distribution: a later
        # call finds the loop compiled (fresh closures were traced and compiled again, 0.7 s a call).
        _, _, value, _ = jax.lax.while_loop(_triangle_rejected, _triangle_redraw, (self, key, value, accepted))
        return value


def _triangle_draw(distribution, key, shape):
    """Draws of ``shape`` uniform in the box, and whether each passes the triangle's weight."""
    low, high = jnp.broadcast_to(distribution.low, shape), jnp.broadcast_to(distribution.high, shape)
    box_key, accept_key = jax.random.split(key)
    value = low + (high - low) * jax.random.uniform(box_key, shape)
    accepted = jax.random.uniform(accept_key, shape[:-1]) < jnp.exp(distribution._log_edge(value))
    return value, accepted


def _triangle_rejected(carry):
    return ~jnp.all(carry[3])


def _triangle_redraw(carry):
    distribution, key, value, accepted = carry
    key, subkey = jax.random.split(key)
    candidate, candidate_accepted = _triangle_draw(distribution, subkey, value.shape)
    value = jnp.where(accepted[..., None], value, candidate)
    return distribution, key, value, accepted | candidate_accepted


def default_prior(rate_scale: float, *, tensor: bool = False) -> dict:
    """The default prior (``attitude_posterior``'s docstring): a dict of numpyro distributions.

    ``rate_scale``: the scale of the isotropic normal prior of each angular-velocity component (the
    data's finite-difference rate times ``DEFAULT_RATE_SCALE``).
    """
    prior = {
        "log_inertia_ratios": TriangleLogUniform(),
        "angular_velocity": dist.Normal(jnp.zeros(3), jnp.full(3, float(rate_scale))).to_event(1),
        "attitude": IsotropicRotation(),
    }
    if tensor:
        prior["principal_axes"] = IsotropicRotation()
    return prior
