"""Assemble and write the study report (``report.html`` + ``figures/*.png``) and the index page."""

from __future__ import annotations

import dataclasses
import html as _html
import json
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import plotly.io as pio

from roboisf.errors import InputError
from roboisf.io.atomic import atomic_write
from roboisf.progress import Progress, task
from roboisf.report import aggregate as agg
from roboisf.report import interactive as ia
from roboisf.report import page as pg
from roboisf.report import plotfig as pf
from roboisf.report.alignment import alignment_html
from roboisf.report.model_check import check_card, check_tables
from roboisf.report.render import PngRenderer, default_processes
from roboisf.report.schema import FACTORS, check_contributions, check_per_point, check_summary
from roboisf.report.statements import diagnosis_html, kind_banner, scope_html, study_kind
from roboisf.report.style import FACTOR_LABELS

__all__ = [
    "FIGURES",
    "HTML_FIGURES",
    "figure_ids",
    "read_headline",
    "write_index",
    "write_report",
]


def preload() -> None:
    """Import what writing the page imports on its first figure: plotly's HTML writer and the
    typed-array encoder of its JSON (plotly's validators module, which loads narwhals: ~80
    modules, 0.035 s), by writing a two-point figure. For a thread with nothing else to do
    before the report is written (the analysis' scans thread, once its scan is done), so that
    the command's serial tail does not pay for them."""
    import plotly._subplots
    import plotly.colors
    import plotly.shapeannotation  # noqa: F401
    from _plotly_utils.utils import convert_to_base64

    # the writer's own imports at call time (its JSON module, narwhals' interchange check)
    tiny = {"data": [{"type": "scatter", "x": np.zeros(2), "y": np.zeros(2)}], "layout": {}}
    convert_to_base64(tiny)
    pio.to_html(tiny, validate=False, full_html=False, include_plotlyjs=False)


def _static() -> Any:
    """:mod:`roboisf.report.static` (matplotlib: ~0.5 s to import), loaded by the first PNG
    drawn: a report without PNGs (the default, ``analyze --png`` asks for them) never loads
    it."""
    from roboisf.report import static

    return static


#: Plot ids of the report of a round part, in page order; each is ``<div id="fig-<id>">`` in
#: the HTML and ``figures/<id>.png``. A part that is not round has ``vjm_contour`` (the contour
#: by arc length) in place of ``vjm_polar`` (:func:`figure_ids`).
FIGURES: tuple[str, ...] = (
    "contributions",
    "forces",
    "deviation_depth",
    "deviation_map",
    "deviation_top",
    "factors_depth",
    "vjm_path",
    "vjm_polar",
    "thickness",
)


#: Plot ids in the HTML only (no PNG), before every figure of :data:`FIGURES`: the 3D view of
#: the formed part.
HTML_FIGURES: tuple[str, ...] = ("part_3d",)


def figure_ids(round_part: bool = True) -> tuple[str, ...]:
    """The report's plot ids in page order: :data:`FIGURES`, with ``vjm_contour`` in place of
    ``vjm_polar`` when the part is not round (see :func:`roboisf.report.aggregate.is_round`)."""
    if round_part:
        return FIGURES
    return tuple("vjm_contour" if f == "vjm_polar" else f for f in FIGURES)


_PLOTLY_CONFIG = {
    "displaylogo": False,
    "responsive": True,
    "modeBarButtonsToRemove": ["lasso2d", "select2d"],
    "toImageButtonOptions": {"format": "png", "scale": 2},
}


@dataclass(frozen=True)
class _Figure:
    id: str
    title: str
    caption: str
    plotly: Callable[[], pf.Figure]
    png: Callable[[], Any]


#: What the blank areas of a point view are.
_SPARSE = (
    "Blank specks are points the subset leaves out (when a part has more) or scan holes (the "
    "unrolled map shows the holes alone); blank wedges at the corners of a part that is not "
    "round are stretches the toolpath's contact points skip: the ball's centre turns on a "
    "tighter radius than the wall, so consecutive contact points lie several mm apart there."
)


