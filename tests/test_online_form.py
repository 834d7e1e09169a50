"""The part the online loop forms, analysed like any study: `analyze` of the virtually formed
part shows the robot-compliance term removed (issue #17, "shown by analyze")."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from roboisf.decompose.pipeline import analyze
from roboisf.errors import InputError
from roboisf.online import Limits
from roboisf.online.sim import applied_per_point, form_online, form_study, virtual_setup
from roboisf.virtual.cell import build_study
from roboisf.virtual.truth import load_truth

#: loops at their real cycle: this module waits on the clock more than it computes (the
#: collection puts it beside a CPU-bound module, tests/conftest.py)
pytestmark = pytest.mark.realtime


@pytest.fixture(scope="module")
def setup(online_cone):
    return virtual_setup(online_cone(20e-3, scan_points=20_000, force_rate=100.0, joint_rate=50.0))


@pytest.fixture(scope="module")
def uncorrected(setup, tmp_path_factory):
    """``analyze``'s decomposition of the part formed without the loop (the reference of the
    in-process and the command-line tests alike), built once."""
    plain = build_study(setup.vc, tmp_path_factory.mktemp("plain") / "uncorrected")
    return analyze(plain).decomposition


def _rms(d, x):
    return float(np.sqrt(np.mean(x[d.valid] ** 2)))


def test_analyze_of_the_online_part_shows_the_compliance_error_removed(
    setup, uncorrected, tmp_path
):
    run = form_online(setup, "egm", limits=Limits())
    online = form_study(setup, run.applied, tmp_path / "online")
    d0 = uncorrected
    d1 = analyze(online).decomposition
    assert d1.valid.sum() > 100

    def error(d):  # the robot run's compliance error as analyze books it (normal, m)
        return d.normal["tool"] + d.normal["tool_holder"] + d.normal["robot_compliance"]

    before, after = _rms(d0, error(d0)), _rms(d1, error(d1))
    assert before > 300e-6  # a real error to remove (≈ 0.43 mm on this cone's wall)
    assert after <= 0.2 * before, (before, after)  # issue #17: ≥ 80 % (measured: ≈ 94 %)
    # the loop pre-deflects tool and holder too; analyze's model has no command, so that part
    # of the correction shows in its robot term: robot_compliance ≈ −(tool + holder)
    th = d1.normal["tool"] + d1.normal["tool_holder"]
    assert _rms(d1, th) > 50e-6
    assert _rms(d1, d1.normal["robot_compliance"] + th) <= 0.2 * before
    # the robot still deflects as much (same force, same VJM at the commanded joints) ...
    assert _rms(d1, d1.normal["vjm"]) == pytest.approx(_rms(d0, d0.normal["vjm"]), rel=0.05)
    # ... and the truth says the command cancels it: n · (δ_robot + command) is small
    t = pd.read_parquet(online / "truth" / "per_point.parquet")
    rc = t["robot_compliance_dn"].to_numpy()
    cancelled = rc + t["command_offset_dn"].to_numpy() + t["tool_dn"] + t["tool_holder_dn"]
    assert np.sqrt(np.mean(rc**2)) > 0.2  # mm
    assert np.sqrt(np.mean(cancelled**2)) < 0.1 * np.sqrt(np.mean(rc**2))


def _error(d):
    return d.normal["tool"] + d.normal["tool_holder"] + d.normal["robot_compliance"]


def test_where_the_model_is_not_the_truth_the_loop_removes_what_it_predicts(setup, tmp_path):
    """The paper scenario's robot differs from the VJM the loop uses (stiffer/softer joints,
    geometric error, springback coupling): what remains on the online part is the uncorrected
    part's model error, analyze's ``delta`` (robot term − VJM), to within the scan's noise."""
    vc = replace(setup.vc, truth=load_truth(scenario="paper", part="cone"))
    s = virtual_setup(vc)
    run = form_online(s, "egm", limits=Limits())
    d0 = analyze(build_study(vc, tmp_path / "uncorrected")).decomposition
    d1 = analyze(form_study(s, run.applied, tmp_path / "online")).decomposition
    v = d0.valid & d1.valid
    assert v.sum() > 100

    def rms(x):
        return float(np.sqrt(np.mean(x[v] ** 2)))

    before, after, delta = rms(_error(d0)), rms(_error(d1)), rms(d0.normal["delta"])
    assert delta > 0.1e-3  # the truth is well off the model (≈ 0.22 mm)
    assert after < 0.5 * before  # ≈ 0.64 → 0.20 mm: the part the model predicts is gone
    assert after > 0.5 * delta  # the rest, the model's error, is not
    assert rms(_error(d1) - d0.normal["delta"]) <= 30e-6  # measured ≈ 19 µm (scan noise)


