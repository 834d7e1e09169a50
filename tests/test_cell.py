"""The one Cell: the study route and the virtual-cell factory give the same cell and results.

The reference for "same" is the factory's own Cell; the study route goes through every file the
virtual cell writes (study.toml poses in mm/deg, compliance JSON) and ``load_study``.
"""

import math
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from roboisf.cell import (
    PAPER_CELL_PLACEMENT,
    Cell,
    CellHolder,
    CellTool,
    ForceModel,
    build_robot,
    cell_from_study,
    make_cell,
    nominal_toolpath,
    tip_compliances,
)
from roboisf.cli.main import main
from roboisf.compensate.cell import cell_deflection_model
from roboisf.errors import InputError
from roboisf.fem import BallEndTool, beam_result
from roboisf.parts import Cone, load_part, tessellate
from roboisf.plan import evaluate_placement, problem_from_cell
from roboisf.study import load_study
from roboisf.virtual.cell import build_study, paper_cone_cell, paper_vwacf_cell

SMALL = {
    "scan_points": 20_000,
    "force_rate": 50.0,
    "joint_rate": 20.0,
    "step_down": 3e-3,
    "spacing": 4e-3,
}


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    """A VWACF cell with a non-default tool rotation and joint stiffness, and its study's cell."""
    K = [4.0e9, 3.5e9, 2.5e9, 6.0e8, 5.5e8, 3.0e8]
    vc = paper_vwacf_cell(**SMALL, tool_rotation=math.radians(20), joint_stiffness=K)
    study = build_study(vc, tmp_path_factory.mktemp("cell") / "study")
    return vc, cell_from_study(load_study(study))


def test_study_cell_equals_factory_cell(both):
    vc, sc = both
    fc = vc.cell
    assert sc.part.to_dict() == fc.part.to_dict()
    assert sc.tool.ball_diameter == pytest.approx(fc.tool.ball_diameter, rel=1e-15)
    np.testing.assert_allclose(sc.T_base_work, fc.T_base_work, rtol=0, atol=1e-12)
    np.testing.assert_allclose(sc.T_flange_tip, fc.T_flange_tip, rtol=0, atol=1e-12)
    assert sc.tool_rotation == pytest.approx(fc.tool_rotation, rel=1e-12)
    assert sc.robot_name == fc.robot_name == "irb7600-500-2.55"
    np.testing.assert_array_equal(sc.robot.stiffness, fc.robot.stiffness)
    np.testing.assert_array_equal(sc.robot.q_min, fc.robot.q_min)
    np.testing.assert_array_equal(sc.robot.q_max, fc.robot.q_max)
    # the preset's stiffness was replaced: the study.toml carried it
    assert not np.array_equal(sc.robot.stiffness, build_robot("irb7600-500-2.55").stiffness)
    _, _, kt_s, kth_s = tip_compliances(sc)
    _, _, kt_f, kth_f = tip_compliances(fc)
    for a, b in ((kt_s, kt_f), (kth_s, kth_f)):
        assert np.max(np.abs(a - b)) <= 1e-15 * np.max(np.abs(b))
    assert sc.force is None and fc.force is not None  # a study's forces are measured


def test_consumers_agree_on_both_cells(both):
    vc, sc = both
    tp = vc.cell.toolpath(**vc.path_settings)
    W = np.tile([30.0, -20.0, 400.0, 1.0, -2.0, 0.5], (len(tp), 1))
    d_s = cell_deflection_model(sc).deflection(tp.tip, W)[0]
    d_f = cell_deflection_model(vc.cell).deflection(tp.tip, W)[0]
    np.testing.assert_allclose(d_s, d_f, rtol=0, atol=1e-12)  # m: far below 1 µm
    assert np.min(np.linalg.norm(d_f, axis=1)) > 1e-5  # ≈ 80 µm: far above the atol
    # plan: the study's cell has no force model; give it the factory's to compare the robots
    from dataclasses import replace

    p_s, _ = problem_from_cell(replace(sc, force=vc.force), **vc.path_settings)
    p_f, _ = problem_from_cell(vc.cell, **vc.path_settings)
    s_s = evaluate_placement(p_s, PAPER_CELL_PLACEMENT, [0.0])
    s_f = evaluate_placement(p_f, PAPER_CELL_PLACEMENT, [0.0])
    assert s_s.ok and s_f.ok
    assert s_s.mean_abs == pytest.approx(s_f.mean_abs, rel=1e-9)


def test_holder_compliance_at_the_tip_is_rigid_body_kinematics():
    """k_th = J k_h Jᵀ against the lever arm written out: the wrench moved to the holder's nose,
    its displacement carried rigidly down to the tip."""
    cell = paper_cone_cell().cell
    _, k_h, _, k_th = tip_compliances(cell)
    assert k_h is not None
    L = cell.holder.offset
    r = np.array([0.0, 0.0, -L]) - k_h.reference_point  # nose → tip
    rng = np.random.default_rng(1)
    for _ in range(5):
        f, m = rng.normal(size=3) * 100, rng.normal(size=3)
        W_nose = np.r_[f, m + np.cross(r, f)]
        u = k_h.compliance @ W_nose
        d_tip = np.r_[u[:3] + np.cross(u[3:], r), u[3:]]
        np.testing.assert_allclose(k_th @ np.r_[f, m], d_tip, rtol=1e-12, atol=1e-20)
    # a lateral force bends the 66 mm lever: far more at the tip than at the nose
    assert k_th[0, 0] > 1.5 * k_h.compliance[0, 0]


