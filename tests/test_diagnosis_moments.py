"""A moment bias is not moment crosstalk: the logs at rest tell them apart.

The flange sensor's moment channels can read an offset (a bias, or the tool's weight acting off
the sensor's axis) or a share of the forces (crosstalk). Along a wall both put a near-constant
false moment on the tip — the axial force barely varies there — so on the path alone a bias
was called ``force_moment_crosstalk`` FAULT (6.05 mm on a clean cone with 3.6 N·m of bias).
With the tool off the sheet a bias still reads, crosstalk does not (it scales with the force):
``force_moment_bias`` and ``force_moment_crosstalk`` each get their own verdict. Without a
stretch at rest both are ``cannot_tell`` when the constant matters, each naming the other —
never a FAULT on the wrong one.
"""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.decompose.diagnose import UnloadedEvidence, fit_sensor, sensor_findings
from test_diagnosis import _noisy, _path

R = 5e-3
MU = np.array([0.8, -0.6, 0.1])  # N·m, |MU| = 1.005 (the limit is 0.5)


def _rest(F=(0.0, 0.0, 0.0), M=(0.0, 0.0, 0.0), *, tared=False, seed=3, n=400):
    """The unloaded start of each log (tip wrench, work axes) with the flange sensor reading
    ``F`` (N) and ``M`` (N·m) at rest; the dynamometer reads zero."""
    from dataclasses import replace

    from roboisf.sensor import unloaded_stretches

    rng = np.random.default_rng(seed)
    out = {}
    for name, (f, m) in (("robot", (F, M)), ("cnc", ((0.0,) * 3, (0.0,) * 3))):
        t = np.arange(2 * n) * 0.01
        W = rng.normal(0, 2.0, (2 * n, 6)) * [1, 1, 1, 0.01, 0.01, 0.01]
        W[:, :3] += f
        W[:, 3:] += m
        W[n:, 2] += 600.0  # the forming starts
        W[n:, 0] += 250 * np.sin(t[n:])
        (u,) = unloaded_stretches(t, W)
        out[name] = [replace(u, tared=tared)]
    return out


def _diagnose(W_rob, rest=None, lever=None):
    p = _path()
    valid = np.ones(len(p["lap"]), bool)
    ev = UnloadedEvidence.from_stretches(**rest, lever=lever) if rest is not None else None
    sf = fit_sensor(
        p["W"], _noisy(W_rob), p["arm"], valid, p["lap"], p["depth"], unloaded=ev, lever=lever
    )
    return sf, {f.suspect: f for f in sensor_findings(sf, R, ev)}


def _with_moment_bias():
    p = _path()
    W = p["W"].copy()
    W[:, 3:] += MU
    return W


def _with_moment_crosstalk(k=8e-3):
    """Each moment channel reads k (m = N·m per N) of each force channel, the axial one too."""
    p = _path()
    W = p["W"].copy()
    W[:, 3:] += k * W[:, :3].sum(axis=1, keepdims=True)
    return W


def test_a_moment_bias_seen_at_rest_is_a_bias_not_crosstalk():
    """It was called force_moment_crosstalk FAULT; the logs at rest read it without load."""
    _sf, f = _diagnose(_with_moment_bias(), _rest(M=MU))
    mb, ct = f["force_moment_bias"], f["force_moment_crosstalk"]
    assert mb.verdict == "fault", mb.explanation
    assert mb.ci_low <= np.linalg.norm(MU) <= mb.ci_high, (mb.ci_low, mb.ci_high)
    assert ct.verdict == "ok", ct.explanation
    assert mb.unit == "N·m" and "no crosstalk" in mb.explanation


