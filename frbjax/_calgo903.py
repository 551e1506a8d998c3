"""The data files of CALGO 903 (FRB) and the motions that its five example drivers compute.

Algorithm 903 (Celledoni and Zanna, "FRB -- Fortran routines for the exact computation of free rigid
body motions", ACM TOMS 37(2), 2010) ships five example drivers, each reading an ``init_exampleN.dat``
file and writing an ``out_exampleN.dat`` file.  This module reads and writes those layouts and
computes what the drivers compute, with :class:`~frbjax.FreeRigidBody` as the free flow:

========  ==============================================  =======================================
layout    input values, in order                           output records
========  ==============================================  =======================================
example0  h; I(3); Pi(3); Q(9)                             Pi, Q, t at t = 0; Pi, Q after one step
example1  a(8); b(7); h; T; Pi(3); Q(9); I(3); u0(3)       Pi, Q, t after every step (torqued body)
example2  h; I(3); Pi(3); q(4)                             Pi, q, t at t = 0; Pi, q after one step
example3  h; T; Pi(3); Q(9); I(3); NP                      Pi, Q, t after every step
example4  h; T; Pi(3); q(4); I(3); NP                      Pi, q, t after every step
========  ==============================================  =======================================

Conventions of the Fortran code: ``Pi`` is the body-frame angular momentum, ``I`` the principal
moments, ``Q`` the attitude matrix (body to space, ``Q' = Q hat(Omega)``) read and written column by
column, ``q`` its quaternion (scalar first, Hamilton product, ``R(q) = Q``), ``h`` the step, ``T`` the
final time, ``NP`` the order of the "semi-exact" quadrature (ignored here: the motion is exact).
The drivers take ``NSTEPS = INT(T/h)`` steps of ``T/NSTEPS``.  The single-step layouts record no time
in their second record.

Every value is a Fortran list-directed number (``1.0D0``, ``-.5``, ``3``) and values are separated by
blanks, commas or line breaks (the files have one value per line; blank lines are allowed).

The drivers normalise ``Pi`` to unit length and multiply the step by ``|Pi|``: that is the motion of the
given ``Pi`` over the step, which is what :class:`~frbjax.FreeRigidBody` computes directly.  The free
examples (0, 2, 3, 4) evaluate the exact motion at every output time from the initial state in one
vectorised call; example 1 composes the exact free flow with kicks step by step, as the driver does,
through the public splitting integrator (:func:`~frbjax.splitting_trajectory`).
All of it needs 64-bit JAX (``jax.config.update("jax_enable_x64", True)``).
"""

from __future__ import annotations

import dataclasses
import math
import re

import jax
import jax.numpy as jnp
import numpy as np

from . import _quaternion as quaternion
from ._body import FreeRigidBody


__all__ = [
    "LAYOUTS",
    "CalgoFormatError",
    "Layout",
    "Problem",
    "Trajectory",
    "example1_method",
    "example1_program",
    "example1_term",
    "format_output",
    "parse_input",
    "parse_output",
    "read_input",
    "read_output",
    "solve",
    "splitting_trajectory_example1",
]

# Tolerances of the consistency checks on the attitude read from a file (values carry ~15 digits).
ROTATION_TOLERANCE = 1e-6
# T/h within this relative distance of an integer counts as that integer (INT(2.9999999999999996) = 2).
STEPS_TOLERANCE = 1e-9


# ------------------------------------------------------------------------------------------ layouts


@dataclasses.dataclass(frozen=True)
class Field:
    """A named group of consecutive values in an input file."""

    name: str
    size: int = 1

    def label(self, index):
        """Fortran-style name of value ``index`` (0-based) of the field: ``h``, ``Pi(2)``, ``Q(1,3)``."""
        if self.size == 1:
            return self.name
        if self.name == "Q":
            return f"Q({index % 3 + 1},{index // 3 + 1})"
        return f"{self.name}({index + 1})"

    def summary(self):
        """``Q(9, column-wise)``-style summary used in messages."""
        if self.size == 1:
            return self.name
        return f"{self.name}({self.size}, column-wise)" if self.name == "Q" else f"{self.name}({self.size})"


_H, _T, _I, _PI, _NP = Field("h"), Field("T"), Field("I", 3), Field("Pi", 3), Field("NP")
_QM, _QQ = Field("Q", 9), Field("q", 4)
_A, _B, _U0 = Field("a", 8), Field("b", 7), Field("u0", 3)


