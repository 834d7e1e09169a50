"""Find and parse a study's ``study.toml`` without the numeric stack.

The commands that take a STUDY argument check it first (no such folder, no ``study.toml``, not
TOML) so that a mistyped path is reported at once (issue #16: bad input in ≤ 0.3 s), not after
the seconds the analysis's libraries take to import. :func:`roboisf.study.load_study` validates
the contents.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from roboisf.errors import InputError
from roboisf.io.text import read_text

__all__ = ["STUDY_FILE", "read_study_toml", "study_file"]

#: The file a study folder is recognised by.
STUDY_FILE = "study.toml"


def study_file(path: str | Path) -> Path:
    """A study folder's ``study.toml`` (or ``path`` itself when it names the file).

    Raises
    ------
    InputError
        when there is no such file.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(
            f"no such study folder (or {STUDY_FILE}): check the path; `roboisf study init` "
            "drafts a study from a folder of your cell's files",
            file=path,
        )
    file = path / STUDY_FILE if path.is_dir() else path
    if not file.is_file():
        raise InputError(f"no {STUDY_FILE} in this folder", file=file)
    return file


def read_study_toml(path: str | Path) -> tuple[Path, dict[str, Any]]:
    """``(file, tables)``: the study's ``study.toml`` located and parsed (not yet validated).

    Raises
    ------
    InputError
        when there is no ``study.toml``, it cannot be decoded, or it is not valid TOML.
    """
    file = study_file(path)
    try:
        return file, tomllib.loads(read_text(file, what=STUDY_FILE))
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"not valid TOML: {e}", file=file) from None
