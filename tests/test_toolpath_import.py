"""CAM toolpath import (issue #13 item 1): every dialect from files written by hand, arcs against
the analytic circle, a roboisf toolpath through G-code and back, and one error per malformed
case naming the line."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from roboisf.cam.apt import read_apt_moves
from roboisf.cam.cam import FEED, RAPID, ReadOptions, arc_points
from roboisf.cam.gcode import read_gcode, read_iso_moves, write_gcode
from roboisf.cam.sinumerik import read_sinumerik_moves
from roboisf.cam.toolpath_csv import read_toolpath_csv, write_toolpath_csv
from roboisf.cam.xyz import read_xyz_moves
from roboisf.errors import InputError
from roboisf.parts import Cone
from roboisf.toolpath import spiral, step_down
from roboisf.toolpath.importer import (
    ImportOptions,
    detect_toolpath_format,
    import_toolpath,
    load_toolpath,
)

MM = 1e-3
UM = 1e-6


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def feed_pts(moves) -> np.ndarray:
    return moves.point[moves.kind == FEED] / MM


# -- ISO / Fanuc / Haas ---------------------------------------------------------------------------

FANUC = """%
O2002 (SPIF CONE TEST)
(T1 BALL D10)
N10 G21 G17 G40 G49 G80 G90
N20 G28 G91 Z0.
N30 G90 G54
N40 T1 M06
N50 G00 G43 H1 Z10. M03 S0
N60 X20. Y0.
N70 G01 Z0. F1000. ; touch the sheet
N80 Z-.5
N90 G03 X20. Y0. I-20. J0. ; full circle
N100 G01 X19.5 Z-1.
N110 G02 X-19.5 Y0. R19.5
N120 G00 Z10.
N130 G28 G91 Z0.
N140 M30
%
"""


def test_fanuc_program_with_percent_number_g28_and_arcs(tmp_path):
    f = write(tmp_path, "cone.nc", FANUC.replace("%\nO2002", "%2002\nO2002"))
    m = read_iso_moves(f)
    # G28 G91 Z0: Z to the reference point (unknown in the work frame), a rapid; then G90
    assert m.kind[0] == RAPID and np.isnan(m.point[1, 2])
    # the first feed move: X20 Y0 Z0 (Z0. and Z-.5 numbers), F in mm/min
    p = feed_pts(m)
    np.testing.assert_allclose(p[0], [20, 0, 0], atol=1e-12)
    np.testing.assert_allclose(p[1], [20, 0, -0.5], atol=1e-12)
    assert m.feed[m.kind == FEED][0] == pytest.approx(1000 * MM / 60)
    # the full circle: every point at radius 20 about the origin, ends where it started
    circ = m.point[m.line == 12] / MM
    np.testing.assert_allclose(np.hypot(circ[:, 0], circ[:, 1]), 20, atol=1e-9)
    np.testing.assert_allclose(circ[-1], [20, 0, -0.5], atol=1e-12)
    phi = np.unwrap(np.arctan2(circ[:, 1], circ[:, 0]))
    assert phi[-1] == pytest.approx(2 * math.pi)  # counter-clockwise, one turn
    # G02 … R19.5 from (19.5, 0) to (−19.5, 0): clockwise half circle through (0, −19.5)
    half = m.point[m.line == 14] / MM
    assert half[len(half) // 2, 1] == pytest.approx(-19.5, abs=0.05)
    assert "M codes ignored" in " ".join(m.notes) and "M6" in " ".join(m.notes)
    assert m.meta["program"] == "%2002" and m.meta["work_offsets"] == ["G54"]
    assert m.meta["tools"] == [1] and m.meta["length_compensation"] == [1]


#: (G, form) → centre of the arc from (a, b) = (r, 0) to (0, r) in units of r, and its sweep.
#: G3 is counter-clockwise seen from the tip of the plane's normal (right-handed a → b), G2
#: clockwise; R > 0 picks the arc of at most 180°, R < 0 the longer one (ISO 6983, Fanuc).
ARCS = {
    (3, "ijk"): ((0, 0), math.pi / 2),
    (2, "ijk"): ((0, 0), -3 * math.pi / 2),
    (3, "r"): ((0, 0), math.pi / 2),
    (2, "r"): ((1, 1), -math.pi / 2),
    (3, "r-long"): ((1, 1), 3 * math.pi / 2),
    (2, "r-long"): ((0, 0), -3 * math.pi / 2),
}


@pytest.mark.parametrize("plane", [17, 18, 19])
@pytest.mark.parametrize(("g", "form"), list(ARCS))
def test_arc_in_every_plane_against_the_analytic_circle(tmp_path, plane, g, form):
    # the plane's axes (a, b) and normal c = a × b: G17 XY/Z, G18 ZX/Y, G19 YZ/X
    a, b, c = {17: ("X", "Y", "Z"), 18: ("Z", "X", "Y"), 19: ("Y", "Z", "X")}[plane]
    ia, ib = {"X": "I", "Y": "J", "Z": "K"}[a], {"X": "I", "Y": "J", "Z": "K"}[b]
    r = 12.5
    arc = {"ijk": f"{ia}{-r:g} {ib}0", "r": f"R{r:g}", "r-long": f"R{-r:g}"}[form]
    text = f"G21 G90 G{plane}\nG0 {a}{r:g} {b}0 {c}0\nG1 {c}0 F600\nG{g} {a}0 {b}{r:g} {arc}\n"
    tol = 0.002 * MM
    m = read_iso_moves(write(tmp_path, "a.nc", text), ReadOptions(chord_tol=tol))
    ax = {"X": 0, "Y": 1, "Z": 2}
    arc_pts = m.point[m.line == 4]
    (ca, cb), sweep = ARCS[(g, form)]
    pts = np.column_stack([np.r_[r, arc_pts[:, ax[a]] / MM], np.r_[0.0, arc_pts[:, ax[b]] / MM]])
    rel = pts - np.array([ca, cb]) * r
    # every vertex on the analytic circle, every chord within the tolerance of it (sagitta)
    np.testing.assert_allclose(np.hypot(rel[:, 0], rel[:, 1]), r, atol=1e-9)
    mid = 0.5 * (rel[1:] + rel[:-1])
    sag = (r - np.hypot(mid[:, 0], mid[:, 1])) * MM
    assert sag.max() <= tol * (1 + 1e-6) and sag.max() > 0.5 * tol
    # the direction and length of the arc
    phi = np.unwrap(np.arctan2(rel[:, 1], rel[:, 0]))
    assert phi[-1] - phi[0] == pytest.approx(sweep)
    np.testing.assert_allclose(arc_pts[-1, [ax[a], ax[b]]], [0, r * MM], atol=1e-15)
    np.testing.assert_allclose(arc_pts[:, ax[c]], 0, atol=1e-15)  # in the plane, no helix


def test_arc_points_chord_error_and_helix():
    c = np.zeros(3)
    for r, tol in ((40e-3, 1e-6), (2e-3, 1e-5), (0.5e-3, 1e-3)):
        start, end = np.array([r, 0, 0]), np.array([r, 0, -2e-3])  # full turn, 2 mm down
        pts = arc_points(start, end, c, np.array([0, 0, 1.0]), True, tol)
        allp = np.vstack([start, pts])
        rad = np.hypot(allp[:, 0], allp[:, 1])
        np.testing.assert_allclose(rad, r, rtol=1e-12)
        mid = 0.5 * (allp[1:, :2] + allp[:-1, :2])
        assert (r - np.hypot(mid[:, 0], mid[:, 1])).max() <= tol * (1 + 1e-9)
        # helical: z linear in the angle, one full turn
        phi = np.unwrap(np.arctan2(allp[:, 1], allp[:, 0]))
        assert phi[-1] == pytest.approx(2 * math.pi)
        np.testing.assert_allclose(allp[:, 2], -2e-3 * phi / (2 * math.pi), atol=1e-15)
    with pytest.raises(InputError, match="not on the circle") as ei:
        arc_points(np.array([10e-3, 0, 0]), np.array([0, 11e-3, 0]), c, [0, 0, 1], True, 1e-6,
                   line=7)  # fmt: skip
    assert ei.value.line == 7


HAAS = """%
O00001 (CONE SPIF)
(T1 D=10. CR=5. - ZMIN=-1. - BALL END MILL)
G00 G17 G40 G49 G80 G90
G187 P1 E0.0005
G103 P1
G154 P1
T1 M06
G43 H01 Z15.
G00 X20. Y0.
G01 Z0. F500.
G01 Z-1.
G17 G02 X20. Y0. Z-2. I-20. J0. (one helical turn down 1 mm)
G05.1 Q1
G01 X10.
G05.1 Q0
G00 Z15.
G28 G91 Z0.
G90
M30
%
"""


def test_haas_and_fanuc_high_speed_words_and_a_helix(tmp_path):
    m = read_iso_moves(write(tmp_path, "haas.nc", HAAS))
    helix = m.point[m.line == 13] / MM
    np.testing.assert_allclose(np.hypot(helix[:, 0], helix[:, 1]), 20, atol=1e-9)
    phi = np.unwrap(np.arctan2(helix[:, 1], helix[:, 0]))
    assert phi[-1] == pytest.approx(-2 * math.pi)  # G02: one clockwise turn
    np.testing.assert_allclose(helix[:, 2], -1 + phi / (2 * math.pi), atol=1e-12)  # linear in z
    notes = " ".join(m.notes)
    for word in ("G187", "G103", "G5.1"):
        assert word in notes
    assert m.meta["work_offsets"] == ["G154P1"]
    f = write(tmp_path, "m97.nc", "G90\nM97 P1000\n")
    with pytest.raises(InputError, match="M97") as ei:
        read_iso_moves(f)
    assert ei.value.line == 2


def test_absolute_arc_centres_and_linuxcnc_blending(tmp_path):
    # G90.1: I/J are the centre itself; G91.1: back to offsets from the start; G64 P0.01 noted
    text = (
        "G21 G90 G17 G64 P0.01\nG0 X30 Y10 Z0\nG1 Z-1 F600\n"
        "G90.1 G3 X10 Y30 I10 J10\nG91.1 G2 X30 Y10 I0 J-20\n"
    )
    m = read_iso_moves(write(tmp_path, "abs.nc", text.replace("G91.1", "G04 X1.5\nG91.1")))
    assert m.dwell[m.line == 6][0] == 1.5  # the dwell in seconds, before the next move
    for line in (4, 6):
        p = m.point[m.line == line] / MM
        np.testing.assert_allclose(np.hypot(p[:, 0] - 10, p[:, 1] - 10), 20, atol=1e-9)
    assert any("G64" in n for n in m.notes)


def test_inverse_time_feed(tmp_path):
    # G93: F is 1/minutes of the move: 10 mm in 1/2 min → 20 mm/min; 5 mm in 1/5 min → 25 mm/min
    f = write(tmp_path, "g93.nc", "G21 G90\nG0 X0 Y0 Z0\nG93 G1 X10 F2\nY5 F5\nG94 G1 X0 F100\n")
    m = read_iso_moves(f)
    np.testing.assert_allclose(m.feed[1:] * 60 / MM, [20, 25, 100])
    f = write(tmp_path, "g93b.nc", "G21 G90\nG0 X0 Y0 Z0\nG93 G1 X10 F2\nY5\n")
    with pytest.raises(InputError, match="F word on every feed move") as ei:
        read_iso_moves(f)
    assert ei.value.line == 4


def test_inch_and_incremental(tmp_path):
    f = write(
        tmp_path,
        "i.nc",
        "G20 G90\nG0 X1. Y0 Z0.1\nG1 Z0 F20.\nG91 G1 X-0.5 Y0.25 Z-0.02\nX.5\nG90 G1 X0 Y0\n",
    )
    m = read_iso_moves(f)
    assert not m.dwell.any()
    np.testing.assert_allclose(
        feed_pts(m) / 25.4,
        [[1, 0, 0], [0.5, 0.25, -0.02], [1.0, 0.25, -0.02], [0, 0, -0.02]],
        atol=1e-12,
    )
    assert m.feed[1] == pytest.approx(20 * 25.4 * MM / 60)
    assert m.meta["units"] == ["inch"]


def test_work_offsets_values_or_warning(tmp_path):
    text = "G21 G90 G54\nG0 X0 Y0 Z5\nG1 Z0 F100\nX10\nG55\nG1 X0\nM30\n"
    f = write(tmp_path, "w.nc", text)
    m = read_iso_moves(f)
    assert any("G55" in w and "not given" in w for w in m.warnings)
    np.testing.assert_allclose(feed_pts(m)[-1], [0, 0, 0])
    opt = ReadOptions(work_offsets={"G54": (0.1, 0.2, -0.3), "G55": (0.15, 0.2, -0.3)})
    m = read_iso_moves(f, opt)
    assert not m.warnings
    np.testing.assert_allclose(feed_pts(m)[-1], [50, 0, 0], atol=1e-9)  # G55 is 50 mm along X
    # G53: machine coordinates in this block only
    f = write(tmp_path, "w53.nc", "G54 G90\nG0 X0 Y0 Z5\nG53 G0 Z-100\nG1 X1 Y1 Z0 F100\n")
    m = read_iso_moves(f, ReadOptions(work_offsets={"G54": (0.0, 0.0, -0.3)}))
    assert m.point[1, 2] == pytest.approx(0.2)  # −100 mm machine = +200 mm in G54
    m = read_iso_moves(f)
    assert np.isnan(m.point[1, 2]) and any("G53" in n for n in m.notes)


def test_sinumerik_safe_start_offset_is_not_the_reference(tmp_path):
    f = write(tmp_path, "s.mpf", "G500\nG54 G90\nG0 X0 Y0 Z=5\nG1 Z=0 F=100\nX10\n")
    m = read_sinumerik_moves(f)
    assert not m.warnings and m.meta["work_offsets"] == ["G500", "G54"]


def test_extra_axis_words_error_or_warning(tmp_path):
    f = write(tmp_path, "a.nc", "G90 G0 X0 Y0 Z5\nG1 Z0 F100\nG1 X1 A5.\nG1 X2 A6\n")
    with pytest.raises(InputError, match="A word") as ei:
        read_iso_moves(f)
    assert ei.value.line == 3
    m = read_iso_moves(f, ReadOptions(ignore_words=frozenset("A")))
    assert m.warnings == ["A words ignored on 2 line(s) (3, 4): the path is read as 3-axis XYZ"]


@pytest.mark.parametrize(
    ("text", "line", "match"),
    [
        ("G90\nG0 X0 Y0 Z1\nG92 X0\n", 3, "G92"),
        ("G90\nG65 P9010\n", 2, "unknown G code G65"),
        ("G90\nG0 X0 Y0 Z1\nG1 X1 F100 (open\n", 3, "not closed"),
        ("G90\nG0 X0 Y0 Z0\nG1 X1\n", 3, "before any F"),
        ("G90\nG0 X10 Y0 Z0\nG2 X0 Y11 I-10 F100\n", 3, "not on the circle"),
        ("G90\nG0 X10 Y0 Z0\nG2 X0 Y50 R10 F100\n", 3, "smaller than half the chord"),
        ("G90\nG0 X10 Y0 Z0\nG2 X0 Y10 F100\n", 3, "arc without centre"),
        ("G90\nG0 X10 Y0 Z0\nG41 D1\n", 3, "cutter radius compensation"),
        ("G90\nG0 X10 Y0 Z0\nG81 X1 Y1 Z-1 R1 F100\n", 3, "canned cycle"),
        ("G90\nG0 X0 Y0 Z1\n#100=5\n", 3, "cannot parse"),
        ("G90\nG0 X0 Y0 Z1\nM98 P1000\n", 3, "subprogram"),
        ("G90\nG0 X0 Y0 Z1\nG1 X1 X2 F100\n", 3, "X given twice"),
        ("G90\nG0 X0 Y0 Z1\nG1 X1 E2 F100\n", 3, "unknown address"),
    ],
)
def test_iso_errors_name_the_line(tmp_path, text, line, match):
    f = write(tmp_path, "bad.nc", text)
    with pytest.raises(InputError, match=match) as ei:
        read_iso_moves(f)
    assert ei.value.line == line and str(f) in str(ei.value)


def test_read_gcode_keeps_reading_roboisf_programs(tmp_path):
    tp = step_down(Cone(depth=3e-3), 5e-3, 0.5e-3, spacing=2e-3)
    write_gcode(tp, tmp_path / "p.nc")
    back = read_gcode(tmp_path / "p.nc")
    assert np.abs(back.tip - tp.tip).max() <= 0.5 * UM
    assert back.feed == pytest.approx(tp.feed)


# -- Sinumerik ------------------------------------------------------------------------------------

MPF = """%_N_CONE_MPF
;$PATH=/_N_MPF_DIR
; cone, ball 10 mm
N10 G17 G71 G90 G54 G642 SOFT FFWON
N20 CYCLE832(0.01,_FINISH,1)
N30 T="BALL10" D1 M6
N40 G0 X0 Y0 Z=50
N50 G0 X=40 Y=0
N60 G1 Z=0 F=1000
N70 G1 Z=-1
N80 G3 X=40 Y0 I=-40 J=0
N90 G1 X=IC(-1) Z=AC(-2)
N100 G2 X0 Y39 CR=-39
N110 G0 Z50
N120 M30
"""


def test_sinumerik_program(tmp_path):
    f = write(tmp_path, "cone.mpf", MPF)
    assert detect_toolpath_format(f) == "sinumerik"
    m = read_sinumerik_moves(f)
    p = feed_pts(m)
    np.testing.assert_allclose(p[:2], [[40, 0, 0], [40, 0, -1]], atol=1e-12)
    circ = m.point[m.line == 11] / MM
    np.testing.assert_allclose(np.hypot(circ[:, 0], circ[:, 1]), 40, atol=1e-9)
    np.testing.assert_allclose(m.point[m.line == 12][0] / MM, [39, 0, -2], atol=1e-12)
    # CR=-39: the long (270°) clockwise arc from (39, 0) to (0, 39), through (−27.6, −27.6)
    long = m.point[m.line == 13] / MM
    np.testing.assert_allclose(np.hypot(long[:, 0], long[:, 1]), 39, atol=1e-9)
    assert long[len(long) // 2, 0] < -20 and long[len(long) // 2, 1] < -20
    notes = " ".join(m.notes)
    for word in ("G642", "SOFT", "FFWON", "CYCLE832", "M6 M30"):
        assert word in notes
    assert m.meta["program"] == "%_N_CONE_MPF"


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("G90\nR1=5\n", "unknown address 'R1'"),
        ("G90\nTRANS X10\n", "TRANS"),
        ("G90\nCYCLE81(10,0,2,-5)\n", "machining cycle CYCLE81"),
        ("G90\nG0 X=SIN(30)\n", "cannot read"),
        ("G90\nFOO\n", "unknown keyword 'FOO'"),
    ],
)
def test_sinumerik_errors_name_the_line(tmp_path, text, match):
    f = write(tmp_path, "bad.mpf", text)
    with pytest.raises(InputError, match=match) as ei:
        read_sinumerik_moves(f)
    assert ei.value.line == 2


# -- APT / CL data --------------------------------------------------------------------------------

APT = """PARTNO / SPIF CONE
UNITS/MM
CUTTER/10.0
LOADTL/1
MULTAX
TLAXIS/0.0,0.0,1.0
RAPID
GOTO/20.0,0.0,10.0,0.0,0.0,1.0
FEDRAT/MMPM,1200.0
GOTO/20.0,0.0,0.0
GOTO / 20.0 , 0.0 , -0.5
CIRCLE/0.0,0.0,-0.5,0.0,0.0,1.0,20.0
GOTO/0.0,20.0,-0.5
GOTO/0.0,19.5,$
-1.0
RAPID
GOTO/0.0,19.5,10.0
FINI
"""


def test_apt_program(tmp_path):
    f = write(tmp_path, "cone.apt", APT)
    assert detect_toolpath_format(f) == "apt"
    m = read_apt_moves(f)
    assert m.kind[0] == RAPID and m.kind[-1] == RAPID
    p = feed_pts(m)
    np.testing.assert_allclose(p[0], [20, 0, 0])
    arc = m.point[m.line == 13] / MM
    np.testing.assert_allclose(np.hypot(arc[:, 0], arc[:, 1]), 20, atol=1e-9)
    assert np.all(arc[:, 1] >= -1e-12)  # counter-clockwise about +z: through the first quadrant
    np.testing.assert_allclose(p[-1], [0, 19.5, -1.0])  # the $ continuation line
    assert m.feed[m.kind == FEED][0] == pytest.approx(1.2 / 60)
    assert m.meta["cutter_diameter"] == pytest.approx(10e-3)
    # inches, FEDRAT/f,IPM
    f = write(tmp_path, "in.cls", "UNITS/INCHES\nFEDRAT/40,IPM\nGOTO/1,0,0\nGOTO/1,1,0\n")
    m = read_apt_moves(f)
    np.testing.assert_allclose(m.point[-1], [0.0254, 0.0254, 0])
    assert m.feed[0] == pytest.approx(40 * 0.0254 / 60)


@pytest.mark.parametrize(
    ("text", "line", "match"),
    [
        ("UNITS/MM\nGOTO/1,2,3\n", 2, "before any FEDRAT"),
        ("UNITS/MM\nGOTO/1,2\n", 2, "expected x,y,z"),
        ("UNITS/MM\nFEDRAT/100\nGOTO/1,2,x\n", 3, "is not a number"),
        ("UNITS/MM\nSPLINE/1,2,3\n", 2, "unknown APT statement 'SPLINE'"),
        ("UNITS/FEET\n", 1, "MM or INCHES"),
    ],
)
def test_apt_errors_name_the_line(tmp_path, text, line, match):
    f = write(tmp_path, "bad.apt", text)
    with pytest.raises(InputError, match=match) as ei:
        read_apt_moves(f)
    assert ei.value.line == line


def test_tilted_tool_axis_is_refused(tmp_path):
    part = Cone(depth=10e-3)
    text = "UNITS/MM\nFEDRAT/600\nGOTO/20,0,-1,0,0,1\nGOTO/20,1,-1,0.1,0,0.995\n"
    f = write(tmp_path, "tilt.apt", text)
    with pytest.raises(InputError, match="tilted") as ei:
        import_toolpath(f, part, 5e-3)
    assert ei.value.line == 4


# -- bare x,y,z lists -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "text",
    [
        "20,0,0\n19.5,1,-0.5\n19,2,-1\n",
        "# units: mm\n20;0;0\n19,5;1;-0,5\n19;2;-1\n",
        "20\t0\t0\n19.5\t1\t-0.5\n19\t2\t-1\n",
        "20\t0\t0\n19,5\t1\t-0,5\n19\t2\t-1\n",
        "  20   0  0\n 19.5 1 -0.5\n19 2  -1\n",
        "X;Y;Z\n20;0;0\n19,5;1;-0,5\n19;2;-1\n",
        "x,y,z,i,j,k\n20,0,0,0,0,1\n19.5,1,-0.5,0,0,1\n19,2,-1,0,0,1\n",
        "# units: m\n0.020 0 0\n0.0195 0.001 -0.0005\n0.019 0.002 -0.001\n",
    ],
)
def test_xyz_any_separator(tmp_path, text):
    f = write(tmp_path, "p.xyz", text)
    assert detect_toolpath_format(f) == "xyz"
    m = read_xyz_moves(f, feed=0.01)
    np.testing.assert_allclose(m.point / MM, [[20, 0, 0], [19.5, 1, -0.5], [19, 2, -1]])
    assert np.all(m.kind == FEED) and np.all(m.feed == 0.01)
    data_lines = [n for n, s in enumerate(text.splitlines(), 1) if s.strip()[:1] in "0123456789"]
    assert list(m.line) == data_lines


@pytest.mark.parametrize(
    ("text", "line", "match"),
    [
        ("1,2,3\n4,5,x\n", 2, "'x' is not a finite number"),
        ("1,2,3\n4,5\n", 2, "missing"),
        ("1,2,3,4\n", 1, "4 values per row"),
        ("a,b,c\n1,2,3\n", 1, "expected the columns x, y, z"),
        ("1;2;3\n4;5;nan\n", 2, "not a finite number"),
    ],
)
def test_xyz_errors_name_the_line(tmp_path, text, line, match):
    f = write(tmp_path, "bad.txt", text)
    with pytest.raises(InputError, match=match) as ei:
        read_xyz_moves(f)
    assert ei.value.line == line


# -- the toolpath against the part ----------------------------------------------------------------


@pytest.fixture(scope="module")
def cone():
    return Cone(depth=8e-3)


@pytest.mark.parametrize("gen", [step_down, spiral])
def test_roboisf_path_through_gcode_and_back(tmp_path, cone, gen):
    """A roboisf cone path exported as G-code (1 µm resolution) and imported: the same points,
    tips and contacts within 1 µm, the same laps, times from the feed."""
    tp = gen(cone, 5e-3, 0.5e-3, spacing=1e-3)
    write_gcode(tp, tmp_path / "p.nc")
    back = import_toolpath(tmp_path / "p.nc", cone, 5e-3)
    assert len(back) == len(tp)
    assert np.abs(back.tip - tp.tip).max() <= UM
    assert np.abs(back.contact - tp.contact).max() <= UM
    assert np.abs(back.normal - tp.normal).max() <= 1e-3
    np.testing.assert_array_equal(back.lap, tp.lap)
    assert back.meta["laps_rule"] == ("z-level" if gen is step_down else "spiral")
    assert back.feed == pytest.approx(tp.feed)
    np.testing.assert_allclose(back.time, tp.time, atol=2 * UM * len(tp) / tp.feed)
    np.testing.assert_allclose(back.wall_angle, tp.wall_angle, atol=1e-3)
    assert back.meta["gap_max"] < UM and not back.meta["warnings"]
    # and through the CSV writer and reader
    write_toolpath_csv(back, tmp_path / "p.csv")
    again = read_toolpath_csv(tmp_path / "p.csv")
    np.testing.assert_allclose(again.tip, back.tip, atol=1e-12)


@pytest.mark.parametrize("spiral_path", [False, True])
def test_pyramid_path_through_gcode_and_back(tmp_path, spiral_path):
    """Any part: the ball-centre slicer's pyramid path (ramps between laps, rounded corners)."""
    from roboisf.parts import Pyramid
    from roboisf.toolpath import toolpath_for_part

    part = Pyramid(top_length=60e-3, top_width=60e-3, wall_angle=math.radians(50), depth=6e-3)
    tp = toolpath_for_part(part, 5e-3, 1e-3, spacing=2e-3, spiral=spiral_path)
    write_gcode(tp, tmp_path / "p.nc")
    back = import_toolpath(tmp_path / "p.nc", part, 5e-3)
    assert len(back) == len(tp)
    np.testing.assert_array_equal(back.lap, tp.lap)
    assert back.meta["laps_rule"] == ("spiral" if spiral_path else "z-level")
    assert np.abs(back.tip - tp.tip).max() <= UM
    # in the rounded corners (vertical-axis radius ≥ 10 − 6/tan 50° = 5 mm, normal-section radius
    # ρ ≥ 5/sin 50° = 6.5 mm) the contact moves ρ/(ρ − R) ≤ 4.4 times the tip's rounding
    # (≤ √3 · 0.5 µm): ≤ 3.8 µm (docs/toolpaths.md); on the flat walls as much as the tip
    assert np.abs(back.contact - tp.contact).max() <= 4.4 * math.sqrt(3) * 0.5 * UM


