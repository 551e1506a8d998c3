"""The ``frbjax`` command: ``run`` on the CALGO 903 example files, its errors, and ``demo``.

The tests call :func:`frbjax.cli.main` in this process (sharing its compiled programs); three run the
installed console script in a subprocess, end to end (a run and a malformed file: exit statuses 0 and
2; the demo that ``make demo`` runs, at its quick size).
"""

from __future__ import annotations

import io
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import frbjax
from frbjax import _calgo903 as calgo, cli


REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
DATA = REPOSITORY / "tests" / "data" / "calgo903"


def needs_data(test):
    """The CALGO 903 files must be there (tests/data/calgo903, tracked): no skip, a missing folder
    fails loudly here."""
    assert DATA.is_dir(), f"CALGO 903 reference data not found: {DATA}"
    return test


TOLERANCE = {"example0": 1e-14, "example1": 1e-10, "example2": 1e-14, "example3": 1e-9, "example4": 1e-9}
EXAMPLE1_STEPS = 200
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
GIF_SIGNATURE = b"GIF89a"


@pytest.fixture(autouse=True)
def cache_environment(monkeypatch):
    """No persistent compilation cache (see conftest.py), here and in subprocesses; nothing goes to
    the user's cache folder."""
    monkeypatch.setenv("FRBJAX_CACHE_DIR", "")
    return dict(os.environ)


def console_script():
    """The installed ``frbjax`` script next to this Python, or ``python -m frbjax.cli``."""
    script = pathlib.Path(sys.executable).with_name("frbjax")
    return [str(script)] if script.exists() else [sys.executable, "-m", "frbjax.cli"]


def compare(path, name, records=None):
    """Max difference between the output file at ``path`` and out_<name>.dat (first ``records``)."""
    layout = calgo.LAYOUTS[name]
    produced = calgo.read_output(path, layout)
    expected = calgo.read_output(DATA / f"out_{name}.dat", layout)
    records = len(expected.time) if records is None else records
    assert len(produced.time) == records
    recorded = ~np.isnan(produced.time)
    np.testing.assert_array_equal(produced.time[recorded], expected.time[:records][recorded])
    return max(
        np.abs(produced.momentum - expected.momentum[:records]).max(),
        np.abs(produced.attitude - expected.attitude[:records]).max(),
    )


# ------------------------------------------------------------------------------------------------ run


@needs_data
@pytest.mark.parametrize("name", ["example0", "example1", "example2", "example3", "example4"])
def test_run_matches_reference(name, tmp_path, capsys, cache_environment):
    output = tmp_path / f"out_{name}.dat"
    argv = ["run", str(DATA / f"init_{name}.dat"), "-o", str(output)]
    if name == "example1":
        argv += ["--steps", str(EXAMPLE1_STEPS)]
    assert cli.main(argv) == 0
    records = EXAMPLE1_STEPS + 1 if name == "example1" else None
    assert compare(output, name, records) <= TOLERANCE[name]
    captured = capsys.readouterr()
    assert captured.out == ""
    assert ("NP = 5" in captured.err) == (name in ("example3", "example4"))
    assert sorted(p.name for p in tmp_path.iterdir()) == [output.name]


@needs_data
def test_forced_layout_and_standard_output(capsys, cache_environment):
    assert cli.main(["run", str(DATA / "init_example2.dat"), "--layout", "example2"]) == 0
    text = capsys.readouterr().out
    assert len(text.splitlines()) == 15
    expected = calgo.read_output(DATA / "out_example2.dat", "example2")
    produced = calgo.parse_output(text, "example2")
    assert np.abs(produced.attitude - expected.attitude).max() <= 1e-14


