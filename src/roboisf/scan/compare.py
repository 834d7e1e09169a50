"""The whole scan-to-nominal comparison: read → check units → register → deviations → select →
per toolpath point → summaries. ``roboisf scan compare`` is a thin shell over
:func:`compare_scan`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.frames.se3 import transform_points
from roboisf.parts.base import Part
from roboisf.parts.mesh import in_spatial_order
from roboisf.path.toolpath import Toolpath
from roboisf.progress import Progress, task
from roboisf.scan.deviation import (
    FootDeviations,
    PointDeviations,
    ToolpathDeviations,
    classify_points,
    default_rim_band,
    foot_deviations,
    point_deviations,
    statistical_outliers_held,
    toolpath_deviations,
)
from roboisf.scan.readers import ScanCloud, check_units
from roboisf.scan.registration import METHODS, Registration, register
from roboisf.scan.summary import by_angle, by_depth, deviation_stats, normal_deviation_stats

if TYPE_CHECKING:  # tables only; pandas is imported where they are built
    import pandas as pd

__all__ = [
    "CompareOptions",
    "PreparedScan",
    "ScanComparison",
    "compare_scan",
    "finish_scan",
    "part_size",
    "prepare_scan",
]

F64 = NDArray[np.float64]


def part_size(part: Part) -> float:
    """Largest extent [m] of the nominal (for the unit plausibility check): of its bounding box,
    or its depth if that is larger."""
    lo, hi = part.bounds
    return max(float(np.max(np.asarray(hi) - np.asarray(lo))), float(part.depth))


@dataclass(frozen=True)
class CompareOptions:
    """Settings of :func:`compare_scan` (SI).

    register : ``none | fixture | flange | axisymmetric | icp`` (:func:`register`, any part);
    rim_band : m below the sheet plane excluded (None:
    :func:`~roboisf.scan.deviation.default_rim_band` of the part's depth, min(20 mm, 0.6·depth);
    :func:`compare_scan` stores the value it used);
    max_distance : m — points farther from the nominal are not the part; outlier_k,
    outlier_std : statistical outlier removal (``outlier_k = 0`` disables); radius,
    max_points, min_points, estimator : per-toolpath-point averaging (see
    :func:`toolpath_deviations`); bin_width : m, z-level bins; contour_z : m, band : m,
    angle_bin : rad — the polar summary; min_overlap : fraction of the scan that must lie
    within ``max_distance`` of the nominal.
    """

    register: str = "none"
    rim_band: float | None = None
    max_distance: float = 3e-3
    outlier_k: int = 8
    outlier_std: float = 3.0
    radius: float = 1e-3
    max_points: int = 64
    min_points: int = 5
    estimator: str = "median"
    bin_width: float = 0.5e-3
    contour_z: float = -11e-3
    band: float = 0.25e-3
    angle_bin: float = math.radians(5.0)
    min_overlap: float = 0.2
    register_kwargs: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.register not in METHODS:
            raise InputError(
                f"unknown registration {self.register!r}; expected one of {', '.join(METHODS)}",
                field="register",
            )
        if self.estimator not in ("median", "trimmed"):
            raise InputError(
                f"unknown estimator {self.estimator!r}; expected median or trimmed",
                field="estimator",
            )
        for name in ("rim_band", "max_distance", "radius", "bin_width", "band"):
            v = getattr(self, name)
            if v is None and name == "rim_band":
                continue
            if not (math.isfinite(v) and (v > 0 or (name == "rim_band" and v == 0))):
                raise InputError(f"must be > 0 mm, got {v * 1e3:g}", field=name)
        if self.min_points < 1 or self.max_points < self.min_points:
            raise InputError("need 1 ≤ min_points ≤ max_points", field="min_points")
        if self.outlier_k < 0:  # a negative k was taken as 0: the filter silently off
            raise InputError(
                f"must be ≥ 0 neighbours (0: no outlier filter), got {self.outlier_k}",
                field="outlier_k",
            )
        if self.outlier_k > 0 and not (math.isfinite(self.outlier_std) and self.outlier_std > 0):
            raise InputError(
                f"must be > 0 standard deviations, got {self.outlier_std:g}", field="outlier_std"
            )


@dataclass(frozen=True)
class ScanComparison:
    """Result of :func:`compare_scan`.

    points : PointDeviations or None — the selected wall points (registered, work frame), in
    spatial (Morton) order, not the file's; None after :meth:`without_points`
    toolpath : ToolpathDeviations or None
    registration : Registration
    counts : dict — points read / near the nominal / on the selected wall / outliers dropped
    by_depth : DataFrame (SI) of the selected points (of the valid toolpath points when a
    toolpath is given); by_angle : DataFrame (SI) of the wall's scan points at the contour
    (rim band *not* excluded there: the paper's contour, z = −11 mm, lies inside it)
    """

    points: PointDeviations | None
    toolpath: ToolpathDeviations | None
    registration: Registration
    counts: dict[str, int]
    by_depth: pd.DataFrame
    by_angle: pd.DataFrame
    options: CompareOptions
    #: the statistics of ``points`` (:func:`deviation_stats`, mm) kept by :meth:`without_points`
    point_stats: dict[str, Any] | None = None

    def without_points(self) -> ScanComparison:
        """This comparison without its per-scan-point arrays (``points`` None: 13 numbers per
        point, 0.18 GB for a 2 M-point scan), everything else and :meth:`summary` unchanged.
        The analysis keeps its scans this way (``analyze(keep_points=False)``): its results
        use the per-toolpath-point deviations, and the first scan's arrays would otherwise sit
        under the second scan's peak."""
        if self.points is None:
            return self
        stats = normal_deviation_stats(self.points.dn, self.points.normal).to_dict()
        return replace(self, points=None, point_stats=stats)

    def summary(self) -> dict[str, Any]:
        """JSON-friendly summary (mm, deg)."""
        o = self.options
        out: dict[str, Any] = {
            "units": {"length": "mm", "angle": "deg"},
            "sign_convention": "dn > 0: material on the tool side of the nominal; "
            "delta = dn * n (n: nominal tool-side normal), work frame",
            "registration": self.registration.to_dict(),
            "counts": dict(self.counts),
            "selection": {
                "rim_band_mm": None if o.rim_band is None else o.rim_band * 1e3,
                "max_distance_mm": o.max_distance * 1e3,
                "outlier_k": o.outlier_k,
                "outlier_std": o.outlier_std,
            },
            "points": (
                normal_deviation_stats(self.points.dn, self.points.normal).to_dict()
                if self.points is not None
                else self.point_stats
            ),
        }
        if self.toolpath is not None:
            t = self.toolpath
            v = t.valid
            out["toolpath"] = {
                "n": int(v.size),
                "n_valid": int(v.sum()),
                "n_holes": int((~v).sum()),
                "radius_mm": o.radius * 1e3,
                "estimator": o.estimator,
                **deviation_stats(t.delta[v], t.dn[v]).to_dict(),
            }
        out["by_depth"] = _frame_mm(self.by_depth, length=("z_lo", "z_hi"))
        out["by_angle"] = {
            "z_mm": o.contour_z * 1e3,
            "band_mm": o.band * 1e3,
            "bins": _frame_mm(self.by_angle, angle=("angle_lo", "angle_hi")),
        }
        return out


def _frame_mm(
    df: pd.DataFrame, *, length: tuple[str, ...] = (), angle: tuple[str, ...] = ()
) -> list[dict[str, Any]]:
    out = df.copy()
    for c in out.columns:
        if c in angle:
            out[c] = np.degrees(out[c])
        elif c != "n" and (c in length or c.startswith(("mean", "max")) or c == "R_m"):
            out[c] = out[c] * 1e3
    out = out.rename(columns={c: f"{c}_mm" for c in out.columns if c != "n" and c not in angle})
    out = out.rename(columns={c: f"{c}_deg" for c in angle})
    return list(out.to_dict(orient="records"))


def compare_scan(
    cloud: ScanCloud,
    part: Part,
    *,
    toolpath: Toolpath | None = None,
    toolpath_source: str | None = None,
    options: CompareOptions | None = None,
    progress: Progress | None = None,
    consume: bool = False,
    keep_points: bool = True,
) -> ScanComparison:
    """Compare a scan with the nominal ``part`` (and a toolpath's contact points).

    Steps: unit plausibility (scan size vs part size) → registration (``options.register``) →
    closest nominal point of every scan point → refuse if less than ``min_overlap`` of the scan
    lies within ``max_distance`` of the nominal → keep the wall below the rim band
    (:func:`select_wall`) → statistical outlier removal → per toolpath point deviations →
    summaries.

    Memory: the scan's points twice at most (a float64 copy in the work frame, in spatial order)
    plus a few bytes per point; the selected points' deviations (13 numbers each) come after
    the whole scan's copy is freed. ``consume=True`` takes the points out of ``cloud``
    (:meth:`ScanCloud.take_points`: the cloud is left empty) so that its copy is freed too, as
    soon as the sorted one exists — the readers' callers that drop the cloud anyway
    (``roboisf analyze``, ``roboisf scan compare``) pass it. ``keep_points=False`` returns
    the comparison :meth:`~ScanComparison.without_points` would (the same numbers), with the
    selected points' coordinates, normals and regions freed as soon as their statistics are
    taken, before the toolpath deviations run on the feet and normal deviations: 7 of the 11
    numbers per point gone from that step's peak (≈ 95 MB on a 1.7 M-point wall).
    """
    prep = prepare_scan(cloud, part, options=options, progress=progress, consume=consume)
    return finish_scan(
        prep,
        part,
        toolpath=toolpath,
        toolpath_source=toolpath_source,
        progress=progress,
        keep_points=keep_points,
    )


class PreparedScan:
    """A scan registered to the part, in spatial order and cut to its wall: the first half of
    :func:`compare_scan` (:func:`prepare_scan`), which :func:`finish_scan` completes once.

    The analysis prepares its second scan in the thread that read the logs while the first
    scan's outlier filter still runs in the other (:mod:`roboisf.decompose.pipeline`): the
    serial steps (reading, registration, sorting) beside a parallel one instead of after it.
    """

    def __init__(
        self,
        points: F64,
        below: NDArray[np.bool_],
        in_band: NDArray[np.bool_],
        registration: Registration,
        options: CompareOptions,
        source: str | None,
        counts: dict[str, int],
    ) -> None:
        self._points: F64 | None = points
        self.below = below
        self.in_band = in_band
        self.registration = registration
        self.options = options
        self.source = source
        self.counts = counts

    def take_points(self) -> F64:
        """(N, 3) m — the wall's points (registered, work frame, spatial order), handed over
        once: :func:`finish_scan` frees them as soon as the selected ones are copied out."""
        if self._points is None:
            raise InputError("this prepared scan was already finished", file=self.source)
        pts, self._points = self._points, None
        return pts


#: Rows per block of :func:`_to_work` (its temporaries stay in cache).
_TRANSFORM_BLOCK = 32_768


def _to_work(T: F64, pts: F64, *, own: bool) -> F64:
    """``transform_points(T, pts)`` of a scan's points (N, 3) [m], the same bits, into ``pts``
    itself when ``own`` (the caller's own C-contiguous float64 array: no second (N, 3) array,
    48 MB and their page faults on a 2 M-point scan), in blocks of columns.

    ``transform_points``' ``einsum`` sums the rotation's three products of a row as
    ``(r0·x + r2·z) + r1·y`` (its SIMD loop of two lanes: x, y, then z with a zero lane) and
    then adds the translation; the columns below add them in that order (0.044 → ~0.015 s on
    2 M points). Where this numpy's ``einsum`` adds otherwise (another build; on arm64 its
    products are fused), :func:`_einsum_order` says so and ``transform_points`` is called."""
    if not (pts.ndim == 2 and pts.shape[1] == 3 and pts.dtype == np.float64 and _einsum_order()):
        return transform_points(T, pts)
    own = own and pts.flags.c_contiguous and pts.flags.writeable
    return _columns(np.asarray(T, dtype=float), pts, pts if own else np.empty(pts.shape))


def _columns(T: F64, pts: F64, out: F64) -> F64:
    """:func:`_to_work`'s sums, block by block of rows, into ``out`` (may be ``pts``)."""
    R, t = T[:3, :3], T[:3, 3]
    n, b = pts.shape[0], _TRANSFORM_BLOCK
    cols = np.empty((3, min(b, n)))
    tmp = np.empty(min(b, n))
    for lo in range(0, n, b):
        X = pts[lo : lo + b]
        m = X.shape[0]
        for i in range(3):
            c = cols[i, :m]
            np.multiply(X[:, 0], R[i, 0], out=c)
            c += np.multiply(X[:, 2], R[i, 2], out=tmp[:m])
            c += np.multiply(X[:, 1], R[i, 1], out=tmp[:m])
            c += t[i]
            c += 0.0  # einsum's sums start from +0: a −0 result is +0
        out[lo : lo + m] = cols[:, :m].T
    return out


_EINSUM_ORDER: list[bool] = []


def _einsum_order() -> bool:
    """Does ``transform_points`` (numpy's ``einsum``) give :func:`_to_work`'s column sums'
    bits? Checked once, on 512 random rows and a random rigid transform: the other orders of
    the three products (or fused products) differ on hundreds of their 1536 numbers."""
    if not _EINSUM_ORDER:
        rng = np.random.default_rng(31)
        X = rng.normal(0.0, 0.05, (512, 3))
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = Q, rng.normal(0.0, 1e-3, 3)
        same = np.array_equal(_columns(T, X, np.empty((512, 3))), transform_points(T, X))
        _EINSUM_ORDER.append(bool(same))
    return _EINSUM_ORDER[0]


def prepare_scan(
    cloud: ScanCloud,
    part: Part,
    *,
    options: CompareOptions | None = None,
    progress: Progress | None = None,
    consume: bool = False,
    unit_setting: tuple[str | Path, str] | None = None,
) -> PreparedScan:
    """The first half of :func:`compare_scan` (the same arguments): unit plausibility,
    registration, the spatial sort, the classification of every point and the overlap check;
    the whole scan's copy is freed, the wall's points kept (:class:`PreparedScan`).
    ``unit_setting``: the (file, key) that set ``cloud.unit`` when it is not ``--unit`` (a
    study's ``runs.NAME.scan_unit``), for the unit error (:func:`check_units`)."""
    o = options or CompareOptions()
    rim_band = default_rim_band(part.depth) if o.rim_band is None else o.rim_band
    o = replace(o, rim_band=rim_band)
    src = cloud.source
    n_read = cloud.n_points
    check_units(cloud.points, part_size(part), unit=cloud.unit, source=src, setting=unit_setting)
    with task(progress, f"register ({o.register})", total=None):
        reg = register(cloud.points, part, o.register, source=src, **o.register_kwargs)
    pts, own = cloud.take_own_points() if consume else (cloud.points, False)
    if o.register != "none":
        # into the work frame: in place when the points are the reader's array, handed over
        # (the raw points are then gone), else a new array (the raw ones freed here if consumed)
        pts = _to_work(reg.T_work_scan, pts, own=own)
    # the whole comparison runs in spatial (Morton) order, sorted once here: every later query
    # (nominal closest point, outlier k-NN, toolpath neighbourhoods) then walks neighbouring
    # tree nodes and stays in cache; the per-point results come out in that order
    with task(progress, "spatial order", total=None):
        pts = in_spatial_order(pts)  # the same rows
    # the whole scan is classified in one pass that keeps four masks (a byte per point each);
    # the feet, normals and deviations are computed again for the selected points only (the
    # same numbers: the query is per point), after the outlier filter, so the whole scan's
    # 13 numbers per point never exist (at 10 M points: 0.64 GB)
    cls = classify_points(
        pts,
        part,
        max_distance=o.max_distance,
        z_below=-rim_band,
        z_band=o.contour_z,
        band=o.band,
        ordered=True,
        progress=progress,
    )
    n_near = int(np.count_nonzero(cls.near))
    frac = n_near / cls.near.size
    if frac < o.min_overlap:
        raise InputError(
            f"the scan does not overlap the part: only {frac:.1%} of its points lie within "
            f"{o.max_distance * 1e3:g} mm of the nominal (need {o.min_overlap:.0%}); check the "
            "part file, the unit and the frame (try --register)",
            file=src,
        )
    # wall points (below the rim band) that the max_distance cut drops: a part that deviates
    # more than the cut loses its largest errors silently (the analysis warns on the count)
    on_wall = cls.wall & cls.below
    n_beyond = int(np.count_nonzero(on_wall & ~cls.near))
    n_on_wall = int(np.count_nonzero(on_wall))
    del on_wall
    # the whole wall (rim band included: the polar summary sits at z = −11 mm, in the band):
    # only its points are kept from here on, the rest of the scan freed before the outlier
    # filter's grid exists; every later row is a subsequence (still in spatial order)
    full = np.flatnonzero(cls.wall & cls.near)
    below, in_band = cls.below[full], cls.band[full]
    del cls
    pts = np.take(pts, full, axis=0)
    del full
    counts = {
        "read": n_read,
        "near_nominal": n_near,
        "wall_beyond_max_distance": n_beyond,
        "wall_total": n_on_wall,
    }
    return PreparedScan(pts, below, in_band, reg, o, None if src is None else str(src), counts)


def finish_scan(
    prep: PreparedScan,
    part: Part,
    *,
    toolpath: Toolpath | None = None,
    toolpath_source: str | None = None,
    progress: Progress | None = None,
    keep_points: bool = True,
) -> ScanComparison:
    """The second half of :func:`compare_scan`: the outlier filter, the deviations of the
    wall, the contour band and the toolpath points, and their tables."""
    o = prep.options
    rim_band = o.rim_band
    assert rim_band is not None  # resolved by prepare_scan
    src = prep.source
    reg = prep.registration
    below, in_band = prep.below, prep.in_band
    pts = prep.take_points()
    n_out = 0
    keep = np.ones(pts.shape[0], dtype=bool)
    if o.outlier_k > 0:
        with task(progress, "outlier removal", total=None):
            # the points handed to the filter (not held here beside its sorted copy of them)
            box = [pts]
            del pts
            keep = statistical_outliers_held(box, o.outlier_k, o.outlier_std)
            pts = box.pop()
            n_out = int(np.count_nonzero(~keep))
    wall_rows = np.flatnonzero(keep & below)
    n_wall = int(wall_rows.size)
    if n_wall == 0:
        raise InputError(
            f"no scan point on the wall below the {rim_band * 1e3:g} mm rim band", file=src
        )
    ring_rows = np.flatnonzero(keep & in_band)
    del keep, below, in_band
    prep.below = prep.in_band = np.zeros(0, dtype=bool)
    # the selected points, the whole wall's copy freed before their deviations exist
    ring_pts, wall_pts = np.take(pts, ring_rows, axis=0), np.take(pts, wall_rows, axis=0)
    del pts, ring_rows, wall_rows
    point_stats = None
    wall: PointDeviations | FootDeviations
    if keep_points or toolpath is None:  # (by_depth without a toolpath needs dn · normal)
        wall = point_deviations(
            wall_pts, part, ordered=True, progress=progress, label="wall deviations"
        )
        if not keep_points:
            point_stats = normal_deviation_stats(wall.dn, wall.normal).to_dict()
    else:
        # what without_points() keeps, taken as the query goes: the toolpath deviations read
        # the feet and the normal deviations only, the normals are never stored
        wall, stats = foot_deviations(wall_pts, part, progress=progress, label="wall deviations")
        point_stats = stats.to_dict()
    ring = point_deviations(ring_pts, part, ordered=True)
    del wall_pts, ring_pts
    tdev = None
    if toolpath is not None:
        with task(progress, "toolpath deviations", total=None):
            tdev = toolpath_deviations(
                wall,
                toolpath.contact,
                toolpath.normal,
                radius=o.radius,
                max_points=o.max_points,
                min_points=o.min_points,
                estimator=o.estimator,
                exclude=toolpath.contact[:, 2] >= -rim_band,
                source=toolpath_source,
                ordered=True,
            )
    if tdev is not None:
        v = tdev.valid
        z, delta, dn = tdev.contact[v, 2], tdev.delta[v], tdev.dn[v]
    else:
        assert isinstance(wall, PointDeviations)
        z, delta, dn = wall.foot[:, 2], wall.delta, wall.dn
    depth_tab = by_depth(z, delta, dn, bin_width=o.bin_width)
    angle_tab = by_angle(
        ring.angle,
        ring.foot[:, 2],
        ring.delta,
        ring.dn,
        z_level=o.contour_z,
        band=o.band,
        bin_width=o.angle_bin,
    )
    c = prep.counts
    counts = {
        "read": c["read"],
        "near_nominal": c["near_nominal"],
        "wall_below_rim_band": n_wall,
        "contour": ring.n_points,
        "outliers_removed": n_out,
        "used": wall.n_points,
        "wall_beyond_max_distance": c["wall_beyond_max_distance"],
        "wall_total": c["wall_total"],
    }
    if not keep_points:
        return ScanComparison(None, tdev, reg, counts, depth_tab, angle_tab, o, point_stats)
    assert isinstance(wall, PointDeviations)
    return ScanComparison(wall, tdev, reg, counts, depth_tab, angle_tab, o)
