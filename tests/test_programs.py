"""Program writers (G-code, ABB RAPID, KUKA KRL, FANUC LS): round trip through their readers,
and checks a controller would make, done independently of the readers:

* G-code through pygcode, an independent RS-274 interpreter (positions, work offset, tool call,
  length compensation);
* RAPID, KRL and LS through small line grammars written here (no parser for these languages is
  published on PyPI), separate from the readers: every line must be one of the forms a controller
  accepts, names must be valid and equal to their files, called routines must exist;
* configuration data (confdata, S/T, CONFIG) against the definitions applied here to the IK
  joint angles, including q6 at −180°;
* size limits per module, frames equal to the cell's, continuity of the moves read back.

Programs are written at 1 µm (0.001 mm), so positions come back to ≤ 0.5 µm (+ float noise)."""

from __future__ import annotations

import math
import os
import re
import stat
from pathlib import Path

import numpy as np
import pytest

from roboisf.cam.gcode import read_gcode, write_gcode
from roboisf.cam.program import RobotTool
from roboisf.errors import InputError
from roboisf.frames import invert
from roboisf.frames.rotations import rot_z
from roboisf.frames.se3 import make_transform
from roboisf.parts import Cone
from roboisf.programs.export import write_toolpath
from roboisf.programs.fanuc import read_fanuc, write_fanuc
from roboisf.programs.krl import read_krl, write_krl
from roboisf.programs.rapid import read_rapid, write_rapid
from roboisf.robot.armconfig import (
    ArmConfig,
    abb_confdata,
    arm_config,
    fanuc_config,
    kuka_status_turn,
    program_config,
)
from roboisf.robot.ik import ik_toolpath, opw_ik, tool_poses
from roboisf.robot.presets import load_robot
from roboisf.toolpath import spiral, step_down

HALF_UM = 0.5e-6 + 1e-12
BASE = np.eye(4)


@pytest.fixture(scope="module")
def tp():
    return step_down(Cone(depth=6e-3), 5e-3, 0.5e-3, spacing=2e-3)


@pytest.fixture(scope="module")
def placement():
    return make_transform(rot_z(math.radians(30.0)), [1.6, -0.2, 0.7])


@pytest.fixture(scope="module")
def cell():
    """The demo cone cell with the blank on the robot base's x-axis (where the path crosses
    q6 = −180°, the boundary the confdata tests need): its robot with its tool, its placement, a
    small path and the IK."""
    from roboisf.virtual.cell import paper_cone_cell

    c = paper_cone_cell(T_base_work=make_transform(p=[2.2, 0.0, 0.2]))
    model, T = c.cell.robot, c.cell.T_base_work
    path = step_down(Cone(depth=8e-3), 5e-3, 0.5e-3, spacing=1.5e-3)
    return model, T, path, program_config(model, path, T, c.tool_rotation)


def max_step(tip: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(tip, axis=0), axis=1).max())


# -- independent grammars (not the readers) -----------------------------------------------------

_N = r"-?\d+(?:\.\d+)?(?:E9)?"
_POSE = rf"\[\[{_N},{_N},{_N}\],\[{_N},{_N},{_N},{_N}\]\]"
_CONF = r"\[-?\d+,-?\d+,-?\d+,[0-7]\]"
_RT = rf"\[\[{_N},{_N},{_N}\],\[{_N},{_N},{_N},{_N}\],{_CONF},\[(?:9E9,){{5}}9E9\]\]"
_RAPID_LINES = [
    r"MODULE (\w+)",
    r"ENDMODULE",
    r"\s*!.*",
    rf"  PERS tooldata \w+ := \[TRUE,{_POSE},\[{_N},\[{_N},{_N},{_N}\],\[1,0,0,0\],0,0,0\]\];",
    rf'  PERS wobjdata \w+ := \[FALSE,TRUE,"",{_POSE},\[\[0,0,0\],\[1,0,0,0\]\]\];',
    rf"  CONST speeddata vForm := \[{_N},500,5000,1000\];",
    r'  CONST string sDir := "[^"\\]*";',
    r"  VAR loadsession ldNext;",
    r"  PROC (\w+)\(\)",
    r"  ENDPROC",
    r"    ConfJ\\(On|Off);",
    r"    ConfL\\(On|Off);",
    rf"    MoveJ Offs\({_RT},0,0,{_N}\),v200,fine,\w+\\WObj:=\w+;",
    rf"    MoveL Offs\({_RT},0,0,{_N}\),v50,fine,\w+\\WObj:=\w+;",
    rf"    MoveL {_RT},vForm,z0,\w+\\WObj:=\w+;",
    r"    (\w+);",
    r'    %"(\w+)"%;',
    r'    StartLoad \\Dynamic, sDir \\File:="(\w+)\.mod", ldNext;',
    r"    WaitLoad ldNext;",
    r'    UnLoad sDir \\File:="(\w+)\.mod";',
]


