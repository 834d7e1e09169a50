"""PLY point cloud or mesh (ascii or binary; ``plyfile``, memory-mapped): vertices and their
normals, or ``sample`` points over the faces."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from roboisf.formats import FileFormat, register_format


def read(path: Path, sample: int | None, seed: int) -> Any:
    """(points (N, 3), normals (N, 3) or None) in the file's unit."""
    from roboisf.scan.readers import read_ply_points

    return read_ply_points(path, sample, seed)


register_format(
    FileFormat(
        name="ply",
        kind="scan",
        label="PLY",
        suffixes=(".ply",),
        reader=read,
        rank=10,
    )
)
