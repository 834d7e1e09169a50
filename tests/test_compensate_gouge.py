"""Gouge rule: distance of the loaded ball centre ≥ R − intended over-bend − tol."""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.cam.program import RobotTool
from roboisf.compensate import (
    CompensationOptions,
    compensate,
    gouge_check,
    write_compensation,
)
from roboisf.compensate.virtual import cell_deflection_model
from roboisf.errors import InputError
from roboisf.virtual.cell import paper_cone_cell, simulate


@pytest.fixture(scope="module")
def cone():
    cell = paper_cone_cell(step_down=2e-3, spacing=3e-3)
    return cell, simulate(cell)


def test_nominal_ball_sits_at_the_tool_radius(cone):
    cell, truth = cone
    tp = truth.toolpath
    g = gouge_check(cell.part, tp.tip, tp.tool_radius)
    np.testing.assert_allclose(g.distance, tp.tool_radius, atol=1e-9)
    assert g.ok


def test_unintended_push_into_the_part_is_flagged_at_its_indices(cone):
    cell, truth = cone
    tp = truth.toolpath
    tip = tp.tip.copy()
    bad = np.array([100, 101, 2000])
    tip[bad] -= 0.3e-3 * tp.normal[bad]  # 0.3 mm into the material, not declared
    g = gouge_check(cell.part, tip, tp.tool_radius)
    np.testing.assert_array_equal(g.indices, bad)
    with pytest.raises(InputError, match=r"gouges the part at 3 points \(indices 100, 101, 2000"):
        g.raise_if_gouging()
    # declared as an intended over-bend of 0.3 mm: allowed
    c = np.zeros(len(tp))
    c[bad] = -0.3e-3
    assert gouge_check(cell.part, tip, tp.tool_radius, normal_offset=c).ok
    # … but not beyond the over-bend limit
    g = gouge_check(cell.part, tip, tp.tool_radius, normal_offset=c, max_overbend=0.2e-3)
    np.testing.assert_array_equal(g.indices, bad)


def test_loaded_position_is_checked_not_the_unloaded_command(cone):
    """A pre-deflected command sits inside the surface unloaded; under load it lands on it."""
    cell, truth = cone
    m = cell_deflection_model(cell.cell)
    comp = compensate(
        cell.part,
        truth.toolpath,
        model=m,
        wrench=truth.wrench_robot,
        options=CompensationOptions(springback=False),
    )
    tp = comp.toolpath
    unloaded = gouge_check(cell.part, tp.tip, tp.tool_radius)
    assert not unloaded.ok  # the command alone is up to ~0.5 mm inside
    assert comp.gouge.ok
    assert np.max(np.abs(comp.gouge.distance - tp.tool_radius)) < 1e-6


def test_a_gouging_command_is_never_written(cone, tmp_path):
    cell, truth = cone
    m = cell_deflection_model(cell.cell)
    D = truth.dn_robot.copy()
    opts = CompensationOptions(gain=1.0, max_overbend=0.5e-3)  # springback needs ≈ 1.3 mm
    comp = compensate(
        cell.part, truth.toolpath, model=m, wrench=truth.wrench_robot, deviation=D, options=opts
    )
    assert not comp.gouge.ok
    out = tmp_path / "out"
    with pytest.raises(InputError, match="gouge"):
        write_compensation(comp, out, T_base_work=m.T_base_work, tool=RobotTool(0.3))
    assert not out.exists()
