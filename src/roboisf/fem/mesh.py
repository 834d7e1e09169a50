"""Quadratic curved tetrahedral meshes from gmsh (headless, one thread, reproducible).

Node orderings are gmsh's: tet10 = 4 vertices, then mid-edge nodes of edges
(0,1) (1,2) (0,2) (0,3) (2,3) (1,3); tri6 = 3 vertices, then (0,1) (1,2) (0,2).
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import pickle
import signal
import subprocess
import sys
import threading
import traceback
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
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

    gmsh runs in a fresh Python process of its own (:func:`_mesh_in_child`), never in the
    caller's: the same mesh as in-process, and the caller keeps its signal handlers, its stack
    limit and its threads' state (docs/fem.md, "gmsh in a process of its own"). A geometry
    that cannot be pickled (a class only the calling script knows) is meshed here instead.

    Raises :class:`InputError` when gmsh cannot mesh it, a face role is empty, or gmsh's process
    ends by a signal (the caller's process is unharmed).
    """
    if not (math.isfinite(mesh_size) and mesh_size > 0):
        raise InputError(
            f"mesh size must be a positive length in m, got {mesh_size!r}", field="mesh_size"
        )
    with task(progress, "mesh", 1) as advance:
        mesh = _mesh_in_child(geometry, float(mesh_size))
        advance(1)
    return mesh


#: What the meshing process runs: read ``(geometry, mesh_size)`` pickled on stdin, answer one
#: pickled ``(kind, value)`` on stdout (:func:`_child_main`).
_CHILD_CODE = "from roboisf.fem.mesh import _child_main; _child_main()"


def _mesh_in_child(geometry: Geometry, mesh_size: float) -> TetMesh:
    """:func:`_mesh_here` in a fresh interpreter (``sys.executable -P``: the current folder is
    not on its path, so a file there cannot stand in for a module; this roboisf first). Its
    answer: the mesh, an :class:`InputError` raised again here, a ``MemoryError``, or a bug's
    traceback (``RuntimeError``)."""
    try:
        payload = pickle.dumps((geometry, mesh_size), protocol=pickle.HIGHEST_PROTOCOL)
    except (pickle.PicklingError, AttributeError, TypeError):
        return _mesh_here(geometry, mesh_size)
    env = dict(os.environ)
    root = str(Path(__file__).resolve().parents[2])  # the folder holding this roboisf
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    proc = subprocess.run(
        [sys.executable, "-P", "-c", _CHILD_CODE], input=payload, capture_output=True, env=env
    )
    if proc.returncode < 0:
        try:
            name = signal.Signals(-proc.returncode).name
        except ValueError:
            name = f"signal {-proc.returncode}"
        raise InputError(
            f"gmsh's meshing process ended by {name} (this process is unharmed); try another "
            "mesh size, or report it with the geometry",
            field="geometry",
        )
    try:
        kind, value = pickle.loads(proc.stdout)
    except Exception:
        raise RuntimeError(
            "the meshing process gave no answer (exit code "
            f"{proc.returncode}):\n{proc.stderr.decode(errors='replace')}"
        ) from None
    if kind == "mesh":
        return value
    if kind == "input":
        message, file, line, field = value
        raise InputError(message, file=file, line=line, field=field)
    if kind == "memory":
        raise MemoryError(value)
    if kind == "unpicklable":  # a class the fresh interpreter cannot import
        return _mesh_here(geometry, mesh_size)
    raise RuntimeError(f"meshing failed in its own process:\n{value}")


def _child_main() -> None:
    """The meshing process (:data:`_CHILD_CODE`). Whatever gmsh or OpenCASCADE print goes to
    stderr: stdout carries only the pickled answer."""
    answer = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    reply: tuple[str, Any]
    try:
        geometry, mesh_size = pickle.load(sys.stdin.buffer)
    except Exception:
        reply = ("unpicklable", traceback.format_exc())
    else:
        try:
            reply = ("mesh", _mesh_here(geometry, mesh_size))
        except InputError as e:
            reply = ("input", (e.message, e.file, e.line, e.field))
        except MemoryError as e:
            reply = ("memory", str(e))
        except Exception:
            reply = ("error", traceback.format_exc())
    with answer:
        pickle.dump(reply, answer, protocol=pickle.HIGHEST_PROTOCOL)


def _mesh_here(geometry: Geometry, mesh_size: float) -> TetMesh:
    """:func:`mesh_geometry`'s work in this process (the meshing process runs it)."""
    h = mesh_size * 1e3
    with gmsh_session() as (gmsh, _):
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
