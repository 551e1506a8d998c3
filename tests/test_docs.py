"""The documentation site: it builds without a warning, names every public function, and its examples run.

- ``mkdocs build --strict`` (what ``make docs`` runs) into a temporary folder: any warning (a broken
  link, a docstring mkdocstrings cannot render, a missing figure) fails the build;
- every public name of frbjax (the top-level functions and classes, the methods of FreeRigidBody,
  every function of frbjax.special, the command's entry point) has its entry in the API reference;
- the ```python blocks of each page run, in order, in a fresh namespace of this interpreter (from the
  repository root, with JAX's default configuration: float32 and numpy rank promotion allowed, so that
  a page that needs float64 must say so as a user would), so that the examples cannot rot.  The
  blocks assert what they show.  One interpreter for all pages: the programs the pages share (the
  same bodies and fits on several guides) are compiled once;
- the API pages typeset the docstrings' mathematics (arithmatex's MathJax markup, as on the theory
  page) and show typed signatures, while ``help()`` keeps the plain text;
- the front door: the README stays short, its links resolve, its headline figures are on the pages
  it links to, the guides of the nav are listed on the README and the home page, and both show the
  demo's animation.
"""

from __future__ import annotations

import contextlib
import html
import inspect
import linecache
import logging
import os
import pathlib
import re
import subprocess
import sys

import jax
import pytest

import frbjax
from frbjax import cli, special


REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
DOCS = REPOSITORY / "docs"
PAGES = sorted(path.relative_to(DOCS) for path in DOCS.rglob("*.md"))
PYTHON_BLOCK = re.compile(r"^```python\n(.*?)^```", re.MULTILINE | re.DOTALL)


def python_blocks(page):
    return PYTHON_BLOCK.findall((DOCS / page).read_text())


def environment():
    """The parent's environment, with mkdocs' notice about its version 2 silenced."""
    return dict(os.environ, NO_MKDOCS_2_WARNING="1")


def public_names():
    """Dotted names of everything a user can call, as the API reference should name them."""
    names = []
    for name in sorted(set(dir(frbjax)) | set(frbjax.__all__)):
        if name.startswith("_"):
            continue
        value = getattr(frbjax, name)
        if inspect.isclass(value) or inspect.isfunction(value):
            names.append(name)
    names += [
        f"FreeRigidBody.{name}"
        for name, _ in inspect.getmembers(frbjax.FreeRigidBody)
        if not name.startswith("_") and callable(getattr(frbjax.FreeRigidBody, name))
    ]
    names += [f"special.{name}" for name in special.__all__]
    names += ["cli.main"]
    return names


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    folder = tmp_path_factory.mktemp("site")
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(folder)],
        cwd=REPOSITORY,
        capture_output=True,
        text=True,
        timeout=300,
        env=environment(),
    )
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
    missing = [
        name
        for name in names
        if not any(anchor == f"frbjax.{name}" or anchor.endswith(f".{name}") for anchor in anchors)
    ]
    assert not missing, f"not in the API reference: {missing}"


def test_pages_have_examples():
    """The guides show code, and every page that does is run below."""
    with_examples = {str(page) for page in PAGES if python_blocks(page)}
    for page in ("getting-started.md", "fitting.md", "interop.md", "calgo903.md", "torqued.md", "index.md"):
        assert page in with_examples, page


@contextlib.contextmanager
def default_jax_configuration():
    """JAX's defaults, as a user's fresh interpreter has them (tests/conftest.py sets float64 and
    rank promotion "raise" for the tests), restored afterwards whatever the page changed."""
    names = ("jax_enable_x64", "jax_numpy_rank_promotion")
    saved = {name: getattr(jax.config, name) for name in names}
    jax.config.update("jax_enable_x64", False)
    jax.config.update("jax_numpy_rank_promotion", "allow")
    try:
        yield
    finally:
        for name, value in saved.items():
            jax.config.update(name, value)


