"""Triangle-mesh nominal surface (STL/OBJ) with exact, fast closest-point queries.

For parts that are not surfaces of revolution. The query has the same shape as the analytic
parts' :meth:`~roboisf.parts.AxisymmetricPart.closest_point` (a :class:`SurfaceQuery`), so the
scan code does not care which kind of nominal it compares against.

Two exact closest-point engines (``MeshPart(..., backend=...)``):

- ``"numba"`` (the default; numba's kernels are built at install): a
  compiled uniform-grid search seeded by the previous point, see :mod:`roboisf.parts.mesh_kernel`;
  2–2.7× less CPU than Open3D's ``RaycastingScene`` on 3 M points, 1.4–3× faster in wall time
  on a contended machine (docs/scan.md);
- ``"numpy"`` (the fallback, always available), described below; ~1.9× slower than Open3D.

They compute the point–triangle distance with the same arithmetic (:func:`point_triangle_distance2`
and its scalar twin), so the distances agree to the last bit wherever they pick the same face.

The numpy closest point algorithm (exact, not approximate):

1. a k-d tree (``scipy.spatial.cKDTree``) over the triangle centroids ``c_j``; every triangle
   lies inside the ball of radius ``ρ_j = max |v − c_j|`` (over its vertices) around its centroid;
2. for each query point x, the ``k`` nearest centroids (k = 24) are candidates; a candidate is
   evaluated exactly (Ericson, *Real-Time Collision Detection* §5.1.5, vectorised) only if its
   lower bound ``sqrt(h² + max(0, q − ρ_j)²)`` — h the distance to the triangle's plane, q the
   in-plane distance to its centroid — is below the best distance found so far;
3. every triangle that is not a candidate is at least ``d_k − ρ_max`` away (``d_k`` = k-th
   centroid distance). Where the best distance is larger than that bound the answer is not
   proven; those points are queried again with 2× more candidates, until proven (or all
   triangles were candidates). The result is therefore the true closest triangle.

Scans should be passed in spatial order (:func:`spatial_order`, done by
:func:`roboisf.scan.point_deviations`): the query is then ~1.5× (numpy) to 3× (numba) faster.

Orientation: the tool-side normal of an ISF part (tool along +z, part below the sheet) has
``n_z ≥ 0``. By default (``orient="up"``) faces whose winding normal points down are flipped;
``orient="winding"`` keeps the file's winding (outward normals of a closed solid point away
from the material, which for a sheet's tool-side surface must then be the tool side).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf import jit
from roboisf.errors import InputError
from roboisf.io.units import to_si
from roboisf.parts import mesh_kernel
from roboisf.parts.axisymmetric import PAPER_SHEET_THICKNESS, SurfaceQuery
from roboisf.parts.base import Symmetry

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

__all__ = [
    "MeshPart",
    "check_sheet_mesh",
    "in_spatial_order",
    "point_triangle_distance2",
    "read_mesh",
    "spatial_order",
    "tessellate",
]

F64 = NDArray[np.float64]

#: Points per chunk of the closest-point query (bounds the temporary memory to ~100 MB).
CHUNK = 200_000
#: Points per thread task of the compiled query (large inputs are split over all cores).
NUMBA_CHUNK = 131_072


def spatial_order(points: ArrayLike, bits: int = 16) -> NDArray[np.integer[Any]]:
    """Permutation (N,) that sorts ``points`` (N, 3) along a Morton (Z-order) curve: int32 below
    2³¹ points on the compiled path (int64 on numpy's, the same values).

    Neighbouring queries then touch neighbouring tree nodes and triangles: the mesh query runs
    1.5–3× faster than on a scan in random order. Pure reordering, results are unchanged.
    Stable (points sharing a code keep their input order) on both engines, so the compiled
    and the numpy path (a cold kernel cache, :func:`roboisf.jit.ready`) give the same order.
    """
    X = np.asarray(points, dtype=float)
    if X.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    if jit.ready("mesh") and 3 * bits <= 64 and X.ndim == 2 and X.shape[1] == 3:
        # compiled passes for the bounds and the codes, and a stable radix sort (the same
        # codes; ties keep their input order): ~5x the numpy codes + argsort on 2 M points
        X = np.ascontiguousarray(X)
        lo, hi = mesh_kernel.bounds(X, np.empty(0, np.int64))
        span = float(np.max(hi - lo)) or 1.0
        idx = np.int32 if X.shape[0] < 2**31 else np.int64
        n = X.shape[0]
        return mesh_kernel.morton_order(
            X, lo, (2**bits - 1) / span, bits, np.arange(n, dtype=idx), np.empty(n, dtype=idx),
            np.empty(n, dtype=np.uint64), np.empty(n, dtype=np.uint64),
        )  # fmt: skip
    lo = X.min(axis=0)
    span = float(np.max(X.max(axis=0) - lo)) or 1.0
    q = ((X - lo) * ((2**bits - 1) / span)).astype(np.uint64)
    code = mesh_kernel.part1by2(q[:, 0]) | (mesh_kernel.part1by2(q[:, 1]) << np.uint64(1))
    code |= mesh_kernel.part1by2(q[:, 2]) << np.uint64(2)
    return np.argsort(code, kind="stable")  # ties (a shared 16-bit cell) as the kernel's


def in_spatial_order(points: ArrayLike, bits: int = 16) -> F64:
    """``points`` (N, 3) [m] as a new array in :func:`spatial_order` (the same rows, sorted).

    Compiled: the rows gathered by the int32 permutation itself (``np.take`` first copies it to
    int64); the sort's and the gather's peak beside a 2 M-point scan is 96 MB instead of 112.
    """
    X = np.asarray(points, dtype=float)
    order = spatial_order(X, bits)
    if order.dtype == np.int64 or X.ndim != 2 or X.shape[1] != 3:
        return np.take(X, order, axis=0)
    return mesh_kernel.gather_rows(np.ascontiguousarray(X), np.empty(0, np.int64), order)


def _kdtree(points: F64) -> cKDTree:
    """scipy's ``cKDTree`` over ``points``, scipy.spatial imported on first use (not when a
    study is read: it is ~0.2 s of every command's start-up, docs/speed.md)."""
    from scipy.spatial import cKDTree as KDTree

    return KDTree(points)


def _dot3(u: F64, v: F64) -> F64:
    """``u·v`` over the last axis (3), summed x + y + z in that order (as the compiled kernel)."""
    return u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1] + u[..., 2] * v[..., 2]


