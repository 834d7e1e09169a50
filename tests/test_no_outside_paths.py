"""The code and the docs cite nothing outside the repository.

A reader of a clone has only the clone: a path into the machine the code was written on (a
working folder, a shared folder of notes, the paper's text copy) is a dead reference for them.
The paper is cited by its reference (Bharti et al., Sci. Rep. 14:20291, 2024), not by a file.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# a machine's working folders and the design notes kept beside the repository
OUTSIDE = re.compile(r"/work/|\.\./shared|shared/seed|/tmp/s\d")


def outside_references(root: Path = ROOT) -> list[str]:
    """``"file:line: text"`` for every line of README.md, docs/, src/, benchmarks/ and
    pyproject.toml that names a path outside the repository."""
    files = [root / "README.md", root / "pyproject.toml"]
    for folder, pattern in (("docs", "*.md"), ("src", "*.py"), ("benchmarks", "*.py")):
        files += sorted((root / folder).rglob(pattern))
    found = []
    for f in files:
        if not f.is_file():
            continue
        for i, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1):
            if OUTSIDE.search(line):
                found.append(f"{f.relative_to(root)}:{i}: {line.strip()}")
    return found


def test_nothing_cites_a_path_outside_the_repository():
    found = outside_references()
    assert not found, "paths outside the repository:\n" + "\n".join(found)


def test_the_check_finds_a_shared_folder_in_the_docs(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text("see docs/report.md\n")
    (tmp_path / "docs" / "report.md").write_text("# Report\n\nfrom the notes\n")
    assert outside_references(tmp_path) == []
    (tmp_path / "docs" / "report.md").write_text("# Report\n\nsee ../shared/seed/paper.txt\n")
    assert outside_references(tmp_path) == ["docs/report.md:3: see ../shared/seed/paper.txt"]