# Pages whose examples compile for over a minute (CPU seconds measured in one interpreter, the pages
# in order): marked slow, with the reason.
SLOW_PAGES = {
    # jax.jacrev through the tensor body's construction and evaluation (70 s of its 100 s).
    "inertia-tensors.md": "its reverse-mode derivative in the tensor's entries compiles for about 70 s",
    # A light-curve inversion: 57 s in CI's tier (2026-11-28), too close to the 60 s limit.
    "lightcurves.md": "it compiles a light-curve inversion (57 s)",
}


@pytest.mark.parametrize(
    "page",
    [
        pytest.param(str(page), marks=pytest.mark.slow(reason=SLOW_PAGES[str(page)]))
        if str(page) in SLOW_PAGES
        else str(page)
        for page in PAGES
        if python_blocks(page)
    ],
)
def test_page_examples_run(page, monkeypatch):
    """The page's blocks as one script, in a fresh namespace, from the repository root; a failure's
    traceback names the page and shows its lines."""
    source = "\n\n".join(python_blocks(page))
    filename = f"docs/{page}"
    linecache.cache[filename] = (len(source), None, source.splitlines(keepends=True), filename)
    monkeypatch.chdir(REPOSITORY)
    with default_jax_configuration():
        exec(compile(source, filename, "exec"), {"__name__": "__main__"})


# ------------------------------------------------------------------ mathematics and types on the API pages


def signature_text(page, name):
    """The text of the signature of ``name`` (a dotted path) on a built API page, tags removed."""
    match = re.search(rf'id="{re.escape(name)}".*?<div class="doc-signature[^"]*">(.*?)</div>', page, re.DOTALL)
    assert match, f"no signature of {name}"
    text = " ".join(html.unescape(re.sub(r"<[^>]+>", "", match[1])).split())
    # mkdocstrings formats a long signature with ruff (installed with the dev extras) over several
    # lines, one parameter a line with a trailing comma: the same signature.
    return re.sub(r",?\s*\)", ")", re.sub(r"\(\s+", "(", text))


def test_api_pages_typeset_mathematics_and_show_types(site):
    """The docstrings' $...$ and $$...$$ reach the API pages as MathJax markup (arithmatex), as on the
    theory page, and the signatures carry their annotations."""
    special_page = (site / "api" / "special" / "index.html").read_text()
    # Display mathematics of ellipk's docstring, inline mathematics of ellipj's.
    assert (
        '<div class="arithmatex">\\[K(m) = \\int_0^{\\pi/2} \\frac{d\\theta}{\\sqrt{1 - m \\sin^2\\theta}}'
        in special_page
    )
    assert '<span class="arithmatex">\\(0 \\le m \\le 1\\)</span>' in special_page
    assert special_page.count('class="arithmatex"') >= 30
    theory = (site / "theory" / "index.html").read_text()
    assert '<span class="arithmatex">\\(' in theory  # the same markup as the theory page's own

    assert signature_text(special_page, "frbjax.special.ellipk") == (
        "ellipk(m: ArrayLike, *, mc: ArrayLike | None = None) -> Array"
    )
    sharding_page = (site / "api" / "sharding" / "index.html").read_text()
    assert signature_text(sharding_page, "frbjax.shard_bodies") == (
        "shard_bodies(body: FreeRigidBody, mesh: Mesh | None = None, *, pad: bool = True) -> FreeRigidBody"
    )
    cli_page = (site / "api" / "cli" / "index.html").read_text()
    assert signature_text(cli_page, "frbjax.cli.main") == "main(argv: list[str] | None = None) -> int"
    # And the page loads MathJax with the settings that typeset arithmatex's markup.
    assert "_javascript/mathjax.js" in special_page and "tex-mml-chtml.js" in special_page


def test_docstring_mathematics_reads_as_text():
    """help() shows the same docstrings as plain text: the dollars, no HTML, no reST directives."""
    text = special.ellipk.__doc__
    assert "$$K(m) = \\int_0^{\\pi/2}" in text and "<" not in text
    for function in (
        special.ellipk,
        special.ellipj,
        special.elliprj,
        frbjax.shard_batch,
        frbjax.quaternion_to_matrix,
        cli.flip_period,
    ):
        assert ".. math::" not in function.__doc__ and ":math:" not in function.__doc__, function


