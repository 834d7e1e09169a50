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


def _write_las(laspy, f):
    """PTS_MM with laspy at 1 µm scale (LAZ when ``f`` ends in .laz: laspy compresses)."""
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = np.array([1e-3, 1e-3, 1e-3])
    header.offsets = np.zeros(3)
    las = laspy.LasData(header)
    las.x, las.y, las.z = PTS_MM[:, 0], PTS_MM[:, 1], PTS_MM[:, 2]
    las.write(str(f))


def test_las_written_by_laspy(tmp_path):
    laspy = pytest.importorskip("laspy")
    f = tmp_path / "scan.las"
    _write_las(laspy, f)
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


def test_laz_written_by_laspy_with_lazrs(tmp_path):
    """LAZ through laspy's lazrs backend, which the scan-formats extra installs (issue #28)."""
    laspy = pytest.importorskip("laspy")
    pytest.importorskip("lazrs")
    f = tmp_path / "scan.laz"
    _write_las(laspy, f)
    assert f.read_bytes()[:4] == b"LASF" and f.read_bytes()[104] & 0x80  # compressed
    np.testing.assert_allclose(read_scan(f, unit="mm").points, PTS_MM * 1e-3, atol=1e-9)


def test_laz_without_a_backend_names_the_extra(tmp_path, monkeypatch):
    laspy = pytest.importorskip("laspy")
    f = tmp_path / "scan.laz"
    _write_las(laspy, tmp_path / "plain.las")
    raw = bytearray((tmp_path / "plain.las").read_bytes())
    raw[104] |= 0x80  # the point format's compression bit: a LAZ file to laspy
    f.write_bytes(bytes(raw))
    # no backend, whatever is installed here
    monkeypatch.setattr(laspy.LazBackend, "is_available", lambda self: False)
    with pytest.raises(InputError, match=r"pip install \"roboisf\[scan-formats\]\""):
        read_scan(f)


def test_the_scan_formats_extra_brings_a_laz_backend():
    import tomllib
    from pathlib import Path

    py = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    extra = py["project"]["optional-dependencies"]["scan-formats"]
    assert any(r.startswith("laspy[lazrs]") or r.startswith("lazrs") for r in extra), extra


def test_e57_scale_error_does_not_offer_a_unit(tmp_path):
    """An E57 whose numbers are millimetres: --unit does not apply to E57 (metres by the
    standard), so the error says to re-export rather than 'pass --unit'."""
    pye57 = pytest.importorskip("pye57")
    from roboisf.scan.readers import check_units

    f = tmp_path / "scan.e57"
    e57 = pye57.E57(str(f), mode="w")
    big = PTS_MM * 1000.0  # a 2 mm part's scan written in mm numbers: 1000× too large in m
    e57.write_scan_raw({"cartesianX": big[:, 0], "cartesianY": big[:, 1], "cartesianZ": big[:, 2]})
    e57.close()
    cloud = read_scan(f)
    with pytest.raises(InputError) as e:
        check_units(cloud.points, 3e-3, unit=cloud.unit, source=f)
    assert "E57 coordinates are metres" in e.value.message
    assert "--unit does not apply" in e.value.message and "pass --unit" not in e.value.message
