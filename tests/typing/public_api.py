"""A user's calls of frbjax's public API, type-checked by pyright (`make typecheck`), never run.

Each assignment states the type a user expects; pyright (basic mode, pyrightconfig.json beside this
file) checks it against the package's annotations, including the names frbjax imports on first use.
"""

import jax
import jax.numpy as jnp
import numpy as np

import frbjax
from frbjax import lightcurve, special, torques


inertia = jnp.array([1.0, 2.0, 3.0])
momentum = jnp.array([0.1, 1.0, 0.2])
attitude = jnp.array([1.0, 0.0, 0.0, 0.0])
body = frbjax.FreeRigidBody(inertia, momentum, attitude)
times = jnp.linspace(0.0, 10.0, 11)
quaternions: jax.Array = body.quaternion(times)
matrices: jax.Array = body.rotation_matrix(times)
angular_momentum: jax.Array = body.angular_momentum(times)
angular_velocity: jax.Array = body.angular_velocity(times)
flowed_momentum, flowed_attitude = frbjax.free_flow(inertia, momentum, attitude, 1.0)
tensor_body = frbjax.FreeRigidBody.from_inertia_tensor(frbjax.InertiaTensor(jnp.eye(3) * inertia), momentum, attitude)
rotation: jax.Array = frbjax.quaternion_to_matrix(quaternions)
back: jax.Array = frbjax.quaternion_from_matrix(rotation)

quarter_period: jax.Array = special.ellipk(0.5)
sn, cn, dn, amplitude = special.ellipj(0.3, 0.5)
third_kind: jax.Array = special.elliprj(1.0, 2.0, 3.0, 4.0)

fit: frbjax.AttitudeFit = frbjax.fit_attitude(np.asarray(times), np.asarray(quaternions))
fitted_moments: jax.Array = fit.inertia
try:
    frbjax.fit_attitude(np.asarray(times), np.asarray(quaternions), throw=True)
except frbjax.FitError as error:
    unconverged = error.result

term = frbjax.RigidBodyTerm(inertia, torque=torques.ConstantTorque(jnp.array([0.0, 0.0, 0.1])))
solver = frbjax.RigidBodySplitting("leapfrog")
methods = frbjax.SPLITTING_METHODS

shape = lightcurve.ConvexShape.ellipsoid(1.0, 0.8, 0.6)
periods = lightcurve.tumbler_periods(inertia, momentum)
