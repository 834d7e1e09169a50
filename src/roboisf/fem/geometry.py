"""Geometries the FE stiffness model meshes: ball-end tool, stepped/tapered holder, a STEP file.

Every geometry lives in its own frame, z along the tool/spindle axis pointing **up** (towards the
spindle), and knows three things: how to build itself in gmsh's OpenCASCADE kernel, which faces
are *clamped* (all displacements zero) and which face is the *coupling* face that carries the six
unit load cases and on which the rigid motion is fitted, and the *reference point* about which
the compliance is given.

* :class:`BallEndTool` — origin at the tool tip (the lowest point of the ball), ball centre at
  ``z = R``, clamped face at ``z = length``. Coupling face: the ball's spherical surface.
* :class:`ToolHolder` — origin at the centre of the nose face (``z = 0``), sections stacked
  upward, clamped at the top face. Coupling face: the nose face, or the tool's footprint on it
  (``coupling_diameter``). Reference point: the nose centre.
* :class:`ToolInHolder` — the tool glued onto the holder's nose (one FE model of both), origin at
  the tip; the check of the serial assembly ``k_t + J k_th Jᵀ``.
* :class:`StepGeometry` — any solid from a STEP file; the user names the clamped and coupling
  faces (labels carried by the file, or face numbers as listed by :func:`step_faces`).

All lengths are SI (m) in these objects; gmsh is driven in mm internally (its tolerances are
absolute) and node coordinates come back in m.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from roboisf.errors import InputError
from roboisf.fem.material import STEEL, Material

__all__ = [
    "PAPER_TOOL_LENGTH",
    "BallEndTool",
    "Built",
    "Geometry",
    "HolderSection",
    "ShaftSegment",
    "StepGeometry",
    "ToolHolder",
    "ToolInHolder",
    "import_step",
    "step_faces",
]

_MM = 1e3  # m → mm for gmsh

#: Free length [m] of a Ø10 mm steel ball-end tool whose FE lateral compliance is the paper's
#: 9.34e-7 m/N (Bharti et al. 2024, Table 2): 9.316e-7 at 66 mm with mesh R/3, ~0.1 % below
#: converged; 60 mm gives 7.01e-7 m/N.
PAPER_TOOL_LENGTH = 66e-3
_TOL = 1e-6  # mm, bounding-box tolerance when classifying CAD faces built here


def _positive(value: float, name: str) -> float:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise InputError(f"must be a positive length in m, got {value!r}", field=name)
    return float(value)


@dataclass(frozen=True)
class ShaftSegment:
    """One axisymmetric piece of a shaft along z (for the beam model and the gmsh build).

    z0, z1 : float, m — ends along the axis (z0 < z1)
    outer0, outer1 : float, m — outer diameter at z0 and z1 (a cone when they differ)
    inner : float, m — bore diameter (0 = solid)
    """

    z0: float
    z1: float
    outer0: float
    outer1: float
    inner: float = 0.0


@dataclass(frozen=True)
class Built:
    """What a geometry build leaves in gmsh: surface tags of each role and body of each volume."""

    clamped: list[int]
    coupling: list[int]
    volumes: dict[int, int]  # gmsh volume tag → body index


class Geometry(Protocol):
    """What :func:`roboisf.fem.mesh.mesh_geometry` needs from a geometry."""

    @property
    def reference_point(self) -> np.ndarray: ...

    @property
    def materials(self) -> tuple[Material, ...]: ...

    @property
    def frame(self) -> str: ...

    @property
    def characteristic_size(self) -> float: ...

    def build(self, occ: Any, model: Any) -> Built: ...

    def to_dict(self) -> dict[str, Any]: ...


def _planar_faces_at(model: Any, tags: Sequence[int], z: float) -> list[int]:
    """Plane faces among ``tags`` whose bounding box lies in the plane ``z`` (mm)."""
    out = []
    for t in tags:
        if model.getType(2, t) != "Plane":
            continue
        bb = model.getBoundingBox(2, t)
        if abs(bb[2] - z) < 1e-4 and abs(bb[5] - z) < 1e-4:
            out.append(t)
    return out


def _boundary_faces(model: Any, volumes: Sequence[int]) -> list[int]:
    faces = model.getBoundary([(3, v) for v in volumes], combined=True, oriented=False)
    return sorted({abs(t) for d, t in faces if d == 2})


def _build_shaft(occ: Any, segments: Sequence[ShaftSegment]) -> list[tuple[int, int]]:
    """OCC solids (mm) of the segments, outer cones minus bores, not yet fused."""
    solids: list[tuple[int, int]] = []
    for s in segments:
        z0, h = s.z0 * _MM, (s.z1 - s.z0) * _MM
        r0, r1 = 0.5 * s.outer0 * _MM, 0.5 * s.outer1 * _MM
        if abs(r0 - r1) < 1e-9:
            vol = occ.addCylinder(0, 0, z0, 0, 0, h, r0)
        else:
            vol = occ.addCone(0, 0, z0, 0, 0, h, r0, r1)
        if s.inner > 0:
            bore = occ.addCylinder(0, 0, z0, 0, 0, h, 0.5 * s.inner * _MM)
            out, _ = occ.cut([(3, vol)], [(3, bore)])
            solids.extend(out)
        else:
            solids.append((3, vol))
    return solids


class _OneBodyAtOrigin:
    """One body whose reference point is its frame origin."""

    material: Material

    @property
    def reference_point(self) -> np.ndarray:
        return np.zeros(3)

    @property
    def materials(self) -> tuple[Material, ...]:
        return (self.material,)


@dataclass(frozen=True)
class BallEndTool(_OneBodyAtOrigin):
    """A ball-end forming tool, clamped at ``length`` above its tip.

    Attributes
    ----------
    ball_diameter : float, m
    length : float, m — free length from the clamped face (holder nose) to the tip
    shank_diameter : float or None, m — default: the ball diameter
    neck_diameter : float or None, m — optional reduced neck right above the ball
    neck_length : float, m — neck length measured up from the ball centre
    taper_length : float, m — conical transition from the neck to the shank
    material : Material
    """

    ball_diameter: float
    length: float
    shank_diameter: float | None = None
    neck_diameter: float | None = None
    neck_length: float = 0.0
    taper_length: float = 0.0
    material: Material = STEEL

    def __post_init__(self) -> None:
        d = _positive(self.ball_diameter, "ball_diameter")
        L = _positive(self.length, "length")
        if self.shank_diameter is not None:
            _positive(self.shank_diameter, "shank_diameter")
        R = 0.5 * d
        if L <= R * (1 + 1e-9):
            raise InputError(
                f"free length {L * 1e3:g} mm must exceed the ball radius {R * 1e3:g} mm "
                "(it runs from the clamped face to the tip of the ball)",
                field="length",
            )
        if self.neck_diameter is not None:
            _positive(self.neck_diameter, "neck_diameter")
            _positive(self.neck_length, "neck_length")
            if self.neck_diameter > d:
                raise InputError(
                    f"neck diameter {self.neck_diameter * 1e3:g} mm must not exceed the ball "
                    f"diameter {d * 1e3:g} mm",
                    field="neck_diameter",
                )
        elif self.neck_length or self.taper_length:
            raise InputError("neck_length/taper_length need a neck_diameter", field="neck_diameter")
        if self.taper_length < 0 or self.neck_length < 0:
            raise InputError("neck and taper lengths must be ≥ 0", field="taper_length")
        if R + self.neck_length + self.taper_length >= L:
            raise InputError(
                "ball radius + neck + taper must be shorter than the free length "
                f"({(R + self.neck_length + self.taper_length) * 1e3:g} mm ≥ {L * 1e3:g} mm)",
                field="neck_length",
            )
        first = self.neck_diameter if self.neck_diameter is not None else self.shank
        if first > d * (1 + 1e-12):
            raise InputError(
                f"shank diameter {first * 1e3:g} mm exceeds the ball diameter {d * 1e3:g} mm; "
                "give a neck_diameter ≤ the ball diameter to join them",
                field="shank_diameter",
            )

    @property
    def shank(self) -> float:
        return float(self.shank_diameter if self.shank_diameter is not None else self.ball_diameter)

    @property
    def radius(self) -> float:
        return 0.5 * self.ball_diameter

    @property
    def frame(self) -> str:
        return "tool: origin at the tip (lowest point of the ball), z along the tool axis up"

    @property
    def characteristic_size(self) -> float:
        return self.radius

    def segments(self, z_offset: float = 0.0) -> list[ShaftSegment]:
        """Shaft above the ball centre (the ball itself is not a beam), in this tool's frame."""
        R, L = self.radius, self.length
        segs = []
        z = R
        if self.neck_diameter is not None:
            segs.append(
                ShaftSegment(z, z + self.neck_length, self.neck_diameter, self.neck_diameter)
            )
            z += self.neck_length
            if self.taper_length > 0:
                segs.append(ShaftSegment(z, z + self.taper_length, self.neck_diameter, self.shank))
                z += self.taper_length
        segs.append(ShaftSegment(z, L, self.shank, self.shank))
        return [
            ShaftSegment(s.z0 + z_offset, s.z1 + z_offset, s.outer0, s.outer1, s.inner)
            for s in segs
        ]

    def _solids(self, occ: Any, z_offset: float = 0.0) -> list[tuple[int, int]]:
        R = self.radius * _MM
        ball = occ.addSphere(0, 0, R + z_offset * _MM, R)
        return [(3, ball), *_build_shaft(occ, self.segments(z_offset))]

    def build(self, occ: Any, model: Any) -> Built:
        solids = self._solids(occ)
        out, _ = occ.fuse(solids[:1], solids[1:])
        occ.synchronize()
        vols = [t for d, t in out if d == 3]
        faces = _boundary_faces(model, vols)
        coupling = [t for t in faces if model.getType(2, t) == "Sphere"]
        clamped = _planar_faces_at(model, faces, self.length * _MM)
        return Built(clamped, coupling, dict.fromkeys(vols, 0))

    def to_dict(self) -> dict[str, Any]:
        return {
            "type": "ball_end_tool",
            "ball_diameter": self.ball_diameter,
            "length": self.length,
            "shank_diameter": self.shank,
            "neck_diameter": self.neck_diameter,
            "neck_length": self.neck_length,
            "taper_length": self.taper_length,
            "material": self.material.to_dict(),
            "units": "m",
        }


