"""Nominal part geometry: cone, VWACF, profile, pyramid and mesh parts; exact surface queries;
part TOML files."""

from roboisf.parts.axisymmetric import (
    PAPER_SHEET_THICKNESS,
    VWACF,
    AxisymmetricPart,
    Cone,
    ProfilePart,
    SurfaceQuery,
    sine_law_thickness,
)
from roboisf.parts.base import Part, Symmetry
from roboisf.parts.generatrix import Arc, Generatrix, Segment
from roboisf.parts.io import load_part, part_from_dict, read_profile_csv, save_part
from roboisf.parts.mesh import MeshPart, tessellate
from roboisf.parts.pyramid import Pyramid

__all__ = [
    "PAPER_SHEET_THICKNESS",
    "VWACF",
    "Arc",
    "AxisymmetricPart",
    "Cone",
    "Generatrix",
    "MeshPart",
    "Part",
    "ProfilePart",
    "Pyramid",
    "Segment",
    "SurfaceQuery",
    "Symmetry",
    "load_part",
    "part_from_dict",
    "read_profile_csv",
    "save_part",
    "sine_law_thickness",
    "tessellate",
]
