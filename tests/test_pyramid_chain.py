"""A pyramid and a freeform STL part through the whole chain (issue #12, Done-when).

``virtual-cell pyramid -o S && analyze S -o R`` must recover every contribution within 20 µm RMS
of the cell's truth (normal component) and every share within 2 points; the same for a freeform
part given as an STL (an elliptic paraboloid pit, tessellated here). ``compensate`` on the pyramid
removes ≥ 90 % of the compliance error in the virtual cell; ``plan --part pyramid.toml`` ranks
placements. Plus known answers for the pieces the chain adds: the scan sampler on any part, the
formed-surface field, and the in-plane force along the wall normal.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from roboisf.cam.toolpath_csv import read_toolpath_csv
from roboisf.cell import ForceModel, tip_wrench
from roboisf.cli.main import main
from roboisf.compensate import precompensate
from roboisf.compensate.virtual import cell_deflection_model
from roboisf.decompose import FACTORS
from roboisf.errors import InputError
from roboisf.parts import Pyramid
from roboisf.parts.io import save_part
from roboisf.programs.rapid import read_rapid
from roboisf.scan.synthetic import height_field_mesh, surface_heights, synthetic_scan
from roboisf.study import load_study
from roboisf.virtual.cell import PYRAMID, paper_cone_cell, pyramid_cell, simulate
from roboisf.virtual.formed import PointField
from summary_check import validated

pytestmark = pytest.mark.slow

SMALL = ["--scan-points", "200000", "--force-rate", "200"]
#: The freeform part's toolpath: 1 mm step-down, 2 mm spacing (the pyramid keeps the default
#: 0.5 / 1 mm of the issue's command). Measured on the default path: largest RMS error 7.95 µm,
#: shares within 0.05 points, registration within 1.3 µm and 0.003°; on this one 7.08 µm, 0.055
#: points, 0.4 µm and 0.0015° — the same margins to the 20 µm / 2 points / 10 µm / 0.01°
#: checks, for 40 % of the virtual cell's CPU (16 → 6.6 s).
STL_PATH = ["--step-down", "1", "--spacing", "2"]


def dome_stl(path, a=50.0, b=35.0, d=30.0, flange=10.0, n_theta=256, n_r=60):
    """Write an elliptic paraboloid pit ``z = −d (1 − ρ²)``, ``ρ² = (x/a)² + (y/b)²`` [mm], with a
    flat flange out to ρ = 1 + flange/b, as an STL (wall angle 50° at the rim along x, 60° along
    y, 0 at the bottom: a freeform part with no symmetry axis of revolution)."""
    import trimesh

    r = np.r_[np.linspace(0.0, 1.0, n_r + 1), 1 + 0.5 * flange / b, 1 + flange / b]
    th = 2 * np.pi * np.arange(n_theta) / n_theta
    V = [np.array([[0.0, 0.0, -d]])]
    for ri in r[1:]:
        z = -d * max(0.0, 1 - ri**2)
        V.append(np.column_stack([a * ri * np.cos(th), b * ri * np.sin(th), np.full(n_theta, z)]))
    j = np.arange(n_theta)
    j1 = (j + 1) % n_theta
    F = [np.column_stack([np.zeros(n_theta, int), 1 + j, 1 + j1])]
    for i in range(len(r) - 2):
        o0, o1 = 1 + i * n_theta, 1 + (i + 1) * n_theta
        F += [
            np.column_stack([o0 + j, o1 + j, o1 + j1]),
            np.column_stack([o0 + j, o1 + j1, o0 + j1]),
        ]
    trimesh.Trimesh(np.vstack(V), np.vstack(F), process=False).export(str(path))


def _run(args):
    assert main(["-q", *args]) == 0, args


@pytest.fixture(scope="module", params=["pyramid", "stl"])
def analysed(request, tmp_path_factory):
    root = tmp_path_factory.mktemp(request.param)
    if request.param == "pyramid":
        _run(["virtual-cell", "pyramid", *SMALL, "-o", str(root / "S")])
    else:
        dome_stl(root / "dome.stl")
        _run(["part", "mesh", str(root / "dome.stl"), "-o", str(root / "dome.toml")])
        part = str(root / "dome.toml")
        _run(["virtual-cell", "--part", part, *SMALL, *STL_PATH, "-o", str(root / "S")])
    _run(["analyze", str(root / "S"), "-o", str(root / "R"), "--no-png"])
    return root


def test_every_term_within_20_um_rms_and_shares_within_2_points(analysed):
    s = validated(analysed / "R" / "summary.json")
    truth = s["truth"]
    rms = truth["rms_error_dn_mm"]
    assert set(rms) == set(FACTORS)
    for factor, err in rms.items():
        assert err < 0.020, (factor, err)
    for file, book in (
        ("contributions_normal.csv", "shares_normal"),
        ("contributions.csv", "shares_per_axis"),
    ):
        got = pd.read_csv(analysed / "R" / file).set_index("factor")["share_percent"]
        for factor in FACTORS:
            assert got[factor] == pytest.approx(truth[book][factor], abs=2.0), (file, factor)
    # the scans were misplaced in the fixture (0.4 mm down, 0.15°/−0.1° tilts): the fixture
    # registration found it on the flange of this non-round part
    for run in ("cnc", "robot"):
        reg = s["registration"][run]
        assert reg["method"] == "fixture"
        assert reg["translation_mm"][2] == pytest.approx(-0.4, abs=0.01)
        assert reg["tilt_deg"] == pytest.approx(math.hypot(0.15, 0.1), abs=0.01)
    # a real robot term and a real springback to recover: the test could fail
    assert truth["R_m_physical_mm"]["robot_compliance"] > 0.1
    assert truth["R_m_physical_mm"]["springback"] > 0.1


def test_the_study_keeps_its_part(analysed):
    st = load_study(analysed / "S")
    assert st.part.kind in ("pyramid", "mesh")
    if st.part.kind == "mesh":  # the mesh travels with the study, exactly
        from roboisf.parts import MeshPart

        orig = MeshPart.from_file(analysed / "dome.stl")
        assert st.part.n_faces == orig.n_faces
        x = np.random.default_rng(1).uniform(-0.05, 0.05, (2000, 3)) * [1, 0.8, 0.6]
        np.testing.assert_allclose(st.part.signed_distance(x), orig.signed_distance(x), atol=1e-15)
    else:
        assert st.part == PYRAMID


def test_compensate_removes_90_percent_of_the_compliance_error():
    """Full model (robot + tool + holder) pre-deflection on the virtual pyramid (from truth)."""
    cell = pyramid_cell(step_down=2e-3, spacing=3e-3)
    before = simulate(cell)
    full = precompensate(before.toolpath, before.wrench_robot, cell_deflection_model(cell.cell))
    after = simulate(cell, commanded=before.toolpath.with_tip(full.commanded))
    e_before = np.mean(np.abs(before.dn_robot - before.springback))
    e_after = np.mean(np.abs(after.dn_robot - after.springback))
    assert e_before > 0.2e-3  # a real compliance error to remove
    assert e_after <= 0.10 * e_before, (e_before, e_after)
    # the robot term alone, the tool and holder left in
    m = replace(cell_deflection_model(cell.cell), k_tip=np.zeros((6, 6)))
    res = precompensate(before.toolpath, before.wrench_robot, m)
    after_r = simulate(cell, commanded=before.toolpath.with_tip(res.commanded))
    n = before.toolpath.normal
    others = np.einsum("ij,ij->i", after_r.tool_robot + after_r.holder_robot, n)
    robot_after = after_r.dn_robot - others - after_r.springback
    robot_before = np.einsum("ij,ij->i", before.robot, n)
    assert np.mean(np.abs(robot_after)) <= 0.10 * np.mean(np.abs(robot_before))


def test_compensate_cli_virtual_pyramid(tmp_path):
    out = tmp_path / "comp"
    _run(
        [
            "compensate",
            "--virtual",
            "pyramid",
            "--step-down",
            "2",
            "--spacing",
            "3",
            "--iterations",
            "2",
            "--no-png",
            "-o",
            str(out),
        ]
    )
    s = json.loads((out / "compensation.json").read_text())
    assert s["complete"] and s["gouge"]["ok"] and s["compliance"]["converged"]
    m = s["mean_abs_dn_per_iteration_mm"]
    assert m[0] > 0.5 and m[-1] < 0.1 * m[0], m


def test_compensate_study_route_writes_programs_for_any_part(analysed, tmp_path):
    """The pyramid and the freeform STL part: the compensated path and its program set."""
    out = tmp_path / "o"
    _run(
        [
            "compensate",
            str(analysed / "S"),
            "--results",
            str(analysed / "R"),
            "-o",
            str(out),
            "--no-png",
        ]
    )
    pp = pd.read_csv(out / "per_point.csv")
    tp = pd.read_csv(analysed / "S" / "toolpath.csv", comment="#")
    assert len(pp) == len(tp)
    assert json.loads((out / "compensation.json").read_text())["gouge"]["ok"]
    cmd = read_toolpath_csv(out / "compensated.csv")
    rapid = read_rapid(out / "compensated.mod")
    assert np.abs(rapid.tip - cmd.tip).max() <= 0.5e-6 + 1e-12  # the program is the path
    for name in ("compensated.src", "compensated.ls", "compensated.nc"):
        assert (out / name).stat().st_size > 0


def test_plan_ranks_pyramid_placements(tmp_path):
    part = tmp_path / "pyramid.toml"
    save_part(PYRAMID, part)
    out = tmp_path / "plan"
    _run(
        [
            "plan",
            "--part",
            str(part),
            "--x-range",
            "1400:2200:3",
            "--y-range",
            "0,300",
            "--z-range",
            "200",
            "--serial",
            "-o",
            str(out),
        ]
    )
    df = pd.read_csv(out / "placements.csv", comment="#")
    ok = df[df.status == "ok"]
    assert len(ok) == 6
    assert list(ok["rank"].astype(int)) == list(range(1, 7))
    assert ok["mean_abs_mm"].is_monotonic_increasing
    # closer to the base is stiffer (as for the cone)
    assert ok.iloc[0]["x_mm"] < ok.iloc[-1]["x_mm"]


# -- the pieces -----------------------------------------------------------------------------------


def test_scan_sampling_is_uniform_by_area_on_a_pyramid():
    """Sharp square pyramid: bottom / (wall + bottom) area = b² / (b² + 2 (L + b) d / sin α)."""
    p = Pyramid(100e-3, 100e-3, math.radians(60.0), 40e-3, corner_radius=0.0)
    scan = synthetic_scan(p, 200_000, noise=0.0, seed=3)
    assert np.max(np.abs(p.signed_distance(scan.points))) < 1e-12  # exactly on the surface
    b = 100e-3 - 2 * 40e-3 / math.tan(math.radians(60.0))
    walls = 2 * (100e-3 + b) * 40e-3 / math.sin(math.radians(60.0))
    expected = b * b / (b * b + walls)
    n_wall, n_bottom = np.sum(scan.region == 1), np.sum(scan.region == 2)
    got = n_bottom / (n_wall + n_bottom)
    sigma = math.sqrt(expected * (1 - expected) / (n_wall + n_bottom))
    assert abs(got - expected) < 4 * sigma + 1e-3, (got, expected)
    V, F = height_field_mesh(p, 1e-3)
    assert np.max(np.abs(p.signed_distance(V[np.unique(F)]))) < 1e-6


def test_surface_heights_meet_bisection_in_a_few_evaluations():
    """The height field's safeguarded Newton: the crossing of each vertical line where 60
    bisections of the signed distance put it (to the tolerance), on planar walls, the rounded
    corners' cones, the bottom, the flange and lines that miss the surface (beyond the rounded
    flange's corners: left with |d| > tolerance); a handful of evaluations, not bisection's 21."""
    p = Pyramid(120e-3, 90e-3, math.radians(55.0), 35e-3, corner_radius=12e-3)
    lo, hi = p.bounds
    rng = np.random.default_rng(2)
    X, Y = (rng.uniform(lo[i], hi[i], 4000) for i in (0, 1))
    X, Y = np.r_[X, hi[0] - 1e-6], np.r_[Y, hi[1] - 1e-6]  # a flange corner: no surface
    calls = []

    class Counted:
        def closest_point(self, pts):
            calls.append(len(pts))
            return p.closest_point(pts)

    z_lo, z_hi = lo[2] - 1e-3, hi[2] + 1e-3
    Z, d = surface_heights(Counted(), X, Y, z_lo, z_hi, 1e-7)
    a, b = np.full(X.size, z_lo), np.full(X.size, z_hi)
    for _ in range(60):
        m = 0.5 * (a + b)
        above = p.signed_distance(np.c_[X, Y, m]) > 0
        a, b = np.where(above, a, m), np.where(above, m, b)
    ref = 0.5 * (a + b)
    hit = np.abs(p.signed_distance(np.c_[X, Y, ref])) < 1e-9
    assert hit.sum() > 3800 and not hit[-1]  # ≈ 2.7 % of the box lies beyond the flange
    np.testing.assert_allclose(Z[hit], ref[hit], rtol=0, atol=1e-7)
    assert np.all(np.abs(d[hit]) <= 0.5e-7) and abs(d[-1]) > 1e-6
    np.testing.assert_array_equal(d, p.signed_distance(np.c_[X, Y, Z]))  # d is where Z is
    assert len(calls) <= 25 and sum(calls) < 6 * X.size, (len(calls), sum(calls) / X.size)


def test_two_scans_of_one_part_share_its_tessellation(monkeypatch):
    """A study's CNC and robot scans sample one nominal surface: tessellated once (kept for the
    last two parts), the same points as without the cache; a part that cannot be hashed is
    tessellated every time and still sampled."""
    import roboisf.scan.synthetic as syn

    calls = []
    real = syn.height_field_mesh

    def counted(part, *a, **k):
        calls.append(part)
        return real(part, *a, **k)

    monkeypatch.setattr(syn, "height_field_mesh", counted)
    syn._cached_tessellation.cache_clear()
    p = Pyramid(80e-3, 60e-3, math.radians(55.0), 25e-3, corner_radius=8e-3)
    a = synthetic_scan(p, 5000, noise=0.0, seed=1)
    b = synthetic_scan(p, 5000, noise=0.0, seed=1)
    assert len(calls) == 1
    np.testing.assert_array_equal(a.points, b.points)
    V, F = syn._cached_tessellation(p)
    assert not V.flags.writeable and not F.flags.writeable

    class Unhashable:  # a user's part class with eq but no hash
        __hash__ = None

        def __getattr__(self, name):
            return getattr(p, name)

    syn._cached_tessellation.cache_clear()
    c = synthetic_scan(Unhashable(), 5000, noise=0.0, seed=1)
    synthetic_scan(Unhashable(), 5000, noise=0.0, seed=1)
    assert len(calls) == 3
    np.testing.assert_array_equal(c.points, a.points)


def test_point_field_known_answers():
    cell = pyramid_cell(step_down=2e-3, spacing=3e-3)
    tp = simulate(cell).toolpath
    const = PointField.from_toolpath(tp, np.full(len(tp), 0.3e-3))
    deep = tp.contact[tp.depth > 10e-3]
    np.testing.assert_allclose(const(deep), 0.3e-3, rtol=1e-12)  # IDW of a constant
    assert np.all(const(tp.contact * [1, 1, 0]) == 0.0)  # the clamped sheet plane does not move
    z_mid = 0.5 * const.z_first  # halfway up the ramp above the first lap
    pts = tp.contact[tp.lap == 2] * [1, 1, 0] + [0, 0, z_mid]
    np.testing.assert_allclose(const(pts), 0.15e-3, rtol=1e-12)
    # a linear field in z is reproduced between the laps (to the lap-to-lap curvature)
    lin = PointField.from_toolpath(tp, -tp.contact[:, 2] * 1e-2)
    mid = tp.contact[(tp.depth > 10e-3) & (tp.depth < 30e-3)]
    np.testing.assert_allclose(lin(mid), -mid[:, 2] * 1e-2, atol=2e-6)
    with pytest.raises(InputError, match="dn"):
        PointField.from_toolpath(tp, np.full(len(tp) - 1, 0.0))


def test_in_plane_force_along_the_wall_normal():
    """On a pyramid's x-wall the radial force is along −x exactly, the friction along ±y; on the
    cone the wall normal gives the radial direction (results unchanged)."""
    cell = pyramid_cell(step_down=2e-3, spacing=3e-3)
    tp = simulate(cell).toolpath
    fm = ForceModel()
    W = tip_wrench(tp, fm, thickness=1.22e-3, step_down=2e-3)
    fz = W[:, 2]
    xwall = (np.abs(tp.normal[:, 1]) < 1e-9) & (tp.normal[:, 0] < -0.5) & (fz > 1.0)
    assert xwall.sum() > 20
    np.testing.assert_allclose(W[xwall, 0] / fz[xwall], -fm.radial_ratio, rtol=1e-9)
    np.testing.assert_allclose(np.abs(W[xwall, 1]) / fz[xwall], fm.tangential_ratio, rtol=1e-9)
    cone = simulate(paper_cone_cell(step_down=2e-3, spacing=3e-3)).toolpath
    Wc = tip_wrench(cone, fm, thickness=1.22e-3, step_down=2e-3)
    r_hat = cone.contact[:, :2] / np.linalg.norm(cone.contact[:, :2], axis=1, keepdims=True)
    radial = -np.einsum("ij,ij->i", Wc[:, :2], r_hat)
    np.testing.assert_allclose(radial, fm.radial_ratio * Wc[:, 2], rtol=1e-9, atol=1e-9)


def test_virtual_cell_pyramid_options_and_bad_input(tmp_path, capsys):
    assert main(["virtual-cell", "cone", "--depth", "30", "-o", str(tmp_path / "a")]) == 2
    assert "--depth" in capsys.readouterr().err
    assert main(["virtual-cell", "pyramid", "--wall-angle", "95", "-o", str(tmp_path / "b")]) == 2
    assert "wall_angle" in capsys.readouterr().err
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
