"""``roboisf history``: analysed parts into a database (SQLite file, PostgreSQL server) and out.

Two small virtual studies (a cone and a pyramid whose springback follows the geometry rule),
analysed once per module. What is checked: the stored values are the results' (units converted,
shares, per-point terms), a part is stored once, list/show/trend, the trend's slope, a crash during
``add`` leaves no half-written part (a real SIGKILL mid-transaction), bad inputs are refused with
one line and the user's files are untouched — on SQLite and on a real PostgreSQL server when one
is reachable (CI starts one: .ci/run).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pandas as pd
import pytest

from roboisf.cli.main import main

TRUTH = "[springback]\ncurvature_gain = 0.4\ncurvature_length = 15.0\n"
CELL = [
    "--step-down", "2", "--spacing", "4", "--scan-points", "60000",
    "--force-rate", "50", "--joint-rate", "20",
]  # fmt: skip
PARTS = {
    "cone": ["cone", "--opening-diameter", "70", "--wall-angle", "55", "--depth", "25"],
    "pyramid": ["pyramid", "--top-length", "80", "--wall-angle", "50", "--depth", "22"],
}
#: the PostgreSQL server the tests use (CI: .ci/run creates this role and database)
PG_URL = os.environ.get(
    "ROBOISF_TEST_POSTGRES", "postgresql://roboisf:roboisf@127.0.0.1:5432/roboisf_test"
)


def _run(args, capsys=None):
    code = main(["-q", *args])
    return code if capsys is None else (code, capsys.readouterr())


@pytest.fixture(scope="module")
def analysed(tmp_path_factory):
    """Two `analyze` results folders: {name: path}."""
    root = tmp_path_factory.mktemp("history-studies")
    (root / "truth.toml").write_text(TRUTH)
    out = {}
    for name, spec in PARTS.items():
        part = root / f"{name}.toml"
        assert _run(["part", *spec, "-o", str(part)]) == 0
        study, res = root / f"S_{name}", root / f"R_{name}"
        assert _run(["virtual-cell", "--part", str(part), "--truth", str(root / "truth.toml"),
                     *CELL, "-o", str(study)]) == 0  # fmt: skip
        assert _run(["analyze", str(study), "-o", str(res), "--no-png"]) == 0
        out[name] = res
    return out


def _pg_or_skip() -> str:
    """The test server's URL, its tables dropped; skip when no server is reachable — except
    where ROBOISF_REQUIRE_POSTGRES is set (CI, which starts one): fail there."""
    skip = pytest.fail if os.environ.get("ROBOISF_REQUIRE_POSTGRES") else pytest.skip
    try:
        import psycopg
    except ImportError:
        skip("psycopg is not installed (pip install 'roboisf[history]')")
    try:
        with psycopg.connect(PG_URL, connect_timeout=3, autocommit=True) as c:
            c.execute("DROP TABLE IF EXISTS points, shares, parts, meta CASCADE")
    except psycopg.OperationalError as e:
        skip(f"no PostgreSQL server reachable at {PG_URL} ({str(e).splitlines()[0]})")
    return PG_URL


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request, tmp_path):
    if request.param == "sqlite":
        return str(tmp_path / "history.db")
    return _pg_or_skip()


def test_add_stores_the_results_values_once(analysed, db_url, capsys):
    from roboisf.history.db import Database
    from roboisf.history.store import list_parts, points_table, show_part

    args = ["history", "add", str(analysed["cone"]), str(analysed["pyramid"]), "--db", db_url]
    assert _run(args) == 0
    capsys.readouterr()
    assert main(["history", "add", str(analysed["cone"]), "--db", db_url]) == 0
    out = capsys.readouterr()
    assert "already in the history as part 1" in out.out + out.err
    with Database(db_url, create=False) as db:
        parts = list_parts(db)
        assert [p["study"] for p in parts] == [
            json.loads((analysed[k] / "summary.json").read_text())["study"]
            for k in ("cone", "pyramid")
        ]  # oldest analysis first, the second add of the cone skipped
        table = points_table(db)
        info = show_part(db, parts[0]["id"])
    pp = pd.read_parquet(analysed["cone"] / "per_point.parquet")
    cone = table[table["part_id"] == parts[0]["id"]]
    assert len(cone) == len(pp)
    np.testing.assert_allclose(cone["depth"], pp["depth"] * 1e-3)
    np.testing.assert_allclose(cone["wall_angle"], np.radians(pp["wall_angle_deg"]))
    np.testing.assert_allclose(cone["springback_dn"], pp["springback_dn"] * 1e-3)
    np.testing.assert_allclose(cone["robot_dn"], pp["robot_compliance_dn"] * 1e-3)
    assert cone["used"].sum() == pp["used"].sum()
    shares = pd.read_csv(analysed["cone"] / "contributions_normal.csv").set_index("factor")
    assert parts[0]["r_m_springback"] == pytest.approx(shares.loc["springback", "R_m"] * 1e-3)
    used = pp[pp["used"]]
    assert info["rms_dn"]["springback_dn"] == pytest.approx(
        np.sqrt(np.mean((used["springback_dn"] * 1e-3) ** 2))
    )
    assert info["part"]["kind"] == "cone" and info["sheet_thickness"] == pytest.approx(1.22e-3)
    assert info["identified_k"] is not None and len(info["identified_k"]) == 6
    assert info["step_down"] == pytest.approx(2e-3, rel=0.05)
    assert len([s for s in info["shares"] if s["book"] == "normal"]) == 5


def test_list_show_and_trend_commands(analysed, db_url, capsys, tmp_path):
    for i, k in enumerate(("cone", "pyramid")):
        args = ["history", "add", str(analysed[k]), "--db", db_url, "--formed", f"2026-0{i + 1}-01"]
        assert _run(args) == 0
    code, out = _run(["history", "list", "--db", db_url, "--kind", "pyramid"], capsys)
    assert code == 0 and "pyramid" in out.out and " cone " not in out.out
    code, out = _run(["history", "show", "1", "--db", db_url], capsys)
    assert code == 0 and json.loads(out.out)["formed_at"] == "2026-01-01T00:00:00Z"
    code, out = _run(
        ["history", "trend", "--db", db_url, "--json", "--factor", "springback"], capsys
    )
    assert code == 0
    (group,) = json.loads(out.out)
    v = group["r_m_m"]
    # two parts 31 days apart: the slope per 30 days is their difference × 30/31
    assert group["slope_m_per_30_days"] == pytest.approx((v[1] - v[0]) * 30 / 31)
    png = tmp_path / "trend.png"
    code, out = _run(["history", "trend", "--db", db_url, "--by", "tool", "-o", str(png)], capsys)
    assert code == 0 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Ø10.0 mm" in out.out  # grouped by the tool the summaries describe


_CRASH = textwrap.dedent(
    """
    import os, signal, sys
    from roboisf.history import db as dbm
    real = dbm.Database.executemany
    def crash(self, sql, rows):
        real(self, sql, rows)
        if sql.startswith("INSERT INTO points"):
            os.kill(os.getpid(), signal.SIGKILL)   # the part's points are in, its shares not
    dbm.Database.executemany = crash
    from roboisf.cli.main import main
    sys.exit(main(["history", "add", sys.argv[1], "--db", sys.argv[2]]))
    """
)


def test_a_crash_during_add_leaves_no_half_written_part(analysed, db_url):
    from roboisf.history.db import Database

    assert _run(["history", "add", str(analysed["cone"]), "--db", db_url]) == 0
    proc = subprocess.run(
        [sys.executable, "-c", _CRASH, str(analysed["pyramid"]), db_url],
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
        capture_output=True,
        timeout=120,
    )
    assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()
    with Database(db_url, create=False) as db:
        assert db.query("SELECT count(*) FROM parts")[0][0] == 1
        assert db.query("SELECT count(DISTINCT part_id) FROM points")[0][0] == 1
        n_cone = len(pd.read_parquet(analysed["cone"] / "per_point.parquet"))
        assert db.query("SELECT count(*) FROM points")[0][0] == n_cone
    # the next add stores the pyramid whole
    assert _run(["history", "add", str(analysed["pyramid"]), "--db", db_url]) == 0
    with Database(db_url, create=False) as db:
        assert db.query("SELECT count(*) FROM parts")[0][0] == 2


def test_bad_inputs_are_refused_in_one_line(analysed, tmp_path, capsys):
    mine = tmp_path / "notes.db"
    mine.write_text("my notes, not a database\n")
    code, out = _run(["history", "add", str(analysed["cone"]), "--db", str(mine)], capsys)
    assert code == 2 and "not a history database" in out.err and str(mine) in out.err
    assert mine.read_text() == "my notes, not a database\n"
    other = tmp_path / "other.db"  # another application's SQLite database
    import sqlite3

    with sqlite3.connect(other) as con:
        con.execute("CREATE TABLE parts (sku TEXT)")
    before = other.read_bytes()
    code, out = _run(["history", "add", str(analysed["cone"]), "--db", str(other)], capsys)
    assert code == 2 and "not a roboisf history" in out.err and other.read_bytes() == before
    empty = tmp_path / "empty.db"
    empty.touch()
    code, out = _run(["history", "add", str(analysed["cone"]), "--db", str(empty)], capsys)
    assert code == 2 and empty.stat().st_size == 0
    code, out = _run(["history", "list", "--db", str(tmp_path / "typo.db")], capsys)
    assert code == 2 and "no such history database" in out.err
    assert not (tmp_path / "typo.db").exists()
    code, out = _run(["history", "add", str(tmp_path), "--db", str(tmp_path / "h.db")], capsys)
    assert code == 2 and "summary.json" in out.err and len(out.err.strip().splitlines()) == 1
    args = ["history", "add", str(analysed["cone"]), "--db", str(tmp_path / "h.db")]
    code, out = _run([*args, "--formed", "yesterday"], capsys)
    assert code == 2 and "--formed" in out.err
    code, out = _run(["history", "trend", "--db", str(tmp_path / "h.db"), "--by", "x"], capsys)
    assert code == 2  # (the database does not exist either: the first problem is reported)
    code, out = _run(["history", "show", "7", "--db", str(tmp_path / "h.db")], capsys)
    assert code == 2


def test_unreachable_postgres_is_one_line(capsys):
    pytest.importorskip("psycopg")
    url = "postgresql://nobody:x@127.0.0.1:1/none"
    code, out = _run(["history", "list", "--db", url], capsys)
    assert code == 2 and "cannot connect to the PostgreSQL server" in out.err
    assert ":x@" not in out.err  # the password is never echoed


def test_predict_and_the_first_part_program_on_a_new_part(analysed, tmp_path, capsys):
    """``predict`` a pyramid of another size from the two-part history, compare each term with
    the virtual cell's truth for that part, then ``compensate --predicted`` and re-form it."""
    from roboisf.cam.toolpath_csv import read_toolpath_csv
    from roboisf.parts.io import load_part
    from roboisf.virtual.cell import PAPER_CELL_PLACEMENT, simulate, virtual_cell
    from roboisf.virtual.truth import load_truth

    pytest.importorskip("sklearn")
    db = tmp_path / "h.db"
    assert _run(["history", "add", *(str(p) for p in analysed.values()), "--db", str(db)]) == 0
    part = tmp_path / "new.toml"
    spec = ["pyramid", "--top-length", "90", "--top-width", "75", "--wall-angle", "55"]
    assert _run(["part", *spec, "--depth", "24", "-o", str(part)]) == 0
    pred = tmp_path / "P"
    args = ["predict", "--part", str(part), "--history", str(db), "-o", str(pred), "--png",
            "--placement", "2200,-500,200,0", "--step-down", "2", "--spacing", "4"]  # fmt: skip
    assert _run(args) == 0
    pp = pd.read_parquet(pred / "prediction.parquet")
    summary = json.loads((pred / "prediction.json").read_text())
    assert (pred / "report.html").is_file() and (pred / "prediction.png").is_file()
    terms = ["springback_dn", "tool_dn", "tool_holder_dn", "robot_compliance_dn"]
    np.testing.assert_allclose(pp["total_dn"], pp[terms].sum(axis=1), atol=1e-9)
    assert np.all(pp["springback_dn_low"] <= pp["springback_dn"])
    assert np.all(pp["springback_dn"] <= pp["springback_dn_high"])
    assert "identified in history part" in summary["joint_stiffness_from"]

    # the truth of this part in the same virtual cell (its truth rule, the same toolpath)
    (tmp_path / "truth.toml").write_text(TRUTH)
    truth_spec = load_truth(tmp_path / "truth.toml")
    vc = virtual_cell(
        "new", load_part(part), T_base_work=PAPER_CELL_PLACEMENT, truth=truth_spec,
        step_down=2e-3, spacing=4e-3,
    )  # fmt: skip
    truth = simulate(vc)
    n = truth.toolpath.normal
    np.testing.assert_allclose(
        pp[["contact_x", "contact_y", "contact_z"]], truth.toolpath.contact * 1e3
    )
    wall = pp["depth"].to_numpy() > summary["rim_band_mm"]
    np.testing.assert_array_equal(pp["below_rim_band"], wall)

    def rel(pred_mm, true_m):
        t = true_m[wall] * 1e3
        return np.sqrt(np.mean((pred_mm[wall] - t) ** 2)) / np.sqrt(np.mean(t**2))

    # tool and robot: the same models as the cell's (the robot run forms with ≤ 6 % less force)
    assert rel(pp["tool_dn"].to_numpy(), np.einsum("ij,ij->i", truth.tool_robot, n)) < 0.1
    assert rel(pp["robot_compliance_dn"].to_numpy(), np.einsum("ij,ij->i", truth.robot, n)) < 0.1
    # springback learned from two parts only: a loose bound (the benchmark's history has ten)
    assert rel(pp["springback_dn"].to_numpy(), truth.springback) < 0.5

    comp = tmp_path / "C"
    assert _run(["compensate", "--predicted", str(pred), "-o", str(comp), "--no-png"]) == 0
    for name in ("compensated.mod", "compensated.src", "compensated.csv", "compensation.json"):
        assert (comp / name).is_file()
    reformed = simulate(vc, commanded=read_toolpath_csv(comp / "compensated.csv"))
    before = np.sqrt(np.mean(truth.dn_robot[wall] ** 2))
    after = np.sqrt(np.mean(reformed.dn_robot[wall] ** 2))
    assert after < 0.5 * before, (before, after)

    # a prediction is tied to its part file: an edited part is refused, nothing written
    part.write_text(part.read_text().replace("24.0", "25.0"))
    code, out = _run(["compensate", "--predicted", str(pred), "-o", str(tmp_path / "C2")], capsys)
    assert code == 2 and "changed since the prediction" in out.err
    assert not (tmp_path / "C2").exists()


