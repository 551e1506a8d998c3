"""A property-based harness over the public surface: what each entry point refuses, and what it accepts.

For every public callable, hypothesis draws a valid set of arguments and then either calls it (the
result must be finite) or spoils one argument in one of the ways real data and misuse do (a NaN or
infinite entry at a random place, a zero, negative or non-unit value, a wrong trailing shape, a
complex or string dtype, a range upside down, a count of zero) and checks that the call raises a
ValueError whose message names that argument.  The spoiled calls raise before anything is compiled;
the valid ones use fixed shapes, so that each entry compiles its program once.

The fits (``fit_attitude``, ``fit_lightcurve``) are in the harness for what they refuse; that valid data
give a finite, accurate fit is what tests/test_fit.py and tests/test_lightcurve_fit.py check on
synthetic motions (random arrays are not data of a free motion).  The special functions follow
scipy.special: outside their domain they return NaN (they are element-wise functions, used under
``jit``), and only arguments that are not real numbers raise.  ``benchmarks/fuzz_inputs.py`` runs the
same harness with many more examples.
"""

from __future__ import annotations

import dataclasses
import os
import re
from collections.abc import Callable

import jax
import numpy as np
import pytest
import scipy.special
from hypothesis import given, HealthCheck, settings, strategies as st

import frbjax
from frbjax import lightcurve, special, torques


