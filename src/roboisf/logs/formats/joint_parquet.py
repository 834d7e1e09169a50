"""A joint log in Parquet (SI columns, units in the schema): :mod:`roboisf.logs.logparquet`.
Chosen by the ``.parquet`` suffix."""

from __future__ import annotations

from roboisf.formats import FileFormat, lazy, register_format

register_format(
    FileFormat(
        name="parquet",
        kind="joint_log",
        label="Parquet joint log",
        suffixes=(".parquet",),
        reader=lazy("roboisf.logs.jointlog", "read_joint_log"),
        writer=lazy("roboisf.logs.logparquet", "write_joint_parquet"),
        binary=True,
        rank=1,
        rounding={"time": 0.0, "angle": 2.1e-7},
    )
)
