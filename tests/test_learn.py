"""The learned springback model (roboisf.learn) on virtual cells' true springback.

Training tables are built straight from :func:`roboisf.virtual.cell.simulate` (the true
springback per toolpath point under the geometry rule of docs/virtual-cell.md, no scans), in the
layout of :func:`roboisf.history.store.points_table`, so these tests isolate the learner; the
whole chain (scans, analyze, history, predict, compensate --predicted) is
tests/test_predict_cli.py and benchmarks/history.py.
"""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pandas as pd
import pytest

# found, not imported: importorskip imported sklearn (0.5 s) at collection on every xdist
# worker, also on the one that runs no test of this module
if importlib.util.find_spec("sklearn") is None:
    pytest.skip("the learned springback model needs scikit-learn", allow_module_level=True)

from roboisf.errors import InputError
from roboisf.learn.features import FEATURES, point_features
from roboisf.learn.springback import fit_springback
from roboisf.parts import VWACF, Cone, Pyramid
from roboisf.scan.deviation import default_rim_band
from roboisf.virtual.cell import pyramid_cell, simulate, virtual_cell
from roboisf.virtual.truth import TruthSpec

RULE = TruthSpec(springback_curvature_gain=0.4, springback_curvature_length=15e-3)
PATH = {"step_down": 2e-3, "spacing": 4e-3}


def _table(part_id, kind, cell, noise=0.0, seed=0):
    truth = simulate(cell)
    tp = truth.toolpath
    rng = np.random.default_rng(seed)
    return pd.DataFrame(
        {
            "part_id": part_id,
            "idx": np.arange(len(tp)),
            "lap": tp.lap,
            "depth": tp.depth,
            "wall_angle": tp.wall_angle,
            "x": tp.contact[:, 0],
            "y": tp.contact[:, 1],
            "z": tp.contact[:, 2],
            "nx": tp.normal[:, 0],
            "ny": tp.normal[:, 1],
            "nz": tp.normal[:, 2],
            "used": (tp.depth > default_rim_band(cell.part.depth)).astype(int),
            "springback_dn": truth.springback + noise * rng.standard_normal(len(tp)),
            "part_kind": kind,
            "robot": "irb7600-500-2.55",
            "tool_radius": tp.tool_radius,
            "sheet_thickness": cell.part.sheet_thickness,
            "material": "AA1050",
            "step_down": PATH["step_down"],
        }
    )


def _cell(part):
    from roboisf.virtual.cell import PAPER_CELL_PLACEMENT

    return virtual_cell("p", part, T_base_work=PAPER_CELL_PLACEMENT, truth=RULE, **PATH)


@pytest.fixture(scope="module")
def history():
    rad = math.radians
    parts = [
        ("cone", Cone(90e-3, rad(60), 40e-3)),
        ("cone", Cone(110e-3, rad(35), 25e-3)),
        ("cone", Cone(70e-3, rad(71), 45e-3)),
        ("vwacf", VWACF(100e-3, 50e-3, final_wall_angle=rad(70))),
        ("pyramid", Pyramid(100e-3, 100e-3, rad(60), 35e-3, corner_radius=10e-3)),
        ("pyramid", Pyramid(100e-3, 80e-3, rad(40), 25e-3, corner_radius=20e-3)),
    ]
    return pd.concat(
        [_table(i + 1, k, _cell(p), noise=20e-6, seed=i) for i, (k, p) in enumerate(parts)],
        ignore_index=True,
    )


def test_features_are_the_documented_columns():
    from roboisf.virtual.cell import cell_toolpath

    tp = cell_toolpath(pyramid_cell(**PATH))
    X = point_features(
        tp.contact, tp.normal, tp.wall_angle, tp.lap, step_down=2e-3, tool_radius=5e-3,
        sheet_thickness=1.22e-3,
    )  # fmt: skip
    assert X.shape == (len(tp), len(FEATURES))
    col = dict(zip(FEATURES, X.T, strict=True))
    np.testing.assert_allclose(col["wall_angle"], tp.wall_angle)
    np.testing.assert_allclose(col["depth"], tp.depth)
    assert np.all(col["step_down"] == 2e-3) and np.all(col["sheet_thickness"] == 1.22e-3)
    with pytest.raises(InputError, match="step_down"):
        point_features(
            tp.contact, tp.normal, tp.wall_angle, tp.lap, step_down=0.0, tool_radius=5e-3,
            sheet_thickness=1.22e-3,
        )  # fmt: skip


