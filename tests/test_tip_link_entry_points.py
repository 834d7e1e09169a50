"""``--tip-link`` wherever a robot is named (issue #28): ``toolpath --robot``, ``plan --part``,
``study init`` and a study's ``[robot] tip_link``.

The robot: Doosan's M0609 (``tests/data/urdf/m0609.urdf``, see the README there) with a 7th
revolute joint behind ``link6``. Without a tip link it is refused as a 7-joint arm; with
``link6`` named it is the 6-joint M0609. So each entry point is checked both ways: the named
link reaches the model (the arm loads, tip ``link6``), and a link that does not exist is
refused in one line naming it — neither can pass if the value is dropped on the way.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from roboisf.cli.main import main
from roboisf.errors import InputError
from roboisf.study.spec import StudyError

M0609 = Path(__file__).parent / "data" / "urdf" / "m0609.urdf"
JOINT7 = (
    '<link name="link7"/><joint name="joint7" type="revolute"><parent link="link6"/>'
    '<child link="link7"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>'
    '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>\n'
)
SMALL_CONE = ["--opening-diameter", "60", "--wall-angle", "60", "--depth", "5", "--spacing", "3"]


def _arm7(folder: Path) -> Path:
    p = folder / "arm7.urdf"
    p.write_text(M0609.read_text().replace("</robot>", JOINT7 + "</robot>"))
    return p


def _err(capsys) -> str:
    return capsys.readouterr().err.replace("\n", " ")


def test_the_robot_needs_its_tip_link(tmp_path):
    from roboisf.robot import load_robot

    p = _arm7(tmp_path)
    with pytest.raises(InputError, match="found 7"):
        load_robot(p)
    assert "tip link6" in load_robot(p, tip_link="link6").source


def test_toolpath_robot_program(tmp_path, capsys):
    """A RAPID program with --robot URDF: IK along the path needs the 6-joint arm."""
    from roboisf.cli.toolpath import PathOptions

    p = _arm7(tmp_path)
    m = PathOptions(robot=str(p), tip_link="link6").robot_model()
    assert m is not None and "tip link6" in m.source
    argv = ["-q", "toolpath", "cone", *SMALL_CONE, "--placement", "500,0,300", "--tool", "150"]
    argv += ["--tool-rotation", "90", "--robot", str(p)]
    out = tmp_path / "cell.mod"
    assert main([*argv, "-o", str(out)]) == 2
    assert "found 7" in _err(capsys)
    assert not out.exists()
    assert main([*argv, "--tip-link", "link6", "-o", str(out)]) == 0
    assert "confdata from the joint angles of the IK branch" in out.read_text()
    out.unlink()
    assert main([*argv, "--tip-link", "nolink", "-o", str(out)]) == 2
    err = _err(capsys)
    assert "arm7.urdf" in err and "'nolink' not in URDF" in err
    assert not out.exists()
    # without a robot there is nothing for the link to name
    argv = ["-q", "toolpath", "cone", *SMALL_CONE, "--placement", "500,0,300", "--tool", "150"]
    assert main([*argv, "--tip-link", "link6", "-o", str(out)]) == 2
    assert "[--tip-link]" in _err(capsys)


def test_plan_part(tmp_path, capsys):
    from roboisf.cell import ForceModel, make_cell
    from roboisf.parts import Cone

    p = _arm7(tmp_path)
    cone = Cone(60e-3, np.radians(60.0), 5e-3)
    T = np.eye(4)
    T[:3, 3] = [0.5, 0.0, 0.3]
    c = make_cell(cone, robot=str(p), T_base_work=T, force=ForceModel(), tip_link="link6")
    assert "tip link6" in c.robot.source and c.tip_link == "link6"
    part = tmp_path / "cone.toml"
    part.write_text('[part]\nkind = "cone"\nopening_diameter = 60\nwall_angle = 60\ndepth = 5\n')
    argv = ["-q", "plan", "--part", str(part), "--robot", str(p)]
    assert main([*argv, "--tip-link", "nolink", "-o", str(tmp_path / "a")]) == 2
    err = _err(capsys)
    assert "'nolink' not in URDF" in err
    assert main([*argv, "-o", str(tmp_path / "b")]) == 2
    assert "found 7" in _err(capsys)


STUDY = """[study]
name = "t"
[part]
kind = "cone"
opening_diameter = 60
wall_angle = 60
depth = 5
[tool]
ball_diameter = 10
free_length = 66
[tool_holder]
rigid = true
[robot]
model = "arm7.urdf"
placement = [500, 0, 300, 0, 0, 0]
{tip}
[runs.cnc]
machine = "cnc"
toolpath = "path.csv"
scan = "cnc.ply"
forces = {{ file = "cnc_f.csv", mount = "fixture", pose = [0, 0, -60, 0, 0, 0] }}
[runs.robot]
machine = "robot"
toolpath = "path.csv"
scan = "robot.ply"
forces = {{ file = "rob_f.csv", mount = "flange", pose = [0, 0, -190, 180, 0, 0] }}
"""


def _study(root: Path, tip: str) -> Path:
    root.mkdir()
    _arm7(root)
    for f in ("path.csv", "cnc.ply", "robot.ply", "cnc_f.csv", "rob_f.csv"):
        (root / f).write_text("x")
    (root / "study.toml").write_text(STUDY.format(tip=tip))
    return root


def test_study_robot_tip_link(tmp_path):
    from roboisf.cell import cell_from_study
    from roboisf.cli.toolpath import PathOptions
    from roboisf.study.spec import load_study

    s = load_study(_study(tmp_path / "a", 'tip_link = "link6"'))
    assert s.robot is not None and s.robot.tip_link == "link6"
    c = cell_from_study(s)
    assert "tip link6" in c.robot.source and c.tip_link == "link6"
    # toolpath --placement STUDY takes the study's robot with its tip link
    m = PathOptions(placement_=str(s.root)).robot_model()
    assert m is not None and "tip link6" in m.source
    with pytest.raises(StudyError) as e:
        load_study(_study(tmp_path / "b", 'tip_link = "nolink"'))
    assert "[robot.tip_link]" in str(e.value) and "'nolink' not in URDF" in str(e.value)
    with pytest.raises(StudyError, match=r"\[robot\.tip_link\].*expected the name of a link"):
        load_study(_study(tmp_path / "c", "tip_link = 6"))
    with pytest.raises(StudyError, match=r"\[robot\.model\].*found 7"):
        load_study(_study(tmp_path / "d", ""))


def test_study_init_writes_the_tip_link(tmp_path, capsys):
    d = tmp_path / "cell"
    d.mkdir()
    p = _arm7(tmp_path)
    base = ["-q", "study", "init", str(d), "--robot", str(p)]
    assert main([*base, "--tip-link", "link6"]) == 0
    data = tomllib.loads((d / "study.toml").read_text())
    assert data["robot"]["tip_link"] == "link6"
    (d / "study.toml").unlink()
    assert main([*base, "--tip-link", "nolink"]) == 2
    err = _err(capsys)
    assert "[--tip-link]" in err and "'nolink' not in URDF" in err
    assert not (d / "study.toml").exists()
    assert main(["-q", "study", "init", str(d), "--tip-link", "link6"]) == 2
    assert "give --robot" in _err(capsys)
