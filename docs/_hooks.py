"""mkdocs hooks: files from outside docs/ and the command's help text, at build time.

- The figures of benchmarks/results (written by the benchmark scripts), the CHANGELOG and CONTRIBUTING
  at the root are added to the site as they are, so that no copy of them is kept under docs/.
- ``<!-- frbjax-help: ARGS -->`` in a page becomes the output of ``frbjax ARGS --help``, so that the
  command-line reference is the parser's own text.
- The API pages' mathematics: docstrings write it as ``$...$`` and ``$$...$$`` (CONTRIBUTING.md,
  "Writing docstrings"), which pymdownx.arithmatex turns into MathJax markup like the pages' own.  A
  ``$`` left in a rendered page outside code and mathematics is a formula that did not parse (an
  unpaired ``$``, a space inside it): a warning, so that the strict build fails.  Docstrings still
  in the reST form (``:math:``, ``.. math::``) are listed at INFO level, to be converted.
"""

from __future__ import annotations

import logging
import os
import pathlib
import re

from mkdocs.structure.files import File


log = logging.getLogger("mkdocs.hooks.frbjax")

ROOT = pathlib.Path(__file__).resolve().parents[1]
FIGURES = (
    "stability.png",
    "throughput.png",
    "work_precision.png",
    "setup_cost.png",
    "torqued_work_precision.png",
    "torqued_energy.png",
    "lightcurve.png",
    "lightcurve_periodogram.png",
    "lightcurve_family.png",
    "lightcurve_family_seed1.png",
    "lightcurve_family_seed2.png",
    "torques_basilisk.png",
    "torques_energy.png",
    "torques_debris.png",
    "posterior_vs_fit.png",
    "posterior_samplers.png",
)
HELP_MARKER = re.compile(r"<!-- frbjax-help:(?P<arguments>[^>]*)-->")


def on_files(files, config):
    for name in FIGURES:
        files.append(File.generated(config, f"images/{name}", abs_src_path=str(ROOT / "benchmarks" / "results" / name)))
    files.append(File.generated(config, "changelog.md", abs_src_path=str(ROOT / "CHANGELOG.md")))
    files.append(File.generated(config, "contributing.md", abs_src_path=str(ROOT / "CONTRIBUTING.md")))
    return files


def _help(arguments):
    from frbjax import cli

    parser = cli.build_parser()
    if arguments:
        # argparse keeps each subcommand's parser in the subparsers action.
        action = next(a for a in parser._actions if a.dest == "command")
        parser = action.choices[arguments[0]]
    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"  # argparse wraps at the terminal width: fix it for the site
    try:
        return parser.format_help()
    finally:
        if previous is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = previous


def on_page_markdown(markdown, page, config, files):
    def replace(match):
        return "```text\n" + _help(match["arguments"].split()).rstrip() + "\n```"

    return HELP_MARKER.sub(replace, markdown)


# What a rendered page may hold a "$" in: code, preformatted blocks, typeset mathematics, scripts.
_EXEMPT = re.compile(r"<(code|pre|script|style)\b.*?</\1>|<(span|div) class=\"arithmatex\">.*?</\2>", re.DOTALL)
_TAGS = re.compile(r"<[^>]+>")
_REST_MATH = re.compile(r":math:|\.\. math::")


def on_page_content(html, page, config, files):
    if not page.file.src_uri.startswith("api/"):
        return html
    text = _TAGS.sub(" ", _EXEMPT.sub(" ", html))
    for line in text.splitlines():
        if "$" in line:
            log.warning(
                f"{page.file.src_uri}: mathematics not typeset (a $ outside $...$ or $$...$$; "
                f'see CONTRIBUTING.md, "Writing docstrings"): {line.strip()[:120]!r}'
            )
    if _REST_MATH.search(text):
        log.info(
            f"{page.file.src_uri}: a docstring still writes mathematics in reST (:math:, .. math::); "
            'CONTRIBUTING.md, "Writing docstrings", has the convention'
        )
    return html
