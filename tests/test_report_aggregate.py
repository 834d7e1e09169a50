"""The reductions the figures draw, against hand-computed answers."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from roboisf.report import aggregate as agg


def _frame(n_laps: int = 3, per_lap: int = 8) -> pd.DataFrame:
    lap = np.repeat(np.arange(n_laps), per_lap)
    k = np.tile(np.arange(per_lap), n_laps)
    return pd.DataFrame(
        {
            "lap": lap,
            "depth": 2.0 * lap + 0.1 * k,
            "time": np.arange(n_laps * per_lap, dtype=float),
            "angle_deg": 360.0 * k / per_lap,
            "contact_z": -(2.0 * lap + 0.1 * k),
            "value": 10.0 * lap + k,
            "cnc_dn": 1.0 + lap * 0.0,
            "robot_dn": np.ones(n_laps * per_lap),
            "robot_compliance_dn": np.ones(n_laps * per_lap),
            "cnc_valid": np.ones(n_laps * per_lap, bool),
            "robot_valid": np.ones(n_laps * per_lap, bool),
        }
    )


def test_lap_profile_mean_and_band():
    f = _frame()
    prof = agg.lap_profile(f, ["value"])
    assert list(prof.index) == [0, 1, 2]
    k = np.arange(8)
    for lap in range(3):
        v = 10.0 * lap + k
        assert prof.loc[lap, "value"] == pytest.approx(v.mean())
        assert prof.loc[lap, "value_lo"] == pytest.approx(np.percentile(v, 5))
        assert prof.loc[lap, "value_hi"] == pytest.approx(np.percentile(v, 95))
        assert prof.loc[lap, "depth"] == pytest.approx(2.0 * lap + 0.35)


def test_masked_follows_the_scan_it_comes_from():
    f = _frame()
    f.loc[3, "cnc_valid"] = False
    f.loc[5, "robot_valid"] = False
    assert np.isnan(agg.masked(f, "cnc_dn")[3]) and np.isfinite(agg.masked(f, "cnc_dn")[5])
    assert np.isnan(agg.masked(f, "robot_dn")[5]) and np.isfinite(agg.masked(f, "robot_dn")[3])
    rc = agg.masked(f, "robot_compliance_dn")
    assert np.isnan(rc[[3, 5]]).all() and np.isfinite(np.delete(rc, [3, 5])).all()
    assert np.isfinite(agg.masked(f, "value")).all()  # not from a scan
    assert np.isfinite(f["cnc_dn"]).all()  # the input is not modified


def test_unrolled_map_bins_and_holes():
    f = _frame(n_laps=2, per_lap=8)
    f.loc[f.index[:2], "cnc_valid"] = False  # lap 0, angles 0° and 45°
    f["cnc_dn"] = f["value"]
    angle, depth, grid = agg.unrolled_map(f, "cnc_dn", n_angle_bins=4)
    assert np.allclose(angle, [45, 135, 225, 315])
    assert depth == pytest.approx([0.35, 2.35])
    # bin 0 of lap 0 held k = 0, 1 (both holes); bin 1 held k = 2, 3 → 2.5
    assert np.isnan(grid[0, 0]) and grid[0, 1] == pytest.approx(2.5)
    assert grid[1] == pytest.approx([10.5, 12.5, 14.5, 16.5])


def test_contour_lap_nearest_and_skips_holes():
    f = _frame(n_laps=4)
    assert agg.contour_lap(f, -2.3)[:2] == (1, pytest.approx(-2.35))
    f.loc[f["lap"] == 1, "robot_valid"] = False
    lap, _, note = agg.contour_lap(f, -2.3)
    assert lap in (0, 2) and "lap 1" in note
    f["robot_valid"] = False
    lap, _, note = agg.contour_lap(f, -2.3)
    assert lap == 1 and "no lap" in note


def test_decimate():
    assert list(agg.decimate(5, 10)) == [0, 1, 2, 3, 4]
    idx = agg.decimate(10_001, 100)
    assert len(idx) == 100 and idx[0] == 0 and idx[-1] == 10_000
    assert np.all(np.diff(idx) > 0)


def test_contour_resultants_sorted_and_closed():
    f = _frame(n_laps=2, per_lap=4)
    f["angle_deg"] = np.tile([270.0, -90.0 + 450.0, 180.0, 0.0], 2)  # 450-90 wraps to 0
    for prefix, v in (("robot_compliance", (3.0, 4.0, 0.0)), ("vjm", (0.0, 0.0, 2.0))):
        for a, x in zip(("dx", "dy", "dz"), v, strict=True):
            f[f"{prefix}_{a}"] = x
    for a in ("dx", "dy", "dz"):
        f[f"delta_{a}"] = f[f"robot_compliance_{a}"] - f[f"vjm_{a}"]
    f.loc[2, "robot_valid"] = False  # lap 0, angle 180°
    c = agg.contour(f, contour_z=-0.1)
    assert c.lap == 0
    assert c.angle_deg == pytest.approx([0, 0, 180, 270, 0])
    assert c.vjm == pytest.approx([2.0] * 5)
    assert np.isnan(c.experiment[2]) and np.isnan(c.delta[2])
    assert np.delete(c.experiment, 2) == pytest.approx([5.0] * 4)
    assert np.delete(c.delta, 2) == pytest.approx([np.sqrt(29.0)] * 4)