def point_triangle_distance2(
    p: F64, a: F64, ab: F64, ac: F64, abab: F64, abac: F64, acac: F64
) -> tuple[F64, F64, F64]:
    """Squared distance from points to triangles, and the barycentric (v, w) of the closest point.

    Broadcasting arrays: ``p, a, ab, ac`` (..., 3) [m] with ``ab = b − a``, ``ac = c − a``;
    ``abab = ab·ab``, ``abac = ab·ac``, ``acac = ac·ac`` (...,). The closest point is
    ``a + v·ab + w·ac``. Exact for every Voronoi region (vertices, edges, face); degenerate
    (zero-area) triangles fall back to their edges. The arithmetic (operation order) is the
    same as the compiled kernel's (:mod:`roboisf.parts.mesh_kernel`), so both give bit-identical
    distances for the same triangle.
    """
    ap = p - a
    d1 = _dot3(ab, ap)
    d2 = _dot3(ac, ap)
    d3 = d1 - abab  # ab·(p − b)
    d4 = d2 - abac  # ac·(p − b)
    d5 = d1 - abac  # ab·(p − c)
    d6 = d2 - acac  # ac·(p − c)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        den = va + vb + vc
        v_in = vb / den
        w_in = vc / den
    in_a = (d1 <= 0) & (d2 <= 0)
    in_b = (d3 >= 0) & (d4 <= d3)
    in_c = (d6 >= 0) & (d5 <= d6)
    # an edge's region only for an edge of non-zero length, the face only for a non-zero area
    # (a triangle with two equal vertices, a mesh file's duplicate vertex, divided 0 by 0)
    on_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0) & (d1 - d3 > 0)
    on_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0) & (d2 - d6 > 0)
    on_bc = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0) & ((d4 - d3) + (d5 - d6) > 0)
    flat = den == 0  # no area and no edge region (rounding): vertex a, an upper bound
    conds = [in_a, in_b, on_ab, in_c, on_ac, on_bc, flat]
    zero = np.zeros_like(d1)
    one = np.ones_like(d1)
    v = np.select(conds, [zero, one, t_ab, zero, zero, 1.0 - t_bc, zero], v_in)
    w = np.select(conds, [zero, zero, zero, one, t_ac, t_bc, zero], w_in)
    # |ap − v ab − w ac|² expanded (no closest point needed for the comparison)
    d2_ = _dot3(ap, ap) - 2.0 * (v * d1 + w * d2) + v * v * abab + 2.0 * v * w * abac + w * w * acac
    return np.maximum(d2_, 0.0), v, w


