"""IK branches and turns chosen by logged joints, ABB confdata or KUKA S/T; numerical IK of
non-OPW robots; ``robot deflect`` on a URDF robot without a joint log (issue #15 items 2, 4)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from roboisf.cam.toolpath_csv import write_toolpath_csv
from roboisf.cli.main import main
from roboisf.errors import InputError
from roboisf.frames import make_transform
from roboisf.io.table import read_table
from roboisf.logs.forcelog import ForceLog, write_force_log
from roboisf.parts import Cone
from roboisf.robot import SingularityWarning, ik_toolpath, load_robot, load_urdf
from roboisf.robot.armconfig import abb_confdata, arm_config, kuka_status_turn, program_config
from roboisf.robot.ik import BRANCHES, start_candidates
from roboisf.toolpath import step_down

URDF = Path(__file__).parent / "data" / "urdf"
TOOL = make_transform(None, [0, 0, 0.3])


@pytest.fixture(scope="module")
def tp():
    return step_down(Cone(), step_down=5e-3)


def _ik(m, tp, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SingularityWarning)
        return ik_toolpath(m, tp.tip, m.default_placement, singular_threshold=None, **kw)


def _branch_paths(m, tp):
    """Every branch whose path is feasible: branch → q (N, 6)."""
    out = {}
    for br in BRANCHES:
        try:
            out[br] = _ik(m, tp, shoulder=br[0], elbow=br[1], wrist=br[2]).q
        except Exception:  # unreachable / beyond limits for this branch
            continue
    return out


@pytest.mark.parametrize("name", ["irb4600-60-2.05", "kr210-r2700-2", "m900ib-700"])
def test_start_candidates_are_all_solutions(name):
    """Every candidate of the first pose reproduces it (FK) and lies within the limits; both
    wrist branches and the second turn of the wide axes 4/6 are there."""
    m = load_robot(name).with_tool(TOOL)
    q = np.radians([10, 20, -10, 30, 40, 50]) * np.sign(m.q_max)
    T = m.fk(q[None], check_limits=False)[0]
    c = start_candidates(m, T)
    qs = np.array([x for _, x in c])
    np.testing.assert_allclose(m.fk(qs), np.broadcast_to(T, (len(c), 4, 4)), atol=1e-9)
    assert {"flip", "noflip"} <= {br[2] for br, _ in c}
    assert np.all(qs <= m.q_max + 1e-9) and np.all(qs >= m.q_min - 1e-9)
    if np.degrees(m.q_max[5] - m.q_min[5]) > 360:
        assert np.ptp(qs[:, 5]) > np.pi  # another turn of axis 6
    # the original joints are one of the candidates
    assert np.min(np.max(np.abs(qs - q), axis=1)) < 1e-9


def test_confdata_picks_branch_and_turns(tp):
    m = load_robot("irb4600-60-2.05").with_tool(TOOL)
    paths = _branch_paths(m, tp)
    assert len(paths) >= 2
    for q in paths.values():
        cf = abb_confdata(arm_config(m, q[:1]))[0]
        q2 = _ik(m, tp, confdata=cf).q
        np.testing.assert_allclose(q2, q, atol=1e-12)
        # the program written from the chosen branch carries that confdata at the first point
        cfg = program_config(m, tp, m.default_placement, confdata=cf)
        np.testing.assert_array_equal(abb_confdata(cfg)[0], cf)
    # one more turn of axis 6 (IRB 4600: ±400°) when it fits: cf6 + 4 quadrants
    q = next(iter(paths.values()))
    cf = abb_confdata(arm_config(m, q[:1]))[0].copy()
    for dk in (4, -4):
        cf2 = cf.copy()
        cf2[2] += dk
        try:
            q2 = _ik(m, tp, confdata=cf2).q
        except Exception:
            continue
        np.testing.assert_allclose(q2[:, 5] - q[:, 5], np.sign(dk) * 2 * np.pi, atol=1e-12)
        np.testing.assert_allclose(q2[:, :5], q[:, :5], atol=1e-12)
        break
    else:
        pytest.fail("no second turn of axis 6 within ±400°")


def test_confdata_not_available_lists_the_options(tp):
    m = load_robot("irb4600-60-2.05").with_tool(TOOL)
    with pytest.raises(InputError, match=r"available there: \[\("):
        _ik(m, tp, confdata=[7, 7, 7, 7])
    with pytest.raises(InputError, match="at most one"):
        _ik(m, tp, confdata=[0, 0, 0, 0], kuka_st=[2, 0])


def test_kuka_status_turn_picks_branch(tp):
    m = load_robot("kr210-r2700-2").with_tool(TOOL)
    paths = _branch_paths(m, tp)
    assert paths
    for q in paths.values():
        st = kuka_status_turn(arm_config(m, q[:1]))[0]
        np.testing.assert_allclose(_ik(m, tp, kuka_st=st).q, q, atol=1e-12)


def test_logged_joints_pick_branch(tp):
    m = load_robot("m900ib-700").with_tool(TOOL)  # coupled FANUC: numpy IK
    paths = _branch_paths(m, tp)
    assert paths
    rng = np.random.default_rng(0)
    for q in paths.values():
        noisy = q[0] + rng.normal(0, 0.01, 6)  # a logged pose near the first point
        np.testing.assert_allclose(_ik(m, tp, match_q=noisy).q, q, atol=1e-12)


@pytest.mark.filterwarnings("ignore::roboisf.robot.ik.NumericalIKWarning")  # opw=False on purpose
def test_numerical_ik_equals_closed_form(tp):
    """A URDF robot read without its OPW form: DLS IK seeded by the first logged pose gives the
    closed-form path to 1e-10 rad, continuous; the deflections agree to 1e-12 m."""
    m = load_robot("irb4600-60-2.05").with_tool(TOOL)
    u = load_urdf(URDF / "irb4600_60_205.urdf", opw=False).with_tool(TOOL)
    assert u.opw is None
    sub = tp.tip[:400]
    P = m.default_placement
    r = ik_toolpath(m, sub, P)
    rn = ik_toolpath(u, sub, P, match_q=r.q[0] + 0.02)
    np.testing.assert_allclose(rn.q, r.q, atol=1e-10)
    K = np.array([3e6, 4e6, 3e6, 6e5, 7e5, 4e5])
    W = np.array([120.0, -80.0, 450.0, 0, 0, 0])
    d = m.with_stiffness(K).deflection(r.q, W)
    dn = u.with_stiffness(K).deflection(rn.q, W)
    assert np.max(np.abs(d - dn)) < 1e-12
    # without a start the numerical IK still gives a valid continuous path
    r2 = ik_toolpath(u, sub, P)
    np.testing.assert_allclose(u.fk(r2.q)[:, :3, 3], r.T_base_tip[:, :3, 3], atol=1e-9)
    assert np.max(np.abs(np.diff(r2.q, axis=0))) < 0.2
    with pytest.raises(InputError, match="no OPW geometry"):
        ik_toolpath(u, sub, P, confdata=[0, 0, 0, 0])


@pytest.fixture(scope="module")
def cell(tmp_path_factory, tp):
    d = tmp_path_factory.mktemp("cell")
    write_toolpath_csv(tp, d / "path.csv")
    t = np.linspace(tp.time[0] - 1, tp.time[-1] + 1, 400)
    W = np.zeros((t.size, 6))
    W[:, 0], W[:, 1], W[:, 2] = 120.0, -80.0, 450.0
    write_force_log(ForceLog(time=t, wrench=W, frame="work", path=None), d / "forces.csv")
    (d / "K.toml").write_text("[stiffness]\nK = [3.1e6, 4.2e6, 3.3e6, 6.4e5, 7.5e5, 4.6e5]\n")
    return d


def _deflection(path):
    t = read_table(path, ["dx", "dy", "dz", "q1"], allow_extra=True)
    return np.stack([t.column(c) for c in ("dx", "dy", "dz")], axis=1) * 1e-3


@pytest.mark.parametrize(
    ("urdf", "preset"),
    [("irb4600_60_205.urdf", "irb4600-60-2.05"), ("kr210_r2700_2.urdf", "kr210-r2700-2")],
)
def test_deflect_urdf_robot_without_joint_log(cell, tmp_path, urdf, preset):
    """Issue #15: `robot deflect --robot ROBOT.urdf --stiffness K.toml --toolpath … --placement …`
    works without a joint log, and equals the preset's deflections within 1e-9 m."""
    d = cell
    common = [
        "robot", "deflect", "--toolpath", str(d / "path.csv"), "--forces", str(d / "forces.csv"),
        "--stiffness", str(d / "K.toml"), "--placement", "1300,100,500,15", "--tool", "0,0,300",
    ]  # fmt: skip
    out_u, out_p = tmp_path / "u.csv", tmp_path / "p.csv"
    assert main([*common, "--robot", str(URDF / urdf), "-o", str(out_u)]) == 0
    assert main([*common, "--robot", preset, "-o", str(out_p)]) == 0
    du, dp = _deflection(out_u), _deflection(out_p)
    assert np.max(np.abs(du)) > 1e-5  # a real deflection, not zeros
    assert np.max(np.abs(du - dp)) < 1e-9