def _thickness_caption(pp: pd.DataFrame, has_meas: bool) -> str:
    """What the thickness figure shows: a band only where the measurement varies within a lap,
    and why the sine law rises at the top when it does (the rim's rounding)."""
    cols = ["thickness_predicted"] + (["thickness_measured"] if has_meas else [])
    prof = agg.lap_profile(pp, cols)
    text = "Sine law t = t₀·cos α (dashed)"
    if has_meas:
        width = (prof["thickness_measured_hi"] - prof["thickness_measured_lo"]).max()
        text += (
            " and the measured thickness (lap mean, 5–95 % band)."
            if width > 1e-3
            else " and the measured thickness (lap mean; it does not vary within a lap, so "
            "no band)."
        )
    else:
        text += "; no measured thickness was given."
    spread = agg.thickness_spread(pp)
    if spread is not None:
        text += (
            f" The walls of a lap differ in angle ({spread.angle_low:.0f}° to "
            f"{spread.angle_high:.0f}°), so the sine law differs between them: the shaded band "
            "spans each lap's thinnest to thickest wall "
            f"(up to {float(np.max(spread.high - spread.low)):.3f} mm apart), the dashed line "
            "is the lap mean."
        )
    pred = prof["thickness_predicted"].dropna()
    if len(pred) > 2 and pred.iloc[0] > 1.05 * pred.median():
        top = float(prof["depth"].iloc[0])
        top = 0.0 if abs(top) < 0.05 else top  # a first lap at the sheet read "depth -0.0 mm"
        text += (
            f" At the top (depth {top:.1f} mm) the tool is still on the "
            "rounding into the rim, where the wall is flatter, so the sine law rises towards "
            "the sheet's thickness there."
        )
    return text


def _figures(
    pp: pd.DataFrame,
    contrib: pd.DataFrame,
    contrib_n: pd.DataFrame,
    contour_z: float | None,
    round_part: bool,
) -> dict[str, _Figure]:
    has_truth = any(f"truth_{f}_dn" in pp.columns for f in FACTORS)
    has_meas = "thickness_measured" in pp.columns
    if round_part:
        contour_fig, contour_caption = ia.vjm_polar_figure(pp, contour_z)
    else:
        contour_fig, contour_caption = ia.vjm_contour_figure(pp, contour_z)
    n_cells = agg.lap_map(pp, "robot_dn").position.size
    band = "Lines are lap means, bands span the 5th–95th percentile of each lap."
    specs = [
        _Figure(
            "contributions",
            "Contribution of each factor",
            "Solid bars: per-axis vectors (the paper's way, eq. 6); hatched bars: the same factors "
            "projected on the surface normal (what a scan can observe).",
            lambda: ia.contributions_figure(contrib, contrib_n),
            lambda: _static().contributions_png(contrib, contrib_n),
        ),
        _Figure(
            "forces",
            "Forming force, CNC vs robot",
            f"Forces at the tool tip in work axes. {band}",
            lambda: ia.forces_figure(pp),
            lambda: _static().forces_png(pp),
        ),
        _Figure(
            "deviation_depth",
            "Measured deviation vs depth",
            "Deviation of each formed part from the nominal, per work axis and along the surface "
            f"normal (positive towards the tool). {band} On an axisymmetric part δx and δy "
            "change sign "
            "around each lap, so their band is wide and their mean near zero.",
            lambda: ia.deviation_depth_figure(pp),
            lambda: _static().deviation_depth_png(pp),
        ),
        _Figure(
            "deviation_map",
            "Deviation map (part unrolled)",
            "Normal deviation δn, one row per lap (at its mean depth), against the position "
            "along the lap as a fraction of its length, from its point nearest the +x axis in "
            "toolpath order (on a round part: the angle φ/360°; the hover gives the arc length "
            f"in mm). {n_cells} cells per lap (the median number of points per lap): dense laps "
            "are averaged, a cell no point falls in takes its lap's nearest point; blank cells "
            "are scan holes. Both maps share one colour scale.",
            lambda: ia.deviation_map_figure(pp),
            lambda: _static().deviation_map_png(pp),
        ),
        _Figure(
            "deviation_top",
            "Deviation map (top view)",
            "The same δn at the toolpath points seen from above (x, y in the work frame), at "
            f"most {agg.MAX_TOP_POINTS} points per part (a fixed random subset: an even stride "
            "would alias with the laps into spokes and rings). "
            f"{_SPARSE} Same colour scale rule as the unrolled map.",
            lambda: ia.deviation_top_figure(pp),
            lambda: _static().deviation_top_png(pp),
        ),
        _Figure(
            "factors_depth",
            "Each factor along the depth",
            "Normal component of each recovered contribution. "
            + ("Dashed: the ground truth of the virtual cell. " if has_truth else "")
            + band,
            lambda: ia.factors_depth_figure(pp),
            lambda: _static().factors_depth_png(pp),
        ),
        _Figure(
            "vjm_path",
            "Robot compliance: experiment vs VJM along the path",
            "δc_exp = δ_robot − δs − δt − δth from the scans, against the Virtual Joint Model "
            f"prediction k_c·W, per work axis, and their difference Δ. {band}",
            lambda: ia.vjm_path_figure(pp),
            lambda: _static().vjm_path_png(pp),
        ),
        _Figure(
            "vjm_polar",
            "Robot compliance around one contour",
            contour_caption + " Resultant magnitudes; angle measured from the work x axis.",
            lambda: contour_fig,
            lambda: _static().vjm_polar_png(pp, contour_z),
        )
        if round_part
        else _Figure(
            "vjm_contour",
            "Robot compliance along one contour",
            contour_caption + " Resultant magnitudes against the arc length along the lap "
            "from its point nearest the +x axis, in toolpath order (the part is not round, so "
            "no polar plot).",
            lambda: contour_fig,
            lambda: _static().vjm_contour_png(pp, contour_z),
        ),
        _Figure(
            "thickness",
            "Wall thickness",
            _thickness_caption(pp, has_meas),
            lambda: ia.thickness_figure(pp),
            lambda: _static().thickness_png(pp),
        ),
    ]
    return {s.id: s for s in specs}


