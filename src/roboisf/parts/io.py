"""Part files: a small TOML ``[part]`` table (mm and degrees), and profile CSVs.

Example::

    [part]
    kind = "cone"              # a registered part kind: cone | vwacf | profile | pyramid | mesh
    opening_diameter = 87.0    # mm
    wall_angle = 71.0          # deg
    depth = 102.97             # mm
    sheet_thickness = 1.22     # mm (optional, default 1.22)
    flange_width = 10.0        # mm (optional, default 10)

``vwacf`` takes ``opening_diameter``, ``arc_radius``, ``final_wall_angle``; ``profile`` takes
``file`` (a CSV of ``r,z`` in mm, rim first; relative paths are relative to the TOML file) or
inline ``r = [...]``, ``z = [...]``; ``pyramid`` takes ``top_length``, ``top_width`` (mm),
``wall_angle`` (deg), optional ``wall_angle_y`` (deg, default ``wall_angle``), ``depth`` (mm) and
optional ``corner_radius`` (mm, default 0; see :class:`roboisf.parts.Pyramid`); ``mesh`` takes
``file`` (an STL/OBJ/PLY, relative to the TOML
file; ``.step``/``.stp``/``.iges``/``.igs`` are tessellated with gmsh to ``tolerance`` mm,
default 0.01), optional ``unit`` (default ``"mm"``) and ``orient`` (``"up"`` default, or
``"winding"``; see :class:`roboisf.parts.MeshPart`) and no ``flange_width``.

Each kind is a format of kind ``part`` in the file-format registry (:mod:`roboisf.formats`), one
module each in :mod:`roboisf.parts.formats`: its ``reader(table, where, common) -> Part`` builds
the part from the table (mm, deg; ``common``: ``sheet_thickness`` and ``flange_width`` in m) and
its ``spec`` (:class:`~roboisf.parts.kind.PartSpec`) lists its keys.
"""

from __future__ import annotations

import csv
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from roboisf.errors import InputError
from roboisf.formats import FileFormat, file_formats
from roboisf.io.atomic import atomic_write
from roboisf.io.text import read_text
from roboisf.parts.base import Part
from roboisf.parts.kind import PartSpec
from roboisf.plausible import check_part

__all__ = [
    "PartSpec",
    "load_part",
    "part_files",
    "part_from_dict",
    "part_kinds",
    "part_number",
    "part_numbers",
    "part_string",
    "read_profile_csv",
    "save_part",
]


def part_kinds() -> tuple[str, ...]:
    """The registered part kinds (``[part] kind``), in listing order."""
    return tuple(f.name for f in _part_formats())


def _part_formats() -> tuple[FileFormat, ...]:
    """Registered part kinds: a builder (``reader``) and a :class:`PartSpec`."""
    return tuple(
        f for f in file_formats("part") if f.reader is not None and isinstance(f.spec, PartSpec)
    )


_COMMON = {"kind", "sheet_thickness", "flange_width"}


