"""Compliance pre-deflection: known answers, acceptance on the virtual cell, bad input."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from roboisf.compensate import CompensationOptions, DeflectionModel, compensate, precompensate
from roboisf.compensate.virtual import cell_deflection_model
from roboisf.errors import ConvergenceError, UnreachableError
from roboisf.robot import ik_toolpath
from roboisf.virtual.cell import paper_cone_cell, paper_vwacf_cell, simulate

COARSE = {"step_down": 2e-3, "spacing": 3e-3}


@pytest.fixture(scope="module")
def cone():
    cell = paper_cone_cell(**COARSE)
    return cell, simulate(cell)


def _dn(v, n):
    return np.einsum("ij,ij->i", v, n)


def test_constant_compliance_known_answer(cone):
    """Tool/holder only (configuration-independent): the exact answer is p = target − δ_c, the
    ball centre's deflection ``[k W]_δ + [k W]_θ × R ẑ``."""
    cell, truth = cone
    m = replace(cell_deflection_model(cell.cell), include_robot=False)
    W = truth.wrench_robot
    res = precompensate(truth.toolpath, W, m, relax=0.5, tol=1e-10)
    kW = W @ m.k_tip.T
    assert m.ball_radius == cell.cell.tool.radius
    expected = truth.toolpath.tip - (kW[:, :3] + np.cross(kW[:, 3:], [0, 0, m.ball_radius]))
    assert np.max(np.abs(res.commanded - expected)) < 2e-10
    # under-relaxed linear fixed point: the residual shrinks by exactly (1 − ω) per update
    h = res.history
    np.testing.assert_allclose(h[1:] / h[:-1], 0.5, rtol=1e-6)


def test_joint_configurations_resolved_for_the_command(cone):
    cell, truth = cone
    m = cell_deflection_model(cell.cell)
    res = precompensate(truth.toolpath, truth.wrench_robot, m)
    q = ik_toolpath(m.robot, res.commanded, m.T_base_work).q
    np.testing.assert_allclose(res.q, q, atol=1e-12)
    # the loaded ball centre lands on its target: p + δ_c(p) = target
    d6 = m.robot.deflection(q, truth.wrench_robot, T_base_work=m.T_base_work)
    d6 += truth.wrench_robot @ m.k_tip.T
    d = d6[:, :3] + np.cross(d6[:, 3:], [0, 0, cell.cell.tool.radius])
    assert np.max(np.linalg.norm(res.commanded + d - truth.toolpath.tip, axis=1)) <= 1e-7
    assert res.converged.all() and res.iterations < 15


@pytest.mark.parametrize("make", [paper_cone_cell, paper_vwacf_cell], ids=["cone", "vwacf"])
def test_acceptance_robot_compliance_cut_by_90_percent(make):
    """Issue 7: the robot-compliance error of the formed part drops by ≥ 90 % (from truth)."""
    cell = make(**COARSE)
    before = simulate(cell)
    n = before.toolpath.normal
    # robot term only: compensate the robot, leave tool and holder to show they stay
    m = replace(cell_deflection_model(cell.cell), k_tip=np.zeros((6, 6)))
    res = precompensate(before.toolpath, before.wrench_robot, m)
    after = simulate(cell, commanded=before.toolpath.with_tip(res.commanded))
    others = _dn(after.tool_robot + after.holder_robot, n) + after.springback
    robot_after = after.dn_robot - others  # command offset + robot deflection at the command
    robot_before = _dn(before.robot, n)
    ratio = np.mean(np.abs(robot_after)) / np.mean(np.abs(robot_before))
    assert np.mean(np.abs(robot_before)) > 0.1e-3  # a real robot error to remove
    assert ratio <= 0.10, ratio
    # and the whole deflection (robot + tool + holder) with the full model
    full = precompensate(before.toolpath, before.wrench_robot, cell_deflection_model(cell.cell))
    after2 = simulate(cell, commanded=before.toolpath.with_tip(full.commanded))
    e_before = before.dn_robot - before.springback
    e_after = after2.dn_robot - after2.springback
    assert np.mean(np.abs(e_after)) <= 0.10 * np.mean(np.abs(e_before))