def check_rapid_set(main: Path) -> dict[str, int]:
    """Grammar + structure of a RAPID program set; returns MoveL per module file."""
    files = {main.stem: main}
    moves: dict[str, int] = {}
    procs: dict[str, str] = {}
    calls: list[tuple[str, str]] = []
    order: list[str] = []
    pending = list(files.items())
    while pending:
        stem, f = pending.pop(0)
        lines = f.read_text().splitlines()
        assert re.fullmatch(r"MODULE (\w+)", lines[0]).group(1) == stem  # module name = file
        assert lines[-1] == "ENDMODULE"
        inside = None
        moves[f.name] = 0
        for ln in lines:
            m = next((re.fullmatch(p, ln) for p in _RAPID_LINES if re.fullmatch(p, ln)), None)
            assert m is not None, f"{f.name}: not RAPID the writer may emit: {ln[:90]!r}"
            if ln.startswith("  PROC"):
                assert inside is None
                inside = m.group(1)
                assert len(inside) <= 32 and inside not in procs
                procs[inside] = f.name
            elif ln == "  ENDPROC":
                inside = None
            elif ln.startswith("    MoveL [["):
                moves[f.name] += 1
            elif ln.startswith("    StartLoad"):
                sub = m.group(1)
                order.append(sub)
                if sub not in files:
                    files[sub] = main.with_name(f"{sub}.mod")
                    pending.append((sub, files[sub]))
            elif re.fullmatch(r"    (\w+);|    %\"(\w+)\"%;", ln) and "Load" not in ln:
                calls.append((inside or "", re.sub(r'[%";\s]', "", ln)))
        assert inside is None
    for _, r in calls:
        assert r in procs, f"call of an undefined routine {r}"
    assert "main" in procs
    return moves


def check_krl(src: Path) -> None:
    """KRL grammar: names = file stem, ≤ 24 characters, HOME at start and end, S/T on the PTP."""
    text = src.read_text().splitlines()
    dat = src.with_suffix(".dat").read_text().splitlines()
    names = [re.fullmatch(r"DEF (\w+)\( \)", ln).group(1) for ln in text if ln.startswith("DEF ")]
    assert names[0] == src.stem and all(len(n) <= 24 for n in names)
    assert len(set(n.lower() for n in names)) == len(names)
    assert re.fullmatch(r"DEFDAT (\w+)", dat[2]).group(1) == src.stem
    frame = r"\{X -?[\d.]+,Y -?[\d.]+,Z -?[\d.]+,A -?[\d.]+,B -?[\d.]+,C -?[\d.]+"
    forms = [
        r"&ACCESS RVP",
        r"&REL 1",
        r"DEF \w+\( \)",
        r"END",
        r"",
        r"\s*;.*",
        r"    GLOBAL INTERRUPT DECL 3 WHEN \$STOPMESS==TRUE DO IR_STOPM \( \)",
        r"    INTERRUPT ON 3",
        r"    BAS\(#INITMOV,0\)",
        r"  \$H_POS = XHOME",
        r"  PTP XHOME",
        r"  \$(TOOL|BASE) = (TOOL|BASE)_ISF",
        r"  \$LOAD\.(M|CM) = LOAD_(M|CM)",
        r"  \$VEL\.CP = [\d.]+",
        r"  \$APO\.CDIS = [\d.]+",
        rf"  PTP {frame}(,S [0-7],T \d+)?\}}",
        rf"  LIN {frame}\}}( C_DIS)?",
        r"  (\w+)\( \)",
    ]
    body = [ln for ln in text if not ln.startswith(("DEF ", "END"))]
    for ln in body:
        assert any(re.fullmatch(p, ln) for p in forms), f"not KRL the writer may emit: {ln!r}"
    main = text[: text.index("END")]
    ptp = [ln.strip() for ln in main if ln.strip().startswith("PTP")]
    assert ptp[0] == "PTP XHOME" and ptp[-1] == "PTP XHOME"  # HOME first and last
    assert main.index("  $H_POS = XHOME") < main.index("  PTP XHOME")
    for ln in main:
        c = re.fullmatch(r"  (\w+)\( \)", ln)
        if c:
            assert c.group(1) in names  # every call has its DEF