@dataclasses.dataclass(frozen=True)
class Layout:
    """One of the five CALGO 903 example layouts.

    ``fields`` is the input layout; ``attitude`` is ``"Q"`` (a matrix) or ``"q"`` (a quaternion) in both
    input and output; ``single_step`` marks examples 0 and 2 (one step of ``h``, no time recorded
    in the second output record).
    """

    name: str
    fields: tuple[Field, ...]
    attitude: str
    single_step: bool

    @property
    def size(self):
        """Number of values of an input file."""
        return sum(field.size for field in self.fields)

    @property
    def record_size(self):
        """Number of values of one output record (with its time)."""
        return 3 + (9 if self.attitude == "Q" else 4) + 1

    def summary(self):
        """``h; I(3); Pi(3); Q(9, column-wise)``."""
        return "; ".join(field.summary() for field in self.fields)

    def labels(self):
        """Name of every input value, in file order."""
        return [field.label(i) for field in self.fields for i in range(field.size)]

    def output_size(self, records):
        """Number of values of an output file with ``records`` records."""
        return records * self.record_size - (1 if self.single_step else 0)


LAYOUTS = {
    layout.name: layout
    for layout in (
        Layout("example0", (_H, _I, _PI, _QM), "Q", single_step=True),
        Layout("example1", (_A, _B, _H, _T, _PI, _QM, _I, _U0), "Q", single_step=False),
        Layout("example2", (_H, _I, _PI, _QQ), "q", single_step=True),
        Layout("example3", (_H, _T, _PI, _QM, _I, _NP), "Q", single_step=False),
        Layout("example4", (_H, _T, _PI, _QQ, _I, _NP), "q", single_step=False),
    )
}


class CalgoFormatError(ValueError):
    """A file that does not hold a CALGO 903 layout: ``str()`` names the file, the line and the problem."""

    def __init__(self, path, line, message):
        self.path = str(path)
        self.line = line
        self.message = message
        where = f"{self.path}, line {line}" if line is not None else self.path
        super().__init__(f"{where}: {message}")


# ------------------------------------------------------------------------------------------ numbers

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[EeDd][+-]?\d+)?")
_SEPARATORS = re.compile(r"[\s,]+")


def _tokens(text):
    """(token, line number) of every blank- or comma-separated value of a text."""
    found = []
    for number, line in enumerate(text.splitlines(), start=1):
        found.extend((token, number) for token in _SEPARATORS.split(line) if token)
    return found


def parse_number(token):
    """Value of a Fortran list-directed real (``1.0D0``, ``-.5``, ``3``); ``None`` if it is not one."""
    if not _NUMBER.fullmatch(token):
        return None
    return float(token.replace("D", "E").replace("d", "e"))


def format_number(value):
    """A double in Fortran E format with 17 significant digits (reads back to the same double)."""
    return f"{value:25.16E}"


# --------------------------------------------------------------------------------------- input files


@dataclasses.dataclass(frozen=True)
class Problem:
    """The contents of an input file: ``values[name]`` is a float64 array per field (shape (size,)).

    ``lines[name]`` is the line of each value, for messages about a field as a whole.
    """

    layout: Layout
    values: dict
    lines: dict
    path: str

    def __getitem__(self, name):
        value = self.values[name]
        return float(value[0]) if value.shape == (1,) else value

    @property
    def steps(self):
        """Number of steps the driver takes: 1 for the single-step layouts, else INT(T/h)."""
        if self.layout.single_step:
            return 1
        return _count_steps(self["T"], self["h"])

    @property
    def step(self):
        """The step the driver takes: h, or T/NSTEPS (the drivers re-adjust h to fit T)."""
        return self["h"] if self.layout.single_step else self["T"] / self.steps

    def initial_state(self):
        """(Pi, q) at t = 0, with q the unit quaternion of the attitude as given."""
        if self.layout.attitude == "Q":
            matrix = self["Q"].reshape(3, 3).T
            return self["Pi"], np.asarray(quaternion.from_matrix(jnp.asarray(matrix)))
        q = self["q"]
        return self["Pi"], q / np.linalg.norm(q)


def _count_steps(final_time, step):
    ratio = final_time / step
    nearest = round(ratio)
    if abs(ratio - nearest) <= STEPS_TOLERANCE * max(1.0, abs(ratio)):
        return int(nearest)
    return int(ratio)


