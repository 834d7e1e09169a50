"""Universal Robots RTDE recordings (issue #28): ``timestamp actual_q_0..5 actual_TCP_force_0..5``
as UR's ``record.py`` writes them (blank-separated, every recipe field, SI by the RTDE spec) read
as joint and force logs by ``auto``, with the RTDE units and the frame caveat said."""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.logs.forcelog import detect_force_format, read_force_log
from roboisf.logs.jointlog import detect_joint_format, read_joint_log


def _rtde(tmp_path, n=40, extra_units=False):
    """A recording with the fields of UR's example recipe around the ones roboisf reads."""
    cols = ["timestamp"]
    cols += [f"target_q_{i}" for i in range(6)] + [f"actual_q_{i}" for i in range(6)]
    cols += [f"actual_TCP_pose_{i}" for i in range(6)] + [f"actual_TCP_force_{i}" for i in range(6)]
    cols += ["robot_mode", "actual_digital_output_bits"]
    t = 1234.5 + 0.008 * np.arange(n)  # the controller's clock at 125 Hz
    q = np.column_stack([0.1 * k + 0.01 * np.sin(t + k) for k in range(6)])
    w = np.empty((n, 6))
    w[:, :3] = np.column_stack([np.full(n, 3.0), np.full(n, -4.0), 250.0 + np.arange(n)])
    w[:, 3:] = [0.5, -0.2, 0.05]
    rows = np.column_stack([t, q + 0.001, q, np.zeros((n, 6)), w, np.full(n, 7), np.zeros(n)])
    p = tmp_path / "robot_data.csv"
    body = "\n".join(" ".join(repr(float(v)) for v in r) for r in rows)
    p.write_text(" ".join(cols) + "\n" + body + "\n")
    return p, t, q, w


def test_rtde_joints_and_forces_auto(tmp_path):
    p, t, q, w = _rtde(tmp_path)
    prof, cols, units = detect_joint_format(p)
    assert prof == "ur" and cols["q1"] == "actual_q_0" and cols["q6"] == "actual_q_5"
    assert units == {"time": "s", "angle": "rad"}
    jl = read_joint_log(p)
    np.testing.assert_allclose(jl.time, t)
    np.testing.assert_allclose(jl.q, q)  # actual_q, not target_q; radians as logged
    prof, cols, units = detect_force_format(p)
    assert prof == "ur" and cols["Mz"] == "actual_TCP_force_5"
    fl = read_force_log(p)
    np.testing.assert_allclose(fl.wrench, w)
    assert fl.frame == "base" and fl.moments_known
    assert any("base axes" in n for n in fl.notes)


def test_rtde_units_given_otherwise_are_refused(tmp_path):
    p, *_ = _rtde(tmp_path)
    with pytest.raises(InputError, match="angle unit declared as 'rad' in the file but 'deg'"):
        read_joint_log(p, angle_unit="deg")


def test_rtde_without_forces_names_the_profiles(tmp_path):
    p = tmp_path / "q_only.csv"
    p.write_text("timestamp actual_q_0 actual_q_1\n0 0 0\n")
    with pytest.raises(InputError, match="UR RTDE"):
        read_joint_log(p)
    with pytest.raises(InputError, match="UR RTDE"):
        read_force_log(p)


def test_fanuc_profile_reads_j_columns(tmp_path):
    """format = "fanuc": J1..J6 as a FANUC export writes them (pendant angles, degrees)."""
    p = tmp_path / "fanuc.csv"
    p.write_text(
        "Time [s];J1 [deg];J2 [deg];J3 [deg];J4 [deg];J5 [deg];J6 [deg]\n"
        "0,0;10,0;-20,0;5,0;0,0;-70,0;0,0\n"
        "0,1;10,5;-20,0;5,0;0,0;-70,0;0,0\n"
    )
    jl = read_joint_log(p, fmt="fanuc")
    np.testing.assert_allclose(np.degrees(jl.q[1]), [10.5, -20, 5, 0, -70, 0])
    np.testing.assert_allclose(jl.time, [0.0, 0.1])
    assert detect_joint_format(p, fmt="fanuc")[0] == "fanuc"


def test_a_real_rtde_recording():
    """A recording from UR's RTDE client repository (tests/data/logs/README.md): found as 'ur' by
    auto, every value equal to the csv module's parse, seconds and radians as RTDE states."""
    import csv
    from pathlib import Path

    p = Path(__file__).parent / "data" / "logs" / "ur_rtde_jointData_head.csv"
    with p.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    t = np.array([float(r["timestamp"]) for r in rows])
    q = np.array([[float(r[f"actual_q_{i}"]) for i in range(6)] for r in rows])
    prof, cols, units = detect_joint_format(p)
    assert prof == "ur" and units == {"time": "s", "angle": "rad"}
    assert cols["q1"] == "actual_q_0" and cols["time"] == "timestamp"
    jl = read_joint_log(p)
    np.testing.assert_array_equal(jl.time, t)
    np.testing.assert_array_equal(jl.q, q)
    assert len(jl.time) == 250 and np.median(np.diff(jl.time)) == pytest.approx(0.008, abs=1e-4)
    with pytest.raises(InputError, match="no force-log format recognised"):
        read_force_log(p)  # joints and poses only: no actual_TCP_force columns


def _named_joint_log(tmp_path):
    p = tmp_path / "j.csv"
    head = "Zeit [s];" + ";".join(f"Achse {i} [deg]" for i in range(1, 7)) + ";Status"
    rows = [
        f"{0.01 * k:.2f};" + ";".join(f"{10 * i + k}" for i in range(1, 7)) + ";ok"
        for k in range(5)
    ]
    p.write_text(head + "\n" + "\n".join(rows) + "\n")
    return p


JOINT_COLUMNS_MAP = {"time": "Zeit", **{f"q{i}": f"Achse {i}" for i in range(1, 7)}}


def test_joint_log_columns_map(tmp_path):
    """issue #28: joint logs take ``columns = {…}`` as force logs do — any header names, units
    from the names' brackets; a name not in the file is refused naming what was looked for."""
    p = _named_joint_log(tmp_path)
    jl = read_joint_log(p, columns=JOINT_COLUMNS_MAP)
    np.testing.assert_allclose(np.degrees(jl.q[2]), [12, 22, 32, 42, 52, 62])
    np.testing.assert_allclose(jl.time, [0, 0.01, 0.02, 0.03, 0.04])
    with pytest.raises(InputError, match="no joint-log format recognised"):
        read_joint_log(p)  # without the map: Achse is no known name
    bad = dict(JOINT_COLUMNS_MAP, q6="Achse 7")
    with pytest.raises(InputError) as e:
        read_joint_log(p, columns=bad)
    assert "Achse 7" in e.value.message  # the names the study gave, not q1..q6
    with pytest.raises(InputError, match="columns must map each of"):
        read_joint_log(p, columns={"time": "Zeit"})


def test_joint_log_columns_from_the_study(tmp_path):
    from roboisf.decompose.pipeline import read_run_joint_log
    from roboisf.study import load_study
    from test_logs_study import _study

    cols = ", ".join(f'{k} = "{v}"' for k, v in JOINT_COLUMNS_MAP.items())
    s = _study(tmp_path, joints=f'[runs.robot.joints]\nfile = "j.csv"\ncolumns = {{{cols}}}')
    _named_joint_log(tmp_path)  # replaces the placeholder j.csv
    st = load_study(s)
    assert st.robot_run.joints_format == "columns"
    jl = read_run_joint_log(st.robot_run)
    np.testing.assert_allclose(np.degrees(jl.q[0]), [10, 20, 30, 40, 50, 60])
