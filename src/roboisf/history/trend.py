"""Trends over the history: is a robot drifting, did a tool change move the tool term?

:func:`trend` groups the parts (by robot, part kind or tool) and, per group in the order they
were formed, gives one factor's normal-book R_m (m) and the VJM check's ratio (measured over
modelled robot deflection: a robot that grows softer shows a rising ratio), with the
least-squares slope of each over time (per 30 days) and, for a tool, the mean per tool
(``by="tool"``: the tool's description as ``summary.json`` gives it).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from roboisf.errors import InputError
from roboisf.history.db import Database
from roboisf.history.store import FACTORS, part_filter

__all__ = ["GROUPS", "TrendGroup", "trend"]

GROUPS = ("robot", "kind", "tool")
_DAYS = 30.0
#: the shortest time (days) the dated values of a group must span for a slope per 30 days: parts
#: formed minutes apart extrapolated to a month gave +100 mm per 30 days for an R_m of 0.3 mm
MIN_SPAN_DAYS = 1.0


@dataclass(frozen=True)
class TrendGroup:
    """One group's parts in the order formed.

    ``formed_at`` ISO strings, ``part_ids``, ``values`` the factor's R_m (m, None where the
    part has no share row), ``vjm_ratio`` (None where not checked); ``slope`` and
    ``ratio_slope`` per 30 days (m and 1; None with fewer than two dated values, or when they
    span less than :data:`MIN_SPAN_DAYS`).
    """

    key: str
    formed_at: list[str]
    part_ids: list[int]
    values: list[float | None]
    vjm_ratio: list[float | None]
    slope: float | None
    ratio_slope: float | None

    def as_dict(self) -> dict[str, Any]:
        return {
            "group": self.key,
            "n_parts": len(self.part_ids),
            "part_ids": self.part_ids,
            "formed_at": self.formed_at,
            "r_m_m": self.values,
            "vjm_ratio": self.vjm_ratio,
            "slope_m_per_30_days": self.slope,
            "vjm_ratio_slope_per_30_days": self.ratio_slope,
        }


def _days(stamp: str) -> float:
    text = stamp.rstrip("Z").replace(" ", "T")
    return datetime.fromisoformat(text).timestamp() / 86400.0


def _slope(t: list[float], v: list[float | None]) -> float | None:
    pairs = [(a, b) for a, b in zip(t, v, strict=True) if b is not None and math.isfinite(b)]
    if len(pairs) < 2:
        return None
    # times from the first: identical stamps give exact zeros (days since 1970 rounded in the
    # mean would leave a spurious ~1e-20 spread and a slope of rounding noise)
    t0 = pairs[0][0]
    pairs = [(a - t0, b) for a, b in pairs]
    if max(a for a, _ in pairs) - min(a for a, _ in pairs) < MIN_SPAN_DAYS:
        return None  # one date, or too short a span to say anything per 30 days
    mt = sum(a for a, _ in pairs) / len(pairs)
    mv = sum(b for _, b in pairs) / len(pairs)
    sxx = sum((a - mt) ** 2 for a, _ in pairs)
    if sxx == 0:
        return None
    return _DAYS * sum((a - mt) * (b - mv) for a, b in pairs) / sxx


def _tool_key(tool_json: str) -> str:
    tool = json.loads(tool_json)
    parts = [f"Ø{tool.get('ball_diameter_mm', '?')} mm", str(tool.get("method", ""))]
    c = tool.get("lateral_compliance_m_per_N")
    if c is not None:
        parts.append(f"{float(c):.3g} m/N")
    return " ".join(p for p in parts if p)


def trend(
    db: Database,
    *,
    by: str = "robot",
    factor: str = "robot_compliance",
    robot: str | None = None,
    kind: str | None = None,
) -> list[TrendGroup]:
    """The parts grouped ``by`` robot, part kind or tool, each group over time (see module)."""
    if by not in GROUPS:
        raise InputError(f"expected one of {', '.join(GROUPS)}, got {by!r}", field="--by")
    if factor not in FACTORS:
        raise InputError(f"expected one of {', '.join(FACTORS)}, got {factor!r}", field="--factor")
    where, params = part_filter(robot=robot, kind=kind)
    rows = db.query(
        "SELECT p.id, p.formed_at, p.robot, p.part_kind, p.tool_json, p.vjm_ratio, s.r_m "
        "FROM parts p LEFT JOIN shares s ON s.part_id = p.id AND s.book = 'normal' "
        "AND s.factor = ?" + where + " ORDER BY p.formed_at, p.id",
        [factor, *params],
    )
    groups: dict[str, list[tuple[Any, ...]]] = {}
    for pid, formed, rob, knd, tool, ratio, r_m in rows:
        key = {"robot": rob, "kind": knd, "tool": _tool_key(tool)}[by]
        groups.setdefault(key, []).append((int(pid), formed, ratio, r_m))
    out = []
    for key, items in groups.items():
        t = [_days(f) for _, f, _, _ in items]
        vals = [None if v is None else float(v) for *_, v in items]
        ratios = [None if r is None else float(r) for _, _, r, _ in items]
        out.append(
            TrendGroup(
                key,
                [f for _, f, _, _ in items],
                [p for p, *_ in items],
                vals,
                ratios,
                _slope(t, vals),
                _slope(t, ratios),
            )
        )
    return out
