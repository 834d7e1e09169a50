"""CLI: roboisf toolpath / part / demo — outputs, formats, bad input (exit 2, no output file)."""

from __future__ import annotations

import math
import os
import stat

import numpy as np
import pytest

from roboisf.cam.gcode import read_gcode
from roboisf.cam.toolpath_csv import read_toolpath_csv
from roboisf.cli.main import main
from roboisf.parts import Cone, load_part
from roboisf.programs.fanuc import read_fanuc
from roboisf.programs.krl import read_krl
from roboisf.programs.rapid import read_rapid

SMALL_CONE = ["--opening-diameter", "60", "--wall-angle", "60", "--depth", "5", "--spacing", "3"]


def _run(argv, capsys=None):
    code = main(argv)
    if capsys is not None:
        return code, capsys.readouterr()
    return code


def test_paper_cone_csv(tmp_path):
    out = tmp_path / "path.csv"
    argv = [
        "toolpath",
        "cone",
        "--opening-diameter",
        "87",
        "--wall-angle",
        "71",
        "--depth",
        "102.97",
        "--step-down",
        "0.5",
        "--tool-diameter",
        "10",
        "--spacing",
        "4",
        "-o",
        str(out),
    ]
    assert main(argv) == 0
    tp = read_toolpath_csv(out)
    assert tp.n_laps == 206
    assert tp.tool_radius == pytest.approx(5e-3)
    assert tp.feed == pytest.approx(750e-3 / 60)
    assert tp.tip[:, 2].min() == pytest.approx(-102.97e-3, abs=1e-9)
    # atomic output is renamed from a private temp file: it must get the usual 0o666 & ~umask
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(os.stat(out).st_mode) == 0o666 & ~mask


ROBOT = ["--placement", "base", "--tool", "200"]


@pytest.mark.parametrize(
    ("name", "reader"),
    [
        ("p.nc", read_gcode),
        ("p.gcode", read_gcode),
        ("p.mod", read_rapid),
        ("p.src", read_krl),
        ("p.ls", read_fanuc),
    ],
)
def test_format_from_suffix(tmp_path, name, reader):
    out = tmp_path / name
    extra = [] if name.endswith(("nc", "gcode")) else ROBOT
    assert main(["toolpath", "cone", *SMALL_CONE, *extra, "-o", str(out)]) == 0
    back = reader(out)
    ref = main(["toolpath", "cone", *SMALL_CONE, "-o", str(tmp_path / "ref.csv")])
    assert ref == 0
    tp = read_toolpath_csv(tmp_path / "ref.csv")
    assert np.abs(back.tip - tp.tip).max() <= 0.5e-6 + 1e-12


def test_format_option_and_program_options(tmp_path):
    out = tmp_path / "prog.txt"
    argv = [
        "toolpath",
        "vwacf",
        "--spiral",
        "--spacing",
        "4",
        "--step-down",
        "1",
        "--format",
        "rapid",
        "--tool-length",
        "250",
        "--tool-rotation",
        "30",
        "--work-frame",
        "1500,100,800,90,0,0",
        "--feed",
        "1200",
        "-o",
        str(out),
    ]
    assert main(argv) == 0
    back = read_rapid(out)
    assert back.feed == pytest.approx(0.02)
    assert back.tool.length == pytest.approx(0.25)
    np.testing.assert_allclose(back.T_base_work[:3, 3], [1.5, 0.1, 0.8])
    np.testing.assert_allclose(back.T_base_work[:3, 0], [0, 1, 0], atol=1e-12)
    g = math.radians(30)
    np.testing.assert_allclose(
        back.R_work_tool[0] @ [1, 0, 0], [math.cos(g), -math.sin(g), 0], atol=1e-8
    )


