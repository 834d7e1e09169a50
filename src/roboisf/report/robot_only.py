"""The report page of a robot-only study (no CNC run): the model-based springback, its
uncertainty and the model check, or "not separable" (``roboisf.decompose.robot_only``)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from roboisf.io.atomic import atomic_write
from roboisf.report import page as pg

__all__ = ["write_robot_only_report"]


def write_robot_only_report(summary: Mapping[str, Any], out_dir: str | Path) -> Path:
    """``out_dir/report.html`` from ``summary`` (``springback_model_based``, mm)."""
    sb = summary["springback_model_based"]
    verdict = (
        f"<p><b>Springback: {pg.esc(sb['label'])}</b> — {pg.esc(sb['reason'])}.</p>"
        if sb["separable"]
        else f'<div class="warnings"><h2>Springback: not separable</h2><p>'
        f"{pg.esc(sb['reason'])}.</p></div>"
    )
    items: list[tuple[str, Any]] = []
    if sb["separable"]:
        items += [
            (
                "mean |springback| (mm)",
                f"{pg.fmt(sb['mean_abs_dn'], 4)} (model interval "
                f"{pg.fmt(sb['mean_abs_dn_lo'], 4)} – {pg.fmt(sb['mean_abs_dn_hi'], 4)})",
            ),
            ("RMS / max (mm)", f"{pg.fmt(sb['rms_dn'], 4)} / {pg.fmt(sb['max_abs_dn'], 4)}"),
            ("mean 1σ per point (mm)", pg.fmt(sb["mean_sigma_dn"], 4)),
        ]
    lo, hi = sb["beta_95"]
    items += [
        ("model check β (95 %)", f"{pg.fmt(sb['beta'], 3)} [{pg.fmt(lo, 3)}, {pg.fmt(hi, 3)}]"),
        (
            "bias bound / tolerance (mm)",
            f"{pg.fmt(sb['bias_bound_mm'], 4)} / {sb['tolerance_mm']:g}",
        ),
        ("VJM spread along laps (mm)", pg.fmt(sb["vjm_spread_mm"], 4)),
        ("measured mean |dn| (mm)", pg.fmt(summary.get("measured_mean_abs_dn_mm"), 4)),
        ("modelled mean |dn| (mm)", summary.get("modelled_mean_abs_dn_mm")),
        ("truth", summary.get("truth")),
        ("study", summary.get("study")),
        ("run", summary.get("run")),
        ("robot", summary.get("robot")),
    ]
    body = (
        '<section id="springback"><h2>Springback without a CNC run</h2><p class="lead">'
        "ŝ = measured normal deviation − (tool + holder + robot VJM + commanded offset): the "
        "residual after the modelled terms, as right as the robot model. The model check "
        "regresses it on the VJM within each lap (springback hardly varies along a lap, the "
        "robot's deflection does).</p>"
        + verdict
        + pg.kv_table(items)
        + "</section>"
        + pg.warnings_box(list(summary.get("warnings", [])))
    )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "report.html"
    with atomic_write(path, "w") as fh:
        fh.write(pg.page(f"roboisf report — {summary['study']} (robot only)", body))
    return path
