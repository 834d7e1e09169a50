"""The virtual cell forms a commanded path: dn = n·(C_cmd − C_nom) + n·δ(commanded) + s."""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.virtual.cell import cell_toolpath, paper_cone_cell, paper_vwacf_cell, simulate


@pytest.fixture(scope="module", params=[paper_cone_cell, paper_vwacf_cell], ids=["cone", "vwacf"])
def cell(request):
    return request.param(step_down=2e-3, spacing=3e-3)


def test_nominal_command_is_the_default(cell):
    a = simulate(cell)
    b = simulate(cell, commanded=cell_toolpath(cell))
    np.testing.assert_array_equal(a.dn_robot, b.dn_robot)
    np.testing.assert_array_equal(a.q, b.q)
    assert np.all(a.command_offset == 0)


def test_normal_offset_of_the_command_moves_the_formed_wall(cell):
    base = simulate(cell)
    tp = base.toolpath
    a = 0.4e-3
    cmd = tp.with_tip(tp.tip + a * tp.normal)
    moved = simulate(cell, commanded=cmd)
    n = tp.normal
    # same forces and springback (the model's assumption); the robot re-solved at the command
    np.testing.assert_array_equal(moved.wrench_robot, base.wrench_robot)
    np.testing.assert_array_equal(moved.springback, base.springback)
    assert np.max(np.abs(moved.q - base.q)) > 1e-7
    d_robot = np.einsum("ij,ij->i", moved.robot - base.robot, n)
    np.testing.assert_allclose(moved.dn_robot - base.dn_robot, a + d_robot, atol=1e-12)
    assert np.max(np.abs(d_robot)) < 5e-6  # 0.4 mm of command barely changes the compliance
    # a tangential offset does not move the wall
    t = np.cross(n, [0.0, 0.0, 1.0])
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    side = simulate(cell, commanded=tp.with_tip(tp.tip + 0.4e-3 * t))
    assert np.max(np.abs(side.dn_robot - base.dn_robot)) < 5e-6
    np.testing.assert_array_equal(moved.dn_cnc, base.dn_cnc)  # the CNC keeps the nominal


def test_commanded_path_of_another_toolpath_is_refused(cell):
    tp = cell_toolpath(cell)
    other = cell_toolpath(paper_cone_cell(step_down=3e-3, spacing=3e-3))
    with pytest.raises(InputError, match="same contact points"):
        simulate(cell, commanded=other if len(other) != len(tp) else other.with_tip(tp.tip))
