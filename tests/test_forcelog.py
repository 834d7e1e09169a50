"""Force logs: units and frame declaration, bad rows with line numbers, attaching to a toolpath."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.logs.forcelog import (
    ForceLog,
    attach_to_toolpath,
    read_force_log,
    window_average,
    write_force_log,
)
from roboisf.parts import Cone
from roboisf.toolpath import step_down

GOOD = """# units: time=s force=N moment=N*m
# frame: sensor
time,Fx,Fy,Fz,Mx,My,Mz
0.0,1,2,-300,0.1,0.2,0.3
0.5,1,2,-310,0.1,0.2,0.3
1.0,1,2,-320,0.1,0.2,0.3
"""


def _write(tmp_path: Path, text: str, name: str = "f.csv") -> Path:
    f = tmp_path / name
    f.write_text(text)
    return f


def test_read_good(tmp_path):
    log = read_force_log(_write(tmp_path, GOOD))
    assert log.frame == "sensor"
    np.testing.assert_allclose(log.time, [0, 0.5, 1.0])
    np.testing.assert_allclose(log.wrench[:, 2], [-300, -310, -320])
    assert log.position is None


def test_units_converted_to_si(tmp_path):
    text = GOOD.replace("time=s force=N moment=N*m", "time=ms force=kN moment=N*mm")
    log = read_force_log(_write(tmp_path, text))
    np.testing.assert_allclose(log.time, [0, 0.5e-3, 1e-3])
    np.testing.assert_allclose(log.wrench[0], [1e3, 2e3, -300e3, 1e-4, 2e-4, 3e-4])


def test_units_from_arguments(tmp_path):
    text = GOOD.replace("# units: time=s force=N moment=N*m\n", "")
    f = _write(tmp_path, text)
    with pytest.raises(InputError, match="unit not declared") as ei:
        read_force_log(f)
    assert ei.value.field == "units"
    log = read_force_log(f, time_unit="s", force_unit="kN", moment_unit="N*m")
    assert log.wrench[0, 2] == pytest.approx(-300e3)
    # same declaration twice is fine, a conflict is not
    read_force_log(_write(tmp_path, GOOD, "g.csv"), force_unit="N")
    with pytest.raises(InputError, match="declared as 'N' in the file but 'kN'"):
        read_force_log(_write(tmp_path, GOOD, "g.csv"), force_unit="kN")


def test_frame_required_and_conflict(tmp_path):
    f = _write(tmp_path, GOOD.replace("# frame: sensor\n", ""))
    with pytest.raises(InputError, match="frame not declared"):
        read_force_log(f)
    assert read_force_log(f, frame="dynamometer").frame == "dynamometer"
    with pytest.raises(InputError, match="frame declared as 'sensor'"):
        read_force_log(_write(tmp_path, GOOD, "g.csv"), frame="tool")


def test_unknown_unit(tmp_path):
    f = _write(tmp_path, GOOD.replace("force=N", "force=kgf"))
    with pytest.raises(InputError, match="unknown force unit 'kgf'") as ei:
        read_force_log(f)
    assert "f.csv:1" in str(ei.value)


def test_units_line_takes_the_spellings_instruments_write(tmp_path):
    """The roboisf CSV's '# units:' line refused lbf and lbf-in (accepted in a header cell and
    by every other profile, and listed in docs/study.md), and 'Nm' in the file against the
    study's 'N*m' was a conflict: units are compared by what they mean."""
    lbf = 4.4482216152605
    log = read_force_log(
        _write(tmp_path, GOOD.replace("force=N moment=N*m", "force=lbf moment=lbf-in"))
    )
    np.testing.assert_allclose(log.wrench[:, 2], np.array([-300, -310, -320]) * lbf)
    np.testing.assert_allclose(log.wrench[:, 3], 0.1 * lbf * 0.0254)
    nm = _write(tmp_path, GOOD.replace("moment=N*m", "moment=Nm"), "nm.csv")
    log = read_force_log(nm, time_unit="s", force_unit="N", moment_unit="N*m")
    np.testing.assert_allclose(log.wrench[:, 3], 0.1)
    with pytest.raises(InputError, match="moment unit declared as 'Nm'"):
        read_force_log(nm, moment_unit="N*mm")  # a real conflict still is one


