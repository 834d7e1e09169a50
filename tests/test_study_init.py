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
    # the cell writes its logs as CSV or Parquet (build_study's log_format): by stem
    kinds = {
        f.path.stem if f.kind.endswith("_log") else f.path.name: f.kind for f in detect_files(d)
    }
    assert kinds == {
        "cnc_forces": "force_log",
        "robot_forces": "force_log",
        "robot_joints": "joint_log",
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
    assert data["runs"]["robot"]["joints"].startswith("robot_joints.")
    assert data["runs"]["robot"]["sync"] == "position" and data["runs"]["cnc"]["sync"] == "time"
    assert data["runs"]["cnc"]["forces"]["file"].startswith("cnc_forces.")
    assert data["runs"]["robot"]["scan"] == "robot_scan.ply"
    with pytest.raises(InputError, match=r"robot\.placement"):
        analyze(d)


def test_a_file_it_cannot_choose_is_a_todo_naming_the_candidates(virtual, tmp_path):
    """Two force logs, neither named for its run: the TODO said 'the robot run's force log'
    without naming either; it lists the candidates to choose from."""
    _, bare, _ = virtual
    d = _fresh(bare, tmp_path)
    cnc = next(d.glob("cnc_forces.*"))
    rob = next(d.glob("robot_forces.*"))
    cnc.rename(d / f"log_a{cnc.suffix}")
    rob.rename(d / f"log_b{rob.suffix}")
    assert main(["-q", "study", "init", str(d)]) == 0
    data = tomllib.loads((d / "study.toml").read_text())
    for run in ("cnc", "robot"):
        todo = data["runs"][run]["forces"]["file"]
        assert todo.startswith("TODO:") and f"log_a{cnc.suffix}, log_b{rob.suffix}" in todo


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


# --- the formats of issue #13, each as a hand-written file in one folder -----------------------

_GCODE = """%
O2002 (SPIF cone, ISO as a CAM post writes it)
N10 G21 G90 G17
N20 G0 X0. Y0. Z10.
N30 G1 Z0. F1000
N40 G1 X20. Y0.
N50 G2 X-20. Y0. I-20. J0.
N60 G2 X20. Y0. I20. J0.
N70 G0 Z10.
N80 M30
%
"""
_ATI = """Start Time,01/01/2026 08:00:00
RDT Sample Rate,100
Force Units,N
Counts per Unit Force,1
Torque Units,Nm
Counts per Unit Torque,1
Status (hex),RDT Sequence,F/T Sequence,Fx,Fy,Fz,Tx,Ty,Tz,Time
0x0,1,1,0.1,0.2,-1.0,0.01,0.02,0.0,0.000
0x0,2,2,0.1,0.2,-2.0,0.01,0.02,0.0,0.010
0x0,3,3,0.3,0.4,-4.0,0.01,0.02,0.0,0.020
"""
_KISTLER = (
    "DynoWare ASCII export\nType 9257B 3-component dynamometer\nSampling rate [Hz]:\t100\n"
    "Number of samples:\t3\n\nTime [s]\tFx [N]\tFy [N]\tFz [N]\n"
    "0,000\t1,0\t0,0\t-10,0\n0,010\t1,0\t0,0\t-11,0\n0,020\t1,0\t0,0\t-12,0\n"
)
_DYNO3 = "time;Fx;Fy;Fz\n0,0;1,5;0,2;-10,0\n0,01;1,5;0,2;-11,0\n0,02;1,5;0,2;-12,0\n"
_ABB_DEG = "Time,J1,J2,J3,J4,J5,J6\n0.0,10,20,30,40,50,60\n0.1,10.5,20,30,40,50,60\n"
_ABB_SMALL = "Time,J1,J2,J3,J4,J5,J6\n0.0,0.1,0.2,0.3,0.4,0.5,0.6\n0.1,0.1,0.2,0.3,0.4,0.5,0.6\n"
_KUKA = (
    "Time [s];" + ";".join(f"A{i} [deg]" for i in range(1, 7)) + "\n"
    "0,0;10,0;20,0;30,0;40,0;50,0;60,0\n0,1;10,5;20,0;30,0;40,0;50,0;60,0\n"
)
_KUKA_RAD = "time [s],A1 [rad],A2 [rad],A3 [rad],A4 [rad],A5 [rad],A6 [rad]\n0,0,0,0,0,0,0\n"
_KUKA_RAD += "0.1,0.1,0,0,0,0,0\n"
_MPF = "%_N_CONE_MPF\n;$PATH=/_N_WKS_DIR/_N_CONE_WPD\nG642\nG1 X=0 Y=0 Z=50 F=1000\n"
_MPF += "G1 X=10 Y=0 Z=0\nG1 X=10 Y=10 Z=0\nM30\n"
_APT = "PARTNO/CONE\nUNITS/MM\nFEDRAT/1000\nGOTO/0,0,0\nGOTO/10,0,0\nGOTO/10,10,0\nFINI\n"
_PTS = "3\n0 0 0\n1 0 0\n0 1 0.5\n"


@pytest.fixture
def cell_files(tmp_path):
    d = tmp_path / "cell"
    d.mkdir()
    for name, text in {
        "program.nc": _GCODE,
        "cone.mpf": _MPF,
        "cone.apt": _APT,
        "ati.csv": _ATI,
        "kistler.txt": _KISTLER,
        "dyno3.csv": _DYNO3,
        "abb_deg.csv": _ABB_DEG,
        "abb_small.csv": _ABB_SMALL,
        "kuka.txt": _KUKA,
        "kuka_rad.csv": _KUKA_RAD,
        "cloud.pts": _PTS,
    }.items():
        (d / name).write_text(text, encoding="utf-8")
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0.5]])
    laspy = pytest.importorskip("laspy")
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales, header.offsets = np.array([1e-3] * 3), np.zeros(3)
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    las.write(str(d / "cloud.las"))
    pye57 = pytest.importorskip("pye57")
    e57 = pye57.E57(str(d / "cloud.e57"), mode="w")
    e57.write_scan_raw({"cartesianX": pts[:, 0], "cartesianY": pts[:, 1], "cartesianZ": pts[:, 2]})
    e57.close()
    return d