def test_not_converged_raises_naming_indices(cone):
    cell, truth = cone
    m = cell_deflection_model(cell.cell)
    with pytest.raises(ConvergenceError, match=r"did not converge at \d+ of \d+ points.*indices"):
        precompensate(truth.toolpath, truth.wrench_robot, m, max_iter=2, tol=1e-9)
    res = precompensate(truth.toolpath, truth.wrench_robot, m, max_iter=2, tol=1e-9, partial=True)
    assert not res.converged.all()
    assert res.report()["not_converged_indices"] == res.not_converged.tolist()
    np.testing.assert_array_equal(res.converged, res.residual <= 1e-9)


def test_partial_compensation_is_not_written_unless_asked(cone, tmp_path):
    from roboisf.cam.program import RobotTool
    from roboisf.compensate import write_compensation
    from roboisf.errors import InputError

    cell, truth = cone
    m = cell_deflection_model(cell.cell)
    opts = CompensationOptions(springback=False, max_iter=2, tol=1e-9, partial=True)
    comp = compensate(cell.part, truth.toolpath, model=m, wrench=truth.wrench_robot, options=opts)
    assert not comp.complete
    # a partial result only when the options asked for it; flags in per_point.csv, complete=false
    out = tmp_path / "partial"
    write_compensation(comp, out, T_base_work=m.T_base_work, tool=RobotTool(0.3))
    import json

    assert json.loads((out / "compensation.json").read_text())["complete"] is False
    bad = replace(comp, options=replace(opts, partial=False))
    with pytest.raises(InputError, match="partial"):
        write_compensation(bad, tmp_path / "no", T_base_work=m.T_base_work, tool=RobotTool(0.3))
    assert not (tmp_path / "no").exists()


def test_target_outside_workspace_names_indices(cone):
    cell, truth = cone
    m = cell_deflection_model(cell.cell)
    target = truth.toolpath.tip.copy()
    far = np.array([5, 17, 300])
    target[far, 0] += 3.0  # 3 m further from the robot: beyond its reach
    with pytest.raises(UnreachableError) as e:
        precompensate(target, truth.wrench_robot, m)
    assert e.value.indices == far.tolist()


def test_deflection_model_needs_stiffness(cone):
    from roboisf.errors import InputError

    cell, _ = cone
    m = cell_deflection_model(cell.cell)
    soft = replace(m.robot, stiffness=None)
    with pytest.raises(InputError, match="joint stiffness"):
        DeflectionModel(soft, m.T_base_work)


def test_every_registered_format_is_a_compensation_output(cone, tmp_path):
    # the compensation's programs loop over the format registry: a format registered in one
    # place is written too, a robot format with the pre-deflected command, a CNC one without it
    from pathlib import Path

    from roboisf.cam.program import RobotTool
    from roboisf.compensate import write_compensation
    from roboisf.programs.registry import ProgramFormat, WriteOptions, register, unregister

    def write(tp, path: Path, o: WriteOptions) -> list[Path]:
        np.save(path.with_name(path.name + ".npy"), tp.tip)
        path.write_text("toy\n")
        return [path]

    cell, truth = cone
    m = cell_deflection_model(cell.cell)
    opts = CompensationOptions(springback=False, max_iter=2, tol=1e-9, partial=True)
    comp = compensate(cell.part, truth.toolpath, model=m, wrench=truth.wrench_robot, options=opts)
    register(ProgramFormat("toyrobot", (".toyr",), "robot", "toy robot", write))
    register(ProgramFormat("toycnc", (".toyc",), "cnc", "toy CNC", write))
    try:
        out = tmp_path / "c"
        write_compensation(comp, out, T_base_work=m.T_base_work, tool=RobotTool(0.3))
    finally:
        unregister("toyrobot")
        unregister("toycnc")
    robot, cnc = np.load(out / "compensated.toyr.npy"), np.load(out / "compensated.toyc.npy")
    np.testing.assert_array_equal(robot, comp.toolpath.tip)  # pre-deflected for the robot
    np.testing.assert_array_equal(cnc, comp.target)  # the CNC command: no pre-deflection
    assert np.max(np.abs(robot - cnc)) > 1e-5
    for name in ("compensated.csv", "compensated.mod", "compensated.src", "compensated.ls"):
        assert (out / name).is_file(), name
