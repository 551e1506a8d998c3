"""The ``frbjax`` command: ``frbjax run`` (CALGO 903 example files) and ``frbjax demo`` (tennis racket).

``frbjax run FILE [-o OUT]`` reads the input file of any of the five example drivers of CALGO 903
(Celledoni and Zanna, ACM TOMS 37(2), 2010) and writes what the driver writes, computed with the exact
motion of `frbjax.FreeRigidBody`.  ``frbjax demo`` shows the Dzhanibekov effect: a T-handle spun
almost about its middle axis flips over and over, with the period $4K(m)/B$ predicted by the complete
elliptic integral $K$; it plots $L(t)$ and $q(t)$ and animates the tumbling body (`FlipAnimation`).

This is an application, not the library: it enables 64-bit JAX and a persistent compilation cache.
It leaves XLA's flags alone: on the CPU the free flows of the splitting steps run in the package's
compiled kernels (``FRBJAX_KERNELS=jax`` runs the JAX formulas instead).  JAX and matplotlib are
imported when a command needs them, so that ``--help`` answers at once.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from typing import TextIO, TYPE_CHECKING

import numpy as np


if TYPE_CHECKING:
    from ._body import FreeRigidBody

PROGRAM = "frbjax"
DEFAULT_DEMO_PATH = "frbjax_demo.png"
ANIMATION_SUFFIXES = (".gif", ".mp4")

_RUN_DESCRIPTION = """\
Run one of the five example drivers of CALGO 903 (FRB, Celledoni & Zanna 2010) on its input file
and write what the driver writes, one value per line, with the exact motion of frbjax.

Input layouts (values in order, Fortran list-directed numbers such as 1.0D0, one per line):
  example0  h; I(3); Pi(3); Q(9)                        one free step, attitude matrix
  example1  a(8); b(7); h; T; Pi(3); Q(9); I(3); u0(3)  torqued body by Blanes-Moan splitting
  example2  h; I(3); Pi(3); q(4)                        one free step, quaternion
  example3  h; T; Pi(3); Q(9); I(3); NP                 free steps to T, attitude matrix
  example4  h; T; Pi(3); q(4); I(3); NP                 free steps to T, quaternion
Pi is the body angular momentum, I the principal moments, Q the attitude matrix (body to space)
column by column, q its quaternion (scalar first).  The layout is detected from the number of values.

Output (the layout of out_exampleN.dat): records Pi, Q or q, t at t = 0 and after every step
(examples 0 and 2: one step, no time in the second record).  The drivers take NSTEPS = INT(T/h)
steps of T/NSTEPS; so does this command.

NP, the order of the Fortran code's "semi-exact" quadrature (examples 3 and 4), is ignored: frbjax
always computes the exact motion (a note on stderr says so).  Example 1 composes the exact free flow
with kicks, 15 flows a step: its 10,000 steps (150,000 free flows) take a few seconds on one CPU
core, compiling included (see FRBJAX_CACHE_DIR); --steps N runs fewer.

A malformed file is reported with its line and what was expected there (exit status 2); no output
file is written then."""

_DEMO_DESCRIPTION = """\
The tennis racket theorem (Dzhanibekov effect) with the exact motion: a T-handle with principal
moments I = (1, 2, 3) spun almost exactly about its middle axis, L(0) = (0.001, 1, 0.001)/|.|.
Prints its state at a few times, the period 4K/B of the flips from the complete elliptic integral K
(frbjax.special.ellipk) next to the period observed in L(t), plots L(t) and q(t) to a PNG, and
animates the tumbling T-handle over one period of L(t) (a flip and a flip back: its body axes and
the angular momentum, fixed in space) to a GIF next to the plot, or an MP4 where ffmpeg exists.
The plot and the animation need matplotlib: pip install 'frbjax[demo]'; without it the demo
prints and says so."""

_EPILOG = """\
environment:
  FRBJAX_CACHE_DIR  where compiled XLA programs are kept between runs (default:
                    $XDG_CACHE_HOME/frbjax or ~/.cache/frbjax; empty: no cache).  JAX's own
                    JAX_COMPILATION_CACHE_DIR takes precedence.
  FRBJAX_KERNELS    jax: the motion as JAX formulas compiled by XLA instead of the
                    package's compiled kernels on the CPU (for comparison)."""