def read_profile_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a generatrix CSV with header ``r,z`` (mm), rim first. Returns (r, z) in m."""
    path = Path(path)
    if not path.is_file():
        raise InputError("profile file not found", file=path)
    rows: list[tuple[float, float]] = []
    text = read_text(path, what="profile CSV")
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise InputError("profile CSV is empty; expected a header 'r,z' (mm) and rows", file=path)
    reader = csv.reader(lines)
    header = [h.strip().lower() for h in next(reader)]
    if header[:2] != ["r", "z"]:
        raise InputError(f"header must be 'r,z' (mm), got {','.join(header)!r}", file=path, line=1)
    for i, row in enumerate(reader, start=2):
        if len(row) < 2:
            raise InputError(f"expected 2 columns r,z, got {len(row)}", file=path, line=i)
        try:
            r, z = float(row[0]), float(row[1])
        except ValueError:
            raise InputError(f"not a number: {row[:2]}", file=path, line=i) from None
        if not (math.isfinite(r) and math.isfinite(z)):
            raise InputError("NaN or inf", file=path, line=i)
        rows.append((r, z))
    if len(rows) < 2:
        raise InputError("profile needs at least two points", file=path)
    a = np.array(rows) * 1e-3
    return a[:, 0], a[:, 1]


def part_number(
    table: dict[str, Any], key: str, where: Path | None, default: float | None = None
) -> float:
    """``table[key]`` as a finite number (in the file's unit), ``default`` if absent (None:
    required), else an InputError naming ``part.<key>``."""
    if key not in table:
        if default is not None:
            return default
        raise InputError("missing key", file=where, field=f"part.{key}")
    v = table[key]
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise InputError(f"expected a number (finite), got {v!r}", file=where, field=f"part.{key}")
    return float(v)


def part_string(
    table: dict[str, Any], key: str, where: Path | None, default: str | None = None
) -> str:
    """``table[key]`` as a string (TOML string), ``default`` if absent (None: required), else an
    InputError naming ``part.<key>``."""
    if key not in table:
        if default is not None:
            return default
        raise InputError("missing key (a string)", file=where, field=f"part.{key}")
    v = table[key]
    if not isinstance(v, str) or not v:
        raise InputError(f"expected a non-empty string, got {v!r}", file=where, field=f"part.{key}")
    return v


def part_numbers(table: dict[str, Any], key: str, where: Path | None) -> np.ndarray:
    """``table[key]`` as an array of finite numbers (mm), else an InputError naming the key."""
    v = table[key]
    if not (
        isinstance(v, list)
        and all(
            isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) for x in v
        )
    ):
        raise InputError(
            f"expected a list of finite numbers (mm), got {v!r}", file=where, field=f"part.{key}"
        )
    return np.asarray(v, dtype=float)


def part_from_dict(table: dict[str, Any], *, where: str | Path | None = None) -> Part:
    """Build a part from a ``[part]`` table (mm, deg). ``where`` resolves relative files.

    A part no forming cell makes (a sheet 500 mm thick, a depth in µm read as mm) is refused
    with the key and the unit slip that explains it (:func:`roboisf.plausible.check_part`).
    """
    part = _part_from_dict(table, where)
    check_part(part, file=where)
    return part


def _part_from_dict(table: dict[str, Any], where: str | Path | None) -> Part:
    src = Path(where) if where is not None else None
    if not isinstance(table, dict):
        raise InputError(
            f"expected a table [part] with a 'kind', got {table!r}", file=src, field="part"
        )
    kind = table.get("kind")
    fmt = next((f for f in _part_formats() if f.name == kind), None)
    if not isinstance(kind, str) or fmt is None or fmt.reader is None:
        raise InputError(
            f"unknown part kind {kind!r}; expected one of {', '.join(part_kinds())}",
            file=src,
            field="part.kind",
        )
    spec: PartSpec = fmt.spec
    keys = set(spec.keys)
    unknown = set(table) - keys - _COMMON
    if unknown:
        raise InputError(
            f"unknown key(s) {', '.join(sorted(unknown))} for kind {kind!r}; "
            f"expected {', '.join(sorted(keys | _COMMON))}",
            file=src,
            field="part",
        )
    common: dict[str, Any] = {
        "sheet_thickness": part_number(table, "sheet_thickness", src, 1.22) * 1e-3,
        "flange_width": part_number(table, "flange_width", src, 10.0) * 1e-3,
    }
    try:
        if not spec.flange and "flange_width" in table:
            raise InputError(
                f"a {kind} part has no flange_width (its flange is in the {kind})",
                file=src,
                field="part.flange_width",
            )
        part: Part = fmt.reader(table, src, common)
        return part
    except InputError as e:
        if e.file is None and src is not None:
            raise InputError(
                e.message, file=src, field=f"part.{e.field}" if e.field else "part"
            ) from None
        raise


def load_part(path: str | Path) -> Part:
    """Load a part TOML file (see module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise InputError("part file not found", file=path)
    try:
        data = tomllib.loads(read_text(path, what="part TOML"))
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"not valid TOML: {e}", file=path) from None
    if "part" not in data or not isinstance(data["part"], dict):
        raise InputError("missing [part] table", file=path)
    return part_from_dict(data["part"], where=path)


def part_files(path: str | Path) -> list[Path]:
    """The part TOML and the file it refers to (profile CSV, mesh, CAD), if any: the inputs an
    output must never overwrite. A TOML that cannot be read yields just itself (its errors are
    :func:`load_part`'s to report)."""
    path = Path(path)
    files = [path]
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8")).get("part", {})
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return files
    f = table.get("file") if isinstance(table, dict) else None
    if isinstance(f, str):
        fp = Path(f)
        files.append(fp if fp.is_absolute() else path.parent / fp)
    return files


#: Significant digits of the numbers in a written part file: the SI → mm/deg conversion leaves
#: binary noise (0.087 m → 87.00000000000001 mm); 12 digits keep 1e-12 of each value.
PART_DIGITS = 12


def _tidy(value: Any) -> Any:
    """``value`` with every float rounded to :data:`PART_DIGITS` significant digits."""
    if isinstance(value, float):
        return float(f"{value:.{PART_DIGITS}g}")
    if isinstance(value, dict):
        return {k: _tidy(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_tidy(v) for v in value]
    return value


def save_part(part: Part, path: str | Path) -> None:
    """Write ``part`` as a ``[part]`` TOML table (mm, deg), atomically; numbers to
    :data:`PART_DIGITS` significant digits (``opening_diameter = 87.0``, not
    ``87.00000000000001``); a part no forming cell makes is refused first
    (:func:`roboisf.plausible.check_part`)."""
    import tomli_w  # on first use: reading parts needs only the standard library's tomllib

    check_part(part)
    with atomic_write(path, "wb") as fh:
        fh.write(tomli_w.dumps({"part": _tidy(part.to_dict())}).encode())
