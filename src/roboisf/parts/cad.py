"""CAD nominal surfaces (STEP, IGES) tessellated with gmsh's OpenCASCADE kernel to a tolerance.

The file is imported through the same path as the FE geometries
(:func:`roboisf.fem.geometry.import_step`, coordinates converted to mm by OCC whatever unit the
file declares), here accepting surfaces and shells as well as solids. Every face is meshed with
triangles of at most size h; the **chordal deviation** — the distance of the triangles from the
CAD surface — is then measured at every triangle's centroid and edge midpoints by projecting
them onto their CAD face (``gmsh.model.getClosestPoint``), and while it exceeds the tolerance
the mesh is redone with ``h ← 0.9 h sqrt(tol / deviation)`` (a sagitta grows as h²). The
vertices lie on the CAD surface; the stated tolerance bounds the deviation at those sample
points (for faces of smooth curvature the largest sagitta of a triangle is near them).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError

__all__ = ["CAD_SUFFIXES", "tessellate_cad"]

F64 = NDArray[np.float64]

CAD_SUFFIXES = (".step", ".stp", ".iges", ".igs")
_MAX_ROUNDS = 8
_MAX_TRIANGLES = 4_000_000


def tessellate_cad(path: str | Path, tolerance: float) -> tuple[F64, NDArray[np.int64], float]:
    """Triangle mesh of every face of a STEP/IGES file.

    Parameters
    ----------
    path : the CAD file
    tolerance : float, m — max. chordal deviation of the triangles from the CAD surface

    Returns
    -------
    vertices : (V, 3) float, m
    faces : (F, 3) int
    deviation : float, m — the measured max. deviation (≤ tolerance)
    """
    from roboisf.fem.geometry import import_step
    from roboisf.fem.mesh import gmsh_session

    path = Path(path)
    if not (math.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"must be > 0 mm, got {tolerance * 1e3:g}", field="tolerance")
    tol_mm = tolerance * 1e3
    with gmsh_session() as (gmsh, _):
        import_step(gmsh, path, require_solid=False)
        model = gmsh.model
        surfaces = [t for _, t in model.getEntities(2)]
        if not surfaces:
            raise InputError("the CAD file holds no surface", file=path)
        xmin, ymin, zmin, xmax, ymax, zmax = model.getBoundingBox(-1, -1)
        extent = max(xmax - xmin, ymax - ymin, zmax - zmin)
        h = extent / 20.0
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 1)
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        dev = math.inf
        for _ in range(_MAX_ROUNDS):
            model.mesh.clear()
            gmsh.option.setNumber("Mesh.MeshSizeMax", h)
            gmsh.option.setNumber("Mesh.MeshSizeMin", 0.0)
            try:
                model.mesh.generate(2)
            except Exception as e:  # gmsh raises a bare Exception with its log line
                raise InputError(f"gmsh could not mesh the surface: {e}", file=path) from None
            tags, coords, _ = model.mesh.getNodes()
            X = np.asarray(coords, dtype=float).reshape(-1, 3)
            index = np.full(int(np.max(tags)) + 1, -1, dtype=np.int64)
            index[np.asarray(tags, dtype=np.int64)] = np.arange(len(tags))
            tris: list[NDArray[np.int64]] = []
            dev = 0.0
            for s in surfaces:
                types, _, nodes = model.mesh.getElements(2, s)
                for t, nd in zip(types, nodes, strict=True):
                    if t != 2:  # 3-node triangles only (first order)
                        continue
                    T = index[np.asarray(nd, dtype=np.int64).reshape(-1, 3)]
                    tris.append(T)
                    a, b, c = X[T[:, 0]], X[T[:, 1]], X[T[:, 2]]
                    probe = np.concatenate([(a + b + c) / 3, (a + b) / 2, (b + c) / 2, (c + a) / 2])
                    on, _ = model.getClosestPoint(2, s, probe.ravel())
                    d = np.linalg.norm(np.asarray(on).reshape(-1, 3) - probe, axis=1)
                    dev = max(dev, float(d.max()) if d.size else 0.0)
            n_tri = sum(len(t) for t in tris)
            if dev <= tol_mm:
                break
            h *= 0.9 * max(0.1, math.sqrt(tol_mm / dev))
            if n_tri * (tol_mm / dev) ** -1 > _MAX_TRIANGLES:
                raise InputError(
                    f"a tessellation within {tol_mm:g} mm would need more than "
                    f"{_MAX_TRIANGLES:,} triangles; give a larger --tolerance",
                    file=path,
                    field="tolerance",
                )
        else:
            raise InputError(
                f"could not tessellate within {tol_mm:g} mm (reached {dev:.3g} mm); give a "
                "larger --tolerance",
                file=path,
                field="tolerance",
            )
        F = np.concatenate(tris) if tris else np.zeros((0, 3), dtype=np.int64)
        if F.shape[0] == 0:
            raise InputError("gmsh made no triangles from the CAD surface", file=path)
        used = np.unique(F)
        remap = np.full(X.shape[0], -1, dtype=np.int64)
        remap[used] = np.arange(used.size)
        return X[used] * 1e-3, remap[F], dev * 1e-3
