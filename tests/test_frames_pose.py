"""One pose parser and formatter (``roboisf.frames.pose``): each convention by hand, round trips,
and one-line errors naming the field, file and the numbers expected."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from roboisf.errors import InputError
from roboisf.frames import abc_to_matrix, rot_x, rot_y, rot_z
from roboisf.frames.pose import (
    XYZ_ABC_MM_DEG,
    XYZ_MM,
    XYZ_RPY_M_DEG,
    XYZ_RPY_MM_DEG,
    XYZ_YAW_MM_DEG,
    PoseFormat,
    format_pose,
    parse_pose,
    pose_numbers,
)


def test_rpy_in_mm_and_deg_by_hand():
    T = parse_pose([100, -20, 5, 10, 20, 30], field="placement")
    R = rot_z(math.radians(30)) @ rot_y(math.radians(20)) @ rot_x(math.radians(10))
    np.testing.assert_allclose(T[:3, :3], R, atol=1e-15)
    np.testing.assert_allclose(T[:3, 3], [0.1, -0.02, 0.005], atol=1e-15)
    np.testing.assert_array_equal(T[3], [0, 0, 0, 1])


def test_each_convention_and_unit_by_hand():
    yaw = parse_pose("1000,0,500,90", XYZ_YAW_MM_DEG, field="--placement")
    np.testing.assert_allclose(yaw[:3, :3] @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(yaw[:3, 3], [1.0, 0.0, 0.5])
    # KUKA A, B, C = yaw, pitch, roll: the same frame as rpy in reverse order
    abc = parse_pose("0,0,0,30,20,10", XYZ_ABC_MM_DEG, field="--work-frame")
    rpy = parse_pose("0,0,0,10,20,30", field="--placement")
    np.testing.assert_allclose(abc, rpy, atol=1e-15)
    np.testing.assert_allclose(abc[:3, :3], abc_to_matrix(np.radians([30, 20, 10])))
    metres = parse_pose([0.1, 0.2, 0.3, 0, 0, 90], XYZ_RPY_M_DEG, field="tool")
    np.testing.assert_allclose(metres[:3, 3], [0.1, 0.2, 0.3])
    radians = parse_pose([0, 0, 0, 0, 0, math.pi / 2], PoseFormat("rpy", "mm", "rad"), field="f")
    np.testing.assert_allclose(radians[:3, :3], metres[:3, :3], atol=1e-15)
    tool = parse_pose("0,0,250", XYZ_MM, field="--tool")
    np.testing.assert_array_equal(
        tool, np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.25], [0, 0, 0, 1]])
    )
    # position only where the caller allows it: unrotated
    np.testing.assert_array_equal(
        parse_pose("1,2,3", field="--placement", position_only=True)[:3, :3], np.eye(3)
    )


angles = st.floats(-179.0, 179.0)
lengths = st.floats(-5000.0, 5000.0)


@settings(max_examples=200, deadline=None)
@given(
    xyz=st.tuples(lengths, lengths, lengths),
    a=st.tuples(angles, st.floats(-89.0, 89.0), angles),
    fmt=st.sampled_from([XYZ_RPY_MM_DEG, XYZ_ABC_MM_DEG, XYZ_RPY_M_DEG]),
)
def test_format_then_parse_gives_the_pose_back(xyz, a, fmt):
    T = parse_pose([*xyz, *a], fmt, field="pose")
    back = parse_pose(format_pose(T, fmt), fmt, field="pose")
    np.testing.assert_allclose(back[:3, :3], T[:3, :3], atol=1e-9)
    np.testing.assert_allclose(back[:3, 3], T[:3, 3], atol=1e-9 * (1e3 if fmt.length == "m" else 1))
    # the numbers themselves come back (pitch / B inside ±90°)
    np.testing.assert_allclose(format_pose(T, fmt), [*xyz, *a], atol=1e-6)


@settings(max_examples=50, deadline=None)
@given(xyz=st.tuples(lengths, lengths, lengths), yaw=angles)
def test_yaw_round_trip_and_a_tilted_frame_is_not_a_yaw_pose(xyz, yaw):
    T = parse_pose([*xyz, yaw], XYZ_YAW_MM_DEG, field="p")
    np.testing.assert_allclose(format_pose(T, XYZ_YAW_MM_DEG), [*xyz, yaw], atol=1e-6)
    with pytest.raises(ValueError, match="cannot say this rotation"):
        format_pose(T @ parse_pose([0, 0, 0, 5, 0, 0], field="p"), XYZ_YAW_MM_DEG)


def test_format_writes_what_study_toml_held_before():
    # the virtual cell wrote [x, y, z, roll, pitch, yaw] as round(mm, 9), round(deg, 9)
    T = parse_pose([2200.123456789, -500, 200, 0.5, -1.25, 30], field="p")
    assert format_pose(T) == [2200.123456789, -500.0, 200.0, 0.5, -1.25, 30.0]


@pytest.mark.parametrize(
    ("values", "fmt", "kw", "message"),
    [
        ("1,2", XYZ_RPY_MM_DEG, {}, "6 comma-separated numbers x,y,z,roll,pitch,yaw (mm, deg)"),
        ("1,2,x,4", XYZ_YAW_MM_DEG, {}, "4 comma-separated numbers x,y,z,yaw (mm, deg)"),
        ("1,2,3,4", XYZ_RPY_MM_DEG, {"position_only": True}, "3 or 6 comma-separated numbers"),
        ("1,2,nan", XYZ_MM, {}, "3 comma-separated numbers x,y,z (mm), got '1,2,nan'"),
        ([1, 2, 3, 4, 5, True], XYZ_RPY_MM_DEG, {}, "[x, y, z, roll, pitch, yaw] in mm and deg"),
        ([1, 2, 3, 4, 5, math.inf], XYZ_RPY_MM_DEG, {}, "(6 finite numbers)"),
        ("1,2,3,4,5,6", XYZ_RPY_MM_DEG, {"strings": False}, "(6 finite numbers), got '1,2,3"),
        ({"x": 1}, XYZ_ABC_MM_DEG, {}, "[x, y, z, A, B, C] in mm and deg"),
        ("1", XYZ_RPY_MM_DEG, {"alternatives": "'base' or a study"}, "'base' or a study, got"),
    ],
)
def test_a_bad_pose_is_one_line_naming_field_file_and_what_was_expected(values, fmt, kw, message):
    with pytest.raises(InputError) as e:
        pose_numbers(values, fmt, field="robot.placement", file="study.toml", **kw)
    text = str(e.value)
    assert text.startswith("study.toml [robot.placement]: expected ") and "\n" not in text
    assert message in text


def test_study_toml_poses_use_the_parser():
    from roboisf.study.spec import pose_to_transform

    T = pose_to_transform([1, 2, 3, 4, 5, 6], field="robot.placement")
    np.testing.assert_array_equal(T, parse_pose([1, 2, 3, 4, 5, 6], field="p"))
    with pytest.raises(InputError, match=r"\[robot\.placement\]: expected \[x, y, z, roll"):
        pose_to_transform("1,2,3,4,5,6", field="robot.placement")  # a TOML string: no


def test_no_module_converts_pose_angles_by_itself():
    # a pose's degrees become a rotation in frames/pose.py only; the controllers' program
    # formats (programs/) and KUKA RSI's messages (online/rsi.py, per 4 ms cycle) read their
    # own pose syntax (E6POS, FANUC P[], <RSol X= … C=>) and stay out
    import re
    from pathlib import Path

    src = Path(__file__).resolve().parents[1] / "src" / "roboisf"
    pattern = re.compile(r"(rpy_to_matrix|abc_to_matrix|rot_z)\((np|math)\.radians\(")
    found = [
        f"{p.relative_to(src)}:{i}"
        for p in sorted(src.rglob("*.py"))
        if p.parent.name not in ("frames", "programs") and p.name != "rsi.py"
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
        if pattern.search(line)
    ]
    assert not found, "pose angles converted outside roboisf.frames.pose: " + ", ".join(found)


def test_draft_study_checks_the_poses_it_is_given(tmp_path):
    # the Python API of `study init` takes poses as lists (mm, deg): checked by the one parser
    from roboisf.study.init import draft_study

    with pytest.raises(InputError, match=r"\[placement\]: expected \[x, y, z, roll, pitch, yaw\]"):
        draft_study(tmp_path, [], placement=[1.0, 2.0, 3.0])
    with pytest.raises(InputError, match=r"\[robot_sensor_pose\].*got \[0, 0, 0, 0, 0, nan\]"):
        draft_study(tmp_path, [], robot_sensor_pose=[0, 0, 0, 0, 0, math.nan])
    draft = draft_study(tmp_path, [], placement=[2200, 0, 300, 0, 0, 90])
    assert draft.data["robot"]["placement"] == [2200.0, 0.0, 300.0, 0.0, 0.0, 90.0]
