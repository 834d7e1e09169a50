"""Write a toolpath in any supported format, chosen by name or by the file suffix.

================  ==========================  ===========================================
format            suffixes                    writer
================  ==========================  ===========================================
``csv``           ``.csv``                    :func:`roboisf.io.toolpath_csv.write_toolpath_csv`
``gcode``         ``.nc .gcode .ngc .tap``    :func:`roboisf.io.gcode.write_gcode`
``rapid``         ``.mod``                    :func:`roboisf.io.rapid.write_rapid`
``krl``           ``.src`` (+ ``.dat``)       :func:`roboisf.io.krl.write_krl`
================  ==========================  ===========================================
"""

from __future__ import annotations

from pathlib import Path

from numpy.typing import ArrayLike

from roboisf.errors import InputError
from roboisf.io.gcode import write_gcode
from roboisf.io.krl import write_krl
from roboisf.io.program import RobotTool
from roboisf.io.rapid import write_rapid
from roboisf.io.toolpath_csv import write_toolpath_csv
from roboisf.toolpath.toolpath import Toolpath

__all__ = ["FORMAT_SUFFIXES", "infer_format", "output_files", "write_toolpath"]

#: Format name → accepted file suffixes (the first is the default).
FORMAT_SUFFIXES: dict[str, tuple[str, ...]] = {
    "csv": (".csv",),
    "gcode": (".nc", ".gcode", ".ngc", ".tap"),
    "rapid": (".mod",),
    "krl": (".src",),
}


def infer_format(path: str | Path, fmt: str | None = None) -> str:
    """Format for ``path``: ``fmt`` if given (checked against the suffix), else from the suffix."""
    suffix = Path(path).suffix.lower()
    if fmt is not None:
        if fmt not in FORMAT_SUFFIXES:
            raise InputError(
                f"unknown format {fmt!r}; expected one of {', '.join(FORMAT_SUFFIXES)}",
                field="format",
            )
        if fmt == "krl" and suffix != ".src":
            raise InputError("a KRL program must be written to a .src file", file=path)
        return fmt
    for name, suffixes in FORMAT_SUFFIXES.items():
        if suffix in suffixes:
            return name
    known = ", ".join(f"{s} ({n})" for n, ss in FORMAT_SUFFIXES.items() for s in ss)
    raise InputError(
        f"cannot tell the format from the suffix {suffix or '(none)'!r}; use one of {known} "
        "or pass --format",
        file=path,
    )


def output_files(path: str | Path, fmt: str) -> list[Path]:
    """Files a write produces (KRL writes the ``.dat`` beside the ``.src``)."""
    path = Path(path)
    return [path, path.with_suffix(".dat")] if fmt == "krl" else [path]


def write_toolpath(
    tp: Toolpath,
    path: str | Path,
    fmt: str | None = None,
    *,
    T_base_work: ArrayLike | None = None,
    tool: RobotTool | None = None,
    tool_rotation: ArrayLike = 0.0,
    safe_height: float = 10e-3,
) -> str:
    """Write ``tp`` to ``path`` in ``fmt`` (inferred from the suffix if None); return the format.

    ``T_base_work``, ``tool`` and ``tool_rotation`` [rad] apply to the robot programs (RAPID,
    KRL); ``safe_height`` [m] to every program format.
    """
    fmt = infer_format(path, fmt)
    if fmt == "csv":
        write_toolpath_csv(tp, path)
    elif fmt == "gcode":
        write_gcode(tp, path, safe_height=safe_height)
    else:
        writer = write_rapid if fmt == "rapid" else write_krl
        writer(
            tp,
            path,
            T_base_work=T_base_work,
            tool=tool,
            tool_rotation=tool_rotation,
            safe_height=safe_height,
        )
    return fmt
