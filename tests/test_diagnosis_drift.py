"""The wrong part blamed: a robot that forms the part displaced is not a misplaced scan.

A work object taught 0.3 mm off and a thermal drift of 0.3 mm over the run make the robot *form*
the part displaced — an error of the part, which compensation must correct. A scan shifted
0.3 mm only *misplaces the measurement* — which compensation must not correct. All three were
called "scan shift: FAULT — re-register the robot scan", and ``compensate`` took the offset out
of what it corrects, so the next part stayed 0.3 mm off.

Now: an offset that grows with the points' forming time is a thermal drift (a scan is one rigid
snapshot); a constant offset is the robot scan's registration or the robot's work object, which
the study's files cannot tell apart (``cannot_tell`` for both), and ``compensate`` asks which
(``--offset scan|part``) instead of guessing. docs/diagnosis.md, docs/compensate.md.
"""

from __future__ import annotations

import json
import math
import re
import shutil

import numpy as np
import pandas as pd
import pytest

from roboisf.decompose.diagnose import (
    DETECTION_LIMITS,
    SUSPECTS,
    Diagnosis,
    fit_robot_term,
    forming_time,
    offset_seen,
    robot_findings,
)
from roboisf.errors import InputError

# --------------------------------------------------------------------------------------------
# the robot term's fit on a synthetic cone path


def _cone(n_laps: int = 16, per_lap: int = 120, seed: int = 0):
    """A 60° cone's path (step-down 2 mm), each joint's nominal share of the VJM's deflection
    (smooth, distinct patterns), forming time in order along the path."""
    rng = np.random.default_rng(seed)
    lap = np.repeat(np.arange(n_laps), per_lap)
    phi = np.tile(np.linspace(0, 2 * np.pi, per_lap, endpoint=False), n_laps)
    depth = 20e-3 + 2e-3 * lap + 2e-3 * phi / (2 * np.pi)
    a = math.radians(60)
    normal = np.column_stack(
        [-np.sin(a) * np.cos(phi), -np.sin(a) * np.sin(phi), np.full_like(phi, np.cos(a))]
    )
    rho = 0.09 - depth / math.tan(a)  # the wall narrows with depth: laps get shorter
    contact = np.column_stack([rho * np.cos(phi), rho * np.sin(phi), -depth])
    Aj = 1e-4 * np.column_stack(
        [
            1.0 + 0.3 * np.cos(phi),
            1.5 + 0.4 * np.sin(phi) + 5 * depth,
            1.2 - 0.3 * np.cos(2 * phi) + 8 * depth,
            0.2 + 0.1 * np.sin(2 * phi),
            0.3 + 0.1 * np.cos(3 * phi),
            np.zeros_like(phi),
        ]
    )
    # forming time: each lap takes as long as it is long (a constant feed)
    seg = np.r_[0.0, np.linalg.norm(np.diff(contact, axis=0), axis=1)]
    tau = forming_time(np.cumsum(seg), len(seg))
    noise = rng.normal(0, 5e-6, len(lap))
    return dict(lap=lap, normal=normal, contact=contact, Aj=Aj, tau=tau, noise=noise)


def _fit(c, y, **kw):
    x = c["Aj"].sum(axis=1)
    valid = np.ones(len(y), bool)
    return fit_robot_term(
        y, x, c["Aj"], c["normal"], c["contact"], valid, c["lap"], tau=c["tau"], **kw
    )


def _verdicts(rf):
    return {f.suspect: f for f in robot_findings(rf, axisymmetric=True)}


def test_an_offset_growing_with_forming_time_is_a_drift_not_the_scans():
    c = _cone()
    x = c["Aj"].sum(axis=1)
    d = np.array([0.3e-3, -0.1e-3])
    y = 1.2 * x + (c["normal"][:, :2] @ d) * c["tau"] + c["noise"]
    f = _verdicts(_fit(c, y))
    assert f["thermal_drift"].verdict == "fault", f["thermal_drift"].explanation
    assert f["thermal_drift"].ci_low <= 1e3 * np.linalg.norm(d) <= f["thermal_drift"].ci_high
    assert f["scan_shift"].verdict == f["work_object"].verdict == "ok"
    # on this path a tilt grows with depth nearly as the drift with time: beside a tilt the
    # drift is still there, the tilt itself is not ruled out
    assert f["work_object_tilt"].verdict != "fault"
    assert f["robot_stiffness"].ci_low <= 1.2 <= f["robot_stiffness"].ci_high
    assert "drift changes from run to run" in f["thermal_drift"].headline


