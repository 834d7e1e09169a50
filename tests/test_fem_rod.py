"""Acceptance: a clamped Ø10 × 100 mm steel rod loaded on its flat end vs Timoshenko beam theory."""

import numpy as np
import pytest

from roboisf.fem import (
    HolderSection,
    SurfaceCoupling,
    ToolHolder,
    beam_compliance,
    cowper_shear_coefficient,
    kabsch_fit,
    solve_six_cases,
)
from roboisf.frames import rotvec_to_matrix

D, L = 10e-3, 100e-3


@pytest.fixture(scope="module")
def rod():
    geom = ToolHolder((HolderSection(L, D),))  # solid rod, clamped at z = L, loaded at z = 0
    return geom, solve_six_cases(geom, 2.5e-3, solver="superlu")


def test_beam_model_closed_form():
    """The slice integral reproduces the textbook cantilever terms."""
    geom = ToolHolder((HolderSection(L, D),))
    E, G, nu = geom.material.E, geom.material.G, geom.material.nu
    A, I = np.pi * D**2 / 4, np.pi * D**4 / 64
    k = beam_compliance(geom.segments(), geom.material)
    kappa = cowper_shear_coefficient(nu)
    assert np.isclose(kappa, 6 * (1 + nu) / (7 + 6 * nu))
    assert np.isclose(k[0, 0], L**3 / (3 * E * I) + L / (kappa * G * A), rtol=1e-12)
    assert np.isclose(k[2, 2], L / (E * A), rtol=1e-12)
    assert np.isclose(k[3, 3], L / (E * I), rtol=1e-12)
    assert np.isclose(k[5, 5], L / (G * 2 * I), rtol=1e-12)
    # Fx at the free end makes it turn about −y (clamp above): k[x, θy] = −L²/(2EI)
    assert np.isclose(k[0, 4], -(L**2) / (2 * E * I), rtol=1e-12)
    assert np.isclose(k[1, 3], +(L**2) / (2 * E * I), rtol=1e-12)
    assert np.allclose(k, k.T, rtol=0, atol=1e-20)
    k_eb = beam_compliance(geom.segments(), geom.material, shear=False)
    assert np.isclose(k_eb[0, 0], L**3 / (3 * E * I), rtol=1e-12)


def test_rod_matches_timoshenko(rod):
    geom, sol = rod
    C, B = sol.compliance, beam_compliance(geom.segments(), geom.material)
    rel = lambda i, j: abs(C[i, j] / B[i, j] - 1)  # noqa: E731
    for i, j in [(0, 0), (1, 1), (2, 2), (3, 3), (4, 4), (0, 4), (4, 0), (1, 3), (3, 1)]:
        assert rel(i, j) < 0.015, (i, j, rel(i, j))
    assert rel(5, 5) < 1e-3  # torsion of a circular shaft is exact Saint-Venant
    # terms beam theory says are zero stay small: correlation-normalised |k_ij|/√(k_ii k_jj);
    # an unstructured mesh is not exactly axisymmetric, hence not 1e-12
    d = np.sqrt(np.diag(C))
    assert np.abs(C / np.outer(d, d))[B == 0].max() < 1e-2


def test_rod_quality_figures(rod):
    _, sol = rod
    q = sol.quality
    assert q["symmetry_error"] <= 1e-9
    assert q["resultant_error"] <= 1e-12
    assert q["kabsch_rel_diff"] < 0.01  # the flat end moves nearly rigidly: both fits agree
    assert min(q["pnr"]) > 10
    ci = np.array(q["ci95"])
    assert ci.shape == (6, 6) and np.all(ci > 0)
    # the CI of each diagonal parameter is small against the parameter itself
    assert np.all(np.diag(ci) < 0.1 * np.abs(np.diag(sol.compliance)))


def test_resultant_is_the_unit_wrench_to_rounding(rod):
    _, sol = rod
    R = sol.coupling.resultant(sol.F, sol.mesh.points)
    assert np.abs(R - np.eye(6)).max() < 1e-12
    # the loads sit only on coupling-surface nodes
    f = np.abs(sol.F.reshape(-1, 3, 6)).sum(axis=(1, 2))
    assert set(np.flatnonzero(f)) <= set(sol.coupling.nodes.tolist())


def test_fits_recover_an_exact_rigid_motion(rod):
    _, sol = rod
    mesh, cp = sol.mesh, sol.coupling
    p, phi = np.array([1e-6, -2e-6, 3e-7]), np.array([2e-5, 1e-5, -3e-5])
    ref = np.array([0.0, 0.0, -5e-3])
    cp2 = SurfaceCoupling.build(mesh.points, mesh.coupling, ref)
    u = p + np.cross(phi, mesh.points - ref)
    c, residual = cp2.fit(u.reshape(-1, 1))
    assert np.allclose(c[:, 0], np.r_[p, phi], rtol=1e-10, atol=0)
    assert np.abs(residual).max() < 1e-18
    ck = kabsch_fit(mesh.points[cp2.nodes], u[cp2.nodes][:, :, None], ref)
    assert np.allclose(ck[:, 0], np.r_[p, phi], rtol=1e-6, atol=0)
    # a finite rotation is also recovered by Kabsch (scaled into the small-motion range)
    R = rotvec_to_matrix(np.array([0.0, 0.0, 1e-3]))
    ud = (mesh.points[cp.nodes] - ref) @ R.T + ref - mesh.points[cp.nodes]
    ck = kabsch_fit(mesh.points[cp.nodes], ud[:, :, None], ref)
    assert np.allclose(ck[3:, 0], [0, 0, 1e-3], rtol=1e-6, atol=1e-12)