def check_ls(path: Path) -> int:
    """FANUC LS grammar: numbered /MN lines, LINE_COUNT, P[i] defined once, CONFIG format."""
    text = path.read_text()
    assert text.startswith(f"/PROG  {path.stem.upper()}\n") and text.endswith("/END\n")
    attr, rest = text.split("/MN\n")
    mn, pos = rest.split("/POS\n")
    lines = mn.splitlines()
    for k, ln in enumerate(lines, start=1):
        assert re.fullmatch(rf"\s*{k}:.* ;", ln), ln
    assert f"LINE_COUNT\t= {len(lines)};" in attr
    used = [int(i) for i in re.findall(r"^\s*\d+:[JL] P\[(\d+)\]", mn, re.M)]
    defined = [int(i) for i in re.findall(r"^P\[(\d+)\]\{", pos, re.M)]
    assert sorted(used) == sorted(defined) and len(set(defined)) == len(defined)
    confs = re.findall(r"CONFIG : '([^']*)'", pos)
    assert len(confs) == len(defined)
    assert all(re.fullmatch(r"[NF] [UD] [TB], -?\d+, -?\d+, -?\d+", c) for c in confs)
    for ln in lines:
        body = ln.split(":", 1)[1].strip()
        assert re.fullmatch(
            r"!.*;|(PR\[\d+\]=LPOS|PR\[\d+,[1-6]\]=-?[\d.]+|U(FRAME|TOOL)\[\d\]=PR\[\d+\]|"
            r"U(FRAME|TOOL)_NUM=\d|CALL \w+)\s*;|"
            r"J P\[\d+\] \d+% FINE\s+;|L P\[\d+\] \d+(mm/sec|cm/min) (FINE|CNT100)\s+;",
            body,
        ), body
    return len(used)


# -- G-code ---------------------------------------------------------------------------------------


def test_gcode_round_trip_and_independent_interpreter(tmp_path, tp):
    from pygcode import Line, Machine

    f = tmp_path / "p.nc"
    write_gcode(tp, f, safe_height=15e-3, work_offset="G55", notes=("a note (with parens)",))
    text = f.read_text()
    back = read_gcode(f)
    assert len(back) == len(tp)
    assert np.abs(back.tip - tp.tip).max() <= HALF_UM
    assert back.feed == pytest.approx(tp.feed)
    assert back.meta["work_offsets"] == ["G55"] and back.meta["tools"] == [1]
    assert back.meta["length_compensation"] == [1]
    assert "(a note [with parens])" in text
    # pygcode, an independent interpreter: every line is valid G-code, the work offset, the
    # tool and its length compensation are active at the first feed move, and the feed-move
    # end points are the toolpath tips
    m = Machine()
    feed_pts, modes = [], []
    for raw in text.splitlines():
        if raw == "%":
            continue
        block = Line(raw).block
        m.process_block(block)
        if any(type(g).__name__ == "GCodeLinearMove" for g in block.gcodes):
            feed_pts.append([m.pos.X, m.pos.Y, m.pos.Z])
            modes.append(str(m.mode))
    assert np.abs(np.array(feed_pts) * 1e-3 - tp.tip).max() <= HALF_UM
    assert "G55" in modes[0] and "G43" in modes[0] and "T1" in modes[0]
    assert "G21" in modes[0] and "G90" in modes[0]
    with pytest.raises(InputError, match="work offset"):
        write_gcode(tp, tmp_path / "q.nc", work_offset="G92")