@dataclass(frozen=True)
class HolderSection:
    """One section of a tool holder, listed from the nose upward.

    length : float, m
    outer_diameter : float, m — at the lower (nose-side) end
    inner_diameter : float, m — bore (0 = solid)
    outer_diameter_end : float or None, m — at the upper end (a taper); default = outer_diameter
    """

    length: float
    outer_diameter: float
    inner_diameter: float = 0.0
    outer_diameter_end: float | None = None

    def __post_init__(self) -> None:
        _positive(self.length, "length")
        _positive(self.outer_diameter, "outer_diameter")
        if self.outer_diameter_end is not None:
            _positive(self.outer_diameter_end, "outer_diameter_end")
        if not (math.isfinite(self.inner_diameter) and self.inner_diameter >= 0):
            raise InputError(f"must be ≥ 0 m, got {self.inner_diameter!r}", field="inner_diameter")
        if self.inner_diameter >= min(self.outer_diameter, self.outer_end) * (1 - 1e-9):
            raise InputError(
                f"bore {self.inner_diameter * 1e3:g} mm must be smaller than the outer diameter "
                f"{min(self.outer_diameter, self.outer_end) * 1e3:g} mm",
                field="inner_diameter",
            )

    @property
    def outer_end(self) -> float:
        return float(
            self.outer_diameter if self.outer_diameter_end is None else self.outer_diameter_end
        )