def detect_layout(count):
    """The layout with ``count`` input values, or ``None``."""
    matches = [layout for layout in LAYOUTS.values() if layout.size == count]
    return matches[0] if matches else None


def _layouts_by_size():
    return ", ".join(f"{layout.size} ({layout.name})" for layout in sorted(LAYOUTS.values(), key=lambda x: x.size))


def parse_input(text, path="<input>", layout=None):
    """Read the text of an ``init_exampleN.dat`` file into a :class:`Problem`.

    ``layout`` (a name such as ``"example3"`` or a :class:`Layout`) forces the layout; by default it
    is detected from the number of values, which differs between the five layouts.  Raises
    :class:`CalgoFormatError` naming the line and what was expected there.
    """
    tokens = _tokens(text)
    if isinstance(layout, str):
        if layout not in LAYOUTS:
            raise ValueError(f"unknown layout {layout!r}; expected one of {', '.join(LAYOUTS)}")
        layout = LAYOUTS[layout]
    if layout is None:
        layout = detect_layout(len(tokens))
        if layout is None:
            _raise_undetected(tokens, path)

    labels = layout.labels()
    if len(tokens) > layout.size:
        token, line = tokens[layout.size]
        raise CalgoFormatError(
            path,
            line,
            f"unexpected value {token!r} after the {layout.size} values of layout {layout.name} ({layout.summary()})",
        )
    numbers = []
    for index, (token, line) in enumerate(tokens):
        value = parse_number(token)
        if value is None or not math.isfinite(value):
            raise CalgoFormatError(
                path,
                line,
                f"expected a number for {labels[index]} (value {index + 1} of "
                f"{layout.size} of layout {layout.name}: {layout.summary()}), found {token!r}",
            )
        numbers.append(value)
    if len(tokens) < layout.size:
        missing = labels[len(tokens)]
        line = tokens[-1][1] + 1 if tokens else 1
        raise CalgoFormatError(
            path,
            line,
            f"end of file after {len(tokens)} values: expected {missing} (value "
            f"{len(tokens) + 1} of {layout.size} of layout {layout.name}: {layout.summary()})",
        )

    values, lines, start = {}, {}, 0
    for field in layout.fields:
        values[field.name] = np.array(numbers[start : start + field.size], dtype=np.float64)
        lines[field.name] = tuple(line for _, line in tokens[start : start + field.size])
        start += field.size
    problem = Problem(layout, values, lines, str(path))
    _check(problem)
    return problem


def _raise_undetected(tokens, path):
    for token, line in tokens:
        if parse_number(token) is None:
            raise CalgoFormatError(path, line, f"expected a number, found {token!r}")
    if not tokens:
        raise CalgoFormatError(
            path, 1, f"empty file: expected a CALGO 903 input file, which holds {_layouts_by_size()} values"
        )
    closest = min(LAYOUTS.values(), key=lambda layout: (abs(layout.size - len(tokens)), layout.size))
    difference = closest.size - len(tokens)
    plural = "s" if abs(difference) != 1 else ""
    raise CalgoFormatError(
        path,
        tokens[-1][1],
        f"the file ends here after {len(tokens)} values, but a CALGO 903 input "
        f"file holds {_layouts_by_size()} values; the closest layout, {closest.name} ({closest.summary()}), "
        f"has {abs(difference)} value{plural} {'more' if difference > 0 else 'fewer'}: force it "
        f"(--layout {closest.name}) to locate the line at fault",
    )