def test_gcode_parser_variants(tmp_path):
    f = tmp_path / "v.nc"
    f.write_text(
        "%\nN10 G20 G90 (inch)\nN20 G0 X0 Y0 Z1\nN30 G1 Z-0.1 F30 ; plunge\nN40 X1\nN50 Y2 Z-0.2\n"
        "M30\n%\n"
    )
    back = read_gcode(f)
    np.testing.assert_allclose(
        back.tip, np.array([[0, 0, -0.1], [1, 0, -0.1], [1, 2, -0.2]]) * 0.0254
    )
    assert back.feed == pytest.approx(30 * 0.0254 / 60)
    # incremental moves are read (tests/test_toolpath_import*.py); from an unknown start they
    # are refused naming the line
    f.write_text("G91\nG1 X1 F100\n")
    with pytest.raises(InputError, match="incremental X move from an unknown position") as ei:
        read_gcode(f)
    assert ei.value.line == 2
    f.write_text("G90\nG1 X1 Y1 Z1\n")
    with pytest.raises(InputError, match="before any F"):
        read_gcode(f)
    f.write_text("G90\nG1 X1 Y1 Z1 F10 Q?\n")
    with pytest.raises(InputError, match="cannot parse"):
        read_gcode(f)


# -- RAPID ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("gamma", [0.0, 0.7])
def test_rapid_round_trip(tmp_path, tp, placement, gamma):
    f = tmp_path / "cone_path.mod"
    tool = RobotTool(length=0.245, mass=3.5, name="tIsf")
    rot = np.linspace(0.0, gamma, len(tp))
    files = write_rapid(tp, f, T_base_work=placement, tool=tool, tool_rotation=rot, max_moves=100)
    assert files == [f]  # below the module limit: one module
    back = read_rapid(f)
    assert len(back) == len(tp)
    assert np.abs(back.tip - tp.tip).max() <= HALF_UM
    expect = np.diag([1.0, -1.0, -1.0]) @ rot_z(rot)
    assert np.abs(back.R_work_tool - expect).max() < 1e-8
    np.testing.assert_allclose(back.T_base_work, placement, atol=1e-9)
    assert back.feed == pytest.approx(tp.feed)
    assert back.tool.length == pytest.approx(0.245) and back.tool.mass == pytest.approx(3.5)
    n_procs = math.ceil(len(tp) / 100)
    assert back.meta["routines"] == [f"cone_path_{k}" for k in range(1, n_procs + 1)]
    text = f.read_text()
    assert text.startswith("MODULE cone_path\n") and text.rstrip().endswith("ENDMODULE")
    assert text.count("PROC ") == n_procs + 1
    assert "[0,1,0,0]" in text  # the first point, tool straight down (γ = 0)
    assert "ConfJ\\Off" in text and "confdata [0,0,0,0]" in text  # no robot: said, checks off
    for proc in re.findall(r"PROC \w+\(\)\n(.*?)ENDPROC", text, re.S)[1:]:
        assert proc.count("MoveL") <= 100
    check_rapid_set(f)