def test_a_pattern_within_a_wrong_robot_models_misfit_is_not_blamed_on_a_drift():
    # the demo's paper cone (joints 0.22x, bending links, no drift nor offset in its truth) read
    # "thermal drift: FAULT 0.88 mm" and an unattributed 0.61 mm offset that compensate refused
    # to guess: a robot 3x softer than modelled misses 2x the VJM's deflection, and the part of
    # that misfit one scale cannot hold (link bending) leaves sideways patterns of its order.
    # Beside such a misfit the drift and the offset are the robot's as well: cannot tell.
    from roboisf.decompose.diagnose import ROBOT_MISFIT, model_off

    c = _cone()
    x = c["Aj"].sum(axis=1)
    d = np.array([0.3e-3, -0.1e-3])
    rf = _fit(c, 3.0 * x + (c["normal"][:, :2] @ d) * c["tau"] + c["noise"])
    f = _verdicts(rf)
    assert model_off(rf)
    assert f["robot_stiffness"].verdict == "fault"
    for name in ("thermal_drift", "scan_shift", "work_object", "work_object_tilt"):
        assert f[name].verdict != "fault", (name, f[name].explanation)
    assert f["thermal_drift"].verdict == "cannot_tell"
    assert ROBOT_MISFIT in f["thermal_drift"].explanation
    # what compensate would otherwise take out of the robot term or refuse to guess: nothing
    diag = Diagnosis(list(f.values()), None, rf, False)
    assert diag.offset_pattern(c["normal"], c["contact"]) is None
    assert diag.drift_pattern(c["normal"], c["tau"]) is None
    # the same drift beside a robot only 1.2x off exceeds that misfit: still found
    # (test_an_offset_growing_with_forming_time_is_a_drift_not_the_scans)


def test_a_constant_offset_cannot_be_told_between_the_scan_and_the_work_object():
    c = _cone()
    x = c["Aj"].sum(axis=1)
    s = np.array([0.0, 0.3e-3])
    rf = _fit(c, x + c["normal"][:, :2] @ s + c["noise"])
    f = _verdicts(rf)
    for name in ("scan_shift", "work_object"):
        assert f[name].verdict == "cannot_tell", name
        assert f[name].ci_low > DETECTION_LIMITS[name][1]  # an offset, for sure
        assert f[name].ci_low <= 0.3 <= f[name].ci_high
        assert "cannot tell apart from these files" in f[name].headline
    assert "the robot scan's registration or the robot's work object" in f["scan_shift"].headline
    assert "--offset scan" in f["work_object"].explanation
    assert f["thermal_drift"].verdict == "ok"
    assert offset_seen(rf) == (True, False)


def test_a_clean_robot_term_shows_no_drift_and_keeps_its_fit():
    """No drift, offset or tilt where there is none, and the drift's column does not take the
    stiffness's interval: the same ratio and interval as without forming time."""
    c = _cone()
    x = c["Aj"].sum(axis=1)
    y = 1.0 * x + c["noise"]
    rf = _fit(c, y)
    f = _verdicts(rf)
    for name in ("scan_shift", "work_object", "thermal_drift", "work_object_tilt"):
        assert f[name].verdict == "ok", (name, f[name].explanation)
    assert rf.model == "shift"
    valid = np.ones(len(y), bool)
    old = fit_robot_term(y, x, c["Aj"], c["normal"], c["contact"], valid, c["lap"])
    assert old is not None and old.drift is None
    assert rf.ratio == old.ratio and rf.ratio_ci == old.ratio_ci


