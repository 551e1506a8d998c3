"""The wheel: built from the tracked files alone, installed into a new virtual environment, run elsewhere.

What a user who installs frbjax gets: ``python -m build --wheel`` on a copy of the tracked files (so
that nothing untracked in this checkout can make it pass), ``pip install --no-deps --no-index`` of
that wheel into a fresh venv, its dependencies being those that pip would install for a user: the
closure of the wheel's own ``Requires-Dist`` (extras left out), taken from this environment (linked
into a folder that the venv reads through a ``.pth`` file) instead of downloaded again, so that a
module the wheel uses without declaring it (matplotlib, the test extras) is missing there as it would
be for a user.  Then, from a folder with no source tree in it, the installed ``frbjax`` command and
package: ``frbjax demo`` runs (without matplotlib, which the wheel does not require: it prints its
table and says that the plot is left out), the version is the one of ``frbjax/__init__.py`` and
``py.typed`` and the compiled kernels ship (the kernels are selected on the CPU).

Slow (a build, the C++ kernels' two builds compiled side by side, and a demo run; 54 s with an
isolated build environment that downloaded scikit-build-core and jaxlib again, 40 s without it, both
at -O3; measured 2026-11-29).  The build takes this environment's build requirements where they are
installed (``make`` installs them with the dev extras), an isolated environment otherwise, and
compiles the kernels at -O1 (see the test).
"""

from __future__ import annotations

import email.parser
import importlib.metadata
import os
import pathlib
import re
import shutil
import subprocess
import sys
import zipfile

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name


REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
UNTRACKED_DIRECTORIES = {
    ".git",
    ".venv",
    "__pycache__",
    ".pytest_cache",
    ".hypothesis",
    "build",
    "dist",
    "site",
    ".ipynb_checkpoints",
}


def tracked_files():
    git = shutil.which("git")
    if git is not None and (REPOSITORY / ".git").exists():
        listing = subprocess.run(
            [git, "ls-files", "-z"], cwd=REPOSITORY, capture_output=True, check=True
        ).stdout.decode()
        return [pathlib.Path(name) for name in listing.split("\0") if name]
    return [
        path.relative_to(REPOSITORY)
        for path in REPOSITORY.rglob("*")
        if path.is_file()
        and not any(
            part in UNTRACKED_DIRECTORIES or part.endswith(".egg-info") for part in path.relative_to(REPOSITORY).parts
        )
    ]


def clean_environment(**extra):
    """The environment without this checkout on the path and without the test venv's settings."""
    env = {
        key: value
        for key, value in os.environ.items()
        if key not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME") and not key.startswith("JAX_")
    }
    env.update(extra)
    return env


def dependency_closure(wheel):
    """This environment's distributions that ``pip install wheel`` would install beside it: the
    closure of the wheel's Requires-Dist under this Python, without extras."""
    with zipfile.ZipFile(wheel) as archive:
        metadata = next(name for name in archive.namelist() if name.endswith(".dist-info/METADATA"))
        requirements = email.parser.Parser().parsestr(archive.read(metadata).decode()).get_all("Requires-Dist") or []
    found, pending = {}, list(requirements)
    while pending:
        requirement = Requirement(pending.pop())
        if requirement.marker is not None and not requirement.marker.evaluate({"extra": ""}):
            continue
        name = canonicalize_name(requirement.name)
        if name not in found:
            found[name] = importlib.metadata.distribution(requirement.name)
            pending += found[name].requires or []
    return found


def link_distributions(distributions, folder):
    """``folder`` holding links to the top-level files and folders (packages, modules, .dist-info)
    of ``distributions``, as their installation put them in site-packages."""
    folder.mkdir()
    for distribution in distributions.values():
        site = pathlib.Path(distribution.locate_file(""))
        for top in {pathlib.PurePath(path).parts[0] for path in distribution.files or []}:
            if top != ".." and (site / top).exists() and not (folder / top).exists():
                (folder / top).symlink_to(site / top)
    return folder