def test_rapid_program_set_splits_loads_and_reads_back(tmp_path, cell):
    """A path above the module limit: main + part modules (≤ limit each, split at lap ends),
    loaded in order, read back to 1 µm with the IK confdata, continuous across modules."""
    model, T, path, cfg = cell
    f = tmp_path / "cone.mod"
    limit = 400
    tool = RobotTool(length=float(model.T_flange_tip[2, 3]))
    files = write_rapid(
        path, f, T_base_work=T, tool=tool, config=cfg, max_module_moves=limit, max_moves=150
    )
    n_mod = len(files) - 1
    assert n_mod == len(list(tmp_path.glob("cone_*.mod"))) >= math.ceil(len(path) / limit)
    moves = check_rapid_set(f)
    assert moves["cone.mod"] == 0  # the main module holds only data, approach and retract
    assert all(0 < moves[f"cone_{k}.mod"] <= limit for k in range(1, n_mod + 1))
    assert sum(moves.values()) == len(path)
    main = f.read_text()
    # load k+1 while k runs; late binding; unload in order
    seq = re.findall(r'(StartLoad|%"|UnLoad)[^\n]*?cone_(\d+)', main)
    assert seq[:2] == [("StartLoad", "1"), ("StartLoad", "2")]
    assert [k for op, k in seq if op == '%"'] == [str(k) for k in range(1, n_mod + 1)]
    assert [k for op, k in seq if op == "UnLoad"] == [str(k) for k in range(1, n_mod + 1)]
    back = read_rapid(f)
    assert np.abs(back.tip - path.tip).max() <= HALF_UM
    assert back.meta["modules"] == ["cone.mod", *(f"cone_{k}.mod" for k in range(1, n_mod + 1))]
    # modules end at lap ends (each lap is shorter than the limit)
    starts = np.cumsum([moves[f"cone_{k}.mod"] for k in range(1, n_mod)])
    assert np.all(path.lap[starts] != path.lap[starts - 1])
    # continuity: no jump between consecutive moves, module boundaries included
    assert max_step(back.tip) <= max_step(path.tip) + 1e-6
    # frames equal to the cell's; confdata equal to the IK branch's
    np.testing.assert_allclose(back.T_base_work, T, atol=1e-9)
    assert back.tool.length == pytest.approx(model.T_flange_tip[2, 3])
    np.testing.assert_array_equal(back.meta["confdata"], abb_confdata(cfg))


def test_rapid_targets_in_one_pass_are_the_per_target_text():
    """The writer's targets (orientation and confdata formatted once per distinct value) are
    :func:`_target`'s text for every row: ±0, values that
    round to 0 or to an integer, halves, several orientations and confdata."""
    from roboisf.programs.rapid import _target, _targets

    rng = np.random.default_rng(3)
    n = 3000
    p = rng.uniform(-1500, 1500, (n, 3))
    p[:50] = np.round(p[:50])
    p[50:100] = -4e-4  # rounds to -0.000: written 0
    p[100:150] = -0.0
    p[150:200] = 12.5
    p[200:250] = 1e-3
    q = np.tile([0.0, 0.70710678, 0.70710678, -0.0], (n, 1))
    q[::7] = rng.normal(size=q[::7].shape)
    q[::11, 0] = -1e-12
    cf = np.zeros((n, 4), dtype=np.int64)
    cf[::3] = rng.integers(-3, 3, cf[::3].shape)
    rows = (p.tolist(), q.tolist(), cf.tolist())
    assert _targets(*rows) == [_target(*r) for r in zip(*rows, strict=True)]
    assert _targets(*rows)[60].startswith("[[0,0,0],[0,0.70710678,0.70710678,0],")


def test_rapid_bad_options(tmp_path, tp):
    with pytest.raises(InputError, match="unknown zone"):
        write_rapid(tp, tmp_path / "a.mod", T_base_work=BASE, zone="z7")
    with pytest.raises(InputError, match="rigid transform"):
        write_rapid(tp, tmp_path / "a.mod", T_base_work=np.diag([2.0, 1, 1, 1]))
    with pytest.raises(InputError, match="placement T_base_work"):
        write_rapid(tp, tmp_path / "a.mod", T_base_work=None)  # never a silent base frame
    with pytest.raises(InputError, match="not a RAPID module name"):
        write_rapid(tp, tmp_path / "next-part.mod", T_base_work=BASE)
    assert not list(tmp_path.iterdir())


# -- configuration data ---------------------------------------------------------------------------