@pytest.mark.parametrize(
    ("row", "match"),
    [
        ("0.7,1,2,nan,0,0,0", "not a finite number"),
        ("0.7,1,2,-300,0,0", "expected 7 columns"),
        ("0.7,1,2,x,0,0,0", "not a number: 'x'"),
        ("0.4,1,2,-300,0,0,0", "time must strictly increase"),
        ("0.5,1,2,-300,0,0,0", "time must strictly increase"),
    ],
)
def test_bad_rows_report_line(tmp_path, row, match):
    lines = GOOD.splitlines()
    lines.insert(5, row)  # after the 0.5 s row: file line 6
    f = _write(tmp_path, "\n".join(lines) + "\n")
    with pytest.raises(InputError, match=match) as ei:
        read_force_log(f)
    assert ei.value.line == 6
    assert "f.csv:6" in str(ei.value)


def test_missing_column(tmp_path):
    f = _write(tmp_path, GOOD.replace("Mz", "Mq"))
    with pytest.raises(InputError, match="missing column"):
        read_force_log(f)


def test_round_trip_with_positions(tmp_path):
    rng = np.random.default_rng(0)
    n = 500
    log = ForceLog(
        np.cumsum(rng.uniform(1e-3, 2e-3, n)),
        rng.normal(0, 300, (n, 6)) * [1, 1, 1, 1e-3, 1e-3, 1e-3],
        "sensor",
        position=rng.normal(0, 0.05, (n, 3)),
    )
    f = tmp_path / "log.csv"
    write_force_log(log, f, force_unit="kN", moment_unit="N*mm", time_unit="ms")
    back = read_force_log(f)
    np.testing.assert_allclose(back.time, log.time, rtol=0, atol=1e-12)
    np.testing.assert_allclose(back.wrench, log.wrench, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(back.position, log.position, rtol=1e-9, atol=1e-15)
    assert back.frame == "sensor"


def test_window_average_exact_for_piecewise_linear():
    t = np.array([0.0, 1.0, 3.0, 4.0])
    y = np.array([[0.0], [2.0], [2.0], [6.0]])
    # ∫0^4 = 1 + 4 + 4 = 9 → mean 9/4; window [0.5, 3.5]: ∫ = 0.75 + 4 + 1.5+... compute by hand:
    # [0.5,1]: mean(1,2)·0.5 = 0.75; [1,3]: 4; [3,3.5]: mean(2,4)·0.5 = 1.5 → 6.25 / 3
    got = window_average(t, y, np.array([0.0, 0.5, 2.0]), np.array([4.0, 3.5, 2.0]))
    np.testing.assert_allclose(got[:, 0], [9 / 4, 6.25 / 3, 2.0])


def test_window_average_matches_dense_sampling():
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.01, 0.1, 200))
    y = rng.normal(size=(200, 2))
    lo = rng.uniform(t[0], t[-1], 30)
    hi = np.minimum(lo + rng.uniform(0.0, 2.0, 30), t[-1])
    got = window_average(t, y, lo, hi)
    for i in range(30):
        x = np.linspace(lo[i], hi[i], 200001)
        ref = [np.interp(x, t, y[:, j]).mean() for j in range(2)]
        np.testing.assert_allclose(got[i], ref, atol=2e-4)


@pytest.fixture(scope="module")
def small_path():
    return step_down(Cone(depth=3e-3), 5e-3, 1e-3, spacing=5e-3)


def _ramp_log(tp, offset=0.0, slope=-50.0):
    """Fz = −300 + slope·t, sampled at 1 kHz over the toolpath (+1 s margins)."""
    t = np.arange(-1.0, tp.time[-1] + 1.0, 1e-3) + offset
    w = np.zeros((t.size, 6))
    w[:, 2] = -300 + slope * (t - offset)
    w[:, 0] = 10.0
    return ForceLog(t, w, "sensor")


def test_attach_by_time_linear_signal(small_path):
    """For a linear signal the window mean is the value at the window centre."""
    tp = small_path
    log = _ramp_log(tp, offset=2.0)
    W = attach_to_toolpath(log, tp, by="time", time_offset=2.0)
    tt = tp.time
    mid = 0.5 * (tt[1:] + tt[:-1])
    centre = 0.5 * (np.concatenate([[tt[0]], mid]) + np.concatenate([mid, [tt[-1]]]))
    np.testing.assert_allclose(W[:, 2], -300 - 50 * centre, atol=1e-9)
    np.testing.assert_allclose(W[:, 0], 10.0)
    W0 = attach_to_toolpath(log, tp, by="time", window=0.0, time_offset=2.0)
    np.testing.assert_allclose(W0[:, 2], -300 - 50 * tt, atol=1e-9)
    Ww = attach_to_toolpath(log, tp, by="time", window=0.2, time_offset=2.0)
    inner = (tt > 0.1) & (tt < tt[-1] - 0.1)
    np.testing.assert_allclose(Ww[inner, 2], -300 - 50 * tt[inner], atol=1e-9)


