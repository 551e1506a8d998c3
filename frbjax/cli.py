"""The ``frbjax`` command: ``frbjax run`` (CALGO 903 example files) and ``frbjax demo`` (tennis racket).

``frbjax run FILE [-o OUT]`` reads the input file of any of the five example drivers of CALGO 903
(Celledoni and Zanna, ACM TOMS 37(2), 2010) and writes what the driver writes, computed with the exact
motion of :class:`frbjax.FreeRigidBody`.  ``frbjax demo`` shows the Dzhanibekov effect: a T-handle spun
almost about its middle axis flips over and over, with the period predicted by the elliptic integral K.

This is an application, not the library: it enables 64-bit JAX and a persistent compilation cache.
It leaves XLA's flags alone: one body stepping in time runs as one kernel through the library's own
one-kernel regions (:mod:`frbjax._kernel`).  JAX and matplotlib are imported when a command needs
them, so that ``--help`` answers at once.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile

import numpy as np

PROGRAM = "frbjax"
DEFAULT_DEMO_PATH = "frbjax_demo.png"

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
(frbjax.special.ellipk) next to the period observed in L(t), and plots L(t) and q(t) to a PNG
(the plot needs matplotlib: pip install 'frbjax[demo]'; without it the demo prints and says so)."""

_EPILOG = """\
environment:
  FRBJAX_CACHE_DIR  where compiled XLA programs are kept between runs (default:
                    $XDG_CACHE_HOME/frbjax or ~/.cache/frbjax; empty: no cache).  JAX's own
                    JAX_COMPILATION_CACHE_DIR takes precedence.
  FRBJAX_ONE_KERNEL 0: compile one body's steps as XLA's ordinary kernels instead of one
                    kernel (frbjax._kernel; for comparison, example 1 then runs about 6 times
                    slower)."""


# --------------------------------------------------------------------------------------------- parser


