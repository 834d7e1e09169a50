"""``kind = "profile"``: any axisymmetric part from its generatrix
(:class:`roboisf.parts.ProfilePart`): ``file`` (a CSV of ``r,z`` in mm, rim first, relative to
the TOML file) or inline ``r = [...]``, ``z = [...]`` (mm)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from roboisf.formats import FileFormat, register_format
from roboisf.parts.kind import PartSpec


def build(table: dict[str, Any], where: Path | None, common: dict[str, Any]) -> Any:
    """The profile part of a ``[part]`` table (mm) with the ``common`` keys (m)."""
    from roboisf.errors import InputError
    from roboisf.parts.axisymmetric import ProfilePart
    from roboisf.parts.io import part_numbers, part_string, read_profile_csv

    if "file" in table:
        f = Path(part_string(table, "file", where))
        fpath = f if f.is_absolute() or where is None else where.parent / f
        r, z = read_profile_csv(fpath)
        return ProfilePart(r=tuple(r), z=tuple(z), source=str(table["file"]), **common)
    if "r" not in table or "z" not in table:
        raise InputError("profile needs 'file' or both 'r' and 'z'", file=where, field="part")
    r = part_numbers(table, "r", where) * 1e-3
    z = part_numbers(table, "z", where) * 1e-3
    return ProfilePart(r=tuple(r), z=tuple(z), **common)


register_format(
    FileFormat(
        name="profile",
        kind="part",
        label="profile (generatrix)",
        reader=build,
        rank=30,
        spec=PartSpec(keys=frozenset({"file", "r", "z"})),
    )
)
