"""Nominal part geometry: cone, VWACF, profile, pyramid and mesh parts; exact surface queries;
part TOML files.

The names below load their module on first use (PEP 562), so that ``roboisf --help`` and the
paper's default dimensions (:mod:`roboisf.parts.defaults`) do not import numpy and scipy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roboisf._lazy import attach

if TYPE_CHECKING:
    from roboisf.parts.axisymmetric import (
        VWACF,
        AxisymmetricPart,
        Cone,
        ProfilePart,
        SurfaceQuery,
        sine_law_thickness,
    )
    from roboisf.parts.base import Part, Symmetry
    from roboisf.parts.defaults import PAPER_SHEET_THICKNESS
    from roboisf.parts.generatrix import Arc, Generatrix, Segment
    from roboisf.parts.io import load_part, part_from_dict, read_profile_csv, save_part
    from roboisf.parts.mesh import MeshPart, tessellate
    from roboisf.parts.pyramid import Pyramid

_WHERE = {
    "axisymmetric": (
        "VWACF",
        "AxisymmetricPart",
        "Cone",
        "ProfilePart",
        "SurfaceQuery",
        "sine_law_thickness",
    ),
    "base": ("Part", "Symmetry"),
    "defaults": ("PAPER_SHEET_THICKNESS",),
    "generatrix": ("Arc", "Generatrix", "Segment"),
    "io": ("load_part", "part_from_dict", "read_profile_csv", "save_part"),
    "mesh": ("MeshPart", "tessellate"),
    "pyramid": ("Pyramid",),
}
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
__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)
