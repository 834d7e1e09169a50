"""Ball-end tool, tool holder and their serial assembly; the compliance JSON file."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.fem import (
    PAPER_TOOL_LENGTH,
    BallEndTool,
    ComplianceResult,
    HolderSection,
    ToolHolder,
    ToolInHolder,
    beam_result,
    fe_compliance,
    load_compliance_json,
    save_compliance_json,
    solve_six_cases,
    tool_beam,
    tool_holder_compliance,
)

PAPER_TOOL_LATERAL = 9.34e-7  # m/N, Bharti et al. 2024, Table 2


@pytest.fixture(scope="module")
def tool60():
    return fe_compliance(BallEndTool(10e-3, 60e-3), solver="superlu")


@pytest.fixture(scope="module")
def paper_tool_coarse():
    """The paper tool at R/2 with the default solver ("auto"): the convergence test's coarse
    mesh and the solver test's "auto" run are the same solve (≈ 1 s), done once. Read-only."""
    return solve_six_cases(BallEndTool(10e-3, PAPER_TOOL_LENGTH), 2.5e-3)


def test_tool_60mm_lateral_compliance(tool60):
    k = tool60.compliance
    assert 6.5e-7 < k[0, 0] < 7.5e-7 and np.isclose(k[0, 0], k[1, 1], rtol=5e-3)
    # beam model with a rigid ball agrees on bending to a few per cent
    beam = tool_beam(BallEndTool(10e-3, 60e-3))
    assert abs(k[0, 0] / beam[0, 0] - 1) < 0.02
    q = tool60.quality
    assert q["symmetry_error"] <= 1e-9
    assert q["resultant_error"] <= 1e-12
    conv = q["mesh_convergence"]
    # default mesh (R/3): the two-mesh Richardson estimate is within the 0.2 % target
    assert conv["richardson_error_lateral"] < 2e-3
    assert q["mesh_size"] == pytest.approx(5e-3 / 3)
    # both fits see the ball move nearly rigidly under lateral load
    kk = np.array(q["kabsch_compliance"])
    assert abs(kk[0, 0] / k[0, 0] - 1) < 0.01


@pytest.mark.slow
def test_paper_tool_length_reproduces_table2():
    """A Ø10 steel tool of 66 mm free length gives the paper's lateral 9.34e-7 m/N."""
    sol = solve_six_cases(BallEndTool(10e-3, PAPER_TOOL_LENGTH), 10e-3 / 6)
    lateral = 0.5 * (sol.compliance[0, 0] + sol.compliance[1, 1])
    assert abs(lateral / PAPER_TOOL_LATERAL - 1) < 0.005


