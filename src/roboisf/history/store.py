"""Analysed parts into the history and back out: add, list, show, per-point tables.

A part in the history is one ``roboisf analyze`` results folder (``summary.json``,
``per_point.parquet``, ``contributions.csv``, ``contributions_normal.csv``): the study's
metadata, part, robot and placement, tool, sheet, the per-point normal terms, both share tables
and the diagnosis (the VJM check's ratio and verdict, the identified joint stiffness). It is
written in **one transaction** (:meth:`roboisf.history.db.Database.transaction`): a process
killed during ``add`` leaves no half-written part. A part is known by the SHA-256 of its
``summary.json`` and ``per_point.parquet``; adding it again is reported and skipped.

Units in the database: m, rad, m/N (the results' mm and degrees are converted on reading).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.history.db import PART_COLUMNS, POINT_COLUMNS, SHARE_COLUMNS, Database
from roboisf.summary import AnalysisSummary, dumps, read_summary

__all__ = [
    "FACTORS",
    "PartRecord",
    "add_parts",
    "list_parts",
    "part_filter",
    "points_table",
    "read_results",
    "show_part",
]

#: the four factors of the decomposition (the share tables' rows) and their per-point columns
FACTORS = ("tool", "tool_holder", "springback", "robot_compliance")
_TERMS = {
    "total_dn": "robot_dn",
    "tool_dn": "tool_dn",
    "holder_dn": "tool_holder_dn",
    "springback_dn": "springback_dn",
    "robot_dn": "robot_compliance_dn",
    "vjm_dn": "vjm_dn",
}
_NEEDED = (
    "lap",
    "depth",
    "wall_angle_deg",
    "contact_x",
    "contact_y",
    "contact_z",
    "normal_x",
    "normal_y",
    "normal_z",
    "used",
    *_TERMS.values(),
)
_DATE = re.compile(r"^\d{4}-\d{2}-\d{2}([T ]\d{2}:\d{2}(:\d{2})?)?Z?$")


@dataclass(frozen=True)
class PartRecord:
    """One analysed part, ready for the history.

    ``meta`` maps the ``parts`` columns (:data:`roboisf.history.db.PART_COLUMNS`) to values
    (SI); ``points`` is (N, len(POINT_COLUMNS)) float in that column order; ``shares`` the
    rows of both share tables (book, factor, mean |δx|, |δy|, |δz| [m], R_m [m], share [%]).
    """

    meta: dict[str, Any]
    points: NDArray[np.float64]
    shares: list[tuple[Any, ...]]


def _sha(*files: Path) -> str:
    h = hashlib.sha256()
    for f in files:
        h.update(f.read_bytes())
    return h.hexdigest()


def _json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(f"not readable JSON ({e})", file=path) from None
    if not isinstance(data, dict):
        raise InputError("expected a JSON object", file=path)
    return data


def _shares(path: Path, book: str) -> list[tuple[Any, ...]]:
    import csv

    rows = []
    try:
        with path.open(encoding="utf-8", newline="") as f:
            reader = csv.DictReader(f)
            for line, row in enumerate(reader, start=2):
                try:
                    vals = [
                        float(row[k]) * s
                        for k, s in (
                            ("mean_abs_dx", 1e-3),
                            ("mean_abs_dy", 1e-3),
                            ("mean_abs_dz", 1e-3),
                            ("R_m", 1e-3),
                            ("share_percent", 1.0),
                        )
                    ]
                except (KeyError, TypeError, ValueError):
                    raise InputError(
                        "expected factor,mean_abs_dx,mean_abs_dy,mean_abs_dz,R_m,share_percent",
                        file=path,
                        line=line,
                    ) from None
                rows.append((book, row["factor"], *vals))
    except OSError as e:
        raise InputError(f"cannot read ({e.strerror})", file=path) from None
    return rows


def _step_down(depth: NDArray[np.float64], lap: NDArray[np.int64]) -> float:
    """Median depth step between consecutive laps' deepest points (m)."""
    laps = np.unique(lap)
    if len(laps) < 2:
        return float("nan")
    deepest = np.array([depth[lap == k].max() for k in laps])
    return float(np.median(np.diff(deepest)))