@dataclass(frozen=True)
class ToolHolder(_OneBodyAtOrigin):
    """A stepped/tapered tool holder: sections from the nose (z = 0) up to the clamped end.

    Attributes
    ----------
    sections : tuple of HolderSection, nose first
    coupling_diameter : float or None, m — if given, the coupling face is the disc (or the annulus
        around the bore) of this diameter on the nose face: the footprint through which the tool
        loads the holder. Default: the whole nose face.
    material : Material
    """

    sections: tuple[HolderSection, ...]
    coupling_diameter: float | None = None
    material: Material = STEEL

    def __post_init__(self) -> None:
        object.__setattr__(self, "sections", tuple(self.sections))
        if not self.sections:
            raise InputError("a tool holder needs at least one section", field="sections")
        for i, (a, b) in enumerate(zip(self.sections[:-1], self.sections[1:], strict=True)):
            # the annulus at the top of a and at the bottom of b must overlap with some area
            lo = max(a.inner_diameter, b.inner_diameter)
            hi = min(a.outer_end, b.outer_diameter)
            if hi <= lo * (1 + 1e-9):
                raise InputError(
                    f"sections {i + 1} and {i + 2} do not meet: section {i + 1} ends with Ø "
                    f"{a.inner_diameter * 1e3:g}–{a.outer_end * 1e3:g} mm, section {i + 2} starts "
                    f"with Ø {b.inner_diameter * 1e3:g}–{b.outer_diameter * 1e3:g} mm",
                    field="sections",
                )
        if self.coupling_diameter is not None:
            _positive(self.coupling_diameter, "coupling_diameter")
            nose = self.sections[0]
            if (
                not nose.inner_diameter
                < self.coupling_diameter
                <= nose.outer_diameter * (1 + 1e-12)
            ):
                raise InputError(
                    f"coupling diameter {self.coupling_diameter * 1e3:g} mm must lie between the "
                    f"nose bore {nose.inner_diameter * 1e3:g} mm and the nose outer diameter "
                    f"{nose.outer_diameter * 1e3:g} mm",
                    field="coupling_diameter",
                )

    @property
    def height(self) -> float:
        return float(sum(s.length for s in self.sections))

    @property
    def frame(self) -> str:
        return "holder: origin at the centre of the nose face, z along the spindle axis up"

    @property
    def characteristic_size(self) -> float:
        return 0.5 * min(
            min(s.outer_diameter, s.outer_end) - s.inner_diameter for s in self.sections
        )

    def segments(self, z_offset: float = 0.0) -> list[ShaftSegment]:
        segs, z = [], z_offset
        for s in self.sections:
            segs.append(
                ShaftSegment(z, z + s.length, s.outer_diameter, s.outer_end, s.inner_diameter)
            )
            z += s.length
        return segs

    def _nose_split(self, occ: Any, z_mm: float) -> list[tuple[int, int]]:
        if (
            self.coupling_diameter is None
            or self.coupling_diameter >= self.sections[0].outer_diameter
        ):
            return []
        return [
            (
                2,
                occ.addDisk(
                    0,
                    0,
                    z_mm,
                    0.5 * self.coupling_diameter * _MM,
                    0.5 * self.coupling_diameter * _MM,
                ),
            )
        ]

    def _coupling_faces(self, model: Any, faces: Sequence[int], z_mm: float) -> list[int]:
        nose = _planar_faces_at(model, faces, z_mm)
        if self.coupling_diameter is None:
            return nose
        rc = 0.5 * self.coupling_diameter * _MM
        keep = []
        for t in nose:
            bb = model.getBoundingBox(2, t)
            if max(abs(bb[0]), abs(bb[1]), abs(bb[3]), abs(bb[4])) <= rc + 1e-4:
                keep.append(t)
        return keep

    def build(self, occ: Any, model: Any) -> Built:
        solids = _build_shaft(occ, self.segments())
        if len(solids) > 1:
            solids, _ = occ.fuse(solids[:1], solids[1:])
        split = self._nose_split(occ, 0.0)
        if split:
            solids, _ = occ.fragment(solids, split)
        occ.synchronize()
        vols = [t for d, t in solids if d == 3]
        faces = _boundary_faces(model, vols)
        clamped = _planar_faces_at(model, faces, self.height * _MM)
        coupling = self._coupling_faces(model, faces, 0.0)
        return Built(clamped, coupling, dict.fromkeys(vols, 0))

    def to_dict(self) -> dict[str, Any]:
        return {
            "type": "tool_holder",
            "sections": [
                {
                    "length": s.length,
                    "outer_diameter": s.outer_diameter,
                    "inner_diameter": s.inner_diameter,
                    "outer_diameter_end": s.outer_end,
                }
                for s in self.sections
            ],
            "coupling_diameter": self.coupling_diameter,
            "material": self.material.to_dict(),
            "units": "m",
        }