def test_arm_config_bits_are_the_ik_branch_and_the_geometry():
    """front/ahead from the joint angles equal the IK branch, and the wrist centre's position
    computed by forward kinematics (an independent route)."""
    model = load_robot("kr210-r2700-2").with_tool(make_transform(p=[0, 0, 0.3]))
    g = model.opw
    tip = np.array([[0.03, 0.01, -0.02], [-0.02, 0.04, -0.03]])
    T_fl = tool_poses(tip, make_transform(p=[1.9, 0.3, 0.2])) @ invert(model.T_flange_tip)
    seen = set()
    for sh in ("front", "back"):
        for el in ("up", "down"):
            for wr in ("noflip", "flip"):
                q, ok = opw_ik(model, T_fl, shoulder=sh, elbow=el, wrist=wr)
                assert ok.all()
                c = arm_config(model, q)
                assert np.all(c.front == (sh == "front"))
                assert np.all((c.ahead == c.front) == (el == "up"))
                # forward kinematics: wrist centre = flange − c4·z_flange, in the axis-1 frame
                Tf = model.with_tool(np.eye(4)).fk(q, check_limits=False)
                C = Tf[:, :3, 3] - g.c4 * Tf[:, :3, 2]
                th1 = q[:, 0] * model.chain.sign[0] + model.chain.offset[0]
                x1 = np.cos(th1) * C[:, 0] + np.sin(th1) * C[:, 1]
                assert np.all((x1 > 0) == c.front)
                cf = abb_confdata(c)
                bits = (4 * (sh == "back"), 2 * (not c.ahead[0]), 1 * (q[0, 4] < 0))
                assert cf[0, 3] == sum(bits)
                seen.add(int(cf[0, 3]))
    assert seen == set(range(8))  # every cfx value is reached by one branch


def test_quadrants_at_minus_180_and_other_boundaries():
    """ABB quadrant = floor(q/90°): q6 = −180° is quadrant −2 whether the float lands a hair
    above or below; 180° is quadrant 2. FANUC turn numbers: [−180°, 180°) is turn 0."""
    pi = math.pi
    q6 = np.array([-pi, -pi + 1e-13, -pi - 1e-13, pi, -pi / 2, 0.0, -1e-14, 3 * pi / 2, -1.9 * pi])
    q = np.zeros((len(q6), 6))
    q[:, 5] = q6
    q[:, 4] = 0.5
    cfg = ArmConfig(q=q, front=np.ones(len(q6), bool), ahead=np.ones(len(q6), bool))
    cf6 = abb_confdata(cfg)[:, 2].tolist()
    assert cf6 == [-2, -2, -2, 2, -1, 0, 0, 3, -4]
    turns = [int(s.split(",")[3]) for s in fanuc_config(cfg)]
    assert turns == [0, 0, 0, 1, 0, 0, 0, 1, -1]
    st = kuka_status_turn(cfg)
    assert st[0, 1] == 32 and st[3, 1] == 0 and st[6, 1] == 0  # T bit 5: A6 < 0


def test_confdata_status_config_equal_the_ik_of_the_cell(tmp_path, cell):
    """The demo cell's path crosses q6 = −180°: confdata, S/T and CONFIG in the files equal the
    definitions applied here to the IK joint angles."""
    model, T, path, cfg = cell
    ik = ik_toolpath(model, path.tip, T)
    np.testing.assert_allclose(cfg.q, ik.q)
    d = np.degrees(ik.q)
    # the path really sits on the q6 = −180° boundary (both quadrants −2 and −3 occur)
    assert d[:, 5].min() < -180 < d[:, 5].max()
    write_rapid(path, tmp_path / "r.mod", T_base_work=T, config=cfg)
    conf = read_rapid(tmp_path / "r.mod").meta["confdata"]
    for j, col in ((0, 0), (3, 1), (5, 2)):
        lo, hi = conf[:, col] * 90.0, (conf[:, col] + 1) * 90.0
        assert np.all((lo <= d[:, j] + 1e-6) & (d[:, j] < hi + 1e-6))  # q in its quadrant
    assert set(conf[:, 2].tolist()) == {-3, -2}
    assert np.all(conf[:, 3] == (d[:, 4] < 0))  # in front of axis 1 and of the lower arm
    # KRL: S and T of the first PTP from the first point's joint angles
    write_krl(path, tmp_path / "k.src", T_base_work=T, config=cfg)
    s, t = read_krl(tmp_path / "k.src").meta["status_turn"]
    assert t == sum(1 << j for j in range(6) if d[0, j] < 0)
    assert s == 2 + 4 * (d[0, 4] < 0)  # basic area, elbow up, A5 sign
    # FANUC: CONFIG per point
    write_fanuc(path, tmp_path / "f.ls", T_base_work=T, config=cfg)
    confs = read_fanuc(tmp_path / "f.ls").meta["config"]
    assert confs == fanuc_config(cfg)
    assert all(c.startswith("N U T") for c in confs)