@pytest.fixture(scope="module")
def learner(history):
    return fit_springback(history, coverage=0.8)


def test_predicts_a_part_it_has_not_seen_within_30_percent(learner):
    # a pyramid of another size and wall angle (rectangular, 50°, a 15 mm corner radius)
    part = Pyramid(90e-3, 70e-3, math.radians(50), 30e-3, corner_radius=15e-3)
    new = _table(99, "pyramid", _cell(part))
    X = point_features(
        new[["x", "y", "z"]].to_numpy(), new[["nx", "ny", "nz"]].to_numpy(),
        new["wall_angle"].to_numpy(), new["lap"].to_numpy(), step_down=2e-3,
        tool_radius=5e-3, sheet_thickness=1.22e-3,
    )[new["used"].to_numpy() == 1]  # fmt: skip
    s, lo, hi = learner.predict(X, "AA1050")
    true = new.loc[new["used"] == 1, "springback_dn"].to_numpy()
    rms = np.sqrt(np.mean(true**2))
    err = np.sqrt(np.mean((s - true) ** 2))
    assert err < 0.3 * rms, (err, rms)
    # the variation within the part is learned, not only its level (corners vs flat walls)
    assert np.corrcoef(s, true)[0, 1] > 0.7
    assert np.mean((true >= lo) & (true <= hi)) >= 0.7
    # the rule: a tight corner recovers less than the flat wall at the same depth
    k = X[:, FEATURES.index("contour_curvature")]
    deep = X[:, FEATURES.index("depth")] > 22e-3
    assert np.mean(s[deep & (k > 50)]) < 0.85 * np.mean(s[deep & (np.abs(k) < 1)])


def test_validation_leaves_whole_parts_out_and_the_interval_is_calibrated(learner):
    assert learner.n_parts == 6 and len(learner.validation) == 6
    assert {v["part_id"] for v in learner.validation} == set(range(1, 7))
    # split-conformal: the half-width is the ⌈(n + 1)·0.8⌉-th smallest out-of-part residual,
    # so over all of them the coverage is the nominal one
    r = np.sort(np.abs(learner.residuals))
    assert learner.half_width == r[math.ceil((len(r) + 1) * 0.8) - 1]
    n = np.array([v["n_points"] for v in learner.validation])
    cov = np.array([v["coverage"] for v in learner.validation])
    assert np.sum(n * cov) / n.sum() == pytest.approx(0.8, abs=0.01)
    # each part's error is its own prediction by the others: no part's error is ~0 (a fit)
    assert min(v["relative_error"] for v in learner.validation) > 0.02
    s = learner.summary()
    assert s["n_parts"] == 6
    assert s["interval_half_width_mm"] == pytest.approx(learner.half_width * 1e3)


def test_refusals(history, learner):
    with pytest.raises(InputError, match="at least 2"):
        fit_springback(history[history["part_id"] == 1])
    with pytest.raises(InputError, match="coverage"):
        fit_springback(history, coverage=1.0)
    X = np.zeros((3, len(FEATURES)))
    with pytest.raises(InputError, match="material 'steel'"):
        learner.predict(X, "steel")
    with pytest.raises(InputError, match="features"):
        learner.predict(np.zeros((3, 2)), "AA1050")
    assert {"depth", "tool_radius", "sheet_thickness"} <= set(learner.outside(X))


def test_floating_point_noise_is_not_outside_the_history(learner):
    """A feature the history holds at one value (a cone's meridian curvature: 0) is not left
    by ±1e-12 noise on the same cone (it was: 72 % of points 'outside'); a real value is."""
    from dataclasses import replace

    j = FEATURES.index("meridian_curvature")
    rng = learner.feature_range.copy()
    rng[j] = 0.0
    one = replace(learner, feature_range=rng)
    X = np.tile(rng.mean(axis=1), (100, 1))  # every feature inside
    X[:, j] = np.linspace(-3e-12, 3e-12, 100)  # rad/m: noise around the history's 0
    assert one.outside(X) == {}
    X[:50, j] = 0.5  # a real change of wall angle down the wall (rad/m)
    assert one.outside(X) == {"meridian_curvature": 0.5}


def test_a_missing_scikit_learn_is_one_line(monkeypatch):
    import builtins

    from roboisf.learn import springback

    real = builtins.__import__

    def no_sklearn(name, *a, **k):
        if name.startswith("sklearn"):
            raise ImportError(name)
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_sklearn)
    with pytest.raises(InputError, match=r"pip install 'roboisf\[history\]'"):
        springback.require_sklearn()