def test_rigid_holder_and_given_compliance():
    tool = BallEndTool(10e-3, 0.066)
    k = beam_result(tool)
    cell = Cell(
        Cone(),
        CellTool(10e-3, compliance=k),
        CellHolder(),
        build_robot("irb7600-500-2.55"),
        PAPER_CELL_PLACEMENT,
    )
    k_tool, k_holder, k_t, k_th = tip_compliances(cell)
    assert k_tool is k and k_holder is None
    np.testing.assert_array_equal(k_t, k.compliance)
    np.testing.assert_array_equal(k_th, np.zeros((6, 6)))


@pytest.mark.parametrize(
    ("build", "field"),
    [
        (lambda r: Cell(Cone(), CellTool(10e-3), CellHolder(), r, np.eye(4)), "tool"),
        (lambda r: Cell(Cone(), CellTool(-1.0, geometry=None), CellHolder(), r, np.eye(4)), "ball"),
        (
            lambda r: Cell(
                Cone(),
                CellTool(10e-3, compliance=beam_result(BallEndTool(10e-3, 0.066))),
                CellHolder(),
                r,
                np.diag([1.0, 1.0, 2.0, 1.0]),
            ),
            "T_base_work",
        ),
        (
            lambda r: Cell(
                "cone",
                CellTool(10e-3, geometry=BallEndTool(10e-3, 0.066)),
                CellHolder(),
                r,
                np.eye(4),
            ),
            "part",
        ),
        (
            lambda r: CellTool(12e-3, geometry=BallEndTool(10e-3, 0.066)),
            "geometry",
        ),
        (lambda r: CellHolder(offset=-1e-3), "offset"),
        (lambda r: make_cell(Cone(), compliance_method="xfem"), "compliance_method"),
    ],
)
def test_cell_is_validated_at_construction(build, field):
    with pytest.raises(InputError) as ei:
        build(build_robot("irb7600-500-2.55"))
    assert field in str(ei.value)


def test_cell_arrays_are_read_only():
    cell = make_cell(Cone(), T_base_work=PAPER_CELL_PLACEMENT, force=ForceModel())
    with pytest.raises(ValueError):
        cell.T_base_work[0, 3] = 1.0


