"""Toolpath CSV: the exchange format of roboisf toolpaths (mm, degrees, seconds).

Layout::

    # roboisf toolpath
    # units: length=mm angle=deg time=s
    # tool_radius: 5 mm
    # feed: 750 mm/min
    # generator: roboisf 0.1.0
    # path_kind: step_down
    index,lap,contact_x,contact_y,contact_z,normal_x,normal_y,normal_z,center_x,center_y,center_z,tip_x,tip_y,tip_z,wall_angle_deg,depth,path_length,time
    0,0,43.327...,0,-0.5,-0.945...,0,0.325...,38.6...,...

* ``contact`` — contact point on the nominal (tool-side) surface; ``normal`` — unit tool-side
  normal there; ``center`` — ball centre C; ``tip`` — programmed tool tip (TCP) T = C − R ẑ.
* ``depth`` = −contact_z; ``path_length`` — cumulative tip-path length; ``time`` = path_length/feed.
* The ``#`` lines are optional. Without ``tool_radius`` the radius is |center − contact| (mean
  over the rows), without ``feed`` it is ``path_length/time`` at the last row.
* ``# center_from_contact: false`` marks a *commanded* (e.g. compensated) path whose centre and
  tip were moved away from ``contact + R·n``; the reader then skips that consistency check.

Numbers are written at 1e-9 mm (lengths), 1e-12 (normals) and 1e-9 s resolution, so a round trip
is exact to ≈ 1e-12 m. Files written by other tools at coarser resolution are accepted: normals
must be unit to ``NORMAL_TOL`` (then renormalised) and the centre/tip consistent to
``CONSISTENCY_TOL``.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from roboisf import __version__
from roboisf.errors import InputError
from roboisf.io.atomic import atomic_write
from roboisf.io.table import Table, finite_float, format_rows, read_table
from roboisf.io.units import to_si
from roboisf.path.toolpath import Toolpath

__all__ = [
    "CONSISTENCY_TOL",
    "NORMAL_TOL",
    "TOOLPATH_COLUMNS",
    "read_toolpath_csv",
    "toolpath_table",
    "write_toolpath_csv",
]

#: The fixed header (mm, deg, s).
TOOLPATH_COLUMNS = (
    "index,lap,contact_x,contact_y,contact_z,normal_x,normal_y,normal_z,center_x,center_y,"
    "center_z,tip_x,tip_y,tip_z,wall_angle_deg,depth,path_length,time"
).split(",")

#: Accepted deviation of |normal| from 1 (files written at 1e-3 resolution pass).
NORMAL_TOL = 2e-3
#: Accepted inconsistency [m] of centre vs contact + R·n, tip vs centre − R ẑ, depth vs −z (10 µm).
CONSISTENCY_TOL = 10e-6

_FORMATS = (
    ["%d", "%d"] + ["%.9f"] * 3 + ["%.12f"] * 3 + ["%.9f"] * 6 + ["%.9f", "%.9f", "%.9f", "%.9f"]
)
_DECIMALS = [int(f[2:-1]) if f != "%d" else 0 for f in _FORMATS]
_UNITS_LINE = "length=mm angle=deg time=s"


def _fmt_num(v: float) -> str:
    return f"{v:.12g}"


def toolpath_table(tp: Toolpath) -> np.ndarray:
    """The CSV columns of ``tp`` as an (N, 18) array in file units (mm, deg, s)."""
    return np.column_stack(
        [
            np.arange(len(tp)),
            tp.lap,
            tp.contact * 1e3,
            tp.normal,
            tp.center * 1e3,
            tp.tip * 1e3,
            np.degrees(tp.wall_angle),
            -tp.contact[:, 2] * 1e3,
            tp.path_length * 1e3,
            tp.time,
        ]
    )


def write_toolpath_csv(tp: Toolpath, path: str | Path, *, generator: str | None = None) -> None:
    """Write ``tp`` as a toolpath CSV (atomically). See the module docstring for the layout.

    Parameters
    ----------
    tp : the toolpath (SI inside)
    path : output file
    generator : text for the ``# generator:`` line (default ``roboisf <version>``)
    """
    resid = tp.center - (tp.contact + tp.tool_radius * tp.normal)
    from_contact = bool(np.max(np.linalg.norm(resid, axis=1)) <= 1e-9)
    head = [
        "# roboisf toolpath",
        f"# units: {_UNITS_LINE}",
        f"# tool_radius: {_fmt_num(tp.tool_radius * 1e3)} mm",
        f"# feed: {_fmt_num(tp.feed * 60e3)} mm/min",
        f"# generator: {generator or f'roboisf {__version__}'}",
    ]
    if not from_contact:
        head.append("# center_from_contact: false")
    for key in ("kind", "part"):
        if key in tp.meta:
            head.append(f"# path_{key}: {tp.meta[key]}")
    for key in ("step_down", "spacing"):
        v = tp.meta.get(key)
        if isinstance(v, int | float):
            head.append(f"# {key}: {_fmt_num(float(v) * 1e3)} mm")
    data = toolpath_table(tp)
    # round to the written resolution first so that tiny negatives do not print as "-0.000"
    data = np.column_stack([np.round(data[:, j], d) for j, d in enumerate(_DECIMALS)]) + 0.0
    with atomic_write(path) as fh:
        fh.write("\n".join(head) + "\n")
        fh.write(",".join(TOOLPATH_COLUMNS) + "\n")
        fh.write(format_rows(data, _FORMATS))


_QUANTITY = re.compile(r"^\s*([-+0-9.eE]+)\s*(\S*)\s*$")


def _quantity(t: Table, key: str, kind: str, default_unit: str) -> float | None:
    """Metadata ``key: <number> [unit]`` → SI, or None if absent. ``kind``: length | speed."""
    if key not in t.meta:
        return None
    m = _QUANTITY.match(t.meta[key])
    if not m:
        raise InputError(f"expected '<number> <unit>', got {t.meta[key]!r}", file=t.path, field=key)
    value = finite_float(m.group(1), file=t.path, field=key)
    unit = m.group(2) or default_unit
    if kind == "length":
        return value * to_si(unit, "length", file=t.path, field=key)
    num, _, den = unit.partition("/")
    if not den:
        raise InputError(f"expected a speed unit like mm/min, got {unit!r}", file=t.path, field=key)
    return (
        value
        * to_si(num, "length", file=t.path, field=key)
        / to_si(den, "time", file=t.path, field=key)
    )


def _check_units(t: Table) -> None:
    if "units" not in t.meta:
        return
    declared = dict(item.split("=", 1) for item in t.meta["units"].split() if "=" in item)
    expected = {"length": "mm", "angle": "deg", "time": "s"}
    for k, v in declared.items():
        if k in expected and v != expected[k]:
            raise InputError(
                f"toolpath CSVs are in {_UNITS_LINE}; this file declares {k}={v}",
                file=t.path,
                field="units",
            )


def _first_bad(mask: np.ndarray) -> int:
    return int(np.argmax(mask))


def read_toolpath_csv(path: str | Path) -> Toolpath:
    """Read a toolpath CSV (see the module docstring) into a :class:`Toolpath` (SI).

    Raises
    ------
    InputError
        naming file and line: missing column, non-numeric or NaN cell, non-unit normal,
        non-increasing index, decreasing time or path length, non-integer or decreasing lap,
        centre inconsistent with contact + R·n, tip inconsistent with centre − R ẑ, bad metadata.
    """
    t = read_table(path, TOOLPATH_COLUMNS, what="toolpath CSV")
    _check_units(t)
    n = t.data.shape[0]
    index = t.column("index")
    lap_f = t.column("lap")
    if np.any(lap_f != np.round(lap_f)) or np.any(lap_f < 0):
        r = _first_bad((lap_f != np.round(lap_f)) | (lap_f < 0))
        raise t.error(f"lap must be a non-negative integer, got {lap_f[r]:g}", r, "lap")
    if n > 1:
        if np.any(np.diff(index) <= 0):
            r = _first_bad(np.diff(index) <= 0) + 1
            raise t.error(
                f"index must increase row by row; {index[r]:g} follows {index[r - 1]:g}", r, "index"
            )
        if np.any(np.diff(lap_f) < 0):
            r = _first_bad(np.diff(lap_f) < 0) + 1
            raise t.error(f"lap must not decrease; {lap_f[r]:g} follows {lap_f[r - 1]:g}", r, "lap")
    mm = 1e-3
    xyz = {
        k: np.column_stack([t.column(f"{k}_{a}") for a in "xyz"])
        for k in ("contact", "normal", "center", "tip")
    }
    contact, center, tip = xyz["contact"] * mm, xyz["center"] * mm, xyz["tip"] * mm
    normal = xyz["normal"]
    nn = np.linalg.norm(normal, axis=1)
    if np.any(np.abs(nn - 1.0) > NORMAL_TOL):
        r = _first_bad(np.abs(nn - 1.0) > NORMAL_TOL)
        raise t.error(f"normal must be a unit vector, |n| = {nn[r]:.6g}", r, "normal_x")
    normal = normal / nn[:, None]
    path_length = t.column("path_length") * mm
    time = t.column("time")
    for name, arr in (("time", time), ("path_length", path_length)):
        if arr[0] < 0:
            raise t.error(f"{name} must be ≥ 0, got {arr[0]:g}", 0, name)
        if n > 1 and np.any(np.diff(arr) < 0):
            r = _first_bad(np.diff(arr) < 0) + 1
            raise t.error(
                f"{name} must not decrease ({arr[r]:.9g} after {arr[r - 1]:.9g})", r, name
            )

    radius = _quantity(t, "tool_radius", "length", "mm")
    if radius is None:
        radius = float(np.mean(np.linalg.norm(center - contact, axis=1)))
        if not radius > 0:
            raise t.error("cannot derive the tool radius: center equals contact", 0, "center_x")
    elif not radius > 0:
        raise InputError(
            f"must be > 0, got {t.meta['tool_radius']}", file=t.path, field="tool_radius"
        )
    feed = _quantity(t, "feed", "speed", "mm/min")
    if feed is None:
        if not time[-1] > 0:
            raise InputError(
                "no '# feed:' line and time is 0 at the last row; cannot derive the feed",
                file=t.path,
                field="feed",
            )
        feed = float(path_length[-1] / time[-1])
    elif not feed > 0:
        raise InputError(f"must be > 0, got {t.meta['feed']}", file=t.path, field="feed")

    from_contact = t.meta.get("center_from_contact", "true").strip().lower() not in (
        "false",
        "no",
        "0",
    )
    if from_contact:
        dev = np.linalg.norm(center - (contact + radius * normal), axis=1)
        if np.any(dev > CONSISTENCY_TOL):
            r = _first_bad(dev > CONSISTENCY_TOL)
            raise t.error(
                f"center is {dev[r] * 1e3:.4g} mm away from contact + R·normal (R = "
                f"{radius * 1e3:g} mm); expected ≤ {CONSISTENCY_TOL * 1e3:g} mm "
                "(mark commanded paths with '# center_from_contact: false')",
                r,
                "center_x",
            )
    expect_tip = center - np.array([0.0, 0.0, radius])
    dev = np.linalg.norm(tip - expect_tip, axis=1)
    if np.any(dev > CONSISTENCY_TOL):
        r = _first_bad(dev > CONSISTENCY_TOL)
        raise t.error(
            f"tip is {dev[r] * 1e3:.4g} mm away from center − R·z (R = {radius * 1e3:g} mm)",
            r,
            "tip_z",
        )
    depth = t.column("depth") * mm
    dev = np.abs(depth + contact[:, 2])
    if np.any(dev > CONSISTENCY_TOL):
        r = _first_bad(dev > CONSISTENCY_TOL)
        raise t.error(f"depth {depth[r] * 1e3:g} mm is not −contact_z", r, "depth")
    meta: dict[str, object] = {"source": str(t.path)}
    for key in ("path_kind", "path_part"):
        if key in t.meta:
            meta[key.removeprefix("path_")] = t.meta[key]
    for key in ("step_down", "spacing"):
        v = _quantity(t, key, "length", "mm")
        if v is not None:
            meta[key] = v
    if not math.isfinite(radius) or not math.isfinite(feed):  # pragma: no cover - guarded above
        raise InputError("tool radius or feed not finite", file=t.path)
    return Toolpath(
        contact=contact,
        normal=normal,
        center=center,
        tip=tip,
        wall_angle=np.radians(t.column("wall_angle_deg")),
        lap=lap_f.astype(np.int64),
        path_length=path_length,
        time=time,
        tool_radius=float(radius),
        feed=float(feed),
        meta=meta,
    )