@dataclass(frozen=True)
class ToolInHolder:
    """One FE body of a tool glued onto the nose face of a holder (perfect bond).

    Frame: origin at the tool tip, z up; the holder nose is at ``z = tool.length`` and the clamped
    face at ``z = tool.length + holder.height``. Coupling face: the ball. Bodies: 0 tool, 1 holder.
    """

    tool: BallEndTool
    holder: ToolHolder

    def __post_init__(self) -> None:
        nose = self.holder.sections[0]
        if nose.inner_diameter > 0:
            raise InputError(
                "ToolInHolder glues the tool onto a solid nose face; the first holder section "
                "must have inner_diameter 0",
                field="sections",
            )
        if self.tool.shank > nose.outer_diameter:
            raise InputError("the tool shank is wider than the holder nose", field="shank_diameter")

    @property
    def reference_point(self) -> np.ndarray:
        return np.zeros(3)

    @property
    def materials(self) -> tuple[Material, ...]:
        return (self.tool.material, self.holder.material)

    @property
    def frame(self) -> str:
        return self.tool.frame

    @property
    def characteristic_size(self) -> float:
        return self.tool.radius

    def build(self, occ: Any, model: Any) -> Built:
        L = self.tool.length
        tool = self.tool._solids(occ)
        tool_out, _ = occ.fuse(tool[:1], tool[1:])
        holder = _build_shaft(occ, self.holder.segments(z_offset=L))
        if len(holder) > 1:
            holder, _ = occ.fuse(holder[:1], holder[1:])
        _, out_map = occ.fragment(tool_out, holder)
        occ.synchronize()
        n_tool = len(tool_out)
        volumes: dict[int, int] = {}
        for i, children in enumerate(out_map):
            for d, t in children:
                if d == 3:
                    volumes.setdefault(t, 0 if i < n_tool else 1)
        vols = list(volumes)
        faces = _boundary_faces(model, vols)
        coupling = [t for t in faces if model.getType(2, t) == "Sphere"]
        clamped = _planar_faces_at(model, faces, (L + self.holder.height) * _MM)
        return Built(clamped, coupling, volumes)

    def to_dict(self) -> dict[str, Any]:
        return {
            "type": "tool_in_holder",
            "tool": self.tool.to_dict(),
            "holder": self.holder.to_dict(),
        }


