"""issue #28: when position alignment fails on a CAM program read with the wrong point (ball
centres read as tips), the error carries the importer's own warning, not only the placement."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.logs.jointlog import JointLog
from roboisf.parts import Cone
from roboisf.sync.run import align_run
from roboisf.toolpath import step_down
from roboisf.toolpath.importer import ImportOptions, import_toolpath


def _setup(tmp_path, point):
    cone = Cone(depth=8e-3)
    tp = step_down(cone, 5e-3, 1e-3, spacing=2e-3)
    body = "".join(f"G1 X{x:.4f} Y{y:.4f} Z{z:.4f}\n" for x, y, z in tp.center * 1e3)
    f = tmp_path / "c.nc"
    f.write_text("G90 G21\nG0 X0 Y0 Z20\nG1 F900\n" + body)
    imported = import_toolpath(f, cone, 5e-3, ImportOptions(point=point))
    # a "robot" whose forward kinematics is the identity on the first three joints: the logged
    # tip follows the true tips of the path
    robot = SimpleNamespace(tip_positions=lambda q, check_limits, T_base_work: q[:, :3])
    cell = SimpleNamespace(robot=robot, T_base_work=np.eye(4), tool_rotation=0.0)
    t = np.arange(len(tp)) * 0.1
    q = np.hstack([tp.tip, np.zeros((len(tp), 3))])
    joints = JointLog(t, q, tmp_path / "j.csv")
    run = SimpleNamespace(
        name="robot", sync="position", forces=SimpleNamespace(file=tmp_path / "f.csv")
    )
    return cell, run, imported, joints


def test_wrong_point_error_shows_the_import_warning(tmp_path):
    cell, run, tp, joints = _setup(tmp_path, "tip")
    with pytest.raises(InputError) as e:
        align_run(cell, run, tp, None, joints)  # type: ignore[arg-type]
    msg = e.value.message
    assert "does the program name the center?" in msg
    assert 'runs.robot.toolpath_point = "center"' in msg
    assert e.value.file is not None and e.value.file.endswith("j.csv")


def test_right_point_aligns(tmp_path):
    cell, run, tp, joints = _setup(tmp_path, "center")
    run.forces.clock = "joint"
    run.forces.time_offset = 0.0
    force_log = SimpleNamespace(time=joints.time)
    a = align_run(cell, run, tp, force_log, joints)  # type: ignore[arg-type]
    assert a.forces.residual.max() < 1e-6