def test_detect_every_equipment_format(cell_files):
    got = {f.path.name: f for f in detect_files(cell_files)}
    kinds = {
        n: (f.kind, f.details.get("profile") or f.details.get("program")) for n, f in got.items()
    }
    assert kinds == {
        "program.nc": ("toolpath", "iso"),
        "cone.mpf": ("toolpath", "sinumerik"),
        "cone.apt": ("toolpath", "apt"),
        "ati.csv": ("force_log", "ati"),
        "kistler.txt": ("force_log", "kistler"),
        "dyno3.csv": ("force_log", "dyno3"),
        "abb_deg.csv": ("joint_log", "abb"),
        "abb_small.csv": ("joint_log", "abb"),
        "kuka.txt": ("joint_log", "kuka"),
        "kuka_rad.csv": ("joint_log", "kuka"),
        "cloud.pts": ("scan", None),
        "cloud.las": ("scan", None),
        "cloud.e57": ("scan", None),
    }
    # CAM programs: their format and the point they name, as study keys
    assert got["program.nc"].keys == {"toolpath_format": "iso", "toolpath_point": "tip"}
    assert got["cone.mpf"].keys["toolpath_format"] == "sinumerik"
    # forces: the ATI and Kistler files declare their units (ATI's time is RDT / rate) ...
    assert got["ati.csv"].keys == {"format": "ati"}
    assert got["ati.csv"].details["peak |F|"] == f"{np.sqrt(0.3**2 + 0.4**2 + 4.0**2):.4g} N"
    assert got["kistler.txt"].keys == {"format": "kistler"}
    assert got["kistler.txt"].details["moments"].startswith("no")
    # ... a bare 3-component table does not: its units are TODO for the user, never guessed
    u = got["dyno3.csv"].keys["units"]
    assert set(u) == {"time", "force"} and all(v.startswith("TODO") for v in u.values())
    # joints: declared (KUKA [deg] / [rad]) as they are; ABB without units: time is TODO, angles
    # are degrees only when the values cannot be radians
    assert got["kuka.txt"].keys == {"format": "kuka"}
    assert "angle deg" in got["kuka.txt"].details["units"]
    assert "angle rad" in got["kuka_rad.csv"].details["units"]
    assert got["abb_deg.csv"].keys["units"]["angle"] == "deg"
    assert got["abb_deg.csv"].keys["units"]["time"].startswith("TODO")
    assert got["abb_small.csv"].keys["units"]["angle"].startswith("TODO")
    # scans: E57 is metres by its standard; the others take scan_unit
    assert got["cloud.e57"].details["units"].startswith("m ")
    assert got["cloud.pts"].details["points"] == "3" and got["cloud.las"].details["points"] == "3"


