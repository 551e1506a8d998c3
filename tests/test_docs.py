"""The documentation site: it builds without a warning, names every public function, and its examples run.

- ``mkdocs build --strict`` (what ``make docs`` runs) into a temporary folder: any warning (a broken
  link, a docstring mkdocstrings cannot render, a missing figure) fails the build;
- every public name of frbjax (the top-level functions and classes, the methods of FreeRigidBody,
  every function of frbjax.special, the command's entry point) has its entry in the API reference;
- the ```python blocks of each page run, in order, in a fresh interpreter (one per page, from the
  repository root), so that the examples cannot rot.  The blocks assert what they show.
"""

from __future__ import annotations

import inspect
import os
import pathlib
import re
import subprocess
import sys

import pytest

import frbjax
from frbjax import cli, special

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
DOCS = REPOSITORY / "docs"
PAGES = sorted(path.relative_to(DOCS) for path in DOCS.rglob("*.md"))
PYTHON_BLOCK = re.compile(r"^```python\n(.*?)^```", re.MULTILINE | re.DOTALL)


def python_blocks(page):
    return PYTHON_BLOCK.findall((DOCS / page).read_text())


def environment(pytestconfig):
    """The parent's environment; compiled programs go to pytest's cache, not the user's."""
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    cache = getattr(pytestconfig, "cache", None)
    if cache is not None:
        env["JAX_COMPILATION_CACHE_DIR"] = str(cache.mkdir("jax-compilation-cache"))
    return env


def public_names():
    """Dotted names of everything a user can call, as the API reference should name them."""
    names = []
    for name in sorted(set(dir(frbjax)) | set(frbjax.__all__)):
        if name.startswith("_"):
            continue
        value = getattr(frbjax, name)
        if inspect.isclass(value) or inspect.isfunction(value):
            names.append(name)
    names += [f"FreeRigidBody.{name}" for name, _ in inspect.getmembers(frbjax.FreeRigidBody)
              if not name.startswith("_") and callable(getattr(frbjax.FreeRigidBody, name))]
    names += [f"special.{name}" for name in special.__all__]
    names += ["cli.main"]
    return names


@pytest.fixture(scope="module")
def site(tmp_path_factory, pytestconfig):
    folder = tmp_path_factory.mktemp("site")
    result = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(folder)],
                            cwd=REPOSITORY, capture_output=True, text=True, timeout=300,
                            env=environment(pytestconfig))
    assert result.returncode == 0, result.stdout + result.stderr
    return folder


def test_site_builds_with_every_page(site):
    for page in PAGES:
        if page.name.startswith("_"):
            continue
        assert (site / page.with_suffix("") / "index.html").is_file() or page.name == "index.md", page
    # The figures come from benchmarks/results at build time (no copies under docs/).
    for figure in ("stability.png", "throughput.png", "work_precision.png"):
        assert (site / "images" / figure).read_bytes() == (REPOSITORY / "benchmarks" / "results" / figure).read_bytes()
    assert "usage: frbjax run" in (site / "api" / "cli" / "index.html").read_text()


def test_api_reference_names_every_public_function(site):
    anchors = set()
    for page in (site / "api").rglob("index.html"):
        anchors |= set(re.findall(r'id="(frbjax\.[\w.]+)"', page.read_text()))
    names = public_names()
    assert len(names) >= 20, names
    missing = [name for name in names
               if not any(anchor == f"frbjax.{name}" or anchor.endswith(f".{name}") for anchor in anchors)]
    assert not missing, f"not in the API reference: {missing}"


def test_pages_have_examples():
    """The guides show code, and every page that does is run below."""
    with_examples = {str(page) for page in PAGES if python_blocks(page)}
    for page in ("getting-started.md", "fitting.md", "interop.md", "calgo903.md", "torqued.md", "index.md"):
        assert page in with_examples, page


@pytest.mark.parametrize("page", [str(page) for page in PAGES if python_blocks(page)])
def test_page_examples_run(page, tmp_path, pytestconfig):
    script = tmp_path / (pathlib.Path(page).stem + ".py")
    script.write_text("\n\n".join(python_blocks(page)))
    result = subprocess.run([sys.executable, str(script)], cwd=REPOSITORY, capture_output=True,
                            text=True, timeout=600, env=environment(pytestconfig))
    assert result.returncode == 0, f"docs/{page}:\n{result.stdout}\n{result.stderr}"
