"""HTML building blocks: the page shell and CSS, tables, the headline cards. No plotting here."""

from __future__ import annotations

import html
import json
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from roboisf import __version__
from roboisf.report.schema import FACTORS

if TYPE_CHECKING:
    import pandas as pd
from roboisf.report.style import FACTOR_COLORS, FACTOR_LABELS, FONT_STACK

__all__ = [
    "BY_CONSTRUCTION",
    "HEADLINE_META",
    "compliance_table",
    "contribution_table",
    "esc",
    "fmt",
    "fmt_scaled",
    "force_contribution_table",
    "kv_table",
    "page",
    "share_bar",
    "share_legend",
    "vjm_table",
    "warnings_box",
]

#: ``<meta name=...>`` carrying the headline numbers as JSON, read back by the index page.
HEADLINE_META = "roboisf-headline"

#: The mark of a number that holds by construction: the study's truth was set to give it, so it
#: is not a finding.
BY_CONSTRUCTION = (
    '<span class="bc" title="set by the study\'s truth, not found by the analysis">'
    "by construction</span>"
)

CSS = """
:root { --text:#1F2933; --muted:#616E7C; --line:#E4E7EB; --bg:#F5F7FA; --accent:#D55E00; }
* { box-sizing:border-box; }
html { -webkit-text-size-adjust:100%; }
body { margin:0; font-family:%FONT%; color:var(--text); background:var(--bg); line-height:1.5;
       font-size:15px; }
header.top { background:#1F2933; color:#F5F7FA; padding:28px 0 24px; }
header.top .wrap { display:flex; flex-wrap:wrap; align-items:flex-end;
    justify-content:space-between; gap:8px 24px; }
header.top h1 { margin:0; font-size:26px; font-weight:650; letter-spacing:-0.01em; }
header.top .sub { color:#CBD2D9; font-size:14px; }
header.top a { color:#F5F7FA; }
.wrap { max-width:1180px; margin:0 auto; padding:0 24px; }
main.wrap { padding:22px 24px 48px; }
nav.toc { display:flex; flex-wrap:wrap; gap:6px 18px; font-size:13.5px; margin:0 0 18px; }
nav.toc a { color:var(--muted); text-decoration:none; border-bottom:1px dotted #9AA5B1; }
nav.toc a:hover { color:var(--text); }
.cards { display:grid; grid-template-columns:repeat(auto-fit, minmax(220px, 1fr));
    gap:14px; margin:0 0 14px; }
.card { background:white; border:1px solid var(--line); border-radius:10px; padding:14px 18px; }
.card .label { color:var(--muted); font-size:13px; font-weight:600; letter-spacing:0.01em; }
.card .value { font-size:30px; font-weight:650; font-variant-numeric:tabular-nums;
    line-height:1.2; margin-top:4px; }
.card .value small { font-size:15px; font-weight:500; color:var(--muted); margin-left:2px; }
.card .note { color:var(--muted); font-size:12.5px; margin-top:2px; }
.card.accent { border-top:4px solid var(--accent); }
.card.warn { border-top:4px solid #D55E00; }
.bc { display:inline-block; font-size:11px; font-weight:600; color:#7A4D00; background:#FFF1CC;
    border:1px solid #F0C36D; border-radius:4px; padding:0 5px; margin-left:4px;
    vertical-align:1px; letter-spacing:0; }
.kind { background:white; border:1px solid var(--line); border-left:5px solid #0072B2;
    border-radius:8px; padding:10px 16px; margin:0 0 14px; font-size:14.5px; }
.kind-virtual_tuned, .kind-virtual { border-left-color:#E69F00; }
p.scope { font-size:14px; margin:-8px 0 18px; color:var(--text); }
td.wrap { white-space:normal; min-width:260px; }
tr.v-fault td { background:#FDECEA; }
tr.v-cannot_tell td { color:var(--muted); }
p.verdict { font-size:16px; margin:4px 0 20px; }
section { background:white; border:1px solid var(--line); border-radius:10px; padding:20px 24px;
          margin:0 0 20px; }
section h2 { margin:0 0 4px; font-size:19px; font-weight:650; }
section h3 { margin:18px 0 6px; font-size:15px; font-weight:650; }
section p.lead { margin:0 0 12px; color:var(--muted); font-size:14px; max-width:880px; }
figure { margin:10px 0 6px; }
figure .plot { width:100%; }
figcaption { color:var(--muted); font-size:13px; margin-top:4px; }
.tables { display:grid; grid-template-columns:1fr; gap:8px; }
.scroll { overflow-x:auto; }
table { border-collapse:collapse; font-size:13.5px; font-variant-numeric:tabular-nums;
    width:100%; margin:4px 0 8px; }
caption { text-align:left; font-weight:600; padding:0 0 6px; font-size:14px; }
caption span { font-weight:400; color:var(--muted); }
th, td { padding:5px 10px; border-bottom:1px solid var(--line); text-align:right;
    white-space:nowrap; }
th:first-child, td:first-child, th.t, td.t { text-align:left; }
.sharebar { display:flex; width:220px; height:12px; border-radius:3px; overflow:hidden;
    background:var(--line); }
.sharebar span { display:block; height:100%; }
.legend { color:var(--muted); font-size:13px; display:flex; gap:16px; flex-wrap:wrap; }
thead th { color:var(--muted); font-weight:600; font-size:12.5px;
    border-bottom:2px solid #CBD2D9; }
tr.total td { font-weight:650; border-top:2px solid #CBD2D9; }
.swatch { display:inline-block; width:10px; height:10px; border-radius:2px;
    margin-right:7px; vertical-align:0; }
.warnings { background:#FFF8E6; border:1px solid #F0C36D; border-left:5px solid #E69F00;
    border-radius:8px;
            padding:10px 16px; margin:0 0 20px; }
.warnings h2 { font-size:15px; margin:0 0 4px; }
.warnings ul { margin:0; padding-left:20px; }
.ok { color:var(--muted); font-size:13.5px; margin:0 0 20px; }
dl.kv { display:grid; grid-template-columns:max-content 1fr; gap:2px 18px; margin:0;
    font-size:14px; }
dl.kv dt { color:var(--muted); }
dl.kv dd { margin:0; font-variant-numeric:tabular-nums; }
footer { color:var(--muted); font-size:12.5px; padding:0 0 32px; }
a { color:#0072B2; }
@media print { body { background:white; } section { break-inside:avoid; border:none; } }
""".replace("%FONT%", FONT_STACK)