def test_hook_fails_the_build_on_mathematics_left_untypeset():
    """docs/_hooks.py warns (so that the strict build fails) on a $ outside code and mathematics."""
    sys.path.insert(0, str(DOCS))
    try:
        import _hooks
    finally:
        sys.path.remove(str(DOCS))

    class Page:
        class file:
            src_uri = "api/special.md"

    typeset = (
        '<p>For <span class="arithmatex">\\(m = 1\\)</span> and <code>$HOME</code>:</p>'
        '<div class="arithmatex">\\[K(m)\\]</div>'
    )
    broken = "<p>For $ m = 1$ the integral diverges.</p>"
    records = []
    handler = logging.Handler()
    handler.emit = records.append
    _hooks.log.addHandler(handler)
    try:
        assert _hooks.on_page_content(typeset, Page, None, None) == typeset
        assert not [r for r in records if r.levelno >= logging.WARNING]
        _hooks.on_page_content(broken, Page, None, None)
        assert [r for r in records if r.levelno >= logging.WARNING and "not typeset" in r.getMessage()]
    finally:
        _hooks.log.removeHandler(handler)


# ----------------------------------------------------------------------------- the front door


README = REPOSITORY / "README.md"
ANIMATION = REPOSITORY / "docs" / "images" / "frbjax_demo.gif"
MARKDOWN_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def test_readme_is_short_and_its_links_resolve():
    """Under 6.5 KB, and every relative link (pages, the animation, CONTRIBUTING) names a file here."""
    size = README.stat().st_size
    assert size < 6500, size
    targets = [target for target in MARKDOWN_LINK.findall(README.read_text()) if not re.match(r"[a-z]+://", target)]
    assert len(targets) >= 10, targets
    for target in targets:
        path = REPOSITORY / target.split("#")[0]
        assert path.is_file(), target


def test_readme_headline_figures_are_on_the_pages_that_measure_them():
    """Each row of the table links to a docs page; every number of its figure is on that page."""
    table = README.read_text().split("## Headline figures", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in table.splitlines() if line.startswith("|") and "docs/" in line]
    assert len(rows) >= 4, rows
    for row in rows:
        _, figure, where = [cell.strip() for cell in row.strip("|").split("|")]
        page = (REPOSITORY / MARKDOWN_LINK.search(where)[1].split("#")[0]).read_text()
        numbers = re.findall(r"\d[\d,.^e-]*\d|\d", figure)
        assert numbers, row
        for number in numbers:
            assert number in page, (number, row)


def test_guides_are_listed_on_the_front_pages():
    """Every guide of the site's nav is in the README's and the home page's "Guides" lists (one line
    each): adding a guide is a line in mkdocs.yml, README.md and docs/index.md."""
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    Loader.add_multi_constructor("", lambda loader, suffix, node: None)  # mkdocs' !!python tags
    nav = yaml.load((REPOSITORY / "mkdocs.yml").read_text(), Loader=Loader)["nav"]
    guides = next(entry["Guides"] for entry in nav if isinstance(entry, dict) and "Guides" in entry)
    pages = [next(iter(guide.values())) for guide in guides]
    assert len(pages) >= 4, pages
    readme = README.read_text().split("## Guides", 1)[1].split("\n## ", 1)[0]
    home = (DOCS / "index.md").read_text().split("## Guides", 1)[1].split("\n## ", 1)[0]
    for page in pages:
        assert f"(docs/{page})" in readme, f"README.md, Guides: add a line for {page}"
        assert f"({page})" in home, f"docs/index.md, Guides: add a line for {page}"


def test_animation_on_the_front_pages(site):
    """The committed animation: a GIF of a few MB at most, with many frames, shown by the README and
    by the home page of the built site."""
    from PIL import Image

    assert ANIMATION.stat().st_size < 3_000_000
    with Image.open(ANIMATION) as gif:
        assert gif.format == "GIF" and gif.n_frames >= 100 and gif.size[0] >= 480
    assert "](docs/images/frbjax_demo.gif)" in README.read_text()
    assert (site / "images" / "frbjax_demo.gif").read_bytes() == ANIMATION.read_bytes()
    assert 'src="images/frbjax_demo.gif"' in (site / "index.html").read_text()
