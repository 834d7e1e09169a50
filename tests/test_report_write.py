"""The study report: written from a fabricated study, self-contained, every figure there, bad input
refused before anything is written."""

from __future__ import annotations

import html
import importlib
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import roboisf
from report_fixtures import make_study
from roboisf.errors import InputError
from roboisf.report import (
    FIGURES,
    HTML_FIGURES,
    OPTIONAL_COLUMNS,
    REQUIRED_COLUMNS,
    read_headline,
    write_index,
    write_report,
)
from roboisf.report import static as st

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def study():
    return make_study(n_laps=40, points_per_lap=60)


@pytest.fixture(scope="module")
def written(study, tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    path = write_report(*study, out, png=True)
    return path, path.read_text(encoding="utf-8")


def test_report_and_every_png_written(written):
    path, _ = written
    assert path.name == "report.html" and path.stat().st_size > 1_000_000  # plotly.js inlined
    for fid in FIGURES:
        png = path.parent / "figures" / f"{fid}.png"
        data = png.read_bytes()
        assert data.startswith(PNG_MAGIC), fid
        width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
        assert width >= 800 and height >= 500, (fid, width, height)  # 200 dpi, paper-sized
    assert not [p for p in path.parent.rglob(".*")], "temporary files left behind"


def test_report_is_offline(written):
    _, text = written
    tags = re.findall(r"<(script|link|img|iframe)\b[^>]*>", text, flags=re.I)
    assert tags and all(t.lower() == "script" for t in tags)
    assert not re.search(r"<script[^>]*\bsrc\s*=", text, flags=re.I)
    assert not re.search(r"<link\b", text, flags=re.I)
    assert not re.search(r"@import|url\(\s*['\"]?https?:", text, flags=re.I)


def test_plotly_js_inlined_exactly_once_and_every_figure_present(written):
    _, text = written
    assert len(re.findall(r"\* plotly\.js v\d", text)) == 1
    assert text.count("Plotly.newPlot(") == len(HTML_FIGURES) + len(FIGURES)
    for fid in HTML_FIGURES + FIGURES:
        assert text.count(f'id="fig-{fid}"') == 1, fid
    # the JS bundle comes before the first figure's newPlot call
    assert text.index("* plotly.js v") < text.index("Plotly.newPlot(")


def test_headline_and_both_tables_labelled(study, written):
    path, text = written
    _, contrib, contrib_n, summary = study
    total = contrib.set_index("factor").loc["total", "R_m"]
    share = contrib.set_index("factor").loc["robot_compliance", "share_percent"]
    assert f"{total:.3f}<small>mm</small>" in text
    assert f"{share:.1f}<small>%</small>" in text
    assert "Per-axis vectors" in text and "Projected on the surface normal" in text
    h = read_headline(path)
    assert h["study"] == summary["study"]
    assert h["R_m_total_mm"] == pytest.approx(total)
    assert h["robot_share_percent"] == pytest.approx(share)
    assert h["R_m_total_normal_mm"] == pytest.approx(
        contrib_n.set_index("factor").loc["total", "R_m"]
    )
    assert summary["warnings"][0] in html.unescape(text)
    # the tables of the robot section
    for needle in ("Table 4", "k<sub>23</sub>", "rad/(N·m)", "Δ resultant"):
        assert needle in text, needle


def test_optional_columns_absent(tmp_path):
    per_point, contrib, contrib_n, summary = make_study(
        n_laps=20, points_per_lap=40, truth=False, measured_thickness=False
    )
    assert not any(c in per_point.columns for c in ("thickness_measured", "truth_tool_dn"))
    per_point = per_point.drop(columns=["cnc_n_points", "robot_n_points"])
    summary = {"study": "bare"}  # every other summary key is optional
    path = write_report(per_point, contrib, contrib_n, summary, tmp_path, png=False)
    text = path.read_text(encoding="utf-8")
    assert "no measured thickness was given" in text
    assert "ground truth" not in text
    assert "No warnings" in text
    assert text.count("Plotly.newPlot(") == len(HTML_FIGURES) + len(FIGURES)
    assert not (tmp_path / "figures").exists()


@pytest.mark.parametrize(
    "column", ["depth", "robot_Fz", "vjm_dy", "cnc_valid", "thickness_predicted"]
)
def test_missing_required_column_names_it(study, tmp_path, column):
    per_point, contrib, contrib_n, summary = study
    with pytest.raises(InputError, match=column) as err:
        write_report(per_point.drop(columns=[column]), contrib, contrib_n, summary, tmp_path)
    assert err.value.field == column
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_non_finite_geometry_and_bad_types_refused(study, tmp_path):
    per_point, contrib, contrib_n, summary = study
    bad = per_point.copy()
    bad.loc[7, "contact_z"] = np.nan
    with pytest.raises(InputError, match="row 7") as err:
        write_report(bad, contrib, contrib_n, summary, tmp_path)
    assert err.value.field == "contact_z"
    bad = per_point.assign(lap=per_point["lap"].astype(str))
    with pytest.raises(InputError, match="numeric") as err:
        write_report(bad, contrib, contrib_n, summary, tmp_path)
    assert err.value.field == "lap"
    with pytest.raises(InputError, match="empty"):
        write_report(per_point.iloc[:0], contrib, contrib_n, summary, tmp_path)
    with pytest.raises(InputError, match="DataFrame"):
        write_report(per_point.to_dict(), contrib, contrib_n, summary, tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_bad_contribution_table_and_summary(study, tmp_path):
    per_point, contrib, contrib_n, summary = study
    with pytest.raises(InputError, match=r"contributions_normal: missing row.*springback"):
        write_report(
            per_point, contrib, contrib_n[contrib_n.factor != "springback"], summary, tmp_path
        )
    with pytest.raises(InputError, match="R_m") as err:
        write_report(per_point, contrib.drop(columns=["R_m"]), contrib_n, summary, tmp_path)
    assert err.value.field == "R_m"
    with pytest.raises(InputError) as err:
        write_report(per_point, contrib, contrib_n, {"part": {}}, tmp_path)
    assert err.value.field == "study"
    with pytest.raises(InputError) as err:
        write_report(per_point, contrib, contrib_n, {**summary, "contour_z": "low"}, tmp_path)
    assert err.value.field == "contour_z"
    with pytest.raises(InputError) as err:
        write_report(per_point, contrib, contrib_n, {**summary, "warnings": "one"}, tmp_path)
    assert err.value.field == "warnings"
    assert list(tmp_path.iterdir()) == []


def test_user_text_is_escaped(study, tmp_path):
    per_point, contrib, contrib_n, summary = study
    evil = {**summary, "study": "<b>x</b>", "warnings": ["<script>alert(1)</script>"]}
    text = write_report(per_point, contrib, contrib_n, evil, tmp_path, png=False).read_text("utf-8")
    assert "<script>alert(1)</script>" not in text and "&lt;script&gt;alert(1)" in text
    assert "<b>x</b>" not in text


def test_failure_half_way_leaves_the_old_report(study, tmp_path, monkeypatch):
    per_point, contrib, contrib_n, summary = study
    (tmp_path / "report.html").write_text("old", encoding="utf-8")

    def boom(fig, path):
        raise RuntimeError("disk full")

    monkeypatch.setattr(st, "save_png", boom)
    with pytest.raises(RuntimeError):
        write_report(per_point, contrib, contrib_n, summary, tmp_path, png=True)
    assert (tmp_path / "report.html").read_text(encoding="utf-8") == "old"


def test_progress_reported(study, tmp_path):
    import contextlib

    seen: dict[str, float] = {}

    class Recorder:
        @contextlib.contextmanager
        def task(self, description, total=None):
            seen["total"] = total

            def advance(amount=1.0):
                seen["done"] = seen.get("done", 0.0) + amount

            yield advance

    write_report(*study, tmp_path, png=False, progress=Recorder())
    assert seen["done"] == seen["total"] == len(FIGURES) + 1


def test_index_links_reports_relatively(study, tmp_path):
    per_point, contrib, contrib_n, summary = study
    a = write_report(
        per_point, contrib, contrib_n, {**summary, "study": "cone-71"}, tmp_path / "cone", png=False
    )
    b = write_report(
        per_point, contrib, contrib_n, {**summary, "study": "vwacf"}, tmp_path / "vwacf", png=False
    )
    index = write_index([a, tmp_path / "vwacf"], tmp_path / "index.html")
    text = index.read_text(encoding="utf-8")
    assert 'href="cone/report.html"' in text and 'href="vwacf/report.html"' in text
    assert "cone-71" in text and "vwacf" in text
    total = contrib.set_index("factor").loc["total", "R_m"]
    assert text.count(f"{total:.3f}") == 2
    assert "<script" not in text
    robot = contrib.set_index("factor").loc["robot_compliance", "share_percent"]
    assert text.count('class="sharebar"') == 2
    assert text.count(f'title="Robot compliance {robot:.1f} %" style="width:{robot:.2f}%') == 2
    assert b.exists()
    with pytest.raises(InputError, match="cannot read"):
        write_index([tmp_path / "nowhere" / "report.html"], tmp_path / "i2.html")
    with pytest.raises(InputError, match="at least one"):
        write_index([], tmp_path / "i3.html")
    assert not (tmp_path / "i2.html").exists()


def test_contract_lists_are_consistent():
    assert len(set(REQUIRED_COLUMNS)) == len(REQUIRED_COLUMNS)
    assert not set(REQUIRED_COLUMNS) & set(OPTIONAL_COLUMNS)
    per_point = make_study(n_laps=3, points_per_lap=10)[0]
    assert set(REQUIRED_COLUMNS) | set(OPTIONAL_COLUMNS) == set(per_point.columns)


def test_core_never_imports_plotting():
    """Only roboisf.report (and the CLI that calls it) may pull plotly or matplotlib in."""
    names = [
        m.name
        for m in pkgutil.walk_packages(roboisf.__path__, "roboisf.")
        if not m.name.startswith(("roboisf.report", "roboisf.cli"))
    ]
    code = (
        "import importlib, sys\n"
        f"for n in {names!r}: importlib.import_module(n)\n"
        "bad = [m for m in sys.modules if m.split('.')[0] in ('plotly', 'matplotlib')]\n"
        "assert not bad, bad[:5]\n"
    )
    src = str(Path(roboisf.__file__).parents[1])
    result = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env={"PYTHONPATH": src},
        timeout=120,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert importlib.import_module("roboisf.report")


def test_fixture_is_a_cone_of_the_paper(study):
    """The fabricated study is what its docstring says (guards the fixture the tests trust)."""
    per_point = make_study()[0]
    assert per_point["lap"].nunique() == 200 and len(per_point) == 30_000
    r = np.hypot(per_point["contact_x"], per_point["contact_y"])
    slope = np.polyfit(per_point["depth"], r, 1)[0]
    assert np.degrees(np.arctan(-1 / slope)) == pytest.approx(71.0, abs=1e-9)
    n = per_point[["normal_x", "normal_y", "normal_z"]].to_numpy()
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    assert per_point["thickness_predicted"].iloc[0] == pytest.approx(1.22 * np.cos(np.radians(71)))
    assert isinstance(per_point, pd.DataFrame)


def test_light_report_modules_do_not_import_the_plotting_libraries():
    """``roboisf analyze`` imports the history rows (:mod:`roboisf.report.iterations`) before
    the analysis; the package's names load on first use, so matplotlib and plotly are not
    imported then (0.4–0.5 s on the critical path: the pipeline loads them beside the scans).
    The public names still resolve, and a submodule still imports by ``from … import``."""
    import os
    import pathlib
    import subprocess
    import sys

    import roboisf

    src = str(pathlib.Path(roboisf.__file__).resolve().parents[1])
    code = (
        "import sys\n"
        "import roboisf.report.iterations, roboisf.report.page, roboisf.report.schema\n"
        "import roboisf.report.style\n"
        "heavy = [m for m in ('matplotlib', 'plotly', 'roboisf.report.document') "
        "if m in sys.modules]\n"
        "assert not heavy, heavy\n"
        "import roboisf.report as r\n"
        "from roboisf.report import render\n"
        "assert callable(r.write_report) and r.FIGURES and r.REQUIRED_COLUMNS\n"
        # matplotlib only for PNGs asked for (write_report's png=True)
        "assert 'matplotlib' not in sys.modules and 'write_report' in dir(r)\n"
        "try:\n"
        "    r.no_such_name\n"
        "except AttributeError as e:\n"
        "    assert 'no_such_name' in str(e)\n"
        "else:\n"
        "    raise AssertionError('no AttributeError')\n"
    )
    env = {**os.environ, "PYTHONPATH": src}
    res = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 0, res.stderr
