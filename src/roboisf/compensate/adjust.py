"""Springback / residual compensation by displacement adjustment.

From a measured part, move the command along the nominal surface normal against the measured
normal deviation ``D_k`` (``dn``, + on the tool side: ``docs/conventions.md``)::

    c_{k+1} = c_k − λ · S[D_k]           (c: commanded normal offset of the ball, m)

``S`` smooths ``D`` so that scanner noise is not fed back: a periodic Gaussian along each lap
(standard deviation ``along``, arc length on the lap) and a Gaussian across laps (``across``, arc
length along the wall between laps). The smoothing is a *normalised convolution*
``S[D] = G ∗ (w D) / G ∗ w`` with weights ``w`` = 1 on valid measurements, 0 on holes — so holes
are filled from their valid neighbours and never fed back as zeros. ``support = G ∗ w`` (1 in a
fully measured neighbourhood) says how much data a value rests on; a point of the compensated
region whose support is below ``min_support`` cannot be filled: it raises, or with
``on_gap="hold"`` keeps its previous offset and is flagged.

The smoothing runs on a regular (lap × angle) grid: each lap's values are interpolated
periodically onto ``n_angles`` angles (loop-free: all laps in one ``np.interp``), smoothed by FFT
along the lap (a per-lap Gaussian in angle, σ_φ = along / lap radius) and by a Gaussian filter
across laps (σ in laps = across / median distance between laps), and read back at each point's
angle on its own lap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import gaussian_filter1d

from roboisf.errors import InputError, short_indices
from roboisf.path.toolpath import Toolpath

__all__ = ["Adjustment", "displacement_adjustment", "smooth_on_laps"]

F64 = NDArray[np.float64]
_SEP = 8 * math.pi  # key separation between laps in the flat interpolation


@dataclass(frozen=True, eq=False)
class Adjustment:
    """Result of :func:`displacement_adjustment` (SI; per toolpath point (N,)).

    Attributes
    ----------
    offset : (N,) float, m — new commanded normal offset ``c_{k+1}`` of the ball
    previous : (N,) float, m — ``c_k``
    deviation : (N,) float, m — the smoothed, hole-filled deviation ``S[D_k]`` (NaN where held)
    support : (N,) float — smoothing support (1: fully measured neighbourhood)
    filled : (N,) bool — no valid measurement at the point: its value came from neighbours
    held : (N,) bool — in the region but not enough data around: offset kept at ``c_k``
    region : (N,) bool — points that were compensated (or held)
    gain, along, across : the parameters used (λ, m, m)
    """

    offset: F64
    previous: F64
    deviation: F64
    support: F64
    filled: NDArray[np.bool_]
    held: NDArray[np.bool_]
    region: NDArray[np.bool_]
    gain: float
    along: float
    across: float

    def report(self) -> dict[str, object]:
        """JSON-able summary (mm)."""
        return {
            "gain": self.gain,
            "smoothing_along_mm": self.along * 1e3,
            "smoothing_across_mm": self.across * 1e3,
            "points_compensated": int(np.sum(self.region & ~self.held)),
            "points_outside_region": int(np.sum(~self.region)),
            "filled_from_neighbours": int(self.filled.sum()),
            "filled_indices": np.flatnonzero(self.filled).tolist(),
            "held_indices": np.flatnonzero(self.held).tolist(),
            "max_abs_offset_mm": float(np.max(np.abs(self.offset))) * 1e3,
        }


def _lap_geometry(tp: Toolpath) -> tuple[F64, F64]:
    """Per lap: mean radius (L,) m and wall arc length from the first lap (L,) m."""
    L = tp.n_laps
    cnt = np.maximum(np.bincount(tp.lap, minlength=L), 1)
    r = np.hypot(tp.contact[:, 0], tp.contact[:, 1])
    r_lap = np.bincount(tp.lap, weights=r, minlength=L) / cnt
    z_lap = np.bincount(tp.lap, weights=tp.contact[:, 2], minlength=L) / cnt
    ds = np.hypot(np.diff(r_lap), np.diff(z_lap))
    return r_lap, np.concatenate([[0.0], np.cumsum(ds)])


def smooth_on_laps(
    toolpath: Toolpath,
    values: ArrayLike,
    weights: ArrayLike | None = None,
    *,
    along: float,
    across: float,
    n_angles: int | None = None,
) -> tuple[F64, F64]:
    """Normalised Gaussian smoothing of per-point ``values`` (N,) along and across laps.

    ``weights`` (N,) ≥ 0 (default 1; 0 marks a hole). ``along``/``across`` are Gaussian standard
    deviations [m] (0: no smoothing in that direction). Returns ``(smoothed (N,), support (N,))``;
    ``smoothed`` is NaN where ``support`` is 0.
    """
    tp = toolpath
    v = np.asarray(values, dtype=float)
    w = np.ones(len(tp)) if weights is None else np.asarray(weights, dtype=float)
    if v.shape != (len(tp),) or w.shape != (len(tp),):
        raise InputError(f"expected ({len(tp)},) values and weights", field="values")
    if not (along >= 0 and across >= 0):
        raise InputError("smoothing widths must be ≥ 0", field="smoothing")
    w = np.where(np.isfinite(v), w, 0.0)
    vw = np.where(w > 0, v, 0.0) * w
    L = tp.n_laps
    if n_angles is None:
        n_angles = max(256, 1 << math.ceil(math.log2(2 * np.bincount(tp.lap).max())))
    A = n_angles
    phi_grid = np.linspace(-np.pi, np.pi, A, endpoint=False)
    # all laps in one interpolation: key = lap·8π + φ, each lap padded by ±2π (periodic)
    phi = tp.angle
    key = tp.lap * _SEP + phi
    order = np.argsort(key, kind="stable")
    k3 = np.concatenate([key[order] - 2 * np.pi, key[order], key[order] + 2 * np.pi])
    o3 = np.argsort(k3, kind="stable")
    xk = k3[o3]
    gk = (np.arange(L)[:, None] * _SEP + phi_grid[None, :]).ravel()
    num = np.interp(gk, xk, np.tile(vw[order], 3)[o3]).reshape(L, A)
    den = np.interp(gk, xk, np.tile(w[order], 3)[o3]).reshape(L, A)
    # along each lap: periodic Gaussian of angular σ = along / r (FFT, per-row transfer function)
    if along > 0:
        r_lap, _ = _lap_geometry(tp)
        sig = along / np.maximum(r_lap, along / np.pi)  # at most ±π: a whole lap average
        kk = np.arange(A // 2 + 1)
        H = np.exp(-0.5 * (sig[:, None] * kk[None, :]) ** 2)
        num = np.fft.irfft(np.fft.rfft(num, axis=1) * H, n=A, axis=1)
        den = np.fft.irfft(np.fft.rfft(den, axis=1) * H, n=A, axis=1)
    if across > 0 and L > 1:
        _, s_lap = _lap_geometry(tp)
        step = float(np.median(np.diff(s_lap)))
        if step > 0:
            sig_laps = across / step
            num = gaussian_filter1d(num, sig_laps, axis=0, mode="constant", truncate=4.0)
            den = gaussian_filter1d(den, sig_laps, axis=0, mode="constant", truncate=4.0)
    # back to the points: periodic linear interpolation on each point's own lap row
    u = np.mod(phi + np.pi, 2 * np.pi) / (2 * np.pi) * A
    j0 = np.floor(u).astype(np.int64) % A
    j1 = (j0 + 1) % A
    f = u - np.floor(u)
    row = tp.lap
    n_pt = num[row, j0] * (1 - f) + num[row, j1] * f
    d_pt = den[row, j0] * (1 - f) + den[row, j1] * f
    d_pt = np.clip(d_pt, 0.0, None)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(d_pt > 1e-12, n_pt / np.where(d_pt > 1e-12, d_pt, 1.0), np.nan)
    return out, d_pt


def displacement_adjustment(
    toolpath: Toolpath,
    deviation: ArrayLike,
    *,
    offset: ArrayLike | None = None,
    valid: ArrayLike | None = None,
    region: ArrayLike | None = None,
    gain: float = 0.8,
    along: float = 3e-3,
    across: float = 1e-3,
    min_support: float = 0.05,
    on_gap: Literal["raise", "hold"] = "raise",
    blend: ArrayLike | None = None,
    source: ArrayLike | None = None,
) -> Adjustment:
    """One displacement-adjustment step ``c_{k+1} = c_k − λ · b · S[D_k]``.

    Parameters
    ----------
    toolpath : the nominal toolpath (laps, angles, normals)
    deviation : (N,) float, m — measured normal deviation ``D_k`` per point (NaN allowed where
        not ``valid``)
    offset : (N,) float, m — current commanded normal offset ``c_k`` (default 0)
    valid : (N,) bool — where ``deviation`` is a measurement (default: where it is finite)
    region : (N,) bool — points to compensate (default all); the rest keep ``c_k``
    gain : λ in (0, 2)
    along, across : m — Gaussian smoothing widths along a lap and across laps
    min_support : a region point whose smoothing support is below this cannot be filled
    on_gap : "raise" (InputError naming the indices) or "hold" (keep ``c_k``, flag ``held``)
    blend : (N,) float in [0, 1] — share ``b`` of the update applied at each point (default 1 in
        the region, 0 outside): a ramp across the edge of the region keeps the command free of a
        step there. Points outside the region with ``b > 0`` are updated too, with the smoothed
        deviation of their ``source`` point.
    source : (N,) int — the point whose smoothed deviation each point uses (default itself; a
        point outside the region needs a source inside it)
    """
    tp = toolpath
    n = len(tp)
    D = np.asarray(deviation, dtype=float)
    if D.shape != (n,):
        raise InputError(f"expected one deviation per toolpath point ({n},), got {D.shape}")
    c = np.zeros(n) if offset is None else np.asarray(offset, dtype=float)
    if c.shape != (n,) or not np.all(np.isfinite(c)):
        raise InputError(f"expected a finite offset per point ({n},)", field="offset")
    ok = np.isfinite(D) if valid is None else np.asarray(valid, dtype=bool) & np.isfinite(D)
    reg = np.ones(n, dtype=bool) if region is None else np.asarray(region, dtype=bool)
    if ok.shape != (n,) or reg.shape != (n,):
        raise InputError(f"valid and region need shape ({n},)", field="valid")
    if not 0 < gain < 2:
        raise InputError(
            f"must be in (0, 2) for the iteration to contract, got {gain:g}", field="gain"
        )
    if on_gap not in ("raise", "hold"):
        raise InputError("must be 'raise' or 'hold'", field="on_gap")
    b = reg.astype(float) if blend is None else np.asarray(blend, dtype=float)
    if b.shape != (n,) or not np.all((b >= 0) & (b <= 1)):
        raise InputError(f"expected ({n},) blend weights in [0, 1]", field="blend")
    src = np.arange(n) if source is None else np.asarray(source)
    if src.shape != (n,) or src.dtype.kind not in "iu" or np.any((src < 0) | (src >= n)):
        raise InputError(f"expected ({n},) point indices", field="source")
    w = (ok & reg).astype(float)
    S, support = smooth_on_laps(tp, D, w, along=along, across=across)
    S, support = S[src], support[src]
    todo = b > 0
    if np.any(todo & ~reg & ~reg[src]):
        raise InputError(
            "a blended point outside the region needs a source inside it", field="source"
        )
    gap = todo & ~(support >= min_support)
    if np.any(gap) and on_gap == "raise":
        idx = np.flatnonzero(gap)
        raise InputError(
            f"{idx.size} toolpath points to compensate have no valid measurement within the "
            f"smoothing reach (support < {min_support:g}) at indices {short_indices(idx)}: "
            "widen the smoothing, rescan, leave them out of the region, or hold them "
            "(roboisf compensate --hold-gaps; on_gap='hold' in Python)",
            field="deviation",
        )
    update = todo & ~gap
    c_new = np.where(update, c - gain * b * np.where(update, S, 0.0), c)
    return Adjustment(
        offset=c_new,
        previous=c,
        deviation=np.where(update, S, np.nan),
        support=support,
        filled=update & ~(ok & reg),
        held=gap,
        region=reg,
        gain=float(gain),
        along=float(along),
        across=float(across),
    )
