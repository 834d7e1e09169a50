"""Program writers (G-code, ABB RAPID, KUKA KRL): round trip through their parsers.

Programs are written at 1 µm (0.001 mm), so positions come back to ≤ 0.5 µm (+ float noise)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.frames.rotations import rot_z
from roboisf.frames.se3 import make_transform
from roboisf.io.gcode import read_gcode, write_gcode
from roboisf.io.krl import read_krl, write_krl
from roboisf.io.program import RobotTool
from roboisf.io.rapid import read_rapid, write_rapid
from roboisf.parts import Cone
from roboisf.toolpath import spiral, step_down

HALF_UM = 0.5e-6 + 1e-12


@pytest.fixture(scope="module")
def tp():
    return step_down(Cone(depth=6e-3), 5e-3, 0.5e-3, spacing=2e-3)


@pytest.fixture(scope="module")
def placement():
    return make_transform(rot_z(math.radians(30.0)), [1.6, -0.2, 0.7])


def test_gcode_round_trip(tmp_path, tp):
    f = tmp_path / "p.nc"
    write_gcode(tp, f, safe_height=15e-3)
    text = f.read_text()
    assert "G21 G90" in text
    assert "F750.0" in text
    back = read_gcode(f)
    assert len(back) == len(tp)
    assert np.abs(back.tip - tp.tip).max() <= HALF_UM
    assert back.feed == pytest.approx(tp.feed)
    # every line of the body is a full X Y Z move in mm at 3 decimals
    body = [ln for ln in text.splitlines() if ln.startswith("G01")]
    assert all(
        re.fullmatch(r"G01 X-?\d+\.\d{3} Y-?\d+\.\d{3} Z-?\d+\.\d{3}( F\d+\.\d)?", ln)
        for ln in body
    )


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
    f.write_text("G91\nG1 X1 F100\n")
    with pytest.raises(InputError, match="G91") as ei:
        read_gcode(f)
    assert ei.value.line == 1
    f.write_text("G90\nG1 X1 Y1 Z1\n")
    with pytest.raises(InputError, match="before any F"):
        read_gcode(f)
    f.write_text("G90\nG1 X1 Y1 Z1 F10 Q?\n")
    with pytest.raises(InputError, match="cannot parse"):
        read_gcode(f)


@pytest.mark.parametrize("gamma", [0.0, 0.7])
def test_rapid_round_trip(tmp_path, tp, placement, gamma):
    f = tmp_path / "cone path.mod"
    tool = RobotTool(length=0.245, mass=3.5, name="tIsf")
    rot = np.linspace(0.0, gamma, len(tp))
    write_rapid(tp, f, T_base_work=placement, tool=tool, tool_rotation=rot, max_moves=100)
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
    for proc in re.findall(r"PROC \w+\(\)\n(.*?)ENDPROC", text, re.S)[1:]:
        assert proc.count("MoveL") <= 100


def test_rapid_bad_options(tmp_path, tp):
    with pytest.raises(InputError, match="unknown zone"):
        write_rapid(tp, tmp_path / "a.mod", zone="z7")
    with pytest.raises(InputError, match="rigid transform"):
        write_rapid(tp, tmp_path / "a.mod", T_base_work=np.diag([2.0, 1, 1, 1]))
    assert not (tmp_path / "a.mod").exists()


@pytest.mark.parametrize("gamma", [0.0, -1.1])
def test_krl_round_trip(tmp_path, tp, placement, gamma):
    f = tmp_path / "Cone-1.src"
    rot = np.full(len(tp), gamma)
    write_krl(
        tp, f, T_base_work=placement, tool=RobotTool(length=0.31), tool_rotation=rot, max_moves=150
    )
    assert (tmp_path / "Cone-1.dat").is_file()
    back = read_krl(f)
    assert len(back) == len(tp)
    assert np.abs(back.tip - tp.tip).max() <= HALF_UM
    expect = np.diag([1.0, -1.0, -1.0]) @ rot_z(rot)
    assert np.abs(back.R_work_tool - expect).max() < 1e-7
    np.testing.assert_allclose(back.meta["abc_deg"][0, :2], [-math.degrees(gamma), 0.0], atol=1e-6)
    np.testing.assert_allclose(back.T_base_work, placement, atol=1e-8)
    assert back.feed == pytest.approx(tp.feed, rel=1e-5)
    assert back.tool.length == pytest.approx(0.31)
    text = f.read_text()
    assert "DEF cone_1( )" in text and "$TOOL = TOOL_ISF" in text and "$BASE = BASE_ISF" in text
    assert "TOOL_ISF={X 310,Y 0,Z 0,A 0,B 90,C 0}" in (tmp_path / "Cone-1.dat").read_text()


def test_spiral_programs_round_trip(tmp_path):
    tp = spiral(Cone(depth=3e-3), 5e-3, 0.5e-3, spacing=3e-3)
    write_krl(tp, tmp_path / "s.src")
    write_rapid(tp, tmp_path / "s.mod")
    write_gcode(tp, tmp_path / "s.nc")
    for back in (
        read_krl(tmp_path / "s.src"),
        read_rapid(tmp_path / "s.mod"),
        read_gcode(tmp_path / "s.nc"),
    ):
        assert np.abs(back.tip - tp.tip).max() <= HALF_UM


def test_krl_wrong_suffix(tmp_path, tp):
    with pytest.raises(InputError, match=r"\.src"):
        write_krl(tp, tmp_path / "p.krl")