#: Largest vertex coordinate a mesh file may hold, in its own units (trimesh merges vertices
#: on int64 keys of the coordinates × 1e8).
_MAX_COORD = 9e10


def read_mesh(path: str | Path, *, unit: str = "mm") -> tuple[F64, NDArray[np.int64]]:
    """Read a triangle mesh (STL ascii/binary, OBJ, PLY with faces) with trimesh.

    Returns ``vertices (V, 3) [m]`` (converted from ``unit``) and ``faces (F, 3) int``.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("mesh file not found", file=path)
    scale = to_si(unit, "length", file=path, field="unit")
    if path.stat().st_size == 0:
        raise InputError("file is empty", file=path)
    import trimesh

    try:
        # unprocessed first: merging vertices casts NaN coordinates to integers (a warning and
        # garbage keys inside trimesh); they are checked here, then the mesh is processed
        mesh = trimesh.load(str(path), force="mesh", process=False)
        raw = np.asarray(getattr(mesh, "vertices", np.empty((0, 3))), dtype=np.float64)
        if raw.size and not np.all(np.isfinite(raw)):
            raise InputError("mesh has NaN or inf vertex coordinates", file=path)
        if raw.size and np.abs(raw).max() > _MAX_COORD:
            # trimesh merges vertices on round(v · 1e8) as int64, which overflows beyond this
            raise InputError(
                f"vertex coordinates up to {np.abs(raw).max():.3g} (file units): beyond "
                f"±{_MAX_COORD:.0e}, not a part or scan (a corrupt file?)",
                file=path,
            )
        if raw.size and isinstance(mesh, trimesh.Trimesh):
            mesh.process()
    except InputError:
        raise
    except Exception as e:
        raise InputError(f"not a readable mesh ({type(e).__name__}: {e})", file=path) from None
    V: F64 = np.array(getattr(mesh, "vertices", np.empty((0, 3))), dtype=np.float64)
    F: NDArray[np.int64] = np.array(getattr(mesh, "faces", np.empty((0, 3))), dtype=np.int64)
    if V.shape[0] == 0 or F.ndim != 2 or F.shape[0] == 0:
        raise InputError("mesh has no triangles (empty or truncated file?)", file=path)
    return V * scale, F


def _compiled(backend: str) -> bool:
    """Whether ``backend`` ("auto" or "numba", checked) runs the compiled query in this process:
    "numba" always (with numba installed), "auto" once the kernels are built — their C form
    (:mod:`roboisf.jit.native`), numba needed or not, or numba's cache
    (:func:`roboisf.jit.ready`). The compiled query runs the C form where it is built."""
    if backend == "numba":
        return mesh_kernel.HAVE_NUMBA
    return jit.ready("mesh")


def _check_backend(backend: str) -> str:
    return jit.check_backend(backend, have_numba=mesh_kernel.HAVE_NUMBA)


def check_sheet_mesh(V: F64, F: NDArray[np.int64], orient: str, where: str | Path) -> None:
    """Refuse a mesh file that cannot be a formed sheet's surface, naming what it is instead.

    A formed part is an open 2-manifold surface with the tool above it: a closed mesh is a solid
    (the CAD body, not its tool-side surface); an edge shared by three or more triangles is a fin
    or a doubled surface; with ``orient = "winding"`` normals pointing down put the tool under the
    part. Before, such meshes were accepted and the next toolpath failed with "a Ø10 mm ball does
    not fit". ``V`` (N, 3) m, ``F`` (M, 3) vertex indices.
    """
    V = np.asarray(V, dtype=float)
    F = np.asarray(F, dtype=np.int64)
    if V.ndim != 2 or F.ndim != 2 or F.shape[1] != 3 or not len(F):
        return  # the shape errors are MeshPart's
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    nrm = np.cross(b - a, c - a)
    area2 = np.linalg.norm(nrm, axis=1)
    ok = area2 > 0
    if not ok.any():
        return
    F, nrm, area2 = F[ok], nrm[ok], area2[ok]
    edges = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    many = uniq[count > 2]
    if len(many):
        p = V[many[0]].mean(axis=0) * 1e3
        raise InputError(
            f"{len(many)} edge(s) shared by three or more triangles (a fin, or a surface "
            f"doubled), the first at ({p[0]:.3g}, {p[1]:.3g}, {p[2]:.3g}) mm: a formed sheet's "
            "surface has each edge in at most two triangles; remove the extra faces",
            file=where,
        )
    # a fin: a (near-)vertical triangle hanging on one edge, its other edges open
    _, inverse = np.unique(edges, axis=0, return_inverse=True)
    open_edges = (count[inverse.reshape(-1)] == 1).reshape(3, len(F)).sum(axis=0)
    steep = np.abs(nrm[:, 2]) / area2 < 0.26  # walls steeper than 75°
    fins = np.flatnonzero((open_edges >= 2) & steep)
    if len(fins):
        p = V[F[fins[0]]].mean(axis=0) * 1e3
        raise InputError(
            f"{len(fins)} triangle(s) stand on one edge with the others open (a fin), the first "
            f"at ({p[0]:.3g}, {p[1]:.3g}, {p[2]:.3g}) mm: no sheet forms that; remove them",
            file=where,
        )
    if not np.any(count == 1):
        raise InputError(
            f"the mesh is closed ({len(F)} triangles, no open edge): a solid body, not the "
            "sheet's surface; export only the tool-side (inner, upper) surface of the part",
            file=where,
        )
    if orient == "winding":
        down = float(np.sum(nrm[:, 2])) / float(np.sum(area2))
        if down < 0:
            raise InputError(
                f"with orient = 'winding' the faces' normals point down (area-weighted mean "
                f"n_z = {down:.2f}): the tool side would be under the part; flip the faces, or "
                "use orient = 'up' (the default)",
                file=where,
            )


@dataclass(frozen=True)
class MeshPart:
    """A nominal surface given as a triangle mesh (work frame, m).

    Parameters
    ----------
    vertices : (V, 3) float, m
    faces : (F, 3) int — vertex indices
    orient : ``"up"`` (default: flip faces so that n_z ≥ 0, the tool side of a part formed
        with the tool along +z) or ``"winding"`` (keep the file's winding)
    sheet_thickness : float, m
    source : the file it came from (for the TOML round trip), or None
    backend : closest-point engine: ``"auto"`` (default: ``"numba"`` when numba is
        installed, else ``"numpy"``), ``"numba"`` (compiled uniform-grid search,
        :mod:`roboisf.parts.mesh_kernel`, 1.4–3× faster than Open3D on the benchmark) or
        ``"numpy"`` (k-d tree over the centroids, see the module doc).
        Both are exact and compute the point–triangle distance with the same arithmetic; at
        exact ties (a point equally far from two triangles) they may name different faces.
        Not saved by :meth:`to_dict` (a choice of the run, not of the part).
    tolerance : float or None, m — for a part tessellated from a STEP/IGES file
        (:meth:`from_file`), the chordal tolerance it was tessellated to (saved by
        :meth:`to_dict`, so the TOML reproduces the mesh); None for a mesh file
    unit : the length unit of ``source``'s coordinates (recorded for :meth:`to_dict`; the
        vertices are always m)

    ``closest_point`` fills :class:`SurfaceQuery` as follows: ``normal`` is the tool-side face
    normal of the closest triangle, ``distance`` is signed with it (+ on the tool side),
    ``wall_angle = arccos n_z``, ``depth = −z`` of the closest point, ``s`` (arc length along a
    generatrix) does not exist for a mesh and is ``NaN``, ``region`` is 1 (wall) except for
    faces within 1° of horizontal: 0 (flange) at the sheet plane (|z| ≤ 0.1 mm), 2 (bottom)
    below it.
    """

    kind: ClassVar[str] = "mesh"
    vertices: F64
    faces: NDArray[np.int64]
    orient: str = "up"
    sheet_thickness: float = PAPER_SHEET_THICKNESS
    source: str | None = None
    backend: str = "auto"
    tolerance: float | None = None
    unit: str = "mm"
    _index: dict[str, Any] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        V = np.ascontiguousarray(np.asarray(self.vertices, dtype=float))
        Fc = np.ascontiguousarray(np.asarray(self.faces, dtype=np.int64))
        where = self.source
        if V.ndim != 2 or V.shape[1] != 3 or V.shape[0] < 3:
            raise InputError(f"mesh vertices must be (V ≥ 3, 3), got {V.shape}", file=where)
        if Fc.ndim != 2 or Fc.shape[1] != 3 or Fc.shape[0] < 1:
            raise InputError(f"mesh faces must be (F ≥ 1, 3) triangles, got {Fc.shape}", file=where)
        if not np.all(np.isfinite(V)):
            raise InputError("mesh has NaN or inf vertex coordinates", file=where)
        if Fc.min() < 0 or Fc.max() >= V.shape[0]:
            raise InputError("mesh face refers to a vertex that does not exist", file=where)
        if self.orient not in ("up", "winding"):
            raise InputError(
                f"orient must be 'up' or 'winding', got {self.orient!r}", field="orient"
            )
        if not (self.sheet_thickness > 0 and math.isfinite(self.sheet_thickness)):
            raise InputError("must be > 0 mm", field="sheet_thickness")
        _check_backend(self.backend)
        a, b, c = V[Fc[:, 0]], V[Fc[:, 1]], V[Fc[:, 2]]
        nrm = np.cross(b - a, c - a)
        area2 = np.linalg.norm(nrm, axis=1)
        if not np.any(area2 > 0):
            raise InputError("mesh has no triangle with a non-zero area", file=where)
        if self.orient == "up":
            flip = nrm[:, 2] < 0
            Fc = Fc.copy()
            Fc[flip] = Fc[flip][:, ::-1]
            nrm[flip] *= -1.0
            a, b, c = V[Fc[:, 0]], V[Fc[:, 1]], V[Fc[:, 2]]
        with np.errstate(invalid="ignore", divide="ignore"):
            unit_n = np.where(area2[:, None] > 0, nrm / area2[:, None], 0.0)
        centroid = (a + b + c) / 3.0
        rho = np.sqrt(np.max(np.stack([((x - centroid) ** 2).sum(1) for x in (a, b, c)]), axis=0))
        ab, ac = b - a, c - a
        object.__setattr__(self, "vertices", V)
        object.__setattr__(self, "faces", Fc)
        idx: dict[str, Any] = {
            "tree": _kdtree(centroid),
            "centroid": centroid,
            "a": a,
            "ab": ab,
            "ac": ac,
            "abab": (ab * ab).sum(1),
            "abac": (ab * ac).sum(1),
            "acac": (ac * ac).sum(1),
            "rho": rho,
            "rho_max": float(rho.max()),
            "normal": unit_n,
        }
        # the compiled query's per-triangle bound data in one row (one cache line)
        idx["bnd"] = np.ascontiguousarray(
            np.column_stack([centroid, rho, unit_n, rho * rho]), dtype=np.float64
        )
        if self.backend != "numpy" and _compiled(self.backend):
            idx["grid"] = mesh_kernel.build_grid(a, b, c, spatial_order(centroid))
        object.__setattr__(self, "_index", idx)

    # -- construction ---------------------------------------------------------------------------
    @classmethod
    def from_file(
        cls,
        path: str | Path,
        *,
        unit: str = "mm",
        orient: str = "up",
        sheet_thickness: float = PAPER_SHEET_THICKNESS,
        source: str | None = None,
        tolerance: float = 0.01e-3,
    ) -> MeshPart:
        """Load an STL/OBJ/PLY mesh (trimesh) whose coordinates are in ``unit`` (default mm), or
        tessellate a STEP/IGES file with gmsh to ``tolerance`` [m] (:mod:`roboisf.parts.cad`;
        the CAD file declares its own unit, so ``unit`` must stay ``"mm"``).

        ``source`` is what :meth:`to_dict` records as the file (default: ``path``)."""
        from roboisf.parts.cad import CAD_SUFFIXES, tessellate_cad

        src = str(path) if source is None else source
        if Path(path).suffix.lower() in CAD_SUFFIXES:
            if unit != "mm":
                raise InputError(
                    "a STEP/IGES file declares its own unit; leave unit at 'mm'",
                    file=path,
                    field="unit",
                )
            V, F, _ = tessellate_cad(path, tolerance)
            check_sheet_mesh(V, F, orient, path)
            return cls(
                V,
                F,
                orient=orient,
                sheet_thickness=sheet_thickness,
                source=src,
                tolerance=tolerance,
            )
        V, F = read_mesh(path, unit=unit)
        check_sheet_mesh(V, F, orient, path)
        return cls(V, F, orient=orient, sheet_thickness=sheet_thickness, source=src, unit=unit)

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def bounds(self) -> tuple[F64, F64]:
        """Lower and upper corners (3,) [m] of the mesh's bounding box."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    @property
    def depth(self) -> float:
        """Depth of the lowest vertex below the sheet plane [m] (positive)."""
        return float(-self.vertices[:, 2].min())

    @property
    def symmetry(self) -> Symmetry:
        """No symmetry is assumed for a mesh (order 1)."""
        return Symmetry(1)

    @property
    def size(self) -> float:
        """Largest extent of the bounding box [m] (for unit plausibility checks)."""
        lo, hi = self.bounds
        return float(np.max(hi - lo))

    @property
    def generatrix(self) -> Any:
        raise InputError(
            "a 'mesh' part has no generatrix (its toolpaths come from roboisf.toolpath.slice)",
            file=self.source,
            field="part.kind",
        )

    def to_dict(self) -> dict[str, object]:
        if self.source is None:
            raise InputError("a mesh part built in memory has no file to save; write an STL first")
        d: dict[str, object] = {
            "kind": "mesh",
            "file": self.source,
            "sheet_thickness": self.sheet_thickness * 1e3,
        }
        if self.unit != "mm":
            d["unit"] = self.unit
        if self.orient != "up":
            d["orient"] = self.orient
        if self.tolerance is not None:
            d["tolerance"] = self.tolerance * 1e3
        return d

    # -- queries ----------------------------------------------------------------------------------
    def closest_faces(
        self, points: ArrayLike, k: int = 24, *, backend: str | None = None
    ) -> tuple[NDArray[np.int64], F64, F64]:
        """Exact closest triangle of each point: ``(face (N,), squared distance (N,) m², closest
        point (N, 3) m)``.

        ``backend`` overrides the part's :attr:`backend` for this call (see the class doc).
        ``k`` is the numpy path's first candidate count (a speed knob, not an accuracy one).
        """
        X = np.atleast_2d(np.asarray(points, dtype=float))
        if X.ndim != 2 or X.shape[1] != 3:
            raise InputError(f"points must have shape (N, 3), got {X.shape}")
        if not np.all(np.isfinite(X)):
            raise InputError("points contain NaN or inf coordinates")
        backend = self.backend if backend is None else _check_backend(backend)
        if backend != "numpy" and _compiled(backend):
            return self._closest_numba(X)
        n = X.shape[0]
        face = np.empty(n, dtype=np.int64)
        d2 = np.empty(n)
        for lo in range(0, n, CHUNK):
            hi = min(lo + CHUNK, n)
            face[lo:hi], _ = self._closest_chunk(X[lo:hi], k)
        # the search's d² went through a sqrt and back: recompute it (exact formula value)
        d2, closest = self._closest_on(X, face)
        return face, d2, closest

    def _closest_numba(self, X: F64) -> tuple[NDArray[np.int64], F64, F64]:
        ix = self._index
        n = X.shape[0]
        X = np.ascontiguousarray(X)
        face = np.empty(n, dtype=np.int64)
        d2 = np.empty(n)
        P = np.empty((n, 3))
        if "grid" not in ix:  # a part built with backend="numpy", asked for numba once
            a = ix["a"]
            ix["grid"] = mesh_kernel.build_grid(
                a, a + ix["ab"], a + ix["ac"], spatial_order(ix["centroid"])
            )
        origin, h, dims, start, items, (nlo, nhi, leaf_tri, n_leaves) = ix["grid"]
        tri = (ix["a"], ix["ab"], ix["ac"], ix["abab"], ix["abac"], ix["acac"])
        # absolute rounding margin [m²] of the kernel's pruning tests (distances are computed
        # to ~1e-16 of the squared cell/triangle size): every triangle at the minimum is seen
        tol2 = 1e-12 * (h * h + 4.0 * ix["rho_max"] ** 2)

        def rows(lo: int, hi: int) -> None:
            mesh_kernel.closest_grid(
                X[lo:hi], origin, h, dims, start, items, *tri, ix["bnd"], nlo, nhi, leaf_tri,
                n_leaves, tol2, True, face[lo:hi], d2[lo:hi], P[lo:hi],
            )  # fmt: skip

        jit.run_chunks(rows, n, NUMBA_CHUNK)  # on every core: the kernel releases the GIL
        return face, d2, P

    def _closest_on(self, X: F64, face: NDArray[np.int64]) -> tuple[F64, F64]:
        ix = self._index
        d2, v, w = point_triangle_distance2(
            X,
            ix["a"][face],
            ix["ab"][face],
            ix["ac"][face],
            ix["abab"][face],
            ix["abac"][face],
            ix["acac"][face],
        )
        return d2, ix["a"][face] + v[:, None] * ix["ab"][face] + w[:, None] * ix["ac"][face]

    def _eval(self, X: F64, f: NDArray[np.int64]) -> F64:
        ix = self._index
        d2, _, _ = point_triangle_distance2(
            X, ix["a"][f], ix["ab"][f], ix["ac"][f], ix["abab"][f], ix["abac"][f], ix["acac"][f]
        )
        return d2

    def _closest_chunk(self, X: F64, k: int) -> tuple[NDArray[np.int64], F64]:
        ix = self._index
        tree: cKDTree = ix["tree"]
        n = X.shape[0]
        n_tri = self.n_faces
        best_f = np.zeros(n, dtype=np.int64)
        best_d = np.full(n, np.inf)
        todo = np.arange(n)
        kk = min(k, n_tri)
        done = 0  # candidate ranks 1..done were evaluated already
        while todo.size:
            ranks = list(range(done + 1, kk + 1))
            dc, fc = tree.query(X[todo], k=ranks, workers=-1)
            dc = dc.reshape(todo.size, len(ranks))
            fc = fc.reshape(todo.size, len(ranks))
            if done == 0:  # upper bound: the triangle of the nearest centroid
                best_f[todo] = fc[:, 0]
                best_d[todo] = np.sqrt(self._eval(X[todo], fc[:, 0]))
            pt = np.repeat(todo, len(ranks))
            self._refine(X, pt, fc.ravel(), dc.ravel(), best_d, best_f)
            if kk >= n_tri:
                break
            # a triangle that is not among the kk candidates is at least d_kk − ρ_max away
            todo = todo[best_d[todo] > dc[:, -1] - ix["rho_max"]]
            done, kk = kk, min(kk * 2, n_tri)
        return best_f, best_d**2

    def _refine(
        self,
        X: F64,
        pt: NDArray[np.int64],
        tri: NDArray[np.int64],
        dcen: F64,
        best_d: F64,
        best_f: NDArray[np.int64],
    ) -> None:
        """Update ``best_d/best_f`` in place with the (point, triangle) pairs ``pt, tri``.

        ``pt`` must be sorted. A pair is evaluated exactly only if its lower bound is below the
        point's best: with
        ``h`` the distance to the triangle's plane and ``q = sqrt(|x − c|² − h²)`` the in-plane
        distance to its centroid, every point of the triangle is at least
        ``sqrt(h² + max(0, q − ρ)²)`` away (the triangle lies in its plane within ρ of c).
        """
        ix = self._index
        keep = dcen - ix["rho"][tri] < best_d[pt]  # cheap ball bound first
        pt, tri, dcen = pt[keep], tri[keep], dcen[keep]
        h = np.abs(np.einsum("ij,ij->i", X[pt] - ix["centroid"][tri], ix["normal"][tri]))
        q = np.sqrt(np.maximum(dcen * dcen - h * h, 0.0))
        gap = np.maximum(q - ix["rho"][tri], 0.0)
        keep = h * h + gap * gap < best_d[pt] ** 2
        pt, tri = pt[keep], tri[keep]
        if pt.size == 0:
            return
        d = np.sqrt(self._eval(X[pt], tri))
        # per point minimum over its pairs (``pt`` comes sorted: one contiguous run per point)
        starts = np.flatnonzero(np.concatenate([[True], pt[1:] != pt[:-1]]))
        mins = np.minimum.reduceat(d, starts)
        hit = np.flatnonzero(d == np.repeat(mins, np.diff(np.append(starts, d.size))))
        grp = np.searchsorted(starts, hit, side="right") - 1
        first = hit[np.concatenate([[True], grp[1:] != grp[:-1]])]
        pt, tri, d = pt[first], tri[first], d[first]
        better = d < best_d[pt]
        best_d[pt[better]] = d[better]
        best_f[pt[better]] = tri[better]

    def closest_point(self, points: ArrayLike, *, backend: str | None = None) -> SurfaceQuery:
        """Exact closest point on the mesh for each of ``points`` (N, 3) [m] (see class doc;
        ``backend`` as in :meth:`closest_faces`)."""
        X = np.atleast_2d(np.asarray(points, dtype=float))
        face, d2, P = self.closest_faces(X, backend=backend)
        N = self._index["normal"][face]
        side = np.einsum("ij,ij->i", X - P, N)
        dist = np.sqrt(d2)
        signed = np.where(side < 0, -dist, dist)
        nz = np.clip(N[:, 2], -1.0, 1.0)
        alpha = np.arccos(nz)
        flat = nz > math.cos(math.radians(1.0))
        region = np.where(flat, np.where(P[:, 2] >= -1e-4, 0, 2), 1).astype(np.int64)
        return SurfaceQuery(P, N, signed, alpha, -P[:, 2], np.full(X.shape[0], np.nan), region)

    def signed_distance(self, points: ArrayLike) -> F64:
        """Signed distance [m] of ``points`` (N, 3) to the mesh (+ on the tool side)."""
        return self.closest_point(points).distance


