"""The compensation report (issue #30): the study report's look, what was compensated in words,
which stiffness (file name only), why the before/after curves start where they start, and a
legend that covers no title."""

from __future__ import annotations

import html
import re

import numpy as np
import pandas as pd
import pytest

from roboisf.report.compensation import compensation_figure, write_compensation_report


def _laps(first: int = 22, n: int = 35) -> pd.DataFrame:
    lap = np.arange(n)
    before = np.where(lap >= first, 2.2, np.nan)
    return pd.DataFrame(
        {
            "lap": lap,
            "command_dn": -np.linspace(0, 2, n),
            "command_norm": np.linspace(0, 2.2, n),
            "abs_dn_before": before,
            "abs_dn_after": before / 10,
        }
    )


def _summary(**extra):
    return {
        "complete": True,
        "terms": {"compliance": True, "springback": True},
        "n_points": 5404,
        "max_command_offset_mm": 2.637,
        "mean_command_offset_mm": 1.434,
        "rim_blend_mm": 5.0,
        "max_lap_step_springback_offset_mm": 0.24,
        "max_lap_step_command_dn_mm": 0.25,
        "springback": {"gain": 0.8},
        "gouge": {"ok": True, "rule": "ball centre ≥ R − over-bend"},
        "study": "pyramid",
        "robot": "irb7600-500-2.55",
        "rim_band_mm": 20.0,
        "stiffness": "/somewhere/results/identified_stiffness.toml",
        "mean_abs_dn_before_mm": 2.211,
        "mean_abs_dn_after_predicted_mm": 0.220,
        "after": "predicted",
        **extra,
    }


def _write(tmp_path, laps=None, **extra) -> str:
    path = write_compensation_report(
        _laps() if laps is None else laps, _summary(**extra), tmp_path, png=False
    )
    return path.read_text(encoding="utf-8")


def test_styled_like_the_study_report_with_cards(tmp_path):
    text = _write(tmp_path)
    assert 'class="cards"' in text and '<header class="top">' in text
    assert "roboisf compensation — pyramid" in text
    cards = re.findall(r'<div class="label">(.*?)</div><div class="value">(.*?)</div>', text)
    labels = [c[0] for c in cards]
    assert labels[:2] == ["Mean |dn| before", "Mean |dn| after (predicted)"]
    assert "2.211" in cards[0][1] and "0.220" in cards[1][1]
    assert "Gouge check" in labels


def test_terms_in_words_not_json(tmp_path):
    text = _write(tmp_path)
    assert '{"compliance"' not in text and "{&quot;" not in text
    assert "pre-deflection" in text and "springback" in text and "gain λ = 0.8" in text
    only = _write(tmp_path / "o", terms={"compliance": False, "springback": True})
    assert "pre-deflection)" not in only.split("Compensated:")[1].split("</p>")[0]


@pytest.mark.parametrize(
    ("stiffness", "words"),
    [
        ("/somewhere/results/identified_stiffness.toml", "identified from the forming run"),
        ("study.toml", "the study's own robot model"),
        ("/x/y/my_k.toml", "my_k.toml (given with --stiffness)"),
    ],
)
def test_says_which_stiffness_by_file_name_only(tmp_path, stiffness, words):
    text = _write(tmp_path, stiffness=stiffness)
    line = text.split("Joint stiffness of the pre-deflection:</b>")[1].split("</p>")[0]
    assert words in html.unescape(line) and "/" not in line


def test_says_why_the_curves_start_late(tmp_path):
    text = _write(tmp_path)
    assert "The before/after curves start at lap 22: the first lap below the rim band" in text
    assert "the top 20 mm of depth" in text
    early = _write(tmp_path / "e", laps=_laps(first=0))
    assert "curves start at lap" not in early  # nothing to explain


def test_legend_under_the_panels():
    fig = compensation_figure(_laps(), _summary())
    assert fig.layout.legend.y < 0 and fig.layout.legend.yanchor == "top"
    # room above the panels' titles for plotly's tool bar (at 40 px it sat on the right title):
    # as much as the study report's subplot figures leave above theirs
    assert fig.layout.margin.t >= 72


