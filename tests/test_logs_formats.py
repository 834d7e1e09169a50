"""Force and joint logs as instruments and controllers write them (issue #13, item 2).

Each file is written by hand in the layout its source writes; the values read back are checked
against the numbers typed in, converted to SI by hand (an independent oracle: no roboisf writer
is involved).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.logs.forcelog import ForceLog, detect_force_format, read_force_log, write_force_log
from roboisf.logs.jointlog import detect_joint_format, read_joint_log, write_joint_log

LBF = 4.4482216152605

# ATI Industrial Automation's Net F/T demo application (NetFTSampleGUI.java, v1.1.1, "Start
# Collecting") writes: a start time, "RDT Sample Rate: N", a quoted caveat, "Force Units: …",
# "Counts per Unit Force: …", "Torque Units: …", "Counts per Unit Torque: …", then the header
# "Status (hex), RDT Sequence, F/T Sequence, Fx, Fy, Fz, Tx, Ty, Tz, Time" and quoted rows whose
# Time is a wall-clock date string (second resolution: the time axis is RDT sequence / rate).
ATI = """Start Time: 3/14/24 10:21 AM
RDT Sample Rate: 500
"PLEASE NOTE: The sample rate is read from the Net F/T when the program starts.  If you \
have changed the sample rate since the program started, this will be incorrect."
Force Units: N
Counts per Unit Force: 1000000.0
Torque Units: Nm
Counts per Unit Torque: 1000000.0
Status (hex), RDT Sequence, F/T Sequence, Fx, Fy, Fz, Tx, Ty, Tz, Time
"0x0","1201","88817","1.5","-2.25","-310.5","0.125","-0.5","0.03125","Mar 14, 2024 10:21:07 AM"
"0x0","1202","88831","1.75","-2.5","-311.0","0.25","-0.25","0.0625","Mar 14, 2024 10:21:07 AM"
"0x0","1203","88845","2.0","-2.75","-312.5","0.5","0.0","0.125","Mar 14, 2024 10:21:07 AM"
"""


def _w(tmp_path, name, text, encoding="utf-8"):
    f = tmp_path / name
    f.write_bytes(text.encode(encoding))
    return f


def test_ati_netft_demo_csv(tmp_path):
    f = _w(tmp_path, "ati.csv", ATI)
    profile, cols, units = detect_force_format(f)
    assert profile == "ati"
    assert cols["Mx"] == "Tx" and cols["rdt"] == "RDT Sequence"
    assert units == {"force": "N", "moment": "Nm"}
    log = read_force_log(f)
    np.testing.assert_allclose(log.time, [0.0, 1 / 500, 2 / 500], rtol=0, atol=1e-15)
    np.testing.assert_allclose(log.wrench[1], [1.75, -2.5, -311.0, 0.25, -0.25, 0.0625])
    assert log.moments_known and log.profile == "ati"


def test_ati_in_pound_force_converted(tmp_path):
    text = ATI.replace("Force Units: N", "Force Units: lbf").replace("Nm", "lbf-in")
    log = read_force_log(_w(tmp_path, "ati.csv", text))
    np.testing.assert_allclose(log.wrench[0, 2], -310.5 * LBF, rtol=1e-12)
    np.testing.assert_allclose(log.wrench[0, 3], 0.125 * LBF * 0.0254, rtol=1e-12)


def test_ati_without_sample_rate_is_refused(tmp_path):
    f = _w(tmp_path, "ati.csv", ATI.replace("RDT Sample Rate: 500\n", ""))
    with pytest.raises(InputError, match="RDT Sample Rate"):
        read_force_log(f)


# A DynoWare-style text export: a free-text block (tab key/value), a tab-separated header of
# channel names, a units row, decimal commas, cp1252 text (German Windows).
KISTLER = (
    "DynoWare\tV3.2.2.0\r\n"
    "Messung\tcone_71\r\n"
    "Abtastrate\t1000\r\n"
    "\r\n"
    "Zeit\tFx\tFy\tFz\tMx\tMy\tMz\r\n"
    "s\tN\tN\tN\tN·m\tN·m\tN·m\r\n"
    "0,000\t12,5\t-3,25\t-400,0\t1,5\t-2,0\t0,125\r\n"
    "0,001\t13,0\t-3,5\t-401,5\t1,25\t-2,5\t0,25\r\n"
)


def test_kistler_dynoware_text_export(tmp_path):
    f = _w(tmp_path, "dyno.txt", KISTLER, encoding="cp1252")
    profile, cols, units = detect_force_format(f)
    assert profile == "kistler"
    assert cols["time"] == "Zeit"
    assert units["force"] == "N" and units["time"] == "s"
    log = read_force_log(f)
    np.testing.assert_allclose(log.time, [0.0, 0.001])
    np.testing.assert_allclose(log.wrench[1], [13.0, -3.5, -401.5, 1.25, -2.5, 0.25])


def test_three_component_dynamometer_has_unknown_moments(tmp_path):
    text = "Time [ms];Fx [kN];Fy [kN];Fz [kN]\n0;0,1;0,2;-0,5\n2;0,125;0,25;-0,75\n"
    f = _w(tmp_path, "d3.csv", text)
    assert detect_force_format(f)[0] == "dyno3"
    log = read_force_log(f)
    np.testing.assert_allclose(log.time, [0.0, 0.002])
    np.testing.assert_allclose(log.force[1], [125.0, 250.0, -750.0])
    assert not log.moments_known and np.all(log.moment == 0)


def test_partial_moments_are_refused(tmp_path):
    f = _w(tmp_path, "p.csv", "time [s],Fx [N],Fy [N],Fz [N],Mz [Nm]\n0,1,2,3,4\n1,1,2,3,4\n")
    with pytest.raises(InputError, match=r"missing column.*Mx"):
        read_force_log(f)


@pytest.mark.parametrize("sep", [",", ";", "\t", "   "])
def test_any_separator_case_and_bom(tmp_path, sep):
    rows = [
        ["TIME", "fx", "FY", "Fz", "mx", "MY", "mz"],
        [0.5, 1, 2, -300, 0.1, 0.2, 0.3],
        [1.0, 1.5, 2.5, -301, 0.15, 0.25, 0.35],
    ]
    text = "\n".join(sep.join(str(c) for c in r) for r in rows) + "\n"
    f = _w(tmp_path, "f.csv", "\ufeff# units: time=s force=N moment=N*m\n" + text)
    log = read_force_log(f)
    np.testing.assert_allclose(log.wrench[1], [1.5, 2.5, -301, 0.15, 0.25, 0.35])
    np.testing.assert_allclose(log.time, [0.5, 1.0])


def test_columns_table_for_any_names(tmp_path):
    text = (
        "Versuch 12\nt [s];Kraft X [N];Kraft Y [N];Kraft Z [N]\n0,0;1,0;2,0;3,0\n0,5;1,5;2,5;3,5\n"
    )
    f = _w(tmp_path, "k.csv", text)
    cols = {"time": "t [s]", "Fx": "Kraft X", "Fy": "Kraft Y", "Fz": "Kraft Z"}
    profile, found, _ = detect_force_format(f, columns=cols)
    assert profile == "columns" and found["Fx"] == "Kraft X [N]"
    log = read_force_log(f, columns=cols)
    np.testing.assert_allclose(log.force[1], [1.5, 2.5, 3.5])
    assert not log.moments_known


def test_units_never_guessed(tmp_path):
    f = _w(tmp_path, "f.csv", "time,Fx,Fy,Fz,Tx,Ty,Tz\n0,1,2,3,4,5,6\n1,1,2,3,4,5,6\n")
    with pytest.raises(InputError, match="unit not declared"):
        read_force_log(f)
    log = read_force_log(f, time_unit="s", force_unit="N", moment_unit="N*m")
    assert log.wrench.shape == (2, 6)
    g = _w(tmp_path, "g.csv", "time [s],Fx [furlong],Fy [N],Fz [N]\n0,1,2,3\n1,1,2,3\n")
    with pytest.raises(InputError, match="unknown force unit 'furlong'"):
        read_force_log(g)


def test_conflicting_units_refused(tmp_path):
    f = _w(tmp_path, "f.csv", "time [s],Fx [kN],Fy [kN],Fz [kN]\n0,1,2,3\n1,1,2,3\n")
    with pytest.raises(InputError, match="declared as 'kN' in the file but 'N'"):
        read_force_log(f, force_unit="N")


def test_bad_cell_names_line_and_column(tmp_path):
    text = "header block\nTime (s)\tFx (N)\tFy (N)\tFz (N)\n0\t1\t2\t3\n1\t1\tabc\t3\n"
    f = _w(tmp_path, "f.txt", text)
    with pytest.raises(InputError, match=r"f\.txt:4 \[Fy\]: not a number: 'abc'"):
        read_force_log(f)
    g = _w(tmp_path, "g.txt", "Time (s)\tFx (N)\tFy (N)\tFz (N)\n0\t1\t2\t3\n1\t1\n")
    with pytest.raises(InputError, match=r"g\.txt:3: expected at least 4 cells"):
        read_force_log(g)


def test_unrecognised_log_names_what_is_expected(tmp_path):
    f = _w(tmp_path, "f.csv", "a,b,c\n1,2,3\n")
    with pytest.raises(InputError, match=r"f\.csv: no force-log format recognised.*columns ="):
        read_force_log(f)


def test_parquet_force_log_round_trip_exact(tmp_path):
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(1e-3, 2e-3, 50))
    W = rng.normal(scale=300, size=(50, 6))
    log = ForceLog(t, W, "sensor", position=rng.normal(size=(50, 3)))
    write_force_log(log, tmp_path / "f.parquet")
    back = read_force_log(tmp_path / "f.parquet")
    # time exact (float64); measured channels as float32 (6e-8 relative), read back bit for bit
    assert np.array_equal(back.time, t)
    assert np.array_equal(back.wrench, W.astype(np.float32).astype(float))
    np.testing.assert_allclose(back.wrench, W, rtol=6e-8)
    assert back.position is not None
    assert np.array_equal(back.position, log.position.astype(np.float32).astype(float))
    assert back.frame == "sensor" and back.moments_known
    assert detect_force_format(tmp_path / "f.parquet")[2]["force"] == "N"


def test_parquet_schema_is_si_with_metadata(tmp_path):
    import json

    import pyarrow.parquet as pq

    log = ForceLog(np.array([0.0, 1.0]), np.ones((2, 6)), "sensor", moments_known=False)
    write_force_log(log, tmp_path / "f.parquet")
    tab = pq.read_table(tmp_path / "f.parquet")
    assert tab.column_names == ["time", "Fx", "Fy", "Fz", "Mx", "My", "Mz"]
    assert str(tab.schema.field("time").type) == "double"
    assert str(tab.schema.field("Fz").type) == "float"
    meta = json.loads(tab.schema.metadata[b"roboisf"])
    assert meta["units"] == {"time": "s", "force": "N", "moment": "N*m"}
    assert meta["kind"] == "force_log" and meta["moments_known"] is False
    assert not read_force_log(tmp_path / "f.parquet").moments_known


def test_foreign_parquet_needs_units(tmp_path):
    import pandas as pd

    pd.DataFrame(
        {"time": [0.0, 1.0], "Fx": [1.0, 2.0], "Fy": [0.0, 0.0], "Fz": [3.0, 4.0]}
    ).to_parquet(tmp_path / "x.parquet")
    with pytest.raises(InputError, match="unit not declared"):
        read_force_log(tmp_path / "x.parquet")
    log = read_force_log(tmp_path / "x.parquet", time_unit="ms", force_unit="kN")
    np.testing.assert_allclose(log.time, [0, 1e-3])
    np.testing.assert_allclose(log.force[:, 2], [3e3, 4e3])


# -- joint logs ---------------------------------------------------------------------------------

Q_DEG = np.array([[10.0, -20.0, 30.5, 0.0, 45.0, -180.0], [10.5, -19.5, 31.0, 0.25, 44.5, -179.5]])


def test_abb_j1_j6_degrees(tmp_path):
    text = "Time [s],J1 [deg],J2 [deg],J3 [deg],J4 [deg],J5 [deg],J6 [deg]\n"
    text += "".join(
        f"{t}," + ",".join(str(v) for v in q) + "\n" for t, q in zip([0, 0.004], Q_DEG, strict=True)
    )
    f = _w(tmp_path, "abb.csv", text)
    assert detect_joint_format(f)[0] == "abb"
    log = read_joint_log(f)
    np.testing.assert_allclose(log.q, np.radians(Q_DEG), rtol=1e-14)


def test_kuka_trace_text_export_semicolon_decimal_comma_ms(tmp_path):
    # KUKA trace data exported as text from WorkVisual's oscilloscope: a few description lines,
    # semicolon-separated channels named "AxisActPos A1 [°]" etc., time in ms, decimal comma
    head = "Trace: ISF_run_3\nController: KRC4\n"
    names = ";".join(f"AxisActPos A{i} [°]" for i in range(1, 7))
    rows = [
        f"{t};" + ";".join(f"{v:.2f}".replace(".", ",") for v in q)
        for t, q in zip(["0", "12"], Q_DEG, strict=True)
    ]
    f = _w(tmp_path, "kuka.txt", head + f"Time [ms];{names}\n" + "\n".join(rows) + "\n", "cp1252")
    profile, cols, units = detect_joint_format(f)
    assert profile == "kuka" and cols["q1"] == "AxisActPos A1 [°]"
    assert units == {"time": "ms", "angle": "°"}
    log = read_joint_log(f)
    np.testing.assert_allclose(log.time, [0.0, 0.012])
    np.testing.assert_allclose(log.q, np.radians(Q_DEG), rtol=1e-14)


def test_joint_radians_declared_by_study(tmp_path):
    row = "\t0.1\t0.2\t0.3\t0.4\t0.5\t0.6\n"
    text = "t\tA1\tA2\tA3\tA4\tA5\tA6\n0" + row + "1" + row
    f = _w(tmp_path, "k.txt", text)
    with pytest.raises(InputError, match="unit not declared"):
        read_joint_log(f)
    log = read_joint_log(f, time_unit="s", angle_unit="rad")
    assert math.isclose(log.q[0, 5], 0.6)


def test_parquet_joint_log_round_trip(tmp_path):
    t = np.array([0.0, 0.004])
    write_joint_log(tmp_path / "j.parquet", t, np.radians(Q_DEG))
    back = read_joint_log(tmp_path / "j.parquet")
    assert np.array_equal(back.q, np.radians(Q_DEG).astype(np.float32).astype(float))
    assert np.array_equal(back.time, t)
    assert detect_joint_format(tmp_path / "j.parquet")[2] == {"time": "s", "angle": "rad"}


def test_roboisf_joint_log_units_from_study_or_conflict(tmp_path):
    body = "time,q1,q2,q3,q4,q5,q6\n0,0.1,0.2,0.3,0.4,0.5,0.6\n1,0.1,0.2,0.3,0.4,0.5,0.6\n"
    f = _w(tmp_path, "j.csv", body)
    with pytest.raises(InputError, match="missing '# units") as e:
        read_joint_log(f)
    # the message says how to declare them in the study, with this file's name
    assert 'joints = {file = "j.csv", units = {time = "s", angle = "deg"}}' in e.value.message
    assert math.isclose(read_joint_log(f, angle_unit="rad").q[0, 0], 0.1)
    g = _w(tmp_path, "g.csv", "# units: time=s angle=deg\n" + body)
    with pytest.raises(InputError, match="declared as 'deg' in the file but 'rad'"):
        read_joint_log(g, angle_unit="rad")
    np.testing.assert_allclose(read_joint_log(g, angle_unit="°").q[0, 0], math.radians(0.1))


# -- writers in instrument profiles (every registered writer's round trip through auto
# detection: tests/test_formats_registry.py) ------------------------------------------------------


def test_ati_writer_needs_uniform_sampling(tmp_path):
    log = ForceLog(np.array([0.0, 0.001, 0.0025]), np.ones((3, 6)), "sensor")
    with pytest.raises(InputError, match="uniformly sampled"):
        write_force_log(log, tmp_path / "a.csv", profile="ati")
