"""STL/OBJ mesh exported by a scanner (``trimesh``): its vertices, or ``sample`` points drawn
uniformly over its faces."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from roboisf.formats import FileFormat, register_format


def read(path: Path, sample: int | None, seed: int) -> Any:
    """(points (N, 3), normals (N, 3) or None) in the file's unit."""
    from roboisf.scan.readers import read_mesh_points

    return read_mesh_points(path, sample, seed)


register_format(
    FileFormat(
        name="mesh",
        kind="scan",
        label="STL/OBJ mesh",
        suffixes=(".stl", ".obj"),
        reader=read,
        rank=60,
    )
)