# -- KRL ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("gamma", [0.0, -1.1])
def test_krl_round_trip(tmp_path, tp, placement, gamma):
    f = tmp_path / "Cone_1.src"
    rot = np.full(len(tp), gamma)
    write_krl(
        tp, f, T_base_work=placement, tool=RobotTool(length=0.31), tool_rotation=rot, max_moves=150
    )
    assert (tmp_path / "Cone_1.dat").is_file()
    check_krl(f)
    back = read_krl(f)
    assert back.meta["def"] == back.meta["defdat"] == "Cone_1"
    assert len(back) == len(tp)
    assert np.abs(back.tip - tp.tip).max() <= HALF_UM
    expect = np.diag([1.0, -1.0, -1.0]) @ rot_z(rot)
    assert np.abs(back.R_work_tool - expect).max() < 1e-7
    np.testing.assert_allclose(back.meta["abc_deg"][0, :2], [-math.degrees(gamma), 0.0], atol=1e-6)
    np.testing.assert_allclose(back.T_base_work, placement, atol=1e-8)
    assert back.feed == pytest.approx(tp.feed, rel=1e-5)
    assert back.tool.length == pytest.approx(0.31)
    assert back.meta["status_turn"] is None  # no robot: no S/T, and the header says so
    text = f.read_text()
    assert "DEF Cone_1( )" in text and "$TOOL = TOOL_ISF" in text and "$BASE = BASE_ISF" in text
    assert "TOOL_ISF={X 310,Y 0,Z 0,A 0,B 90,C 0}" in (tmp_path / "Cone_1.dat").read_text()
    assert max_step(back.tip) <= max_step(tp.tip) + 1e-6


def test_krl_names_must_be_the_file_name(tmp_path, tp):
    with pytest.raises(InputError, match=r"\.src"):
        write_krl(tp, tmp_path / "p.krl", T_base_work=BASE)
    with pytest.raises(InputError, match=r"next_part\.src"):  # refused, with the name to use
        write_krl(tp, tmp_path / "next-part.src", T_base_work=BASE)
    with pytest.raises(InputError, match="24 characters"):
        write_krl(tp, tmp_path / ("a" * 25 + ".src"), T_base_work=BASE)
    with pytest.raises(InputError, match="placement"):
        write_krl(tp, tmp_path / "p.src", T_base_work=None)
    assert not list(tmp_path.iterdir())
    write_krl(tp, tmp_path / ("a" * 24 + ".src"), T_base_work=BASE)
    check_krl(tmp_path / ("a" * 24 + ".src"))


# -- FANUC ----------------------------------------------------------------------------------------


def test_fanuc_round_trip_and_split(tmp_path, cell):
    _, T, path, cfg = cell
    f = tmp_path / "cone.ls"
    files = write_fanuc(path, f, T_base_work=T, config=cfg, tool=RobotTool(length=0.306))
    assert files == [f]
    assert check_ls(f) == len(path) + 2  # approach + forming moves + retract
    back = read_fanuc(f)
    assert np.abs(back.tip - path.tip).max() <= HALF_UM
    assert np.abs(back.R_work_tool - np.diag([1.0, -1.0, -1.0])).max() < 1e-8
    np.testing.assert_allclose(back.T_base_work, T, atol=1e-9)  # UFRAME = the cell's
    assert back.tool.length == pytest.approx(0.306)
    assert back.feed == pytest.approx(path.feed)  # 750 mm/min = 75 cm/min
    assert "75cm/min CNT100" in f.read_text()
    # split into CALLed sub-programs, each at most the limit
    g = tmp_path / "big.ls"
    files = write_fanuc(path, g, T_base_work=T, config=cfg, max_module_moves=300)
    assert len(files) > 2
    for sub in files[1:]:
        assert 0 < check_ls(sub) <= 300
    check_ls(g)
    back2 = read_fanuc(g)
    assert back2.meta["sub_programs"] == [p.stem.upper() for p in files[1:]]
    assert np.abs(back2.tip - path.tip).max() <= HALF_UM
    assert back2.meta["config"] == fanuc_config(cfg)
    assert max_step(back2.tip) <= max_step(path.tip) + 1e-6
    with pytest.raises(InputError, match="placement"):
        write_fanuc(path, tmp_path / "x.ls", T_base_work=None)
    with pytest.raises(InputError, match="FANUC program name"):
        write_fanuc(path, tmp_path / "1x.ls", T_base_work=T)


