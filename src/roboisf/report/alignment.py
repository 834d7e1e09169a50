"""One line per run in the report: how its logs were matched to the toolpath (``summary.json``
``alignment``, :mod:`roboisf.sync`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from roboisf.report.page import esc

__all__ = ["alignment_html"]


def _line(run: str, a: Mapping[str, Any]) -> str:
    method = str(a.get("method", "?"))
    if method == "time":
        return (
            f"<b>{esc(run)}</b>: by nominal time (path length / feed), log offset "
            f'{float(a.get("offset") or 0.0):.3g} s; no residual (set sync = "position" or '
            '"force" to check the timing)'
        )
    unit = str(a.get("residual_unit", ""))
    rms, mx = a.get("residual_rms"), a.get("residual_max")
    fmt = ".3f" if unit == "mm" else ".2f"
    res = "–" if rms is None else f"RMS {rms:{fmt}} {unit}, max {mx:{fmt}} {unit}"
    pauses = a.get("pauses") or []
    p = ", ".join(f"{float(d):.1f} s at {float(t):.1f} s" for t, d in pauses) if pauses else "none"
    by = "position (FK of the joint log)" if method == "position" else "force signature"
    line = (
        f"<b>{esc(run)}</b>: by {by}; residual {res}; clock {float(a.get('clock_scale', 1)):.4f} "
        f"log s per nominal s, program start at log time {float(a.get('offset', 0)):.3f} s; "
        f"pauses: {p}"
    )
    fc = a.get("force_clock")
    if isinstance(fc, Mapping):
        line += (
            f"; force log on its own clock: τ_force = {float(fc['offset']):.3f} s + "
            f"{float(fc['scale']):.5f} · τ_joint (misfit "
            f"{float(fc['fit_rms_points']):.2f} points RMS)"
        )
    return line


def alignment_html(alignment: Any) -> str:
    """``<p>`` listing each run's alignment, or an empty string when the summary has none."""
    if not isinstance(alignment, Mapping) or not alignment:
        return ""
    items = "".join(
        f"<li>{_line(str(run), a)}</li>" for run, a in alignment.items() if isinstance(a, Mapping)
    )
    head = "<p>Alignment of the logs to the toolpath:</p>"
    return f'<div class="alignment">{head}<ul>{items}</ul></div>'
