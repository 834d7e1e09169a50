"""The ``-o``/``--overwrite`` options and the check every command makes before computing.

Policy (docs/conventions.md, "Outputs"; implemented in :mod:`roboisf.io.outdir`): a folder output
must be new, empty or a previous result of the same command unless ``--overwrite``, and roboisf
never removes or changes a file it did not write; a file output that exists needs
``--overwrite``. Both are checked, and locked against a second run, before any computation.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Annotated

import typer

from roboisf.io.outdir import claim_output_dir, claim_output_file

__all__ = ["DIR_HELP", "FILE_HELP", "Overwrite", "output_dir", "output_file", "study_inputs"]

#: Appended to the help of a folder ``-o``.
DIR_HELP = (
    "Created if new; a previous result of this command there is replaced when the new one is "
    "complete. Files roboisf did not write are never touched."
)
#: Appended to the help of a file ``-o``.
FILE_HELP = "An existing file is replaced only with --overwrite."

Overwrite = Annotated[
    bool,
    typer.Option(
        "--overwrite",
        help="Write into an -o that holds something else (a non-empty folder that is not a "
        "result of this command, or an existing file). Only files roboisf wrote are replaced; "
        "your own files in the folder stay as they are.",
    ),
]

#: ``--png``: static PNG figures beside the HTML page, on request. The page's plotly figures need
#: none (each has its own PNG download button); matplotlib's import and drawing were ~1 s of the
#: paper cone's ~6 s ``analyze`` (docs/speed.md), so a command draws them only when asked.
Png = Annotated[
    bool,
    typer.Option(
        "--png/--no-png",
        help="Also write static PNG figures (matplotlib, for print and papers). The HTML "
        "report's own figures each have a PNG download button.",
    ),
]


def study_inputs(study: Path | None) -> list[Path]:
    """A study argument (folder or its study.toml) as inputs: the study folder either way.

    Checks first that it has a ``study.toml`` that parses as TOML (InputError → exit 2): before
    the command imports its numeric libraries, so that a mistyped path is reported at once."""
    if study is None:
        return []
    from roboisf.study.locate import read_study_toml

    read_study_toml(study)
    return [study, study.parent] if study.suffix.lower() == ".toml" else [study]


def output_dir(
    path: Path, command: str, overwrite: bool, inputs: Sequence[Path | str | None] = ()
) -> Path:
    """Check and lock the output folder ``path`` of ``command`` (InputError → exit 2)."""
    claim_output_dir(path, command, overwrite=overwrite, inputs=[p for p in inputs if p])
    return path


def output_file(
    path: Path, command: str, overwrite: bool, inputs: Sequence[Path | str | None] = ()
) -> Path:
    """Check and lock the output file ``path`` of ``command`` (InputError → exit 2)."""
    claim_output_file(path, command, overwrite=overwrite, inputs=[p for p in inputs if p])
    return path