def test_applied_per_point_from_the_controllers_report(setup):
    n = len(setup.toolpath)
    k = np.array([0, 2, 4, 4, 4]) if n > 5 else np.array([0])
    a = np.array([[0, 0, 0], [2e-4, 0, 0], [4e-4, 0, 0], [9e-4, 0, 0], [9e-4, 0, 0]])
    out = applied_per_point(setup, k, a)
    assert out.shape == (n, 3)
    np.testing.assert_allclose(out[:5, 0], [0, 1e-4, 2e-4, 3e-4, 4e-4])  # first of a held point
    assert not out[5:].any()  # never reached: formed uncorrected
    with pytest.raises(InputError):
        applied_per_point(setup, k[::-1], a)
    with pytest.raises(InputError):
        form_study(setup, np.full((n, 3), np.nan), "unused")


@pytest.mark.slow
def test_online_simulate_form_from_the_command_line(tmp_path, monkeypatch, setup, uncorrected):
    """`roboisf online --simulate --form STUDY` over localhost UDP, then `analyze` of the study
    (a small cone in place of the paper's, so it is quick)."""
    import roboisf.virtual.cell as vcell
    from roboisf.cli.main import main

    small = setup.vc
    monkeypatch.setattr(vcell, "paper_cone_cell", lambda **kw: replace(small, **kw))
    log, formed = tmp_path / "log.parquet", tmp_path / "formed"
    args = ["-q", "online", "-c", "egm", "--virtual", "cone", "--simulate", "--duration", "3"]
    args += ["--form", str(formed), "--scan-points", "20000", "-o", str(log)]
    assert main(args) == 0
    d0, d1 = uncorrected, analyze(formed).decomposition
    err = [
        d.normal["tool"] + d.normal["tool_holder"] + d.normal["robot_compliance"] for d in (d0, d1)
    ]
    before, after = _rms(d0, err[0]), _rms(d1, err[1])
    print(
        f"online --simulate --form: compliance error RMS {before * 1e6:.0f} → {after * 1e6:.0f} µm"
    )
    assert after <= 0.2 * before, (before, after)


