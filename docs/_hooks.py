"""mkdocs hooks: files from outside docs/ and the command's help text, at build time.

- The figures of benchmarks/results (written by the benchmark scripts) and the CHANGELOG at the root
  are added to the site as they are, so that no copy of them is kept under docs/.
- ``<!-- frbjax-help: ARGS -->`` in a page becomes the output of ``frbjax ARGS --help``, so that the
  command-line reference is the parser's own text.
"""

from __future__ import annotations

import os
import pathlib
import re

from mkdocs.structure.files import File

ROOT = pathlib.Path(__file__).resolve().parents[1]
FIGURES = ("stability.png", "throughput.png", "work_precision.png", "setup_cost.png", "torqued_work_precision.png",
           "torqued_energy.png")
HELP_MARKER = re.compile(r"<!-- frbjax-help:(?P<arguments>[^>]*)-->")


def on_files(files, config):
    for name in FIGURES:
        files.append(File.generated(config, f"images/{name}",
                                    abs_src_path=str(ROOT / "benchmarks" / "results" / name)))
    files.append(File.generated(config, "changelog.md", abs_src_path=str(ROOT / "CHANGELOG.md")))
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
