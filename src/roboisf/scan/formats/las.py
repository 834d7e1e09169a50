"""LAS/LAZ point cloud (``laspy``, optional extra): the scaled coordinates in the declared unit
(LAS carries none)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from roboisf.formats import FileFormat, register_format


def read(path: Path, sample: int | None, seed: int) -> Any:
    """(points (N, 3), normals (N, 3) or None) in the file's unit."""
    from roboisf.scan.readers import read_las_points

    return (read_las_points(path), None)


register_format(
    FileFormat(
        name="las",
        kind="scan",
        label="LAS/LAZ",
        suffixes=(".las", ".laz"),
        reader=read,
        rank=50,
    )
)
