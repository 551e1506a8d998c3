"""A clone of the repository carries everything it reads: no tracked file names a folder beside it.

Developers of frbjax once kept reading material in a sibling folder of the repository; a user's clone
has nothing beside it, so a tracked file that reads or cites that folder (a data path, a "see ..."
in a docstring) is broken for everyone else.  This test reads every tracked file (``git ls-files``;
without git, every file of the tree outside caches and build outputs) and looks for such a reference.
"""

from __future__ import annotations

import pathlib
import re
import shutil
import subprocess


REPOSITORY = pathlib.Path(__file__).resolve().parents[1]

# Built from pieces so that this file does not match its own pattern: the folder's name preceded by
# "../" or by anything that cannot continue an identifier, or the bare name quoted (a path component).
FOLDER = "sha" + "red"
SIBLING_REFERENCE = re.compile(rf"(\.\./|[^a-z_]){FOLDER}/|[\"']{FOLDER}[\"']".encode())

# Without git: what .gitignore leaves out of the tree, and git's own folder.
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


def tracked_files() -> list[pathlib.Path]:
    git = shutil.which("git")
    if git is not None and (REPOSITORY / ".git").exists():
        listing = subprocess.run([git, "ls-files", "-z"], cwd=REPOSITORY, capture_output=True, check=True).stdout
        return [REPOSITORY / name for name in listing.decode().split("\0") if name]
    return [
        path
        for path in REPOSITORY.rglob("*")
        if path.is_file()
        and not any(
            part in UNTRACKED_DIRECTORIES or part.endswith(".egg-info") for part in path.relative_to(REPOSITORY).parts
        )
    ]


def test_pattern_finds_what_it_looks_for():
    """The pattern catches the forms a sibling reference takes, and not a word that merely ends so."""
    for text in (f"../{FOLDER}/reference", f"see {FOLDER}/design/x.md", f'parent / "{FOLDER}" / "x"', f"`{FOLDER}/x`"):
        assert SIBLING_REFERENCE.search(text.encode()), text
    for text in (f"un{FOLDER}/x", f"not_{FOLDER}/x", f"{FOLDER} memory"):
        assert not SIBLING_REFERENCE.search(text.encode()), text


def test_no_tracked_file_names_a_folder_beside_the_repository():
    files = tracked_files()
    assert len(files) > 50, f"only {len(files)} files found under {REPOSITORY}"
    offenders = []
    for path in files:
        if not path.is_file():  # a tracked file deleted in the working tree
            continue
        for number, line in enumerate(path.read_bytes().splitlines(), start=1):
            if SIBLING_REFERENCE.search(line):
                offenders.append(f"{path.relative_to(REPOSITORY)}:{number}: {line[:120]!r}")
    assert not offenders, "files that name a folder beside the repository:\n" + "\n".join(offenders)