def step_faces(path: str | Path) -> list[dict[str, Any]]:
    """The faces of a STEP file as gmsh numbers them: ``[{"face", "name", "type", "bbox_mm"}]``.

    Use these numbers (or the names, when the file carries face labels) for
    :class:`StepGeometry`'s ``clamped``/``coupling``.
    """
    from roboisf.fem.mesh import gmsh_session

    with gmsh_session() as (gmsh, _):
        import_step(gmsh, Path(path))
        return _face_table(gmsh.model)


def import_step(gmsh: Any, path: Path, *, require_solid: bool = True) -> list[tuple[int, int]]:
    """Import a STEP (or IGES) file into the current gmsh model, in mm; ``require_solid=False``
    accepts surfaces and shells (a part's nominal surface, :mod:`roboisf.parts.cad`)."""
    if not path.is_file():
        raise InputError("STEP file not found", file=path)
    gmsh.option.setString("Geometry.OCCTargetUnit", "MM")
    try:
        out = gmsh.model.occ.importShapes(str(path))
    except Exception as e:  # gmsh raises a bare Exception with its log line
        raise InputError(f"could not read the STEP file: {e}", file=path) from None
    gmsh.model.occ.synchronize()
    if require_solid and not any(d == 3 for d, _ in out):
        raise InputError("the STEP file holds no solid body", file=path)
    return out


