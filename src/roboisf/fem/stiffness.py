"""Six virtual experiments on a meshed body → 6×6 compliance about its reference point.

Pipeline (each stage reports progress): mesh (gmsh, curved P2 tets) → assemble (vectorised,
:mod:`roboisf.fem.assembly`) → factorise the free-DOF stiffness once (PARDISO if ``pypardiso`` is
installed, else SuperLU) → solve the six unit load cases Fx Fy Fz Mx My Mz together → fit a rigid
motion over the coupling surface (:mod:`roboisf.fem.coupling`) → stack the six ``[p; φ]`` columns.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.fem.assembly import assemble_stiffness
from roboisf.fem.beam import beam_compliance
from roboisf.fem.coupling import SurfaceCoupling, kabsch_fit
from roboisf.fem.geometry import BallEndTool, Geometry, ToolHolder
from roboisf.fem.mesh import TetMesh, mesh_geometry
from roboisf.fem.result import ComplianceResult
from roboisf.frames import serial_assembly
from roboisf.progress import Progress, task

__all__ = [
    "RICHARDSON_ORDER",
    "FESolution",
    "beam_result",
    "default_mesh_size",
    "fe_compliance",
    "holder_compliance",
    "solve_six_cases",
    "tool_compliance",
    "tool_holder_compliance",
]

F64 = NDArray[np.float64]

#: Convergence order of the compliance assumed by the two-mesh Richardson estimate. P2 energy
#: quantities would converge as h⁴ on a smooth problem, but the edge where the clamped face meets
#: the free surface is a clamped–free 90° wedge whose stresses are singular as r^(λ−1), λ ≈ 0.71
#: (ν = 0.3), so the energy (and the compliance) converges as h^(2λ) ≈ h^1.4 — what the Ø10 tool
#: shows between R/2, R/3 and R/4 (observed order 1.4).
RICHARDSON_ORDER = 1.4


class _Suffixed:
    """A progress whose stage names carry a suffix (the coarse convergence run)."""

    def __init__(self, inner: Progress | None, suffix: str) -> None:
        self.inner, self.suffix = inner, suffix

    def task(self, description: str, total: float | None = None) -> Any:
        return task(self.inner, description + self.suffix, total)


def default_mesh_size(geometry: Geometry) -> float:
    """Default element size [m]: a third of the geometry's characteristic size.

    R/3 for a ball-end tool (0.13 % from converged on the Ø10 × 60 mm tool, target ≤ 0.2 %), a
    third of the thinnest section radius (or wall thickness, if bored) for a holder.
    """
    size = geometry.characteristic_size
    if not math.isfinite(size):
        raise InputError("give a mesh size for a STEP geometry", field="mesh_size")
    return size / 3.0


#: pypardiso's variable for the path of MKL's runtime library (read by every PyPardisoSolver).
MKL_RT_VARIABLE = "PYPARDISO_MKL_RT"


def mkl_runtime() -> str | None:
    """The path of MKL's runtime library (``libmkl_rt.so.N``, ``mkl_rt.N.dll``) as the ``mkl``
    wheel's installed-files record lists it, or None (no ``mkl`` distribution, or no such file:
    MKL from conda or the system, which pypardiso's own search finds)."""
    from importlib import metadata

    try:
        files = metadata.files("mkl") or []
    except metadata.PackageNotFoundError:
        return None
    for f in sorted(files, key=lambda f: len(str(f))):
        name = f.name
        if "mkl_rt" in name and (".so" in name or name.endswith((".dll", ".dylib"))):
            path = f.locate()
            if os.path.isfile(path):
                return os.path.realpath(path)
    return None


def _import_pypardiso() -> Any:
    """``pypardiso``, told where MKL's runtime is when the ``mkl`` wheel says so.

    Without ``PYPARDISO_MKL_RT`` each ``PyPardisoSolver()`` (one at pypardiso's import, one per
    factorisation) looks for the library with ``ctypes.util.find_library`` (which runs
    ``ldconfig`` and a compiler) and then a recursive glob over the whole environment: 0.5 s
    each on a virtualenv with the test extras, 1.0 s for the import. A path the user set is
    kept."""
    if MKL_RT_VARIABLE not in os.environ:
        path = mkl_runtime()
        if path is not None:
            os.environ[MKL_RT_VARIABLE] = path
    import pypardiso

    return pypardiso


