"""``roboisf study init`` (issue #13, item 6): a study.toml drafted from the files of a folder.

The truth: a virtual-cell study folder whose study.toml is removed. Given what no file can say
(robot, placement, sensor poses, part, holder offset) as options, init must write a study that
``analyze`` runs to the same decomposition as the original study.toml.
"""

from __future__ import annotations

import shutil
import tomllib

import numpy as np
import pytest

from roboisf.cli.main import main
from roboisf.decompose.pipeline import analyze
from roboisf.errors import InputError
from roboisf.study.init import detect_files
from roboisf.virtual.cell import build_study, paper_cone_cell


@pytest.fixture(scope="module")
def virtual(tmp_path_factory):
    root = tmp_path_factory.mktemp("init")
    cell = paper_cone_cell(
        scan_points=150_000, force_rate=50.0, joint_rate=20.0, step_down=2e-3, spacing=4e-3
    )
    study = build_study(cell, root / "study")
    original = tomllib.loads((study / "study.toml").read_text())
    bare = root / "bare"
    shutil.copytree(study, bare)
    (bare / "study.toml").unlink()
    return study, bare, original


def _fresh(bare, tmp_path):
    d = tmp_path / "files"
    shutil.copytree(bare, d)
    return d


def test_detect_files_names_every_file(virtual, tmp_path):
    _, bare, _ = virtual
    d = _fresh(bare, tmp_path)
    (d / "notes.txt").write_text("operator: pressed stop at 14:02\n")
    kinds = {f.path.name: f.kind for f in detect_files(d)}
    assert kinds == {
        "cnc_forces.csv": "force_log",
        "robot_forces.csv": "force_log",
        "robot_joints.csv": "joint_log",
        "toolpath.csv": "toolpath",
        "cnc_scan.ply": "scan",
        "robot_scan.ply": "scan",
        "robot_thickness.csv": "thickness",
        "tool_compliance.json": "compliance",
        "holder_compliance.json": "compliance",
        "notes.txt": "unknown",
    }
    unknown = next(f for f in detect_files(d) if f.kind == "unknown")
    assert "toolpath" in unknown.problem  # says why the readers refused it


def test_draft_with_todo_keys_is_refused_by_name(virtual, tmp_path):
    _, bare, _ = virtual
    d = _fresh(bare, tmp_path)
    assert main(["-q", "study", "init", str(d)]) == 0
    text = (d / "study.toml").read_text()
    assert "TODO before `roboisf analyze`: part, robot.model, robot.placement" in text
    data = tomllib.loads(text)
    # detected: the files in their roles, the ball from the toolpath, position sync for the robot
    assert data["tool"]["ball_diameter"] == pytest.approx(10.0)
    assert data["runs"]["robot"]["joints"] == "robot_joints.csv"
    assert data["runs"]["robot"]["sync"] == "position" and data["runs"]["cnc"]["sync"] == "time"
    assert data["runs"]["cnc"]["forces"]["file"] == "cnc_forces.csv"
    assert data["runs"]["robot"]["scan"] == "robot_scan.ply"
    with pytest.raises(InputError, match=r"robot\.placement"):
        analyze(d)


def test_never_overwrites_a_study_toml(virtual, tmp_path):
    _, bare, _ = virtual
    d = _fresh(bare, tmp_path)
    (d / "study.toml").write_text("# mine\n")
    assert main(["-q", "study", "init", str(d)]) == 2
    assert (d / "study.toml").read_text() == "# mine\n"
    assert main(["-q", "study", "init", str(d), "--overwrite"]) == 0
    assert "drafted by `roboisf study init`" in (d / "study.toml").read_text()


def test_bad_folder_and_bad_pose_exit_2(tmp_path, capsys):
    assert main(["-q", "study", "init", str(tmp_path / "nowhere")]) == 2
    assert not (tmp_path / "nowhere").exists()
    assert main(["-q", "study", "init", str(tmp_path), "--placement", "1,2,3"]) == 2
    err = capsys.readouterr().err
    assert "[--placement]" in err and "6 comma-separated numbers" in err
    assert not (tmp_path / "study.toml").exists()


def _pose(values):
    return ",".join(f"{v:g}" for v in values)


@pytest.mark.slow
def test_init_study_analyzes_like_the_original(virtual, tmp_path):
    import tomli_w

    study, bare, original = virtual
    d = _fresh(bare, tmp_path)
    part = tmp_path / "cone.toml"
    part.write_text(tomli_w.dumps({"part": original["part"]}))
    rb, runs = original["robot"], original["runs"]
    args = ["-q", "study", "init", str(d), "--robot", rb["model"]]
    args += ["--placement", _pose(rb["placement"]), "--flange-to-tip", _pose(rb["flange_to_tip"])]
    args += ["--part", str(part), "--holder-offset", str(original["tool_holder"]["offset"])]
    args += ["--cnc-sensor-pose", _pose(runs["cnc"]["forces"]["pose"])]
    args += ["--robot-sensor-pose", _pose(runs["robot"]["forces"]["pose"])]
    assert main(args) == 0
    assert "TODO" not in (d / "study.toml").read_text()
    a, b = analyze(study), analyze(d)
    for table in ("contributions", "contributions_normal"):
        x = getattr(a, table).share_percent.to_numpy()
        y = getattr(b, table).share_percent.to_numpy()
        np.testing.assert_allclose(y, x, atol=1e-6)
