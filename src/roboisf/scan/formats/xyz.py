"""XYZ/CSV/TXT/ASC point list, Leica ``.pts`` (``pandas``): any separator, an optional header
``x,y,z[,nx,ny,nz]``, decimal commas."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from roboisf.formats import FileFormat, register_format


def read(path: Path, sample: int | None, seed: int) -> Any:
    """(points (N, 3), normals (N, 3) or None) in the file's unit."""
    from roboisf.scan.readers import read_xyz_points

    return read_xyz_points(path)


register_format(
    FileFormat(
        name="xyz",
        kind="scan",
        label="XYZ point list",
        suffixes=(".xyz", ".csv", ".txt", ".asc", ".pts"),
        reader=read,
        rank=30,
    )
)
