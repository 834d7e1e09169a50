"""Local geometry of a toolpath around each point: what a part looks like where the tool is.

Three measures per toolpath point, from the contact points, normals and laps alone (so a
toolpath read from an analysis's ``per_point.parquet`` and one generated for a part not yet
formed give the same numbers):

- :func:`contour_curvature` — curvature of the lap's contour in the sheet plane (1/m), signed
  positive where the contour bends towards the tool side (every convex pit section: a cone's lap
  of radius r has 1/r; a pyramid's flat wall 0, its corner 1/corner radius). Three-point
  (circumcircle) estimate on the closed lap, in the order the tool runs it.
- :func:`meridian_curvature` — rate of change of the wall angle along the wall, down the part
  (rad/m): ``dα/ds`` between the nearest points of the neighbouring laps, ``ds`` their distance
  across the contour (a VWACF's arc of
  radius ρ: +1/ρ; a cone or pyramid wall 0; a dome whose wall flattens with depth: < 0).
- :func:`rim_distance` — distance (m) from the contact to the nearest contact of the first lap,
  the one next to the clamped rim.

Arrays: ``contact (N, 3) m``, ``normal (N, 3)``, ``lap (N,) int``, ``wall_angle (N,) rad``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["contour_curvature", "meridian_curvature", "rim_distance"]

F64 = NDArray[np.float64]
#: m — points closer than this are the same point (a lap's repeated seam point)
_SAME = 1e-7
#: a move that goes down more than this fraction of its horizontal length is a plunge, not the
#: contour (a spiral descends ~0.005 of it)
_RAMP = 0.2
#: m — neighbouring-lap points closer than this give no wall-angle slope (a seam shared by two
#: laps); 0.1 mm is well below any step-down
_MIN_DS = 1e-4


def _laps(lap: NDArray[np.int64]) -> list[NDArray[np.int64]]:
    """Indices of each lap's points in path order (laps by increasing index)."""
    lap = np.asarray(lap)
    return [np.flatnonzero(lap == k) for k in np.unique(lap)]


def contour_curvature(contact: F64, normal: F64, lap: NDArray[np.int64]) -> F64:
    """Signed curvature (N,) 1/m of each lap's contour in the x-y plane at every point.

    The lap is taken as closed (its last point neighbours its first). The sign is that of the
    curvature vector on the normal's horizontal part: positive where the contour turns towards
    the tool side. Laps with fewer than three points get 0.
    """
    contact = np.asarray(contact, dtype=float)
    normal = np.asarray(normal, dtype=float)
    out = np.zeros(len(contact))
    for idx in _laps(lap):
        p = contact[idx, :2]
        # the contour is the lap's level points: a point repeated along the lap (a slicer's
        # seam) and the plunge from the previous level (steeper than _RAMP) take the value of
        # the level point before them
        dxy = np.linalg.norm(p - np.roll(p, 1, axis=0), axis=1)
        dz = np.abs(contact[idx, 2] - np.roll(contact[idx, 2], 1))
        level = (dxy > _SAME) & (dz <= _RAMP * dxy)
        keep = (level | np.roll(level, -1)) & (dxy > _SAME)
        if keep.sum() < 3:
            continue
        twin = (np.cumsum(keep) - 1) % keep.sum()  # a dropped first point: the lap's last
        q = p[keep]
        a, c = np.roll(q, 1, axis=0), np.roll(q, -1, axis=0)
        u, v, w = q - a, c - q, c - a
        cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
        den = np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1) * np.linalg.norm(w, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.where(den > 0, 2.0 * np.abs(cross) / den, 0.0)
        # the curvature vector points from q towards the midpoint of its neighbours
        side = np.einsum("ij,ij->i", (a + c) / 2 - q, normal[idx[keep], :2])
        out[idx] = np.where(side < 0, -k, k)[twin]
    return out


def meridian_curvature(contact: F64, wall_angle: F64, lap: NDArray[np.int64]) -> F64:
    """``dα/ds`` (N,) rad/m down the wall: the wall angle's change to the nearest points of the
    previous and next laps over the distance to them (one-sided at the first and last lap)."""
    contact = np.asarray(contact, dtype=float)
    alpha = np.asarray(wall_angle, dtype=float)
    laps = _laps(lap)
    from scipy.spatial import cKDTree

    trees = [cKDTree(contact[idx]) for idx in laps]
    out = np.zeros(len(contact))
    for j, idx in enumerate(laps):
        p = contact[idx]
        lo = j - 1 if j > 0 else j
        hi = j + 1 if j + 1 < len(laps) else j
        if lo == hi:
            continue
        _, i_lo = trees[lo].query(p)
        _, i_hi = trees[hi].query(p)
        a, b = laps[lo][i_lo], laps[hi][i_hi]
        # down the wall only: the neighbouring laps' nearest points may sit half a point
        # spacing apart along the contour, a part of the step that is not the meridian's
        t = np.roll(p, -1, axis=0) - np.roll(p, 1, axis=0)
        t[:, 2] = 0.0
        t /= np.maximum(np.linalg.norm(t, axis=1), _SAME)[:, None]
        step = contact[b] - contact[a]
        ds = np.linalg.norm(step - np.einsum("ij,ij->i", step, t)[:, None] * t, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[idx] = np.where(ds > _MIN_DS, (alpha[b] - alpha[a]) / ds, 0.0)
    return out


def rim_distance(contact: F64, lap: NDArray[np.int64]) -> F64:
    """Distance (N,) m from each contact to the nearest contact of the first lap."""
    contact = np.asarray(contact, dtype=float)
    first = _laps(lap)[0]
    from scipy.spatial import cKDTree

    d, _ = cKDTree(contact[first]).query(contact)
    return np.asarray(d, dtype=float)
