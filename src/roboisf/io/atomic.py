"""Atomic file output: write to a temporary file in the target folder, then rename.

A crash or an error half-way leaves the old file (or nothing), never a half-written one. The
policy of where roboisf may write (markers, locks, signals) is :mod:`roboisf.io.outdir`.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import IO

from roboisf.errors import InputError
from roboisf.io.outdir import deferred_signals, mark_written, staged_output_dir

__all__ = ["atomic_path", "atomic_write", "check_not_input", "staged_directory"]


def _default_mode(base: int) -> int:
    """``base`` (0o666 files, 0o777 folders) under the process umask — what open()/mkdir() give.

    mkstemp/mkdtemp create private 0o600/0o700 entries; renamed into place as they are, a user's
    output files would be unreadable to colleagues and web servers.
    """
    mask = os.umask(0)
    os.umask(mask)
    return base & ~mask


def check_not_input(output: str | Path, inputs: Sequence[str | Path]) -> None:
    """Refuse to write ``output`` over one of ``inputs`` (never overwrite an input)."""
    out = Path(output).resolve()
    for item in inputs:
        if Path(item).resolve() == out:
            raise InputError("output would overwrite an input file; choose another -o", file=output)


@contextlib.contextmanager
def atomic_path(path: str | Path, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success rename it onto ``path``.

    Use for libraries that want a file name (pyarrow, matplotlib). On an exception the temporary
    file is removed and ``path`` is untouched.
    """
    path = Path(path)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    tmp_path: Path | None = None
    try:
        with deferred_signals():  # a signal right after mkstemp still finds `tmp_path` set
            fd, tmp = tempfile.mkstemp(
                prefix=f".{path.name}.", suffix=suffix or path.suffix or ".tmp", dir=path.parent
            )
            os.close(fd)
            tmp_path = Path(tmp)
        yield tmp_path
        os.chmod(tmp_path, _default_mode(0o666))
        os.replace(tmp_path, path)
        mark_written(path)
    except BaseException:
        if tmp_path is not None:
            with contextlib.suppress(FileNotFoundError):
                tmp_path.unlink()
        raise


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "w", encoding: str | None = "utf-8") -> Iterator[IO]:
    """Open a temporary file for writing; rename it onto ``path`` when the block succeeds."""
    if "b" in mode:
        encoding = None
    newline = "" if "b" not in mode else None
    with atomic_path(path) as tmp, open(tmp, mode, encoding=encoding, newline=newline) as fh:
        yield fh


@contextlib.contextmanager
def staged_directory(
    path: str | Path, command: str | None = None, *, overwrite: bool = False
) -> Iterator[Path]:
    """Build a whole output folder in a sibling staging folder, then move it into place.

    The output policy of :mod:`roboisf.io.outdir`: ``path`` must be new, empty or a previous
    result of ``command`` (its marker) unless ``overwrite``; only files roboisf wrote there are
    replaced, a user's files are kept. On an error or interruption the staging folder is removed
    and ``path`` is left as it was. Inside a command that claimed ``path``
    (:func:`roboisf.io.outdir.claim_output_dir`) that claim's command and ``overwrite`` apply.
    """
    with staged_output_dir(path, command, overwrite=overwrite) as stage:
        yield stage