@pytest.mark.parametrize("registered", [True, False])
def test_a_tilt_of_the_formed_part_is_not_taken_for_a_drift(registered):
    """A work object tilted 0.3° about y leaves an offset growing with depth, and on a
    step-down path forming time follows depth: fitted without a tilt it read as a 0.6 mm drift
    (and, before the drift's column, as a scan shift). The tilt is the work object's when the
    scan's registration fitted its tilts (the flange), the scan's or the work object's when it
    did not — then it is an offset compensate must ask about."""
    c = _cone()
    x = c["Aj"].sum(axis=1)
    th = math.radians(0.3)
    tilt = th * np.einsum("ij,ij->i", c["normal"], np.cross([0.0, 1.0, 0.0], c["contact"]))
    rf = _fit(c, x + tilt + c["noise"], tilt_registered=registered)
    f = _verdicts(rf)
    assert rf.model == "tilt"
    assert f["thermal_drift"].verdict != "fault", f["thermal_drift"].explanation
    assert f["scan_shift"].verdict != "fault" and f["work_object"].verdict != "fault"
    t = f["work_object_tilt"]  # mm sideways at the deepest analysed point
    assert t.unit == "mm" and rf.depth_max == pytest.approx(0.052, abs=1e-3)
    assert t.ci_low <= th * rf.depth_max * 1e3 <= t.ci_high
    diag = Diagnosis(robot_findings(rf, axisymmetric=True), None, rf, False)
    pattern = diag.offset_pattern(c["normal"], c["contact"])
    if registered:
        assert t.verdict == "fault" and "not the scan's" in t.explanation
        assert pattern is None  # the part's: compensate corrects it
    else:
        assert t.verdict == "cannot_tell" and "robot scan tilted" in t.explanation
        assert pattern is not None and np.allclose(pattern, tilt, atol=0.02e-3)


def test_where_the_analysed_laps_take_a_short_part_of_the_run_a_drift_is_an_offset():
    """The VWACF's analysed laps (small circles below the rim band) are formed in the last 4 %
    of its run: a drift there reads as a constant offset. Fitted beside the offset, the two
    columns threw a 1.3 mm offset and a 1.4 mm drift of opposite signs on a part with neither.
    Not fitted: ok where no offset is seen, cannot_tell beside one (which stays unattributed)."""
    c = _cone()
    c["tau"] = 0.96 + 0.04 * c["tau"]
    x = c["Aj"].sum(axis=1)
    rf = _fit(c, x + c["noise"])
    assert rf.drift is None and rf.drift_separable < 0.08 and rf.model == "shift"
    f = _verdicts(rf)
    for name in ("scan_shift", "work_object", "thermal_drift"):
        assert f[name].verdict == "ok", (name, f[name].explanation)
    assert f["thermal_drift"].ci_high < 0.06  # the offset's bound over κ ≈ 0.98
    s = np.array([0.25e-3, 0.0])
    f = _verdicts(_fit(c, x + c["normal"][:, :2] @ s * c["tau"] + c["noise"]))
    assert f["thermal_drift"].verdict == "cannot_tell"
    assert "a thermal drift of the robot as well as" in f["thermal_drift"].explanation
    assert f["scan_shift"].verdict == "cannot_tell" and f["scan_shift"].ci_low > 0.05
    assert "thermal drift" in f["scan_shift"].explanation


def test_forming_time_from_the_log_or_the_order_along_the_path():
    # the log's clock, from the first point; a pause (10 s standing) counts: a drift keeps
    # growing while the robot stands
    t = forming_time(np.array([5.0, 6.0, 16.0, 17.0]), 4)
    np.testing.assert_allclose(t, [0, 1 / 12, 11 / 12, 1])
    for bad in (np.array([0.0, 2.0, 1.0, 3.0]), np.array([0.0, np.nan, 2.0, 3.0]), None):
        np.testing.assert_allclose(forming_time(bad, 4), [0, 1 / 3, 2 / 3, 1])


# --------------------------------------------------------------------------------------------
# what compensate does with it


def _pp(**cols):
    names = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")
    pp = pd.DataFrame({f"robot_{w}": [1.0, 2.0] for w in names})
    pp["robot_dn"] = [0.5, 0.4]
    for k, v in cols.items():
        pp[k] = v
    return pp


def test_compensate_asks_whose_an_unattributed_offset_is():
    from roboisf.compensate.study import diagnosed_inputs

    pp = _pp(offset_pattern_dn=[0.3, -0.3])
    diag = [
        {"suspect": "scan_shift", "verdict": "cannot_tell", "estimate": 0.3, "ci_low": 0.28,
         "ci_high": 0.31, "detection_limits": [0.0, 0.05]},
    ]  # fmt: skip
    with pytest.raises(InputError) as e:
        diagnosed_inputs(pp, None, diag)
    msg = e.value.message
    assert "a sideways offset of 0.300 mm [0.280, 0.310]" in msg
    assert "robot scan's registration" in msg and "robot's work object" in msg
    assert "--offset scan" in msg and "--offset part" in msg
    _, dn = diagnosed_inputs(pp, "scan", diag)
    np.testing.assert_allclose(dn, [0.2e-3, 0.7e-3])  # left out, as a scan's fault was
    _, dn = diagnosed_inputs(pp, "part", diag)
    np.testing.assert_allclose(dn, [0.5e-3, 0.4e-3])  # kept: corrected as the part's
    with pytest.raises(InputError):
        diagnosed_inputs(pp, "robot", diag)
    # a drift at fault is the part's: kept, no question asked
    _, dn = diagnosed_inputs(_pp(drift_pattern_dn=[0.1, 0.2]))
    np.testing.assert_allclose(dn, [0.5e-3, 0.4e-3])