def test_draft_writes_format_and_units_keys(tmp_path):
    d = tmp_path / "cell"
    d.mkdir()
    (d / "robot_program.nc").write_text(_GCODE)
    (d / "robot_ati.csv").write_text(_ATI)
    (d / "robot_trace.csv").write_text(_ABB_DEG)
    (d / "cnc_dyno.csv").write_text(_DYNO3)
    assert main(["-q", "study", "init", str(d)]) == 0
    text = (d / "study.toml").read_text()
    data = tomllib.loads(text)
    rob, cnc = data["runs"]["robot"], data["runs"]["cnc"]
    assert rob["toolpath"] == "robot_program.nc" and rob["toolpath_format"] == "iso"
    assert rob["toolpath_point"] == "tip"
    assert data["tool"]["ball_diameter"].startswith("TODO")  # a G-code does not say its ball
    assert rob["forces"]["file"] == "robot_ati.csv" and rob["forces"]["format"] == "ati"
    assert "units" not in rob["forces"]
    assert rob["joints"]["file"] == "robot_trace.csv" and rob["joints"]["format"] == "abb"
    assert rob["joints"]["units"]["angle"] == "deg" and rob["sync"] == "position"
    assert cnc["forces"]["format"] == "dyno3"
    for key in (
        "runs.robot.joints.units.time",
        "runs.cnc.forces.units.force",
        "tool.ball_diameter",
    ):
        assert key in text.splitlines()[1]  # the TODO header line names every undeclared unit


def test_robot_file_is_written_relative_to_the_study_and_checked(tmp_path, monkeypatch, capsys):
    """issue #28: ``--robot cell/urdf/x.urdf`` typed from the folder above the study is found
    there and written as ``urdf/x.urdf`` (study paths are relative to the study); a robot file
    that does not exist is refused at once, naming where it was looked for."""
    from pathlib import Path

    d = tmp_path / "cell"
    (d / "urdf").mkdir(parents=True)
    src = Path(__file__).parent / "data" / "urdf" / "kr210_r2700_2.urdf"
    shutil.copy(src, d / "urdf" / "kr.urdf")
    monkeypatch.chdir(tmp_path)
    assert main(["-q", "study", "init", "cell", "--robot", "cell/urdf/kr.urdf"]) == 0
    data = tomllib.loads((d / "study.toml").read_text())
    assert data["robot"]["model"] == "urdf/kr.urdf"
    assert (d / data["robot"]["model"]).is_file()
    (d / "study.toml").unlink()
    assert main(["-q", "study", "init", "cell", "--robot", "urdf/kr.urdf"]) == 2
    err = capsys.readouterr().err
    assert "[--robot]" in err and "neither a preset" in err
    assert str(tmp_path / "urdf" / "kr.urdf") in err.replace("\n", "")
    assert not (d / "study.toml").exists()
    assert main(["-q", "study", "init", "cell", "--part", "nope.toml"]) == 2
    assert "[--part]" in capsys.readouterr().err


def test_a_log_with_repeated_stamps_is_drafted_with_repair(tmp_path):
    """issue #28: a force log whose clock repeats a few stamps is not left out of the draft: it
    gets timestamps = "repair", and the note says what that repairs."""
    d = tmp_path / "cell"
    d.mkdir()
    rows = [f"{0.01 * i:.2f},1,2,-300,0,0,0" for i in range(50)]
    rows.insert(20, rows[19])  # one row written twice
    (d / "robot_forces.csv").write_text(
        "# units: time=s force=N moment=N*m\n# frame: sensor\ntime,Fx,Fy,Fz,Mx,My,Mz\n"
        + "\n".join(rows)
        + "\n"
    )
    from roboisf.study.init import draft_study

    files = detect_files(d)
    (f,) = files
    assert f.kind == "force_log" and f.keys["timestamps"] == "repair"
    draft = draft_study(d, files)
    assert draft.data["runs"]["robot"]["forces"]["timestamps"] == "repair"
    assert any("1 exact duplicate row(s) dropped" in n for n in draft.notes)