def esc(value: Any) -> str:
    return html.escape(str(value), quote=True)


#: Below this magnitude a table number is floating-point noise and reads 0 (a moment of
#: 9.2e-21 N·m, a compliance coupling of -2.9e-24 m/N showed as such); every physical value
#: the reports print is far above it in its unit (the smallest: compliances of ~1e-9 m/N).
FLOAT_NOISE = 1e-15


#: Digit group separator of large table numbers (U+202F, narrow no-break space, as SI writes
#: 3 730 000): never a line break inside a number.
GROUP_SEPARATOR = "\u202f"
#: From this magnitude on a table number has its digits grouped by three.
GROUP_FROM = 1e4
#: Significant digits a real value smaller than a column's last decimal keeps.
SMALL_DIGITS = 2


def fmt(value: Any, digits: int = 3) -> str:
    """A table number, always in fixed point (no e-notation beside fixed-point neighbours).

    ``digits`` decimals for ordinary sizes; a real value too small for them keeps
    :data:`SMALL_DIGITS` significant digits (1.574e-4 at 3 decimals reads 0.00016, not
    1.574e-04 nor 0.000), while a floating-point zero (below :data:`FLOAT_NOISE`) reads 0.000;
    from :data:`GROUP_FROM` on the digits are grouped by three (3 730 000, not 3.730e+06
    beside 638000). '—' for none, NaN or inf. Where a whole column is small, give it a scaled
    unit instead (µm/N, N/kN) so that it reads at the column's precision.
    """
    if value is None:
        return "—"
    if isinstance(value, bool) or not isinstance(value, int | float):
        return esc(value)
    x = float(value)
    if not math.isfinite(x):
        return "—"
    if abs(x) < FLOAT_NOISE:  # a zero computed in floating point (1e-21 N·m), not a value
        x = 0.0
    decimals = digits
    if x != 0 and abs(x) < 10.0 ** (-digits):
        decimals = SMALL_DIGITS - 1 - math.floor(math.log10(abs(x)))
    if abs(x) >= GROUP_FROM:
        return f"{x:,.{decimals}f}".replace(",", GROUP_SEPARATOR)
    text = f"{x:.{decimals}f}"
    return text[1:] if text.startswith("-") and float(text) == 0 else text  # no "-0.000"