def _part_figure(pp: pd.DataFrame) -> _Figure:
    """The 3D view of the formed part: HTML only (a PNG of it says little)."""
    view = agg.part_view(pp)
    laps = "every lap" if view.lap_step == 1 else f"every {view.lap_step}th lap"
    return _Figure(
        "part_3d",
        "The formed part, coloured by each term",
        f"The toolpath's contact points, {laps} whole (at most {agg.MAX_3D_POINTS} points), "
        "drawn as lines coloured by the normal value δn of the term picked above (positive: "
        "the material lies on the tool side of the nominal); every term has its own symmetric "
        "colour scale, so compare sizes in the cards and tables, patterns here. Total: the "
        "robot part's measured deviation, the sum of the four factors; residual: what the robot "
        "model leaves, Δ = δc_exp − δc_VJM. A break in a line is a scan hole.",
        lambda: ia.part_figure(pp),
        lambda: None,
    )


def _mismatch_reason(summary: Mapping[str, Any]) -> str:
    """Why experiment and VJM differ when the model check says the model does not hold ('' when
    it holds or there is no check)."""
    vc = summary.get("vjm_check")
    if not isinstance(vc, Mapping) or vc.get("verdict") != "mismatch" or vc.get("ratio") is None:
        return ""
    return (
        f"Experiment and VJM differ because the robot model does not hold: the measured robot "
        f"deflection is {float(vc['ratio']):.2f}× the VJM's along the normal (95 % "
        f"[{pg.fmt(vc.get('ci_low'), 2)}, {pg.fmt(vc.get('ci_high'), 2)}], the check in the "
        "table above); the robot term of the decomposition is the measured one."
    )