def test_predicting_a_history_part_finds_it_inside_the_history(analysed, tmp_path, capsys):
    """The history's own cone, predicted: no feature outside the history's range. The rim band
    (the history's analyses leave it out) is said once, not counted as 'outside' — it was:
    depth and rim distance 69 % of the points, meridian curvature 20 %."""
    pytest.importorskip("sklearn")
    db = tmp_path / "h.db"
    assert _run(["history", "add", *(str(p) for p in analysed.values()), "--db", str(db)]) == 0
    part = tmp_path / "cone.toml"
    assert _run(["part", *PARTS["cone"], "-o", str(part)]) == 0
    pred = tmp_path / "P"
    code, out = _run(["predict", "--part", str(part), "--history", str(db), "-o", str(pred),
                      "--step-down", "2", "--spacing", "4", "--no-png"], capsys)  # fmt: skip
    assert code == 0, out.err
    summary = json.loads((pred / "prediction.json").read_text())
    assert summary["extrapolated_features"] == {}
    pp = pd.read_parquet(pred / "prediction.parquet")
    n_rim = int((~pp["below_rim_band"]).sum())
    assert summary["rim_band_points"] == n_rim > 0
    # -q prints nothing; the report says it
    page = (pred / "report.html").read_text()
    assert f"{n_rim} of {len(pp)} points" in page and "Outside the history" not in page


