"""The local geometry of a toolpath (roboisf.toolpath.geometry) and the virtual cell's springback
rule that depends on it (SpringbackModel.curvature_gain, truth key springback.curvature_gain)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.toolpath.geometry import contour_curvature, meridian_curvature, rim_distance
from roboisf.virtual.cell import cell_toolpath, paper_cone_cell, paper_vwacf_cell, pyramid_cell
from roboisf.virtual.springback import SpringbackModel
from roboisf.virtual.truth import TruthSpec, load_truth


def _circle_laps(radii, n=90, dz=1e-3):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    contact, normal, lap = [], [], []
    for k, r in enumerate(radii):
        contact.append(np.c_[r * np.cos(t), r * np.sin(t), np.full(n, -k * dz)])
        normal.append(np.c_[-np.cos(t), -np.sin(t), np.zeros(n)])  # tool side: inwards
        lap.append(np.full(n, k))
    return np.vstack(contact), np.vstack(normal), np.concatenate(lap)


def test_contour_curvature_of_circles_is_one_over_radius_and_signed_by_the_tool_side():
    c, n, lap = _circle_laps([0.04, 0.02])
    k = contour_curvature(c, n, lap)
    np.testing.assert_allclose(k[lap == 0], 25.0, rtol=1e-3)
    np.testing.assert_allclose(k[lap == 1], 50.0, rtol=1e-3)
    # the tool outside the contour (a boss, not a pit): the contour bends away from the tool
    assert np.all(contour_curvature(c, -n, lap) < 0)


def test_contour_curvature_on_the_cone_and_pyramid_toolpaths():
    tp = cell_toolpath(paper_cone_cell(step_down=2e-3, spacing=4e-3))
    k = contour_curvature(tp.contact, tp.normal, tp.lap)
    r = np.hypot(tp.contact[:, 0], tp.contact[:, 1])
    np.testing.assert_allclose(k, 1 / r, rtol=0.02)
    tp = cell_toolpath(pyramid_cell(step_down=2e-3, spacing=4e-3))
    k = contour_curvature(tp.contact, tp.normal, tp.lap)
    # flat walls (|x| or |y| well inside the corners' reach) are straight; the plunge from one
    # level to the next and the seam's repeated point add no spike
    flat = (np.abs(tp.contact[:, 1]) < 0.01) | (np.abs(tp.contact[:, 0]) < 0.01)
    assert np.max(np.abs(k[flat])) < 1e-6
    assert k.min() > -1e-6
    assert np.max(k) > 1 / 0.011  # the corners (10 mm at the top, tighter below)


def test_meridian_curvature_and_rim_distance():
    tp = cell_toolpath(paper_vwacf_cell(step_down=2e-3, spacing=4e-3))
    m = meridian_curvature(tp.contact, tp.wall_angle, tp.lap)
    wall = (tp.depth > 5e-3) & (tp.depth < 25e-3)
    # the VWACF's generatrix is a 39 mm arc: dα/ds = 1/39 mm
    np.testing.assert_allclose(np.median(m[wall]), 1 / 39e-3, rtol=0.05)
    tp = cell_toolpath(paper_cone_cell(step_down=2e-3, spacing=4e-3))
    m = meridian_curvature(tp.contact, tp.wall_angle, tp.lap)
    assert np.max(np.abs(m[tp.depth > 10e-3])) < 1e-6
    d = rim_distance(tp.contact, tp.lap)
    assert np.all(d[tp.lap == 0] == 0)
    # down a 71° wall the distance to the first lap grows as depth / sin α
    deep = tp.depth > 20e-3
    first_depth = tp.depth[tp.lap == 0].max()
    np.testing.assert_allclose(
        d[deep], (tp.depth[deep] - first_depth) / math.sin(math.radians(71)), rtol=0.03
    )


def test_the_geometry_rule_scales_springback_by_the_contour_curvature():
    sb = SpringbackModel(curvature_gain=0.4, curvature_length=15e-3)
    base = SpringbackModel()
    depth, alpha = np.full(3, 0.05), np.full(3, math.radians(60))
    k = np.array([0.0, 1 / 0.043, -10.0])
    ratio = sb.normal(depth, alpha, k) / base.normal(depth, alpha)
    np.testing.assert_allclose(ratio, [1.0, 1 - 0.4 * math.tanh(15 / 43), 1.0])
    with pytest.raises(InputError, match="curvature"):
        sb.normal(depth, alpha)
    with pytest.raises(InputError, match="curvature_gain"):
        SpringbackModel(curvature_gain=1.0)


def test_truth_file_switches_the_rule_on_in_the_simulated_cell(tmp_path):
    from roboisf.virtual.cell import simulate

    f = tmp_path / "t.toml"
    f.write_text("[springback]\ncurvature_gain = 0.4\ncurvature_length = 15.0\n")
    truth = load_truth(f)
    assert truth.springback_curvature_gain == 0.4
    assert truth.springback_curvature_length == pytest.approx(15e-3)
    assert truth.to_table()["springback"]["curvature_length"] == pytest.approx(15.0)
    # springback is measured, not modelled, in a study: like its amplitude, the rule leaves
    # the model in study.toml the truth
    assert truth.is_model
    kw = {"step_down": 4e-3, "spacing": 6e-3}
    s0 = simulate(pyramid_cell(**kw)).springback
    s1 = simulate(pyramid_cell(truth=truth, **kw)).springback
    tp = cell_toolpath(pyramid_cell(**kw))
    k = contour_curvature(tp.contact, tp.normal, tp.lap)
    np.testing.assert_allclose(s1, s0 * (1 - 0.4 * np.tanh(np.clip(k, 0, None) * 15e-3)))
    assert np.any(s1 < 0.9 * s0)
    with pytest.raises(InputError, match="curvature_gain"):
        TruthSpec(springback_curvature_gain=-0.1)