def fmt_scaled(value: Any, scale: float, digits: int = 3) -> str:
    """:func:`fmt` of ``value × scale`` — a number shown in a scaled unit (µm/N for m/N, N/kN
    for N/N); a floating-point zero of the *unscaled* value still reads 0.000."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return fmt(value, digits)
    x = float(value)
    return fmt(0.0 if abs(x) < FLOAT_NOISE else x * scale, digits)


def _swatch(factor: str) -> str:
    return f'<span class="swatch" style="background:{FACTOR_COLORS[factor]}"></span>'


def contribution_table(table: pd.DataFrame, title: str, note: str) -> str:
    """The paper's Table 5 from a checked contribution table (indexed by factor; mm, %)."""
    head = (
        "<thead><tr><th>factor</th><th>mean |δx| (mm)</th><th>mean |δy| (mm)</th>"
        "<th>mean |δz| (mm)</th><th>R<sub>m</sub> (mm)</th><th>share (%)</th></tr></thead>"
    )
    rows = []
    for f in (*FACTORS, "total"):
        r = table.loc[f]
        cls = ' class="total"' if f == "total" else ""
        rows.append(
            f"<tr{cls}><td>{_swatch(f)}{esc(FACTOR_LABELS[f])}</td>"
            f"<td>{fmt(r['mean_abs_dx'], 4)}</td><td>{fmt(r['mean_abs_dy'], 4)}</td>"
            f"<td>{fmt(r['mean_abs_dz'], 4)}</td><td>{fmt(r['R_m'], 4)}</td>"
            f"<td>{fmt(r['share_percent'], 2)}</td></tr>"
        )
    caption = f"<caption>{esc(title)} <span>— {esc(note)}</span></caption>"
    return f"<table>{caption}{head}<tbody>{''.join(rows)}</tbody></table>"


_K_KEY = re.compile(r"^k_?([1-6])([1-6])$")


def _k_unit(i: int, j: int) -> str:
    """The unit of ``k_ij`` in the table, scaled by 10⁶ (SI: m/N, rad/(N·m), 1/N)."""
    if i <= 3 and j <= 3:
        return "µm/N"
    if i >= 4 and j >= 4:
        return "µrad/(N·m)"
    return "µm/(N·m)" if i <= 3 else "µrad/N"  # 1/N: a moment's displacement, a force's turn


#: The compliance table's scale: SI × 10⁶ (µm/N …), so a robot's 1e-9 … 1e-5 m/N read as
#: 0.0010 … 10.0000 at four decimals instead of 8.522e-07 beside 0.000.
K_SCALE = 1e6


