"""Scans as scanners write them (issue #13 item 5): Leica PTS with its count line and
intensity/RGB columns, decimal-comma point lists, E57 (pye57) and LAS (laspy) files written
with the libraries themselves."""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.scan import read_scan

PTS_MM = np.array([[10.5, -20.25, 3.0], [11.0, -19.75, 2.5], [12.125, -18.0, 2.0]])


def _rows(sep, dec=".", extra=""):
    out = []
    for p in PTS_MM:
        cells = [f"{v:.3f}".replace(".", dec) for v in p]
        out.append(sep.join(cells) + extra)
    return "\n".join(out) + "\n"


def test_leica_pts_count_line_intensity_rgb(tmp_path):
    f = tmp_path / "scan.pts"
    f.write_text("3\n" + _rows(" ", extra=" -1204 128 64 32"))
    cloud = read_scan(f)
    np.testing.assert_allclose(cloud.points, PTS_MM * 1e-3)
    assert cloud.normals is None  # intensity, r, g are not normals


def test_pts_count_mismatch_is_an_error(tmp_path):
    f = tmp_path / "scan.pts"
    f.write_text("5\n" + _rows(" ", extra=" 10"))
    with pytest.raises(InputError, match=r"scan\.pts:1: PTS count line says 5 points but 3"):
        read_scan(f)


@pytest.mark.parametrize("sep", [";", "\t", " "])
def test_decimal_comma_point_list(tmp_path, sep):
    f = tmp_path / "scan.xyz"
    f.write_text(_rows(sep, dec=","))
    np.testing.assert_allclose(read_scan(f).points, PTS_MM * 1e-3)


def test_decimal_comma_with_header(tmp_path):
    f = tmp_path / "scan.csv"
    f.write_text("x;y;z\n" + _rows(";", dec=","))
    np.testing.assert_allclose(read_scan(f).points, PTS_MM * 1e-3)


def test_e57_written_by_pye57(tmp_path):
    pye57 = pytest.importorskip("pye57")
    f = tmp_path / "scan.e57"
    pts_m = PTS_MM * 1e-3
    e57 = pye57.E57(str(f), mode="w")
    e57.write_scan_raw(
        {"cartesianX": pts_m[:, 0], "cartesianY": pts_m[:, 1], "cartesianZ": pts_m[:, 2]}
    )
    e57.close()
    cloud = read_scan(f)  # metres by the E57 standard, whatever unit the study declares
    np.testing.assert_allclose(cloud.points, pts_m, atol=1e-12)
    assert cloud.unit == "m"


def test_las_written_by_laspy(tmp_path):
    laspy = pytest.importorskip("laspy")
    f = tmp_path / "scan.las"
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = np.array([1e-3, 1e-3, 1e-3])
    header.offsets = np.zeros(3)
    las = laspy.LasData(header)
    las.x, las.y, las.z = PTS_MM[:, 0], PTS_MM[:, 1], PTS_MM[:, 2]
    las.write(str(f))
    np.testing.assert_allclose(read_scan(f, unit="mm").points, PTS_MM * 1e-3, atol=1e-9)


def test_not_an_e57_file(tmp_path):
    pytest.importorskip("pye57")
    f = tmp_path / "scan.e57"
    f.write_bytes(b"not an e57 file" * 100)
    with pytest.raises(InputError, match=r"scan\.e57: not a readable E57 file"):
        read_scan(f)


def test_missing_optional_library_says_how_to_install(tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "laspy", None)  # import laspy → ImportError
    f = tmp_path / "scan.las"
    f.write_bytes(b"LASF" + b"\0" * 300)
    with pytest.raises(InputError, match=r"scan\.las.*pip install 'roboisf\[scan-formats\]'"):
        read_scan(f)
