"""Siemens Sinumerik part program (``.mpf``/``.spf``): :mod:`roboisf.cam.sinumerik`. Recognised by
its suffix, or — when the head has no APT words — by ``%_N_``, ``;$PATH``, ``X=`` words,
``CR=``, ``G641``…``G645``, ``CYCLE…``, ``SOFT``, ``FFWON`` or ``MSG(``."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from roboisf.cam.camformat import CamSpec, code_lines, head_lines
from roboisf.formats import FileFormat, register_format

SUFFIXES = (".mpf", ".spf")
_HINT = re.compile(
    r"(^%_N_|^;\$PATH|\b[XYZIJKF]\s*=|\bCR\s*=|\bG64[1-5]\b|\bCYCLE\d|\bSOFT\b|\bFFWON\b|\bMSG\s*\()",
    re.I,
)


def detect(path: Path) -> bool:
    if path.suffix.lower() in SUFFIXES:
        return True
    from roboisf.cam.formats.cam_apt import has_apt_words

    head = head_lines(path)
    return not has_apt_words(head) and any(_HINT.search(ln) for ln in code_lines(head))


def read(path: Path, options: Any, *, units: str | None, feed: float) -> Any:
    from roboisf.cam.sinumerik import read_sinumerik_moves

    return read_sinumerik_moves(path, options)


register_format(
    FileFormat(
        name="sinumerik",
        kind="cnc",
        label="Sinumerik part program",
        suffixes=SUFFIXES,
        reader=read,
        detect=detect,
        rank=10,
        spec=CamSpec(),
    )
)
