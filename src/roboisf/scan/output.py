"""Deviation tables (Parquet or CSV, mm, units in the metadata) and the JSON summary.

Parquet: schema metadata ``roboisf.units`` = JSON ``{column: unit}``, ``roboisf.frame`` =
``"work"``, ``roboisf.kind`` = ``"toolpath_deviations" | "point_deviations"``, and each field's
own metadata ``unit``. CSV: ``# key: value`` comment lines first (``# units: …``,
``# frame: work``, ``# kind: …``), then the header. Files are written atomically.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from roboisf.errors import InputError
from roboisf.io.atomic import atomic_path, atomic_write
from roboisf.io.jsonvalues import jsonable
from roboisf.scan.deviation import PointDeviations, ToolpathDeviations

__all__ = [
    "POINT_COLUMNS",
    "TOOLPATH_COLUMNS",
    "jsonable",
    "point_table",
    "toolpath_table",
    "write_summary_json",
    "write_table",
]

#: Per-toolpath-point table: column → unit.
TOOLPATH_COLUMNS = {
    "index": "1",
    "contact_x": "mm",
    "contact_y": "mm",
    "contact_z": "mm",
    "dx": "mm",
    "dy": "mm",
    "dz": "mm",
    "dn": "mm",
    "n_points": "1",
    "valid": "bool",
    "spread": "mm",
}

#: Per-scan-point table: column → unit.
POINT_COLUMNS = {
    "x": "mm",
    "y": "mm",
    "z": "mm",
    "dx": "mm",
    "dy": "mm",
    "dz": "mm",
    "dn": "mm",
    "depth": "mm",
    "angle": "deg",
}


def toolpath_table(tdev: ToolpathDeviations) -> pd.DataFrame:
    """Per-toolpath-point table (mm), rows in toolpath order."""
    d = tdev.delta * 1e3
    c = tdev.contact * 1e3
    return pd.DataFrame(
        {
            "index": np.arange(c.shape[0], dtype=np.int64),
            "contact_x": c[:, 0],
            "contact_y": c[:, 1],
            "contact_z": c[:, 2],
            "dx": d[:, 0],
            "dy": d[:, 1],
            "dz": d[:, 2],
            "dn": tdev.dn * 1e3,
            "n_points": tdev.n_points,
            "valid": tdev.valid,
            "spread": tdev.spread * 1e3,
        }
    )


def point_table(dev: PointDeviations) -> pd.DataFrame:
    """Per-scan-point table (mm, deg)."""
    p = dev.points * 1e3
    d = dev.delta * 1e3
    return pd.DataFrame(
        {
            "x": p[:, 0],
            "y": p[:, 1],
            "z": p[:, 2],
            "dx": d[:, 0],
            "dy": d[:, 1],
            "dz": d[:, 2],
            "dn": dev.dn * 1e3,
            "depth": dev.depth * 1e3,
            "angle": np.degrees(np.mod(dev.angle, 2 * math.pi)),
        }
    )


def write_table(df: pd.DataFrame, path: str | Path, units: dict[str, str], kind: str) -> None:
    """Write ``df`` atomically as Parquet (``.parquet``/``.pq``) or CSV (``.csv``)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".parquet", ".pq"):
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.Table.from_pandas(df, preserve_index=False)
        fields = [f.with_metadata({"unit": units.get(f.name, "")}) for f in table.schema]
        meta = dict(table.schema.metadata or {})
        meta.update(
            {
                b"roboisf.units": json.dumps(units).encode(),
                b"roboisf.frame": b"work",
                b"roboisf.kind": kind.encode(),
            }
        )
        table = table.cast(pa.schema(fields, metadata=meta))
        with atomic_path(path) as tmp:
            pq.write_table(table, tmp)
    elif suffix == ".csv":
        with atomic_write(path, "w") as fh:
            fh.write("# units: " + " ".join(f"{k}={v}" for k, v in units.items()) + "\n")
            fh.write("# frame: work\n")
            fh.write(f"# kind: {kind}\n")
            df.to_csv(fh, index=False, float_format="%.6f", lineterminator="\n")
    else:
        raise InputError(
            f"unknown table format {path.suffix!r}; expected .parquet or .csv", file=path
        )


def write_summary_json(summary: dict[str, Any], path: str | Path) -> None:
    """Write the summary dict as JSON (atomically; non-finite numbers become null)."""
    with atomic_write(path, "w") as fh:
        json.dump(jsonable(summary), fh, indent=2)
        fh.write("\n")
