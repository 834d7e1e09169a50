"""E57 scans (``pye57``, optional extra ``roboisf[scan-formats]``): every scan with its pose
applied. Metres by the standard (ASTM E2807): the declared unit does not apply."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from roboisf.formats import FileFormat, register_format
from roboisf.scan.formatspec import ScanSpec


def read(path: Path, sample: int | None, seed: int) -> Any:
    """(points (N, 3), normals (N, 3) or None) in the file's unit."""
    from roboisf.scan.readers import read_e57_points

    return (read_e57_points(path), None)


register_format(
    FileFormat(
        name="e57",
        kind="scan",
        label="E57",
        suffixes=(".e57",),
        reader=read,
        rank=40,
        spec=ScanSpec("m", "metres", "by the standard"),
    )
)