def test_predict_on_a_robot_without_a_published_stiffness_takes_a_stiffness_file(
    analysed, tmp_path, capsys
):
    """A KUKA preset has no published joint stiffness and the history none identified for it:
    the error pointed to a --stiffness option predict did not have. It has it now; the file's
    K is the prediction's (recorded for compensate --predicted)."""
    pytest.importorskip("sklearn")
    db = tmp_path / "h.db"
    assert _run(["history", "add", *(str(p) for p in analysed.values()), "--db", str(db)]) == 0
    part = tmp_path / "cone.toml"
    assert _run(["part", *PARTS["cone"], "-o", str(part)]) == 0
    args = ["predict", "--part", str(part), "--history", str(db), "--robot", "kr210-r2700-2",
            "--step-down", "2", "--spacing", "4", "--no-png"]  # fmt: skip
    code, out = _run([*args, "-o", str(tmp_path / "P0")], capsys)
    assert code == 2 and "--stiffness" in out.err and not (tmp_path / "P0").exists()
    K = [4.0e6, 4.5e6, 2.5e6, 6.0e5, 5.0e5, 3.0e5]
    (tmp_path / "k.toml").write_text(f"[stiffness]\nK = {K}\n")
    code, out = _run([*args, "-o", str(tmp_path / "P"), "--stiffness", str(tmp_path / "k.toml")],
                     capsys)  # fmt: skip
    assert code == 0, out.err
    summary = json.loads((tmp_path / "P" / "prediction.json").read_text())
    assert summary["setup"]["joint_stiffness_N_m_per_rad"] == K
    assert "--stiffness" in summary["joint_stiffness_from"]
    code, out = _run([*args, "-o", str(tmp_path / "P2"), "--stiffness", str(tmp_path / "no.toml")],
                     capsys)  # fmt: skip
    assert code == 2 and "no such stiffness file" in out.err