def _truth_reason(summary: Mapping[str, Any]) -> str:
    """Why the robot panel's recovered term differs from the dashed truth, when the truth says
    ('' otherwise): a springback coupling moves part of the machine's deflection into the
    sheet's recovery."""
    truth = summary.get("truth")
    sc = truth.get("springback_coupling") if isinstance(truth, Mapping) else None
    if not isinstance(sc, Mapping) or not sc.get("coupling"):
        return ""
    c, depth = float(sc["coupling"]), sc.get("depth_mm")
    law = f"{c:g}·exp(−depth / {float(depth):g} mm)" if depth else f"{c:g}"
    return (
        "Robot compliance: the dashed truth is the machine's deflection; the recovered term is "
        "what the formed part keeps of it. The truth's springback coupling makes the sheet "
        f"recover c(depth) = {law} of the machine's normal deflection, so the recovered robot "
        "term lies below the truth where c is large and approaches it where c fades — the "
        "method separates what the part shows, as intended, not a failure."
    )


def _figure_html(spec: _Figure, fig: pf.Figure, first: bool) -> str:
    div = pio.to_html(
        fig.to_plotly_json(),
        validate=False,  # plain JSON (roboisf.report.plotfig); tests validate every figure
        full_html=False,
        include_plotlyjs=True if first else False,
        include_mathjax=False,
        div_id=f"fig-{spec.id}",
        config=_PLOTLY_CONFIG,
        default_height=f"{int(fig.layout.get('height') or 420)}px",
        default_width="100%",
    )
    return (
        f'<figure id="figure-{spec.id}"><h3>{pg.esc(spec.title)}</h3><div class="plot">{div}</div>'
        f"<figcaption>{pg.esc(spec.caption)}</figcaption></figure>"
    )


def _headline_dict(
    h: agg.Headline, summary: Mapping[str, Any], contrib: pd.DataFrame
) -> dict[str, Any]:
    ranked = sorted(FACTORS, key=lambda f: -float(contrib.loc[f, "share_percent"]))
    part = summary.get("part") or {}
    robot = summary.get("robot") or {}
    return {
        "study": str(summary["study"]),
        "part": str(part.get("kind", "")) if isinstance(part, Mapping) else str(part),
        "robot": str(robot.get("preset", "")) if isinstance(robot, Mapping) else str(robot),
        "R_m_total_mm": h.R_m_total,
        "robot_share_percent": h.robot_share_percent,
        "springback_share_percent": h.springback_share_percent,
        "R_m_total_normal_mm": h.R_m_total_normal,
        "robot_share_percent_normal": h.robot_share_percent_normal,
        "largest_factor": ranked[0],
        "shares_percent": {f: float(contrib.loc[f, "share_percent"]) for f in FACTORS},
        "n_warnings": len(summary["warnings"]),
        "study_kind": study_kind(summary).kind,
        **_check_headline(summary),
    }


def _check_headline(summary: Mapping[str, Any]) -> dict[str, Any]:
    vc = summary.get("vjm_check")
    if not isinstance(vc, Mapping):
        return {}
    return {
        "vjm_ratio": vc.get("ratio"),
        "vjm_verdict": "holds by construction" if vc.get("by_construction") else vc.get("verdict"),
    }


def _cards(h: agg.Headline, summary: Mapping[str, Any]) -> str:
    vjm = summary.get("vjm_vs_experiment") or {}
    resultant = vjm.get("resultant") if isinstance(vjm, Mapping) else None
    tuned = study_kind(summary).kind == "virtual_tuned"
    mark = f" {pg.BY_CONSTRUCTION}" if tuned else ""
    why = " · truth tuned to the paper's share" if tuned else ""
    cards = [
        (
            "",
            "Resultant mean deviation R<sub>m</sub>",
            f"{h.R_m_total:.3f}<small>mm</small>",
            f"normal projection: {h.R_m_total_normal:.3f} mm",
        ),
        (
            " accent",
            f"Robot compliance share{mark}",
            f"{h.robot_share_percent:.1f}<small>%</small>",
            f"R<sub>m</sub> {h.robot_R_m:.3f} mm · normal projection: "
            f"{h.robot_share_percent_normal:.1f} %{why}",
        ),
        (
            "",
            f"Springback share{mark}",
            f"{h.springback_share_percent:.1f}<small>%</small>",
            f"CNC part taken as rigid{why}",
        ),
    ]
    check = check_card(summary)
    if check is not None:
        cards.append(check)
    elif resultant is not None:
        cards.append(
            (
                "",
                "VJM − experiment |Δ|",
                f"{float(resultant):.3f}<small>mm</small>",
                "mean Δ resultant, see the robot section",
            )
        )
    return (
        '<div class="cards">'
        + "".join(
            f'<div class="card{cls}"><div class="label">{label}</div><div '
            f'class="value">{value}</div>'
            f'<div class="note">{note}</div></div>'
            for cls, label, value, note in cards
        )
        + "</div>"
    )