def test_moment_crosstalk_reads_nothing_at_rest():
    """The reverse: crosstalk from every force channel (a near-constant share from the axial
    force) is what the load brings; the moment channels read nothing at rest."""
    _sf, f = _diagnose(_with_moment_crosstalk(), _rest())
    assert f["force_moment_crosstalk"].verdict == "fault", f["force_moment_crosstalk"].explanation
    assert f["force_moment_bias"].verdict == "ok", f["force_moment_bias"].explanation
    # its estimate: what the load brings, the axial share included (the lateral forces' part
    # alone is less): RMS of k·(Fx + Fy + Fz) over each of 3 channels per RMS |F|
    p = _path()
    F = p["W"][:, :3]
    deep = p["depth"] >= np.median(p["depth"])
    want = (
        np.sqrt(3 * np.mean(F[deep].sum(1) ** 2)) * 8e-3 / np.sqrt(np.mean((F[deep] ** 2).sum(1)))
    )
    ct = f["force_moment_crosstalk"]
    assert abs(ct.estimate - want * 1e3) < 0.03 * want * 1e3, (ct.estimate, want * 1e3)


@pytest.mark.parametrize("case", ["bias", "crosstalk"])
def test_without_the_logs_at_rest_the_constant_cannot_be_told(case):
    """A tared log (its stretch at rest reads zero by construction) or one that starts loaded
    has no evidence: a bias and the axial force's crosstalk are the same constant along a wall.
    Never a FAULT on the wrong suspect; cannot_tell naming both where the constant matters. The
    share that follows the lateral force is crosstalk for sure."""
    W = _with_moment_bias() if case == "bias" else _with_moment_crosstalk()
    for rest in (None, _rest(M=MU if case == "bias" else (0.0,) * 3, tared=True)):
        _sf, f = _diagnose(W, rest)
        mb, ct = f["force_moment_bias"], f["force_moment_crosstalk"]
        if case == "bias":
            assert ct.verdict == "cannot_tell", ct.explanation
            assert mb.verdict == "cannot_tell", mb.explanation
            for x in (mb, ct):
                assert "cannot be told apart" in x.explanation
                assert "force_moment_bias" in x.explanation
                assert "force_moment_crosstalk" in x.explanation
            assert mb.ci_low <= np.linalg.norm(MU) <= mb.ci_high
        else:
            assert ct.verdict == "fault", ct.explanation  # it follows the lateral force too
            assert mb.verdict != "fault", mb.explanation


def test_a_force_bias_carried_up_the_arm_is_neither():
    """A force bias at a sensor 250 mm above the tip makes a constant tip moment lever × b
    (8 N·m for 30 N). It was cannot_tell for the moment crosstalk; at rest the sensor reads the
    same moment with the same force: no moment-channel fault at all."""
    p = _path()
    lever = np.array([0.0, 0.0, 0.25])
    b = np.array([25.0, -15.0, 5.0])
    W = p["W"].copy()
    W[:, :3] += b
    W[:, 3:] += np.cross(lever, b)
    _sf, f = _diagnose(W, _rest(F=b, M=np.cross(lever, b)), lever=lever)
    assert f["force_bias"].verdict == "fault"
    assert f["force_moment_crosstalk"].verdict == "ok", f["force_moment_crosstalk"].explanation
    assert f["force_moment_bias"].verdict == "ok", f["force_moment_bias"].explanation
    # the same without knowing where the sensor is: its force offset's moment is taken for a
    # moment bias — the lever is what tells them apart
    _sf, f = _diagnose(W, _rest(F=b, M=np.cross(lever, b)))
    assert f["force_moment_bias"].verdict == "fault"


def test_the_crosstalks_text_says_its_json_estimate():
    """force_moment_crosstalk said 15.93 mm in its text (the whole false moment) where
    summary.json held 4.26 mm (the part that follows the force): the text's first number is
    the estimate now, and the whole is named as such."""
    from test_diagnosis_text import _same

    for W, rest in (
        (_with_moment_crosstalk(), _rest()),
        (_with_moment_crosstalk(), None),
        (_with_moment_bias(), None),
        (_with_moment_bias(), _rest(M=MU)),
    ):
        _sf, f = _diagnose(W, rest)
        e = f["force_moment_crosstalk"].to_dict()
        first = e["explanation"].split(" mm")[0].rsplit(" ", 1)[-1]
        assert _same(first, e["estimate"]), (first, e["estimate"], e["explanation"])
        whole = {p["name"]: p for p in e["parts"]}["whole"]
        assert f"{whole['estimate']:.2f} mm" in e["explanation"]
        assert "whole false moment" in e["explanation"]