def test_center_programs_and_the_wrong_point(tmp_path, cone):
    tp = step_down(cone, 5e-3, 1e-3, spacing=2e-3)
    centre = tp.center / MM
    body = "".join(f"G1 X{x:.4f} Y{y:.4f} Z{z:.4f}\n" for x, y, z in centre)
    f = write(tmp_path, "c.nc", "G90 G21\nG0 X0 Y0 Z20\nG1 F900\n" + body)
    back = import_toolpath(f, cone, 5e-3, ImportOptions(point="center"))
    assert np.abs(back.tip - tp.tip).max() <= 0.1 * UM
    np.testing.assert_array_equal(back.lap, tp.lap)
    # read as tips: the ball floats about R above the part; the warning says so
    wrong = import_toolpath(f, cone, 5e-3, ImportOptions(point="tip"))
    w = " ".join(wrong.meta["warnings"])
    assert "does the program name the center?" in w


def test_forming_points_rapids_merges_and_times(tmp_path, cone):
    text = """G21 G90
G0 X20 Y0 Z10
G1 Z2 F600 (approach above the sheet: not forming)
G1 Z-0.5
G1 Z-0.5 (a repeated point)
G1 X20 Y10 F1200
G0 Z10 (retract)
G0 X0 Y20
G0 Z-0.2 (a rapid below the sheet: warned)
G1 X0 Y20 Z-1 F1200
G1 X-10
"""
    f = write(tmp_path, "r.nc", text)
    tp = import_toolpath(f, cone, 5e-3)
    np.testing.assert_allclose(
        tp.tip / MM, [[20, 0, -0.5], [20, 10, -0.5], [0, 20, -1], [-10, 20, -1]], atol=1e-12
    )
    assert tp.meta["merged_points"] == 1
    assert any("below the sheet plane" in w for w in tp.meta["warnings"])
    assert any("above the sheet plane" in n for n in tp.meta["notes"])
    # times: 10 mm at 1200 mm/min = 0.5 s; the retract and rapids take no time without a rate;
    # 0.8 mm plunge at 1200 → 0.04 s; 10 mm → 0.5 s
    np.testing.assert_allclose(tp.time, [0, 0.5, 0.54, 1.04], atol=1e-12)
    np.testing.assert_array_equal(tp.lap, [0, 0, 1, 1])
    assert tp.feed == pytest.approx(1200 * MM / 60)
    # with a rapid rate the rapids count: 10.5 up, 22.36 across, 10.2 down at 6000 mm/min
    tp2 = import_toolpath(f, cone, 5e-3, ImportOptions(rapid_rate=0.1))
    extra = (10.5 + math.hypot(20, 10) + 10.2) * MM / 0.1
    assert tp2.time[2] - tp.time[2] == pytest.approx(extra)
    # --spacing resamples the long moves, evenly
    tp3 = import_toolpath(f, cone, 5e-3, ImportOptions(spacing=1e-3))
    assert len(tp3) == 1 + 10 + 1 + 10
    assert np.linalg.norm(np.diff(tp3.tip[:11], axis=0), axis=1).max() <= 1e-3 + 1e-15
    np.testing.assert_allclose(tp3.time[10], 0.5)
    assert any("--spacing" in w for w in tp.meta["warnings"])