def test_profile_and_part_files(tmp_path):
    prof = tmp_path / "data" / "profile.csv"
    prof.parent.mkdir()
    prof.write_text("r,z\n40,0\n35,-5\n30,-12\n28,-20\n")
    toml = tmp_path / "parts" / "p.toml"
    toml.parent.mkdir()
    assert main(["part", "profile", str(prof), "-o", str(toml)]) == 0
    assert 'file = "../data/profile.csv"' in toml.read_text()
    assert load_part(toml).depth == pytest.approx(20e-3)
    out = tmp_path / "from_toml.src"
    argv = ["toolpath", "--part", str(toml), "-o", str(out), "--spacing", "3", *ROBOT]
    assert main(argv) == 0
    assert out.is_file() and out.with_suffix(".dat").is_file()
    out2 = tmp_path / "direct.csv"
    assert main(["toolpath", "profile", str(prof), "-o", str(out2), "--spacing", "3"]) == 0
    a, b = read_krl(out), read_toolpath_csv(out2)
    assert np.abs(a.tip - b.tip).max() <= 0.5e-6 + 1e-12


def test_part_cone_round_trip(tmp_path):
    toml = tmp_path / "cone.toml"
    assert main(["part", "cone", "--wall-angle", "65", "--depth", "50", "-o", str(toml)]) == 0
    part = load_part(toml)
    ref = Cone(87e-3, math.radians(65.0), 50e-3).to_dict()
    assert part.to_dict() == pytest.approx(ref)
    assert main(["part", "vwacf", "--arc-radius", "30", "-o", str(tmp_path / "v.toml")]) == 0
    assert load_part(tmp_path / "v.toml").depth == pytest.approx(30e-3)


BAD_PROFILES = {
    "goes_up": "r,z\n40,0\n35,-5\n30,-3\n",
    "crosses_axis": "r,z\n40,0\n10,-10\n-2,-12\n",
    "empty": "",
    "malformed": "r,z\n40,0\n35,abc\n",
    "header_only": "r,z\n",
}


@pytest.mark.parametrize("kind", sorted(BAD_PROFILES))
def test_bad_profile_exit_2_no_output(tmp_path, capsys, kind):
    prof = tmp_path / "prof.csv"
    prof.write_text(BAD_PROFILES[kind])
    out = tmp_path / "out.csv"
    code, cap = _run(["toolpath", "profile", str(prof), "-o", str(out)], capsys)
    assert code == 2
    assert not out.exists()
    err = cap.err.strip()
    assert err.startswith("error:") and "prof.csv" in err and len(err.splitlines()) == 1
    code = main(["part", "profile", str(prof), "-o", str(tmp_path / "p.toml")])
    assert code == 2 and not (tmp_path / "p.toml").exists()


@pytest.mark.parametrize(
    ("args", "expect"),
    [
        (["cone", "--depth", "-5"], "[--depth]"),
        (["cone", "--depth", "0"], "[--depth]"),
        (["cone", "--opening-diameter", "0"], "[--opening-diameter]"),
        (["cone", "--wall-angle", "90"], "[--wall-angle]"),
        (["cone", "--wall-angle", "95"], "[--wall-angle]"),
        (["cone", "--depth", "10", "--step-down", "20"], "[--step-down]"),
        (["cone", "--tool-diameter", "0"], "--tool-diameter"),
        (["cone", "--step-down", "-0.5"], "--step-down"),
        (["cone", "--feed", "0"], "--feed"),
        (["cone", "--work-frame", "1,2,3"], "--work-frame"),
        (["cone", "--work-offset", "G92"], "--work-offset"),
        (["cone", "--format", "step"], "format"),
        # the generators' own checks name the option typed, not their SI parameter
        (["cone", "--spacing", "0.0001"], "[--step-down]"),
        (["cone", "--scallop-height", "9"], "[--scallop-height]"),
        (["vwacf", "--arc-radius", "100"], "[--arc-radius]"),
        (["vwacf", "--final-wall-angle", "120"], "[--final-wall-angle]"),
    ],
)
def test_bad_dimensions_exit_2_no_output(tmp_path, capsys, args, expect):
    out = tmp_path / "out.csv"
    code, cap = _run(["toolpath", *args, "-o", str(out)], capsys)
    assert code == 2, cap
    assert not out.exists()
    assert expect in cap.err and len(cap.err.strip().splitlines()) == 1