def test_compensate_refuses_a_bad_offset_reading_before_computing(tmp_path, capsys):
    from roboisf.cli.main import main

    (tmp_path / "s").mkdir()
    (tmp_path / "s" / "study.toml").write_text("", encoding="utf-8")
    out = tmp_path / "out"
    assert main(["compensate", str(tmp_path / "s"), "--offset", "robot", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--offset" in err and "expected scan" in err
    assert main(["compensate", "--virtual", "cone", "--offset", "scan", "-o", str(out)]) == 2
    assert "applies to a STUDY" in capsys.readouterr().err
    assert not out.exists()


def test_the_next_command_says_which_offset_to_give():
    from pathlib import Path

    from roboisf.cli.analyze import next_command, unattributed_offset

    entry = {"suspect": "scan_shift", "verdict": "cannot_tell", "estimate": 0.3, "ci_low": 0.28,
             "ci_high": 0.31, "detection_limits": [0.0, 0.05]}  # fmt: skip
    s = {"diagnosis": [entry], "vjm_check": {"verdict": "consistent"}}
    assert unattributed_offset(s)
    assert next_command(s, Path("st"), Path("res")).endswith("--offset SCAN_OR_PART -o compensated")
    s["diagnosis"] = [{**entry, "ci_low": 0.0}]  # an offset not certain: no question
    assert not unattributed_offset(s)
    assert "--offset" not in next_command(s, Path("st"), Path("res"))


# --------------------------------------------------------------------------------------------
# the defect's studies: a pyramid formed 0.3 mm off, three ways, and a clean one

PYRAMID = dict(scan_points=60_000, step_down=1e-3, spacing=2e-3, force_rate=100.0, joint_rate=50.0)
TRUTHS = {
    "drift": {"robot": {"thermal_drift": [0.3, 0.0, 0.0]}},
    "work_object": {"robot": {"kinematic_error": {"work_object": [0.3, 0, 0, 0, 0, 0]}}},
    "scan_shift": {"scan": {"shift": [0.3, 0.0, 0.0]}},
    "clean": {},
}


@pytest.fixture(scope="module")
def studies(tmp_path_factory):
    """Each truth's pyramid study and analysis results, built on first use."""
    from roboisf.decompose.pipeline import analyze, write_results
    from roboisf.virtual.cell import build_study, pyramid_cell
    from roboisf.virtual.truth import truth_from_table

    root = tmp_path_factory.mktemp("drift")
    done: dict[str, tuple] = {}

    def get(name: str):
        if name not in done:
            cell = pyramid_cell(truth=truth_from_table(TRUTHS[name]), **PYRAMID)
            build_study(cell, root / name / "study")
            r = analyze(root / name / "study")
            write_results(r, root / name / "results", png=False)
            diag = {e["suspect"]: e for e in r.summary.diagnosis}
            done[name] = (root / name, r, diag)
        return done[name]

    return get


@pytest.mark.slow
def test_a_thermal_drift_is_the_robots_fault_and_compensated(studies, tmp_path):
    from roboisf.compensate.study import compensate_study

    folder, r, diag = studies("drift")
    assert list(diag) == list(SUSPECTS)
    d = diag["thermal_drift"]
    assert d["verdict"] == "fault", d["explanation"]
    assert d["ci_low"] <= 0.3 <= d["ci_high"], d
    for name in ("scan_shift", "work_object", "scan_rotation", "work_object_tilt"):
        assert diag[name]["verdict"] != "fault", (name, diag[name]["explanation"])
    assert r.summary.diagnosis_headline.startswith("diagnosis: thermal drift: FAULT")
    assert "re-register" not in r.summary.diagnosis_headline
    pp = r.per_point
    assert "drift_pattern_dn" in pp and "offset_pattern_dn" not in pp
    assert "scan_pattern_dn" not in pp  # nothing put on the scan
    sc = compensate_study(folder / "study", results=folder / "results")  # no question asked
    assert "drift changes from run to run" in sc.compensation.meta["thermal_drift"]["note"]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["work_object", "scan_shift"])
def test_a_constant_offset_is_the_scans_or_the_work_objects(studies, name):
    """The work object's offset and the scan's shift leave the same pattern in the robot term:
    the honest answer is the same for both truths."""
    _folder, r, diag = studies(name)
    for s in ("scan_shift", "work_object"):
        d = diag[s]
        assert d["verdict"] == "cannot_tell", d
        assert d["ci_low"] > 0.05 and d["ci_low"] - 0.01 <= 0.3 <= d["ci_high"] + 0.01, d
    assert diag["thermal_drift"]["verdict"] == "ok", diag["thermal_drift"]["explanation"]
    assert not any(e["verdict"] == "fault" for e in diag.values())
    head = r.summary.diagnosis_headline
    assert "the robot scan's registration or the robot's work object — cannot tell apart" in head
    assert "check the scan's reference marks, or measure the work object" in head
    assert "offset_pattern_dn" in r.per_point and "scan_pattern_dn" not in r.per_point


@pytest.mark.slow
def test_compensate_refuses_to_guess_and_offset_scan_is_todays_correction(
    studies, tmp_path, capsys
):
    """Without --offset: exit 2, naming the offset and both readings, nothing written. With
    --offset scan: the correction of a scan's fault as before (the same tips as results whose
    pattern is the scan's, scan_pattern_dn); with --offset part the offset is corrected."""
    from roboisf.cli.main import main

    folder, _r, _diag = studies("scan_shift")
    study, results = folder / "study", folder / "results"
    out = tmp_path / "c"
    base = ["-q", "compensate", str(study), "--no-png"]
    assert main([*base, "--results", str(results), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    size = float(re.search(r"sideways offset of ([0-9.]+) mm", err).group(1))
    assert abs(size - 0.3) < 0.02 and "--offset scan" in err
    assert "--offset part" in err and not out.exists()
    assert main([*base, "--results", str(results), "--offset", "scan", "-o", str(out)]) == 0
    record = json.loads((out / "compensation.json").read_text(encoding="utf-8"))
    assert record["unattributed_offset"]["reading"] == "scan"
    assert "left out of the correction" in record["unattributed_offset"]["note"]
    # today's: the same pattern as a scan's fault (scan_pattern_dn), no question asked
    old = tmp_path / "old_results"
    shutil.copytree(results, old)
    pp = pd.read_parquet(old / "per_point.parquet")
    pp.rename(columns={"offset_pattern_dn": "scan_pattern_dn"}).to_parquet(
        old / "per_point.parquet", index=False
    )
    assert main([*base, "--results", str(old), "-o", str(tmp_path / "o")]) == 0
    a = pd.read_csv(out / "compensated.csv", comment="#")
    b = pd.read_csv(tmp_path / "o" / "compensated.csv", comment="#")
    pd.testing.assert_frame_equal(a, b)
    p = tmp_path / "p"
    assert main([*base, "--results", str(results), "--offset", "part", "-o", str(p)]) == 0
    ps = pd.read_csv(out / "per_point.csv")
    pp_ = pd.read_csv(p / "per_point.csv")
    pattern = pd.read_parquet(results / "per_point.parquet")["offset_pattern_dn"].to_numpy()
    judged = np.isfinite(ps["dn_before"].to_numpy())
    np.testing.assert_allclose(
        (pp_["dn_before"] - ps["dn_before"]).to_numpy()[judged], pattern[judged], atol=2e-5
    )


@pytest.mark.slow
def test_a_clean_pyramid_shows_no_drift_offset_or_tilt(studies):
    folder, r, diag = studies("clean")
    assert not any(e["verdict"] == "fault" for e in diag.values()), r.summary.diagnosis_headline
    for name in ("thermal_drift", "work_object_tilt"):
        assert diag[name]["verdict"] == "ok", diag[name]["explanation"]
    assert r.summary.diagnosis_headline.startswith("diagnosis: no fault found")
    assert "offset_pattern_dn" not in r.per_point and "drift_pattern_dn" not in r.per_point
    from roboisf.compensate.study import compensate_study

    compensate_study(folder / "study", results=folder / "results")  # no question asked