def test_origin_shift(tmp_path, cone):
    """A program whose zero is on the machine table, 10.1 mm below the sheet top and offset in
    x/y: --origin moves it into the work frame."""
    tp = step_down(cone, 5e-3, 1e-3, spacing=2e-3)
    body = "".join(f"G1 X{x + 60:.4f} Y{y + 30:.4f} Z{z + 10.1:.4f}\n" for x, y, z in tp.tip / MM)
    f = write(tmp_path, "table.nc", "G90 G21\nG0 X60 Y30 Z40\nG1 F900\n" + body)
    back = import_toolpath(f, cone, 5e-3, ImportOptions(origin=(0.06, 0.03, 0.0101)))
    assert np.abs(back.tip - tp.tip).max() <= 0.1 * UM
    np.testing.assert_array_equal(back.lap, tp.lap)
    with pytest.raises(InputError, match="no forming moves"):  # without it: all above the sheet
        import_toolpath(f, cone, 5e-3)


def test_no_forming_moves(tmp_path, cone):
    f = write(tmp_path, "air.nc", "G90\nG0 X0 Y0 Z10\nG1 Z5 F100\n")
    with pytest.raises(InputError, match="no forming moves"):
        import_toolpath(f, cone, 5e-3)


def test_detect_format(tmp_path):
    tp = step_down(Cone(depth=2e-3), 5e-3, 1e-3, spacing=3e-3)
    write_toolpath_csv(tp, tmp_path / "tp.csv")
    write_gcode(tp, tmp_path / "tp.nc")
    assert detect_toolpath_format(tmp_path / "tp.csv") == "csv"
    assert detect_toolpath_format(tmp_path / "tp.nc") == "iso"
    assert detect_toolpath_format(write(tmp_path, "fanuc.txt", FANUC)) == "iso"
    assert detect_toolpath_format(write(tmp_path, "haas.tap", HAAS)) == "iso"  # 'D=' in a comment
    assert detect_toolpath_format(write(tmp_path, "s.nc", MPF)) == "sinumerik"
    assert detect_toolpath_format(write(tmp_path, "a.txt", APT)) == "apt"
    assert detect_toolpath_format(write(tmp_path, "p.csv", "1;2;3\n")) == "xyz"
    with pytest.raises(InputError, match="cannot tell"):
        detect_toolpath_format(write(tmp_path, "x.bin", "hello world\n"))
    # the study hook reads a roboisf CSV as it is and imports the rest
    part = Cone(depth=2e-3)
    a = load_toolpath(tmp_path / "tp.csv", part, 5e-3)
    b = load_toolpath(tmp_path / "tp.nc", part, 5e-3)
    assert np.abs(a.tip - b.tip).max() <= UM and np.array_equal(a.lap, b.lap)