# The suite's size; the benchmark sets FRBJAX_HARNESS_EXAMPLES for its larger run.
EXAMPLES = int(os.environ.get("FRBJAX_HARNESS_EXAMPLES", "12"))
HARNESS = settings(
    max_examples=EXAMPLES,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

# ------------------------------------------------------------------------------ valid arguments


def floats(low, high):
    return st.floats(low, high, allow_nan=False, allow_infinity=False)


def vectors(size, low=-3.0, high=3.0):
    return st.lists(floats(low, high), min_size=size, max_size=size).map(np.array)


def moments():
    return vectors(3, 0.2, 5.0)


def quaternions():
    return vectors(4).filter(lambda q: np.linalg.norm(q) > 0.1).map(lambda q: q / np.linalg.norm(q))


def unit_vectors(count=None):
    one = vectors(3).filter(lambda v: np.linalg.norm(v) > 0.1).map(lambda v: v / np.linalg.norm(v))
    return one if count is None else st.lists(one, min_size=count, max_size=count).map(np.array)


def times(count=5):
    return st.lists(floats(-50.0, 50.0), min_size=count, max_size=count, unique=True).map(
        lambda t: np.sort(np.array(t))
    )


def rotations():
    return quaternions().map(lambda q: np.asarray(frbjax.quaternion_to_matrix(q)))


def tensors():
    """Symmetric positive definite matrices with moments that obey nothing in particular."""
    return st.tuples(moments(), rotations()).map(lambda a: a[1] @ np.diag(a[0]) @ a[1].T)


def positive_scalar(low=0.1, high=5.0):
    return floats(low, high)


# ------------------------------------------------------------------------------ spoiling one argument

# The ways of spoiling an argument, by what it is.  Each takes (value, draw) and returns the spoiled
# value.  "finite" applies to every array of real numbers.


def _at_random_entry(value, draw, replacement):
    spoiled = np.array(value, dtype=float)
    index = draw(st.integers(0, spoiled.size - 1))
    spoiled.reshape(-1)[index] = replacement
    return spoiled


SPOILERS = {
    "nan": lambda v, draw: _at_random_entry(v, draw, np.nan),
    "inf": lambda v, draw: _at_random_entry(v, draw, draw(st.sampled_from([np.inf, -np.inf]))),
    "complex": lambda v, draw: np.asarray(v, dtype=complex) + 1j,
    "string": lambda v, draw: np.asarray(v).astype(str),
    "trailing": lambda v, draw: np.concatenate([np.atleast_1d(v), np.atleast_1d(v)[..., :1]], -1),
    "nonpositive": lambda v, draw: _at_random_entry(v, draw, draw(st.sampled_from([0.0, -1.0, -1e-300]))),
    "zero": lambda v, draw: np.zeros_like(np.asarray(v, float)),
    "scaled": lambda v, draw: np.asarray(v) * draw(st.sampled_from([0.5, 1.01, 2.0, 100.0])),
    "reflected": lambda v, draw: np.asarray(v) @ np.diag([1.0, 1.0, -1.0]),
    "asymmetric": lambda v, draw: np.asarray(v) + np.triu(np.ones((3, 3)), 1) * 0.1,
    "indefinite": lambda v, draw: np.asarray(v) - 10 * np.eye(3),
    "upside_down": lambda v, draw: np.asarray(v)[..., ::-1],
    "negative": lambda v, draw: -1.0 - abs(float(np.asarray(v).reshape(-1)[0])),
    "empty": lambda v, draw: [],
    "unbatched": lambda v, draw: np.asarray(v)[0],
    "scalar": lambda v, draw: np.asarray(v)[0],
    "repeated": lambda v, draw: np.concatenate([np.asarray(v)[:1], np.asarray(v)[:-1]]),
    "negative_int": lambda v, draw: -1 - draw(st.integers(0, 5)),
    "float_count": lambda v, draw: float(v) + 0.5,
    "unknown_name": lambda v, draw: "no_such_" + str(v),
}

ARRAY = ("nan", "inf", "complex", "string")
KINDS = {
    "finite": ARRAY,
    "finite3": ARRAY + ("trailing",),
    "positive3": ARRAY + ("trailing", "nonpositive"),
    "positive": ("nan", "inf", "nonpositive", "string"),
    "times": ("nan", "inf", "string"),
    "quaternion": ARRAY + ("trailing", "zero"),
    "unit_quaternion": ARRAY + ("trailing", "zero", "scaled"),
    "unit_vectors": ("nan", "inf", "complex", "zero", "scaled"),
    "rotation": ("nan", "inf", "complex", "scaled", "reflected"),
    "spd": ("nan", "inf", "asymmetric", "indefinite"),
    "range": ("nan", "inf", "nonpositive", "upside_down"),
    "count": ("negative_int", "float_count"),
    "option": ("unknown_name",),
    "distinct_times": ("nan", "inf", "repeated", "string"),
    "nonnegative": ("nan", "inf", "negative", "string"),
    "nonempty": ("empty",),
    "batch": ("unbatched",),
    "batched_tree": ("scalar",),
}


@dataclasses.dataclass
class Entry:
    """A public callable: its valid arguments (strategies), which of them to spoil and how (KINDS),
    and what to do with a valid call (``call``; None: the entry is checked for what it refuses)."""

    arguments: dict[str, st.SearchStrategy]
    kinds: dict[str, str]
    build: Callable
    call: Callable | None = lambda result: result
    # Spoiled arguments whose message names another (e.g. a body's inertia inside ``brightness``).
    named: dict[str, str] = dataclasses.field(default_factory=dict)


def _body(inertia, angular_momentum, attitude):
    return frbjax.FreeRigidBody(inertia, angular_momentum, attitude)


def _attitude_data():
    """A short record that is valid as input (unit quaternions, distinct times): fits refuse its spoils."""
    return st.tuples(times(8), st.lists(quaternions(), min_size=8, max_size=8).map(np.array))


def _fit_attitude(data, angular_velocity_sigma, n_starts, loss):
    (t, q) = data
    return frbjax.fit_attitude(t, q, angular_velocity_sigma=angular_velocity_sigma, n_starts=n_starts, loss=loss)


_SUN = np.array([1.0, 0.0, 0.0])
_OBSERVER = np.array([np.cos(0.3), np.sin(0.3), 0.0])


def _fit_lightcurve(times, brightness, sun, periods, inertia_range, starts_per_period, law):
    return lightcurve.fit_lightcurve(
        times,
        brightness,
        sun,
        _OBSERVER,
        periods=periods,
        inertia_range=inertia_range,
        starts_per_period=starts_per_period,
        law=law,
    )


_ICOSAHEDRON = lightcurve.icosphere(0)


def _sum_of_torques(parts):
    return torques.SumOfTorques(parts)


ENTRIES = {
    "FreeRigidBody": Entry(
        dict(inertia=moments(), angular_momentum=vectors(3), attitude=quaternions(), t=times()),
        dict(inertia="positive3", angular_momentum="finite3", attitude="quaternion", t="times"),
        lambda inertia, angular_momentum, attitude, t: _body(inertia, angular_momentum, attitude).state(t),
    ),
    "FreeRigidBody.from_inertia_tensor": Entry(
        dict(inertia_tensor=tensors(), angular_momentum=vectors(3)),
        dict(inertia_tensor="spd", angular_momentum="finite3"),
        lambda inertia_tensor, angular_momentum: (
            frbjax.FreeRigidBody.from_inertia_tensor(inertia_tensor, angular_momentum).momentum_norm
        ),
    ),
    "free_flow": Entry(
        dict(inertia=moments(), angular_momentum=vectors(3), attitude=quaternions(), t=floats(-50, 50)),
        dict(inertia="positive3", angular_momentum="finite3", attitude="quaternion", t="times"),
        frbjax.free_flow,
    ),
    "InertiaTensor": Entry(
        dict(matrix=tensors()), dict(matrix="spd"), lambda matrix: frbjax.InertiaTensor(matrix).principal_moments
    ),
    "quaternion_to_matrix": Entry(dict(q=quaternions()), dict(q="unit_quaternion"), frbjax.quaternion_to_matrix),
    "quaternion_from_matrix": Entry(dict(matrix=rotations()), dict(matrix="rotation"), frbjax.quaternion_from_matrix),
    "fit_attitude": Entry(
        dict(
            data=_attitude_data(),
            angular_velocity_sigma=positive_scalar(),
            n_starts=st.integers(1, 4),
            loss=st.sampled_from(["squared", "huber", "cauchy"]),
        ),
        dict(data="fit_data", angular_velocity_sigma="positive", n_starts="count", loss="option"),
        _fit_attitude,
        call=None,
    ),
    "pad_batch": Entry(dict(tree=vectors(3), multiple=st.integers(1, 4)), dict(multiple="count"), frbjax.pad_batch),
    "ConstantTorque": Entry(
        dict(torque=vectors(3)), dict(torque="finite3"), lambda torque: torques.ConstantTorque(torque).torque
    ),
    "UniformGravity": Entry(
        dict(centre_of_mass=vectors(3), weight=vectors(3)),
        dict(centre_of_mass="finite3", weight="finite3"),
        lambda centre_of_mass, weight: torques.UniformGravity(centre_of_mass, weight).weight,
    ),
    "CircularOrbit": Entry(
        dict(radius=positive_scalar(1.0, 10.0), mu=positive_scalar()),
        dict(radius="positive", mu="positive"),
        lambda radius, mu: torques.CircularOrbit(radius, mu).rate,
    ),
    "LinearDamping": Entry(
        dict(inertia=moments(), damping=moments()),
        dict(inertia="positive3", damping="finite3"),
        lambda inertia, damping: torques.LinearDamping(inertia, damping).damping,
    ),
    "RigidBodyTerm": Entry(
        dict(inertia=moments()),
        dict(inertia="positive3"),
        lambda inertia: frbjax.RigidBodyTerm(inertia, torque=lambda t, q, args: q[1:]).inertia,
    ),
    "splitting_trajectory": Entry(
        dict(y0=st.tuples(vectors(3), quaternions()), dt=positive_scalar(0.01, 0.1), steps=st.integers(1, 3)),
        dict(dt="positive", steps="count"),
        lambda y0, dt, steps: frbjax.splitting_trajectory(
            frbjax.RigidBodyTerm(np.array([1.0, 2.0, 3.0]), torque=lambda t, q, args: q[1:]), y0, dt=dt, steps=steps
        ),
        call=None,
    ),
    "ConvexShape.ellipsoid": Entry(
        dict(a=positive_scalar(), b=positive_scalar(), c=positive_scalar(), subdivisions=st.integers(0, 1)),
        dict(a="positive", b="positive", c="positive", subdivisions="count"),
        lambda a, b, c, subdivisions: lightcurve.ConvexShape.ellipsoid(a, b, c, subdivisions).areas,
    ),
    "ConvexShape": Entry(
        dict(normals=unit_vectors(6), areas=vectors(6, 0.0, 2.0)),
        dict(normals="unit_vectors", areas="finite"),
        lambda normals, areas: lightcurve.ConvexShape(normals, areas).total_area,
    ),
    "ConvexShape.from_mesh": Entry(
        dict(vertices=moments().map(lambda axes: _ICOSAHEDRON[0] * axes)),
        dict(vertices="finite3"),
        lambda vertices: lightcurve.ConvexShape.from_mesh(vertices, _ICOSAHEDRON[1]).areas,
    ),
    "mesh_inertia": Entry(
        dict(vertices=moments().map(lambda axes: _ICOSAHEDRON[0] * axes)),
        dict(vertices="finite3"),
        lambda vertices: lightcurve.mesh_inertia(vertices, _ICOSAHEDRON[1]),
    ),
    "icosphere": Entry(dict(subdivisions=st.integers(0, 2)), dict(subdivisions="count"), lightcurve.icosphere),
    "tumbler_periods": Entry(
        dict(inertia=moments(), angular_momentum=vectors(3).filter(lambda v: np.linalg.norm(v) > 0.1)),
        dict(inertia="positive3", angular_momentum="finite3"),
        lambda inertia, angular_momentum: lightcurve.tumbler_periods(inertia, angular_momentum)[0],
    ),
    "tumbler_periodogram": Entry(
        dict(times=times(6), brightness=vectors(6, 0.5, 2.0), period_range=st.just(np.array([0.2, 2.0]))),
        dict(times="times", brightness="positive", period_range="range"),
        lambda times, brightness, period_range: lightcurve.tumbler_periodogram(
            times, brightness, period_range=period_range
        ),
        call=None,
    ),
    "GravityGradient": Entry(
        dict(inertia=moments(), mu=positive_scalar()),
        dict(inertia="positive3", mu="positive"),
        lambda inertia, mu: torques.GravityGradient(inertia, lambda t: np.array([7.0, 0.0, 0.0]), mu).mu,
    ),
    "EddyCurrent": Entry(
        dict(inertia=moments(), tensor=moments()),
        dict(inertia="positive3", tensor="finite3"),
        lambda inertia, tensor: torques.EddyCurrent(inertia, tensor, lambda t: np.array([0.0, 0.0, 1.0])).tensor,
    ),
    "PDController": Entry(
        dict(inertia=moments(), proportional=moments(), derivative=moments(), target=quaternions()),
        dict(inertia="positive3", proportional="finite3", derivative="finite3", target="quaternion"),
        lambda inertia, proportional, derivative, target: (
            torques.PDController(inertia, proportional, derivative, target=target).proportional
        ),
    ),
    "BDot": Entry(
        dict(inertia=moments(), gain=positive_scalar()),
        dict(inertia="positive3", gain="nonnegative"),
        lambda inertia, gain: torques.BDot(inertia, gain, lambda t: np.array([0.0, 0.0, 1.0])).gain,
    ),
    "SumOfTorques": Entry(
        dict(torques=vectors(3).map(lambda v: [torques.ConstantTorque(v)])),
        dict(torques="nonempty"),
        lambda torques: _sum_of_torques(torques).linear_in_momentum,
        call=lambda result: np.asarray(0.0),
    ),
    "RigidBodySplitting": Entry(
        dict(method=st.sampled_from(sorted(frbjax.SPLITTING_METHODS))),
        dict(method="option"),
        lambda method: frbjax.RigidBodySplitting(method),
        call=lambda result: np.asarray(0.0),
    ),
    "batch_mesh": Entry(
        dict(devices=st.just(jax.devices())),
        dict(devices="nonempty"),
        lambda devices: frbjax.batch_mesh(devices),
        call=lambda result: np.asarray(0.0),
    ),
    "shard_batch": Entry(dict(tree=vectors(4)), dict(tree="batched_tree"), frbjax.shard_batch),
    "shard_bodies": Entry(
        dict(inertia=st.lists(moments(), min_size=2, max_size=2).map(np.array)),
        dict(inertia="batch"),
        lambda inertia: frbjax.shard_bodies(_body(inertia, np.array([0.3, 1.0, -0.2]), None)).momentum_norm,
        named={"inertia": "body"},
    ),
    "facet_brightness": Entry(
        dict(
            normals=unit_vectors(6), sun_body=unit_vectors(5), c=positive_scalar(), law=st.sampled_from(lightcurve.LAWS)
        ),
        dict(c="nonnegative", law="option", sun_body="finite3"),
        lambda normals, sun_body, c, law: lightcurve.facet_brightness(normals, sun_body, sun_body, law=law, c=c),
    ),
    "brightness": Entry(
        dict(inertia=moments(), t=times(), sun=unit_vectors(5), law=st.sampled_from(lightcurve.LAWS)),
        dict(inertia="positive3", t="times", sun="unit_vectors", law="option"),
        lambda inertia, t, sun, law: lightcurve.brightness(
            _body(inertia, np.array([0.3, 1.0, -0.2]), None),
            lightcurve.ConvexShape.ellipsoid(1.0, 0.8, 0.6, 0),
            t,
            sun,
            _OBSERVER,
            law=law,
        ),
        named={"t": "times"},
    ),
    "fit_lightcurve": Entry(
        dict(
            times=times(6),
            brightness=vectors(6, 0.5, 2.0),
            sun=unit_vectors(6),
            periods=st.just(np.array([[1.0, 2.0], [3.0, 4.0]])),
            inertia_range=st.just(np.array([0.3, 0.98])),
            starts_per_period=st.integers(1, 4),
            law=st.sampled_from(lightcurve.LAWS),
        ),
        dict(
            times="times",
            brightness="positive",
            sun="unit_vectors",
            periods="range",
            inertia_range="range",
            starts_per_period="count",
            law="option",
        ),
        _fit_lightcurve,
        call=None,
    ),
}
# Spoilers of the attitude record: its times and quaternions, each named by the message.
FIT_DATA = {
    "times": ("distinct_times", 0),
    "quaternions": ("unit_quaternion", 1),
}
# Which kinds a fit refuses within a record (the fits see rows, not shapes of one vector).
ROW_SPOILERS = {
    "unit_quaternion": ("nan", "inf", "zero", "scaled", "complex"),
    "distinct_times": KINDS["distinct_times"],
}

# What a spoiled argument's message names when it is not the argument itself.
NAMES = {"t": "t", "data": None}

SPECIAL = {
    # name: (function, strategies of in-domain arguments)
    "ellipk": (special.ellipk, (floats(-5.0, 0.99),)),
    "ellipkm1": (special.ellipkm1, (floats(0.01, 5.0),)),
    "ellipe": (special.ellipe, (floats(-5.0, 1.0),)),
    "ellipkinc": (special.ellipkinc, (floats(-3.0, 3.0), floats(-5.0, 0.9))),
    "ellipeinc": (special.ellipkinc, (floats(-3.0, 3.0), floats(-5.0, 0.9))),
    "ellippi": (special.ellippi, (floats(-3.0, 0.9), floats(-5.0, 0.9))),
    "ellippiinc": (special.ellippiinc, (floats(-3.0, 0.9), floats(-1.5, 1.5), floats(-5.0, 0.9))),
    "elliprf": (special.elliprf, (floats(0.0, 5.0), floats(0.1, 5.0), floats(0.1, 5.0))),
    "elliprd": (special.elliprd, (floats(0.0, 5.0), floats(0.1, 5.0), floats(0.1, 5.0))),
    "elliprj": (special.elliprj, (floats(0.1, 5.0), floats(0.1, 5.0), floats(0.1, 5.0), floats(0.1, 5.0))),
    "elliprc": (special.elliprc, (floats(0.0, 5.0), floats(0.1, 5.0))),
    "ellipj": (special.ellipj, (floats(-10.0, 10.0), floats(0.0, 1.0))),
}
# Arguments outside each function's domain: NaN wherever scipy.special gives NaN (the independent
# reference for the functions it has).
OUT_OF_DOMAIN = {
    "ellipk": (2.0,),
    "ellipkm1": (-1.0,),
    "ellipe": (1.5,),
    "elliprf": (-1.0, 1.0, 1.0),
    "elliprd": (-1.0, 1.0, 1.0),
    "elliprc": (-1.0, 0.0),
    "elliprj": (-1.0, 1.0, 1.0, 1.0),
}


def _finite(result):
    leaves = [np.asarray(leaf) for leaf in jax.tree.leaves(result) if np.asarray(leaf).dtype.kind in "fc"]
    return all(np.all(np.isfinite(leaf)) for leaf in leaves)


@pytest.mark.parametrize("name", ENTRIES)
@HARNESS
@given(data=st.data())
def test_entry_point(name, data):
    """Valid arguments give a finite result; one spoiled argument raises a ValueError naming it."""
    entry = ENTRIES[name]
    arguments = {key: data.draw(strategy, label=key) for key, strategy in entry.arguments.items()}
    spoilable = sorted(entry.kinds)
    choice = data.draw(st.sampled_from(([None] if entry.call is not None else []) + spoilable), label="spoil")
    if choice is None:
        assert _finite(entry.call(entry.build(**arguments))), name
        return
    kind = entry.kinds[choice]
    if kind == "fit_data":  # a record: spoil its times or its quaternions
        field = data.draw(st.sampled_from(sorted(FIT_DATA)), label="record field")
        row_kind, position = FIT_DATA[field]
        spoiler = data.draw(st.sampled_from(ROW_SPOILERS[row_kind]), label="how")
        record = list(arguments[choice])
        record[position] = SPOILERS[spoiler](record[position], data.draw)
        arguments[choice] = tuple(record)
        expected = field
    else:
        spoiler = data.draw(st.sampled_from(KINDS[kind]), label="how")
        arguments[choice] = SPOILERS[spoiler](arguments[choice], data.draw)
        expected = entry.named.get(choice, choice)
    with pytest.raises(ValueError) as error:
        entry.build(**arguments)
    message = str(error.value)
    assert re.search(rf"\b{re.escape(expected)}\b", message) or (
        # The fits refuse non-finite samples as rows: the message lists the argument among others.
        expected in message
    ), (name, choice, spoiler, message)


@pytest.mark.parametrize("name", SPECIAL)
@HARNESS
@given(data=st.data())
def test_special_function(name, data):
    """In the domain: finite; outside it: NaN, as scipy.special; arguments that are not real: ValueError."""
    function, strategies = SPECIAL[name]
    arguments = [data.draw(strategy) for strategy in strategies]
    assert _finite(function(*arguments)), (name, arguments)
    if name in OUT_OF_DOMAIN:
        assert np.isnan(getattr(scipy.special, name)(*OUT_OF_DOMAIN[name]))
        assert np.isnan(np.asarray(function(*OUT_OF_DOMAIN[name]))), name
    spoiled = list(arguments)
    spoiled[data.draw(st.integers(0, len(arguments) - 1))] = data.draw(st.sampled_from([1j, "0.5"]))
    with pytest.raises(ValueError, match="real numbers"):
        function(*spoiled)


def test_every_public_callable_is_in_the_harness():
    """A new public function or class has to be added to the harness (or be a result type)."""
    # Result types, constants, namespaces and the base class of torques: nothing to call with data.
    results = {
        "AttitudeFit",
        "LightcurveFit",
        "CompetingBasins",
        "AmbiguousFitWarning",
        "MisfitWarning",
        "TumblerPeriodogram",
        "FitError",
        "SPLITTING_METHODS",
        "LAWS",
        "special",
        "torques",
        "lightcurve",
        "AbstractTorque",
    }
    covered = {name.split(".")[0] for name in ENTRIES} | set(SPECIAL) | results
    public = (
        set(frbjax.__all__)
        | set(lightcurve.__all__)
        | set(special.__all__)
        | set(torques.__all__)
        | {"pad_batch", "batch_mesh", "shard_batch", "shard_bodies"}
    )
    assert public <= covered, sorted(public - covered)