def read_results(folder: str | Path, *, formed_at: str | None = None) -> PartRecord:
    """Read one ``analyze`` results folder into a :class:`PartRecord`.

    ``formed_at`` (ISO 8601 date or date-time, UTC) is when the part was formed; default: when
    the results were written (the folder's ``.roboisf-output.json``, else ``summary.json``'s
    modification time).
    """
    import pandas as pd

    root = Path(folder)
    if not root.is_dir():
        raise InputError("expected an `roboisf analyze` results folder", file=root)
    files = {
        n: root / n
        for n in (
            "summary.json",
            "per_point.parquet",
            "contributions.csv",
            "contributions_normal.csv",
        )
    }
    for name, path in files.items():
        if not path.is_file():
            raise InputError(
                f"no {name}: not a results folder of `roboisf analyze`",
                file=root,
            )
    summary = read_summary(files["summary.json"])
    if not isinstance(summary, AnalysisSummary):
        raise InputError(
            "the results of a robot-only study (no CNC run): the history holds analyses that "
            "split the error with a CNC run",
            file=files["summary.json"],
        )
    try:
        df = pd.read_parquet(files["per_point.parquet"])
    except Exception as e:  # pyarrow raises several types for a damaged file
        raise InputError(
            f"not a readable Parquet table ({e})", file=files["per_point.parquet"]
        ) from None
    missing = [c for c in _NEEDED if c not in df.columns]
    if missing:
        raise InputError(
            f"missing columns {', '.join(missing)} (written by another roboisf version?)",
            file=files["per_point.parquet"],
        )
    if len(df) == 0:
        raise InputError("has no rows", file=files["per_point.parquet"])

    def need(key: str, table: dict[str, Any], where: str) -> Any:
        if key not in table:
            raise InputError("missing field", file=files["summary.json"], field=f"{where}.{key}")
        return table[key]

    part, robot, tool = summary.part, summary.robot, summary.tool
    kind = str(need("kind", part, "part"))
    try:
        t = float(need("sheet_thickness", part, "part")) * 1e-3
    except (TypeError, ValueError):
        raise InputError(
            "expected a number (mm)", file=files["summary.json"], field="part.sheet_thickness"
        ) from None
    ball = tool.ball_diameter_mm * 1e-3 / 2
    if formed_at is None:
        marker = root / ".roboisf-output.json"
        stamp = None
        if marker.is_file():
            stamp = _json(marker).get("written_utc")
        if not isinstance(stamp, str):
            mtime = files["summary.json"].stat().st_mtime
            stamp = datetime.fromtimestamp(mtime, UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
        formed_at = stamp
    elif not _DATE.match(formed_at):
        raise InputError(
            f"expected YYYY-MM-DD or YYYY-MM-DDTHH:MM:SS (UTC), got {formed_at!r}",
            field="--formed",
        )
    try:  # one form in the database, so that text order is time order
        when = datetime.fromisoformat(formed_at.rstrip("Z").replace(" ", "T"))
    except ValueError:
        raise InputError(f"not a valid date: {formed_at!r}", field="--formed") from None
    formed_at = when.strftime("%Y-%m-%dT%H:%M:%SZ")

    mm = 1e-3
    lap = df["lap"].to_numpy(dtype=np.int64)
    depth = df["depth"].to_numpy(dtype=float) * mm
    cols = {
        "idx": np.arange(len(df), dtype=float),
        "lap": lap.astype(float),
        "depth": depth,
        "wall_angle": np.radians(df["wall_angle_deg"].to_numpy(dtype=float)),
        "x": df["contact_x"].to_numpy(dtype=float) * mm,
        "y": df["contact_y"].to_numpy(dtype=float) * mm,
        "z": df["contact_z"].to_numpy(dtype=float) * mm,
        "nx": df["normal_x"].to_numpy(dtype=float),
        "ny": df["normal_y"].to_numpy(dtype=float),
        "nz": df["normal_z"].to_numpy(dtype=float),
        "used": df["used"].to_numpy(dtype=bool).astype(float),
        **{k: df[v].to_numpy(dtype=float) * mm for k, v in _TERMS.items()},
    }
    points = np.column_stack([cols[c] for c in POINT_COLUMNS])
    check = summary.vjm_check
    k_ident = summary.identification.get("K")
    placement = robot.placement_T_base_work_m
    tool_c = tool.lateral_compliance_m_per_N
    rim = summary.rim_band_mm
    meta = {
        "fingerprint": _sha(files["summary.json"], files["per_point.parquet"]),
        "study": summary.study,
        "source": str(root.resolve()),
        "formed_at": formed_at,
        "added_at": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "part_kind": kind,
        "part_json": json.dumps(part, sort_keys=True),
        "robot": robot.model,
        "placement_json": json.dumps(placement),
        "tool_json": json.dumps(dataclasses.asdict(tool), sort_keys=True),
        "tool_radius": ball,
        "tool_compliance": float(tool_c),
        "sheet_thickness": t,
        "material": str(part.get("material", "unknown")),
        "step_down": _step_down(depth, lap),
        "rim_band": float(rim) * mm,
        "n_points": len(df),
        "n_used": int(df["used"].sum()),
        "vjm_ratio": _finite(check.get("ratio")) if check else None,
        "vjm_verdict": check.get("verdict") if check else None,
        "identified_k_json": json.dumps(k_ident) if k_ident is not None else None,
        "summary_json": json.dumps(json.loads(dumps(summary)), sort_keys=True),
    }
    shares = _shares(files["contributions.csv"], "per_axis") + _shares(
        files["contributions_normal.csv"], "normal"
    )
    return PartRecord(meta, points, shares)


def _finite(v: Any) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _none(v: float) -> float | None:
    return None if not math.isfinite(v) else v


def add_parts(db: Database, records: list[PartRecord]) -> list[tuple[int, bool]]:
    """Store ``records``, each in its own transaction; returns (part id, newly added) per record
    (a part already in the history by its fingerprint is not added again)."""
    out = []
    cols = ", ".join(PART_COLUMNS)
    marks = ", ".join("?" for _ in PART_COLUMNS)
    pcols = ", ".join(POINT_COLUMNS)
    pmarks = ", ".join("?" for _ in POINT_COLUMNS)
    scols = ", ".join(SHARE_COLUMNS)
    smarks = ", ".join("?" for _ in SHARE_COLUMNS)
    ints = {POINT_COLUMNS.index(c) for c in ("idx", "lap", "used")}
    for rec in records:
        with db.transaction():
            known = db.query(
                "SELECT id FROM parts WHERE fingerprint = ?", (rec.meta["fingerprint"],)
            )
            if known:
                out.append((int(known[0][0]), False))
                continue
            pid = db.insert_returning_id(
                f"INSERT INTO parts ({cols}) VALUES ({marks})",
                [rec.meta[c] for c in PART_COLUMNS],
            )
            rows = [
                (pid, *(int(v) if j in ints else _none(float(v)) for j, v in enumerate(row)))
                for row in rec.points.tolist()
            ]
            db.executemany(f"INSERT INTO points (part_id, {pcols}) VALUES (?, {pmarks})", rows)
            db.executemany(
                f"INSERT INTO shares (part_id, {scols}) VALUES (?, {smarks})",
                [(pid, *row) for row in rec.shares],
            )
        out.append((pid, True))
    return out


_LIST = (
    "id",
    "formed_at",
    "study",
    "part_kind",
    "robot",
    "tool_radius",
    "sheet_thickness",
    "n_points",
    "n_used",
    "vjm_ratio",
    "vjm_verdict",
)


def part_filter(*, robot: str | None = None, kind: str | None = None) -> tuple[str, list[Any]]:
    """A `` WHERE …`` clause on the ``parts`` table aliased ``p`` (empty without a filter) and
    its parameters."""
    where, params = [], []
    if robot is not None:
        where.append("p.robot = ?")
        params.append(robot)
    if kind is not None:
        where.append("p.part_kind = ?")
        params.append(kind)
    return (" WHERE " + " AND ".join(where) if where else ""), params


def list_parts(
    db: Database, *, robot: str | None = None, kind: str | None = None
) -> list[dict[str, Any]]:
    """The parts in the history (oldest formed first) with their normal-book R_m per factor
    (``r_m_<factor>``, m) and total; ``robot`` / ``kind`` filter."""
    where, params = part_filter(robot=robot, kind=kind)
    sql = (
        f"SELECT {', '.join('p.' + c for c in _LIST)}, s.factor, s.r_m FROM parts p "
        "LEFT JOIN shares s ON s.part_id = p.id AND s.book = 'normal'"
        + where
        + " ORDER BY p.formed_at, p.id"
    )
    parts: dict[int, dict[str, Any]] = {}
    for row in db.query(sql, params):
        pid = int(row[0])
        entry = parts.setdefault(pid, dict(zip(_LIST, row[: len(_LIST)], strict=True)))
        factor, r_m = row[len(_LIST)], row[len(_LIST) + 1]
        if factor is not None:
            entry[f"r_m_{factor}"] = r_m
    return list(parts.values())


def show_part(db: Database, part_id: int) -> dict[str, Any]:
    """Everything the history holds on one part except its points (their count and the
    normal terms' RMS over the used points [m] instead)."""
    rows = db.query(f"SELECT id, {', '.join(PART_COLUMNS)} FROM parts WHERE id = ?", (part_id,))
    if not rows:
        raise InputError(f"no part {part_id} in the history", field="PART_ID")
    info = dict(zip(("id", *PART_COLUMNS), rows[0], strict=True))
    for key in ("part_json", "placement_json", "tool_json", "identified_k_json"):
        v = info.pop(key)
        info[key.removesuffix("_json")] = None if v is None else json.loads(v)
    info.pop("summary_json")
    info["shares"] = [
        dict(zip(SHARE_COLUMNS, r, strict=True))
        for r in db.query(
            f"SELECT {', '.join(SHARE_COLUMNS)} FROM shares WHERE part_id = ? "
            "ORDER BY book, factor",
            (part_id,),
        )
    ]
    terms = ("tool_dn", "holder_dn", "springback_dn", "robot_dn", "total_dn")
    sums = db.query(
        "SELECT count(*), "
        + ", ".join(f"avg({t} * {t})" for t in terms)
        + " FROM points WHERE part_id = ? AND used = 1",
        (part_id,),
    )[0]
    info["used_points"] = int(sums[0])
    info["rms_dn"] = {
        t: (None if v is None else math.sqrt(float(v)))
        for t, v in zip(terms, sums[1:], strict=True)
    }
    return info


def points_table(db: Database, part_ids: list[int] | None = None) -> Any:
    """Per-point rows (pandas DataFrame, SI) of the given parts (default: every part), with
    the part's ``part_id``, ``part_kind``, ``robot``, ``tool_radius``, ``sheet_thickness``,
    ``material`` and ``step_down``."""
    import pandas as pd

    meta = ("part_kind", "robot", "tool_radius", "sheet_thickness", "material", "step_down")
    sql = (
        f"SELECT pt.part_id, {', '.join('pt.' + c for c in POINT_COLUMNS)}, "
        f"{', '.join('p.' + c for c in meta)} FROM points pt JOIN parts p ON p.id = pt.part_id"
    )
    params: list[Any] = []
    if part_ids is not None:
        if not part_ids:
            return pd.DataFrame(columns=["part_id", *POINT_COLUMNS, *meta])
        sql += f" WHERE pt.part_id IN ({', '.join('?' for _ in part_ids)})"
        params = list(part_ids)
    sql += " ORDER BY pt.part_id, pt.idx"
    df = pd.DataFrame(db.query(sql, params), columns=["part_id", *POINT_COLUMNS, *meta])
    for c in POINT_COLUMNS:
        if c not in ("idx", "lap", "used"):
            df[c] = df[c].astype(float)
    return df