def test_superlu_and_pardiso_give_the_same_compliance(request):
    """The two direct solvers of ``solver=``: the suite runs PARDISO where the test extra
    installs it (x86-64), so SuperLU — the plain install's — is checked against it here; "auto"
    takes PARDISO when it is there."""
    pytest.importorskip("pypardiso", reason="pypardiso (the pardiso extra) not installed")
    tool = BallEndTool(10e-3, PAPER_TOOL_LENGTH)
    slu = solve_six_cases(tool, 2.5e-3, solver="superlu")
    par = solve_six_cases(tool, 2.5e-3, solver="pardiso")
    auto = request.getfixturevalue("paper_tool_coarse")  # solve_six_cases(tool, 2.5e-3)
    assert (slu.quality["solver"], par.quality["solver"]) == ("superlu", "pardiso")
    assert auto.quality["solver"] == "pardiso"
    scale = np.abs(slu.U).max()
    np.testing.assert_allclose(par.U, slu.U, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(par.compliance, slu.compliance, rtol=1e-9, atol=1e-9 * scale)


@pytest.mark.slow
def test_mesh_convergence_paper_tool(paper_tool_coarse):
    """Paper tool at R/2 within 0.3 % of a twice-finer mesh (R/4). The R/3-vs-R/6 pair is run by
    ``benchmarks/fem_tool.py --convergence`` (188k DOFs, too big for a unit test): 0.07 %."""
    tool = BallEndTool(10e-3, PAPER_TOOL_LENGTH)
    coarse = paper_tool_coarse.compliance  # solve_six_cases(tool, 2.5e-3)
    fine = solve_six_cases(tool, 1.25e-3).compliance
    for i in (0, 1, 2, 5):
        assert abs(coarse[i, i] / fine[i, i] - 1) < 3e-3


def test_serial_assembly_matches_assembled_fe_model():
    """k_t (clamped at the nose) + J k_th Jᵀ (loaded on the tool footprint) vs one FE body."""
    tool = BallEndTool(10e-3, 60e-3)
    holder = ToolHolder((HolderSection(25e-3, 20e-3),), coupling_diameter=10e-3)
    h = 2.5e-3
    kt = solve_six_cases(tool, h).compliance
    kh = solve_six_cases(holder, h).compliance
    ka = solve_six_cases(ToolInHolder(tool, holder), h).compliance
    res = lambda k: ComplianceResult(k, np.zeros(3), "test")  # noqa: E731
    ks = tool_holder_compliance(res(kt), res(kh), tool.length).compliance
    for i, j in [(0, 0), (1, 1), (0, 4), (1, 3)]:
        assert abs(ks[i, j] / ka[i, j] - 1) < 0.02, (i, j, ks[i, j] / ka[i, j])
    # and the holder contributes visibly (the test is not tool-only)
    assert ks[0, 0] - kt[0, 0] > 0.1 * kt[0, 0]


def test_hollow_holder_matches_timoshenko_with_cowper_kappa():
    """A uniform tube (Ø20/Ø8 × 80 mm) loaded on its nose annulus: hollow-section beam theory."""
    holder = ToolHolder((HolderSection(80e-3, 20e-3, 8e-3),))
    fe = fe_compliance(holder, 2.5e-3, convergence=False)
    beam = beam_result(holder).compliance
    rel = np.diag(fe.compliance) / np.diag(beam) - 1
    assert np.all(np.abs(rel[:5]) < 0.015), rel
    assert abs(rel[5]) < 1e-3, rel  # torsion of a tube: exact Saint-Venant
    assert fe.quality["beam_rel_diff_diag"] == pytest.approx(rel.tolist())


def test_stepped_tapered_holder_builds_and_is_a_valid_compliance():
    """Steps and tapers add 3D junction compliance beam theory does not see (here ~7 % in
    torsion for a 20→30 mm taper into a Ø40 step); FE must still be symmetric, PSD, and stiffer
    than the thinnest section alone."""
    holder = ToolHolder(
        (HolderSection(20e-3, 20e-3, 6e-3, 30e-3), HolderSection(15e-3, 40e-3, 6e-3))
    )
    fe = fe_compliance(holder, 5e-3, convergence=False)
    k = fe.compliance
    assert fe.quality["symmetry_error"] < 1e-9
    assert np.all(np.linalg.eigvalsh(k / np.sqrt(np.outer(np.diag(k), np.diag(k)))) > 0)
    thin = beam_result(ToolHolder((HolderSection(35e-3, 20e-3, 6e-3),))).compliance
    assert np.all(np.diag(k) < np.diag(thin))
    beam = beam_result(holder).compliance
    assert np.all(np.abs(np.diag(k) / np.diag(beam) - 1) < 0.25)


def test_neck_and_taper_tool_is_softer():
    plain = tool_beam(BallEndTool(10e-3, 50e-3))
    necked = tool_beam(BallEndTool(10e-3, 50e-3, 12e-3, 8e-3, 10e-3, 5e-3))
    assert necked[0, 0] > plain[0, 0] * 0.5  # sanity: same order
    fe = fe_compliance(
        BallEndTool(10e-3, 50e-3, 12e-3, 8e-3, 10e-3, 5e-3), 2.5e-3, convergence=False
    )
    assert abs(fe.compliance[0, 0] / necked[0, 0] - 1) < 0.05


def test_json_round_trip_and_schema(tmp_path, tool60):
    path = save_compliance_json(tool60, tmp_path / "tool.json")
    data = json.loads(path.read_text())
    for key in ("compliance", "reference_point", "frame", "quality", "geometry", "units", "order"):
        assert key in data
    assert data["order"] == ["Fx", "Fy", "Fz", "Mx", "My", "Mz"]
    assert data["geometry"]["length"] == pytest.approx(0.06)
    back = load_compliance_json(path)
    assert np.array_equal(back.compliance, tool60.compliance)
    assert np.array_equal(back.reference_point, tool60.reference_point)
    assert back.quality["symmetry_error"] == tool60.quality["symmetry_error"]


def test_load_rejects_bad_files(tmp_path):
    bad = tmp_path / "bad.json"
    k = np.diag([1e-6, 1e-6, 1e-9, 1e-3, 1e-3, 1e-3])
    k[0, 4] = 1e-5  # not symmetric
    bad.write_text(json.dumps({"compliance": k.tolist(), "reference_point": [0, 0, 0]}))
    with pytest.raises(InputError, match="symmetric") as e:
        load_compliance_json(bad)
    assert e.value.file == str(bad)
    bad.write_text(json.dumps({"compliance": np.eye(6).tolist()}))
    with pytest.raises(InputError, match="reference_point"):
        load_compliance_json(bad)
    bad.write_text("{not json")
    with pytest.raises(InputError, match="JSON") as e:
        load_compliance_json(bad)
    assert e.value.line == 1
    with pytest.raises(InputError, match="not found"):
        load_compliance_json(tmp_path / "missing.json")


class _Recorder:
    def __init__(self):
        self.stages = []

    def task(self, description, total=None):
        import contextlib

        self.stages.append(description)
        return contextlib.nullcontext(lambda amount=1.0: None)


def test_progress_stages_and_reproducible_mesh():
    rec = _Recorder()
    tool = BallEndTool(10e-3, 30e-3)
    fe_compliance(tool, 4e-3, progress=rec)
    assert rec.stages == [
        "mesh",
        "assemble",
        "factorise",
        "solve",
        "mesh (2h check)",
        "assemble (2h check)",
        "factorise (2h check)",
        "solve (2h check)",
    ]
    from roboisf.fem import mesh_geometry

    a, b = mesh_geometry(tool, 3e-3), mesh_geometry(tool, 3e-3)
    assert np.array_equal(a.points, b.points) and np.array_equal(a.tets, b.tets)


def test_bored_holder_couples_on_the_footprint_annulus():
    from roboisf.fem import SurfaceCoupling, mesh_geometry

    holder = ToolHolder((HolderSection(20e-3, 30e-3, 6e-3),), coupling_diameter=16e-3)
    mesh = mesh_geometry(holder, 3e-3)
    area = SurfaceCoupling.build(mesh.points, mesh.coupling, holder.reference_point).area
    # circles as quadratic arcs: area exact to the P2 geometry error (~h⁴/R⁴)
    assert area == pytest.approx(np.pi / 4 * (16e-3**2 - 6e-3**2), rel=1e-3)
    assert np.all(np.abs(mesh.points[mesh.coupling][..., 2]) < 1e-12)  # on the nose plane
    assert np.all(np.abs(mesh.points[mesh.clamped][..., 2] - 20e-3) < 1e-12)


def test_serial_assembly_lever_arm_against_beam_theory():
    """Two beam pieces in series equal the beam of the whole shaft (checks v = tip − nose)."""
    from roboisf.fem import beam_compliance
    from roboisf.fem.geometry import ShaftSegment

    mat = BallEndTool(10e-3, 60e-3).material
    whole = beam_compliance([ShaftSegment(0.0, 0.1, 10e-3, 10e-3)], mat)
    lower = beam_compliance([ShaftSegment(0.0, 0.04, 10e-3, 10e-3)], mat)
    upper = beam_compliance([ShaftSegment(0.0, 0.06, 10e-3, 10e-3)], mat)  # about its own base
    res = lambda k: ComplianceResult(k, np.zeros(3), "test")  # noqa: E731
    ks = tool_holder_compliance(res(lower), res(upper), 0.04).compliance
    assert np.allclose(ks, whole, rtol=1e-10, atol=1e-14 * np.abs(whole).max())
    # a holder file whose reference point is off its origin is moved consistently
    from roboisf.frames import to_tip

    upper_at_10mm = to_tip(upper, np.array([0.0, 0.0, 0.01]))  # the same piece, about z = 10 mm
    ks2 = tool_holder_compliance(
        res(lower), ComplianceResult(upper_at_10mm, [0, 0, 0.01], "t"), 0.04
    )
    assert np.allclose(ks2.compliance, whole, rtol=1e-10, atol=1e-14 * np.abs(whole).max())


def test_inverted_element_is_an_input_error():
    from roboisf.errors import InputError
    from roboisf.fem import STEEL, assemble_stiffness, mesh_geometry
    from roboisf.fem.mesh import TetMesh

    m = mesh_geometry(BallEndTool(10e-3, 30e-3), 5e-3)
    tets = m.tets.copy()
    tets[0, [1, 2]] = tets[0, [2, 1]]  # swap two vertices: negative Jacobian
    tets[0, [4, 6]] = tets[0, [6, 4]]
    tets[0, [8, 9]] = tets[0, [9, 8]]
    bad = TetMesh(m.points, tets, m.body, m.clamped, m.coupling, m.mesh_size)
    with pytest.raises(InputError, match="inverted") as e:
        assemble_stiffness(bad, np.array([STEEL.lame]))
    assert e.value.field == "mesh_size"


_NO_SEARCH = """
import glob, os, sys
os.environ.pop("PYPARDISO_MKL_RT", None)
def refuse(*a, **k):
    raise AssertionError(f"pypardiso searched for MKL: glob{a}")
glob.glob = refuse
import ctypes.util
ctypes.util.find_library = lambda name: refuse(name)
import numpy as np, scipy.sparse as sp
from roboisf.fem.stiffness import MKL_RT_VARIABLE, _factorize
K = sp.csr_matrix(np.array([[4.0, 1.0], [1.0, 3.0]]))
solve, name = _factorize(K, "pardiso")
x = solve(np.array([1.0, 2.0]))
print(name, os.path.basename(os.environ[MKL_RT_VARIABLE]), np.abs(K @ x - [1.0, 2.0]).max() < 1e-12)
"""


def test_pardiso_is_told_where_mkl_is_and_searches_nothing():
    """pypardiso's own search for MKL's runtime (``find_library``, which runs ``ldconfig`` and a
    compiler, then a recursive glob of the whole environment) cost 0.5 s per factorisation and
    1 s at its import. With the ``mkl`` wheel installed roboisf passes the library's path from
    the wheel's file record: the search never runs (both are made to fail here), and the
    solver loads that library and solves."""
    pytest.importorskip("pypardiso", reason="pypardiso (the pardiso extra) not installed")
    from roboisf.fem.stiffness import mkl_runtime

    if mkl_runtime() is None:
        pytest.skip("MKL not from the mkl wheel: pypardiso's own search is what finds it")
    r = subprocess.run(
        [sys.executable, "-c", _NO_SEARCH], capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0, r.stderr[-2000:]
    name, lib, ok = r.stdout.split()
    assert (name, ok) == ("pardiso", "True")
    assert "mkl_rt" in lib


def test_a_users_mkl_path_is_kept(monkeypatch):
    from roboisf.fem import stiffness

    pytest.importorskip("pypardiso", reason="pypardiso (the pardiso extra) not installed")
    monkeypatch.setenv(stiffness.MKL_RT_VARIABLE, "/opt/my/libmkl_rt.so.2")
    stiffness._import_pypardiso()
    assert os.environ[stiffness.MKL_RT_VARIABLE] == "/opt/my/libmkl_rt.so.2"
