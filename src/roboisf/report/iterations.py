"""The iteration history of a study with several robot runs: per run and per term, RMS, max and
share, and the improvement of the measured part (docs/compensate.md, "The loop").

``analyze`` on a study with robot runs ``robot``, ``robot_2``, … analyses each against the CNC
run and puts :func:`history_row` of each into ``summary["iterations"]``; the report adds
:func:`iterations_section` and ``iterations.csv`` (:func:`write_iterations_csv`). All values are
over the analysed wall (``used``), normal components (what a scan observes), mm and %.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from roboisf.io.atomic import atomic_write
from roboisf.report.page import esc, fmt
from roboisf.report.schema import FACTORS
from roboisf.report.style import FACTOR_LABELS

__all__ = [
    "HISTORY_TERMS",
    "LEAD",
    "history_row",
    "iterations_section",
    "iterations_table",
    "write_iterations_csv",
]

#: The section's lead line.
LEAD = (
    "Each robot run of the study, formed with the program named, analysed against the CNC run; "
    "this report's other sections are the last run's."
)

#: The terms of the history: the four factors and, for a compensated run, the command offset.
HISTORY_TERMS = (*FACTORS, "command")
_LABELS = {**FACTOR_LABELS, "command": "commanded offset", "total": "measured part"}


def history_row(
    run: str, program: str, per_point: pd.DataFrame, contributions_normal: pd.DataFrame
) -> dict[str, Any]:
    """One run's line of the history.

    Parameters
    ----------
    run, program : the run's name and the toolpath/program file it was formed with
    per_point : the analysis' per-point table (mm): ``used``, ``robot_dn``, ``<factor>_dn`` and,
        for a compensated run, ``command_dn``
    contributions_normal : the normal-book contribution table (``factor``, ``share_percent``)

    Returns
    -------
    ``{"run", "program", "mean_abs_dn_mm", "rms_dn_mm", "max_abs_dn_mm", "terms": {term:
    {"rms_mm", "max_abs_mm", "share_percent"}}}`` — shares of the four factors from the normal
    book (the command offset has none: it is what the command adds on purpose).
    """
    used = per_point["used"].to_numpy(dtype=bool)
    dn = per_point["robot_dn"].to_numpy(dtype=float)[used]
    shares = dict(
        zip(contributions_normal["factor"], contributions_normal["share_percent"], strict=True)
    )
    terms: dict[str, dict[str, float | None]] = {}
    for t in HISTORY_TERMS:
        col = f"{t}_dn"
        v = (
            per_point[col].to_numpy(dtype=float)[used]
            if col in per_point
            else np.zeros(int(used.sum()))
        )
        terms[t] = {
            "rms_mm": float(np.sqrt(np.mean(v**2))) if v.size else float("nan"),
            "max_abs_mm": float(np.max(np.abs(v))) if v.size else float("nan"),
            "share_percent": float(shares[t]) if t in shares else None,
        }
    return {
        "run": run,
        "program": program,
        "mean_abs_dn_mm": float(np.mean(np.abs(dn))) if dn.size else float("nan"),
        "rms_dn_mm": float(np.sqrt(np.mean(dn**2))) if dn.size else float("nan"),
        "max_abs_dn_mm": float(np.max(np.abs(dn))) if dn.size else float("nan"),
        "terms": terms,
    }


def _improvement(rows: Sequence[Mapping[str, Any]], k: int) -> float:
    """% by which run ``k``'s mean |dn| is below the first run's."""
    first = float(rows[0]["mean_abs_dn_mm"])
    return 100.0 * (1.0 - float(rows[k]["mean_abs_dn_mm"]) / first) if first > 0 else 0.0


def iterations_table(rows: Sequence[Mapping[str, Any]]) -> pd.DataFrame:
    """The history as a flat table: one row per run (mm, %)."""
    out = []
    for k, r in enumerate(rows):
        d: dict[str, Any] = {
            "run": r["run"],
            "program": r["program"],
            "mean_abs_dn_mm": r["mean_abs_dn_mm"],
            "rms_dn_mm": r["rms_dn_mm"],
            "max_abs_dn_mm": r["max_abs_dn_mm"],
            "improvement_percent": _improvement(rows, k),
        }
        for t, v in r["terms"].items():
            d[f"{t}_rms_mm"] = v["rms_mm"]
            d[f"{t}_max_abs_mm"] = v["max_abs_mm"]
            d[f"{t}_share_percent"] = v["share_percent"]
        out.append(d)
    return pd.DataFrame(out)


def write_iterations_csv(rows: Sequence[Mapping[str, Any]], out_dir: str | Path) -> Path:
    """``out_dir/iterations.csv`` (mm, %), written atomically."""
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    path = Path(out_dir) / "iterations.csv"
    with atomic_write(path) as fh:
        iterations_table(rows).to_csv(fh, index=False, float_format="%.6g")
    return path


def iterations_section(rows: Sequence[Mapping[str, Any]]) -> str:
    """The report's "Iterations" section body: the measured part per run and its improvement,
    then per term RMS / max |dn| / share per run."""
    head = (
        "<thead><tr><th>run</th><th>formed with</th><th>mean |dn| (mm)</th><th>RMS (mm)</th>"
        "<th>max |dn| (mm)</th><th>below the first (%)</th></tr></thead>"
    )
    body = "".join(
        f"<tr><td>{esc(r['run'])}</td><td>{esc(r['program'])}</td>"
        f"<td>{fmt(r['mean_abs_dn_mm'], 4)}</td><td>{fmt(r['rms_dn_mm'], 4)}</td>"
        f"<td>{fmt(r['max_abs_dn_mm'], 4)}</td><td>{fmt(_improvement(rows, k), 1)}</td></tr>"
        for k, r in enumerate(rows)
    )
    parts = [
        "<table><caption>The measured part, run by run <span>— analysed wall, normal "
        f"deviation</span></caption>{head}<tbody>{body}</tbody></table>"
    ]
    th = "".join(f"<th>{esc(r['run'])}</th>" for r in rows)
    term_rows = []
    for t in HISTORY_TERMS:
        cells = []
        for r in rows:
            v = r["terms"][t]
            share = "" if v["share_percent"] is None else f" · {fmt(v['share_percent'], 1)} %"
            cells.append(f"<td>{fmt(v['rms_mm'], 4)} / {fmt(v['max_abs_mm'], 4)}{esc(share)}</td>")
        term_rows.append(f"<tr><td>{esc(_LABELS[t])}</td>{''.join(cells)}</tr>")
    parts.append(
        "<table><caption>Per term <span>— RMS / max |dn| (mm) · share (normal book)</span>"
        f"</caption><thead><tr><th>term</th>{th}</tr></thead>"
        f"<tbody>{''.join(term_rows)}</tbody></table>"
    )
    return "".join(parts)
