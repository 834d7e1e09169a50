"""The diagnosis's text says the numbers summary.json holds.

Each finding's explanation and headline are what the terminal and the report print; its
``estimate``, ``ci_low``, ``ci_high`` (and the named ``parts`` behind it) are what a program
reads. They once disagreed: ``force_moment_crosstalk`` read 4.26 mm in the JSON (the false
moment that follows the force) and 15.93 mm in the text (the whole false moment), a scan shift
printed the one-scale fit's interval where the JSON held the union of both fits', a scan
rotation printed a signed interval beside the JSON's interval of its size. Every interval the
text prints must be one the JSON holds, at the printed precision.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
import pytest

from roboisf.decompose.diagnose import (
    RobotTermFit,
    UnloadedEvidence,
    fit_sensor,
    robot_findings,
    sensor_findings,
)
from roboisf.report.statements import DIAGNOSIS_NUMBERS, _estimate

R = 5e-3
#: a bracketed interval as the explanations print it: "[0.985, 1.032]", "[-0.197, +0.002]"
INTERVAL = re.compile(r"\[\s*([+-]?\d+(?:\.\d+)?)\s*,\s*([+-]?\d+(?:\.\d+)?)\s*\]")


def _decimals(s: str) -> int:
    return len(s.split(".")[1]) if "." in s else 0


def _same(printed: str, value: float | None, scale: float = 1.0) -> bool:
    """``printed`` is ``value × scale`` (its display unit) rounded to the printed decimals."""
    if value is None:
        return False
    value = value * scale
    d = _decimals(printed)
    return abs(float(printed) - value) <= 0.5 * 10.0**-d + 1e-12 * max(1.0, abs(value))


def _json_intervals(e: Mapping[str, Any]) -> list[tuple[str, float | None, float | None, float]]:
    """The entry's intervals with the scale to their display unit (a crosstalk in N/kN; a part
    in its own unit as it is)."""
    scale = DIAGNOSIS_NUMBERS[e["suspect"]][1]
    out = [("ci", e.get("ci_low"), e.get("ci_high"), scale)]
    for p in e.get("parts") or []:
        own = 1.0 if p.get("unit") is not None else scale
        out.append((str(p["name"]), p.get("ci_low"), p.get("ci_high"), own))
    return out


def mismatched_intervals(entries: Iterable[Mapping[str, Any]]) -> list[str]:
    """Every interval printed in an entry's explanation or headline that is none of the JSON's
    intervals of that entry (its own or one of its parts'), at the printed precision."""
    bad = []
    for e in entries:
        known = _json_intervals(e)
        for where in ("explanation", "headline"):
            for m in INTERVAL.finditer(str(e.get(where, ""))):
                lo, hi = m.group(1), m.group(2)
                if not any(_same(lo, a, k) and _same(hi, b, k) for _, a, b, k in known):
                    bad.append(f"{e['suspect']} {where}: [{lo}, {hi}] not in {known}")
    return bad


def _rf(ratio=1.212, ratio_ci=(1.199, 1.233), rotation=True):
    """A robot-term fit whose two shift fits disagree and whose rotation is seen."""
    s1, sj = np.array([1e-4, 0.2e-4]), np.array([0.3e-4, -0.1e-4])
    rot = (math.radians(-0.195), (math.radians(-0.1972), math.radians(-0.1921)))
    rotj = (math.radians(-0.196), (math.radians(-0.1991), math.radians(-0.1932)))
    return RobotTermFit(
        ratio,
        ratio_ci,
        s1,
        (0.084e-3, 0.121e-3),
        sj,
        (0.0, 0.074e-3),
        rot[0] if rotation else None,
        rot[1] if rotation else None,
        rotj[0] if rotation else None,
        rotj[1] if rotation else None,
        0.3e-3,
        0.1e-3,
        0.05e-3,
        [1, 2, 3],
    )


def _path(n_laps: int = 16, per_lap: int = 120, seed: int = 0):
    from test_diagnosis import _path as path

    return path(n_laps, per_lap, seed)


def _sensor_cases():
    """Synthetic sensor fits through each branch of the sensor's texts."""
    from test_diagnosis import _at_rest, _axial_crosstalk, _noisy

    p = _path()
    valid = np.ones(len(p["lap"]), bool)
    W = p["W"]
    b = np.array([10.0, -5.0, 30.0])
    Wb = W.copy()
    Wb[:, :3] += b
    Wx = W.copy()
    Wx[:, 3:] += 10e-3 * W[:, :3].sum(axis=1, keepdims=True)
    Wbx = Wx.copy()
    Wbx[:, :3] += b
    cases = {
        "clean": (W, None),
        "gain": (0.9 * W, None),
        "bias": (Wb, None),
        "moment crosstalk": (Wx, None),
        "bias and moment crosstalk": (Wbx, None),
        "axial crosstalk": (_axial_crosstalk(W), None),
        "axial crosstalk, at rest": (_axial_crosstalk(W), _at_rest((0.0, 0.0, 0.0))),
        "bias at rest": (Wb, _at_rest(b)),
    }
    for name, (Wr, rest) in cases.items():
        ev = UnloadedEvidence.from_stretches(**rest) if rest else None
        sf = fit_sensor(W, _noisy(Wr), p["arm"], valid, p["lap"], p["depth"], unloaded=ev)
        yield name, sensor_findings(sf, R, ev)
    yield "no fit, at rest", sensor_findings(None, R, UnloadedEvidence.from_stretches(
        _at_rest((0.0, 20.0, 0.0))["robot"], []))  # fmt: skip


def _robot_cases():
    """Robot-term fits through the offset's, the drift's and the tilt's branches (a drift, a
    constant offset, none, a tilt with the scan's tilts registered or not, a run whose analysed
    laps take a short part of it with and without an offset), and synthetic ones whose shift
    fits disagree and whose rotation is seen."""
    from test_diagnosis_drift import _cone, _fit

    c = _cone()
    x, n, p = c["Aj"].sum(axis=1), c["normal"], c["contact"]
    tilt = math.radians(0.3) * np.einsum("ij,ij->i", n, np.cross([0.0, 1.0, 0.0], p))
    yield "drift", _fit(c, 1.2 * x + (n[:, :2] @ [0.3e-3, -0.1e-3]) * c["tau"] + c["noise"])
    yield "offset", _fit(c, x + n[:, :2] @ [0.0, 0.3e-3] + c["noise"])
    yield "clean", _fit(c, x + c["noise"])
    for registered in (True, False):
        yield f"tilt {registered}", _fit(c, x + tilt + c["noise"], tilt_registered=registered)
    short = dict(c, tau=0.96 + 0.04 * c["tau"])
    yield "short run", _fit(short, x + c["noise"])
    drift = (n[:, :2] @ [0.25e-3, 0.0]) * short["tau"]
    yield "short run, drift", _fit(short, x + drift + c["noise"])
    for i, rf in enumerate((_rf(), _rf(0.712, (0.670, 0.745)), _rf(rotation=False))):
        yield f"synthetic {i}", rf


def test_every_interval_in_the_text_is_the_jsons_on_each_branch():
    """Synthetic fits through every text's branch (sensor faults alone and together, the logs
    at rest or not; the robot term's offset, rotation, drift and tilt)."""
    bad = []
    for name, findings in _sensor_cases():
        bad += [f"{name}: {b}" for b in mismatched_intervals(f.to_dict() for f in findings)]
    for name, rf in _robot_cases():
        entries = [f.to_dict() for f in robot_findings(rf, axisymmetric=rf.rotation is None)]
        bad += [f"{name}: {b}" for b in mismatched_intervals(entries)]
    assert not bad, "\n".join(bad)


def test_the_texts_estimate_is_the_jsons():
    """The first number of each finding's first clause that is followed by the finding's unit
    is its JSON estimate (the headline says what the JSON holds)."""
    found = 0
    for _name, findings in _sensor_cases():
        for f in findings:
            e = f.to_dict()
            if e["suspect"] != "force_moment_crosstalk" or e["estimate"] is None:
                continue
            m = re.search(r"(\d+\.\d+) mm", e["headline"] if e["verdict"] != "ok" else
                          e["explanation"])  # fmt: skip
            assert m, e["explanation"]
            assert _same(m.group(1), e["estimate"]), (m.group(1), e["estimate"], e["explanation"])
            found += 1
    assert found >= 5


@pytest.mark.slow
def test_a_faulted_studys_text_and_json_agree(tmp_path):
    """A pyramid (its rotation is seen) with a misregistered scan and a flange sensor reading
    low with a bias and crosstalk into its moment channels: every interval the explanations,
    headlines and the terminal's lines print is the JSON's, and the moment crosstalk's text
    says its JSON estimate first."""
    from roboisf.decompose.pipeline import analyze, write_results
    from roboisf.report.statements import verdict_lines
    from roboisf.virtual.cell import build_study, pyramid_cell
    from roboisf.virtual.truth import truth_from_table

    table = {
        "force_sensor": {"gain": 0.92, "bias": [20.0, -10.0, 5.0, 0, 0, 0],
                         "crosstalk_moment": 8.0},
        "scan": {"shift": [0.15, 0.0, 0.0], "rotation": [0.0, 0.0, -0.2]},
    }  # fmt: skip
    cell = pyramid_cell(
        truth=truth_from_table(table),
        step_down=2e-3,
        spacing=3e-3,
        scan_points=60_000,
        force_rate=100.0,
        joint_rate=50.0,
    )
    build_study(cell, tmp_path / "study")
    r = analyze(tmp_path / "study")
    write_results(r, tmp_path / "results", png=False)
    from summary_check import validated

    s = validated(tmp_path / "results" / "summary.json")
    entries = s["diagnosis"]
    assert {e["verdict"] for e in entries} >= {"fault"}
    bad = mismatched_intervals(entries)
    # the terminal: its warnings and verdict lines carry the findings' headlines as they are
    # (checked above with their findings), and no interval of their own beside them
    heads = sorted({e["headline"] for e in entries}, key=len, reverse=True)
    lines = [ln for ln in [*s["warnings"], *verdict_lines(s)] if any(h in ln for h in heads)]
    assert any(ln.startswith("diagnosis:") for ln in lines)
    for line in lines:
        rest = line
        for h in heads:
            rest = rest.replace(h, "")
        bad += [f"terminal line {line!r}: {m.group(0)}" for m in INTERVAL.finditer(rest)]
    assert not bad, "\n".join(bad)
    ct = {e["suspect"]: e for e in entries}["force_moment_crosstalk"]
    m = re.search(r"(\d+\.\d+) mm", ct["explanation"])
    assert m and _same(m.group(1), ct["estimate"]), (ct["estimate"], ct["explanation"])


def _table_vs_text(entries: Iterable[Mapping[str, Any]]) -> tuple[list[str], int]:
    """Entries whose report estimate column ([lo, hi] and unit) is not printed verbatim in the
    explanation that quotes the finding's interval; and how many were compared."""
    bad, seen = [], 0
    for e in entries:
        if e.get("ci_low") is None:
            continue
        cell = _estimate(e)
        m = re.search(r"\[[^]]*\]", cell)
        assert m, cell
        # the text quotes the finding's own interval, in the display unit, at its precision
        own = [
            t.group(0)
            for t in INTERVAL.finditer(str(e.get("explanation", "")))
            if _same(t.group(1), e["ci_low"], DIAGNOSIS_NUMBERS[e["suspect"]][1])
            and _same(t.group(2), e["ci_high"], DIAGNOSIS_NUMBERS[e["suspect"]][1])
        ]
        if not own:
            continue
        seen += 1
        unit = {"deg": "°"}.get(cell[m.end() :].strip(), cell[m.end() :].strip())
        if m.group(0) not in own or (unit not in ("", "×") and unit not in e["explanation"]):
            bad.append(f"{e['suspect']}: table {cell!r}, text {e['explanation']!r}")
    return bad, seen


def test_the_report_table_and_the_text_print_the_same_numbers():
    """The report's estimate column and the finding's text print one suspect's interval in one
    unit at one precision: "36.000 N/kN" stood beside "0.0360 N per N", a bias's 12.345 N beside
    12.3 N."""
    bad, seen = [], 0
    for name, findings in _sensor_cases():
        b, n = _table_vs_text(f.to_dict() for f in findings)
        bad += [f"{name}: {x}" for x in b]
        seen += n
    for name, rf in _robot_cases():
        entries = [f.to_dict() for f in robot_findings(rf, axisymmetric=rf.rotation is None)]
        b, n = _table_vs_text(entries)
        bad += [f"{name}: {x}" for x in b]
        seen += n
    assert seen >= 20 and not bad, "\n".join(bad)


def test_a_small_crosstalk_is_not_printed_as_zero():
    """A clean sensor's crosstalk of a few 1e-6 N/N read "0.0000 N per N" and "largest force
    crosstalk 0.000": a real small value keeps two significant digits."""
    texts = []
    for name, findings in _sensor_cases():
        if name != "clean":
            continue
        for f in findings:
            if f.suspect in ("force_gain", "force_crosstalk"):
                texts.append(f.explanation)
    assert texts
    for t in texts:
        assert not re.search(r"(?<![\d.])0\.0+ N(/kN| per N)", t), t
        assert not re.search(r"largest force crosstalk 0\.0+(?!\d)", t), t


def test_vectors_in_the_texts_keep_small_components_and_no_negative_zero():
    # a moment bias at rest of a few mN·m read "(+0.00, +0.00, +0.00) N·m": a real value shown
    # as none, beside an estimate column that keeps two significant digits
    from roboisf.decompose.diagnose import _mvec, _vec

    assert _mvec(np.array([0.0023, -0.001, 0.0])) == "(+0.0023, -0.0010, +0.00) N·m"
    assert _mvec(np.array([3.6, -1e-20, 0.5])) == "(+3.60, +0.00, +0.50) N·m"
    assert _vec(np.array([-0.0, 0.0, -3.0])) == "(+0.0, +0.0, -3.0) N"
    assert "-0.0" not in _vec(np.array([-1e-18, -0.0, 12.34]))
