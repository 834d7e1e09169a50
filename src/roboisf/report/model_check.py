"""HTML of the model check (``summary.json`` → ``vjm_check``, ``identification``,
``terms_normal``): the headline card and the robot section's tables. No plotting here."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from roboisf.report.page import BY_CONSTRUCTION, esc, fmt

__all__ = ["check_card", "check_tables", "terms_table"]

_VERDICT = {
    "consistent": "model holds",
    "mismatch": "model does not hold",
    "not_observable": "not observable",
}


def check_card(summary: Mapping[str, Any]) -> tuple[str, str, str, str] | None:
    """The headline card ``(css class, label, value, note)`` of the VJM check, or None.

    When the study is a virtual cell whose truth is the model, the card says the agreement holds
    by construction instead of quoting it as a finding."""
    vc = summary.get("vjm_check")
    if not isinstance(vc, Mapping):
        return None
    if vc.get("verdict") == "not_observable" or vc.get("ratio") is None:
        return ("", "Robot model check", "not observable", esc(vc.get("reason", "")))
    ratio, lo, hi = vc["ratio"], vc.get("ci_low"), vc.get("ci_high")
    interval = f"95 % [{fmt(lo, 2)}, {fmt(hi, 2)}]"
    if vc.get("by_construction"):
        return (
            "",
            f"Robot model check {BY_CONSTRUCTION}",
            "holds by construction",
            "virtual cell whose truth is the model: measured/VJM "
            # the estimate and its interval at one precision ("0.997 (95 % [1.00, 1.00])"
            # put the estimate outside its own interval)
            f"{fmt(ratio, 3)} (95 % [{fmt(lo, 3)}, {fmt(hi, 3)}]) shows only the measurement's "
            "error",
        )
    verdict = str(vc.get("verdict", ""))
    cls = " warn" if verdict == "mismatch" else ""
    return (
        cls,
        f"Robot: measured / VJM ({esc(_VERDICT.get(verdict, verdict))})",
        f"{fmt(ratio, 2)}<small>×</small>",
        f"{interval}; normal book, along the path",
    )


def terms_table(terms: Mapping[str, Mapping[str, float]]) -> str:
    """Signed mean, RMS and mean |·| of each normal term (mm)."""
    from roboisf.report.style import FACTOR_LABELS

    labels = {**FACTOR_LABELS, "vjm": "VJM prediction", "delta": "Δ = measured − VJM"}
    labels |= {"cnc": "CNC part (measured)", "robot": "robot part (measured)"}
    rows = "".join(
        f'<tr><td class="t">{esc(labels.get(k, k))}</td><td>{fmt(v.get("mean_mm"), 4)}</td>'
        f"<td>{fmt(v.get('rms_mm'), 4)}</td><td>{fmt(v.get('mean_abs_mm'), 4)}</td>"
        f"<td>{fmt(v.get('std_mm'), 4)}</td></tr>"
        for k, v in terms.items()
    )
    return (
        "<table><caption>Each term along the normal <span>— signed mean beside RMS and mean "
        "|·| (mm): a term whose mean |·| is far above its |mean| changes sign over the part "
        "(noise, a sideways misregistration), which mean |·| alone would book as error of one "
        "sign</span></caption><thead><tr><th>term</th><th>mean (mm)</th><th>RMS (mm)</th>"
        "<th>mean |·| (mm)</th><th>std (mm)</th></tr></thead>"
        f"<tbody>{rows}</tbody></table>"
    )


def check_tables(summary: Mapping[str, Any]) -> str:
    """The VJM check per depth and the identification, for the robot section ('' if none)."""
    out = []
    vc = summary.get("vjm_check")
    if isinstance(vc, Mapping):
        rows = "".join(
            f"<tr><td>{fmt(r.get('depth_lo_mm'), 1)}–{fmt(r.get('depth_hi_mm'), 1)}</td>"
            f"<td>{fmt(r.get('ratio'), 3)}</td><td>{int(r.get('n', 0))}</td></tr>"
            for r in vc.get("per_depth", [])
        )
        by = (
            " Truth and model are one here: the check holds by construction."
            if vc.get("by_construction")
            else ""
        )
        out.append(
            "<table><caption>Does the VJM hold? <span>— "
            f"measured / VJM robot deflection {fmt(vc.get('ratio'), 3)}, 95 % "
            f"[{fmt(vc.get('ci_low'), 3)}, {fmt(vc.get('ci_high'), 3)}]: "
            f"<b>{esc(vc.get('verdict'))}</b> — {esc(vc.get('reason', ''))}. "
            f"{esc(vc.get('method', ''))}.{by}</span></caption>"
            "<thead><tr><th>depth (mm)</th><th>measured / VJM</th><th>points</th></tr></thead>"
            f"<tbody>{rows}</tbody></table>"
        )
    ident = summary.get("identification")
    if isinstance(ident, Mapping) and ident.get("mode"):
        K, lo, hi = ident.get("K", []), ident.get("ci_low", []), ident.get("ci_high", [])
        K0 = ident.get("K_nominal", [])
        alone = ident.get("identified_joints", [])
        scale = ident["mode"] == "scale"  # one factor on every joint: none is separate

        def how(i: int) -> str:
            if scale:
                return "common scale" + (" (alone: yes)" if i + 1 in alone else "")
            return "yes" if i + 1 in alone else "no"

        rows = "".join(
            f"<tr><td>A{i + 1}</td><td>{fmt(K0[i] if i < len(K0) else None, 0)}</td>"
            f"<td>{fmt(K[i], 0)}</td><td>{fmt(lo[i], 0)} – {fmt(hi[i], 0)}</td>"
            f'<td class="t">{how(i)}</td></tr>'
            for i in range(len(K))
        )
        path = summary.get("identified_stiffness")
        out.append(
            "<table><caption>Joint stiffness identified from this forming run <span>— mode "
            f"<b>{esc(ident['mode'])}</b>; {esc(ident.get('observability', ''))}"
            + (f"; written to {esc(path)} next to this report" if path else "")
            + " (accepted by compensate, plan and robot deflect with --stiffness)</span>"
            "</caption><thead><tr><th>joint</th><th>nominal K (N·m/rad)</th>"
            "<th>identified K (N·m/rad)</th><th>95 % interval</th>"
            + (
                '<th class="t">identified as</th>'
                if scale
                else '<th class="t">separately identifiable</th>'
            )
            + f"</tr></thead><tbody>{rows}</tbody></table>"
        )
    terms = summary.get("terms_normal")
    if isinstance(terms, Mapping) and terms:
        out.append(terms_table(terms))
    return "".join(out)