def test_deflect_branch_options(cell, tmp_path, capsys):
    d = cell
    common = [
        "robot", "deflect", "--toolpath", str(d / "path.csv"), "--forces", str(d / "forces.csv"),
        "--stiffness", str(d / "K.toml"), "--robot", "irb4600-60-2.05", "--tool", "0,0,300",
    ]  # fmt: skip
    out = tmp_path / "a.csv"
    assert main([*common, "--confdata", "9,9,9,9", "-o", str(out)]) == 2
    assert "confdata" in capsys.readouterr().err
    assert main([*common, "--confdata", "0,0,0,0", "--kuka-st", "2,0", "-o", str(out)]) == 2
    assert not out.exists()


def test_toolpath_program_follows_the_chosen_configuration(tmp_path):
    """`roboisf toolpath … --robot R --arm-config …`: the RAPID confdata / KRL S,T written in the
    program are those of the chosen branch (first point as requested, the rest from its joints)."""
    from roboisf.cam.toolpath_csv import read_toolpath_csv
    from roboisf.frames.rotations import rpy_to_matrix
    from roboisf.programs.krl import read_krl
    from roboisf.programs.rapid import read_rapid
    from roboisf.robot.armconfig import abb_confdata, parse_arm_config

    cone = ["--opening-diameter", "60", "--wall-angle", "60", "--depth", "5", "--spacing", "3"]
    cell = ["--placement", "2200,0,200,0,0,10", "--tool", "306", "--robot", "irb7600-500-2.55"]
    ref = tmp_path / "ref.csv"
    assert main(["toolpath", "cone", *cone, "-o", str(ref)]) == 0
    tp = read_toolpath_csv(ref)
    m = load_robot("irb7600-500-2.55").with_tool(make_transform(None, [0, 0, 0.306]))
    T = make_transform(rpy_to_matrix(np.radians([0, 0, 10])), [2.2, 0, 0.2])
    default = abb_confdata(program_config(m, tp, T))
    # another feasible configuration: the flipped wrist
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SingularityWarning)
        q_flip = ik_toolpath(m, tp.tip, T, wrist="flip", singular_threshold=None).q
    cf = abb_confdata(arm_config(m, q_flip[:1]))[0]
    assert not np.array_equal(cf, default[0])
    out = tmp_path / "p.mod"
    arg = ",".join(str(int(x)) for x in cf)
    assert main(["toolpath", "cone", *cone, *cell, "--arm-config", arg, "-o", str(out)]) == 0
    conf = read_rapid(out).meta["confdata"]
    np.testing.assert_array_equal(conf[0], cf)
    np.testing.assert_array_equal(conf, abb_confdata(arm_config(m, q_flip)))
    # KUKA S,T and joints in degrees parse to the same choice
    st = kuka_status_turn(arm_config(m, q_flip[:1]))[0]
    src = tmp_path / "p.src"
    assert (
        main(["toolpath", "cone", *cone, *cell, "--arm-config", f"{st[0]},{st[1]}", "-o", str(src)])
        == 0
    )
    assert tuple(read_krl(src).meta["status_turn"]) == tuple(int(x) for x in st)
    kw = parse_arm_config(",".join(f"{x:.6f}" for x in np.degrees(q_flip[0])))
    np.testing.assert_allclose(kw["match_q"], q_flip[0], atol=1e-8)
    with pytest.raises(InputError, match="2 \\(KUKA"):
        parse_arm_config("1,2,3")