def _verdict(contrib: pd.DataFrame) -> str:
    ranked = sorted(FACTORS, key=lambda f: -float(contrib.loc[f, "share_percent"]))
    parts = [
        f"<b>{FACTOR_LABELS[f].lower()}</b> ({contrib.loc[f, 'share_percent']:.1f} %)"
        for f in ranked
    ]
    return (
        f'<p class="verdict">Largest contributor: {parts[0]}, then {parts[1]}, {parts[2]} '
        f"and {parts[3]} "
        "(shares of the per-axis resultant mean deviation).</p>"
    )


def _section(sid: str, title: str, lead: str, content: str) -> str:
    return (
        f'<section id="{sid}"><h2>{pg.esc(title)}</h2><p class="lead">{lead}</p>{content}</section>'
    )


def write_report(
    per_point: pd.DataFrame,
    contributions: pd.DataFrame,
    contributions_normal: pd.DataFrame,
    summary: Mapping[str, Any],
    out_dir: str | Path,
    *,
    png: bool = False,
    progress: Progress | None = None,
    processes: int | None = None,
) -> Path:
    """Write ``out_dir/report.html`` (self-contained, offline) and ``out_dir/figures/<id>.png``.

    Parameters
    ----------
    per_point : DataFrame
        One row per toolpath point, columns :data:`roboisf.report.REQUIRED_COLUMNS` (+ optional
        :data:`~roboisf.report.OPTIONAL_COLUMNS`); mm, deg, N, N·m, s.
    contributions, contributions_normal : DataFrame
        The contribution table (paper's Table 5) per-axis and projected on the surface normal:
        columns ``factor, mean_abs_dx, mean_abs_dy, mean_abs_dz, R_m, share_percent``, rows
        ``tool, tool_holder, springback, robot_compliance, total`` (mm, %).
    summary : dict
        Must have ``study``; uses ``part, robot, tool, units, compliance_stats,
        force_contributions, vjm_vs_experiment, contour_z`` (mm; absent or None: the middle of
        the analysed wall) and ``warnings``.
    out_dir
        Created if missing. Files are written atomically; other files in it are left alone.
    png
        Also write the static matplotlib figures (:data:`FIGURES`, one PNG each).
    progress
        Optional :class:`roboisf.progress.Progress`.
    processes
        Worker processes drawing the PNGs while this process writes the HTML (0: all in this
        process). Default: ``$ROBOISF_REPORT_PROCESSES``, else one fewer than the usable CPUs
        (at most 3). The files are the same bytes either way.

    Returns
    -------
    Path of ``report.html``.

    Raises
    ------
    InputError
        A required column, row or key is missing or malformed (named in the message), before any
        file is written.
    """
    pp = check_per_point(per_point)
    contrib = check_contributions(contributions, name="contributions")
    contrib_n = check_contributions(contributions_normal, name="contributions_normal")
    summ = check_summary(summary)
    out = Path(out_dir)
    part = summ.get("part")
    kind = part.get("kind") if isinstance(part, Mapping) else part
    round_part = agg.is_round(pp, summ["part_symmetry"], None if kind is None else str(kind))
    ids = figure_ids(round_part)
    with agg.reused():  # both renderers draw the same reductions: computed once
        return _write_report(
            pp, contrib, contrib_n, summ, out, png, progress, round_part, ids, processes
        )


