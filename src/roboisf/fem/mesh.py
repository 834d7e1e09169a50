"""Quadratic curved tetrahedral meshes from gmsh (headless, one thread, reproducible).

Node orderings are gmsh's: tet10 = 4 vertices, then mid-edge nodes of edges
(0,1) (1,2) (0,2) (0,3) (2,3) (1,3); tri6 = 3 vertices, then (0,1) (1,2) (0,2).
"""

from __future__ import annotations

import contextlib
import itertools
import math
import signal
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.fem.geometry import Geometry
from roboisf.progress import Progress, task

__all__ = ["TetMesh", "gmsh_session", "mesh_geometry"]

_counter = itertools.count()


def _sigpipe() -> Any:
    """SIGPIPE's handler as Python knows it (None where there is no SIGPIPE)."""
    return signal.getsignal(signal.SIGPIPE) if hasattr(signal, "SIGPIPE") else None


def _restore_sigpipe(handler: Any) -> None:
    """Put SIGPIPE's handler back after ``gmsh.initialize``, which resets it to the default
    action (terminate the process). Python ignores SIGPIPE, so that writing to a pipe whose
    reader is gone raises BrokenPipeError; after gmsh the whole process died silently instead
    (exit 141) — e.g. when the demo stopped its second process while a queue thread still wrote
    to it (tests/test_fem_mesh_signals.py). From a thread other than the main one Python may
    not set handlers: C's ``signal`` sets SIG_IGN / SIG_DFL there."""
    if handler is None:
        return
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGPIPE, handler)
    elif handler in (signal.SIG_IGN, signal.SIG_DFL):
        import ctypes

        libc = ctypes.CDLL(None)
        libc.signal.argtypes = [ctypes.c_int, ctypes.c_void_p]
        libc.signal.restype = ctypes.c_void_p
        libc.signal(int(signal.SIGPIPE), int(handler))


@contextlib.contextmanager
def gmsh_session() -> Iterator[tuple[Any, str]]:
    """A fresh gmsh model, headless and single-threaded; removed (and gmsh finalised) on exit."""
    import gmsh

    owner = not gmsh.isInitialized()
    if owner:
        pipe = _sigpipe()
        gmsh.initialize(["-noenv"], readConfigFiles=False, run=False, interruptible=False)
        _restore_sigpipe(pipe)
    name = f"roboisf_{next(_counter)}"
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.Verbosity", 1)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.MaxNumThreads1D", 1)
        gmsh.option.setNumber("Mesh.MaxNumThreads2D", 1)
        gmsh.option.setNumber("Mesh.MaxNumThreads3D", 1)
        gmsh.model.add(name)
        yield gmsh, name
    finally:
        with contextlib.suppress(Exception):
            gmsh.model.setCurrent(name)
            gmsh.model.remove()
        if owner:
            gmsh.finalize()


