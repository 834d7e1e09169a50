"""Text files at the boundary: UTF-8 (with or without a byte-order mark), nothing else.

Every roboisf text input (TOML, CSV logs, profiles) is UTF-8. Editors on Windows often save UTF-8
with a byte-order mark (``EF BB BF``); it is stripped. Any other encoding (Latin-1, UTF-16, a
binary file given by mistake) is refused with the file, the line and the byte offset of the
first byte that is not UTF-8, instead of a ``UnicodeDecodeError`` from deep inside a parser.
"""

from __future__ import annotations

import codecs
from pathlib import Path

from roboisf.errors import InputError

__all__ = ["decode_utf8", "read_text"]


def decode_utf8(data: bytes, *, file: str | Path | None, what: str = "file") -> str:
    """``data`` decoded as UTF-8 (a leading BOM removed).

    Raises
    ------
    InputError
        naming ``file``, the 1-based line and the byte offset of the first invalid byte.
    """
    if data.startswith(codecs.BOM_UTF8):
        data = data[len(codecs.BOM_UTF8) :]
        skipped = len(codecs.BOM_UTF8)
    else:
        skipped = 0
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        hint = ""
        if data[:2] in (codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE):
            hint = " (the file is UTF-16; save it as UTF-8)"
        raise InputError(
            f"{what} is not UTF-8 text: byte 0x{data[e.start]:02x} at byte offset "
            f"{e.start + skipped} ({e.reason}){hint}; save it as UTF-8",
            file=file,
            line=line,
        ) from None


def read_text(path: str | Path, *, what: str = "file") -> str:
    """The text of ``path`` (UTF-8, BOM stripped); see :func:`decode_utf8`."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as e:
        raise InputError(f"cannot read {what}: {e.strerror}", file=p) from None
    return decode_utf8(data, file=p, what=what)
