"""Timestamp policy of a log (issue #28): refuse by default with the line and the counts, or
repair — a few rows put back in order, exact duplicates dropped, equal stamps averaged —
counted and said; a clock that jumps back is refused either way."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.io.timestamps import repair_time
from roboisf.logs.forcelog import read_force_log
from roboisf.logs.jointlog import read_joint_log


def _force_csv(tmp_path: Path, rows: list[tuple[float, ...]], name="f.csv") -> Path:
    p = tmp_path / name
    body = "\n".join(",".join(f"{v:g}" for v in r) for r in rows)
    p.write_text(
        "# units: time=s force=N moment=N*m\n# frame: sensor\ntime,Fx,Fy,Fz,Mx,My,Mz\n"
        + body
        + "\n"
    )
    return p


def _rows(n: int) -> list[tuple[float, ...]]:
    return [(0.01 * i, 1.0 + i, 2.0, -300.0 - i, 0.0, 0.0, 0.1 * i) for i in range(n)]


def test_refuse_is_the_default_and_names_the_line(tmp_path):
    rows = _rows(20)
    rows.insert(10, rows[9])  # an exact duplicate at data row 10 → file line 3 + 10 + 1
    p = _force_csv(tmp_path, rows)
    with pytest.raises(InputError) as e:
        read_force_log(p)
    assert e.value.line == 14
    assert "0.09 s repeats 0.09 s" in e.value.message
    assert "1 repeated and 0 decreasing" in e.value.message
    assert 'timestamps = "repair"' in e.value.message


def test_repair_drops_duplicates_averages_equal_stamps_and_reorders(tmp_path):
    good = _rows(300)
    rows = list(good)
    rows.insert(50, good[49])  # exact duplicate
    rows.insert(100, (good[98][0], 5.0, 2.0, -310.0, 0.0, 0.0, 1.0))  # same stamp, other values
    rows[200], rows[201] = rows[201], rows[200]  # two rows swapped
    p = _force_csv(tmp_path, rows)
    log = read_force_log(p, timestamps="repair")
    assert np.all(np.diff(log.time) > 0)
    np.testing.assert_allclose(log.time, [r[0] for r in good], atol=1e-12)
    # the averaged sample is the mean of its two rows; every other row is the file's
    i = 98
    other_row = np.array([5.0, 2, -310, 0, 0, 1])
    np.testing.assert_allclose(log.wrench[i], (np.array(good[i][1:]) + other_row) / 2)
    other = np.delete(np.arange(300), i)
    np.testing.assert_allclose(log.wrench[other], np.array(good)[other, 1:])
    (note,) = log.notes
    assert "1 row(s) put back in time order" in note
    assert "1 exact duplicate row(s) dropped" in note
    assert "1 row(s) with a repeated time averaged" in note
    # a clean log has no note
    assert read_force_log(_force_csv(tmp_path, good, "g.csv"), timestamps="repair").notes == ()


def test_a_clock_that_jumps_back_is_refused_even_under_repair(tmp_path):
    rows = _rows(100)
    rows += [(r[0] - 0.5, *r[1:]) for r in _rows(10)]  # the clock restarts: 10 rows back
    p = _force_csv(tmp_path, rows)
    with pytest.raises(InputError, match="clock that jumps back") as e:
        read_force_log(p, timestamps="repair")
    assert e.value.line == 3 + 100 + 1


def test_joint_log_policy(tmp_path):
    p = tmp_path / "j.csv"
    lines = ["# units: time=s angle=deg", "time,q1,q2,q3,q4,q5,q6"]
    for i in range(50):
        lines.append(f"{0.004 * i:.3f},{i},10,20,0,30,0")
        if i == 20:
            lines.append(f"{0.004 * i:.3f},{i},10,20,0,30,0")  # the controller wrote it twice
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match="time must strictly increase") as e:
        read_joint_log(p)
    assert e.value.line == 2 + 21 + 1
    jl = read_joint_log(p, timestamps="repair")
    assert len(jl.time) == 50 and np.all(np.diff(jl.time) > 0)
    assert "1 exact duplicate" in jl.notes[0]


def test_repair_time_counts_like_the_issue_log():
    """A 28.5 k-row log with 108 repeated stamps (one tick of a coarse clock): 108 averaged."""
    rng = np.random.default_rng(1)
    t = np.arange(28_500) * 1e-3
    rep = rng.choice(np.arange(1, 28_500), 108, replace=False)
    t[rep] = t[rep - 1]
    v = rng.normal(size=(28_500, 3))
    t2, _, r = repair_time(t, v, "repair", error=lambda m, i: InputError(m, line=i))
    assert r.averaged == 108 and r.duplicates == 0 and r.reordered == 0
    assert len(t2) == 28_500 - 108 and np.all(np.diff(t2) > 0)
    with pytest.raises(InputError, match="108 repeated"):
        repair_time(t, v, "refuse", error=lambda m, i: InputError(m, line=i))


def test_study_keys(tmp_path):
    """``timestamps`` per log in study.toml: parsed, "refuse" by default, a typo named."""
    from roboisf.study import StudyError, load_study
    from test_logs_study import _study

    s = _study(
        tmp_path,
        rob='timestamps = "repair"',
        joints='[runs.robot.joints]\nfile = "j.csv"\ntimestamps = "repair"',
    )
    st = load_study(s)
    assert st.robot_run.forces.timestamps == "repair" and st.cnc.forces.timestamps == "refuse"
    assert st.robot_run.joints_timestamps == "repair"
    s = _study(tmp_path, cnc='timestamps = "fix"')
    with pytest.raises(StudyError) as ei:
        load_study(s)
    hits = [p for p in ei.value.problems if p.field == "runs.cnc.forces.timestamps"]
    assert hits and "expected one of refuse, repair" in hits[0].message
