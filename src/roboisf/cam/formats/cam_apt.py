"""APT / CL data (``GOTO/``, ``FEDRAT/``, ``TLAXIS/`` …): :mod:`roboisf.cam.apt`. Recognised by an
APT statement in the head."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from roboisf.cam.camformat import CamSpec, head_lines
from roboisf.formats import FileFormat, register_format

_HINT = re.compile(r"^\s*(GOTO|FEDRAT|TLAXIS|MULTAX|PARTNO|FROM|RAPID|UNITS)\s*(/|$)", re.I)


def has_apt_words(head: list[str]) -> bool:
    """Whether a line of ``head`` is an APT statement."""
    return any(_HINT.match(ln) for ln in head)


def detect(path: Path) -> bool:
    return has_apt_words(head_lines(path))


def read(path: Path, options: Any, *, units: str | None, feed: float) -> Any:
    from roboisf.cam.apt import read_apt_moves

    return read_apt_moves(path, options)


register_format(
    FileFormat(
        name="apt",
        kind="cnc",
        label="APT/CL data",
        suffixes=(".apt", ".cls", ".cl", ".aptsource", ".clt"),
        reader=read,
        detect=detect,
        rank=20,
        spec=CamSpec(),
    )
)