def build_parser():
    """The argparse parser of the ``frbjax`` command and its subcommands."""
    parser = argparse.ArgumentParser(
        prog=PROGRAM,
        description="Exact motion of the torque-free rigid body (frbjax, JAX).",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    run = commands.add_parser(
        "run", help="run a CALGO 903 example input file with the exact motion",
        description=_RUN_DESCRIPTION, epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    run.add_argument("file", metavar="FILE", help="input file in one of the layouts above")
    run.add_argument("-o", "--output", metavar="OUT",
                     help="output file (default: standard output); written whole or not at all")
    run.add_argument("--layout", choices=["example0", "example1", "example2", "example3", "example4"],
                     help="read FILE in this layout instead of detecting it from the number of values")
    run.add_argument("--steps", type=_non_negative_int, metavar="N",
                     help="take N steps (examples 1, 3 and 4; default: INT(T/h), as the drivers)")
    run.set_defaults(handler=_run)

    demo = commands.add_parser(
        "demo", help="the Dzhanibekov effect: a flipping T-handle, table and plot",
        description=_DEMO_DESCRIPTION, epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    demo.add_argument("--out", metavar="PNG", default=DEFAULT_DEMO_PATH,
                      help=f"where to save the plot (default: {DEFAULT_DEMO_PATH})")
    demo.add_argument("--quick", action="store_true",
                      help="fewer sample times and a smaller image (for tests)")
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


def main(argv=None):
    """Entry point of the ``frbjax`` console script; returns the exit status."""
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


def write_atomically(path, text):
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
        return _error("run", f"--steps applies to examples 1, 3 and 4; {args.file} is {layout.name}, "
                             "a single step")
    if args.output is not None:
        if os.path.isdir(args.output):
            return _error("run", f"{args.output} is a folder; expected an output file name")
        folder = os.path.dirname(os.path.abspath(args.output))
        if not os.path.isdir(folder):
            return _error("run", f"cannot write {args.output}: no folder {folder}")

    if "NP" in problem.values:
        _note("run", f"NP = {int(problem['NP'])} (order of the semi-exact quadrature) is ignored: "
                     "frbjax computes the exact motion")
    if not layout.single_step and problem.step != problem["h"]:
        _note("run", f"h = {problem['h']!r} does not divide T = {problem['T']!r}; the step is "
                     f"T/INT(T/h) = {problem.step!r}, as in the driver")
    steps = problem.steps if args.steps is None else args.steps
    if layout.name == "example1":
        _note("run", f"{steps} steps of the splitting, 15 exact free flows each (seconds, "
                     "most of it compiling)")

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


def flip_period(inertia, angular_momentum):
    """Period 4K(m)/(B |L|) of L(t) for a body with sorted moments I1 < I2 < I3 rotating about I1.

    That is the regime d = 2E/|L|^2 > 1/I2 (just above the separatrix: the minor axis side), with
    B = sqrt((d I3 - 1)(I2 - I1)/(I1 I2 I3)) and m = (1 - d I1)(I3 - I2)/((d I3 - 1)(I2 - I1)).  Next to
    the separatrix m is close to 1, so its complement is formed without cancellation,
    1 - m = (I3 - I1)(d I2 - 1)/((d I3 - 1)(I2 - I1)), with d I2 - 1 = l1^2 (I2 - I1)/I1 - l3^2 (I3 - I2)/I3.
    """
    from .special import ellipk

    i1, i2, i3 = inertia
    norm = float(np.linalg.norm(angular_momentum))
    l1, l2, l3 = np.asarray(angular_momentum) / norm
    g1 = l2**2 * (i2 - i1) / i2 + l3**2 * (i3 - i1) / i3   # 1 - d I1
    g2 = l1**2 * (i2 - i1) / i1 - l3**2 * (i3 - i2) / i3   # d I2 - 1
    g3 = l1**2 * (i3 - i1) / i1 + l2**2 * (i3 - i2) / i2   # d I3 - 1
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
        padded = np.concatenate([roots, times[len(roots):]])
        moment = np.asarray(body.angular_momentum(padded))[: len(roots)]
        velocity = moment / inertia
        slope = moment[:, 2] * velocity[:, 0] - moment[:, 0] * velocity[:, 2]
        roots = roots - moment[:, 1] / slope
    return np.sort(roots[: len(upward)]), np.sort(roots[len(upward):])


def run_demo(out=DEFAULT_DEMO_PATH, quick=False, stream=None):
    """The demo: print the table and the periods to ``stream`` (stdout), save the plot to ``out``.

    Without matplotlib (not a dependency of the library: the ``demo`` extra) the plot is left out and
    the demo says so.

    Returns a dict with the predicted and observed periods and the sampled motion.
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
    print(f"{'t':>8} {'L1':>10} {'L2':>10} {'L3':>10}   {'q0':>9} {'q1':>9} {'q2':>9} {'q3':>9}",
          file=stream)
    rows = slice(None, None, (len(times) - 1) // 10)  # 11 rows, on the sample grid
    for t, l, q in zip(times[rows], momentum[rows], attitude[rows]):
        print(f"{t:8.2f} {l[0]:10.6f} {l[1]:10.6f} {l[2]:10.6f}   "
              f"{q[0]:9.5f} {q[1]:9.5f} {q[2]:9.5f} {q[3]:9.5f}", file=stream)
    print(f"\nflips (L2 changes sign) at t = {', '.join(f'{t:.3f}' for t in flips)}", file=stream)
    print(f"period of L(t), a flip and a flip back, 4K(m)/B = {period:.12f}", file=stream)
    print(f"observed: L2 rises through 0 every            {observed:.12f}   "
          f"(relative difference {abs(observed - period) / period:.1e})", file=stream)
    print(f"drift of |L|, E and the spatial L over the run: {np.ptp(np.linalg.norm(momentum, axis=-1)):.1e}, "
          f"{np.ptp(energy):.1e}, {np.abs(spatial - spatial[0]).max():.1e}", file=stream)

    result = {"period": period, "observed_period": observed, "flips": flips, "times": times,
              "angular_momentum": momentum, "quaternion": attitude}
    try:
        import matplotlib
    except ImportError:
        # The library does not need matplotlib; the plot is the demo's only use of it.
        print(f"\nno plot: matplotlib is not installed ({MATPLOTLIB_HINT})", file=stream)
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
        top.annotate("", xy=(upward[1], 1.12), xytext=(upward[0], 1.12),
                     arrowprops=dict(arrowstyle="<->", color="0.2"))
        top.text((upward[0] + upward[1]) / 2, 1.16, f"$4K/B = {period:.3f}$", ha="center", va="bottom")
    top.set_ylim(-1.2, 1.35)
    top.set_ylabel("body angular momentum")
    top.set_title("Body-frame angular momentum $L(t)$: $L_2$ switches sign at every flip")
    bottom.set_ylabel("quaternion")
    bottom.set_xlabel("time $t$ (units of $I_1/|L|$)")
    bottom.set_title("Attitude $q(t)$ (body to space)")
    figure.suptitle("Tennis racket theorem: exact motion of a T-handle, $I = (1, 2, 3)$, "
                    "spun about the middle axis", fontsize=13)
    figure.savefig(out, dpi=80 if quick else 150)
    plt.close(figure)
    print(f"\nplot saved to {out}", file=stream)
    return result


def _demo(args):
    folder = os.path.dirname(os.path.abspath(args.out))
    if not os.path.isdir(folder):
        return _error("demo", f"cannot save {args.out}: no folder {folder}")
    try:
        run_demo(args.out, args.quick)
    except OSError as error:
        return _error("demo", f"cannot save {args.out}: {error.strerror or error}", status=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
