"""What the report states in words at the top: what kind of study it is (measured, virtual,
virtual with a tuned truth), which numbers hold by construction, what the analysis used (rim
band, share of the points, points beyond the analysis distance) and the diagnosis. HTML and
plain sentences only; no plotting here. The terminal (``roboisf analyze``) prints the same
sentences (:func:`verdict_lines`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from roboisf.report.page import esc, fmt, fmt_scaled

__all__ = [
    "DIAGNOSIS_NUMBERS",
    "DIAGNOSIS_VERDICTS",
    "StudyKind",
    "diagnosis_html",
    "diagnosis_number",
    "diagnosis_unit",
    "kind_banner",
    "scope_html",
    "scope_sentence",
    "study_kind",
    "suspect_name",
    "verdict_lines",
]

#: The verdicts a ``summary["diagnosis"]`` entry may carry, in the order the report lists them.
DIAGNOSIS_VERDICTS = ("fault", "cannot_tell", "ok")

_SUSPECTS = {
    "robot_stiffness": "robot joint stiffness",
    "force_gain": "force sensor gain",
    "force_moment_crosstalk": "force/moment crosstalk",
    "force_bias": "force sensor bias",
    "force_moment_bias": "force sensor moment bias",
    "force_crosstalk": "axial force crosstalk",
    "scan_shift": "scan shift",
    "work_object": "robot work object",
    "thermal_drift": "robot thermal drift",
    "work_object_tilt": "robot work object tilt",
    "scan_rotation": "scan rotation",
    "springback_coupling": "springback coupling",
}

_CHECK = {
    "consistent": "the robot model holds",
    "mismatch": "the robot model does not hold",
    "not_observable": "the robot model check is not observable",
}


def suspect_name(suspect: str) -> str:
    """A diagnosis suspect in words (``force_gain`` → "force sensor gain")."""
    return _SUSPECTS.get(suspect, suspect.replace("_", " "))


@dataclass(frozen=True)
class StudyKind:
    """``kind``: ``measured``, ``virtual`` or ``virtual_tuned``; ``label``: a few words for the
    headline; ``sentence``: what that means for the numbers below it."""

    kind: str
    label: str
    sentence: str


def study_kind(summary: Mapping[str, Any]) -> StudyKind:
    """What kind of study the summary describes.

    A study with no ``truth`` entry is measured. A virtual cell's ``truth`` (written by
    ``roboisf analyze`` from the study's ``truth/``) carries ``truth_source``: a truth from a
    shipped scenario (``"scenario paper (cone)"``) was tuned so the analysis lands on the paper's
    numbers, so its shares reproduce the paper by construction; ``model_equals_truth``: the
    robot model check holds by construction.
    """
    truth = summary.get("truth")
    if not isinstance(truth, Mapping):
        return StudyKind(
            "measured",
            "measured study",
            "Forces, joint angles and scans come from the forming cell; nothing "
            "below was set beforehand, every number is a finding.",
        )
    source = str(truth.get("truth_source") or "")
    if "scenario" in source:
        return StudyKind(
            "virtual_tuned",
            "virtual cell, truth tuned to the paper",
            f"Synthetic data whose hidden truth ({source}) was tuned so this "
            "analysis reproduces the paper's Table 5: the shares land on the paper's by "
            "construction — they reproduce it, they do not confirm it. The recovered terms "
            "are compared with that truth (dashed in the figures).",
        )
    model = (
        " The truth's robot is the study's model, so the robot model check holds by construction."
        if truth.get("model_equals_truth")
        else ""
    )
    return StudyKind(
        "virtual",
        "virtual cell",
        "Synthetic data with a hidden ground truth: the recovered terms are "
        f"compared with it (dashed in the figures).{model}",
    )


def kind_banner(summary: Mapping[str, Any]) -> str:
    """The banner at the top of the report: the study kind in bold and what it implies."""
    k = study_kind(summary)
    return (
        f'<div class="kind kind-{k.kind}" id="study-kind"><b>{esc(k.label.capitalize())}.</b> '
        f"{esc(k.sentence)}</div>"
    )


def _beyond(summary: Mapping[str, Any]) -> list[str]:
    beyond = summary.get("beyond_max_distance")
    out = []
    if isinstance(beyond, Mapping):
        for name, c in beyond.items():
            if isinstance(c, Mapping) and c.get("of"):
                n, of = int(c.get("n", 0)), int(c["of"])
                out.append(f"{name} {n} of {of} ({100.0 * n / of:.1f} %)")
    return out


def scope_sentence(summary: Mapping[str, Any], n_points: int, n_used: int | None) -> str:
    """One sentence: the rim band, the share of the toolpath points analysed and the scan points
    beyond the analysis distance (plain text, for the report and the terminal).

    ``n_used`` None: taken from ``summary["n_points_used"]``; neither: the share is not stated.
    """
    total = int(summary.get("n_points", n_points) or n_points)
    used = summary.get("n_points_used", n_used) if n_used is None else n_used
    parts = []
    if used is not None and total:
        parts.append(
            f"{int(used)} of {total} toolpath points analysed ({100.0 * int(used) / total:.0f} %)"
        )
    rim = summary.get("rim_band_mm")
    if rim is not None:
        parts.append(
            f"rim band: the top {float(rim):.1f} mm of depth left out (clamping and the bend "
            "from the blank, not the factors)"
            + (", and the scan holes" if used is not None and int(used) < total else "")
        )
    beyond = _beyond(summary)
    if beyond:
        dist = summary.get("max_distance_mm")
        parts.append(
            "scan points beyond the analysis distance"
            + (f" ({float(dist):g} mm)" if dist is not None else "")
            + " left out: "
            + ", ".join(beyond)
        )
    return "; ".join(parts) + "." if parts else ""


def scope_html(summary: Mapping[str, Any], n_points: int, n_used: int | None) -> str:
    """:func:`scope_sentence` as the report's "Analysed" line ('' when there is nothing to say)."""
    text = scope_sentence(summary, n_points, n_used)
    if not text:
        return ""
    return f'<p class="scope" id="analysis-scope"><b>Analysed:</b> {esc(text)}</p>'


