"""Thickness profiles: round trip, units, bad rows named by line."""

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.logs.thickness import read_thickness_csv, write_thickness_csv


def test_round_trip_and_interpolation(tmp_path):
    d = np.linspace(1e-3, 50e-3, 50)
    t = 0.4e-3 + 1e-3 * d
    write_thickness_csv(tmp_path / "t.csv", d, t)
    prof = read_thickness_csv(tmp_path / "t.csv")
    np.testing.assert_allclose(prof.thickness, t, atol=1e-8)
    assert prof.at(np.array([25.5e-3]))[0] == pytest.approx(0.4e-3 + 25.5e-6, abs=1e-8)
    assert np.isnan(prof.at(np.array([0.0, 60e-3]))).all()  # no extrapolation


def test_units_and_errors(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("# units: length=m\ndepth,thickness\n0.002,0.0004\n0.001,0.0005\n")
    prof = read_thickness_csv(p)
    np.testing.assert_allclose(prof.depth, [1e-3, 2e-3])  # sorted
    p.write_text("depth,thickness\n1,0.4\n2,-0.1\n")
    with pytest.raises(InputError) as e:
        read_thickness_csv(p)
    assert e.value.line == 3
    p.write_text("depth,thick\n1,0.4\n")
    with pytest.raises(InputError, match="missing column"):
        read_thickness_csv(p)
