"""``roboisf robot …``: list, show (+PNG), identify, deflect (IK and joint log), bad input."""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.cam.toolpath_csv import write_toolpath_csv
from roboisf.cli.main import main
from roboisf.frames import make_transform
from roboisf.io.table import read_table
from roboisf.logs.forcelog import ForceLog, write_force_log
from roboisf.logs.jointlog import read_joint_log, write_joint_log
from roboisf.parts import Cone
from roboisf.robot import ik_toolpath, load_robot, rotate_6
from roboisf.toolpath import step_down


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    d = tmp_path_factory.mktemp("cell")
    tp = step_down(Cone(), step_down=5e-3)  # coarse: fast
    write_toolpath_csv(tp, d / "path.csv")
    n = len(tp)
    t = np.linspace(tp.time[0] - 1, tp.time[-1] + 1, 400)
    W = np.zeros((t.size, 6))
    W[:, 0], W[:, 1], W[:, 2] = 120.0, -80.0, 450.0
    write_force_log(ForceLog(time=t, wrench=W, frame="work", path=None), d / "forces.csv")
    return d, tp, n


def _deflect(d, out, *extra):
    return [
        "robot", "deflect", "--toolpath", str(d / "path.csv"), "--forces", str(d / "forces.csv"),
        "-o", str(out), *extra,
    ]  # fmt: skip


def _read_deflection(path):
    t = read_table(path, ["index", "time", "dx", "dy", "dz"], allow_extra=True)
    return np.stack([t.column(c) for c in ("dx", "dy", "dz")], axis=1) * 1e-3