def _stitch(a0: int, m: int, b0: int, n: int) -> NDArray[np.int64]:
    """Triangles between ring A (``m`` vertices from index ``a0``) and ring B (``n`` from
    ``b0``), both starting at angle 0: a merge of the two angle sequences (m + n triangles)."""
    ua = np.arange(1, m + 1) / m
    ub = np.arange(1, n + 1) / n
    u = np.concatenate([ua, ub])
    from_a = np.concatenate([np.ones(m, bool), np.zeros(n, bool)])
    order = np.argsort(u, kind="stable")
    from_a = from_a[order]
    i = np.cumsum(from_a)  # A vertices passed after each event
    j = np.cumsum(~from_a)
    ia_prev = (i - from_a) % m
    jb_prev = (j - ~from_a) % n
    tri_a = np.stack([a0 + ia_prev, b0 + jb_prev, a0 + i % m], axis=1)
    tri_b = np.stack([a0 + ia_prev, b0 + jb_prev, b0 + j % n], axis=1)
    return np.where(from_a[:, None], tri_a, tri_b)


def tessellate(part: Any, *, chordal_error: float = 0.05e-3, edge: float | None = None) -> MeshPart:
    """Triangle mesh of an axisymmetric part's nominal surface (flange, wall, bottom).

    Parameters
    ----------
    part : AxisymmetricPart
    chordal_error : float, m — max. distance between a facet and the true surface (rings carry
        enough vertices that a triangle spanning two rings' angular spacings has a sagitta
        ``r (1 − cos(Δφ/2)) ≤ chordal_error``; arcs of the generatrix are subdivided to the
        same sagitta)
    edge : float, m, optional — target edge length: rings are spaced by at most ``edge`` along
        the generatrix and carry at least ``2πr/edge`` vertices, so the triangles are near
        equilateral (the mesh then has about ``2.3·area/edge²`` triangles)

    The vertices lie exactly on the nominal surface; every facet is within ``chordal_error``
    of it.
    """
    if not (chordal_error > 0 and math.isfinite(chordal_error)):
        raise InputError("must be > 0", field="chordal_error")
    g = part.generatrix
    r_list: list[F64] = []
    z_list: list[F64] = []
    for prim in g.primitives:
        n = 1
        if isinstance(getattr(prim, "radius", None), float):  # arc: sagitta ρ(1 − cos(Δβ/2))
            dbeta = 2.0 * math.acos(max(-1.0, 1.0 - chordal_error / prim.radius))
            n = max(n, math.ceil((prim.beta1 - prim.beta0) / dbeta))
        if edge is not None:
            n = max(n, math.ceil(prim.length / edge))
        r, z, _ = prim.at(np.linspace(0.0, prim.length, n + 1))
        r_list.append(r[1:] if r_list else r)
        z_list.append(z[1:] if z_list else z)
    r = np.concatenate(r_list)
    z = np.concatenate(z_list)
    verts: list[F64] = []
    faces: list[NDArray[np.int64]] = []
    start: list[int] = []
    count: list[int] = []
    n_v = 0
    # a triangle between two rings spans up to the sum of their angular spacings: with the
    # count of each ring set for a quarter of the sagitta at the largest radius of its
    # neighbourhood, that span's sagitta stays within chordal_error
    r_nb = np.maximum(r, np.maximum(np.r_[r[1:], 0.0], np.r_[0.0, r[:-1]]))
    for ri, zi, rn in zip(r, z, r_nb, strict=True):
        if ri <= 1e-12:
            m = 1
            ring = np.array([[0.0, 0.0, zi]])
        else:
            m = math.ceil(math.pi / math.acos(max(-1.0, 1.0 - chordal_error / 4 / rn)))
            if edge is not None:
                m = max(m, math.ceil(2 * math.pi * ri / edge))
            m = max(m, 8)
            phi = 2 * math.pi * np.arange(m) / m
            ring = np.stack([ri * np.cos(phi), ri * np.sin(phi), np.full(m, zi)], axis=1)
        verts.append(ring)
        start.append(n_v)
        count.append(m)
        n_v += m
    for k in range(len(start) - 1):
        tri = _stitch(start[k], count[k], start[k + 1], count[k + 1])
        # a ring of one vertex (on the axis) makes degenerate triangles: drop them
        ok = (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])
        faces.append(tri[ok])
    return MeshPart(
        np.concatenate(verts), np.concatenate(faces), sheet_thickness=part.sheet_thickness
    )
