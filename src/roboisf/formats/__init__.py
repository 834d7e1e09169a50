"""The registry of file formats (:mod:`roboisf.formats.registry`): every kind of file roboisf
reads or writes — toolpath tables, CNC and robot programs, force logs, joint logs, scans, parts —
one :class:`~roboisf.formats.registry.FileFormat` per format, registered by one module each, as
meshio registers its mesh formats.

This package is the lowest but one: it imports nothing of roboisf but :mod:`roboisf.errors`; the
formats themselves live with what they read (``roboisf.cam.formats``, ``roboisf.logs.formats``,
``roboisf.programs.formats``) and are found by module name (plugin packages), never by an import
arrow up the layers.
"""

from __future__ import annotations

from roboisf.formats.registry import (
    KINDS,
    FileFormat,
    file_formats,
    find_file_format,
    get_file_format,
    lazy,
    register_format,
    unregister_format,
)

__all__ = [
    "KINDS",
    "FileFormat",
    "file_formats",
    "find_file_format",
    "get_file_format",
    "lazy",
    "register_format",
    "unregister_format",
]