def test_list_and_show(tmp_path, capsys):
    assert main(["robot", "list"]) == 0
    assert "kr210-r2700-2" in capsys.readouterr().out
    png = tmp_path / "map.png"
    assert (
        main(
            ["robot", "show", "--robot", "irb7600-500-2.55", "-o", str(png), "--half-width", "300"]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "A2: limits [  -60.0,    85.0]" in out and "3.73e+06" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("name", ["map.jpg", "map.pdf", "map"])
def test_show_refuses_a_map_name_that_is_not_png(tmp_path, capsys, name):
    """The map is PNG data: a .jpg name would hold a PNG (``file`` says PNG)."""
    out = tmp_path / name
    assert main(["-q", "robot", "show", "--robot", "irb7600-500-2.55", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "[--output]" in err and "expected a .png" in err, err
    assert name in err and not out.exists()


def test_deflect_by_ik_matches_library(cell, tmp_path):
    d, tp, n = cell
    out = tmp_path / "defl.csv"
    rc = main(
        _deflect(
            d,
            out,
            "--robot",
            "irb7600-500-2.55",
            "--placement",
            "1600,0,800,0",
            "--tool",
            "0,0,300",
        )
    )
    assert rc == 0
    m = load_robot("irb7600-500-2.55").with_tool(make_transform(None, [0, 0, 0.3]))
    T = make_transform(None, [1.6, 0, 0.8])
    q = ik_toolpath(m, tp, T).q
    W = np.tile([120.0, -80.0, 450.0, 0, 0, 0], (n, 1))
    ref = m.deflection(q, rotate_6(W, T[:3, :3]))[:, :3]
    got = _read_deflection(out)
    np.testing.assert_allclose(got, ref, atol=2e-12)
    assert 1e-5 < np.abs(ref).max() < 5e-3  # tenths of a mm, as the paper


def test_deflect_with_joint_log(cell, tmp_path):
    d, tp, n = cell
    m = load_robot("irb7600-500-2.55").with_tool(make_transform(None, [0, 0, 0.3]))
    q = ik_toolpath(m, tp, make_transform(None, [1.6, 0, 0.8])).q
    write_joint_log(d / "joints.csv", tp.time, q)
    jl = read_joint_log(d / "joints.csv")
    np.testing.assert_allclose(jl.q, q, atol=1e-10)
    out = tmp_path / "defl.csv"
    args = [*_deflect(d, out, "--tool", "0,0,300"), "--joints", str(d / "joints.csv")]
    assert main(args) == 0
    assert _read_deflection(out).shape == (n, 3)


def test_deflect_bad_input(cell, tmp_path, capsys):
    d, _tp, _n = cell
    out = tmp_path / "x.csv"
    base = _deflect(d, out)
    assert main([*base, "--robot", "nope"]) == 2
    assert "irb7600-500-2.55" in capsys.readouterr().err
    assert main([*base, "--robot", "kr210-r2700-2"]) == 2  # no stiffness
    assert "stiffness" in capsys.readouterr().err
    assert main([*base, "--placement", "5000,0,800,0"]) == 2  # out of reach
    assert "out of reach" in capsys.readouterr().err
    assert main([*base, "--placement", "1,2"]) == 2
    assert not out.exists()
    bad = d / "badjoints.csv"
    bad.write_text("# units: time=s angle=deg\ntime,q1,q2,q3,q4,q5,q6\n0,0,0,0,0,0\n")
    assert main([*base, "--joints", str(bad)]) == 2
    assert "badjoints.csv:3" in capsys.readouterr().err
    assert not out.exists()


def test_a_placement_typed_in_m_names_the_slip(cell, tmp_path, capsys):
    """``--placement 2.2,0,0.5,0`` (2200,0,500 in m) put the part 2.3 mm from the robot base and
    was refused only as 'beyond the joint limits'; the error now names --placement, the value
    and the m-for-mm slip (deflect, and show's stiffness map). A placement at a real cell's
    distance that the robot cannot reach keeps its own reason, no slip guessed."""
    d, _tp, _n = cell
    out = tmp_path / "x.csv"
    base = _deflect(d, out, "--tool", "0,0,300")
    assert main([*base, "--placement", "2.2,0,0.5,0"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for needle in ("[--placement]", "beyond the limits", "--placement 2.2,0,0.5,0",
                   "if it was written in m", "2200,0,500 mm"):  # fmt: skip
        assert needle in err, err
    assert main([*base, "--placement", "5000,0,800,0"]) == 2
    err = capsys.readouterr().err
    assert "out of reach" in err and "written in" not in err, err
    png = tmp_path / "map.png"
    assert main(["robot", "show", "--placement", "1.6,0,0.8,0", "-o", str(png)]) == 2
    err = capsys.readouterr().err
    assert "[--placement]" in err and "1600,0,800 mm" in err, err
    assert not out.exists() and not png.exists()


def test_deflect_says_the_start_joints_back_in_degrees(cell, tmp_path, capsys):
    """--start-joints is degrees; typed in radians (0.26 for 15°) it was taken without a word
    as a pose near the zero pose. It cannot be told from one, so the run says the start back in
    degrees with the first point's joints: a slip shows as a start far from where the path
    begins."""
    d, tp, _n = cell
    m = load_robot("irb7600-500-2.55").with_tool(make_transform(None, [0, 0, 0.3]))
    q0 = np.degrees(ik_toolpath(m, tp, make_transform(None, [1.6, 0, 0.8])).q[0])
    start = ",".join(f"{v:.1f}" for v in q0)
    out = tmp_path / "s.csv"
    args = _deflect(d, out, "--placement", "1600,0,800,0", "--tool", "0,0,300")
    assert main([*args, "--start-joints", start]) == 0
    said = capsys.readouterr().out
    line = next(x for x in said.splitlines() if "--start-joints" in x)
    given = line.split("--start-joints ")[1].split(" deg (degrees")[0]
    first = line.split("the first point at ")[1].removesuffix(" deg")
    np.testing.assert_allclose([float(v) for v in given.split(", ")], np.round(q0, 1))
    np.testing.assert_allclose([float(v) for v in first.split(", ")], q0, atol=0.006)


def _translations_sheet(tmp_path):
    """(robot, path) of a calibration sheet of 30 poses with translations only (mm, N, N·m,
    deg), the IRB 7600's deflections under random loads plus 2 µm of gauge noise."""
    m = load_robot("irb7600-500-2.55").with_tool(make_transform(None, [0.3, 0.1, 0.4]))
    rng = np.random.default_rng(0)
    q = rng.uniform(m.q_min * 0.7, m.q_max * 0.7, (30, 6))
    W = rng.normal(size=(30, 6)) * [1500, 1500, 1500, 150, 150, 150]
    dd = m.deflection(q, W)[:, :3] + rng.normal(size=(30, 3)) * 2e-6
    f = tmp_path / "calib.csv"
    rows = np.column_stack([np.degrees(q), W, dd * 1e3])
    f.write_text(
        "# units: angle=deg length=mm force=N moment=N*m\n"
        "q1,q2,q3,q4,q5,q6,Fx,Fy,Fz,Mx,My,Mz,dx,dy,dz\n"
        + "\n".join(",".join(f"{v:.17g}" for v in r) for r in rows)
        + "\n"
    )
    return m, f


def test_identify_cli(tmp_path, capsys):
    m, f = _translations_sheet(tmp_path)
    out = tmp_path / "stiffness.toml"
    assert (
        main(
            [
                "robot",
                "identify",
                str(f),
                "--tool",
                "300,100,400",
                "--sigma",
                "0.002",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    from roboisf.robot import load_stiffness

    np.testing.assert_allclose(load_stiffness(out), m.joint_stiffness, rtol=0.03)
    # a stiffness file feeds a robot without published stiffness; the identified one names the
    # robot it was identified on and is refused for another (issue 29)
    capsys.readouterr()
    assert main(["robot", "show", "--robot", "kr210-r2700-2", "--stiffness", str(out)]) == 2
    assert "identified on the robot 'irb7600-500-2.55'" in capsys.readouterr().err
    plain = tmp_path / "plain.toml"
    plain.write_text("".join(ln for ln in out.read_text().splitlines(True) if "robot =" not in ln))
    assert main(["robot", "show", "--robot", "kr210-r2700-2", "--stiffness", str(plain)]) == 0
    assert "3.7" in capsys.readouterr().out
    # bare flange: joint 6 cannot be identified → exit 2, no output
    out2 = tmp_path / "s2.toml"
    assert main(["robot", "identify", str(f), "-o", str(out2)]) == 2
    assert not out2.exists()


@pytest.mark.parametrize(
    ("flag", "value"),
    [("--sigma", "0"), ("--sigma", "-0.01"), ("--sigma", "nan"), ("--sigma-rot", "0")],
)
def test_identify_refuses_a_standard_deviation_not_above_zero(tmp_path, capsys, flag, value):
    """σ = 0 was a ZeroDivisionError traceback (exit 1) and a negative σ was used as |σ|: both
    are one line naming the option, exit 2, and no stiffness file."""
    f = tmp_path / "calib.csv"
    f.write_text(
        "# units: angle=deg length=mm force=N moment=N*m\n"
        "q1,q2,q3,q4,q5,q6,Fx,Fy,Fz,Mx,My,Mz,dx,dy,dz\n"
        + "\n".join(f"{i},10,20,0,45,0,1000,0,-500,0,0,0,0.01,0.003,-0.05" for i in range(8))
        + "\n"
    )
    out = tmp_path / "K.toml"
    args = ["robot", "identify", str(f), "--tool", "300,100,400", flag, value, "-o", str(out)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert f"[{flag}]" in err and "Traceback" not in err
    assert not out.exists()


def test_identify_design_refuses_an_implausible_load(tmp_path, capsys):
    """A 2 MN design load made the information matrix singular: a LinAlgError traceback
    (exit 1); now refused as outside what a stiffness experiment applies (exit 2)."""
    out = tmp_path / "design"
    args = ["robot", "identify", "--design", "-o", str(out), "--tool", "0,0,306"]
    assert main([*args, "--force", "2e6"]) == 2
    err = capsys.readouterr().err
    assert "[--force]" in err and "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize(
    "args",
    [
        ["robot", "show", "--robot", "irb7600-500-2.55"],
        ["robot", "identify", "--design", "-o", "{tmp}/design"],
        ["robot", "identify", "{tmp}/calib.csv", "-o", "{tmp}/K.toml"],
        ["plan", "--part", "{tmp}/cone.toml", "-o", "{tmp}/plan"],
    ],
    ids=["robot-show", "identify-design", "identify", "plan"],
)
def test_a_tool_typed_in_m_is_refused_naming_the_slip(tmp_path, capsys, args):
    """``--tool 0,0,0.306`` (a 306 mm tool in m) ran as a tool 0.3 mm long: a stiffness map, a
    plan, a designed experiment or an identification of the wrong tool. Refused where the
    toolpath's --tool is (5–2000 mm from the flange, or the flange itself), nothing written."""
    (tmp_path / "calib.csv").write_text(
        "# units: angle=deg length=mm force=N moment=N*m\n"
        "q1,q2,q3,q4,q5,q6,Fx,Fy,Fz,Mx,My,Mz,dx,dy,dz\n"
        + "\n".join(f"{i},10,20,0,45,0,1000,0,-500,0,0,0,0.01,0.003,-0.05" for i in range(8))
        + "\n"
    )
    assert main(["part", "cone", "-o", str(tmp_path / "cone.toml")]) == 0
    capsys.readouterr()
    argv = [a.replace("{tmp}", str(tmp_path)) for a in args]
    assert main([*argv, "--tool", "0.25,0,0.306"]) == 2
    err = capsys.readouterr().err
    assert "[--tool]" in err and "if it was written in m" in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calib.csv", "cone.toml"]


def test_identify_design_writes_the_program_of_the_robots_maker(tmp_path, capsys):
    """A FANUC preset got an ABB RAPID module; it gets a TP program of joint positions (the
    pendant's angles, the experiment.csv's q1…q6). A URDF robot's angles are the URDF's, not
    its pendant's (FANUC's J3 is the pendant's J3 + J2): no program, said, the poses in the CSV."""
    import re

    from roboisf.programs.fanuc import _read_ls

    k = tmp_path / "k.toml"
    k.write_text("[stiffness]\nK = [4.0e6, 4.5e6, 2.5e6, 6.0e5, 5.0e5, 3.0e5]\n")
    base = ["robot", "identify", "--design", "--stiffness", str(k), "--tool", "0,0,306",
            "--placement", "1800,0,300,0"]  # fmt: skip
    assert main([*base, "--robot", "r2000ic-210f", "-o", str(tmp_path / "F")]) == 0
    assert sorted(p.name for p in (tmp_path / "F").glob("[!.]*")) == [
        "design.toml", "experiment.csv", "experiment.ls"
    ]  # fmt: skip
    name, body, _ = _read_ls(tmp_path / "F" / "experiment.ls")
    text = (tmp_path / "F" / "experiment.ls").read_text()
    J = np.array(
        [[float(v) for v in re.findall(r"J\d= *(-?[\d.]+) deg", blk)]
         for blk in re.findall(r"P\[\d+\]\{(.*?)\};", text, re.S)]
    )  # fmt: skip
    import csv

    lines = (tmp_path / "F" / "experiment.csv").read_text().splitlines()
    rows = list(csv.DictReader(ln for ln in lines if not ln.startswith("#")))  # dx… left blank
    q = np.array([[float(r[f"q{j}"]) for j in range(1, 7)] for r in rows])
    assert name == "ROBOISF_IDENTIFY" and body.count("PAUSE") == len(q) == len(J)
    np.testing.assert_allclose(J, q, atol=5e-4)  # deg, as written
    capsys.readouterr()
    urdf = "tests/data/urdf/m900ia260l.urdf"
    assert main([*base, "--robot", urdf, "-o", str(tmp_path / "U")]) == 0
    assert sorted(p.name for p in (tmp_path / "U").glob("[!.]*")) == [
        "design.toml", "experiment.csv"
    ]  # fmt: skip
    assert "no robot program for m900ia260l" in capsys.readouterr().out


@pytest.mark.parametrize("hw", ["1e7", "0", "nan"])
def test_a_stiffness_map_wider_than_any_cell_is_refused(tmp_path, capsys, hw):
    """--half-width 1e7 drew a 20 km map with one pixel inside the robot's reach."""
    out = tmp_path / "map.png"
    assert main(["robot", "show", "--half-width", hw, "-o", str(out)]) == 2
    assert "[--half-width]" in capsys.readouterr().err and not out.exists()


def _calib_with_rotations(path, noise_rot=2e-6):
    """A calibration CSV of 30 virtual experiments with measured rotations (rx, ry, rz, rad)
    whose noise is ``noise_rot`` rad; the tool 300,100,400 mm."""
    m = load_robot("irb7600-500-2.55").with_tool(make_transform(None, [0.3, 0.1, 0.4]))
    rng = np.random.default_rng(1)
    q = rng.uniform(m.q_min * 0.7, m.q_max * 0.7, (30, 6))
    W = rng.normal(size=(30, 6)) * [1500, 1500, 1500, 150, 150, 150]
    d = m.deflection(q, W)
    d[:, :3] += rng.normal(size=(30, 3)) * 2e-6
    d[:, 3:] += rng.normal(size=(30, 3)) * noise_rot
    rows = np.column_stack([np.degrees(q), W, d[:, :3] * 1e3, d[:, 3:]])
    path.write_text(
        "# units: angle=deg length=mm force=N moment=N*m rotation=rad\n"
        "q1,q2,q3,q4,q5,q6,Fx,Fy,Fz,Mx,My,Mz,dx,dy,dz,rx,ry,rz\n"
        + "\n".join(",".join(f"{v:.17g}" for v in r) for r in rows)
        + "\n"
    )
    return m


def _identify(tmp_path, calib, out, *extra):
    args = ["robot", "identify", str(calib), "--tool", "300,100,400", "-o", str(out), *extra]
    return main(args)


def test_sigma_rot_takes_its_unit_and_a_bare_number_keeps_its_old_reading(tmp_path, capsys):
    """--sigma-rot was in rad while every other angle on the command line is in degrees. A
    silent switch to degrees would change what existing scripts identify, so: a number with
    its unit is read in it (0.00114592deg = 2e-5rad, the same stiffness), a bare number is read
    in rad as before, with a warning naming both readings."""
    from roboisf.robot import load_stiffness

    calib = tmp_path / "calib.csv"
    _calib_with_rotations(calib)
    K = {}
    for name, value in (("rad", "2e-5rad"), ("deg", "0.0011459156deg"), ("bare", "2e-5")):
        out = tmp_path / f"{name}.toml"
        assert _identify(tmp_path, calib, out, "--sigma-rot", value) == 0, name
        K[name] = load_stiffness(out)
        err = capsys.readouterr().err
        assert ("has no unit" in err) == (name == "bare"), err
    np.testing.assert_allclose(K["deg"], K["rad"], rtol=1e-6)
    np.testing.assert_array_equal(K["bare"], K["rad"])
    # the weight is used: a rotation std a thousand times larger gives other numbers
    out = tmp_path / "loose.toml"
    assert _identify(tmp_path, calib, out, "--sigma-rot", "2e-2rad") == 0
    assert np.max(np.abs(load_stiffness(out) / K["rad"] - 1)) > 1e-4


@pytest.mark.parametrize(
    ("value", "expect"),
    [
        ("0.1", ["a bare 0.1 is read in rad", "0.1 rad (5.73°)", "write 0.1deg"]),
        ("2", ["a bare 2 is read in rad", "2 rad (115°)", "write 2deg"]),
        ("5deg", ["5deg (0.0873 rad)", "at most 0.05 rad"]),
        ("1e-5furlong", ["unknown unit 'furlong'", "rad, mrad, urad, deg, arcsec"]),
        ("0", ["must be a standard deviation > 0"]),
    ],
)
def test_sigma_rot_refuses_a_bare_number_that_can_only_be_degrees(tmp_path, capsys, value, expect):
    """A bare --sigma-rot 0.1 (0.1°, as the command line's convention says) ran as 0.1 rad —
    5.7°, no measurement's standard deviation — and weighted the rotations 57× too little.
    Refused: exit 2, one line naming the option, the unit read and what was expected; nothing
    written."""
    calib = tmp_path / "calib.csv"
    _calib_with_rotations(calib)
    out = tmp_path / "K.toml"
    assert _identify(tmp_path, calib, out, "--sigma-rot", value) == 2
    err = capsys.readouterr().err
    assert "[--sigma-rot]" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    for e in expect:
        assert e in err
    assert not out.exists()


def test_sigma_rot_without_rotation_columns_is_said_unused(tmp_path, capsys):
    """--sigma-rot weights only the rx,ry,rz columns: on a sheet without them it changes
    nothing, and the command says so rather than let the user think it was applied."""
    _, f = _translations_sheet(tmp_path)
    assert _identify(tmp_path, f, tmp_path / "K.toml", "--sigma-rot", "0.001deg") == 0
    assert "--sigma-rot is not used" in capsys.readouterr().err


@pytest.mark.parametrize("design", [False, True])
def test_sigma_in_um_typed_as_mm_is_refused(tmp_path, capsys, design):
    """--sigma 10 (10 µm meant, the option is mm) ran: an identification weighted as if the
    gauges read to 10 mm, and a design whose expected intervals were 1000× too wide
    (K6 ± 1331 %). Refused naming the slip."""
    calib = tmp_path / "calib.csv"
    _calib_with_rotations(calib)
    if design:
        out = tmp_path / "D"
        args = ["robot", "identify", "--design", "--tool", "0,0,306", "-o", str(out)]
    else:
        out = tmp_path / "K.toml"
        args = ["robot", "identify", str(calib), "--tool", "300,100,400", "-o", str(out)]
    assert main([*args, "--sigma", "10"]) == 2
    err = capsys.readouterr().err
    assert "[--sigma]" in err and "0.01 mm if it was written in µm" in err
    assert not out.exists()


def test_show_checks_the_maps_options_before_printing(tmp_path, capsys):
    """A bad --placement passed unread without -o (exit 0), and with -o was refused only after
    the robot's table was printed; a robot without stiffness printed its table before the map
    refused it. Now: the placement is checked first, the map's options without -o are said to
    be unused, and a refusal comes before any output."""
    assert main(["robot", "show", "--placement", "1,2"]) == 2
    cap = capsys.readouterr()
    assert "[--placement]" in cap.err and cap.out == ""
    assert main(["robot", "show", "--placement", "1600,0,800,0"]) == 0
    cap = capsys.readouterr()
    assert "--placement set the stiffness map (-o map.png): unused without -o" in cap.err
    assert "A1: limits" in cap.out
    png = tmp_path / "m.png"
    assert main(["robot", "show", "-o", str(png), "--placement", "1600,0,800"]) == 2
    cap = capsys.readouterr()
    assert "[--placement]" in cap.err and cap.out == "" and not png.exists()
    assert main(["robot", "show", "--robot", "kr210-r2700-2", "-o", str(png)]) == 2
    cap = capsys.readouterr()
    assert "no joint stiffness" in cap.err and cap.out == "" and not png.exists()


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--tool-rotation", "1e9"], "[--tool-rotation]: 1e+09 deg is outside"),
        (["--tool-rotation", "nan"], "[--tool-rotation]: expected a finite number"),
        (["--kuka-st", "2,10"], "[--kuka-st]: no IK solution"),
    ],
)
def test_deflect_names_the_option_it_refuses(cell, tmp_path, capsys, extra, needle):
    """--tool-rotation nan was '[tool_rotation]: tool_rotation contains NaN or inf' (the
    function's parameter, not the option) and 1e9° ran; --kuka-st's refusal named 'kuka_st'."""
    d, _, _ = cell
    out = tmp_path / "d.csv"
    assert main(_deflect(d, out, *extra)) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err
    assert not out.exists()


def test_design_says_what_it_cannot_do(tmp_path, capsys):
    """--experiments 100000 was refused as 'only 740 of 40000 random poses put the tip within
    1000 mm: place the robot closer' — the robot was fine, the count was the slip. And a design
    with joint 6 all but unloaded (a 5 mm bracket: K6 expected ± 3447 %) was written without a
    word beyond the table."""
    out = tmp_path / "D"
    base = ["robot", "identify", "--design", "--tool", "0,0,300", "-o", str(out)]
    assert main([*base, "--experiments", "100000"]) == 2
    err = capsys.readouterr().err
    assert "[--experiments]" in err and "ask for fewer experiments" in err
    assert not out.exists()
    assert main([*base, "--bracket", "-5"]) == 0
    err = capsys.readouterr().err
    assert "identifies K6" in err and "only weakly" in err and "--bracket" in err
    assert main([*base, "--overwrite"]) == 0  # the default 250 mm bracket: no warning
    assert "only weakly" not in capsys.readouterr().err


def test_design_refuses_a_placement_typed_in_metres(tmp_path, capsys):
    """--placement 1.6,0,0.8,0 (metres typed where mm are expected) put the work origin 1.8 mm
    from the robot base, and the design was written — 24 poses around the robot's own base —
    with exit 0. A preset's base is the robot's: refused, the slip named, nothing written. A
    URDF's root may be the cell's origin: the same line as a warning, the design written."""
    out = tmp_path / "D"
    base = ["robot", "identify", "--design", "--tool", "0,0,306", "--placement", "1.6,0,0.8,0"]
    assert main([*base, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for needle in ("[--placement]", "1.789 mm from the robot base", "around the robot's base",
                   "if it was written in m (x,y,z = 1600,0,800 mm)"):  # fmt: skip
        assert needle in err, err
    assert not out.exists()
    urdf = "tests/data/urdf/m900ia260l.urdf"
    k = tmp_path / "k.toml"
    k.write_text("[stiffness]\nK = [4.0e6, 4.5e6, 2.5e6, 6.0e5, 5.0e5, 3.0e5]\n")
    assert main([*base, "--robot", urdf, "--stiffness", str(k), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "warning:" in err and "unless the URDF's root is not the robot's base" in err, err
    assert "1600,0,800 mm" in err and (out / "experiment.csv").exists()