@pytest.mark.slow
def test_online_form_of_the_paper_cone_is_analysed_and_its_robot_term_is_the_loops_log(tmp_path):
    """#27 item 4: `online --simulate --form` of the paper cone at the virtual cell's own log
    rates, then `analyze` of the study: exit 0 (it was 2, 2 of 2 runs: "the force log covers
    … but the joint log puts the toolpath at …", the correction held at the path's end moving
    where the joint log places the end by a few ms). analyze's robot term less its VJM model,
    n · (command), is the correction the loop logged, point by point."""
    from roboisf.cam.toolpath_csv import read_toolpath_csv
    from roboisf.cli.main import main
    from roboisf.virtual.cell import paper_cone_cell

    log, formed = tmp_path / "log.parquet", tmp_path / "formed"
    args = ["-q", "online", "-c", "egm", "--virtual", "cone", "--simulate", "--cycle", "12"]
    args += ["--duration", "6", "--form", str(formed), "-o", str(log)]  # 300 k-point scans
    assert main(args) == 0
    # --no-png: the figures are not what this test reads (≈ 1.4 s of rendering them)
    assert main(["-q", "analyze", str(formed), "--no-png", "-o", str(tmp_path / "report")]) == 0
    # analyze's per-point results as that run wrote them (mm; `used`: the decomposition's valid
    # points) — not a second analysis of the 300 k-point scans
    pp = pd.read_parquet(tmp_path / "report" / "per_point.parquet")
    tp = read_toolpath_csv(formed / "toolpath.csv")
    n = len(tp)
    step = int(np.ceil(n / 500))  # --duration 6 s, 12 ms cycles: 500 cycles over the path
    df = pd.read_parquet(log)
    # What the controller applied, from its own feedback in the loop's log (EGM's feedBack
    # joints, as a real controller reports them): message seq s carries the joints of toolpath
    # point (s − 1)·step moved by the correction it applied there. A reply that missed its
    # cycle is not applied — the controller keeps the one before — so this, not the loop's
    # commanded corrections shifted by a cycle, is what formed the part: on a loaded machine
    # the shifted commands put the part a cycle late wherever a reply missed (8 cycles per lap
    # of the cone here: 45° of the force's turn), a correlation of 0.939 in one CI run.
    k = (df["seq"].to_numpy() - 1) * step
    q = np.radians(df[[f"q{i}_deg" for i in range(1, 7)]].to_numpy())
    vc = paper_cone_cell()
    T_work_tip = vc.cell.robot.fk(q, T_base_work=vc.cell.T_base_work)
    fed_back = T_work_tip[:, :3, 3] - tp.tip[np.minimum(k, n - 1)]
    # the protocol, cycle by cycle: each feedback is the loop's correction of the cycle before
    # (its reply in time) or the feedback before (missed: held) — to 1 µm (the joints' first
    # order in the correction: 0.2 µm at 0.5 mm), units and frame included
    corr = df[["corr_x_mm", "corr_y_mm", "corr_z_mm"]].to_numpy() * 1e-3
    took = np.linalg.norm(fed_back[1:] - corr[:-1], axis=1) < 1e-6
    held = np.linalg.norm(fed_back[1:] - fed_back[:-1], axis=1) < 1e-6
    assert np.all(took | held), np.flatnonzero(~(took | held))[:10]
    assert took.sum() >= 10, took.sum()  # (all held: nothing applied)
    print(f"replies applied in their cycle: {took.sum()} of {len(took)}")
    keep = k < n
    applied = np.column_stack(
        [np.interp(np.arange(n), k[keep], fed_back[keep, j]) for j in range(3)]
    )
    n_applied = np.einsum("ij,ij->i", applied, tp.normal)
    assert len(pp) == n
    analysed = (pp["robot_compliance_dn"] - pp["vjm_dn"]).to_numpy() * 1e-3
    v = pp["used"].to_numpy()
    a, b = n_applied[v], analysed[v]
    assert float(np.sqrt(np.mean(a**2))) > 0.1e-3
    # the analysed term follows the applied correction one to one (sign, unit, frame): measured
    # slope 0.96, correlation 0.98 (paper cone, 300 k-point scans); what is left is analyze's
    # own scatter on a scan (≈ 36 µm RMS there; ≈ 55 µm and a correlation of 0.88 with 20 k)
    r = float(np.corrcoef(a, b)[0, 1])
    slope = float((a @ b) / (a @ a))
    assert 0.9 < slope < 1.1, (slope, r)
    assert r > 0.95, r


@pytest.fixture(scope="module")
def setup_logged(online_cone):
    """The cone at the virtual cell's own log rates (1 kHz forces, joints at their default):
    the study `online --simulate --form` writes, whose joint log places the path's end to a
    few ms."""
    return virtual_setup(online_cone(20e-3, scan_points=20_000))


def test_the_online_part_analyses_and_its_robot_term_is_the_loops_correction(
    setup_logged, tmp_path
):
    """In process (the loop's codecs, no sockets): at the virtual cell's own log rates the
    formed part's study is analysed, and analyze's robot term moves, from the uncorrected
    part's, by the loop's own correction n · applied."""
    s = setup_logged
    run = form_online(s, "egm", limits=Limits())
    d0 = analyze(build_study(s.vc, tmp_path / "plain")).decomposition
    d1 = analyze(form_study(s, run.applied, tmp_path / "online")).decomposition
    v = d0.valid & d1.valid
    assert v.sum() > 100  # the points the scan covers
    n_applied = np.einsum("ij,ij->i", run.applied, s.toolpath.normal)
    moved = d1.normal["robot_compliance"] - d0.normal["robot_compliance"]
    rms = float(np.sqrt(np.mean(n_applied[v] ** 2)))
    assert rms > 0.2e-3
    # the same to within what the commanded pose changes of the VJM deflection and the scan
    assert float(np.sqrt(np.mean((moved - n_applied)[v] ** 2))) < 0.05 * rms