def _face_table(model: Any) -> list[dict[str, Any]]:
    return [
        {
            "face": t,
            "name": model.getEntityName(2, t),
            "type": model.getType(2, t),
            "bbox_mm": [round(v, 4) for v in model.getBoundingBox(2, t)],
        }
        for _, t in model.getEntities(2)
    ]


def _select_faces(model: Any, wanted: Sequence[int | str], role: str, path: Path) -> list[int]:
    table = _face_table(model)
    tags = {row["face"] for row in table}
    chosen: list[int] = []
    for w in wanted:
        if isinstance(w, int) or (isinstance(w, str) and w.isdigit()):
            if int(w) not in tags:
                raise InputError(f"the STEP file has no face number {w}", file=path, field=role)
            chosen.append(int(w))
            continue
        hits = [
            row["face"]
            for row in table
            if row["name"] and (row["name"] == w or row["name"].rsplit("/", 1)[-1] == w)
        ]
        for dim, group in model.getPhysicalGroups(2):
            if model.getPhysicalName(dim, group) == w:
                hits.extend(int(t) for t in model.getEntitiesForPhysicalGroup(dim, group))
        if not hits:
            listing = "; ".join(
                f"{row['face']}: {row['type']}{(' ' + repr(row['name'])) if row['name'] else ''} "
                f"bbox {row['bbox_mm']}"
                for row in table[:40]
            )
            raise InputError(
                f"no face named {w!r} in the STEP file; name the {role} faces by a label the file "
                f"carries or by face number. Faces (number: type bbox mm): {listing}",
                file=path,
                field=role,
            )
        chosen.extend(hits)
    return sorted(set(chosen))


@dataclass(frozen=True)
class StepGeometry:
    """A solid from a STEP file with user-named clamped and coupling faces.

    Attributes
    ----------
    path : Path — the STEP file (read in mm whatever its declared unit; OCC converts)
    clamped, coupling : tuple of int or str — face numbers (see :func:`step_faces`) or labels
    reference_point : (3,) float, m — where the compliance is given, in the file's frame
    material : Material
    """

    path: Path
    clamped: tuple[int | str, ...]
    coupling: tuple[int | str, ...]
    reference_point: np.ndarray = field(default_factory=lambda: np.zeros(3))
    material: Material = STEEL

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", Path(self.path))
        for role in ("clamped", "coupling"):
            v = getattr(self, role)
            v = (v,) if isinstance(v, int | str) else tuple(v)
            if not v:
                raise InputError(f"name at least one {role} face", field=role)
            object.__setattr__(self, role, v)
        p = np.asarray(self.reference_point, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise InputError(
                "reference_point must be 3 finite numbers (m)", field="reference_point"
            )
        object.__setattr__(self, "reference_point", p)

    @property
    def materials(self) -> tuple[Material, ...]:
        return (self.material,)

    @property
    def frame(self) -> str:
        return f"STEP file frame of {self.path.name}"

    @property
    def characteristic_size(self) -> float:
        return float("nan")  # decided from the bounding box at build time

    def build(self, occ: Any, model: Any) -> Built:
        import gmsh

        out = import_step(gmsh, self.path)
        vols = [t for d, t in out if d == 3]
        clamped = _select_faces(model, self.clamped, "clamped", self.path)
        coupling = _select_faces(model, self.coupling, "coupling", self.path)
        if set(clamped) & set(coupling):
            raise InputError(
                "a face cannot be both clamped and coupling", file=self.path, field="coupling"
            )
        return Built(clamped, coupling, dict.fromkeys(vols, 0))

    def to_dict(self) -> dict[str, Any]:
        return {
            "type": "step",
            "path": str(self.path),
            "clamped": list(self.clamped),
            "coupling": list(self.coupling),
            "reference_point": self.reference_point.tolist(),
            "material": self.material.to_dict(),
            "units": "m",
        }
