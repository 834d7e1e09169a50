"""Scan readers: every format round-trips to the same points in m; bad files fail clearly."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from plyfile import PlyData, PlyElement

from roboisf.errors import InputError
from roboisf.parts import Cone
from roboisf.scan import check_units, part_size, read_scan, write_ply


@pytest.fixture
def cloud():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-40e-3, 40e-3, (500, 3))
    nrm = rng.normal(size=(500, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return pts, nrm


@pytest.mark.parametrize("binary", [True, False])
def test_ply_round_trip_with_normals(tmp_path, cloud, binary):
    pts, nrm = cloud
    f = tmp_path / "s.ply"
    write_ply(pts, f, normals=nrm, binary=binary)
    s = read_scan(f)
    np.testing.assert_allclose(s.points, pts, atol=5e-9)  # float32 mm: < 5 nm here
    assert s.normals is not None
    np.testing.assert_allclose(s.normals, nrm, atol=1e-6)
    assert s.unit == "mm" and s.source == str(f)


def test_ply_double_precision_in_metres(tmp_path, cloud):
    pts, _ = cloud
    rec = np.empty(len(pts), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("intensity", "u1")])
    rec["x"], rec["y"], rec["z"] = pts.T
    rec["intensity"] = 7
    f = tmp_path / "m.ply"
    PlyData([PlyElement.describe(rec, "vertex")]).write(str(f))
    s = read_scan(f, unit="m")
    np.testing.assert_array_equal(s.points, pts)
    assert s.normals is None


def _write_pcd(path, pts, nrm=None, mode="ascii"):
    fields = "x y z" + (" normal_x normal_y normal_z" if nrm is not None else "")
    k = 3 if nrm is None else 6
    arr = pts * 1e3 if nrm is None else np.hstack([pts * 1e3, nrm])
    head = (
        f"# .PCD v0.7\nVERSION 0.7\nFIELDS {fields}\nSIZE {' '.join(['4'] * k)}\n"
        f"TYPE {' '.join(['F'] * k)}\nCOUNT {' '.join(['1'] * k)}\nWIDTH {len(pts)}\nHEIGHT 1\n"
        f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(pts)}\nDATA {mode}\n"
    )
    with open(path, "wb") as fh:
        fh.write(head.encode())
        if mode == "ascii":
            np.savetxt(fh, arr, fmt="%.6f")
        else:
            fh.write(arr.astype("<f4").tobytes())


@pytest.mark.parametrize("mode", ["ascii", "binary"])
def test_pcd_ascii_and_binary(tmp_path, cloud, mode):
    pts, nrm = cloud
    f = tmp_path / "s.pcd"
    _write_pcd(f, pts, nrm, mode)
    s = read_scan(f)
    np.testing.assert_allclose(s.points, pts, atol=1e-8)
    assert s.normals is not None
    np.testing.assert_allclose(s.normals, nrm, atol=2e-6)


def test_pcd_compressed_and_truncated_are_refused(tmp_path, cloud):
    pts, _ = cloud
    f = tmp_path / "c.pcd"
    _write_pcd(f, pts, None, "binary_compressed")
    with pytest.raises(InputError, match="binary_compressed") as ei:
        read_scan(f)
    assert str(f) in str(ei.value)
    g = tmp_path / "t.pcd"
    _write_pcd(g, pts, None, "binary")
    g.write_bytes(g.read_bytes()[:-100])
    with pytest.raises(InputError, match="truncated"):
        read_scan(g)


@pytest.mark.parametrize(
    ("name", "sep", "header"),
    [("a.xyz", " ", None), ("b.csv", ",", "x,y,z,nx,ny,nz"), ("c.txt", ";", "X;Y;Z"),
     ("d.txt", "\t", None)],
)  # fmt: skip
def test_point_lists(tmp_path, cloud, name, sep, header):
    pts, nrm = cloud
    with_n = header is not None and "nx" in header
    arr = np.hstack([pts * 1e3, nrm]) if with_n else pts * 1e3
    f = tmp_path / name
    with open(f, "w") as fh:
        fh.write("# exported by a scanner\n")
        if header:
            fh.write(header + "\n")
        for row in arr:
            fh.write(sep.join(f"{v:.9f}" for v in row) + "\n")
    s = read_scan(f)
    np.testing.assert_allclose(s.points, pts, atol=1e-12)
    assert (s.normals is not None) == with_n


@pytest.mark.parametrize(
    ("header", "sep", "decimal"),
    [("x,y,z", ",", "."), ("x;y;z", ";", ","), (None, " ", "."), (None, ";", ",")],
)
def test_point_list_with_a_byte_order_mark(tmp_path, cloud, header, sep, decimal):
    """Excel's "CSV UTF-8" (and many Windows exporters) start the file with a UTF-8 BOM: it used
    to land in the first header cell ('\\ufeffx,y,z': "has no x, y, z columns"), or make a
    header-less first row look like a header."""
    pts, _ = cloud
    rows = [sep.join(f"{v:.9f}".replace(".", decimal) for v in p) for p in pts * 1e3]
    text = "\r\n".join(([header] if header else []) + rows) + "\r\n"
    f = tmp_path / "bom.csv"
    f.write_bytes(b"\xef\xbb\xbf" + text.encode())
    np.testing.assert_allclose(read_scan(f).points, pts, atol=1e-12)


def test_point_list_with_extra_columns_and_header_order(tmp_path, cloud):
    pts, _ = cloud
    f = tmp_path / "e.csv"
    with open(f, "w") as fh:
        fh.write("intensity,z,y,x\n")
        for p in pts * 1e3:
            fh.write(f"1,{p[2]:.9f},{p[1]:.9f},{p[0]:.9f}\n")
    np.testing.assert_allclose(read_scan(f).points, pts, atol=1e-12)


def test_mesh_scan_vertices_or_sampled(tmp_path):
    box = trimesh.creation.box(extents=(80.0, 80.0, 40.0))
    f = tmp_path / "b.stl"
    box.export(f)
    s = read_scan(f)
    assert s.points.shape == (8, 3)
    np.testing.assert_allclose(np.abs(s.points), 0.04 * np.array([1, 1, 0.5]) * np.ones((8, 3)))
    sampled = read_scan(f, sample=2000)
    assert sampled.points.shape == (2000, 3)
    # every sample lies on the box surface
    a = np.abs(sampled.points) / np.array([0.04, 0.04, 0.02])
    np.testing.assert_allclose(a.max(axis=1), 1.0, atol=1e-9)
    obj = tmp_path / "b.obj"
    box.export(obj)
    assert read_scan(obj).points.shape == (8, 3)


def test_empty_truncated_nan_and_unknown_files(tmp_path, cloud):
    pts, _ = cloud
    e = tmp_path / "empty.ply"
    e.write_bytes(b"")
    with pytest.raises(InputError, match="empty") as ei:
        read_scan(e)
    assert "empty.ply" in str(ei.value)
    hdr = tmp_path / "nopts.ply"
    write_ply(pts[:0], hdr)
    with pytest.raises(InputError, match="no points"):
        read_scan(hdr)
    t = tmp_path / "trunc.ply"
    write_ply(pts, t)
    t.write_bytes(t.read_bytes()[:-777])
    with pytest.raises(InputError, match="truncated") as ei:
        read_scan(t)
    assert "trunc.ply" in str(ei.value)
    ta = tmp_path / "trunc_ascii.ply"
    write_ply(pts, ta, binary=False)
    ta.write_text("\n".join(ta.read_text().splitlines()[:-50]) + "\n")
    with pytest.raises(InputError, match="PLY") as ei:
        read_scan(ta)
    assert "trunc_ascii.ply" in str(ei.value)
    n = tmp_path / "nan.xyz"
    bad = pts * 1e3
    bad[17, 1] = np.nan
    bad[40, 2] = np.inf
    np.savetxt(n, bad)
    with pytest.raises(InputError, match=r"2 point\(s\) have NaN or inf.*point 17") as ei:
        read_scan(n)
    assert "nan.xyz" in str(ei.value)
    nply = tmp_path / "nan.ply"
    write_ply(np.where(np.arange(500)[:, None] == 3, np.nan, pts), nply)
    with pytest.raises(InputError, match="NaN"):
        read_scan(nply)
    u = tmp_path / "s.rcp"  # a vendor's project file, not a point format
    u.write_text("x")
    with pytest.raises(InputError, match="unknown scan format"):
        read_scan(u)
    with pytest.raises(InputError, match="not found"):
        read_scan(tmp_path / "missing.ply")
    with pytest.raises(InputError, match="unknown length unit"):
        read_scan(n, unit="furlong")
    txt = tmp_path / "words.csv"
    txt.write_text("a,b\n1,2\n")
    with pytest.raises(InputError, match="x, y, z"):
        read_scan(txt)


def test_ascii_ply_bad_cell_names_its_line_and_a_short_one_its_rows(tmp_path, cloud):
    """A word in an ascii PLY's vertex rows was "row 3: property 'y': malformed input; the file
    may be truncated" — no line, and a truncation hint for a file that is whole."""
    pts, _ = cloud
    f = tmp_path / "a.ply"
    write_ply(pts, f, binary=False)
    lines = f.read_text().splitlines()
    first = lines.index("end_header") + 1
    bad = lines.copy()
    bad[first + 3] = bad[first + 3].split()[0] + " abc " + bad[first + 3].split()[2]
    f.write_text("\n".join(bad) + "\n")
    with pytest.raises(InputError, match="vertex row 3, property 'y': malformed") as e:
        read_scan(f)
    assert e.value.line == first + 4 and "truncated" not in str(e.value)
    f.write_text("\n".join(lines[:-10]) + "\n")
    with pytest.raises(InputError, match=f"ends after {len(pts) - 10} vertex rows of the 500"):
        read_scan(f)