def _diagnosis(summary: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    diag = summary.get("diagnosis")
    if isinstance(diag, Mapping):  # {"entries": [...], "headline": ...} as well as a list
        diag = diag.get("entries") or diag.get("suspects")
    if not isinstance(diag, list):
        return []
    return [e for e in diag if isinstance(e, Mapping) and "suspect" in e]


def _diagnosis_headline(summary: Mapping[str, Any]) -> str | None:
    head = summary.get("diagnosis_headline")
    diag = summary.get("diagnosis")
    if head is None and isinstance(diag, Mapping):
        head = diag.get("headline")
    if head is None:
        return None
    text = str(head).strip()
    # the analysis writes it as the terminal line ("diagnosis: …"); the prefix is said here
    return text[len("diagnosis:") :].strip() if text.lower().startswith("diagnosis:") else text


#: How each suspect's numbers read — in the report's estimate column and in the finding's own
#: text alike (``roboisf.decompose.diagnose`` formats its explanations with
#: :func:`diagnosis_number`), so the two print the same number: (unit, scale from
#: summary.json's unit, decimals). ``None``: the entry's own unit. A dimensionless ratio reads
#: "×" (a lone "1" after the interval read as a typo), a crosstalk newtons per kilonewton
#: (× 1000: a real sensor's 1e-5 … 1e-2 N/N read 0.01 … 10.00, not 1.574e-04 beside 0.000),
#: a fraction (springback coupling) bare.
DIAGNOSIS_NUMBERS: dict[str, tuple[str | None, float, int]] = {
    "robot_stiffness": ("×", 1.0, 3),
    "force_gain": ("×", 1.0, 3),
    "force_moment_crosstalk": (None, 1.0, 2),
    "force_moment_bias": (None, 1.0, 2),
    "force_bias": (None, 1.0, 1),
    "force_crosstalk": ("N/kN", 1e3, 2),
    "scan_shift": (None, 1.0, 3),
    "work_object": (None, 1.0, 3),
    "scan_rotation": (None, 1.0, 3),
    "thermal_drift": (None, 1.0, 3),
    "work_object_tilt": (None, 1.0, 3),
    "springback_coupling": ("", 1.0, 3),
}
_DEFAULT_NUMBER = (None, 1.0, 3)


def diagnosis_unit(suspect: str, unit: str | None) -> str:
    """The unit a suspect's numbers are printed in (``unit``: summary.json's)."""
    shown = DIAGNOSIS_NUMBERS.get(suspect, _DEFAULT_NUMBER)[0]
    return shown if shown is not None and unit in ("1", None) else str(unit or "")


def diagnosis_number(
    suspect: str, value: Any, *, signed: bool = False, scaled: bool = True, none: str = "—"
) -> str:
    """A diagnosis number of ``suspect`` (summary.json's unit) as the report and the text print
    it: :func:`~roboisf.report.page.fmt` at the suspect's decimals in its display unit
    (:data:`DIAGNOSIS_NUMBERS`) — a real small value keeps two significant digits, a
    floating-point zero reads 0.00 …, never "-0.00"; with its sign when ``signed``; ``scaled``
    False for a number already in another unit (a part's own). ``none`` for a missing one."""
    _, scale, decimals = DIAGNOSIS_NUMBERS.get(suspect, _DEFAULT_NUMBER)
    if value is None:
        return none
    text = fmt_scaled(value, scale if scaled else 1.0, decimals)
    if signed and text != "—" and not text.startswith("-"):
        text = "+" + text
    return text


def _estimate(e: Mapping[str, Any]) -> str:
    suspect = str(e.get("suspect"))
    unit = diagnosis_unit(suspect, e.get("unit"))
    est = diagnosis_number(suspect, e.get("estimate"))
    if e.get("ci_low") is None and e.get("ci_high") is None:
        return f"{est} {unit}".strip()
    lo, hi = diagnosis_number(suspect, e.get("ci_low")), diagnosis_number(suspect, e.get("ci_high"))
    return f"{est} [{lo}, {hi}] {unit}".strip()


def diagnosis_html(summary: Mapping[str, Any]) -> str:
    """The diagnosis (``summary["diagnosis"]``): its headline and one row per suspect, faults
    first ('' when the summary has none)."""
    entries = _diagnosis(summary)
    if not entries:
        return ""
    order = {v: i for i, v in enumerate(DIAGNOSIS_VERDICTS)}
    ranked = sorted(entries, key=lambda e: order.get(str(e.get("verdict")), len(order)))
    rows = "".join(
        f'<tr class="v-{esc(e.get("verdict"))}"><td class="t">'
        f"{esc(suspect_name(str(e['suspect'])))}</td>"
        f'<td class="t"><b>{esc(str(e.get("verdict", "")).replace("_", " "))}</b></td>'
        f"<td>{_estimate(e)}</td>"
        f'<td class="t wrap">{esc(e.get("explanation", ""))}</td></tr>'
        for e in ranked
    )
    head = _diagnosis_headline(summary)
    lead = f'<p class="verdict" id="diagnosis-headline">{esc(head)}</p>' if head else ""
    return (
        f'<div id="diagnosis">{lead}<table><caption>Diagnosis <span>— what could make the '
        "robot model and the measurement disagree, each estimated from this run with its 95 % "
        'interval</span></caption><thead><tr><th>suspect</th><th class="t">verdict</th>'
        '<th>estimate [95 %]</th><th class="t">why</th></tr></thead>'
        f"<tbody>{rows}</tbody></table></div>"
    )


def verdict_lines(summary: Mapping[str, Any]) -> list[str]:
    """The verdicts as plain lines for the terminal: the study kind, the model check and the
    diagnosis — its headline when the summary has one, else a line per fault and per suspect
    it cannot tell."""
    lines = ["study: " + study_kind(summary).label]
    vc = summary.get("vjm_check")
    if isinstance(vc, Mapping):
        verdict = str(vc.get("verdict", ""))
        if vc.get("by_construction"):
            text = "the robot model holds by construction (the cell's truth is the model)"
        else:
            text = _CHECK.get(verdict, verdict)
        if vc.get("ratio") is not None:
            text += (
                f": measured / VJM robot deflection {fmt(vc['ratio'], 2)} (95 % "
                f"[{fmt(vc.get('ci_low'), 2)}, {fmt(vc.get('ci_high'), 2)}])"
            )
        lines.append("model check: " + text)
    head = _diagnosis_headline(summary)
    if head:  # the analysis' own line says the faults (or that there are none) already
        lines.append("diagnosis: " + head)
        return lines
    for e in _diagnosis(summary):
        if e.get("verdict") in ("fault", "cannot_tell"):
            name = suspect_name(str(e["suspect"]))
            lines.append(
                f"diagnosis: {name} — {str(e['verdict']).replace('_', ' ')}, {_estimate(e)}"
            )
    return lines