@needs_data
def test_console_script(tmp_path, cache_environment):
    """The installed command, end to end: output file, note on stderr, exit status 0."""
    output = tmp_path / "out.dat"
    result = subprocess.run(
        [*console_script(), "run", str(DATA / "init_example4.dat"), "-o", str(output)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=cache_environment,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert "NP = 5" in result.stderr and "ignored" in result.stderr
    assert compare(output, "example4") <= 1e-9


@needs_data
def test_example1_leaves_xla_flags_alone(tmp_path, capsys, monkeypatch):
    """The command takes its speed from the library (the compiled kernels on the CPU), not from
    XLA_FLAGS, which it leaves as it found them (here: absent).

    1000 steps against the Fortran output: measured 7.0e-13 (5e-12 is the tolerance).
    """
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    output = tmp_path / "out.dat"
    assert cli.main(["run", str(DATA / "init_example1.dat"), "-o", str(output), "--steps", "1000"]) == 0
    assert "XLA_FLAGS" not in os.environ
    assert compare(output, "example1", 1001) <= 5e-12
    capsys.readouterr()


def test_help_mentions_that_np_is_ignored(capsys):
    with pytest.raises(SystemExit) as stop:
        cli.main(["run", "--help"])
    assert stop.value.code == 0
    text = capsys.readouterr().out
    assert "NP" in text and "ignored" in text and "--layout" in text


# --------------------------------------------------------------------------------------------- errors


def malformed_example0(tmp_path, edit):
    """A copy of init_example0.dat with its lines edited by ``edit(lines)``."""
    lines = (DATA / "init_example0.dat").read_text().splitlines()
    edit(lines)
    path = tmp_path / "init_bad.dat"
    path.write_text("\n".join(lines) + "\n")
    return path


def delete_line_8(lines):
    del lines[7]


def replace_line_6(lines):
    lines[5] = "  -0.68514471715x487e+00"


def add_a_line(lines):
    lines.insert(3, "1.5")


@needs_data
@pytest.mark.parametrize(
    "edit, layout, line, words",
    [
        (delete_line_8, None, 15, "15 values"),
        (delete_line_8, "example0", 16, "end of file after 15 values: expected Q(3,3)"),
        (replace_line_6, None, 6, "expected a number for Pi(2)"),
        (add_a_line, None, 17, "17 values"),
        (add_a_line, "example0", 17, "unexpected value"),
    ],
    ids=["missing-line", "missing-line-layout", "not-a-number", "wrong-count", "wrong-count-layout"],
)
def test_malformed_file(tmp_path, capsys, edit, layout, line, words):
    path = malformed_example0(tmp_path, edit)
    output = tmp_path / "out.dat"
    argv = ["run", str(path), "-o", str(output)] + (["--layout", layout] if layout else [])
    assert cli.main(argv) == 2
    message = capsys.readouterr().err
    assert f"{path}, line {line}:" in message
    assert words in message
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


@needs_data
def test_malformed_file_leaves_an_existing_output_alone(tmp_path, capsys):
    path = malformed_example0(tmp_path, replace_line_6)
    output = tmp_path / "out.dat"
    output.write_text("previous results\n")
    assert cli.main(["run", str(path), "-o", str(output)]) == 2
    assert output.read_text() == "previous results\n"


@needs_data
def test_malformed_file_console_script(tmp_path, cache_environment):
    path = malformed_example0(tmp_path, delete_line_8)
    output = tmp_path / "out.dat"
    result = subprocess.run(
        [*console_script(), "run", str(path), "-o", str(output)],
        capture_output=True,
        text=True,
        env=cache_environment,
        timeout=300,
    )
    assert result.returncode == 2
    assert f"{path}, line 15:" in result.stderr
    assert not output.exists()


def test_missing_input_file(tmp_path, capsys):
    assert cli.main(["run", str(tmp_path / "absent.dat")]) == 2
    assert "absent.dat" in capsys.readouterr().err


@needs_data
def test_output_folder_must_exist(tmp_path, capsys):
    output = tmp_path / "no" / "out.dat"
    assert cli.main(["run", str(DATA / "init_example2.dat"), "-o", str(output)]) == 2
    assert "no folder" in capsys.readouterr().err


@needs_data
def test_steps_rejected_for_single_step_layouts(capsys):
    assert cli.main(["run", str(DATA / "init_example0.dat"), "--steps", "3"]) == 2
    assert "--steps" in capsys.readouterr().err


def test_write_atomically(tmp_path):
    path = tmp_path / "out.dat"
    cli.write_atomically(path, "1.0\n")
    assert path.read_text() == "1.0\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.dat"]
    with pytest.raises(OSError):
        cli.write_atomically(tmp_path / "missing" / "out.dat", "1.0\n")


# ----------------------------------------------------------------------------------------------- demo


def test_demo_quick(tmp_path, capsys):
    """``frbjax demo --quick``: a PNG, a GIF next to it, the table, and flips recurring with the period 4K/B."""
    output = tmp_path / "tmp.png"
    assert cli.main(["demo", "--quick", "--out", str(output)]) == 0
    stdout = capsys.readouterr().out
    assert output.read_bytes().startswith(PNG_SIGNATURE)
    assert (tmp_path / "tmp.gif").read_bytes().startswith(GIF_SIGNATURE)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tmp.gif", "tmp.png"]
    assert f"saved to {tmp_path / 'tmp.gif'}" in stdout
    lines = stdout.splitlines()
    table = [line for line in lines if line[:8].strip().replace(".", "").isdigit()]
    assert len(table) == 11
    flips = next(line for line in lines if line.startswith("flips"))
    assert flips.count(",") == 4
    period = float(next(line for line in lines if "4K(m)/B" in line).split("=")[-1])
    assert 100 < period < 120
    observed = next(line for line in lines if "rises through 0 every" in line)
    assert float(observed.split("relative difference")[1].strip(" )")) < 1e-10
    assert "plot saved" in stdout


def test_flip_period_against_the_published_value():
    """tau = 4K/B = 116.472 for I = (1, 2, 3) and d = 2E/|L|^2 = 0.5000001 (a published worked example)."""
    d = 0.5000001
    momentum = np.array([np.sqrt(1.5 * (d - 1 / 3)), 0.0, np.sqrt(1.5 * (1 - d))])
    assert abs(cli.flip_period((1.0, 2.0, 3.0), momentum) - 116.472) < 5e-4
    assert abs(cli.flip_period((1.0, 2.0, 3.0), 2 * momentum) - 116.472 / 2) < 5e-4


def test_demo_folder_must_exist(tmp_path, capsys):
    assert cli.main(["demo", "--quick", "--out", str(tmp_path / "no" / "demo.png")]) == 2
    assert "no folder" in capsys.readouterr().err
    assert (
        cli.main(
            ["demo", "--quick", "--out", str(tmp_path / "demo.png"), "--animation", str(tmp_path / "no" / "demo.gif")]
        )
        == 2
    )
    assert "no folder" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_demo_animation_format_errors(tmp_path, capsys, monkeypatch):
    """Checked before anything is computed: a suffix other than .gif or .mp4, an .mp4 without ffmpeg,
    and --animation with --no-animation are usage errors (status 2) that write nothing."""
    png = str(tmp_path / "demo.png")
    assert cli.main(["demo", "--quick", "--out", png, "--animation", str(tmp_path / "demo.avi")]) == 2
    assert "expected a .gif or .mp4" in capsys.readouterr().err
    monkeypatch.setattr(cli, "_ffmpeg_available", lambda: False)
    assert cli.main(["demo", "--quick", "--out", png, "--animation", str(tmp_path / "demo.mp4")]) == 2
    assert "ffmpeg is not installed" in capsys.readouterr().err
    assert cli.main(["demo", "--quick", "--out", png, "--animation", str(tmp_path / "demo.gif"), "--no-animation"]) == 2
    assert "exclude each other" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_t_handle_geometry():
    """The drawn body is the demo's body: rods whose moments are proportional to I = (1, 2, 3), each
    point carried by R (x_space = R x_body), lengths kept."""
    # Thin uniform rods of equal mass: the inertia tensor about the common centre of mass.
    tensor = np.zeros((3, 3))
    for name in ("bar", "stem"):
        a, b = cli.BODY_POINTS[name]
        # The mean of p p^T over the rod from a to b: the integral of (a + s (b - a)) (...)^T over s.
        second = (np.outer(a, a) + np.outer(b, b)) / 3 + (np.outer(a, b) + np.outer(b, a)) / 6
        tensor += np.trace(second) * np.eye(3) - second
    centre = np.mean([cli.BODY_POINTS[name].mean(axis=0) for name in ("bar", "stem")], axis=0)
    np.testing.assert_allclose(centre, 0.0, atol=1e-15)
    np.testing.assert_allclose(tensor / tensor[0, 0], np.diag(cli.DEMO_INERTIA), atol=1e-14)

    rotation = np.asarray(frbjax.quaternion_to_matrix(np.array([0.8, 0.1, -0.5, 0.3]) / np.sqrt(0.99)))
    geometry = cli.t_handle_geometry(rotation)
    for name, points in cli.BODY_POINTS.items():
        np.testing.assert_allclose(geometry[name], points @ rotation.T, atol=1e-15)
        np.testing.assert_allclose(
            np.linalg.norm(np.diff(geometry[name], axis=0)), np.linalg.norm(np.diff(points, axis=0)), rtol=1e-14
        )
    for k in range(3):
        np.testing.assert_allclose(geometry[f"e{k + 1}"][1], cli.AXIS_LENGTH * rotation[:, k], atol=1e-15)


def test_demo_animation_frames(tmp_path):
    """The animation made at small size (``--quick``): its frames show the T-handle at
    ``rotation_matrix`` of their times, at least one flip among them.

    - the frame times cover a flip: L2, along the stem, goes from +1 to -1;
    - for every frame, the 3D artists read back (``get_data_3d``) are the body axes and rods of an
      independently built FreeRigidBody's ``rotation_matrix`` at that frame's time;
    - the GIF holds one image per frame time, and image k of the file is the figure drawn at frame k:
      nearer to a fresh drawing of frame k than to a drawing of any other frame.
    """
    from PIL import Image, ImageSequence

    from frbjax import FreeRigidBody

    out = tmp_path / "demo.png"
    result = cli.run_demo(out, quick=True, stream=io.StringIO())
    animation = result["animation"]
    times = animation.times
    assert len(times) >= 20 and times[0] == 0.0
    assert times[-1] == pytest.approx(result["period"])

    momentum = np.array(cli.DEMO_MOMENTUM) / np.linalg.norm(cli.DEMO_MOMENTUM)
    body = FreeRigidBody(np.array(cli.DEMO_INERTIA), momentum)
    rotations = np.asarray(body.rotation_matrix(times))
    stem = np.asarray(body.angular_momentum(times))[:, 1]
    assert stem[0] > 0.99 and stem.min() < -0.99 and stem[-1] > 0.99  # a flip and a flip back

    for k in range(len(times)):
        animation.frame(k)
        for j in range(3):
            ends = np.array(animation.artists[f"e{j + 1}"].get_data_3d()).T
            np.testing.assert_allclose(ends[0], 0.0, atol=1e-15)
            np.testing.assert_allclose(ends[1], cli.AXIS_LENGTH * rotations[k][:, j], atol=1e-12)
        for name in ("bar", "stem"):
            ends = np.array(animation.artists[name].get_data_3d()).T
            np.testing.assert_allclose(ends, cli.BODY_POINTS[name] @ rotations[k].T, atol=1e-12)

    with Image.open(tmp_path / "demo.gif") as gif:
        assert gif.n_frames == len(times)
        assert gif.info["duration"] == pytest.approx(1000 / animation.fps, abs=1)
        saved = [np.asarray(image.convert("RGB"), dtype=float) for image in ImageSequence.Iterator(gif)]

    def drawn(k):
        animation.frame(k)
        buffer = io.BytesIO()
        animation.figure.savefig(buffer, format="rgba", dpi=animation.dpi)
        width, height = saved[0].shape[1], saved[0].shape[0]
        return np.frombuffer(buffer.getvalue(), np.uint8).reshape(height, width, 4)[..., :3].astype(float)

    checked = range(0, len(times), 5)
    drawings = {k: drawn(k) for k in checked}
    for k in checked:
        distance = {j: np.abs(saved[k] - drawings[j]).mean() for j in checked}
        assert min(distance, key=distance.get) == k, (k, distance)
        assert distance[k] < 0.5 * min(d for j, d in distance.items() if j != k), (k, distance)


# ------------------------------------------------------------------------------------- README


def test_readme_quick_start_commands(tmp_path, cache_environment):
    """The README's Quick start block is exactly `make demo` and `make test`, and what `make demo` runs
    runs, end to end in its own process (the console script).

    (`make test` is what CI runs: this very suite.)  The command is read from ``make --dry-run demo``
    (its last line: the stamp's install commands come before it when pyproject.toml is newer than
    the stamp, and are not run here) and run with ``--quick`` into a temporary folder: the same code
    as the full-size demo at fewer samples, frames and dots per inch (the full size draws 180 frames
    for about a minute); its plot and its animation are written, its table printed.
    """
    root = pathlib.Path(__file__).resolve().parent.parent
    readme = (root / "README.md").read_text()
    section = readme.split("## Quick start", 1)[1]
    block = section.split("```", 2)[1]
    commands = [line.strip() for line in block.splitlines()[1:] if line.strip()]
    assert commands == ["make demo", "make test"]
    dry_run = subprocess.run(
        # --no-print-directory: under `make test` this make is a sub-make (MAKELEVEL is inherited), which
        # would print "make[1]: Entering directory ..." around its commands.
        ["make", "--no-print-directory", "--dry-run", "demo"],
        capture_output=True,
        text=True,
        cwd=root,
        env=cache_environment,
        timeout=60,
    )
    assert dry_run.returncode == 0, dry_run.stdout + dry_run.stderr
    program, *arguments = dry_run.stdout.strip().splitlines()[-1].split()
    assert program.endswith("/frbjax") and arguments == ["demo"], dry_run.stdout
    output = tmp_path / "frbjax_demo.png"
    result = subprocess.run(
        [str(root / program), *arguments, "--quick", "--out", str(output)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=cache_environment,
        timeout=300,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "4K(m)/B" in result.stdout and f"plot saved to {output}" in result.stdout
    assert f"saved to {tmp_path / 'frbjax_demo.gif'}" in result.stdout
    assert output.read_bytes().startswith(PNG_SIGNATURE)
    assert (tmp_path / "frbjax_demo.gif").read_bytes().startswith(GIF_SIGNATURE)