# --------------------------------------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    """The argparse parser of the ``frbjax`` command and its subcommands."""
    parser = argparse.ArgumentParser(
        prog=PROGRAM,
        description="Exact motion of the torque-free rigid body (frbjax, JAX).",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    run = commands.add_parser(
        "run",
        help="run a CALGO 903 example input file with the exact motion",
        description=_RUN_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    run.add_argument("file", metavar="FILE", help="input file in one of the layouts above")
    run.add_argument(
        "-o", "--output", metavar="OUT", help="output file (default: standard output); written whole or not at all"
    )
    run.add_argument(
        "--layout",
        choices=["example0", "example1", "example2", "example3", "example4"],
        help="read FILE in this layout instead of detecting it from the number of values",
    )
    run.add_argument(
        "--steps",
        type=_non_negative_int,
        metavar="N",
        help="take N steps (examples 1, 3 and 4; default: INT(T/h), as the drivers)",
    )
    run.set_defaults(handler=_run)

    demo = commands.add_parser(
        "demo",
        help="the Dzhanibekov effect: a flipping T-handle, table and plot",
        description=_DEMO_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    demo.add_argument(
        "--out", metavar="PNG", default=DEFAULT_DEMO_PATH, help=f"where to save the plot (default: {DEFAULT_DEMO_PATH})"
    )
    demo.add_argument(
        "--animation",
        metavar="PATH",
        help="where to save the animation: .gif (Pillow, always available) or .mp4 "
        "(needs ffmpeg) (default: the plot's name with .gif)",
    )
    demo.add_argument("--no-animation", dest="animate", action="store_false", help="plot only, no animation")
    demo.add_argument(
        "--quick",
        action="store_true",
        help="fewer sample times, a smaller image and a short, small animation (for tests)",
    )
    demo.set_defaults(handler=_demo)
    return parser


def _non_negative_int(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, found {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a number of steps >= 0, found {value}")
    return value


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``frbjax`` console script; returns the exit status.

    ``argv`` are the arguments after the program name (default: ``sys.argv[1:]``), e.g.
    ``main(["demo", "--quick"])``.  0 is success, 2 a usage or input error, 1 an output that could
    not be written.
    """
    args = build_parser().parse_args(argv)
    return args.handler(args)


# ----------------------------------------------------------------------------------------- utilities


def _configure_jax():
    """64-bit JAX and a persistent compilation cache unless one is set already or disabled."""
    import jax

    jax.config.update("jax_enable_x64", True)
    if jax.config.jax_compilation_cache_dir is not None:
        return
    default = os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), PROGRAM)
    directory = os.environ.get("FRBJAX_CACHE_DIR", default)
    if directory:
        jax.config.update("jax_compilation_cache_dir", directory)
        # The eager evaluations compile many small programs: keep those too.
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)


def _error(command, message, status=2):
    print(f"{PROGRAM} {command}: error: {message}", file=sys.stderr)
    return status


def _note(command, message):
    print(f"{PROGRAM} {command}: note: {message}", file=sys.stderr)


def write_atomically(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file in the same folder, renamed at the end.

    Readers never see a partial file, and a failure leaves no file behind (nor changes an old one).
    """
    folder = os.path.dirname(os.path.abspath(path))
    descriptor, temporary = tempfile.mkstemp(dir=folder, prefix=f".{os.path.basename(path)}.", suffix=".tmp")
    try:
        with os.fdopen(descriptor, "w", encoding="utf-8") as file:
            file.write(text)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)
        os.replace(temporary, path)
    except BaseException:
        os.unlink(temporary)
        raise


# ---------------------------------------------------------------------------------------------- run


def _run(args):
    from . import _calgo903 as calgo

    try:
        with open(args.file, encoding="utf-8", errors="replace") as file:
            text = file.read()
    except OSError as error:
        return _error("run", f"cannot read {args.file}: {error.strerror}")
    try:
        problem = calgo.parse_input(text, args.file, args.layout)
    except calgo.CalgoFormatError as error:
        return _error("run", str(error))
    layout = problem.layout
    if args.steps is not None and layout.single_step:
        return _error("run", f"--steps applies to examples 1, 3 and 4; {args.file} is {layout.name}, a single step")
    if args.output is not None:
        if os.path.isdir(args.output):
            return _error("run", f"{args.output} is a folder; expected an output file name")
        folder = os.path.dirname(os.path.abspath(args.output))
        if not os.path.isdir(folder):
            return _error("run", f"cannot write {args.output}: no folder {folder}")

    if "NP" in problem.values:
        _note(
            "run",
            f"NP = {int(problem['NP'])} (order of the semi-exact quadrature) is ignored: "
            "frbjax computes the exact motion",
        )
    if not layout.single_step and problem.step != problem["h"]:
        _note(
            "run",
            f"h = {problem['h']!r} does not divide T = {problem['T']!r}; the step is "
            f"T/INT(T/h) = {problem.step!r}, as in the driver",
        )
    steps = problem.steps if args.steps is None else args.steps
    if layout.name == "example1":
        _note("run", f"{steps} steps of the splitting, 15 exact free flows each (seconds, most of it compiling)")

    _configure_jax()
    trajectory = calgo.solve(problem, None if layout.single_step else steps)
    output = calgo.format_output(layout, trajectory)
    if args.output is None:
        sys.stdout.write(output)
        return 0
    try:
        write_atomically(args.output, output)
    except OSError as error:
        return _error("run", f"cannot write {args.output}: {error.strerror}", status=1)
    return 0


# --------------------------------------------------------------------------------------------- demo

DEMO_INERTIA = (1.0, 2.0, 3.0)
DEMO_MOMENTUM = (1e-3, 1.0, 1e-3)
MATPLOTLIB_HINT = "pip install 'frbjax[demo]' adds it"


def flip_period(inertia: tuple[float, float, float], angular_momentum: np.ndarray) -> float:
    r"""Period $4K(m)/(B |L|)$ of $L(t)$ for a body with sorted moments $I_1 < I_2 < I_3$ rotating about $I_1$.

    That is the regime $d = 2E/|L|^2 > 1/I_2$ (just above the separatrix: the minor axis side), with

    $$B = \sqrt{\frac{(d I_3 - 1)(I_2 - I_1)}{I_1 I_2 I_3}}, \qquad
      m = \frac{(1 - d I_1)(I_3 - I_2)}{(d I_3 - 1)(I_2 - I_1)}.$$

    Next to the separatrix $m$ is close to 1, so its complement is formed without cancellation,
    $1 - m = (I_3 - I_1)(d I_2 - 1)/((d I_3 - 1)(I_2 - I_1))$, with
    $d I_2 - 1 = l_1^2 (I_2 - I_1)/I_1 - l_3^2 (I_3 - I_2)/I_3$ ($l = L/|L|$).
    """
    from .special import ellipk

    i1, i2, i3 = inertia
    norm = float(np.linalg.norm(angular_momentum))
    l1, l2, l3 = np.asarray(angular_momentum) / norm
    g1 = l2**2 * (i2 - i1) / i2 + l3**2 * (i3 - i1) / i3  # 1 - d I1
    g2 = l1**2 * (i2 - i1) / i1 - l3**2 * (i3 - i2) / i3  # d I2 - 1
    g3 = l1**2 * (i3 - i1) / i1 + l2**2 * (i3 - i2) / i2  # d I3 - 1
    if not (i1 < i2 < i3 and g2 > 0):
        raise ValueError("expected I1 < I2 < I3 and rotation about the I1 axis (d > 1/I2)")
    b = np.sqrt(g3 * (i2 - i1) / (i1 * i2 * i3))
    m = g1 * (i3 - i2) / (g3 * (i2 - i1))
    mc = (i3 - i1) * g2 / (g3 * (i2 - i1))
    return 4 * float(ellipk(m, mc=mc)) / (b * norm)


def _crossings(body, times, momentum):
    """Times at which L2(t) changes sign, refined by Newton's method (dL2/dt = L3 Omega1 - L1 Omega3).

    Returns (upward, downward) crossing times, each sorted.  Every evaluation uses an array of the
    shape of ``times`` (the roots padded with sample times): eagerly, each new shape costs compilations.
    """
    l2 = momentum[:, 1]
    upward = np.flatnonzero((l2[:-1] < 0) & (l2[1:] >= 0))
    downward = np.flatnonzero((l2[:-1] > 0) & (l2[1:] <= 0))
    index = np.concatenate([upward, downward])
    fraction = l2[index] / (l2[index] - l2[index + 1])
    roots = times[index] + fraction * (times[index + 1] - times[index])
    inertia = np.asarray(body.inertia)
    for _ in range(4):
        padded = np.concatenate([roots, times[len(roots) :]])
        moment = np.asarray(body.angular_momentum(padded))[: len(roots)]
        velocity = moment / inertia
        slope = moment[:, 2] * velocity[:, 0] - moment[:, 0] * velocity[:, 2]
        roots = roots - moment[:, 1] / slope
    return np.sort(roots[: len(upward)]), np.sort(roots[len(upward) :])


def run_demo(
    out: str | os.PathLike = DEFAULT_DEMO_PATH,
    quick: bool = False,
    stream: TextIO | None = None,
    animation: bool | str | os.PathLike = True,
) -> dict:
    """The demo: print the table and the periods to ``stream`` (stdout), save the plot to ``out``
    and the animation of the tumbling T-handle (`FlipAnimation`) to ``animation``.

    ``animation`` is a path (``.gif``, or ``.mp4`` where ffmpeg exists), ``True`` for the plot's path
    with ``.gif`` (``frbjax_demo.gif``), or ``False`` for none.  ``quick`` makes everything small and
    short (for tests).  Without matplotlib (not a dependency of the library: the ``demo`` extra) the
    plot and the animation are left out and the demo says so.

    Returns a dict with the predicted and observed periods, the sampled motion and, when one was
    saved, the animation (``"animation"``: the `FlipAnimation`, its figure closed).
    """
    _configure_jax()
    from ._body import FreeRigidBody
    from ._quaternion import as_matrix

    stream = sys.stdout if stream is None else stream
    inertia = np.array(DEMO_INERTIA)
    momentum0 = np.array(DEMO_MOMENTUM) / np.linalg.norm(DEMO_MOMENTUM)
    body = FreeRigidBody(inertia, momentum0)
    period = flip_period(inertia, momentum0)

    span = 2.5 * period
    times = np.linspace(0.0, span, 801 if quick else 4001)
    momentum = np.asarray(body.angular_momentum(times))
    attitude = np.asarray(body.quaternion(times))
    upward, downward = _crossings(body, times, momentum)
    observed = float(np.mean(np.diff(upward)))
    flips = np.sort(np.concatenate([upward, downward]))

    energy = 0.5 * np.sum(momentum**2 / inertia, axis=-1)
    spatial = np.einsum("nij,nj->ni", np.asarray(as_matrix(attitude)), momentum)

    print("Dzhanibekov effect: a T-handle with I = (1, 2, 3) spun about its middle axis,", file=stream)
    print(f"L(0) = ({momentum0[0]:.3e}, {momentum0[1]:.9f}, {momentum0[2]:.3e}), |L| = 1.\n", file=stream)
    print(f"{'t':>8} {'L1':>10} {'L2':>10} {'L3':>10}   {'q0':>9} {'q1':>9} {'q2':>9} {'q3':>9}", file=stream)
    rows = slice(None, None, (len(times) - 1) // 10)  # 11 rows, on the sample grid
    for t, l, q in zip(times[rows], momentum[rows], attitude[rows]):
        print(
            f"{t:8.2f} {l[0]:10.6f} {l[1]:10.6f} {l[2]:10.6f}   {q[0]:9.5f} {q[1]:9.5f} {q[2]:9.5f} {q[3]:9.5f}",
            file=stream,
        )
    print(f"\nflips (L2 changes sign) at t = {', '.join(f'{t:.3f}' for t in flips)}", file=stream)
    print(f"period of L(t), a flip and a flip back, 4K(m)/B = {period:.12f}", file=stream)
    print(
        f"observed: L2 rises through 0 every            {observed:.12f}   "
        f"(relative difference {abs(observed - period) / period:.1e})",
        file=stream,
    )
    print(
        f"drift of |L|, E and the spatial L over the run: {np.ptp(np.linalg.norm(momentum, axis=-1)):.1e}, "
        f"{np.ptp(energy):.1e}, {np.abs(spatial - spatial[0]).max():.1e}",
        file=stream,
    )

    result = {
        "period": period,
        "observed_period": observed,
        "flips": flips,
        "times": times,
        "angular_momentum": momentum,
        "quaternion": attitude,
    }
    try:
        import matplotlib
    except ImportError:
        # The library does not need matplotlib; the plot is the demo's only use of it.
        print(f"\nno plot: matplotlib is not installed ({MATPLOTLIB_HINT}); no animation either", file=stream)
        return result
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(10, 6.5), constrained_layout=True)
    colours = ("tab:blue", "tab:orange", "tab:green", "tab:red")
    for k in range(3):
        top.plot(times, momentum[:, k], color=colours[k], lw=1.6, label=f"$L_{k + 1}$")
    for k in range(4):
        bottom.plot(times, attitude[:, k], color=colours[k], lw=1.3, label=f"$q_{k}$")
    for axis in (top, bottom):
        for index, t in enumerate(flips):
            axis.axvline(t, color="0.55", ls=":", lw=1, label="flip" if index == 0 else None)
        axis.grid(True, alpha=0.3)
        axis.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    if len(upward) >= 2:
        top.annotate("", xy=(upward[1], 1.12), xytext=(upward[0], 1.12), arrowprops=dict(arrowstyle="<->", color="0.2"))
        top.text((upward[0] + upward[1]) / 2, 1.16, f"$4K/B = {period:.3f}$", ha="center", va="bottom")
    top.set_ylim(-1.2, 1.35)
    top.set_ylabel("body angular momentum")
    top.set_title("Body-frame angular momentum $L(t)$: $L_2$ switches sign at every flip")
    bottom.set_ylabel("quaternion")
    bottom.set_xlabel("time $t$ (units of $I_1/|L|$)")
    bottom.set_title("Attitude $q(t)$ (body to space)")
    figure.suptitle(
        "Tennis racket theorem: exact motion of a T-handle, $I = (1, 2, 3)$, spun about the middle axis", fontsize=13
    )
    figure.savefig(out, dpi=80 if quick else 150)
    plt.close(figure)
    print(f"\nplot saved to {out}", file=stream)

    path = animation_path(out, animation)
    if path is not None:
        frames = FlipAnimation(body, np.linspace(0.0, period, 24 if quick else 180), quick=quick)
        frames.save(path)
        result["animation"] = frames
        print(
            f"animation ({len(frames.times)} frames, one period of L: a flip and a flip back) saved to {path}",
            file=stream,
        )
    return result


def animation_path(out, animation):
    """Where ``run_demo`` saves the animation: ``None`` for none, the plot's name with .gif for True."""
    if animation is False or animation is None:
        return None
    if animation is True:
        return os.path.splitext(os.fspath(out))[0] + ".gif"
    return os.fspath(animation)


def _demo(args):
    animation = args.animation if args.animation is not None else args.animate
    if args.animation is not None and not args.animate:
        return _error("demo", "--animation and --no-animation exclude each other")
    paths = [args.out]
    target = animation_path(args.out, animation)
    if target is not None:
        if os.path.splitext(target)[1].lower() not in ANIMATION_SUFFIXES:
            return _error("demo", f"cannot save the animation as {target}: expected a .gif or .mp4 file")
        if target.lower().endswith(".mp4") and not _ffmpeg_available():
            return _error("demo", f"cannot save {target}: ffmpeg is not installed (a .gif needs nothing more)")
        paths.append(target)
    for path in paths:
        folder = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(folder):
            return _error("demo", f"cannot save {path}: no folder {folder}")
    try:
        run_demo(args.out, args.quick, animation=animation)
    except OSError as error:
        return _error("demo", f"cannot save {error.filename or args.out}: {error.strerror or error}", status=1)
    return 0


# ---------------------------------------------------------------------------------------- animation

# The demo's body as two thin uniform rods of equal mass joined in a T: a crossbar of length 2 along
# the body axis e1 and a stem of length s = sqrt(0.8) along e2, from the middle of the crossbar.  About
# their centre of mass (s/4 up the stem) their moments are m s^2 (1/16 + 1/12 + 1/16) = m/6 about e1,
# m/3 about e2 and m/2 about e3: proportional to the demo's I = (1, 2, 3).  The demo spins it about
# the stem (the middle axis) and the crossbar turns it over.
_STEM = float(np.sqrt(0.8))
_BASE = -_STEM / 4
AXIS_LENGTH = 1.45
BODY_POINTS = {
    "bar": np.array([[-1.0, _BASE, 0.0], [1.0, _BASE, 0.0]]),
    "stem": np.array([[0.0, _BASE, 0.0], [0.0, _BASE + _STEM, 0.0]]),
    "e1": np.array([[0.0, 0.0, 0.0], [AXIS_LENGTH, 0.0, 0.0]]),
    "e2": np.array([[0.0, 0.0, 0.0], [0.0, AXIS_LENGTH, 0.0]]),
    "e3": np.array([[0.0, 0.0, 0.0], [0.0, 0.0, AXIS_LENGTH]]),
}


def t_handle_geometry(rotation: np.ndarray) -> dict[str, np.ndarray]:
    r"""The T-handle and its body axes in space at the attitude matrix ``rotation`` (3, 3).

    Returns ``{name: points}`` with ``points`` of shape (2, 3), the two ends of each segment in the
    space frame ($x_\text{space} = R\, x_\text{body}$): ``"bar"`` and ``"stem"`` (the two rods, about
    the centre of mass) and ``"e1"``, ``"e2"``, ``"e3"`` (from the centre of mass along the body axes,
    length ``AXIS_LENGTH``): the end of ``"ek"`` is ``AXIS_LENGTH`` times column $k$ of $R$.
    """
    rotation = np.asarray(rotation)
    return {name: points @ rotation.T for name, points in BODY_POINTS.items()}


def _ffmpeg_available():
    try:
        from matplotlib import animation
    except ImportError:  # no matplotlib: the demo says so, and makes neither plot nor animation
        return True
    return animation.writers.is_available("ffmpeg")


class FlipAnimation:
    """The tumbling T-handle of the demo, drawn with matplotlib frame by frame.

    Left, in 3D: the body (`t_handle_geometry`) at ``body.rotation_matrix(t)``, its body axes $e_1$
    (along the crossbar), $e_2$ (along the stem) and $e_3$, the path of the stem's end over the last
    frames, and the angular momentum $R L$, fixed in space (vertical).  Right: the body-frame
    $L(t)$, whose $L_2$ changes sign at every flip, with the time of the frame marked.

    ``times`` are the frame times; ``quick`` draws small (for tests).  ``frame(k)`` sets every
    artist to frame ``k`` (what `matplotlib.animation.FuncAnimation` calls); ``artists`` holds them
    by name (the 3D lines under the names of `t_handle_geometry`) so that a test can read them back;
    ``save(path)`` writes a GIF (Pillow) or an MP4 (ffmpeg).
    """

    TRAIL = 14  # frames of the stem end's path

    def __init__(self, body: FreeRigidBody, times: np.ndarray, *, quick: bool = False):
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib import animation

        self.times = np.asarray(times, dtype=float)
        self.rotations = np.asarray(body.rotation_matrix(self.times))
        self.momentum = np.asarray(body.angular_momentum(self.times))
        self.quick = quick
        self.fps = 10 if quick else 20  # GIF frame durations are whole hundredths of a second
        self.dpi = 40 if quick else 90
        self.geometry = [t_handle_geometry(rotation) for rotation in self.rotations]
        # The spatial angular momentum R L is the same at every frame (to rounding): take frame 0's.
        spatial = self.rotations[0] @ self.momentum[0]
        momentum_axis = 1.5 * spatial / np.linalg.norm(spatial)

        self.figure = figure = plt.figure(figsize=(6.4, 3.6))
        grid = figure.add_gridspec(
            1, 2, width_ratios=(1.15, 1), left=0.0, right=0.97, bottom=0.14, top=0.84, wspace=0.18
        )
        space = figure.add_subplot(grid[0], projection="3d")
        space.view_init(elev=16, azim=-62, vertical_axis="y")
        limit = 1.25
        space.set(xlim=(-limit, limit), ylim=(-limit, limit), zlim=(-limit, limit))
        space.set_box_aspect((1, 1, 1), zoom=1.35)
        space.set_axis_off()
        colours = {"bar": "#2f3b4c", "stem": "#2f3b4c", "e1": "#d62728", "e2": "#2ca02c", "e3": "#1f77b4"}
        thick = 2.2 if quick else 1.0  # line widths are in points: scale with the small figure's dpi
        artists = {}
        space.plot(*np.stack([-momentum_axis, momentum_axis]).T, color="#e0a800", lw=2.0 * thick, ls=(0, (4, 2)))
        space.text(*(0.92 * momentum_axis), "  $L$ (fixed)", color="#b08400", fontsize=10, ha="left", va="center")
        (artists["trail"],) = space.plot([], [], [], color=colours["e2"], lw=1.0 * thick, alpha=0.55)
        for name in ("bar", "stem"):
            (artists[name],) = space.plot([], [], [], color=colours[name], lw=7.0 * thick, solid_capstyle="round")
        for name in ("e1", "e2", "e3"):
            (artists[name],) = space.plot([], [], [], color=colours[name], lw=1.8 * thick)
            artists[name + "_label"] = space.text(
                0, 0, 0, f"$e_{name[1]}$", color=colours[name], fontsize=10, ha="center", va="center"
            )

        plot = figure.add_subplot(grid[1])
        for k, colour in enumerate(("#d62728", "#2ca02c", "#1f77b4")):
            plot.plot(self.times, self.momentum[:, k], color=colour, lw=1.3 * thick, label=f"$L_{k + 1}$")
        artists["cursor"] = plot.axvline(self.times[0], color="0.3", lw=0.8 * thick)
        (artists["marker"],) = plot.plot([], [], "o", color=colours["e2"], ms=4 * thick)
        plot.set_xlim(self.times[0], self.times[-1])
        plot.set_ylim(-1.15, 1.15)
        plot.set_xlabel("time $t$")
        plot.set_ylabel("body-frame $L(t)$")
        plot.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), fontsize=9, frameon=False, ncol=3)
        plot.grid(True, alpha=0.3)
        artists["title"] = figure.suptitle("", fontsize=11)
        self.artists = artists
        self.animation = animation.FuncAnimation(
            figure, self.frame, frames=len(self.times), interval=1000 / self.fps, blit=False
        )

    def frame(self, index: int) -> list:
        """Set every artist to frame ``index`` (time ``times[index]``); returns the artists."""
        geometry = self.geometry[index]
        for name, points in geometry.items():
            self.artists[name].set_data_3d(*points.T)
        for name in ("e1", "e2", "e3"):
            label = self.artists[name + "_label"]
            x, y, z = 1.13 * geometry[name][1]
            label.set_position((x, y))
            label.set_3d_properties(z, None)
        first = max(0, index - self.TRAIL)
        trail = np.array([self.geometry[k]["stem"][1] for k in range(first, index + 1)])
        self.artists["trail"].set_data_3d(*trail.T)
        t = self.times[index]
        self.artists["cursor"].set_xdata([t, t])
        self.artists["marker"].set_data([t], [self.momentum[index, 1]])
        self.artists["title"].set_text(f"The Dzhanibekov flip of a T-handle, exact motion (frbjax): t = {t:5.1f}")
        return list(self.artists.values())

    def save(self, path: str | os.PathLike) -> None:
        """Write every frame to ``path``: a GIF (``.gif``, Pillow) or an MP4 (``.mp4``, ffmpeg)."""
        import matplotlib.pyplot as plt
        from matplotlib import animation

        if os.fspath(path).lower().endswith(".mp4"):
            writer = animation.FFMpegWriter(fps=self.fps, bitrate=800)
        else:
            writer = animation.PillowWriter(fps=self.fps)
        try:
            self.animation.save(path, writer=writer, dpi=self.dpi)
        finally:
            plt.close(self.figure)


if __name__ == "__main__":
    sys.exit(main())
