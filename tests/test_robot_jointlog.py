"""Joint-log CSV: round trip in controller degrees, line-numbered errors."""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.logs.jointlog import read_joint_log, write_joint_log


def test_round_trip(tmp_path):
    t = np.linspace(0, 2, 11)
    q = np.radians(np.random.default_rng(0).uniform(-170, 170, (11, 6)))
    f = tmp_path / "j.csv"
    write_joint_log(f, t, q)
    assert f.read_text().startswith("# units: time=s angle=deg\ntime,q1,")
    back = read_joint_log(f)
    np.testing.assert_allclose(back.time, t, atol=1e-9)
    np.testing.assert_allclose(back.q, q, atol=1e-10)


def test_radians_and_ms(tmp_path):
    f = tmp_path / "j.csv"
    f.write_text(
        "# units: time=ms angle=rad\ntime,q1,q2,q3,q4,q5,q6\n0,0,0.1,0,0,0,0\n500,0,0.2,0,0,0,0\n"
    )
    log = read_joint_log(f)
    np.testing.assert_allclose(log.time, [0, 0.5])
    np.testing.assert_allclose(log.q[:, 1], [0.1, 0.2])


@pytest.mark.parametrize(
    ("text", "where"),
    [
        ("time,q1,q2,q3,q4,q5,q6\n0,0,0,0,0,0,0\n", "units"),  # units line required
        ("# units: time=s angle=grad\ntime,q1,q2,q3,q4,q5,q6\n0,0,0,0,0,0,0\n", "angle"),
        ("# units: time=s angle=deg\ntime,q1,q2,q3,q4,q5,q6\n0,0,0,0,0,0,0\n0,1,0,0,0,0,0\n", ":4"),
        ("# units: time=s angle=deg\ntime,q1,q2,q3,q4,q5\n0,0,0,0,0,0\n", "q6"),
        ("# units: time=s angle=deg\ntime,q1,q2,q3,q4,q5,q6\n0,0,x,0,0,0,0\n", ":3"),
    ],
)
def test_bad_files(tmp_path, text, where):
    f = tmp_path / "j.csv"
    f.write_text(text)
    with pytest.raises(InputError) as e:
        read_joint_log(f)
    assert where in str(e.value) and "j.csv" in str(e.value)


def test_writer_checks_shape(tmp_path):
    with pytest.raises(InputError):
        write_joint_log(tmp_path / "j.csv", np.zeros(3), np.zeros((3, 5)))
    assert not (tmp_path / "j.csv").exists()