def test_attach_by_time_out_of_range(small_path):
    log = _ramp_log(small_path)
    with pytest.raises(InputError, match="outside the logged time span"):
        attach_to_toolpath(log, small_path, by="time", time_offset=5.0)


def test_attach_by_position(small_path):
    tp = small_path
    # log sampled exactly at the toolpath tips, shuffled, plus far-away noise samples
    rng = np.random.default_rng(2)
    order = rng.permutation(len(tp))
    wrench = np.zeros((len(tp), 6))
    wrench[:, 2] = -np.arange(len(tp), dtype=float)
    log = ForceLog(
        np.arange(len(tp), dtype=float),
        wrench[order],
        "sensor",
        position=tp.tip[order] + rng.normal(0, 1e-6, (len(tp), 3)),
    )
    W = attach_to_toolpath(log, tp, by="position")
    np.testing.assert_array_equal(W[:, 2], -np.arange(len(tp), dtype=float))
    with pytest.raises(InputError, match="needs the tip position"):
        attach_to_toolpath(ForceLog(log.time, log.wrench, "sensor"), tp, by="position")
    with pytest.raises(InputError, match="no logged position within"):
        attach_to_toolpath(log, tp, by="position", positions=log.position + 0.01, max_distance=1e-3)


def test_cumulative_integral_in_place_same_bits_as_the_textbook_formula():
    # issue #16: the running trapezoid sum is built in one buffer; it must give the same bits
    # as the formula it replaced (0.5 scales exactly, so no rounding differs)
    from roboisf.logs.forcelog import _cumulative_integral

    rng = np.random.default_rng(7)
    t = np.cumsum(rng.uniform(0.5e-3, 1.5e-3, 50_001))
    y = rng.normal(scale=300.0, size=(t.size, 6))
    ref = np.concatenate(
        [np.zeros((1, 6)), np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t)[:, None], axis=0)]
    )
    got = _cumulative_integral(t, y)
    assert got.shape == (t.size, 6) and got.flags.c_contiguous
    assert np.array_equal(got, ref)
    # and it is the integral: ∫ of a linear y = a + b t is exact for the trapezoid rule
    lin = (2.0 + 3.0 * t)[:, None]
    exact = 2.0 * (t - t[0]) + 1.5 * (t**2 - t[0] ** 2)
    assert np.allclose(_cumulative_integral(t, lin)[:, 0], exact, rtol=1e-12, atol=1e-12)


def test_parquet_force_log_read_unchanged_by_in_place_scaling(tmp_path):
    # the reader scales columns in place and fills one (N, 6) wrench: same values as the log
    # written, in SI, with and without moment channels
    from roboisf.logs.logparquet import read_force_parquet, write_force_parquet

    rng = np.random.default_rng(3)
    t = np.arange(1000) * 1e-3
    W = rng.normal(scale=100.0, size=(t.size, 6)).astype(np.float32).astype(float)
    log = ForceLog(t, W, "sensor")
    write_force_parquet(log, tmp_path / "f.parquet")
    back = read_force_parquet(tmp_path / "f.parquet")
    assert np.array_equal(back.time, t) and np.array_equal(back.wrench, W)
    assert back.wrench.flags.c_contiguous and back.moments_known


@pytest.mark.parametrize("sep", [",", ";", "\t"])
def test_a_header_one_force_column_short_names_the_missing_one(tmp_path, sep):
    """A log with Fz cut out was 'no force-log format recognised: expected a header naming
    time, Fx, Fy, Fz …'; the header's line and the missing column are named."""
    rows = ["# some logger", sep.join(["time [s]", "Fx [N]", "Fy [N]", "Mx", "My", "Mz"]),
            sep.join(["0.0", "1", "2", "0", "0", "0"])]  # fmt: skip
    f = _write(tmp_path, "\n".join(rows) + "\n")
    with pytest.raises(InputError) as ei:
        read_force_log(f)
    e = ei.value
    assert e.line == 2 and e.field == "Fz" and "no Fz" in e.message
