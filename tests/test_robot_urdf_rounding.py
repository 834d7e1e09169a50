"""URDFs as they are published (issue #28): angles rounded in the file (Doosan's M0609 writes
π/2 as 1.571), a tip link whose x — not z — lies along axis 6, a robot without a spherical wrist
(numerical IK, and a line saying why), a 7-joint arm, ``--tip-link``.

``tests/data/urdf/m0609.urdf``: doosan-robotics/doosan-robot2 (Apache-2.0), see the README there.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.robot.ik import NumericalIKWarning, ik_toolpath, opw_ik
from roboisf.robot.kinematics import chain_fk
from roboisf.robot.opw_fit import explain_opw
from roboisf.robot.urdf import SNAP_TOL, load_urdf, read_urdf_arm

M0609 = Path(__file__).parent / "data" / "urdf" / "m0609.urdf"
HALF_PI = repr(math.pi / 2)


def _exact(tmp_path: Path, extra: str = "", text: str | None = None) -> Path:
    """The M0609 with its angles written in full (what its author meant)."""
    t = (text or M0609.read_text()).replace("1.571", HALF_PI)
    t = t.replace("</robot>", extra + "</robot>")
    p = tmp_path / "m0609_exact.urdf"
    p.write_text(t)
    return p


def _q(model, n=50, seed=2):
    rng = np.random.default_rng(seed)
    return rng.uniform(model.q_min * 0.9, model.q_max * 0.9, (n, 6))


def test_rounded_angles_are_snapped_and_said(tmp_path):
    arm = read_urdf_arm(M0609)
    fit, why = explain_opw(arm.chain, arm.q_min, arm.q_max)
    assert fit is None and why  # 2e-4 rad of rounding: the 1e-9 test refuses it as written
    m = load_urdf(M0609)
    assert m.opw is not None and not m.ik_note
    assert "snapped" in m.source and "joint 'joint2' rpy[1] -1.571 → -90°" in m.source
    # the snapped model is the robot the file means: FK equal to the full-precision file's
    exact = read_urdf_arm(_exact(tmp_path))
    q = _q(m)
    T = m.fk(q)
    np.testing.assert_allclose(T, chain_fk(exact.chain, q), atol=1e-9)
    # and it moved from the file as written by what the source says (≤ the stated µm)
    stated = float(m.source.split("FK moves by ≤ ")[1].split(" µm")[0]) * 1e-6
    gap = np.linalg.norm(T[:, :3, 3] - chain_fk(arm.chain, q)[:, :3, 3], axis=1).max()
    assert 1e-5 < gap <= 1.05 * stated
    assert SNAP_TOL >= 2e-4


def test_closed_form_ik_round_trip_on_the_snapped_m0609():
    m = load_urdf(M0609)
    q = _q(m, 200)
    T = m.fk(q)
    best = np.full(len(q), np.inf)
    for s in ("front", "back"):
        for e in ("up", "down"):
            for w in ("noflip", "flip"):
                qi, ok = opw_ik(m, T, shoulder=s, elbow=e, wrist=w)
                d = np.abs((qi - q + np.pi) % (2 * np.pi) - np.pi).max(axis=1)
                best = np.where(ok, np.minimum(best, d), best)
    assert best.max() < 1e-9


def test_tip_link_with_x_along_axis_6(tmp_path):
    """tool0 mounted as some descriptions do (rpy="3.1416 -1.5708 0": its x along the flange
    normal): the flange is put on axis 6, tool0 rides on it, FK of tool0 and of tools on it are
    the file's to 1e-9."""
    tool0 = (
        '<link name="tool0"/><joint name="link6-tool0" type="fixed"><parent link="link6"/>'
        '<child link="tool0"/><origin rpy="3.1416 -1.5708 0" xyz="0 0 0"/></joint>\n'
    )
    p = _exact(tmp_path, tool0)
    m = load_urdf(p)
    assert m.opw is not None, m.ik_note
    assert "not an OPW flange" in m.source
    # tool0's own rounded angles need no snapping: it is a constant on the flange, exact as written
    assert "snapped" not in m.source
    assert not np.allclose(m.T_flange_link, np.eye(4))
    meant = read_urdf_arm(p)
    q = _q(m)
    np.testing.assert_allclose(m.fk(q), chain_fk(meant.chain, q), atol=1e-9)
    T_tool = np.eye(4)
    T_tool[:3, 3] = [0.3, 0.0, 0.05]  # a tool along tool0's x (the flange normal)
    np.testing.assert_allclose(
        m.with_tool(T_tool).fk(q), chain_fk(meant.chain, q) @ T_tool, atol=1e-9
    )