def _build_requirements_installed():
    """Whether pyproject.toml's [build-system] requirements are met in this environment, CMake among
    them (scikit-build-core asks for CMake from the package index where none is on the path)."""
    import tomllib

    if shutil.which("cmake") is None:
        return False

    requirements = tomllib.loads((REPOSITORY / "pyproject.toml").read_text())["build-system"]["requires"]
    for text in requirements:
        requirement = Requirement(text)
        try:
            version = importlib.metadata.version(requirement.name)
        except importlib.metadata.PackageNotFoundError:
            return False
        if not requirement.specifier.contains(version, prereleases=True):
            return False
    return True


def run(command, cwd, timeout, env=None):
    result = subprocess.run(
        command,
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        env=clean_environment() if env is None else env,
    )
    assert result.returncode == 0, f"{command}:\n{result.stdout[-4000:]}\n{result.stderr[-4000:]}"
    return result


@pytest.mark.slow
def test_wheel_installs_and_runs_from_another_folder(tmp_path):
    source = tmp_path / "source"
    for name in tracked_files():
        if (REPOSITORY / name).is_file():
            (source / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPOSITORY / name, source / name)
    dist = tmp_path / "dist"
    # Built with this environment's scikit-build-core and jaxlib (the build requirements, which `make`
    # installed) rather than an isolated environment that downloads them again; the kernels' two
    # builds compile side by side.
    # The kernels compile at optimisation level 1 here (about 12 s a build instead of 46 at the
    # release's -O3): what this test checks is the packaging (what the wheel holds, that it installs
    # and runs), and the optimised build is the one `make` installs, which every other test runs.
    build = [
        sys.executable,
        "-m",
        "build",
        "--wheel",
        "--outdir",
        str(dist),
        "--config-setting=cmake.define.CMAKE_CXX_FLAGS_RELEASE=-O1 -DNDEBUG",
    ]
    if _build_requirements_installed():
        build.append("--no-isolation")
    environment = clean_environment(CMAKE_BUILD_PARALLEL_LEVEL=str(max(1, min(2, os.cpu_count() or 1))))
    run(build + [str(source)], tmp_path, 600, env=environment)
    wheels = list(dist.glob("frbjax-*.whl"))
    assert len(wheels) == 1, wheels

    version = re.search(r'^__version__ = "([^"]+)"', (REPOSITORY / "frbjax" / "__init__.py").read_text(), re.MULTILINE)[
        1
    ]
    assert wheels[0].name.startswith(f"frbjax-{version}-")

    venv = tmp_path / "venv"
    run([sys.executable, "-m", "venv", "--without-pip", str(venv)], tmp_path, 300)
    python = venv / "bin" / "python"
    run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            str(python),
            "install",
            "--quiet",
            "--no-deps",
            "--no-index",
            str(wheels[0]),
        ],
        tmp_path,
        300,
    )
    dependencies = dependency_closure(wheels[0])
    assert {"jax", "jaxlib", "numpy", "diffrax"} <= set(dependencies) and "matplotlib" not in dependencies
    site_packages = pathlib.Path(
        run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"], tmp_path, 60).stdout.strip()
    )
    linked = link_distributions(dependencies, tmp_path / "dependencies")
    (site_packages / "frbjax_test_dependencies.pth").write_text(f"{linked}\n")

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.rmtree(source)  # no source tree anywhere near
    check = run(
        [
            str(python),
            "-c",
            "import pathlib, frbjax, jax.numpy as jnp; from frbjax.special import _compiled; "
            "print(frbjax.__version__); print(pathlib.Path(frbjax.__file__).parent); "
            "print(_compiled.selected(jnp.ones(1)))",
        ],
        elsewhere,
        300,
    )
    installed_version, package, kernels_selected = check.stdout.split()
    # The compiled kernels were built into the wheel and run on the CPU.
    assert kernels_selected == "True"
    assert installed_version == version
    assert pathlib.Path(package).is_relative_to(venv)
    assert (pathlib.Path(package) / "py.typed").is_file()

    env = clean_environment(FRBJAX_CACHE_DIR=str(tmp_path / "cache"))
    demo = run([str(venv / "bin" / "frbjax"), "demo", "--quick"], elsewhere, 600, env=env)
    assert "4K(m)/B" in demo.stdout
    observed = next(line for line in demo.stdout.splitlines() if "rises through 0 every" in line)
    assert float(observed.split("relative difference")[1].strip(" )")) < 1e-10
    assert "no plot: matplotlib is not installed" in demo.stdout
    assert not (elsewhere / "frbjax_demo.png").exists()
