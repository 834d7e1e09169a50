"""Brute-force closest point on a triangle mesh: the oracle the mesh tests compare the grid
search (numba) and the k-d tree search (numpy) against — every point against every triangle."""

from __future__ import annotations

import numpy as np

from roboisf.parts import MeshPart
from roboisf.parts.mesh import point_triangle_distance2


def brute_closest(mesh: MeshPart, X: np.ndarray) -> tuple[np.ndarray, ...]:
    """Face (lowest index at the minimum), d² and closest point over all triangles, and the
    (N, F) d² of every pair."""
    ix = mesh._index
    d2, v, w = point_triangle_distance2(
        X[:, None, :],
        ix["a"][None],
        ix["ab"][None],
        ix["ac"][None],
        ix["abab"][None],
        ix["abac"][None],
        ix["acac"][None],
    )
    f = np.argmin(d2, axis=1)
    r = np.arange(X.shape[0])
    P = ix["a"][f] + v[r, f][:, None] * ix["ab"][f] + w[r, f][:, None] * ix["ac"][f]
    return f, d2[r, f], P, d2