def _write_report(
    pp: pd.DataFrame,
    contrib: pd.DataFrame,
    contrib_n: pd.DataFrame,
    summ: Mapping[str, Any],
    out: Path,
    png: bool,
    progress: Progress | None,
    round_part: bool,
    ids: tuple[str, ...],
    processes: int | None = None,
) -> Path:
    part = summ.get("part")
    kind = part.get("kind") if isinstance(part, Mapping) else part
    contour_id = ids[ids.index("vjm_path") + 1]
    figs = _figures(pp, contrib, contrib_n, summ["contour_z"], round_part)
    reason = _truth_reason(summ)
    if reason and any(f"truth_{f}_dn" in pp.columns for f in FACTORS):
        spec = figs["factors_depth"]
        figs["factors_depth"] = dataclasses.replace(spec, caption=f"{spec.caption} {reason}")
    mismatch = _mismatch_reason(summ)
    for fid in ("vjm_path", contour_id) if mismatch else ():
        figs[fid] = dataclasses.replace(figs[fid], caption=f"{figs[fid].caption} {mismatch}")

    html_parts: dict[str, str] = {}
    with task(progress, "report", total=len(ids) * (2 if png else 1) + 1) as advance:
        if png:
            out.joinpath("figures").mkdir(parents=True, exist_ok=True)
        renderer = PngRenderer(
            out / "figures",
            ids if png else (),
            figs,
            (pp, contrib, contrib_n, summ["contour_z"], round_part),
            default_processes() if processes is None else processes,
            on_done=lambda: advance(1),
        )
        with renderer:  # PNG workers draw while this process writes the plotly HTML
            # the 3D view comes first on the page and carries plotly.js (HTML only, no PNG)
            spec3d = _part_figure(pp)
            part3d = _figure_html(spec3d, spec3d.plotly(), first=True)
            for fid in ids:
                html_parts[fid] = _figure_html(figs[fid], figs[fid].plotly(), first=False)
                advance(1)
            renderer.finish()  # draws what the workers have not taken, waits for them

        h = agg.headline(contrib, contrib_n)
        head = _headline_dict(h, summ, contrib)
        n_used = int(pp["used"].sum()) if "used" in pp.columns else None
        body = [
            kind_banner(summ),
            _cards(h, summ),
            _verdict(contrib),
            scope_html(summ, len(pp), n_used),
            diagnosis_html(summ),
            pg.warnings_box(summ["warnings"]),
            _section(
                "part",
                "The formed part",
                "Each term along the surface normal at the toolpath points, in 3D: pick a term "
                "with the buttons, drag to turn, scroll to zoom.",
                part3d,
            ),
        ]
        toc = [
            ("part", "3D part"),
            ("contributions", "Contributions"),
            ("forces", "Forces"),
            ("deviations", "Deviations"),
            ("factors", "Factors"),
            ("robot", "Robot model"),
            ("thickness", "Thickness"),
            ("study", "Study"),
        ]
        body.insert(
            0, '<nav class="toc">' + "".join(f'<a href="#{a}">{t}</a>' for a, t in toc) + "</nav>"
        )
        body.append(
            _section(
                "contributions",
                "Contributions (Table 5)",
                "δR = δc + δs + δt + δth. Per factor: mean absolute deviation per work "
                "axis, the resultant "
                "R<sub>m</sub> = √(mean|δx|² + mean|δy|² + mean|δz|²) and its share. Two versions: "
                "<b>per-axis vectors</b> (the paper's way) and <b>projected on the surface "
                "normal</b> "
                "(the only component a scan of the formed surface can observe).",
                '<div class="tables">'
                + pg.contribution_table(contrib, "Per-axis vectors", "the paper's way")
                + pg.contribution_table(
                    contrib_n, "Projected on the surface normal", "what a scan observes"
                )
                + "</div>"
                + html_parts["contributions"],
            )
        )
        body.append(
            _section(
                "forces",
                "Forming forces",
                "Wrenches brought from the sensors to the tool tip, CNC vs robot.",
                alignment_html(summ.get("alignment")) + html_parts["forces"],
            )
        )
        body.append(
            _section(
                "deviations",
                "Measured deviations",
                "Scan of each formed part against the nominal surface, per toolpath point.",
                html_parts["deviation_depth"]
                + html_parts["deviation_map"]
                + html_parts["deviation_top"],
            )
        )
        body.append(
            _section(
                "factors",
                "Decomposition along the depth",
                "Tool and holder from their compliances and the measured wrench; "
                "springback = CNC deviation − "
                "tool; robot compliance = robot deviation − springback − tool − holder.",
                html_parts["factors_depth"],
            )
        )
        robot_tables = []
        books = [
            (label, summ[key])
            for key, label in (
                ("vjm_vs_experiment", "projected on the surface normal (what a scan observes)"),
                ("vjm_vs_experiment_per_axis", "per-axis vectors (the paper's way)"),
            )
            if isinstance(summ.get(key), Mapping)
        ]
        if books:
            robot_tables.append(pg.vjm_table(books))
        if isinstance(summ.get("force_contributions"), Mapping) and summ["force_contributions"]:
            robot_tables.append(pg.force_contribution_table(summ["force_contributions"]))
        if isinstance(summ.get("compliance_stats"), Mapping) and summ["compliance_stats"]:
            robot_tables.append(pg.compliance_table(summ["compliance_stats"]))
        body.append(
            _section(
                "robot",
                "Robot compliance: experiment vs Virtual Joint Model",
                "δc<sub>VJM</sub> = k<sub>c</sub>·W with k<sub>c</sub> = J<sub>θ</sub> "
                "K<sub>θ</sub><sup>−1</sup> "
                "J<sub>θ</sub><sup>T</sup> along the path; Δ = δc<sub>exp</sub> − "
                "δc<sub>VJM</sub>.",
                check_tables(summ)
                + html_parts["vjm_path"]
                + html_parts[contour_id]
                + "".join(robot_tables),
            )
        )
        body.append(
            _section(
                "thickness",
                "Wall thickness",
                "Sine law and, when given, measurement.",
                html_parts["thickness"],
            )
        )
        if summ.get("iterations"):  # several robot runs: report/iterations.py
            from roboisf.report import iterations as it

            body.append(
                _section(
                    "iterations", "Iterations", it.LEAD, it.iterations_section(summ["iterations"])
                )
            )
            it.write_iterations_csv(summ["iterations"], out)
        items = [(k, summ.get(k)) for k in ("study", "part", "robot", "tool", "units")]
        lap, z, note = agg.contour_lap(pp, summ["contour_z"])
        asked = summ["contour_z"]
        items.append(
            (
                "contour for the polar plot" if round_part else "contour plot (part not round)",
                f"lap {lap} at z = {z:.2f} mm"
                + (
                    " (none asked: the middle of the analysed wall)"
                    if asked is None
                    else f" (asked: z = {asked:g} mm{'' if note is None else '; see its caption'})"
                ),
            )
        )
        items.append(
            (
                "toolpath",
                f"{len(pp)} points, {pp['lap'].nunique()} laps, depth "
                f"{pp['depth'].min():.2f}–{pp['depth'].max():.2f} mm",
            )
        )
        if png:
            items.append(("static figures", ", ".join(f"figures/{f}.png" for f in ids)))
        body.append(_section("study", "Study", "What was analysed.", pg.kv_table(items)))

        subtitle = pg.esc(" · ".join(str(x) for x in (kind, head["robot"]) if x))
        document = pg.page(
            f"roboisf report — {summ['study']}", "".join(body), headline=head, subtitle=subtitle
        )
        out.mkdir(parents=True, exist_ok=True)
        path = out / "report.html"
        with atomic_write(path, "w") as fh:
            fh.write(document)
        advance(1)
    return path


