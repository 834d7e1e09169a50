"""A force log in Parquet (SI columns, units in the schema): :mod:`roboisf.logs.logparquet`.
Chosen by the ``.parquet`` suffix."""

from __future__ import annotations

from roboisf.formats import FileFormat, lazy, register_format

register_format(
    FileFormat(
        name="parquet",
        kind="force_log",
        label="Parquet force log",
        suffixes=(".parquet",),
        reader=lazy("roboisf.logs.forcelog", "read_force_log"),
        writer=lazy("roboisf.logs.logparquet", "write_force_parquet"),
        binary=True,
        rank=1,
        rounding={"time": 0.0, "value": 6e-8},
    )
)
