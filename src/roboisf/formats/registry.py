"""One registry of file formats, of every kind, one module per format.

A :class:`FileFormat` names a format (``name``, unique within its ``kind``), the ``suffixes`` it
is written with, its ``reader``/``writer`` where one exists, a ``detect`` that sniffs a file's head
and the ``companions`` written beside the main file. Kind-specific data (a force-log profile's
column matchers, a program format's write options) rides in ``spec``.

The built-in formats are the modules of the plugin packages in :data:`PLUGIN_PACKAGES`; each
module registers its format(s) with :func:`register_format` when imported, and the registry
imports them all on first use. A user's format registers itself the same way. Everything that
lists or detects formats — readers' auto-detection, exports, the virtual cell's log writers, the
CLI's help — loops over :func:`file_formats`, so a new format is one new module.

This module imports nothing heavy (no numpy): a format's reader and writer load their module on
first use (:func:`lazy`).
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from roboisf.errors import InputError

__all__ = [
    "KINDS",
    "PLUGIN_PACKAGES",
    "FileFormat",
    "file_formats",
    "find_file_format",
    "get_file_format",
    "lazy",
    "register_format",
    "unregister_format",
]

#: What a file holds: roboisf's toolpath table, a CNC program, a robot program, a force log, a
#: joint log, a scan (point cloud) or a part (its geometry).
KINDS = ("toolpath", "cnc", "robot", "force_log", "joint_log", "scan", "part")
Kind = Literal["toolpath", "cnc", "robot", "force_log", "joint_log", "scan", "part"]

#: The packages whose every module registers built-in formats (imported on first use, by name).
PLUGIN_PACKAGES = (
    "roboisf.cam.formats",
    "roboisf.logs.formats",
    "roboisf.parts.formats",
    "roboisf.programs.formats",
    "roboisf.scan.formats",
)


def lazy(module: str, name: str) -> Callable[..., Any]:
    """``module.name`` as a function that imports ``module`` on its first call (a format's
    module registers its reader and writer without importing numpy or pandas)."""

    def call(*args: Any, **kwargs: Any) -> Any:
        return getattr(importlib.import_module(module), name)(*args, **kwargs)

    call.__name__ = call.__qualname__ = name
    call.__doc__ = f"{module}.{name}, imported on the first call."
    return call


@dataclass(frozen=True)
class FileFormat:
    """One file format.

    Attributes
    ----------
    name : the format's name within its kind (``"ati"``, ``"krl"``); a study's ``format`` key
    kind : one of :data:`KINDS`
    label : what the format is called in messages and help (``"ATI Net F/T CSV"``)
    suffixes : file suffixes, lower case with the dot, the first the default; ``()``: any
    reader : reads a file (signature per kind: a force log's ``read(path, **units) -> ForceLog``)
    writer : writes one (signature per kind: a force log's ``write(log, path)``), or None
    detect : ``detect(path) -> bool``, sniffing the file's head; None: chosen by suffix or by the
        kind's own detection (``spec``)
    companions : suffixes of files always written beside the main one (KRL's ``.dat``)
    rank : detection and listing order (lower first); ties by name
    binary : the format is not text (Parquet): chosen by suffix only
    rounding : what a round trip through the writer and the reader may change, by quantity:
        ``time`` absolute [s], ``angle`` absolute [rad], ``value`` relative (forces, moments);
        None: not stated (no writer)
    spec : kind-specific description (a force-log profile's column matchers, a
        ``roboisf.programs.registry.ProgramFormat``)
    """

    name: str
    kind: Kind
    label: str
    suffixes: tuple[str, ...] = ()
    reader: Callable[..., Any] | None = None
    writer: Callable[..., Any] | None = None
    detect: Callable[[Path], bool] | None = None
    companions: tuple[str, ...] = ()
    rank: int = 100
    binary: bool = False
    rounding: dict[str, float] | None = None
    spec: Any = None

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"format name {self.name!r} is not an identifier")
        if self.kind not in KINDS:
            raise ValueError(f"format {self.name!r}: kind {self.kind!r} not in {KINDS}")
        bad = [s for s in (*self.suffixes, *self.companions) if not _is_suffix(s)]
        if bad:
            raise ValueError(
                f"format {self.name!r}: suffixes must be lower case and start with '.', got {bad}"
            )

    def output_files(self, path: Path) -> list[Path]:
        """The main file and its companions."""
        return [path, *(path.with_suffix(s) for s in self.companions)]


def _is_suffix(s: str) -> bool:
    return s.startswith(".") and len(s) > 1 and s == s.lower()


_FORMATS: dict[tuple[str, str], FileFormat] = {}
_loaded = False


def _load_builtins() -> None:
    """Import every module of the :data:`PLUGIN_PACKAGES` (each registers its formats)."""
    global _loaded
    if _loaded:
        return
    _loaded = True
    for package in PLUGIN_PACKAGES:
        pkg = importlib.import_module(package)
        for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
            importlib.import_module(f"{package}.{info.name}")


def register_format(fmt: FileFormat) -> FileFormat:
    """Add ``fmt``; returns it. A name already taken within the kind is a ``ValueError``."""
    _load_builtins()
    key = (fmt.kind, fmt.name)
    if key in _FORMATS:
        raise ValueError(f"a {fmt.kind} format named {fmt.name!r} is already registered")
    _FORMATS[key] = fmt
    return fmt


def unregister_format(kind: str, name: str) -> None:
    """Remove the ``kind`` format ``name`` (a test's toy format); unknown names are ignored."""
    _FORMATS.pop((kind, name), None)


def file_formats(*kinds: str) -> tuple[FileFormat, ...]:
    """The registered formats of ``kinds`` (all kinds if none), in order (``rank``, name)."""
    unknown = [k for k in kinds if k not in KINDS]
    if unknown:
        raise ValueError(f"unknown format kind {unknown[0]!r}; expected one of {KINDS}")
    _load_builtins()
    found = (f for f in _FORMATS.values() if not kinds or f.kind in kinds)
    return tuple(sorted(found, key=lambda f: (f.rank, f.name, f.kind)))


def get_file_format(kind: str, name: str, *, field: str = "format") -> FileFormat:
    """The ``kind`` format called ``name``; ``InputError`` (``field``) listing the known ones."""
    _load_builtins()
    fmt = _FORMATS.get((kind, name))
    if fmt is None:
        names = ", ".join(f.name for f in file_formats(kind))
        what = kind.replace("_", " ")
        raise InputError(f"unknown {what} format {name!r}; expected one of {names}", field=field)
    return fmt


def find_file_format(path: str | Path, *kinds: str) -> FileFormat | None:
    """The first format of ``kinds`` (in rank order) whose ``detect`` accepts ``path`` — a
    format without ``detect`` accepts by suffix when it lists suffixes; None if none does."""
    p = Path(path)
    suffix = p.suffix.lower()
    for fmt in file_formats(*kinds):
        if fmt.detect is not None:
            if fmt.detect(p):
                return fmt
        elif fmt.suffixes and suffix in fmt.suffixes:
            return fmt
    return None