def compliance_table(stats: Mapping[str, Any]) -> str:
    """Cartesian compliance along the path: ``{"k_11": {mean, std, min, max}, ...}`` (SI in,
    shown × :data:`K_SCALE` in µm/N, µm/(N·m), µrad/N and µrad/(N·m) at four decimals)."""

    def order(key: str) -> tuple[int, int, str]:
        m = _K_KEY.match(key)
        return (int(m.group(1)), int(m.group(2)), key) if m else (9, 9, key)

    rows = []
    for key in sorted(stats, key=order):
        entry = stats[key]
        m = _K_KEY.match(key)
        unit = _k_unit(int(m.group(1)), int(m.group(2))) if m else ""
        label = f"k<sub>{m.group(1)}{m.group(2)}</sub>" if m else esc(key)
        scale = K_SCALE if m else 1.0  # a key that is no k_ij: as given, its unit unknown
        if isinstance(entry, Mapping):
            cells = "".join(
                f"<td>{fmt_scaled(entry.get(s), scale, 4)}</td>"
                for s in ("mean", "std", "min", "max")
            )
        else:
            cells = f"<td>{fmt_scaled(entry, scale, 4)}</td>" + "<td>—</td>" * 3
        rows.append(f"<tr><td>{label}</td><td>{esc(unit)}</td>{cells}</tr>")
    head = (
        "<thead><tr><th>entry</th><th>unit</th><th>mean</th><th>std</th><th>min</th><th>max</th>"
        "</tr></thead>"
    )
    return (
        "<table><caption>Cartesian compliance at the tool tip along the path "
        "<span>— robot, work frame, in millionths of the SI unit (µm/N …)</span></caption>"
        f"{head}<tbody>{''.join(rows)}</tbody></table>"
    )


_WRENCH_ORDER = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")


def force_contribution_table(fc: Mapping[str, Any]) -> str:
    """The paper's Table 4: ``{"dx": {"Fx": mm, ..., "Mz": mm}, "dy": ..., "dz": ...}``."""
    comps: list[str] = [
        c for c in _WRENCH_ORDER if any(isinstance(v, Mapping) and c in v for v in fc.values())
    ]
    for v in fc.values():
        if isinstance(v, Mapping):
            comps += [c for c in v if c not in comps]
    head = (
        "<thead><tr><th>deflection</th>"
        + "".join(f"<th>{esc(c)} (mm)</th>" for c in comps)
        + "</tr></thead>"
    )
    rows = []
    for axis, values in fc.items():
        label = esc(axis).replace("d", "δ", 1) if str(axis).startswith("d") else esc(axis)
        if isinstance(values, Mapping):
            cells = "".join(f"<td>{fmt(values.get(c), 4)}</td>" for c in comps)
        else:
            cells = f"<td>{fmt(values, 4)}</td>" + "<td></td>" * (len(comps) - 1)
        rows.append(f"<tr><td>{label}</td>{cells}</tr>")
    return (
        "<table><caption>Contribution of each force/moment component to the robot deflection "
        "<span>— the paper's Table 4, mm</span></caption>"
        f"{head}<tbody>{''.join(rows)}</tbody></table>"
    )


def vjm_table(books: Sequence[tuple[str, Mapping[str, Any]]]) -> str:
    """Δ_i = mean|δc_exp,i| − mean|δc_VJM,i| per axis and its resultant (mm), one row per book
    (label, values)."""
    keys = ["x", "y", "z", "resultant"]
    head = (
        "<thead><tr><th>book</th>"
        + "".join(f"<th>Δ{esc(k) if k != 'resultant' else ' resultant'} (mm)</th>" for k in keys)
        + "</tr></thead>"
    )
    body = "".join(
        f'<tr><td class="t">{esc(label)}</td>'
        + "".join(f"<td>{fmt(vjm.get(k, float('nan')), 4)}</td>" for k in keys)
        + "</tr>"
        for label, vjm in books
    )
    return (
        "<table><caption>VJM vs experiment "
        "<span>— Δ<sub>i</sub> = mean|δc<sub>exp,i</sub>| − mean|δc<sub>VJM,i</sub>| (the "
        "paper's comparison). Only the normal projection can vanish when the model is right: "
        "no scan sees the VJM's tangential deflection.</span>"
        f"</caption>{head}<tbody>{body}</tbody></table>"
    )


#: Key–value entries whose key names an SI unit too small to read, shown in the tables' scaled
#: unit instead (suffix of the key: unit, scale, decimals): a tool's lateral compliance
#: 9.40099e-07 m/N reads 0.9401 µm/N, as in the compliance table.
KV_SCALED_UNITS = {"_m_per_N": ("µm/N", K_SCALE, 4)}
#: Significant digits of any other float in a key–value list (an echo of the study's inputs).
KV_DIGITS = 6