@dataclass(frozen=True)
class TetMesh:
    """A quadratic tetrahedral mesh with its clamped and coupling surfaces.

    Attributes
    ----------
    points : (N, 3) float, m
    tets : (M, 10) int — gmsh tet10 node order
    body : (M,) int — body index of each tet (index into the geometry's materials)
    clamped : (Kc, 6) int — tri6 facets of the clamped surface
    coupling : (Kl, 6) int — tri6 facets of the coupling surface
    mesh_size : float, m — target element size
    """

    points: NDArray[np.float64]
    tets: NDArray[np.int64]
    body: NDArray[np.int64]
    clamped: NDArray[np.int64]
    coupling: NDArray[np.int64]
    mesh_size: float

    @property
    def n_nodes(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_dofs(self) -> int:
        return 3 * self.n_nodes


def _elements(model: Any, dim: int, tag: int, etype: int, nper: int) -> NDArray[np.int64]:
    types, _, nodes = model.mesh.getElements(dim, tag)
    for t, n in zip(types, nodes, strict=True):
        if t == etype:
            return np.asarray(n, dtype=np.int64).reshape(-1, nper)
    return np.zeros((0, nper), dtype=np.int64)


def mesh_geometry(
    geometry: Geometry,
    mesh_size: float,
    *,
    progress: Progress | None = None,
) -> TetMesh:
    """Mesh ``geometry`` with curved 10-node tetrahedra of target size ``mesh_size`` [m].

    Raises :class:`InputError` when gmsh cannot mesh it or a face role is empty.
    """
    if not (math.isfinite(mesh_size) and mesh_size > 0):
        raise InputError(
            f"mesh size must be a positive length in m, got {mesh_size!r}", field="mesh_size"
        )
    h = mesh_size * 1e3
    with task(progress, "mesh", 1) as advance, gmsh_session() as (gmsh, _):
        model = gmsh.model
        built = geometry.build(model.occ, model)
        for role, faces_of_role in (("clamped", built.clamped), ("coupling", built.coupling)):
            if not faces_of_role:
                raise InputError(f"the geometry has no {role} face", field=role)
        xmin, ymin, zmin, xmax, ymax, zmax = model.getBoundingBox(-1, -1)
        extent = max(xmax - xmin, ymax - ymin, zmax - zmin)
        if h > extent:
            raise InputError(
                f"mesh size {mesh_size * 1e3:g} mm is larger than the part ({extent:g} mm)",
                field="mesh_size",
            )
        if extent / h > 400:
            raise InputError(
                f"mesh size {mesh_size * 1e3:g} mm is too fine for a {extent:g} mm part "
                "(> 400 elements across)",
                field="mesh_size",
            )
        model.addPhysicalGroup(2, built.clamped, name="clamped")
        model.addPhysicalGroup(2, built.coupling, name="coupling")
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.1 * h)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 1)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)
        gmsh.option.setNumber("Mesh.ElementOrder", 2)
        gmsh.option.setNumber("Mesh.SecondOrderLinear", 0)  # mid-nodes on the CAD surface
        gmsh.option.setNumber("Mesh.HighOrderOptimize", 1)
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        try:
            model.mesh.generate(3)
        except Exception as e:
            raise InputError(f"gmsh could not mesh the geometry: {e}", field="geometry") from None
        node_tags, node_xyz, _ = model.mesh.getNodes()
        tags = np.asarray(node_tags, dtype=np.int64)
        xyz = np.asarray(node_xyz, dtype=float).reshape(-1, 3) * 1e-3
        tets, body = [], []
        for vol, b in built.volumes.items():
            t = _elements(model, 3, vol, 11, 10)
            tets.append(t)
            body.append(np.full(len(t), b, dtype=np.int64))
        tet_tags = np.concatenate(tets) if tets else np.zeros((0, 10), np.int64)
        if len(tet_tags) == 0:
            raise InputError("gmsh produced no tetrahedra for this geometry", field="geometry")
        faces = {
            role: np.concatenate([_elements(model, 2, s, 9, 6) for s in surf])
            for role, surf in (("clamped", built.clamped), ("coupling", built.coupling))
        }
        advance(1)
    # compress to the nodes the tets use, numbered 0..N-1
    used = np.unique(tet_tags)
    lookup = np.full(int(max(tags.max(), used.max())) + 1, -1, dtype=np.int64)
    lookup[tags] = np.arange(len(tags))
    pts = xyz[lookup[used]]
    renum = np.full(lookup.shape, -1, dtype=np.int64)
    renum[used] = np.arange(len(used))
    out = {k: renum[v] for k, v in faces.items()}
    for role, f in out.items():
        if len(f) == 0 or np.any(f < 0):
            raise InputError(f"the {role} surface is not part of the meshed solid", field=role)
    return TetMesh(
        points=pts,
        tets=renum[tet_tags],
        body=np.concatenate(body),
        clamped=out["clamped"],
        coupling=out["coupling"],
        mesh_size=float(mesh_size),
    )