def test_predict_refuses_a_history_it_cannot_validate(analysed, tmp_path, capsys):
    pytest.importorskip("sklearn")
    db = tmp_path / "h.db"
    assert _run(["history", "add", str(analysed["cone"]), "--db", str(db)]) == 0
    part = tmp_path / "p.toml"
    assert _run(["part", "cone", "--depth", "20", "-o", str(part)]) == 0
    code, out = _run(["predict", "--part", str(part), "--history", str(db),
                      "-o", str(tmp_path / "P")], capsys)  # fmt: skip
    assert code == 2 and "at least 2" in out.err
    code, out = _run(["predict", "--part", str(tmp_path / "none.toml"), "--history", str(db)],
                     capsys)  # fmt: skip
    assert code == 2 and "no such part file" in out.err


def test_trend_slopes():
    from roboisf.history.trend import _days, _slope

    t = [_days("2026-11-28T01:20:10Z")] * 100  # 100 parts formed at once
    v = [float(i % 3) for i in range(100)]
    assert _slope(t, v) is None  # one date: no slope (not the rounding noise of the mean)
    assert _slope([20000.0, 20030.0, 20060.0], [1.0, 2.0, 3.0]) == pytest.approx(1.0)
    assert _slope([20000.0, 20030.0], [1.0, None]) is None
    # parts formed minutes apart: no slope per 30 days (extrapolating 6 minutes to a month gave
    # +100 mm per 30 days for an R_m of 0.3 mm); a day apart is enough
    minutes = [20000.0, 20000.002, 20000.004]
    assert _slope(minutes, [0.3e-3, 0.4e-3, 0.25e-3]) is None
    assert _slope([20000.0, 20001.0], [1.0, 2.0]) == pytest.approx(30.0)