def _factorize(K: sp.csr_matrix, solver: str) -> tuple[Callable[[F64], F64], str]:
    if solver not in ("auto", "pardiso", "superlu"):
        raise InputError(f"solver must be auto, pardiso or superlu, got {solver!r}", field="solver")
    if solver in ("auto", "pardiso"):
        try:
            pypardiso = _import_pypardiso()

            ps = pypardiso.PyPardisoSolver(mtype=2)  # real symmetric positive definite
            Ku = sp.triu(K, format="csr")
            ps.factorize(Ku)
            return (lambda b: ps.solve(Ku, b)), "pardiso"
        except ImportError:
            if solver == "pardiso":
                raise InputError(
                    "solver 'pardiso' needs the optional extra: pip install roboisf[pardiso]",
                    field="solver",
                ) from None
    from scipy.sparse.linalg import splu

    lu = splu(K.tocsc(), permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
    return lu.solve, "superlu"


@dataclass(frozen=True)
class FESolution:
    """Raw outputs of one FE run (for tests, diagnostics and plots).

    compliance : (6, 6) float, SI — about the reference point, before symmetrising
    mesh : TetMesh
    coupling : SurfaceCoupling
    U : (n_dofs, 6) float, m — nodal displacements of the six unit load cases
    F : (n_dofs, 6) float, N — their consistent nodal loads
    quality : dict — the quality figures (see ComplianceResult)
    """

    compliance: F64
    mesh: TetMesh
    coupling: SurfaceCoupling
    U: F64
    F: F64
    quality: dict[str, Any]


def solve_six_cases(
    geometry: Geometry,
    mesh_size: float,
    *,
    intorder: int = 2,
    solver: str = "auto",
    progress: Progress | None = None,
) -> FESolution:
    """One FE run at ``mesh_size`` [m]: the compliance and its quality figures (no convergence)."""
    t0 = time.perf_counter()
    mesh = mesh_geometry(geometry, mesh_size, progress=progress)
    t1 = time.perf_counter()
    lame = np.array([m.lame for m in geometry.materials])
    K = assemble_stiffness(mesh, lame, intorder=intorder, progress=progress)
    t2 = time.perf_counter()
    fixed = np.zeros(mesh.n_dofs, dtype=bool)
    fixed[(3 * np.unique(mesh.clamped)[:, None] + np.arange(3)).ravel()] = True
    free = np.flatnonzero(~fixed)
    Kff = K[free][:, free]
    with task(progress, "factorise", 1) as advance:
        solve, used = _factorize(Kff, solver)
        advance(1)
    t3 = time.perf_counter()
    coupling = SurfaceCoupling.build(mesh.points, mesh.coupling, geometry.reference_point)
    F = coupling.loads(np.eye(6))
    with task(progress, "solve", 6) as advance:
        U = np.zeros_like(F)
        U[free] = np.asarray(solve(np.ascontiguousarray(F[free]))).reshape(len(free), 6)
        advance(6)
    t4 = time.perf_counter()
    C, residual = coupling.fit(U)
    stats = coupling.fit_statistics(C, residual)
    nodes = coupling.nodes
    C_kabsch = kabsch_fit(mesh.points[nodes], U.reshape(-1, 3, 6)[nodes], geometry.reference_point)
    resultant = coupling.resultant(F, mesh.points)
    scale = np.abs(C).max()
    quality: dict[str, Any] = {
        "symmetry_error": float(np.linalg.norm(C - C.T) / np.linalg.norm(C)),
        "resultant_error": float(np.abs(resultant - np.eye(6)).max()),
        "pnr": stats["pnr"].tolist(),
        "rms_residual": stats["rms_residual"].tolist(),
        "ci95": stats["ci95"].tolist(),
        "kabsch_rel_diff": float(np.abs(C_kabsch - C).max() / scale),
        "kabsch_compliance": C_kabsch.tolist(),
        "mesh_size": float(mesh_size),
        "n_nodes": mesh.n_nodes,
        "n_tets": len(mesh.tets),
        "n_dofs": len(free),
        "coupling_area": coupling.area,
        "intorder": intorder,
        "solver": used,
        "timings": {"mesh": t1 - t0, "assemble": t2 - t1, "factorise": t3 - t2, "solve": t4 - t3},
    }
    return FESolution(compliance=C, mesh=mesh, coupling=coupling, U=U, F=F, quality=quality)


def _beam_reference(geometry: Geometry) -> F64 | None:
    if isinstance(geometry, BallEndTool | ToolHolder):
        return beam_compliance(geometry.segments(), geometry.material)
    return None


def fe_compliance(
    geometry: Geometry,
    mesh_size: float | None = None,
    *,
    convergence: bool = True,
    intorder: int = 2,
    solver: str = "auto",
    progress: Progress | None = None,
) -> ComplianceResult:
    """6×6 compliance [SI] of ``geometry`` about its reference point by six FE load cases.

    Parameters
    ----------
    geometry : BallEndTool, ToolHolder, ToolInHolder or StepGeometry
    mesh_size : float, m — target element size (default :func:`default_mesh_size`)
    convergence : bool — also solve at twice the element size and store the Richardson
        estimate of the discretisation error in ``quality["mesh_convergence"]``
    intorder : int — tet quadrature degree
    solver : "auto" | "pardiso" | "superlu"
    progress : roboisf.progress.Progress or None
    """
    h = default_mesh_size(geometry) if mesh_size is None else float(mesh_size)
    fine = solve_six_cases(geometry, h, intorder=intorder, solver=solver, progress=progress)
    C = fine.compliance
    quality = dict(fine.quality)
    if convergence:
        coarse = solve_six_cases(
            geometry,
            2 * h,
            intorder=intorder,
            solver=solver,
            progress=None if progress is None else _Suffixed(progress, " (2h check)"),
        )
        Cc = coarse.compliance
        diag_rel = np.abs(np.diag(C) - np.diag(Cc)) / np.abs(np.diag(C))
        factor = 2.0**RICHARDSON_ORDER - 1.0
        quality["mesh_convergence"] = {
            "coarse_mesh_size": 2 * h,
            "assumed_order": RICHARDSON_ORDER,
            "rel_change_diag": diag_rel.tolist(),
            "richardson_error_diag": (diag_rel / factor).tolist(),
            "richardson_error_lateral": float(np.max(diag_rel[:2]) / factor),
            "extrapolated": (C + (C - Cc) / factor).tolist(),
        }
    beam = _beam_reference(geometry)
    if beam is not None:
        quality["beam_compliance"] = beam.tolist()
        quality["beam_rel_diff_diag"] = (np.diag(C) / np.diag(beam) - 1.0).tolist()
    return ComplianceResult(
        compliance=0.5 * (C + C.T),
        reference_point=geometry.reference_point,
        frame=geometry.frame,
        method="fe",
        quality=quality,
        geometry=geometry.to_dict(),
    )


def tool_compliance(
    tool: BallEndTool, mesh_size: float | None = None, **kw: Any
) -> ComplianceResult:
    """FE compliance of a ball-end tool at its tip (see :func:`fe_compliance`)."""
    return fe_compliance(tool, mesh_size, **kw)


def holder_compliance(
    holder: ToolHolder, mesh_size: float | None = None, **kw: Any
) -> ComplianceResult:
    """FE compliance of a tool holder at the centre of its nose face."""
    return fe_compliance(holder, mesh_size, **kw)


def tool_holder_compliance(
    tool: ComplianceResult, holder: ComplianceResult, tool_length: float
) -> ComplianceResult:
    """Tool + holder in series about the tool tip (the paper's serial assembly).

    ``tool`` is given in the tool frame (origin at the tip), ``holder`` in the holder frame (origin
    at the nose centre, ``tool_length`` [m] above the tip, same axes); each about its reference
    point. ``k = J_t k_t J_tᵀ + J_th k_th J_thᵀ`` with ``v = tip − reference point`` — for the
    usual references (tip; nose centre) ``k_t + J k_th Jᵀ``, ``v_th = (0, 0, −L)``.
    """
    if not (math.isfinite(tool_length) and tool_length > 0):
        raise InputError(
            f"tool length must be positive (m), got {tool_length!r}", field="tool_length"
        )
    # holder frame: origin at the nose centre, which is (0, 0, L) in the tool frame, same axes
    v = -(np.array([0.0, 0.0, tool_length]) + holder.reference_point)
    k = serial_assembly([(tool.compliance, -tool.reference_point), (holder.compliance, v)])
    return ComplianceResult(
        compliance=k,
        reference_point=np.zeros(3),
        frame=tool.frame,
        method="assembly",
        quality={"tool": tool.quality, "holder": holder.quality},
        geometry={
            "type": "tool_plus_holder",
            "tool": tool.geometry,
            "holder": holder.geometry,
            "tool_length": tool_length,
        },
    )


def beam_result(geometry: BallEndTool | ToolHolder, *, shear: bool = True) -> ComplianceResult:
    """The analytical (Timoshenko, or Euler–Bernoulli with ``shear=False``) compliance as a result.

    A tool: at its tip, ball rigid. A holder: at the centre of its nose face.
    """
    if not isinstance(geometry, BallEndTool | ToolHolder):
        raise InputError("the beam model needs a ball-end tool or a stepped holder", field="method")
    k = beam_compliance(geometry.segments(), geometry.material, shear=shear)
    return ComplianceResult(
        compliance=k,
        reference_point=geometry.reference_point,
        frame=geometry.frame,
        method="beam",
        quality={"model": "timoshenko" if shear else "euler-bernoulli"},
        geometry=geometry.to_dict(),
    )
