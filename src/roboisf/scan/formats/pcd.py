"""PCD point cloud (``DATA ascii`` or ``binary``; ``binary_compressed`` needs re-saving)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from roboisf.formats import FileFormat, register_format


def read(path: Path, sample: int | None, seed: int) -> Any:
    """(points (N, 3), normals (N, 3) or None) in the file's unit."""
    from roboisf.scan.readers import read_pcd_points

    return read_pcd_points(path)


register_format(
    FileFormat(
        name="pcd",
        kind="scan",
        label="PCD",
        suffixes=(".pcd",),
        reader=read,
        rank=20,
    )
)