def test_a_log_that_starts_forming_is_no_proof_of_a_moment_bias():
    """Two logs starting on the path read forming force there, the robot's (the rim) 6 % below
    the dynamometer's. About a sensor 286 mm above the tip that difference is a moment of its
    own — 2.6 N·m here (150 N of lateral force), five times the 0.5 N·m limit with no bias at
    all. The processes' force
    difference (RIM_PROCESS_GAP) on that lever is in the interval: not a fault."""
    from roboisf.decompose.diagnose import RIM_PROCESS_GAP
    from roboisf.sensor.conditioning import UnloadedStretch

    rng = np.random.default_rng(2)
    lever = np.array([0.0, 0.0, 0.286])

    def stretch(F):
        B = np.zeros((16, 6))
        B[:, :3] = np.asarray(F) + rng.normal(0, 0.05, (16, 3))
        # the tip moment of a force at the contact, a few mm from the tip: ~0
        return UnloadedStretch("start", 0.0, 3.95, 400, B, on_path=True)

    F_cnc = np.array([150.0, 0.0, 60.0])
    ev = UnloadedEvidence.from_stretches([stretch(0.94 * F_cnc)], [stretch(F_cnc)], lever=lever)
    mu, _se = ev.moment_offset(1.0, np.zeros(3), 2 * R)
    assert np.linalg.norm(mu) > 2.0  # the processes' difference on the lever
    f = {x.suspect: x for x in sensor_findings(None, R, ev)}
    assert f["force_moment_bias"].verdict != "fault", f["force_moment_bias"].explanation
    assert f["force_moment_bias"].ci_low == 0.0
    assert RIM_PROCESS_GAP >= 0.06
    # a large moment bias beside it still stands out (the lever's allowance: ~3 N·m per axis)
    biased = stretch(0.94 * F_cnc).blocks + np.array([0, 0, 0, 0, 20.0, 0])
    B = UnloadedStretch("start", 0.0, 3.95, 400, biased, on_path=True)
    ev = UnloadedEvidence.from_stretches([B], [stretch(F_cnc)], lever=lever)
    f = {x.suspect: x for x in sensor_findings(None, R, ev)}
    assert f["force_moment_bias"].verdict == "fault", f["force_moment_bias"].explanation


@pytest.mark.slow
def test_a_log_without_moment_channels_has_no_moment_fault(tmp_path):
    """A 3-component flange sensor (DynoWare text) with a 22 N force bias: its tip moments are
    the point-contact moment the analysis puts there, its reading at rest no moment at all —
    compared with a lever's worth of force offset they made a 10.6 mm moment crosstalk FAULT.
    The moment suspects are ok by construction and say why; the bias is the force's."""
    from roboisf.decompose.pipeline import analyze
    from roboisf.virtual.cell import build_study, paper_cone_cell
    from roboisf.virtual.equipment import Equipment
    from roboisf.virtual.truth import truth_from_table

    truth = truth_from_table({"force_sensor": {"bias": [20.0, -10.0, 5.0, 0, 0, 0]}})
    cell = paper_cone_cell(
        truth=truth,
        step_down=3e-3,
        spacing=3e-3,
        scan_points=60_000,
        force_rate=100.0,
        joint_rate=50.0,
    )
    build_study(cell, tmp_path / "study", equipment=Equipment(robot_force_profile="kistler"))
    r = analyze(tmp_path / "study")
    f = {d["suspect"]: d for d in r.summary.diagnosis}
    assert f["force_bias"]["verdict"] == "fault"
    for s in ("force_moment_crosstalk", "force_moment_bias"):
        assert f[s]["verdict"] == "ok", f[s]["explanation"]
        assert "no moment channels" in f[s]["explanation"]
