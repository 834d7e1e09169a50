"""Done-when of issue #13, end to end: ``roboisf virtual-cell`` writes its logs the way real
equipment does — a Kistler 3-component export for the CNC dynamometer, an ATI Net F/T CSV for
the robot's flange sensor (with the truth's bias and the tool's weight in it), a KUKA trace
export for the joints, a 2 % fast controller clock with a 7 s offset and a 30 s pause — and
``analyze`` recovers the decomposition of the clean study (ideal sensor, nominal clock, roboisf
logs): every share within 1 percentage point, once the user states what they know (the tool's
mass and centre of gravity, weighed; ``tare = "auto"``). Left untared, the bias is flagged.

Slow (one small study built here, the clean one shared from tests/conftest.py, three
analyses); each piece is covered fast elsewhere: the formats by
test_logs_formats.py / test_study_init.py, alignment by test_sync.py, conditioning by
test_sensor*.py.
"""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from roboisf.decompose import FACTORS
from roboisf.decompose.pipeline import analyze
from roboisf.logs.forcelog import detect_force_format, read_force_log
from roboisf.logs.jointlog import detect_joint_format
from roboisf.virtual.cell import build_study, paper_cone_cell
from roboisf.virtual.equipment import Equipment
from roboisf.virtual.truth import TruthSpec

BIAS = np.array([30.0, -12.0, 8.0, 0.6, -0.4, 0.15])  # N, N·m, sensor axes
MASS, COG_FLANGE = 4.0, np.array([0.0, 0.0, 0.150])  # kg; m, flange frame
EQUIPMENT = Equipment(
    clock_scale=1.02,
    offset=7.0,
    pauses=((300.0, 30.0),),
    cnc_force_profile="kistler",
    robot_force_profile="ati",
    joint_profile="kuka",
)


@pytest.fixture(scope="module")
def studies(tmp_path_factory, small_cone_settings, small_cone_analysis):
    """The clean study's analysis (the small paper cone, ideal equipment: tests/conftest.py,
    shared) and the same cell with the sensor's bias, the tool's weight and real equipment."""
    root = tmp_path_factory.mktemp("equipment")
    truth = TruthSpec(sensor_bias=BIAS, tool_mass=MASS, tool_cog=COG_FLANGE)
    cell = paper_cone_cell(**small_cone_settings, truth=truth)
    real = build_study(cell, root / "real", equipment=EQUIPMENT)
    return small_cone_analysis, real, cell


def _shares(result, table):
    return getattr(result, table).set_index("factor").share_percent


@pytest.mark.slow
def test_files_are_written_as_the_equipment_writes_them(studies):
    _, real, _ = studies
    assert detect_force_format(real / "cnc_forces.csv")[0] == "kistler"
    assert detect_force_format(real / "robot_forces.csv")[0] == "ati"
    assert detect_joint_format(real / "robot_joints.csv")[0] == "kuka"
    assert not read_force_log(real / "cnc_forces.csv").moments_known  # 3-component
    # the controller starts logging 7 s before the program: an unloaded stretch to tare on
    log = read_force_log(real / "robot_forces.csv")
    first = log.time < 5.0
    assert first.sum() > 50
    spread = log.force[first].std(axis=0)
    assert np.all(spread < 5.0)  # noise only: no load in it
    assert np.linalg.norm(log.force[first].mean(axis=0)) > 30.0  # bias + weight


@pytest.mark.slow
def test_untared_bias_is_flagged(studies):
    _, real, _ = studies
    got = analyze(real)
    flagged = [w for w in got.summary.warnings if "not tared" in w]
    assert len(flagged) == 1 and "robot_forces.csv" in flagged[0]


@pytest.mark.slow
def test_stated_tool_and_auto_tare_recover_the_clean_decomposition(studies, tmp_path):
    clean, real, cell = studies
    s = tmp_path / "s"
    shutil.copytree(real, s)
    data = tomllib.loads((s / "study.toml").read_text())
    f = data["runs"]["robot"]["forces"]
    # what the user knows: the tool weighed, its CoG in the sensor frame (as the sensor maker's
    # software asks for it), and that the approach is unloaded
    T_flange_sensor = cell.T_flange_tip @ cell.T_tip_sensor
    cog_s = np.linalg.solve(T_flange_sensor, np.append(COG_FLANGE, 1.0))[:3]
    f.update(tare="auto", tool_mass=MASS, tool_cog=[float(v) * 1e3 for v in cog_s])
    (s / "study.toml").write_text(tomli_w.dumps(data))
    got = analyze(s)
    assert not [w for w in got.summary.warnings if "not tared" in w]
    for table in ("contributions", "contributions_normal"):
        a, b = _shares(clean, table), _shares(got, table)
        for fac in FACTORS:
            assert b[fac] == pytest.approx(a[fac], abs=1.0), (table, fac, a[fac], b[fac])