def test_virtual_cell_iterations_named_and_listed(tmp_path):
    extra = {
        "study": None,
        "robot": None,
        "stiffness": None,
        "rim_band_mm": None,
        "cell": "pyramid",
        "mean_abs_dn_per_iteration_mm": [1.29, 0.164, 0.037],
        "after": "virtual cell",
        "mean_abs_dn_after_virtual_cell_mm": 0.037,
    }
    text = html.unescape(_write(tmp_path, **extra))
    assert "roboisf compensation — pyramid" in text and "virtual cell" in text
    assert "1.290 → 0.164 → 0.037 mm" in text
    assert "after: formed again on the virtual cell" in text
    assert "Mean |dn| after (virtual cell)" in text
    assert "the cell's robot model" in text  # no stiffness file: the cell's own


GOUGE = {  # compensation.json's gouge report of the paper cone (mm)
    "ok": True,
    "rule": "distance of the loaded ball centre from the nominal >= R - intended over-bend - tol; "
    "intended over-bend <= max_overbend",
    "tool_radius_mm": 5.0,
    "tol_mm": 0.01,
    "max_overbend_mm": 2.0,
    "min_margin_mm": 0.009999858188756289,
    "max_intended_overbend_mm": 1.0088007028193466,
    "gouge_indices": [],
}


def _gouge_card(text: str) -> tuple[str, str]:
    m = re.search(
        r'<div class="label">Gouge check</div><div class="value">(.*?)</div>'
        r'<div class="note">(.*?)</div>',
        text,
    )
    assert m, "no gouge card"
    return m.group(1), html.unescape(m.group(2))


def test_gouge_card_gives_its_margin_and_how_close_is_too_close(tmp_path):
    """The card said "ok" and the rule: not the 0.010 mm margin nor where a gouge begins."""
    value, note = _gouge_card(_write(tmp_path, gouge=GOUGE))
    assert value.startswith("ok") and "margin 0.010 mm" in value
    # margin = tol: the loaded ball is exactly where intended; a gouge is > tol deeper
    assert "at the intended depth" in note and "more than 0.010 mm deeper than intended" in note
    assert "over-bend up to 1.009 mm of the 2.000 mm allowed" in note
    shallow = {**GOUGE, "min_margin_mm": 0.35}
    value, note = _gouge_card(_write(tmp_path / "s", gouge=shallow))
    assert "margin 0.350 mm" in value and "0.340 mm shallower than intended" in note
    bad = {**GOUGE, "ok": False, "min_margin_mm": -0.042, "gouge_indices": [3, 4, 9]}
    text = _write(tmp_path / "b", gouge=bad)
    value, note = _gouge_card(text)
    assert value.startswith("GOUGE") and "margin -0.042 mm" in value
    assert "0.052 mm deeper than intended" in note and "3 points gouge" in note
    assert 'class="card warn"' in text
    # the rule in words stays, in the details
    assert "gouge rule" in text and "max_overbend" in text.split('id="details"')[1]
    # an older compensation.json without the margin: the verdict and the rule, as before
    value, note = _gouge_card(_write(tmp_path / "o", gouge={"ok": True, "rule": "the rule"}))
    assert value == "ok" and note == "the rule"


def test_compensate_without_png_never_loads_matplotlib():
    # compensation.png is written only with --png: the compensation's modules load no
    # matplotlib (~0.5 s of every compensate before), a fresh interpreter shows it
    import os
    import subprocess
    import sys
    from pathlib import Path

    src = str(Path(__file__).resolve().parents[1] / "src")
    code = (
        "import sys\n"
        "import roboisf.compensate.pipeline, roboisf.report.compensation\n"
        "assert 'matplotlib' not in sys.modules, sorted(m for m in sys.modules if 'matplot' in m)\n"
        "from roboisf.report.compensation import compensation_png\n"
        "import pandas as pd\n"
        "laps = pd.DataFrame({'lap': [1, 2], 'command_dn': [0.1, 0.2],\n"
        "                     'command_norm': [0.1, 0.2]})\n"
        "compensation_png(laps, {})\n"
        "assert 'matplotlib' in sys.modules\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code],
        env={**os.environ, "PYTHONPATH": src},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr[-2000:]
