"""Toolpath CSV: exact header, round trip, metadata-free files, bad input with file:line."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from roboisf.cam.toolpath_csv import TOOLPATH_COLUMNS, read_toolpath_csv, write_toolpath_csv
from roboisf.errors import InputError
from roboisf.parts import VWACF, Cone
from roboisf.toolpath import spiral, step_down

HEADER = (
    "index,lap,contact_x,contact_y,contact_z,normal_x,normal_y,normal_z,center_x,center_y,"
    "center_z,tip_x,tip_y,tip_z,wall_angle_deg,depth,path_length,time"
)


@pytest.fixture(scope="module")
def cone_path():
    return step_down(Cone(depth=10e-3), 5e-3, 0.5e-3, spacing=2e-3)


def _assert_same(a, b, tol=1e-9):
    for name in ("contact", "normal", "center", "tip", "path_length"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=tol)
    np.testing.assert_allclose(a.wall_angle, b.wall_angle, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.time, b.time, rtol=0, atol=1e-8)
    np.testing.assert_array_equal(a.lap, b.lap)
    assert a.tool_radius == pytest.approx(b.tool_radius, abs=1e-12)
    assert a.feed == pytest.approx(b.feed, rel=1e-10)


def test_header_is_fixed():
    assert ",".join(TOOLPATH_COLUMNS) == HEADER


def test_round_trip_cone(tmp_path: Path, cone_path):
    f = tmp_path / "p.csv"
    write_toolpath_csv(cone_path, f)
    lines = f.read_text().splitlines()
    header = next(ln for ln in lines if not ln.startswith("#"))
    assert header == HEADER
    assert "# units: length=mm angle=deg time=s" in lines
    assert "# tool_radius: 5 mm" in lines
    assert "# feed: 750 mm/min" in lines
    back = read_toolpath_csv(f)
    _assert_same(cone_path, back, tol=1e-12)
    assert back.meta["kind"] == "step_down"


def test_round_trip_spiral_vwacf(tmp_path: Path):
    tp = spiral(VWACF(), 4e-3, 1e-3, spacing=3e-3, feed=0.02)
    f = tmp_path / "s.csv"
    write_toolpath_csv(tp, f)
    _assert_same(tp, read_toolpath_csv(f))


def test_values_are_mm_deg_s(tmp_path: Path, cone_path):
    f = tmp_path / "p.csv"
    write_toolpath_csv(cone_path, f)
    rows = [ln.split(",") for ln in f.read_text().splitlines() if ln[:1].isdigit()]
    recs = [dict(zip(TOOLPATH_COLUMNS, map(float, r), strict=True)) for r in rows]
    first = next(r for r in recs if r["lap"] == 10)  # tip at −5.5 mm, ball on the 71° wall
    a = math.radians(71)
    z_contact = -5.5 + 5 * (1 - math.cos(a))
    assert first["tip_z"] == pytest.approx(-5.5, abs=1e-9)
    assert first["contact_z"] == pytest.approx(z_contact, abs=1e-9)
    assert first["contact_x"] == pytest.approx(43.5 + z_contact / math.tan(a), abs=1e-9)
    assert first["depth"] == pytest.approx(-z_contact, abs=1e-9)
    assert first["wall_angle_deg"] == pytest.approx(71.0, abs=1e-9)
    last = recs[-1]
    # 750 mm/min → time = length / 12.5 mm/s
    assert last["time"] == pytest.approx(last["path_length"] / 12.5, rel=1e-9)


def test_reader_without_metadata_derives_radius_and_feed(tmp_path: Path, cone_path):
    f = tmp_path / "p.csv"
    write_toolpath_csv(cone_path, f)
    g = tmp_path / "bare.csv"
    g.write_text("\n".join(ln for ln in f.read_text().splitlines() if not ln.startswith("#")))
    back = read_toolpath_csv(g)
    _assert_same(cone_path, back)


def test_coarse_third_party_file_accepted(tmp_path: Path, cone_path):
    """A file written at 1 µm / 1e-4 resolution by another tool reads (normals renormalised)."""
    f = tmp_path / "coarse.csv"
    rows = []
    tp = cone_path
    for i in range(len(tp)):
        vals = [
            i,
            tp.lap[i],
            *(tp.contact[i] * 1e3),
            *tp.normal[i],
            *(tp.center[i] * 1e3),
            *(tp.tip[i] * 1e3),
            math.degrees(tp.wall_angle[i]),
            -tp.contact[i, 2] * 1e3,
            tp.path_length[i] * 1e3,
            tp.time[i],
        ]
        rows.append(
            ",".join(f"{v:.3f}" if j < 2 or j > 7 else f"{v:.4f}" for j, v in enumerate(vals))
        )
    f.write_text(HEADER + "\n" + "\n".join(rows) + "\n")
    back = read_toolpath_csv(f)
    np.testing.assert_allclose(back.tip, tp.tip, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(back.normal, axis=1), 1.0, atol=1e-15)
    assert back.tool_radius == pytest.approx(5e-3, abs=1e-6)


def test_commanded_path_round_trip(tmp_path: Path, cone_path):
    """A compensated path (tip moved off contact + R·n) is flagged and reads back."""
    moved = cone_path.with_tip(cone_path.tip + np.array([0.2e-3, 0.0, -0.1e-3]))
    f = tmp_path / "c.csv"
    write_toolpath_csv(moved, f)
    assert "# center_from_contact: false" in f.read_text()
    _assert_same(moved, read_toolpath_csv(f), tol=1e-12)


def _rows(f: Path):
    lines = f.read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    return lines, head


def _corrupt(tmp_path, tp, row, col, value):
    f = tmp_path / "bad.csv"
    write_toolpath_csv(tp, f)
    lines, head = _rows(f)
    cells = lines[head + 1 + row].split(",")
    cells[TOOLPATH_COLUMNS.index(col)] = value
    lines[head + 1 + row] = ",".join(cells)
    f.write_text("\n".join(lines) + "\n")
    return f, head + 2 + row  # 1-based file line of that row


@pytest.mark.parametrize(
    ("col", "value", "match"),
    [
        ("contact_x", "nan", "not a finite number"),
        ("tip_z", "abc", "not a number"),
        ("normal_z", "0.5", "unit vector"),
        ("index", "0", "index must increase"),
        ("time", "0", "time must not decrease"),
        ("center_x", "12.0", "away from contact"),
        ("lap", "0.5", "non-negative integer"),
    ],
)
def test_bad_cells_name_file_and_line(tmp_path, cone_path, col, value, match):
    f, line = _corrupt(tmp_path, cone_path, 5, col, value)
    with pytest.raises(InputError, match=match) as ei:
        read_toolpath_csv(f)
    assert ei.value.line == line
    assert ei.value.file == str(f)
    assert f"bad.csv:{line}" in str(ei.value)


def test_missing_column(tmp_path, cone_path):
    f = tmp_path / "m.csv"
    write_toolpath_csv(cone_path, f)
    text = f.read_text().replace(",wall_angle_deg,", ",wall_angle,")
    f.write_text(text)
    with pytest.raises(InputError, match=r"missing column.*wall_angle_deg"):
        read_toolpath_csv(f)


def test_short_row_and_empty(tmp_path, cone_path):
    f = tmp_path / "short.csv"
    write_toolpath_csv(cone_path, f)
    lines, head = _rows(f)
    lines[head + 3] = ",".join(lines[head + 3].split(",")[:10])
    f.write_text("\n".join(lines))
    with pytest.raises(InputError, match="expected 18 columns") as ei:
        read_toolpath_csv(f)
    assert ei.value.line == head + 4
    e = tmp_path / "empty.csv"
    e.write_text("# only: comments\n\n")
    with pytest.raises(InputError, match="empty"):
        read_toolpath_csv(e)
    h = tmp_path / "header_only.csv"
    h.write_text(HEADER + "\n")
    with pytest.raises(InputError, match="no data rows"):
        read_toolpath_csv(h)
    with pytest.raises(InputError, match="not found"):
        read_toolpath_csv(tmp_path / "nope.csv")


def test_wrong_declared_units(tmp_path, cone_path):
    f = tmp_path / "u.csv"
    write_toolpath_csv(cone_path, f)
    f.write_text(f.read_text().replace("length=mm", "length=m"))
    with pytest.raises(InputError, match="length=m"):
        read_toolpath_csv(f)


def test_metadata_units_converted(tmp_path, cone_path):
    f = tmp_path / "p.csv"
    write_toolpath_csv(cone_path, f)
    f.write_text(f.read_text().replace("# feed: 750 mm/min", "# feed: 12.5 mm/s"))
    assert read_toolpath_csv(f).feed == pytest.approx(12.5e-3)
    f.write_text(f.read_text().replace("# feed: 12.5 mm/s", "# feed: 750"))
    assert read_toolpath_csv(f).feed == pytest.approx(12.5e-3)
    f.write_text(f.read_text().replace("# feed: 750", "# feed: 750 furlongs"))
    with pytest.raises(InputError, match="speed unit"):
        read_toolpath_csv(f)
