"""CLI: roboisf scan compare — outputs (Parquet/CSV, units, JSON), exit codes, no half output."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from roboisf.cam.toolpath_csv import write_toolpath_csv
from roboisf.cli.main import main
from roboisf.parts import Cone
from roboisf.scan import synthetic_scan, write_ply
from roboisf.toolpath import step_down

CONE = Cone()
DN = -0.4e-3


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("scan")
    s = synthetic_scan(CONE, 150_000, offset=DN, noise=25e-6, outlier_fraction=0.01, seed=7)
    write_ply(s.points, d / "scan.ply")
    (d / "cone.toml").write_text(
        '[part]\nkind = "cone"\nopening_diameter = 87.0\nwall_angle = 71.0\ndepth = 102.97\n'
    )
    write_toolpath_csv(step_down(CONE, 5e-3, 2e-3, spacing=4e-3), d / "path.csv")
    return d


def test_compare_per_toolpath_point_parquet(files, tmp_path):
    out = tmp_path / "dev.parquet"
    argv = ["scan", "compare", str(files / "scan.ply"), "--part", str(files / "cone.toml"),
            "--toolpath", str(files / "path.csv"), "-r", "none", "-o", str(out)]  # fmt: skip
    assert main(argv) == 0
    t = pq.read_table(out)
    meta = t.schema.metadata
    units = json.loads(meta[b"roboisf.units"])
    assert units["dx"] == "mm" and units["n_points"] == "1"
    assert t.schema.field("dn").metadata[b"unit"] == b"mm"
    df = t.to_pandas()
    cols = ["index", "contact_x", "contact_y", "contact_z", "dx", "dy", "dz", "dn", "n_points"]
    assert list(df.columns[:9]) == cols
    assert df["index"].tolist() == list(range(len(df)))  # toolpath order
    v = df[df["valid"]]
    assert len(v) > 0.5 * len(df)
    err = v["dn"].to_numpy() - DN * 1e3
    assert np.sqrt(np.mean(err**2)) < 0.010  # ~22 points × 25 µm noise: σ ≈ 7 µm per median
    assert (df.loc[df["contact_z"] > -20.0, "valid"] == False).all()  # noqa: E712
    summary = json.loads((tmp_path / "dev.summary.json").read_text())
    assert summary["toolpath"]["n_valid"] == len(v)
    assert summary["registration"]["method"] == "none"
    assert summary["points"]["mean_dn_mm"] == pytest.approx(DN * 1e3, abs=0.01)
    assert summary["by_angle"]["z_mm"] == -11.0 and len(summary["by_angle"]["bins"]) == 72


def test_compare_per_point_csv_with_registration(files, tmp_path):
    out = tmp_path / "points.csv"
    argv = ["-q", "scan", "compare", str(files / "scan.ply"), "-p", str(files / "cone.toml"),
            "--register", "axisymmetric", "--rim-band", "30", "-o", str(out)]  # fmt: skip
    assert main(argv) == 0
    lines = out.read_text().splitlines()
    assert lines[0].startswith("# units: x=mm") and lines[1] == "# frame: work"
    df = pd.read_csv(out, comment="#")
    assert list(df.columns) == ["x", "y", "z", "dx", "dy", "dz", "dn", "depth", "angle"]
    assert df["depth"].min() > 30.0
    s = json.loads((tmp_path / "points.summary.json").read_text())
    assert s["registration"]["dof"] == 5
    assert s["registration"]["rotation_vector_deg"][2] == 0.0
    # a uniform wall offset looks like a z shift to a wall fit: dz ≈ −dn / cos α (documented)
    tz = s["registration"]["translation_mm"][2]
    assert 0 < tz < -DN * 1e3 / math.cos(CONE.wall_angle) * 1.05


@pytest.mark.parametrize(
    ("extra", "code", "msg"),
    [
        (["--unit", "m"], 2, "--unit mm"),
        (["--register", "bogus"], 2, "unknown registration"),
        (["--rim-band", "-1"], 2, "rim_band"),
        (["--estimator", "mean"], 2, "estimator"),
        (["--points", "p.txt"], 2, "expected a .parquet or .csv table"),
    ],
)
def test_bad_input_exit_codes_and_no_output(files, tmp_path, capsys, extra, code, msg):
    out = tmp_path / "x.parquet"
    argv = ["scan", "compare", str(files / "scan.ply"), "--part", str(files / "cone.toml"),
            "-o", str(out), *extra]  # fmt: skip
    assert main(argv) == code
    assert msg in capsys.readouterr().err.replace("\n", "")
    assert not out.exists() and not (tmp_path / "x.summary.json").exists()
    assert list(tmp_path.iterdir()) == []  # no temporary files left either


def test_bad_files(files, tmp_path, capsys):
    out = tmp_path / "x.parquet"
    trunc = tmp_path / "trunc.ply"
    trunc.write_bytes((files / "scan.ply").read_bytes()[:5000])
    base = ["scan", "compare", "--part", str(files / "cone.toml"), "-o", str(out)]
    assert main([*base, str(trunc)]) == 2
    assert "trunc.ply" in capsys.readouterr().err
    assert main([*base, str(tmp_path / "none.ply")]) == 2
    assert "not found" in capsys.readouterr().err
    # output over an input
    assert main([*base[:-1], str(files / "scan.ply"), str(files / "scan.ply")]) == 2
    assert "overwrite an input" in capsys.readouterr().err
    # a toolpath of another part (a cone 3× larger): outside the scan
    big = Cone(opening_diameter=261e-3, depth=90e-3)
    write_toolpath_csv(step_down(big, 5e-3, 5e-3, spacing=10e-3), tmp_path / "big.csv")
    assert main([*base, str(files / "scan.ply"), "--toolpath", str(tmp_path / "big.csv")]) == 2
    err = capsys.readouterr().err.replace("\n", "")
    assert "big.csv" in err and "outside the scanned" in err
    assert not out.exists()


def test_default_registration_is_fixture_as_analyze(files, tmp_path):
    """`scan compare` registers like `analyze` unless told otherwise ([analysis] registration)."""
    from roboisf.study.spec import AnalysisSpec

    out = tmp_path / "d.csv"
    argv = ["scan", "compare", str(files / "scan.ply"), "--part", str(files / "cone.toml"),
            "-o", str(out)]  # fmt: skip
    assert main(argv) == 0
    summary = json.loads((tmp_path / "d.summary.json").read_text())
    assert summary["registration"]["method"] == AnalysisSpec().registration == "fixture"


def test_a_registrations_shift_reads_without_negative_zero():
    # x and y locked by the fixture registration: a tilt about the flange leaves them at
    # ±1e-13 m, which printed as "-0.0000 mm"
    from roboisf.cli.scan import shift_mm

    assert shift_mm([-1e-13, 2e-17, -0.3995e-3]) == "0.0000, 0.0000, -0.3995"
    assert shift_mm([-0.00004e-3, 0.00006e-3, 1.23456e-3]) == "0.0000, 0.0001, 1.2346"


def test_the_fixture_registration_is_said_in_two_lines(files, tmp_path, capsys):
    out = tmp_path / "dev.csv"
    argv = ["scan", "compare", str(files / "scan.ply"), "--part", str(files / "cone.toml"),
            "--toolpath", str(files / "path.csv"), "-o", str(out)]  # fmt: skip
    assert main(argv) == 0
    said = capsys.readouterr()
    lines = [ln for ln in (said.out + said.err).splitlines() if "registration fixture" in ln]
    assert len(lines) == 2 and "-0.0000" not in lines[0], lines
    assert lines[1].count("fixture registration") == 1, lines
