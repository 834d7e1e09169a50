"""The mesh and scan-point kernels (roboisf.parts.mesh_kernel): their C form against their numba
form, bit for bit — bounds, the Morton order, the row gather and scatter, the grid's rows and the
closest-triangle query — on the inputs their callers pass and at the special paths."""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from mesh_oracle import brute_closest
from native_forms import c_library, numba_form, same_bits
from roboisf.jit import HAVE_NUMBA
from roboisf.parts import Cone, MeshPart, tessellate
from roboisf.parts import mesh_kernel as mk
from roboisf.parts.mesh import spatial_order

pytestmark = pytest.mark.skipif(not HAVE_NUMBA, reason="numba not installed (the oracle)")

MK = "roboisf.parts.mesh_kernel"


def _both(f: Callable[[], Any]) -> tuple[Any, Any]:
    """``f()`` with the C form, then with the numba form."""
    c_library(mk)
    got = f()
    with numba_form(MK):
        want = f()
    return got, want


def _same(got: Any, want: Any) -> None:
    """The same arrays bit for bit (the sign of a zero and NaNs included), of the same type."""
    same_bits(got, want)


def _scan(n: int, seed: int = 0) -> np.ndarray:
    """A scan-like cloud (N, 3) [m]: points on the paper cone's surface with 0.1 mm noise, a few
    strays (what roboisf.scan's readers give spatial_order, bounds and the k-NN filter)."""
    rng = np.random.default_rng(seed)
    pts = Cone().surface_grid(60, 90)[0]
    X = pts[rng.integers(0, pts.shape[0], n)] + rng.normal(scale=1e-4, size=(n, 3))
    X[rng.integers(0, n, max(1, n // 1000))] += rng.uniform(-0.05, 0.05, 3)
    return X


def _layouts(X: np.ndarray) -> dict[str, np.ndarray]:
    """The layouts callers pass: C order, a column slice of a wider table (readers'
    np.asarray), rows read backwards, Fortran order."""
    W = np.hstack([X[:, :1], X, X[:, :1]])
    return {"C": X, "column slice": W[:, 1:4], "reversed": X[::-1], "F": np.asfortranarray(X)}


# ---- bounds ------------------------------------------------------------------------------


@pytest.mark.parametrize("layout", ["C", "column slice", "reversed", "F"])
def test_bounds_c_equals_numba(layout: str) -> None:
    X = _layouts(_scan(20_000))[layout]
    rng = np.random.default_rng(1)
    rows = rng.integers(0, X.shape[0], 5000).astype(np.int64)  # the k-NN filter's rows
    for R in (np.zeros(0, np.int64), rows, rows[:1], np.array([-1, 3, -7], dtype=np.int64)):
        got, want = _both(lambda R=R: mk.bounds(X, R))
        _same(got, want)
        assert got[0].shape == (3,)
        Y = X[R] if R.size else X  # negative rows count from the end, as numba's do
        np.testing.assert_array_equal(got[0], Y.min(axis=0))
        np.testing.assert_array_equal(got[1], Y.max(axis=0))


def test_bounds_edge_cases() -> None:
    one = np.array([[0.1, -0.2, 0.3]])
    got, want = _both(lambda: mk.bounds(one, np.zeros(0, np.int64)))
    _same(got, want)
    np.testing.assert_array_equal(got[0], one[0])
    # a NaN coordinate: the comparisons as numba's (a NaN first row stays the bound)
    X = _scan(100, seed=2)
    for row in (0, 50):
        Y = X.copy()
        Y[row] = np.nan
        got, want = _both(lambda Y=Y: mk.bounds(Y, np.zeros(0, np.int64)))
        _same(got, want)
        assert np.isnan(got[0]).all() == (row == 0)
    c_library(mk)
    with pytest.raises(TypeError):
        mk.bounds(X.astype(np.float32), np.zeros(0, np.int64))
    with pytest.raises(ValueError):
        mk.bounds(np.empty((0, 3)), np.zeros(0, np.int64))


# ---- gather, scatter -----------------------------------------------------------------------


@pytest.mark.parametrize("dtype", [np.int32, np.int64, np.uint32])
@pytest.mark.parametrize("layout", ["C", "column slice", "reversed"])
def test_gather_and_scatter_c_equal_numba(dtype: Any, layout: str) -> None:
    X = _layouts(_scan(30_000, seed=3))[layout]
    rng = np.random.default_rng(4)
    order = rng.permutation(X.shape[0]).astype(dtype)  # spatial_order's / the k-NN sort's
    rows = rng.integers(0, X.shape[0], X.shape[0]).astype(np.int64)  # mean_knn_distance(rows=)
    for R in (np.zeros(0, np.int64), rows):
        got, want = _both(lambda R=R: mk.gather_rows(X, R, order))
        _same(got, want)
        np.testing.assert_array_equal(got, X[R[order]] if R.size else X[order])
        assert got.flags.c_contiguous
    # an order read with a stride (every other index)
    half = order[::2]
    got, want = _both(lambda: mk.gather_rows(X, np.zeros(0, np.int64), half))
    _same(got, want)
    np.testing.assert_array_equal(got, X[half])
    # scatter: the inverse of the gather
    Xs = X[order]
    got, want = _both(lambda: mk.scatter_rows(Xs, order))
    _same(got, want)
    np.testing.assert_array_equal(got, X)


def test_gather_and_scatter_edge_cases() -> None:
    X = _scan(50, seed=5)
    none = np.zeros(0, np.int64)
    for order in (np.zeros(0, np.int32), np.array([7], np.int64), np.array([-1, 0], np.int32)):
        got, want = _both(lambda o=order: mk.gather_rows(X, none, o))
        _same(got, want)
        np.testing.assert_array_equal(got, X[order])  # -1: the last row, as numba indexes
    got, want = _both(lambda: mk.scatter_rows(X[:0], np.zeros(0, np.int32)))
    assert got.shape == want.shape == (0, 3)
    c_library(mk)
    with pytest.raises(TypeError):
        mk.gather_rows(X, none, np.zeros(3))  # float indices never reach C


# ---- the Morton order ----------------------------------------------------------------------


def _morton(
    X: np.ndarray, dtype: Any, bits: int = 16, scale_bits: int | None = None
) -> tuple[np.ndarray, bool]:
    """mesh.spatial_order's call of morton_order: the order, and whether it is the ``tmp_o``
    buffer (an odd number of radix passes run). ``scale_bits`` (default ``bits``): the codes'
    bits per axis; fewer than ``bits``: the top digits all zero, their passes skipped."""
    n = X.shape[0]
    lo, hi = (
        mk.bounds(np.ascontiguousarray(X), np.zeros(0, np.int64))
        if n
        else (np.zeros(3), np.ones(3))
    )
    span = float(np.max(hi - lo))
    sb = bits if scale_bits is None else scale_bits
    order, tmp = np.arange(n, dtype=dtype), np.empty(n, dtype=dtype)
    code, tmp_c = np.empty(n, np.uint64), np.empty(n, np.uint64)
    out = mk.morton_order(X, lo, (2**sb - 1) / (span or 1.0), bits, order, tmp, code, tmp_c)
    return out.copy(), bool(n) and np.shares_memory(out, tmp)


@pytest.mark.parametrize("kind", ["scan", "ties", "plane", "one", "none", "nan"])
@pytest.mark.parametrize("dtype", [np.int32, np.int64])
def test_morton_order_c_equals_numba(kind: str, dtype: Any) -> None:
    X = _scan(40_000, seed=6)
    if kind == "ties":  # many points share a 16-bit cell
        X = np.round(X, 3)
    elif kind == "plane":  # z constant: the z digits all zero, their passes skipped
        X[:, 2] = -0.01
    elif kind == "one":
        X = X[:1]
    elif kind == "none":
        X = X[:0]
    elif kind == "nan":  # a NaN coordinate: numba's float → uint64 of NaN (CPU-dependent)
        X[[10, 20_000], [0, 2]] = np.nan
    # (sort bits, code bits): 6 passes; 8 (the most); 3 (an odd number: the answer in tmp_o);
    # 4 of which the last skipped (3 run: tmp_o again); 1; none
    combos = [(16, 16), (21, 21), (8, 8), (10, 8), (2, 2), (0, 0)]
    for bits, sb in combos:
        got, want = _both(lambda bits=bits, sb=sb: _morton(X, dtype, bits, sb))
        _same(got[0], want[0])
        assert got[0].dtype == dtype
        assert got[1] == want[1]  # the same buffer holds the answer
    if kind in ("scan", "plane"):  # both buffers, and a skipped pass, are exercised
        c_library(mk)
        assert [_morton(X, dtype, b, sb)[1] for b, sb in combos] == [0, 0, 1, 1, 1, 0]
    if kind == "nan":  # a NaN's code has all 21 bits of its axis set: the top pass runs
        c_library(mk)
        assert _morton(X, dtype, 10, 8)[1] is False
    if kind in ("scan", "ties"):  # the stable argsort of the codes (the numpy form's order)
        o, _ = _morton(X, dtype)
        np.testing.assert_array_equal(o, spatial_order(X).astype(dtype))
        if kind == "ties":
            assert np.any(np.diff(o) > 0) and np.any(np.diff(o) < 0)


def test_morton_order_layouts_and_checks() -> None:
    X = _scan(5000, seed=7)
    ref, _ = _both(lambda: _morton(X, np.int32))
    for name, Y in _layouts(X).items():
        got, want = _both(lambda Y=Y: _morton(Y, np.int32))
        _same(got[0], want[0])
        if name != "reversed":  # the same points in the same order: the same permutation
            np.testing.assert_array_equal(got[0], ref[0])
    c_library(mk)
    n = X.shape[0]
    lo = X.min(axis=0)
    args = (np.empty(n, np.uint64), np.empty(n, np.uint64))
    with pytest.raises(TypeError):  # mixed index types
        mk.morton_order(X, lo, 1.0, 16, np.arange(n, dtype=np.int32), np.empty(n), *args)
    with pytest.raises(ValueError):  # codes wider than 64 bits
        mk.morton_order(X, lo, 1.0, 22, np.arange(n), np.empty(n, np.int64), *args)


# ---- the grid and the closest triangle -----------------------------------------------------


def _soup() -> MeshPart:
    """tests/test_mesh_closest.py's triangle soup, with its degenerate triangles (a segment,
    three collinear vertices)."""
    rng = np.random.default_rng(1)
    V = rng.uniform(-1, 1, (300, 3)) * np.array([0.05, 0.05, 0.01])
    F = rng.integers(0, 300, (250, 3))
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    V = np.concatenate([V, [[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.02, 0.0, 0.0]]])
    k = V.shape[0] - 3
    F = np.concatenate([F, [[k, k + 1, k + 1], [k, k + 1, k + 2], [k + 2, k, k + 1]]])
    return MeshPart(V, F, backend="numba")


def _pyramid() -> MeshPart:
    """An STL-like pyramid frustum (a pyramid part's wall, flange and bottom: few, large, long
    triangles, ties along its edges)."""
    a, b, d = 0.06, 0.025, 0.04
    V = np.array(
        [
            *([-a, -a, 0], [a, -a, 0], [a, a, 0], [-a, a, 0]),  # the opening
            *([-b, -b, -d], [b, -b, -d], [b, b, -d], [-b, b, -d]),  # the bottom
            *([-1.5 * a, -1.5 * a, 0], [1.5 * a, -1.5 * a, 0], [1.5 * a, 1.5 * a, 0]),
            [-1.5 * a, 1.5 * a, 0],  # the flange's outer corners
        ]
    )
    F = [[4, 5, 6], [4, 6, 7]]
    for i in range(4):
        j = (i + 1) % 4
        F += [[i, j, j + 4], [i, j + 4, i + 4], [i + 8, j + 8, j], [i + 8, j, i]]
    return MeshPart(V, np.array(F), backend="numba")


def _fine(make: Callable[[], MeshPart], cell_edges: float) -> Callable[[], MeshPart]:
    """``make`` with grid cells of ``cell_edges`` mean triangle edges (a grid of several cells
    for a mesh of few large triangles: the ring search and the BVH are then exercised)."""

    def made() -> MeshPart:
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(mk, "CELL_EDGES", cell_edges)
            return make()

    return made


MESHES: dict[str, Callable[[], MeshPart]] = {
    "cone": lambda: tessellate(Cone(), chordal_error=0.3e-3, edge=6e-3),
    "pyramid": _fine(_pyramid, 0.25),
    "soup": _fine(_soup, 0.3),
}


def test_grid_rows_c_equal_numba() -> None:
    for make in MESHES.values():
        mesh = make()
        ix = mesh._index
        a = ix["a"]
        b, c = a + ix["ab"], a + ix["ac"]
        for cell_edges in (3.0, 1.0, 20.0):  # many cells per triangle, or one cell
            lo = np.minimum(np.minimum(a, b), c)
            hi = np.maximum(np.maximum(a, b), c)
            span = np.maximum(hi.max(axis=0) - lo.min(axis=0), 1e-12)
            edge = float(np.mean(np.linalg.norm(b - a, axis=1)))
            h = cell_edges * edge
            dims = (np.floor(span / h) + 1).astype(np.int64)
            origin = lo.min(axis=0)
            args = (lo, hi, origin, h, dims)
            got, want = _both(lambda args=args: mk._grid_rows(*args))
            _same(got, want)
            if cell_edges == 1.0:
                assert got[1].size > a.shape[0]  # triangles listed in several cells


def _query(mesh: MeshPart, X: np.ndarray, seed: bool, out: Any = None) -> tuple[np.ndarray, ...]:
    """MeshPart._closest_numba's call of closest_grid, into fresh outputs (or ``out``)."""
    ix = mesh._index
    origin, h, dims, start, items, bvh = ix["grid"]
    n = X.shape[0]
    face, d2, P = out if out is not None else (np.full(n, -9), np.full(n, -1.0), np.empty((n, 3)))
    tol2 = 1e-12 * (h * h + 4.0 * ix["rho_max"] ** 2)
    mk.closest_grid(
        X, origin, h, dims, start, items, ix["a"], ix["ab"], ix["ac"], ix["abab"], ix["abac"],
        ix["acac"], ix["bnd"], *bvh, tol2, seed, face, d2, P,
    )  # fmt: skip
    return face, d2, P


def _mesh_points(mesh: MeshPart, n: int, seed: int) -> np.ndarray:
    """A scan of the mesh (vertices and edge midpoints ± noise: ties), points a few cells off it
    (the ring search), far points (the BVH), in spatial order as point_deviations queries."""
    rng = np.random.default_rng(seed)
    V, F = mesh.vertices, mesh.faces
    lo, hi = mesh.bounds
    span = float(np.max(hi - lo))
    vi = rng.integers(0, V.shape[0], n)
    fi = rng.integers(0, F.shape[0], n)
    mid = 0.5 * (V[F[fi, 0]] + V[F[fi, 1]])
    X = np.concatenate(
        [
            V[vi],
            mid,
            V[vi] + rng.normal(scale=1e-4 * span, size=(n, 3)),
            mid + rng.normal(scale=2e-2 * span, size=(n, 3)),
            rng.uniform(lo - 0.5 * span, hi + 0.5 * span, (n // 4, 3)),
            rng.uniform(lo - 5 * span, hi + 5 * span, (n // 10, 3)),
            hi + rng.uniform(0.5 * span, 3 * span, (n // 20, 3)),
        ]
    )
    return X[spatial_order(X)]


def _bvh_points(mesh: MeshPart, X: np.ndarray, d2: np.ndarray) -> int:
    """How many of the points ``X`` (true squared distances ``d2``) the unseeded search surely
    finishes in the BVH: after ring MAX_RINGS the grid beyond the cube of rings may still hold a
    nearer triangle even for the final best (the kernel's stopping test, with the best it can
    have then)."""
    ix = mesh._index
    origin, h, dims = ix["grid"][:3]
    tol2 = 1e-12 * (h * h + 4.0 * ix["rho_max"] ** 2)
    g_hi = origin + dims * h
    cell = np.clip(np.floor((X - origin) / h), 0, dims - 1)
    R = mk.MAX_RINGS
    lb2 = np.full(X.shape[0], np.inf)
    for ax in range(3):
        for side in (0, 1):
            use = cell[:, ax] - R > 0 if side == 0 else cell[:, ax] + R < dims[ax] - 1
            lo = np.broadcast_to(origin, X.shape).copy()
            hi = np.broadcast_to(g_hi, X.shape).copy()
            if side == 0:
                hi[:, ax] = origin[ax] + (cell[:, ax] - R) * h
            else:
                lo[:, ax] = origin[ax] + (cell[:, ax] + R + 1) * h
            gap = np.maximum(np.maximum(lo - X, X - hi), 0.0)
            lb2 = np.where(use, np.minimum(lb2, (gap * gap).sum(axis=1)), lb2)
    return int(np.sum(np.isfinite(lb2) & (lb2 <= d2 * (1.0 + 1e-12) + tol2)))


@pytest.mark.parametrize("name", list(MESHES))
@pytest.mark.parametrize("seed", [True, False])
def test_closest_grid_c_equals_numba(name: str, seed: bool) -> None:
    mesh = MESHES[name]()
    X = _mesh_points(mesh, 400, seed=11)
    got, want = _both(lambda: _query(mesh, X, seed))
    _same(got, want)
    assert np.all(got[0] >= 0)
    # and the query is exact: the d² of its face is the smallest over all faces
    from mesh_oracle import brute_closest

    fb, db, _, d2_all = brute_closest(mesh, X)
    assert _bvh_points(mesh, X, db) > 10  # the BVH path is taken
    np.testing.assert_array_equal(got[1], db)
    np.testing.assert_array_equal(got[0], fb)
    assert np.mean(np.sum(d2_all == db[:, None], axis=1) > 1) > 0.05  # exact ties, lowest index


def test_closest_grid_layouts_and_chunks() -> None:
    """Strided points and outputs (a column slice, every other row), and the chunks of
    MeshPart.closest_faces on threads (the first point of a chunk is not seeded)."""
    mesh = MESHES["cone"]()
    X = _mesh_points(mesh, 2000, seed=12)
    n = X.shape[0]
    W = np.hstack([X[:, :1], X])[:, 1:]

    def strided() -> tuple[np.ndarray, ...]:
        f, d, P = (np.full(2 * n, -9), np.full(2 * n, -1.0), np.zeros((2 * n, 4), order="F"))
        _query(mesh, W, True, (f[::2], d[::2], P[::2, 1:]))
        return f, d, P

    got, want = _both(strided)
    _same(got, want)
    ref, _ = _both(lambda: _query(mesh, X, True))
    np.testing.assert_array_equal(got[0][::2], ref[0])
    np.testing.assert_array_equal(got[2][::2, 1:], ref[2])
    # through MeshPart on threads, chunks of 97 points
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("roboisf.parts.mesh.NUMBA_CHUNK", 97)
        got, want = _both(lambda: mesh.closest_faces(X, backend="numba"))
    _same(got, want)


def test_closest_grid_edge_cases() -> None:
    mesh = MESHES["soup"]()
    X = _mesh_points(mesh, 300, seed=13)
    # no point; one point; a NaN point (no triangle wins: face -1, the last triangle's corner
    # as numba indexes a[-1]); an infinite coordinate (the ring search's clamped cell)
    nan = np.array([[np.nan, 0.0, 0.0], [0.01, 0.0, 0.0]])
    inf = np.array([[np.inf, 0.0, 0.0], [0.0, 0.0, 0.0]])
    for Y in (X[:0], X[:1], nan, inf, nan[::-1]):
        for seed in (True, False):
            got, want = _both(lambda Y=Y, seed=seed: _query(mesh, Y, seed))
            _same(got, want)
    got, _ = _both(lambda: _query(mesh, nan, False))
    assert got[0][0] == -1 and np.isinf(got[1][0])
    np.testing.assert_array_equal(got[2][0], mesh._index["a"][-1])


def test_a_triangle_with_two_equal_vertices_is_its_remaining_edge_in_every_form() -> None:
    """A triangle with two equal vertices (ab = 0: a mesh file's duplicate vertex, which
    trimesh's merge leaves as a face) is the segment of its other two: numba raised
    ZeroDivisionError for a point beyond its far vertex (0 / 0 in the edge ab's region) and the
    numpy form gave NaN; the three forms now give the brute-force closest point."""
    V = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.02, 0.02, 0.0]])
    mesh = MeshPart(V, np.array([[0, 1, 2], [3, 3, 1]]), backend="numba")
    # near the triangle, then beside the middle of the segment (3, 1), then beyond vertex 3
    X = np.array(
        [[0.001, 0.001, 0.001], [0.002, 0.001, 0.0], [0.015, 0.01, 0.0005], [0.03, 0.03, 0.0]]
    )
    f, d2, P, _ = brute_closest(mesh, X)
    assert np.isfinite(d2).all() and f.tolist() == [0, 0, 1, 1]
    # the segment's own closest point, by hand: (0.015, 0.01) projects onto (3, 1) at its middle
    np.testing.assert_allclose(P[2], [0.015, 0.01, 0.0], atol=1e-15)
    np.testing.assert_allclose(P[3], V[3], atol=1e-15)
    results = []
    for form in ("c", "numba"):
        c_library(mk)
        out = (np.full(4, -9), np.full(4, -1.0), np.zeros((4, 3)))
        with numba_form(MK) if form == "numba" else contextlib.nullcontext():
            _query(mesh, X, True, out)
        results.append(out)
    _same(*results)
    assert results[0][0].tolist() == f.tolist()
    np.testing.assert_allclose(results[0][1], d2, rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(results[0][2], P, atol=1e-15)
    numpy_face, _, numpy_P = mesh.closest_faces(X, backend="numpy")
    assert numpy_face.tolist() == f.tolist()
    np.testing.assert_allclose(numpy_P, P, atol=1e-15)


def test_mesh_queries_run_the_c_form() -> None:
    """MeshPart's query, spatial_order and the gather go through C when it is built: the numba
    kernels are not called."""
    from roboisf.parts.mesh import in_spatial_order

    c_library(mk)
    mesh = MESHES["pyramid"]()
    X = _mesh_points(mesh, 200, seed=14)
    names = ("_closest_grid", "_morton_order", "_bounds_nb", "_gather_rows_into", "_fill_grid")
    with pytest.MonkeyPatch.context() as mp:
        for name in names:
            mp.setattr(mk, name, None)  # calling one would raise
        MeshPart(mesh.vertices, mesh.faces, backend="numba").closest_faces(X)
        in_spatial_order(X)