def test_logged_positions_are_checked_at_the_aligned_times():
    """check_force_log's x,y,z check uses the alignment's log time of each point when there is
    one: a log on a 2 % fast clock with a 7 s offset and a long stop is on the path there, and
    off it by nominal time (the test can fail both ways)."""
    import math

    from roboisf.errors import InputError
    from roboisf.logs.forcelog import ForceLog
    from roboisf.parts import Cone
    from roboisf.study.checks import check_force_log
    from roboisf.toolpath import step_down

    part = Cone(opening_diameter=0.06, wall_angle=math.radians(45), depth=0.01)
    tp = step_down(part, 5e-3, 2e-3, spacing=5e-3)
    half = 0.5 * float(tp.time[-1])
    point_time = 7.0 + 1.02 * (tp.time + np.where(tp.time > half, 30.0, 0.0))
    tau = np.linspace(0.0, float(point_time[-1]) + 1.0, 4000)
    pos = np.column_stack([np.interp(tau, point_time, tp.tip[:, j]) for j in range(3)])
    W = np.tile([50.0, 0.0, 400.0, 2.0, 0.0, 0.0], (tau.size, 1))
    log = ForceLog(tau, W, "sensor", Path("f.csv"), pos)
    assert check_force_log(log, tp, time_offset=7.0, point_time=point_time) == []
    with pytest.raises(InputError, match=r"f\.csv.*another path"):
        check_force_log(log, tp, time_offset=7.0)


