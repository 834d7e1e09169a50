"""Tool and tool-holder stiffness: FE virtual experiments and a beam model (docs: ``docs/fem.md``).

Six unit load cases (Fx, Fy, Fz, Mx, My, Mz) about a reference point are applied as a consistent
traction over a named coupling face of a gmsh-meshed body (curved P2 tetrahedra), the rigid motion
of that face is fitted, and the six ``[p; φ]`` columns form the 6×6 compliance (SI).

The names below load their module on first use (PEP 562): reading a compliance JSON or using the
beam model does not import scipy.sparse, scikit-fem or gmsh.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roboisf._lazy import attach

if TYPE_CHECKING:
    from roboisf.fem.assembly import assemble_stiffness, assemble_stiffness_skfem
    from roboisf.fem.beam import beam_compliance, cowper_shear_coefficient, holder_beam, tool_beam
    from roboisf.fem.coupling import SurfaceCoupling, kabsch_fit
    from roboisf.fem.geometry import (
        PAPER_TOOL_LENGTH,
        BallEndTool,
        HolderSection,
        ShaftSegment,
        StepGeometry,
        ToolHolder,
        ToolInHolder,
        step_faces,
    )
    from roboisf.fem.material import STEEL, Material
    from roboisf.fem.mesh import TetMesh, mesh_geometry
    from roboisf.fem.result import (
        LOAD_CASES,
        ComplianceResult,
        load_compliance_json,
        save_compliance_json,
    )
    from roboisf.fem.stiffness import (
        FESolution,
        beam_result,
        default_mesh_size,
        fe_compliance,
        holder_compliance,
        solve_six_cases,
        tool_compliance,
        tool_holder_compliance,
    )

_WHERE = {
    "assembly": (
        "assemble_stiffness",
        "assemble_stiffness_skfem",
    ),
    "beam": (
        "beam_compliance",
        "cowper_shear_coefficient",
        "holder_beam",
        "tool_beam",
    ),
    "coupling": (
        "SurfaceCoupling",
        "kabsch_fit",
    ),
    "geometry": (
        "PAPER_TOOL_LENGTH",
        "BallEndTool",
        "HolderSection",
        "ShaftSegment",
        "StepGeometry",
        "ToolHolder",
        "ToolInHolder",
        "step_faces",
    ),
    "material": (
        "STEEL",
        "Material",
    ),
    "mesh": (
        "TetMesh",
        "mesh_geometry",
    ),
    "result": (
        "LOAD_CASES",
        "ComplianceResult",
        "load_compliance_json",
        "save_compliance_json",
    ),
    "stiffness": (
        "FESolution",
        "beam_result",
        "default_mesh_size",
        "fe_compliance",
        "holder_compliance",
        "solve_six_cases",
        "tool_compliance",
        "tool_holder_compliance",
    ),
}
__all__ = [
    "LOAD_CASES",
    "PAPER_TOOL_LENGTH",
    "STEEL",
    "BallEndTool",
    "ComplianceResult",
    "FESolution",
    "HolderSection",
    "Material",
    "ShaftSegment",
    "StepGeometry",
    "SurfaceCoupling",
    "TetMesh",
    "ToolHolder",
    "ToolInHolder",
    "assemble_stiffness",
    "assemble_stiffness_skfem",
    "beam_compliance",
    "beam_result",
    "cowper_shear_coefficient",
    "default_mesh_size",
    "fe_compliance",
    "holder_beam",
    "holder_compliance",
    "kabsch_fit",
    "load_compliance_json",
    "mesh_geometry",
    "save_compliance_json",
    "solve_six_cases",
    "step_faces",
    "tool_beam",
    "tool_compliance",
    "tool_holder_compliance",
]
__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)
