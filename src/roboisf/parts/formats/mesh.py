"""``kind = "mesh"``: a part from a surface mesh (:class:`roboisf.parts.MeshPart`): ``file`` (an
STL/OBJ/PLY, relative to the TOML file; ``.step``/``.stp``/``.iges``/``.igs`` are tessellated
with gmsh to ``tolerance`` mm, default 0.01), optional ``unit`` (default ``"mm"``) and ``orient``
(``"up"`` default, or ``"winding"``); no ``flange_width`` (the flange is in the mesh)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from roboisf.formats import FileFormat, register_format
from roboisf.parts.kind import PartSpec


def build(table: dict[str, Any], where: Path | None, common: dict[str, Any]) -> Any:
    """The mesh part of a ``[part]`` table with the common ``sheet_thickness`` (m)."""
    from roboisf.errors import InputError
    from roboisf.parts.io import part_number, part_string
    from roboisf.parts.mesh import MeshPart

    if not isinstance(table.get("file"), str):
        raise InputError(
            "mesh needs 'file' (an STL/OBJ/PLY/STEP/IGES path)", file=where, field="part.file"
        )
    f = Path(table["file"])
    fpath = f if f.is_absolute() or where is None else where.parent / f
    return MeshPart.from_file(
        fpath,
        unit=part_string(table, "unit", where, "mm"),
        orient=part_string(table, "orient", where, "up"),
        sheet_thickness=common["sheet_thickness"],
        source=str(table["file"]),
        tolerance=part_number(table, "tolerance", where, 0.01) * 1e-3,
    )


register_format(
    FileFormat(
        name="mesh",
        kind="part",
        label="mesh (STL/OBJ/PLY/STEP/IGES)",
        reader=build,
        rank=50,
        spec=PartSpec(keys=frozenset({"file", "unit", "orient", "tolerance"}), flange=False),
    )
)