def _kv_float(x: float) -> str:
    """A float of a key–value list: as typed (6 significant digits), in fixed point — never
    e-notation beside the tables' fixed point (1.03274e-07 reads 0.000000103274); a
    floating-point zero (below :data:`FLOAT_NOISE`) reads 0."""
    if not math.isfinite(x):
        return "—"
    if abs(x) < FLOAT_NOISE:
        return "0"
    text = f"{x:.{KV_DIGITS}g}"
    if "e" not in text:
        return text
    decimals = max(0, KV_DIGITS - 1 - math.floor(math.log10(abs(x))))
    text = f"{x:,.{decimals}f}".replace(",", GROUP_SEPARATOR if abs(x) >= GROUP_FROM else "")
    return text.rstrip("0").rstrip(".") if "." in text else text


def _inline(value: Any, key: str = "") -> str:
    if isinstance(value, Mapping):
        return ", ".join(f"{esc(k)} = {_inline(v, str(k))}" for k, v in value.items())
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_inline(v, key) for v in value) + "]"
    if isinstance(value, float | int) and not isinstance(value, bool):
        for suffix, (unit, scale, digits) in KV_SCALED_UNITS.items():
            if key.endswith(suffix):
                return f"{fmt_scaled(value, scale, digits)} {esc(unit)}"
    if isinstance(value, float):
        return esc(_kv_float(value))
    return esc(value)


def kv_table(items: Iterable[tuple[str, Any]]) -> str:
    """A definition list of (label, value); nested dicts are flattened inline. Numbers never in
    e-notation: a value whose key names a tiny SI unit (``…_m_per_N``) in the tables' scaled
    unit (:data:`KV_SCALED_UNITS`), any other float in fixed point (:func:`_kv_float`)."""
    body = "".join(
        f"<dt>{esc(k)}</dt><dd>{_inline(v, str(k))}</dd>"
        for k, v in items
        if v not in (None, {}, [])
    )
    return f'<dl class="kv">{body}</dl>'


def share_bar(shares: Mapping[str, Any]) -> str:
    """A stacked bar (pure CSS) of the factors' shares in percent."""
    spans = []
    for f in FACTORS:
        value = shares.get(f)
        if isinstance(value, int | float) and math.isfinite(value) and value > 0:
            title = f"{FACTOR_LABELS[f]} {value:.1f} %"
            spans.append(
                f'<span title="{esc(title)}" '
                f'style="width:{min(value, 100.0):.2f}%;background:{FACTOR_COLORS[f]}"></span>'
            )
    return f'<div class="sharebar">{"".join(spans)}</div>'


def share_legend() -> str:
    items = "".join(f"<span>{_swatch(f)}{esc(FACTOR_LABELS[f])}</span>" for f in FACTORS)
    return f'<div class="legend">{items}</div>'


def warnings_box(warnings: list[str]) -> str:
    if not warnings:
        return '<p class="ok">No warnings from the analysis.</p>'
    items = "".join(f"<li>{esc(w)}</li>" for w in warnings)
    title = f"<h2>Warnings ({len(warnings)})</h2>"
    return f'<div class="warnings" id="warnings">{title}<ul>{items}</ul></div>'


def page(
    title: str, body: str, *, headline: Mapping[str, Any] | None = None, subtitle: str = ""
) -> str:
    meta = ""
    if headline is not None:
        meta = f'<meta name="{HEADLINE_META}" content="{esc(json.dumps(dict(headline)))}">'
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f'<meta name="generator" content="roboisf {esc(__version__)}">{meta}'
        f"<title>{esc(title)}</title><style>{CSS}</style></head><body>"
        f'<header class="top"><div class="wrap"><h1>{esc(title)}</h1>'
        f'<div class="sub">{subtitle}</div></div></header>'
        f'<main class="wrap">{body}</main>'
        f'<footer class="wrap">Written by roboisf {esc(__version__)} — method after Bharti et al., '
        "Sci. Rep. 14:20291 (2024). Lengths in mm, angles in degrees, forces in N. "
        "This file is self-contained and works offline.</footer>"
        "</body></html>\n"
    )