# -- all formats ----------------------------------------------------------------------------------


def test_spiral_programs_round_trip(tmp_path):
    tp = spiral(Cone(depth=3e-3), 5e-3, 0.5e-3, spacing=3e-3)
    for name in ("s.src", "s.mod", "s.nc", "s.ls"):
        write_toolpath(tp, tmp_path / name, T_base_work=BASE)
    for back in (
        read_krl(tmp_path / "s.src"),
        read_rapid(tmp_path / "s.mod"),
        read_gcode(tmp_path / "s.nc"),
        read_fanuc(tmp_path / "s.ls"),
    ):
        assert np.abs(back.tip - tp.tip).max() <= HALF_UM


def test_output_mode(tmp_path, tp):
    out = tmp_path / "p.ls"
    write_fanuc(tp, out, T_base_work=BASE)
    # atomic output is renamed from a private temp file: it must get the usual 0o666 & ~umask
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(os.stat(out).st_mode) == 0o666 & ~mask


def test_readers_refuse_broken_program_sets(tmp_path, tp):
    """A missing part module, a bad LS line number or a non-UTF-8 file: InputError naming the
    file, never a traceback."""
    write_rapid(tp, tmp_path / "s.mod", T_base_work=BASE, max_module_moves=400)
    (tmp_path / "s_2.mod").unlink()
    with pytest.raises(InputError, match="not found") as ei:
        read_rapid(tmp_path / "s.mod")
    assert ei.value.file.endswith("s_2.mod")
    write_fanuc(tp, tmp_path / "f.ls", T_base_work=BASE)
    text = (tmp_path / "f.ls").read_text()
    (tmp_path / "f.ls").write_text(text.replace("   5:", "   7:", 1))
    with pytest.raises(InputError, match="expected line 5"):
        read_fanuc(tmp_path / "f.ls")
    (tmp_path / "f.ls").write_bytes(b"/PROG \xff\xfe\n")
    with pytest.raises(InputError, match="UTF-8"):
        read_fanuc(tmp_path / "f.ls")


@pytest.mark.parametrize("name", ["p.nc", "p.src", "p.mod"])
def test_non_utf8_program_is_an_input_error(tmp_path, name):
    f = tmp_path / name
    f.write_bytes(b"\xff\xfe garbage\n")
    reader = {"p.nc": read_gcode, "p.src": read_krl, "p.mod": read_rapid}[name]
    with pytest.raises(InputError, match="UTF-8"):
        reader(f)


def test_fmt_num_is_the_shortest_fixed_point_text():
    """Controllers read these numbers: trailing zeros go, the integer part's never (``nd=0``
    wrote 10 as "1" and -0.4 as "-"), no "-0"."""
    from roboisf.cam.program import fmt_num
    from roboisf.programs.krl import frame_to_krl

    assert [fmt_num(v) for v in (12.5, 12.0, 100.0, -0.0004, 0.0, 1e-9, -2.25)] == [
        "12.5", "12", "100", "0", "0", "0", "-2.25"
    ]  # fmt: skip
    assert [fmt_num(v, 0) for v in (10.0, 100.0, -0.4, 2.6, 0.0)] == ["10", "100", "0", "3", "0"]
    assert fmt_num(90.00000004, 6) == "90"
    assert frame_to_krl([10, 200, 0], [0, 90, 180], nd_angle=0) == "{X 10,Y 200,Z 0,A 0,B 90,C 180}"