def _check(problem):
    """Checks that the Fortran drivers leave to the user; raise CalgoFormatError on failure."""
    path, lines = problem.path, problem.lines
    inertia = problem["I"]
    for k in range(3):
        if inertia[k] <= 0:
            raise CalgoFormatError(
                path,
                lines["I"][k],
                f"expected a positive moment of inertia for I({k + 1}), found {float(inertia[k])!r}",
            )
    if problem.layout.attitude == "Q":
        matrix = problem["Q"].reshape(3, 3).T
        defect = np.abs(matrix.T @ matrix - np.eye(3)).max()
        if defect > ROTATION_TOLERANCE or np.linalg.det(matrix) <= 0:
            raise CalgoFormatError(
                path,
                lines["Q"][0],
                f"expected Q(1,1)..Q(3,3) (lines {lines['Q'][0]}-{lines['Q'][-1]}) "
                f"to be a rotation matrix, column by column; found |Q'Q - 1| = {defect:.2e}, "
                f"det Q = {np.linalg.det(matrix):.6g}",
            )
    else:
        norm = float(np.linalg.norm(problem["q"]))
        if abs(norm - 1) > ROTATION_TOLERANCE:
            raise CalgoFormatError(
                path,
                lines["q"][0],
                f"expected q(1)..q(4) (lines {lines['q'][0]}-{lines['q'][-1]}) "
                f"to be a unit quaternion, found |q| = {norm!r}",
            )
    if "NP" in problem.values:
        order = problem["NP"]
        if order != int(order) or not 0 <= order <= 10:
            raise CalgoFormatError(path, lines["NP"][0], f"expected NP, an integer from 0 to 10, found {order!r}")
    if not problem.layout.single_step:
        step, final_time = problem["h"], problem["T"]
        if step == 0 or final_time / step < 1 - STEPS_TOLERANCE:
            raise CalgoFormatError(
                path, lines["T"][0], f"expected T/h >= 1 (at least one step), found h = {step!r}, T = {final_time!r}"
            )


def read_input(path, layout=None):
    """:func:`parse_input` of the file at ``path``."""
    with open(path, encoding="utf-8", errors="replace") as file:
        return parse_input(file.read(), path, layout)


# -------------------------------------------------------------------------------------- output files


@dataclasses.dataclass(frozen=True)
class Trajectory:
    """Output records: ``momentum`` (n, 3), ``attitude`` (n, 3, 3) or (n, 4), ``time`` (n,).

    ``attitude`` is the matrix Q (``x_space = Q x_body``) or the quaternion q, as the layout has it.
    The single-step layouts record no time in their second record: ``time[1]`` is NaN when read back.
    """

    momentum: np.ndarray
    attitude: np.ndarray
    time: np.ndarray


def format_output(layout, trajectory):
    """Text of an ``out_exampleN.dat`` file: one value per line, in the layout's order."""
    layout = LAYOUTS[layout] if isinstance(layout, str) else layout
    lines = []
    records = len(trajectory.time)
    for n in range(records):
        attitude = np.asarray(trajectory.attitude[n])
        if layout.attitude == "Q":
            attitude = attitude.T  # column by column
        record = [*trajectory.momentum[n], *attitude.ravel()]
        if not (layout.single_step and n == records - 1):
            record.append(trajectory.time[n])
        lines.extend(format_number(float(value)) for value in record)
    return "\n".join(lines) + "\n"


def parse_output(text, layout, path="<output>"):
    """Read the text of an ``out_exampleN.dat`` file (``layout`` is required) into a :class:`Trajectory`."""
    layout = LAYOUTS[layout] if isinstance(layout, str) else layout
    tokens = _tokens(text)
    numbers = []
    for token, line in tokens:
        value = parse_number(token)
        if value is None:
            raise CalgoFormatError(path, line, f"expected a number, found {token!r}")
        numbers.append(value)
    size = layout.record_size
    count = len(numbers) + (1 if layout.single_step else 0)
    if count % size or (layout.single_step and count != 2 * size) or not count:
        expected = f"{layout.output_size(2)}" if layout.single_step else f"a positive multiple of {size}"
        raise CalgoFormatError(
            path,
            tokens[-1][1] if tokens else None,
            f"{len(numbers)} values, expected {expected} for layout {layout.name}",
        )
    if layout.single_step:
        numbers.append(math.nan)
    table = np.array(numbers, dtype=np.float64).reshape(-1, size)
    attitude = table[:, 3:-1]
    if layout.attitude == "Q":
        attitude = attitude.reshape(-1, 3, 3).transpose(0, 2, 1)
    return Trajectory(table[:, :3], attitude, table[:, -1])


def read_output(path, layout):
    """:func:`parse_output` of the file at ``path``."""
    with open(path, encoding="utf-8", errors="replace") as file:
        return parse_output(file.read(), layout, path)


# ------------------------------------------------------------------------------------------- motions


def _require_x64():
    if not jax.config.jax_enable_x64:
        raise RuntimeError(
            'the CALGO 903 examples need 64-bit JAX: call jax.config.update("jax_enable_x64", True) first'
        )


def _exact_motion(inertia, momentum, attitude, times):
    """L and q of the free body at ``times``, eagerly: the whole program takes far longer to compile."""
    body = FreeRigidBody(inertia, momentum, attitude)
    return body.angular_momentum(times), body.quaternion(times)