def test_unit_plausibility_names_the_right_unit():
    cone = Cone()
    size = part_size(cone)
    pts = np.array([[-43.5, 0, 0], [43.5, 0, -103.0]])  # a cone scan in mm
    check_units(pts * 1e-3, size, unit="mm", source="s.ply")  # fine
    with pytest.raises(InputError, match=r"'mm'.*--unit mm") as ei:
        check_units(pts, size, unit="m", source="s.ply")  # mm numbers read as m
    assert "s.ply" in str(ei.value)
    with pytest.raises(InputError, match="--unit m"):
        check_units(pts * 1e-6, size, unit="mm", source="s.ply")  # m numbers read as mm


def test_read_scan_checks_the_points_once(tmp_path, monkeypatch):
    """The NaN/inf check runs once per read (in ``ScanCloud``), after the unit scaling: a
    second pass over the points was read_scan's own check before."""
    import roboisf.scan.readers as readers

    calls: list[int] = []
    real = readers.check_finite
    monkeypatch.setattr(readers, "check_finite", lambda p, s: (calls.append(len(p)), real(p, s))[1])
    f = tmp_path / "a.xyz"
    np.savetxt(f, np.random.default_rng(0).random((50, 3)))
    assert readers.read_scan(f).n_points == 50
    assert calls == [50]
    bad = np.random.default_rng(0).random((50, 3))
    bad[7, 2] = np.inf
    np.savetxt(f, bad)
    with pytest.raises(InputError, match=r"1 point\(s\) have NaN or inf.*point 7"):
        readers.read_scan(f)