_META_RE = re.compile(r'<meta name="' + pg.HEADLINE_META + r'" content="([^"]*)">')


def read_headline(report: str | Path) -> dict[str, Any]:
    """The headline numbers a report written by :func:`write_report` carries in its ``<head>``."""
    path = Path(report)
    if path.is_dir():
        path = path / "report.html"
    try:
        with open(path, encoding="utf-8") as fh:
            head = fh.read(65536)
    except OSError as exc:
        raise InputError(f"cannot read the report ({exc.strerror})", file=path) from None
    m = _META_RE.search(head)
    if not m:
        raise InputError("not a roboisf report (no headline in its <head>)", file=path)
    result: dict[str, Any] = json.loads(_html.unescape(m.group(1)))
    return result


#: The index's words for each study kind (:func:`roboisf.report.statements.study_kind`).
_KIND_LABELS = {
    "measured": "measured",
    "virtual": "virtual cell",
    "virtual_tuned": "virtual, tuned truth",
}


def write_index(entries: Sequence[str | Path], out_path: str | Path) -> Path:
    """Write an index page linking several study reports, with their headline numbers.

    Parameters
    ----------
    entries
        Paths of ``report.html`` files written by :func:`write_report` (or their folders).
        Links are written relative to the index, so the folder can be moved as a whole.
    out_path
        The index HTML file (written atomically).
    """
    if not entries:
        raise InputError("no reports to index (expected at least one report.html)", field="entries")
    out = Path(out_path)
    rows, kinds = [], set()
    for entry in entries:
        path = Path(entry)
        path = path / "report.html" if path.is_dir() else path
        h = read_headline(path)
        kinds.add(h.get("study_kind"))
        href = os.path.relpath(path.resolve(), out.resolve().parent).replace(os.sep, "/")
        warn = h.get("n_warnings", 0)
        rows.append(
            f'<tr><td><a href="{pg.esc(href)}">{pg.esc(h["study"])}</a></td>'
            f'<td class="t">{pg.esc(_KIND_LABELS.get(h.get("study_kind", ""), "—"))}</td>'
            f'<td class="t">{pg.esc(h.get("part", ""))}</td>'
            f'<td class="t">{pg.esc(h.get("robot", ""))}</td>'
            f"<td>{pg.fmt(h['R_m_total_mm'], 3)}</td>"
            f"<td>{pg.fmt(h['robot_share_percent'], 1)}</td>"
            f"<td>{pg.fmt(h['springback_share_percent'], 1)}</td>"
            f"<td>{pg.fmt(h.get('vjm_ratio'), 2)}</td>"
            f'<td class="t">{pg.esc(h.get("vjm_verdict") or "—")}</td>'
            f'<td class="t">{pg.share_bar(h.get("shares_percent") or {})}</td><td>{warn}</td></tr>'
        )
    tuned = (
        " A virtual cell whose truth was tuned to the paper reproduces the paper's shares by "
        "construction: they reproduce it, they do not confirm it."
        if "virtual_tuned" in kinds
        else ""
    )
    table = (
        '<table><thead><tr><th>study</th><th class="t">kind</th><th class="t">part</th>'
        '<th class="t">robot</th>'
        "<th>R<sub>m</sub> (mm)</th><th>robot share (%)</th><th>springback share (%)</th>"
        '<th>measured / VJM</th><th class="t">robot model</th>'
        '<th class="t">shares</th><th>warnings</th>'
        f"</tr></thead><tbody>{''.join(rows)}</tbody></table>"
    )
    body = (
        '<section><h2>Studies</h2><p class="lead">Each row links to a self-contained report. '
        "R<sub>m</sub> and shares are the per-axis (paper's) version; each report also gives them "
        f'projected on the surface normal.{tuned}</p><div class="scroll">{table}</div>'
        f"{pg.share_legend()}</section>"
    )
    document = pg.page("roboisf — study reports", body, subtitle=f"{len(rows)} studies")
    with atomic_write(out, "w") as fh:
        fh.write(document)
    return out