def test_bad_suffix_and_missing_part(tmp_path, capsys):
    code, cap = _run(["toolpath", "cone", "-o", str(tmp_path / "out.xyz")], capsys)
    assert code == 2 and "--format" in cap.err
    assert not (tmp_path / "out.xyz").exists()
    assert (
        main(["toolpath", "--part", str(tmp_path / "none.toml"), "-o", str(tmp_path / "o.csv")])
        == 2
    )
    assert not (tmp_path / "o.csv").exists()
    assert main(["part", "cone", "--depth", "-1", "-o", str(tmp_path / "c.toml")]) == 2
    assert not (tmp_path / "c.toml").exists()


def test_options_before_subcommand_are_not_ignored(tmp_path, capsys):
    out = tmp_path / "o.csv"
    code, cap = _run(["toolpath", "--step-down", "1", "cone", "-o", str(out)], capsys)
    assert code == 2 and "after the subcommand" in cap.err
    assert not out.exists()


def test_never_overwrites_input(tmp_path):
    prof = tmp_path / "profile.csv"
    text = "r,z\n40,0\n30,-10\n"
    prof.write_text(text)
    assert main(["toolpath", "profile", str(prof), "-o", str(prof)]) == 2
    assert prof.read_text() == text


@pytest.mark.parametrize("suffix", [".mod", ".src", ".ls"])
def test_robot_program_needs_placement_and_tool(tmp_path, capsys, suffix):
    """Never a silent robot-base frame or a made-up tool: exit 2 before generating."""
    out = tmp_path / f"p{suffix}"
    code, cap = _run(["toolpath", "cone", *SMALL_CONE, "--tool", "250", "-o", str(out)], capsys)
    assert code == 2 and "--placement" in cap.err and "base" in cap.err
    code, cap = _run(
        ["toolpath", "cone", *SMALL_CONE, "--placement", "1,2,3", "-o", str(out)], capsys
    )
    assert code == 2 and "--tool" in cap.err
    code, cap = _run(
        ["toolpath", "cone", "--placement", "1,2", "--tool", "9", "-o", str(out)], capsys
    )
    assert code == 2 and "x,y,z[,roll,pitch,yaw] (mm, deg), 'base' or a study" in cap.err
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("flag", ["--tool", "--tool-length"])
def test_robot_program_refuses_a_tool_length_in_m(tmp_path, capsys, flag):
    """--tool 0.306 (a 306 mm tool typed in m) wrote a RAPID program whose tooldata put the
    ball tip 0.306 mm below the flange; now one line naming the slip, exit 2, no program."""
    out = tmp_path / "p.mod"
    argv = ["toolpath", "cone", *SMALL_CONE, "--placement", "2200,0,200", flag, "0.306"]
    code, cap = _run([*argv, "-o", str(out)], capsys)
    assert code == 2 and f"[{flag}]" in cap.err
    assert "it is 306 mm if it was written in m" in cap.err
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("config", "said"),
    [("1,2,3", "expected 2 (KUKA S,T), 4 (ABB"), ("0,0,0,0", "--arm-config needs a robot")],
)
def test_arm_config_is_never_dropped_without_a_word(tmp_path, capsys, config, said):
    """Without a robot --arm-config was ignored, even when malformed: a program was written
    with the default branch's confdata [0,0,0,0] and checks off, as if none had been asked."""
    out = tmp_path / "p.mod"
    argv = ["toolpath", "cone", *SMALL_CONE, "--placement", "2200,0,200", "--tool", "306"]
    code, cap = _run([*argv, "--arm-config", config, "-o", str(out)], capsys)
    assert code == 2 and "[--arm-config]" in cap.err and said in cap.err
    assert not list(tmp_path.iterdir())


