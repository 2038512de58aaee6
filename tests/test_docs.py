"""The documentation as a guide (issue 29): its example output is what the commands print
now, and it refers to no document outside the repository."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve()  # it spells the pattern out
REPO = HERE.parents[1]
BINARY = {".png", ".pt", ".rrd", ".tlog"}
SKIP_DIRS = {".git", "build", "dist", "runs", "__pycache__", "node_modules"}
# A reference to the contracts file that lived beside the repository (../shared/SPEC.md):
# "SPEC §4", "SPEC "Encounter campaigns"", "the SPEC's names", "SPEC.md". Words that merely
# contain the letters (TURB_MILSPEC, SPECIAL) are not references.
OUTSIDE = re.compile(r"\bSPEC\b|SPEC\.md|\.\./shared/")


def _repo_text_files() -> list[Path]:
    found = []
    for path in REPO.rglob("*"):
        rel = path.relative_to(REPO)
        parts = rel.parts
        if any(p in SKIP_DIRS or p.startswith(".venv") or p.endswith(".egg-info") for p in parts):
            continue
        if path.is_file() and path.suffix not in BINARY and path != HERE:
            found.append(path)
    return found


def test_no_file_refers_to_a_document_outside_the_repository() -> None:
    hits = []
    for path in _repo_text_files():
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, OSError):
            continue  # binary data
        for n, line in enumerate(text.splitlines(), 1):
            if OUTSIDE.search(line):
                hits.append(f"{path.relative_to(REPO)}:{n}: {line.strip()[:100]}")
    assert len(_repo_text_files()) > 200  # the walk saw the repository
    assert hits == [], "\n".join(hits)


def test_the_outside_pattern_finds_what_it_is_for() -> None:
    """The pattern above could fail to match and the test would pass on anything."""
    for ref in ("(SPEC §7)", 'SPEC "Encounter campaigns"', "the SPEC's names", "../shared/SPEC.md"):
        assert OUTSIDE.search(ref), ref
    for word in ("TURB_MILSPEC = 3", "SPECIAL, EXEMPLARY", "spec", "inspect"):
        assert not OUTSIDE.search(word), word


def test_readme_examples_are_what_the_commands_print() -> None:
    """The cheap README example blocks (a head-on encounter flown in JSBSim and a decision of it
    explained) are run again and compared; docs/examples/regenerate.py names a stale block."""
    proc = subprocess.run(
        [sys.executable, str(REPO / "docs" / "examples" / "regenerate.py"), "--check", "--cheap"],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