def test_scan_compare_and_robot_deflect_take_a_cam_program(tmp_path, capsys):
    """``scan compare --toolpath`` imports a CAM program against --part with --tool-diameter
    (the deviations it gives are those of the same path as a roboisf CSV); without the diameter,
    and in ``robot deflect`` (no part), a one-line error points to ``roboisf toolpath import``."""
    import json

    from roboisf.cam.toolpath_csv import write_toolpath_csv
    from roboisf.cli.main import main
    from roboisf.parts import Cone
    from roboisf.scan import synthetic_scan, write_ply
    from roboisf.toolpath import step_down

    cone, dn = Cone(), -0.4e-3
    s = synthetic_scan(cone, 150_000, offset=dn, noise=25e-6, seed=7)
    write_ply(s.points, tmp_path / "scan.ply")
    (tmp_path / "cone.toml").write_text(
        '[part]\nkind = "cone"\nopening_diameter = 87.0\nwall_angle = 71.0\ndepth = 102.97\n'
    )
    tp = step_down(cone, 5e-3, 2e-3, spacing=4e-3)
    write_toolpath_csv(tp, tmp_path / "path.csv")
    rows = [f"G1 X{x:.4f} Y{y:.4f} Z{z:.4f}" for x, y, z in tp.tip * 1e3]
    text = "%\nO1000 (cone)\nG21 G90 G17\nG0 X0. Y0. Z20.\nF1000\n" + "\n".join(rows)
    (tmp_path / "cone.nc").write_text(text + "\nG0 Z20.\nM30\n%\n")
    base = ["-q", "scan", "compare", str(tmp_path / "scan.ply"), "-p", str(tmp_path / "cone.toml")]
    base += ["-r", "none"]
    got = {}
    for name, extra in (
        ("csv", ["--toolpath", str(tmp_path / "path.csv")]),
        ("nc", ["--toolpath", str(tmp_path / "cone.nc"), "--tool-diameter", "10"]),
    ):
        out = tmp_path / f"dev_{name}.csv"
        assert main([*base, *extra, "-o", str(out)]) == 0
        got[name] = json.loads((tmp_path / f"dev_{name}.summary.json").read_text())
    assert got["nc"]["toolpath"]["n_valid"] > 0.9 * got["csv"]["toolpath"]["n_valid"]
    for g in got.values():
        assert g["toolpath"]["mean_dn_mm"] == pytest.approx(dn * 1e3, abs=0.01)
    capsys.readouterr()
    out = tmp_path / "dev_bad.csv"
    assert main([*base, "--toolpath", str(tmp_path / "cone.nc"), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "cone.nc" in err and "roboisf toolpath import" in err and "--tool-diameter" in err
    assert not out.exists()
    head = "# units: time=s force=N moment=N*m\n# frame: tip\ntime,Fx,Fy,Fz,Mx,My,Mz\n"
    (tmp_path / "f.csv").write_text(head + "0,0,0,-400,0,0,0\n1,0,0,-400,0,0,0\n")
    args = ["-q", "robot", "deflect", "--toolpath", str(tmp_path / "cone.nc")]
    args += ["--forces", str(tmp_path / "f.csv"), "-o", str(tmp_path / "d.csv")]
    assert main(args) == 2
    assert "roboisf toolpath import" in capsys.readouterr().err


def _doc_blocks() -> list[tuple[str, str]]:
    import re

    doc = (Path(__file__).parents[1] / "docs" / "study.md").read_text(encoding="utf-8")
    sec = doc.split("### Worked example: a CAM program, an ATI log and a KUKA trace export")[1]
    sec = sec.split("\n## ")[0]
    return re.findall(r"```(\w+)\n(.*?)```", sec, re.S)


def _run_bash(block: str) -> None:
    import shlex

    from roboisf.cli.main import main

    for line in block.replace("\\\n", " ").splitlines():
        args = shlex.split(line, comments=True)
        if not args:
            continue
        if args[0] == "roboisf":
            assert main(["-q", *args[1:]]) == 0, line
        elif args[0] == "mkdir":
            Path(args[1]).mkdir()
        elif args[0] == "cp":
            *src, dst = args[1:]
            for f in src:
                shutil.copy(f, dst)
        else:  # pragma: no cover - the doc uses only these
            raise AssertionError(f"unknown command in the doc: {line}")


def _size_options(block: str) -> dict[str, float]:
    """The doc's ``virtual-cell`` options that set the cell's size (toolpath, scans, log
    rates), in the virtual cell's units (m, Hz, points)."""
    import shlex

    line = next(ln for ln in block.replace("\\\n", " ").splitlines() if "virtual-cell" in ln)
    args = shlex.split(line)
    scale = {"--step-down": 1e-3, "--spacing": 1e-3, "--scan-points": 1}
    scale |= {"--force-rate": 1, "--joint-rate": 1}
    return {
        a[2:].replace("-", "_"): float(args[i + 1]) * scale[a]
        for i, a in enumerate(args)
        if a in scale
    }


def _merge(a: dict, b: dict) -> None:
    for k, v in b.items():
        if isinstance(v, dict) and isinstance(a.get(k), dict):
            _merge(a[k], v)
        else:
            a[k] = v


def _subset(part: dict, whole: dict, where: str = "") -> None:
    for k, v in part.items():
        assert k in whole, f"{where}{k} not in the draft"
        if isinstance(v, dict):
            _subset(v, whole[k], f"{where}{k}.")
        else:
            assert whole[k] == v, f"{where}{k}: doc {v!r}, draft {whole[k]!r}"


@pytest.mark.slow
def test_docs_worked_example(tmp_path, monkeypatch, small_cone_settings, small_cone_analysis):
    """Runs docs/study.md's worked example block by block: the draft holds what the doc shows,
    and the analysis of the confirmed study gives the clean study's shares (1 point). The clean
    study is the shared small paper cone (tests/conftest.py): the doc's cell has its size."""
    import pandas as pd

    blocks = _doc_blocks()
    assert [k for k, _ in blocks] == ["toml", "bash", "python", "bash", "toml", "toml", "bash"]
    size = _size_options(blocks[1][1])
    assert size == pytest.approx(small_cone_settings), "the doc's cell is not the shared one"
    monkeypatch.chdir(tmp_path)
    Path("sensor.toml").write_text(blocks[0][1])
    _run_bash(blocks[1][1])
    exec(compile(blocks[2][1], "docs/study.md", "exec"), {})
    _run_bash(blocks[3][1])
    text = Path("my-cell/study.toml").read_text()
    draft = tomllib.loads(text)
    shown = blocks[4][1]
    assert shown.splitlines()[0] in text  # the TODO line
    _subset({k: v for k, v in tomllib.loads(shown).items() if k != "tool"}, draft)
    _merge(draft, tomllib.loads(blocks[5][1]))
    Path("my-cell/study.toml").write_text(tomli_w.dumps(draft))
    _run_bash(blocks[6][1])
    for table in ("contributions", "contributions_normal"):
        a = _shares(small_cone_analysis, table)
        b = pd.read_csv(Path("results") / f"{table}.csv", comment="#").set_index("factor")
        for fac in FACTORS:
            assert b.share_percent[fac] == pytest.approx(a[fac], abs=1.0), (table, fac)


def test_abb_joint_layout_gets_its_units_in_the_study(tmp_path):
    """The ABB export declares no units; the virtual cell's study says them (as its user
    would), so the study reads; the file alone is refused (units never guessed)."""
    from roboisf.decompose.pipeline import read_run_joint_log
    from roboisf.errors import InputError
    from roboisf.logs.jointlog import read_joint_log
    from roboisf.study import load_study

    kw = {"scan_points": 20_000, "force_rate": 50.0, "joint_rate": 20.0}
    kw |= {"step_down": 3e-3, "spacing": 6e-3}
    s = build_study(
        paper_cone_cell(**kw), tmp_path / "abb", equipment=Equipment(joint_profile="abb")
    )
    data = tomllib.loads((s / "study.toml").read_text())
    assert data["runs"]["robot"]["joints"] == {
        "file": "robot_joints.csv",
        "units": {"time": "s", "angle": "deg"},
    }
    with pytest.raises(InputError, match="unit not declared"):
        read_joint_log(s / "robot_joints.csv")
    st = load_study(s)
    q = read_run_joint_log(st.robot_run).q
    assert np.abs(q).max() < 2 * np.pi  # radians inside: the degrees were converted
    assert np.ptp(q[:, 0]) > 0.01  # and the robot moved