def _stage_coefficients(a, b):
    """(kick, flow) coefficients of the 15 stages of one palindromic step a1 b1 ... a8 ... b1 a1.

    Stage k kicks by kick_k h and then flows by flow_k h; the first stage has no kick (kick 0).
    """
    kicks = np.concatenate([[0.0], b, b[::-1]])
    flows = np.concatenate([a, a[-2::-1]])
    return kicks, flows


def example1_term(problem):
    """The torqued body of example 1 as a :class:`~frbjax.RigidBodyTerm`, with ``args = u0``.

    The driver's kick adds b h (u2, -u1, 0) to Pi with u = Q^T u0: the torque u x e3 of the potential
    V(Q) = u0 . Q e3 (a heavy top with its centre of mass on the third body axis and u0 the weight).
    """
    from ._splitting import RigidBodyTerm

    return RigidBodyTerm(problem["I"], potential=_example1_potential)


def _example1_potential(t, attitude, u0):
    return jnp.dot(u0, quaternion.as_matrix(attitude)[:, 2])


def example1_method(problem):
    """The file's splitting a1 b1 ... a8 ... b1 a1 as a :class:`~frbjax.RigidBodySplitting`."""
    from ._splitting import RigidBodySplitting

    kicks, flows = _stage_coefficients(problem["a"], problem["b"])
    return RigidBodySplitting(kicks=(*kicks, 0.0), flows=flows, order=6)


def example1_program(problem, steps):
    """A compiled function (Pi, q) -> the states (Pi, q) at the ``steps + 1`` step times.

    The body, step and u0 of the file are constants of the program (it serves this one problem).
    """
    from ._splitting import splitting_trajectory

    term, method = example1_term(problem), example1_method(problem)
    step, u0 = problem.step, jnp.asarray(problem["u0"])

    def states(momentum, attitude):
        _, states = splitting_trajectory(term, (momentum, attitude), dt=step, steps=steps, args=u0, method=method)
        return states

    return jax.jit(states)


def splitting_trajectory_example1(problem, steps=None):
    """Example 1: the torqued body by the Blanes-Moan splitting, ``steps`` steps (default: all).

    One step of size h is the palindrome a1 b1 a2 b2 ... a7 b7 a8 b7 a7 ... b2 a2 b1 a1: 15 exact free
    flows and 14 kicks, which leave the attitude alone and add b_i h (u2, -u1, 0) to Pi, with
    u = Q^T u0.  It runs through the public API: :func:`~frbjax.splitting_trajectory` with
    :func:`example1_term` and :func:`example1_method` (:func:`example1_program`).
    """
    _require_x64()
    steps = problem.steps if steps is None else steps
    momentum, attitude = problem.initial_state()
    momenta, attitudes = example1_program(problem, steps)(momentum, attitude)
    return _trajectory(problem, np.asarray(momenta)[1:], np.asarray(attitudes)[1:], steps)


def _trajectory(problem, momenta, attitudes, steps):
    """Records at t = 0 (the input as given, like the drivers) and after each step."""
    initial = problem["Q"].reshape(3, 3).T if problem.layout.attitude == "Q" else problem["q"]
    if problem.layout.attitude == "Q":
        attitudes = np.asarray(quaternion.as_matrix(jnp.asarray(attitudes)))
    momentum = np.concatenate([problem["Pi"][None], momenta])
    attitude = np.concatenate([initial[None], attitudes])
    time = np.arange(steps + 1) * problem.step
    return Trajectory(momentum, attitude, time)


def solve(problem, steps=None):
    """The driver's output records for a :class:`Problem`, as a :class:`Trajectory`.

    Free examples: the exact motion at t = n h for n = 0..NSTEPS (one step for examples 0 and 2),
    evaluated from the initial state; ``NP`` is ignored.  Example 1: :func:`splitting_trajectory_example1`.
    ``steps`` limits the number of steps (default: what the driver takes).
    """
    _require_x64()
    if problem.layout.name == "example1":
        return splitting_trajectory_example1(problem, steps)
    steps = problem.steps if steps is None else steps
    momentum, attitude = problem.initial_state()
    times = np.arange(1, steps + 1) * problem.step
    momenta, attitudes = _exact_motion(problem["I"], momentum, attitude, times)
    return _trajectory(problem, np.asarray(momenta), np.asarray(attitudes), steps)
