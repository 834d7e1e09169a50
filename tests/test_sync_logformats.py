"""Equipment log layouts written by the virtual cell (issue #13) — each a registered format's
writer (roboisf.formats, issue #25): ATI Net F/T CSV, Kistler
DynoWare text (3 components, decimal comma), ABB J1..J6, KUKA A1..A6 trace CSV.

Checked by an independent parser (pandas with the layout's separator, decimal mark and header
rows, written here by hand from the layout's description), not by roboisf's readers: the values
read back must be the log's.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from roboisf.errors import InputError
from roboisf.logs.forcelog import ForceLog
from roboisf.virtual.equipment import Equipment
from roboisf.virtual.logformats import write_force_profile, write_joint_profile


@pytest.fixture
def log():
    rng = np.random.default_rng(3)
    t = 12.5 + np.arange(200) / 500.0
    return ForceLog(t, rng.normal(scale=300.0, size=(200, 6)), "sensor")


def test_ati_netft_csv(log, tmp_path):
    # the ATI demo's layout, as roboisf's ATI reader expects it (one registered writer)
    p = tmp_path / "ati.csv"
    write_force_profile(log, p, "ati")
    lines = p.read_text().splitlines()
    assert lines[1] == "RDT Sample Rate: 500" and lines[3] == "Force Units: N"
    assert lines[5] == "Torque Units: Nm"
    df = pd.read_csv(p, skiprows=7, skipinitialspace=True)
    assert list(df.columns) == [
        "Status (hex)",
        "RDT Sequence",
        "F/T Sequence",
        "Fx",
        "Fy",
        "Fz",
        "Tx",
        "Ty",
        "Tz",
        "Time",
    ]
    assert (df["Status (hex)"] == "0x0").all()
    # RDT sequence counts samples at the sample rate: time = sequence / rate
    np.testing.assert_array_equal(np.diff(df["RDT Sequence"]), np.ones(199))
    np.testing.assert_allclose(df["RDT Sequence"] / 500.0, log.time, atol=1e-9)
    np.testing.assert_allclose(df[["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"]], log.wrench, rtol=1e-9)


def test_kistler_dynoware_text(log, tmp_path):
    p = tmp_path / "kistler.txt"
    write_force_profile(log, p, "kistler")
    df = pd.read_csv(p, sep="\t", decimal=",", skiprows=5)
    assert list(df.columns) == ["Time [s]", "Fx [N]", "Fy [N]", "Fz [N]"]  # no moments
    np.testing.assert_allclose(df[["Fx [N]", "Fy [N]", "Fz [N]"]], log.force, rtol=1e-9)
    np.testing.assert_allclose(df["Time [s]"], log.time, atol=1e-9)
    assert "." not in p.read_text().split("\n", 6)[-1]  # decimal commas only


def test_abb_and_kuka_joint_logs(tmp_path):
    rng = np.random.default_rng(4)
    t = np.arange(50) * 0.004
    q = rng.uniform(-2, 2, size=(50, 6))
    write_joint_profile(tmp_path / "abb.csv", t, q, "abb")
    df = pd.read_csv(tmp_path / "abb.csv")
    assert list(df.columns) == ["Time", "J1", "J2", "J3", "J4", "J5", "J6"]
    np.testing.assert_allclose(df.iloc[:, 1:], np.degrees(q), atol=1e-8)
    write_joint_profile(tmp_path / "kuka.csv", t, q, "kuka")
    df = pd.read_csv(tmp_path / "kuka.csv", sep=";", decimal=",")
    assert list(df.columns) == ["Time [s]"] + [f"A{i} [deg]" for i in range(1, 7)]
    np.testing.assert_allclose(df.iloc[:, 1:], np.degrees(q), atol=1e-8)
    np.testing.assert_allclose(df["Time [s]"], t, atol=1e-9)


def test_unknown_profiles_are_refused(log, tmp_path):
    with pytest.raises(InputError, match="unknown force log format 'dewesoft'"):
        write_force_profile(log, tmp_path / "x.csv", "dewesoft")
    with pytest.raises(InputError, match="expected one of roboisf, abb, kuka"):
        Equipment(joint_profile="fanuc")
    assert not Equipment(cnc_force_profile="kistler").is_clean
    assert Equipment(cnc_force_profile="kistler").clock_is_nominal


def test_virtual_cell_writes_the_profiles(tmp_path):
    """The study's log files in the chosen layouts, same content as the roboisf ones."""
    from roboisf.logs.forcelog import read_force_log
    from roboisf.logs.jointlog import read_joint_log
    from roboisf.virtual.cell import build_study, paper_cone_cell

    kw = {"scan_points": 20_000, "force_rate": 50.0, "joint_rate": 20.0}
    kw |= {"step_down": 3e-3, "spacing": 6e-3}
    clean = build_study(paper_cone_cell(**kw), tmp_path / "clean", log_format="csv")
    eq = Equipment(cnc_force_profile="kistler", robot_force_profile="ati", joint_profile="kuka")
    prof = build_study(paper_cone_cell(**kw), tmp_path / "prof", equipment=eq)
    ref = read_force_log(clean / "robot_forces.csv")
    ati = pd.read_csv(prof / "robot_forces.csv", skiprows=7, skipinitialspace=True)
    n = len(ref) - 2  # the equipment logs 2 s past the end out of contact, the clean log in it
    assert len(ati) > n
    seq = ati["RDT Sequence"].to_numpy()[:n]  # ATI's time axis: RDT sequence / sample rate
    np.testing.assert_allclose((seq - seq[0]) / kw["force_rate"], ref.time[:n] - ref.time[0])
    # same cell, other noise draw: the same forces within the sensor noise (2 N)
    d = ati[["Fx", "Fy", "Fz"]].to_numpy()[:n] - ref.force[:n]
    assert np.abs(d).max() < 20.0 and np.abs(d).mean() < 4.0
    kis = pd.read_csv(prof / "cnc_forces.csv", sep="\t", decimal=",", skiprows=5)
    assert kis.shape[1] == 4
    j = read_joint_log(clean / "robot_joints.csv")
    kuka = pd.read_csv(prof / "robot_joints.csv", sep=";", decimal=",")
    m = len(j.time)
    np.testing.assert_allclose(kuka.iloc[:m, 1:], np.degrees(j.q), atol=1e-6)
    assert "sync" not in (prof / "study.toml").read_text()  # nominal clock: nothing to align