def test_placement_tool_and_robot_flags(tmp_path):
    """--placement X,Y,Z,RX,RY,RZ (R = Rz Ry Rx as study.toml), --tool, --robot → confdata of the
    IK branch; --placement base is the identity, said explicitly."""
    from roboisf.frames.rotations import rpy_to_matrix
    from roboisf.frames.se3 import make_transform
    from roboisf.robot.armconfig import abb_confdata, program_config
    from roboisf.robot.presets import load_robot

    out = tmp_path / "cell.mod"
    argv = ["toolpath", "cone", *SMALL_CONE, "--placement", "2200,0,200,0,0,10", "--tool", "306"]
    assert main([*argv, "--robot", "irb7600-500-2.55", "-o", str(out)]) == 0
    back = read_rapid(out)
    T = np.eye(4)
    T[:3, :3] = rpy_to_matrix(np.radians([0, 0, 10]))
    T[:3, 3] = [2.2, 0, 0.2]
    np.testing.assert_allclose(back.T_base_work, T, atol=1e-9)
    assert back.tool.length == pytest.approx(0.306)
    model = load_robot("irb7600-500-2.55").with_tool(make_transform(p=[0, 0, 0.306]))
    tp = read_toolpath_csv(_csv(tmp_path))
    cfg = program_config(model, tp, T)
    np.testing.assert_array_equal(back.meta["confdata"], abb_confdata(cfg))
    assert "ConfJ\\On" in out.read_text()
    base = tmp_path / "base.src"
    assert main(["toolpath", "cone", *SMALL_CONE, *ROBOT, "-o", str(base)]) == 0
    np.testing.assert_allclose(read_krl(base).T_base_work, np.eye(4), atol=1e-12)


def _csv(tmp_path):
    ref = tmp_path / "ref.csv"
    assert main(["toolpath", "cone", *SMALL_CONE, "-o", str(ref)]) == 0
    return ref


@pytest.mark.parametrize("name", ["next-part.src", "2nd.mod", "my part.ls"])
def test_program_name_refused_before_generation(tmp_path, capsys, name):
    """KRL DEF/DEFDAT, RAPID module and FANUC program are named after the file: an invalid name is
    refused with the name to use, never cut or renamed silently."""
    out = tmp_path / name
    code, cap = _run(["toolpath", "cone", *SMALL_CONE, *ROBOT, "-o", str(out)], capsys)
    assert code == 2 and "name" in cap.err and len(cap.err.strip().splitlines()) == 1
    assert not list(tmp_path.iterdir())


def test_frames_and_robot_from_a_study(tmp_path):
    """--placement STUDY / --tool STUDY: the study's [robot] placement, flange_to_tip and robot
    (for the S/T of the first PTP)."""
    from roboisf.study.spec import load_study
    from roboisf.virtual.cell import build_study, paper_cone_cell

    st = tmp_path / "study"
    build_study(
        paper_cone_cell(spacing=6e-3, scan_points=20000, force_rate=50.0, joint_rate=50.0), st
    )
    robot = load_study(st).robot
    out = tmp_path / "cell.src"
    argv = ["toolpath", "cone", *SMALL_CONE, "--placement", str(st), "--tool", str(st)]
    assert main([*argv, "-o", str(out)]) == 0
    back = read_krl(out)
    np.testing.assert_allclose(back.T_base_work, robot.T_base_work, atol=1e-8)
    assert back.tool.length == pytest.approx(robot.T_flange_tip[2, 3])
    assert back.meta["status_turn"] is not None  # the study's robot gave the IK branch


def test_gcode_work_offset_flag(tmp_path):
    out = tmp_path / "p.nc"
    assert main(["toolpath", "cone", *SMALL_CONE, "--work-offset", "G56", "-o", str(out)]) == 0
    back = read_gcode(out)
    assert back.meta["work_offsets"] == ["G56"] and back.meta["length_compensation"] == [1]
