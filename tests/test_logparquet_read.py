"""Parquet logs read column by column into the SI arrays (issue #16): the same values as an
independent read (pyarrow → float64 × unit factor), every column still checked."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from roboisf.errors import InputError
from roboisf.logs.forcelog import ForceLog
from roboisf.logs.logparquet import (
    read_force_parquet,
    read_joint_parquet,
    write_force_parquet,
    write_joint_parquet,
)


def _foreign(path, cols):
    pq.write_table(pa.table(cols), path, row_group_size=700)  # several chunks per column


def test_foreign_units_types_and_positions(tmp_path) -> None:
    rng = np.random.default_rng(1)
    n = 2000
    t_ms = np.arange(n, dtype=np.int64) * 2 + 5  # integer milliseconds
    F = rng.normal(scale=0.4, size=(n, 3)).astype(np.float32)  # kN, float32
    M = rng.normal(scale=20.0, size=(n, 3))  # N*m, float64
    xyz = rng.normal(scale=50.0, size=(n, 3)).astype(np.float32)  # mm
    cols = {"time": t_ms, "extra": rng.normal(size=n)}
    cols.update({c: F[:, j] for j, c in enumerate(("Fx", "Fy", "Fz"))})
    cols.update({c: M[:, j] for j, c in enumerate(("Mx", "My", "Mz"))})
    cols.update({c: xyz[:, j] for j, c in enumerate("xyz")})
    _foreign(tmp_path / "f.parquet", cols)
    units = {"time": "ms", "force": "kN", "moment": "N*m", "length": "mm"}
    log = read_force_parquet(tmp_path / "f.parquet", given=units)
    np.testing.assert_array_equal(log.time, t_ms.astype(np.float64) * 1e-3)
    np.testing.assert_array_equal(log.wrench[:, :3], F.astype(np.float64) * 1e3)
    np.testing.assert_array_equal(log.wrench[:, 3:], M)
    assert log.position is not None
    np.testing.assert_array_equal(log.position, xyz.astype(np.float64) * 1e-3)
    assert log.wrench.flags.c_contiguous and log.wrench.flags.writeable


def test_three_component_and_joint_log(tmp_path) -> None:
    t = np.arange(500) * 1e-3
    W = np.zeros((500, 6))
    W[:, :3] = np.random.default_rng(2).normal(scale=300, size=(500, 3)).astype(np.float32)
    write_force_parquet(ForceLog(t, W, "sensor", moments_known=False), tmp_path / "f.parquet")
    back = read_force_parquet(tmp_path / "f.parquet")
    assert not back.moments_known
    np.testing.assert_array_equal(back.wrench, W)
    q = np.random.default_rng(3).uniform(-2, 2, size=(500, 6))
    write_joint_parquet(tmp_path / "j.parquet", t, q)
    tj, qj = read_joint_parquet(tmp_path / "j.parquet")
    np.testing.assert_array_equal(tj, t)
    np.testing.assert_array_equal(qj, q.astype(np.float32).astype(np.float64))


@pytest.mark.parametrize(
    ("column", "value", "message"),
    [("Fy", np.nan, "row 7 is not a finite number"), ("extra", np.inf, "row 7 is not a finite")],
)
def test_bad_values_named(tmp_path, column, value, message) -> None:
    t = np.arange(20) * 1e-3
    cols = {"time": t, **{c: np.ones(20, np.float32) for c in ("Fx", "Fy", "Fz")}}
    cols["extra"] = np.zeros(20)
    cols[column] = cols[column].copy()
    cols[column][7] = value
    _foreign(tmp_path / "f.parquet", cols)
    with pytest.raises(InputError, match=message) as e:
        read_force_parquet(tmp_path / "f.parquet", given={"time": "s", "force": "N"})
    assert e.value.field == column


def test_text_column_refused(tmp_path) -> None:
    t = np.arange(5) * 1e-3
    cols = {"time": t, "Fx": np.ones(5), "Fy": ["a", "b", "c", "d", "e"], "Fz": np.ones(5)}
    _foreign(tmp_path / "f.parquet", cols)
    with pytest.raises(InputError, match="not numeric"):
        read_force_parquet(tmp_path / "f.parquet", given={"time": "s", "force": "N"})


def test_bad_value_in_a_later_batch_named_by_its_file_row(tmp_path) -> None:
    n = 70_000  # more rows than one decoded batch
    cols = {"time": np.arange(n) * 1e-3, **{c: np.ones(n, np.float32) for c in ("Fx", "Fy", "Fz")}}
    cols["Fz"][65_541] = np.inf
    _foreign(tmp_path / "f.parquet", cols)
    with pytest.raises(InputError, match="row 65541 is not a finite number"):
        read_force_parquet(tmp_path / "f.parquet", given={"time": "s", "force": "N"})


def test_time_not_increasing_named_by_its_row(tmp_path) -> None:
    t = np.arange(20) * 1e-3
    t[12] = t[11]  # a repeated stamp
    cols = {"time": t, **{c: np.ones(20, np.float32) for c in ("Fx", "Fy", "Fz")}}
    _foreign(tmp_path / "f.parquet", cols)
    with pytest.raises(InputError, match=r"time must strictly increase \(row 12\)") as e:
        read_force_parquet(tmp_path / "f.parquet", given={"time": "s", "force": "N"})
    assert e.value.field == "time"
    write_joint_parquet(tmp_path / "j.parquet", t, np.zeros((20, 6)))
    from roboisf.logs.jointlog import read_joint_log

    with pytest.raises(InputError, match=r"time must increase strictly \(row 12\)"):
        read_joint_log(tmp_path / "j.parquet")


def test_checked_log_is_the_validated_one(tmp_path) -> None:
    """The reader's log (ForceLog.checked: not validated twice) equals the one the constructor
    validates; arrays that are not a reader's get the constructor's checks and messages."""
    rng = np.random.default_rng(4)
    t = np.arange(300) * 1e-3
    W = rng.normal(scale=100, size=(300, 6)).astype(np.float32).astype(np.float64)
    write_force_parquet(ForceLog(t, W, "sensor"), tmp_path / "f.parquet")
    back = read_force_parquet(tmp_path / "f.parquet")
    ref = ForceLog(back.time, back.wrench, "sensor", back.path, None, profile="parquet")
    for k in ("time", "wrench"):
        np.testing.assert_array_equal(getattr(back, k), getattr(ref, k))
    for k in ("frame", "path", "position", "moments_known", "profile", "notes"):
        assert getattr(back, k) == getattr(ref, k), k
    with pytest.raises(InputError, match="wrench must have shape"):
        ForceLog.checked(t, W[:, :3], "sensor")
    with pytest.raises(InputError, match="frame must be a non-empty name"):
        ForceLog.checked(t, W, "")