def test_no_spherical_wrist_falls_back_with_the_reason(tmp_path):
    text = M0609.read_text().replace(
        '<origin rpy="-1.571 0 0" xyz="0 0 0"/>', '<origin rpy="-1.571 0 0" xyz="0.04 0 0"/>'
    )
    p = _exact(tmp_path, text=text)
    m = load_urdf(p)
    assert m.opw is None
    assert "closed-form IK not available" in m.ik_note and "no spherical wrist" in m.ik_note
    q0 = np.array([0.1, -0.3, 1.2, 0.2, 0.8, 0.1])
    T = m.fk(q0[None])[0]
    tips = T[:3, 3] + np.array([[0, 0, 0], [1e-3, 0, 0], [2e-3, 0, 0]])
    T_base_work = np.eye(4)
    T_base_work[:3, :3] = T[:3, :3] @ np.diag([1.0, -1.0, -1.0])  # tool z down = work −z
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            ik_toolpath(
                m, tips @ T_base_work[:3, :3], T_base_work, match_q=q0, singular_threshold=None
            )
        except InputError:
            pass  # reach does not matter here: the line is said before the solve
    lines = [str(w.message) for w in caught if issubclass(w.category, NumericalIKWarning)]
    assert lines and "no spherical wrist" in lines[0]


SEVEN = """<robot name="arm7">
<link name="base"/>{links}
<link name="hand"/><joint name="j7-hand" type="fixed"><parent link="l7"/><child link="hand"/>
<origin xyz="0 0 0.1"/></joint>
<link name="finger_l"/><joint name="finger_l" type="prismatic"><parent link="hand"/>
<child link="finger_l"/><axis xyz="0 1 0"/><limit lower="0" upper="0.04"/></joint>
<link name="finger_r"/><joint name="finger_r" type="prismatic"><parent link="hand"/>
<child link="finger_r"/><axis xyz="0 -1 0"/><limit lower="0" upper="0.04"/>
<mimic joint="finger_l"/></joint>
</robot>"""


def _seven(tmp_path: Path) -> Path:
    links, parent = "", "base"
    for i in range(1, 8):
        ax = "0 0 1" if i % 2 else "0 1 0"
        links += (
            f'\n<link name="l{i}"/><joint name="j{i}" type="revolute"><parent link="{parent}"/>'
            f'<child link="l{i}"/><origin xyz="0 0 0.2"/><axis xyz="{ax}"/>'
            '<limit lower="-2.9" upper="2.9"/></joint>'
        )
        parent = f"l{i}"
    p = tmp_path / "arm7.urdf"
    p.write_text(SEVEN.format(links=links))
    return p


def test_seven_joint_arm_is_refused_for_its_seven_joints(tmp_path):
    p = _seven(tmp_path)
    with pytest.raises(InputError) as e:
        load_urdf(p)
    assert "found 7" in e.value.message and "7-joint arm" in e.value.message
    assert "prismatic" not in e.value.message  # not the gripper's finger
    with pytest.raises(InputError, match=r"prismatic.*--tip-link"):
        load_urdf(p, "finger_l")


def test_cli_tip_link(tmp_path, capsys):
    from roboisf.cli.main import main

    tool0 = (
        '<link name="tool0"/><joint name="link6-tool0" type="fixed"><parent link="link6"/>'
        '<child link="tool0"/><origin rpy="0 0 0" xyz="0 0 0.1"/></joint>\n'
    )
    p = _exact(tmp_path, tool0)
    assert main(["robot", "show", "--robot", str(p), "--tip-link", "link6"]) == 0
    assert "tip link6" in capsys.readouterr().out
    assert main(["robot", "show", "--robot", str(p)]) == 0
    assert "tip tool0" in capsys.readouterr().out
    assert main(["-q", "robot", "show", "--robot", str(p), "--tip-link", "nolink"]) == 2
    assert "'nolink' not in URDF" in capsys.readouterr().err
    assert main(["-q", "robot", "show", "--robot", "irb7600-500-2.55", "--tip-link", "x"]) == 2
    assert "[--tip-link]" in capsys.readouterr().err


def test_against_pinocchio(tmp_path):
    """pinocchio (independent): the generic chain is the file as written; the snapped OPW model
    is the file with its angles in full."""
    pin = pytest.importorskip("pinocchio")

    def pin_fk(urdf: Path, q: np.ndarray) -> np.ndarray:
        m = pin.buildModelFromUrdf(str(urdf))
        d = m.createData()
        fid = m.getFrameId("link6")
        out = np.empty((len(q), 4, 4))
        for k, qk in enumerate(q):
            pin.framesForwardKinematics(m, d, qk)
            out[k] = d.oMf[fid].homogeneous
        return out

    snapped = load_urdf(M0609)
    q = _q(snapped, 300, seed=9)
    assert np.abs(load_urdf(M0609, opw=False).fk(q) - pin_fk(M0609, q)).max() < 1e-9
    assert np.abs(snapped.fk(q) - pin_fk(_exact(tmp_path), q)).max() < 1e-9