def test_plan_does_not_import_the_synthetic_data_package():
    code = (
        "import sys, roboisf.plan, roboisf.decompose.pipeline, roboisf.compensate.study;"
        "bad = [m for m in sys.modules if m.startswith('roboisf.virtual')];"
        "assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.fixture(scope="module")
def mesh_part_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("mesh")
    mesh = tessellate(Cone(), chordal_error=0.2e-3, edge=4e-3)
    trimesh.Trimesh(mesh.vertices * 1e3, mesh.faces, process=False).export(d / "cone.stl")
    f = d / "cone_mesh.toml"
    f.write_text('[part]\nkind = "mesh"\nfile = "cone.stl"\n')
    return f


def test_toolpath_dispatch_slices_any_other_part(mesh_part_file):
    """A non-axisymmetric part kind gets the sliced step-down path with the same settings;
    ``max_wall_step`` (a generatrix refinement) is refused for it."""
    from roboisf.toolpath.slice import sliced_step_down

    part = load_part(mesh_part_file)
    tp = nominal_toolpath(part, 5e-3, 5e-3, spacing=5e-3)
    ref = sliced_step_down(part, 5e-3, 5e-3, spacing=5e-3)
    np.testing.assert_array_equal(tp.tip, ref.tip)
    np.testing.assert_array_equal(tp.lap, ref.lap)
    with pytest.raises(InputError, match=r"axisymmetric parts only.*'mesh'"):
        nominal_toolpath(part, 5e-3, 5e-3, spacing=5e-3, max_wall_step=0.5e-3)


def test_virtual_cell_cli_takes_a_part_file(tmp_path, mesh_part_file, capsys):
    cone = tmp_path / "cone.toml"
    assert main(["-q", "part", "cone", "-o", str(cone)]) == 0
    out = tmp_path / "study"
    args = ["--scan-points", "20000", "--force-rate", "50"]
    assert main(["-q", "virtual-cell", "--part", str(cone), "-o", str(out), *args]) == 0
    s = load_study(out)
    got, want = s.part.to_dict(), Cone().to_dict()
    assert s.name == "cone" and got.pop("kind") == want.pop("kind") == "cone"
    assert got == pytest.approx(want, rel=1e-12)
    # the paper-like cell around it: same robot, placement and tool compliance as the paper cone
    c, ref = cell_from_study(s), paper_cone_cell().cell
    np.testing.assert_allclose(c.T_base_work, ref.T_base_work, atol=1e-12)
    np.testing.assert_allclose(tip_compliances(c)[3], tip_compliances(ref)[3], rtol=1e-12)
    # a part file carries its own shape: the built-in pyramid's options are refused, exit 2
    bad = tmp_path / "bad"
    args = ["--part", str(mesh_part_file), "--depth", "30", "-o", str(bad)]
    assert main(["-q", "virtual-cell", *args]) == 2
    assert "--depth" in capsys.readouterr().err
    assert not bad.exists()
    # exactly one of PART and --part
    assert main(["-q", "virtual-cell", "cone", "--part", str(cone), "-o", str(bad)]) == 2
    assert main(["-q", "virtual-cell", "-o", str(bad)]) == 2


def test_virtual_cell_of_a_profile_part_stands_alone(tmp_path):
    """A profile part names its generatrix CSV relative to the part file: the study kept that
    name without the file, and analyze refused it ('profile file not found'). The generatrix
    is written into the study's [part] table."""
    parts = tmp_path / "parts"
    parts.mkdir()
    (parts / "gen.csv").write_text("r,z\n60,0\n40,-20\n25,-50\n")
    part = parts / "prof.toml"
    assert main(["-q", "part", "profile", str(parts / "gen.csv"), "-o", str(part)]) == 0
    out = tmp_path / "study"
    args = ["--scan-points", "5000", "--force-rate", "50", "--step-down", "4", "--spacing", "8"]
    assert main(["-q", "virtual-cell", "--part", str(part), "-o", str(out), *args]) == 0
    assert not (out / "gen.csv").exists()
    s = load_study(out)  # refused before
    np.testing.assert_allclose(s.part.r, [0.06, 0.04, 0.025], rtol=1e-12)
    np.testing.assert_allclose(s.part.z, [0.0, -0.02, -0.05], atol=1e-15)


def test_virtual_cell_cli_coarse_path_and_joint_rate(tmp_path, capsys):
    """--step-down/--spacing [mm] and --joint-rate [Hz] reach the virtual cell: the study's
    toolpath is the paper cone's on that coarse path, its joint log at that rate (the small demo
    cell of docs/study.md's worked example); a step that is not > 0 is refused, exit 2."""
    from roboisf.cam.toolpath_csv import read_toolpath_csv
    from roboisf.decompose.pipeline import read_run_joint_log
    from roboisf.virtual.cell import cell_toolpath

    out = tmp_path / "study"
    args = ["--scan-points", "2000", "--force-rate", "5", "--joint-rate", "4"]
    args += ["--step-down", "5", "--spacing", "8", "-o", str(out)]
    assert main(["-q", "virtual-cell", "cone", *args]) == 0
    st = load_study(out)
    got = read_toolpath_csv(st.robot_run.toolpath)
    want = cell_toolpath(paper_cone_cell(step_down=5e-3, spacing=8e-3))
    assert len(got) == len(want) < len(cell_toolpath(paper_cone_cell(step_down=5e-3)))
    np.testing.assert_allclose(got.tip, want.tip, atol=1e-9)
    t = read_run_joint_log(st.robot_run).time
    assert float(np.median(np.diff(t))) == pytest.approx(0.25, rel=1e-6)
    capsys.readouterr()
    for opt in ("--step-down", "--spacing"):
        bad = tmp_path / f"bad{opt}"
        assert main(["-q", "virtual-cell", "cone", opt, "0", "-o", str(bad)]) == 2
        err = capsys.readouterr().err
        assert opt in err and "> 0 mm" in err and len(err.strip().splitlines()) == 1
        assert not bad.exists()


def test_virtual_cell_of_a_robot_without_published_stiffness_takes_the_users(tmp_path, capsys):
    """A preset without a published joint stiffness (KUKA, FANUC) is refused naming --stiffness,
    exit 2, nothing written; with --stiffness its file's K is the cell's, written into the
    study's [robot] joint_stiffness (analyze then uses it); a file identified on another robot
    is refused."""
    from roboisf.study import load_study

    small = ["--scan-points", "20000", "--step-down", "3", "--spacing", "6", "--force-rate", "50"]
    out = tmp_path / "kuka"
    args = ["-q", "virtual-cell", "cone", "--robot", "kr210-r2700-2", *small, "-o", str(out)]
    assert main(args) == 2
    assert "--stiffness" in capsys.readouterr().err and not out.exists()
    K = [3.0e6, 2.5e6, 2.0e6, 4.0e5, 3.5e5, 2.0e5]
    f = tmp_path / "k.toml"
    f.write_text(f"[stiffness]\nK = {K}\n")
    assert main([*args, "--stiffness", str(f)]) == 0
    s = load_study(out)
    assert s.robot is not None and s.robot.model == "kr210-r2700-2"
    np.testing.assert_array_equal(cell_from_study(s).robot.joint_stiffness, K)
    other = tmp_path / "other.toml"
    other.write_text(f'[stiffness]\nrobot = "irb7600-500-2.55"\nK = {K}\n')
    again = tmp_path / "again"
    assert main([*args[:-1], str(again), "--stiffness", str(other)]) == 2
    assert "irb7600-500-2.55" in capsys.readouterr().err and not again.exists()
