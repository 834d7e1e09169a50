"""study.toml keys of logs: format, columns, units, tare, tool mass/CoG, joints as a table."""

from __future__ import annotations

import pytest

from roboisf.study import StudyError, load_study

HEAD = """
[part]
kind = "cone"
opening_diameter = 87
wall_angle = 71
depth = 50
sheet_thickness = 1.22
[tool]
ball_diameter = 10
free_length = 60
[runs.cnc]
machine = "cnc"
toolpath = "tp.csv"
scan = "s.ply"
[runs.cnc.forces]
file = "f.csv"
pose = [0, 0, -60, 0, 0, 0]
{cnc}
[runs.robot]
machine = "robot"
toolpath = "tp.csv"
scan = "s.ply"
{joints}
[runs.robot.forces]
file = "f.csv"
pose = [0, 0, -190, 180, 0, 0]
{rob}
"""


def _study(tmp_path, cnc="", rob="", joints='joints = "j.csv"'):
    for f in ("tp.csv", "s.ply", "f.csv", "j.csv"):
        (tmp_path / f).write_text("x")
    (tmp_path / "study.toml").write_text(HEAD.format(cnc=cnc, rob=rob, joints=joints))
    return tmp_path


def test_log_keys_parsed(tmp_path):
    s = _study(
        tmp_path,
        cnc='columns = {time = "Zeit [s]", Fx = "Kraft X", Fy = "Kraft Y", Fz = "Kraft Z"}',
        rob='format = "ati"\nunits = {force = "lbf", moment = "lbf-in"}\ntare = [0.5, 1.5]\n'
        "tool_mass = 4.2\ntool_cog = [12, -8, 95]",
        joints='[runs.robot.joints]\nfile = "j.csv"\nformat = "kuka"\n'
        'units = {time = "ms", angle = "deg"}',
    )
    st = load_study(s)
    f = st.robot_run.forces
    assert f.format == "ati" and f.units == {"force": "lbf", "moment": "lbf-in"}
    assert f.tare == (0.5, 1.5) and f.tool_mass == 4.2
    assert f.tool_cog == pytest.approx((0.012, -0.008, 0.095))
    c = st.cnc.forces
    assert c.format == "columns" and c.columns is not None and c.columns["Fx"] == "Kraft X"
    r = st.robot_run
    assert r.joints is not None and r.joints.name == "j.csv"
    assert r.joints_format == "kuka" and r.joints_units == {"time": "ms", "angle": "deg"}


@pytest.mark.parametrize(
    ("cnc", "rob", "key", "msg"),
    [
        ("", 'tare = "sometimes"', "runs.robot.forces.tare", 'expected "none", "auto"'),
        ("", "tare = [2, 1]", "runs.robot.forces.tare", "t1 > t0"),
        ("tool_mass = 3\ntool_cog = [0, 0, 50]", "", "runs.cnc.forces.tool_mass", "flange"),
        ("", "tool_mass = 3", "runs.robot.forces", "give both tool_mass"),
        ("", 'format = "ati"\ncolumns = {time = "t"}', "runs.robot.forces.format", "conflicts"),
        ("", 'units = {force = "furlong"}', "runs.robot.forces.units.force", "unknown force unit"),
        ("", 'format = "csv"', "runs.robot.forces.format", "expected one of auto"),
        ("", 'units = {mass = "kg"}', "runs.robot.forces.units.mass", "unknown quantity"),
    ],
)
def test_bad_log_keys_name_the_key(tmp_path, cnc, rob, key, msg):
    s = _study(tmp_path, cnc=cnc, rob=rob)
    with pytest.raises(StudyError) as ei:
        load_study(s)
    hits = [p for p in ei.value.problems if p.field == key]
    assert hits, [str(p) for p in ei.value.problems]
    assert msg in hits[0].message


def test_joints_table_needs_a_file(tmp_path):
    s = _study(tmp_path, joints='[runs.robot.joints]\nformat = "abb"')
    with pytest.raises(StudyError, match=r"runs\.robot\.joints\.file"):
        load_study(s)
