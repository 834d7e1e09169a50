"""Toolpath generation for axisymmetric parts: step-down contours and spirals.

Levels are **tool-tip heights** (CAM "Z-level" contours): lap k has its programmed tip at
z = −kΔz, the last lap at the full part depth. At every height the ball (radius R) is placed as
far out as it can go **without entering the nominal surface** — tangent to it:

* on a wall the contact P is a wall point, ``C = P + R·n``, ``T = C − R·ẑ`` (at 71°, R = 5 mm:
  C is R·sin α = 4.73 mm inward and T is R(1 − cos α) = 3.37 mm below P);
* near a convex edge (the rim of a cone) the ball rolls over the edge: P is the edge and n the
  direction from it to C;
* at a concave corner (wall → flat bottom) the last lap's ball touches wall and bottom at once:
  the part's nominal depth is reached by the tip, never passed.

Why tip levels and not contact levels: with contact levels the last laps of a flat-bottomed part
put the ball up to R(1 − cos α) below the bottom (3.37 mm on the paper's cone), gouging the
nominal part, and a part narrower than the ball (the VWACF near 90° with a Ø10 ball) would put the
ball centre across the axis. Where the ball no longer fits at all (it would touch the wall on the
other side of the axis), the path stops at the deepest height that fits; ``meta`` records it
(``"truncated": True``, ``"reachable_tip_z"``) and the CLI warns.

* **Step-down** (the paper's "step toolpath"): closed contours; between contours the tool steps
  down at the lap's start angle.
* **Spiral**: the tip height ramps linearly within each lap (no plunge marks); a final closed
  contour at the last height finishes the bottom edge.
* **Along-wall step** (``max_wall_step``): where the wall is shallow (VWACF near 0°) a constant
  Δz gives contacts far apart along the wall; extra heights are inserted so that consecutive laps
  touch the wall at most ``max_wall_step`` apart *along the generatrix*.

Point spacing: points on a lap are evenly spaced in angle with at most ``spacing`` of arc between
neighbours at the contact radius (and at least 8 points per lap).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.parts.axisymmetric import AxisymmetricPart
from roboisf.parts.generatrix import Generatrix, HeightQuery
from roboisf.path.toolpath import Toolpath
from roboisf.toolpath.limits import MAX_POINTS

__all__ = [
    "BYTES_PER_POINT",
    "DEFAULT_FEED",
    "MAX_POINTS",
    "ball_position",
    "estimate_points",
    "spiral",
    "step_down",
    "tip_levels",
]

F64 = NDArray[np.float64]

#: Paper feed rate, 750 mm/min in m/s.
DEFAULT_FEED = 750e-3 / 60.0

#: Memory per toolpath point, generating and writing it (measured peak of the generator
#: ≈ 0.3 kB/point with tracemalloc, the CSV/program writers add their text), rounded up.
BYTES_PER_POINT = 1000

#: Bisection iterations for the ball position (interval ≤ 1 m → < 1e-15 m).
_BISECT = 52
#: A ball closer than R − _FIT_TOL to the surface is gouging (float noise of d is ~1e-17 m).
_FIT_TOL = 1e-15
#: Heights solved (and points queried) at a time: bounds the closest-point queries' work arrays
#: (~0.35 kB a height) whatever the path's size; each height's numbers are its own.
_CHUNK = 1 << 16


class _Geometry:
    """The part's generatrix and opening radius, taken once per call: ``part.generatrix``
    builds a new chain of primitives on every access."""

    __slots__ = ("g", "opening")

    def __init__(self, part: AxisymmetricPart) -> None:
        self.g: Generatrix = part.generatrix
        self.opening = float(part.opening_radius)


def _check(
    part: AxisymmetricPart, tool_radius: float, step: float, spacing: float, feed: float
) -> None:
    for name, v in (
        ("tool_radius", tool_radius),
        ("step_down", step),
        ("spacing", spacing),
        ("feed", feed),
    ):
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"must be > 0, got {v:g} (SI)", field=name)
    if step > part.depth:
        raise InputError(
            f"step-down {step * 1e3:g} mm is larger than the part depth {part.depth * 1e3:g} mm",
            field="step_down",
        )


def estimate_points(
    part: AxisymmetricPart,
    tool_radius: float,
    step_down: float,
    spacing: float,
    max_wall_step: float | None = None,
) -> int:
    """Number of points a step-down or spiral toolpath will have, estimated before generating.

    Laps: ``ceil(depth / step_down)``, or more when ``max_wall_step`` asks for laps along a
    shallow wall (the contact arc length between 64 sampled levels over ``max_wall_step``).
    Points per lap from the contact radius at those sampled levels (as :func:`step_down`
    counts them). Cost: 64 ball positions, whatever the step-down. Measured within 15 % of the
    generated count on the paper's cone and VWACF from 0.05 to 2 mm step-down (more, on the safe
    side, for paths of a few laps: it adds two laps of margin).
    """
    geo = _Geometry(part)
    return _estimate_points(geo, part.depth, tool_radius, step_down, spacing, max_wall_step)


def _estimate_points(
    geo: _Geometry,
    depth: float,
    tool_radius: float,
    step_down: float,
    spacing: float,
    max_wall_step: float | None,
) -> int:
    n_levels = math.ceil(depth / step_down - 1e-9)
    m = min(64, n_levels)
    g = n_levels / m  # levels each sample stands for
    z = -np.linspace(depth / m, depth, m)
    cr, mask, q = _ball(geo, tool_radius, z)
    fits = np.asarray(mask, dtype=bool)
    rp, _, _, ss = _closest(geo, cr, z + tool_radius, q)
    per_lap = np.maximum(8.0, np.ceil(2 * math.pi * rp / spacing))
    laps = np.full(m, g)
    if max_wall_step is not None and max_wall_step > 0:
        s0 = _contact_s(geo, tool_radius, np.array([0.0]))
        ds = np.abs(np.diff(np.concatenate([s0, ss])))
        laps = g * np.maximum(1.0, np.ceil(ds / (g * max_wall_step)))
    total = float(np.sum((laps * per_lap)[fits])) if fits.any() else 8.0 * n_levels
    return math.ceil(total) + int(2 * per_lap.max())


def _check_size(
    geo: _Geometry,
    part: AxisymmetricPart,
    tool_radius: float,
    step: float,
    spacing: float,
    max_wall_step: float | None,
    max_points: int | None,
) -> None:
    """Refuse, before generating, a toolpath larger than ``max_points`` (None: no limit)."""
    if max_points is None:
        return
    n = _estimate_points(geo, part.depth, tool_radius, step, spacing, max_wall_step)
    refuse_size(n, part.depth, step, spacing, max_points)


def refuse_size(n: int, depth: float, step: float, spacing: float, max_points: int | None) -> None:
    """InputError when an estimated ``n`` points exceed ``max_points`` (None: no limit)."""
    if max_points is not None and n > max_points:
        raise InputError(
            f"this toolpath would have about {n:,} points (≈ {n * BYTES_PER_POINT / 1e9:.1f} GB "
            f"to generate and write; step-down {step * 1e3:g} mm, spacing {spacing * 1e3:g} mm "
            f"over a {depth * 1e3:g} mm deep part), above the limit of {max_points:,}; "
            "use a larger step-down or spacing, or raise the limit (--max-points)",
            field="step_down",
        )


def ball_position(
    part: AxisymmetricPart, tool_radius: float, tip_z: ArrayLike
) -> tuple[F64, NDArray[np.bool_]]:
    """Radius of the ball centre ``C_r`` [m] for tip heights ``tip_z`` (M,) [m], and a mask of
    the heights where the ball fits.

    ``C_r`` is the largest radius (≤ the opening radius) at which the ball centred at
    ``(C_r, tip_z + R)`` keeps a distance ≥ R from the nominal surface, i.e. is tangent to it.
    The distance to the material never increases when moving outwards at a fixed height (the
    material is closed under outward radial shifts), so bisection finds it exactly.
    """
    cr, fits, _ = _ball(_Geometry(part), tool_radius, tip_z)
    return cr, np.asarray(fits, dtype=bool)


def _fits(geo: _Geometry, tool_radius: float, tip_z: F64) -> NDArray[np.bool_]:
    """Whether the ball fits at tip heights ``tip_z``: the mask of :func:`ball_position`, the
    signed distance of its centre on the axis (without the bisection)."""
    cz = np.asarray(tip_z, dtype=float) + tool_radius
    flat = cz.reshape(-1)
    fits = np.empty(flat.shape, dtype=bool)
    for a in range(0, flat.size, _CHUNK):
        q = geo.g.at_heights(flat[a : a + _CHUNK])
        fits[a : a + _CHUNK] = q.signed(np.zeros(q.n)) >= tool_radius - _FIT_TOL
    return fits.reshape(cz.shape)


def _ball(
    geo: _Geometry, tool_radius: float, tip_z: ArrayLike, fits: bool = True
) -> tuple[F64, NDArray[np.bool_] | None, HeightQuery | None]:
    """:func:`ball_position` (the mask only if ``fits``), and the height query of the ball
    centres (flattened; None beyond :data:`_CHUNK` heights), for their closest points.

    One bisection for all heights, every height's iterates its own (so a height gives the same
    bits whatever the other heights of the call). The signed distance of a centre is that to its
    closest point on the generatrix (ties within 1e-12 m go to wall primitives: deterministic
    contacts at the concave bottom corner, where the last ball touches wall and bottom at once),
    + on the tool side; a :class:`~roboisf.parts.generatrix.HeightQuery` at the centres' heights
    computes it: the bits of :meth:`~roboisf.parts.generatrix.Generatrix.closest` and of the
    signed distance taken from it, in under half the numpy calls. Where only the mask is
    wanted, :func:`_fits` asks for it without the bisection."""
    R = tool_radius
    cz = np.asarray(tip_z, dtype=float) + R
    flat = cz.reshape(-1)
    thr = R - _FIT_TOL
    cr = np.empty(flat.shape)
    fit = np.empty(flat.shape, dtype=bool) if fits else None
    q = None
    for a in range(0, flat.size, _CHUNK):
        b = min(a + _CHUNK, flat.size)
        q = geo.g.at_heights(flat[a:b])
        lo = np.zeros(q.n)
        hi = np.full(q.n, geo.opening)
        if fit is not None:
            fit[a:b] = q.signed(lo) >= thr
        top = q.signed(hi) >= thr
        mid = np.empty(q.n)
        for _ in range(_BISECT):
            np.add(lo, hi, out=mid)
            mid *= 0.5
            ok = q.signed(mid) >= thr
            np.copyto(lo, mid, where=ok)
            np.copyto(hi, mid, where=~ok)
        cr[a:b] = np.where(top, hi, lo)
    q = q if flat.size <= _CHUNK else None
    return cr.reshape(cz.shape), (None if fit is None else fit.reshape(cz.shape)), q


def _closest(
    geo: _Geometry, r: F64, z: F64, q: HeightQuery | None = None
) -> tuple[F64, F64, F64, F64]:
    """``rp, zp, alpha, s`` of :meth:`~roboisf.parts.generatrix.Generatrix.closest` for the
    meridian points ``(r, z)`` (N,): through ``q``, the height query at ``z`` (from
    :func:`_ball`), or by queries of :data:`_CHUNK` points."""
    if q is not None:
        return q.closest(r)[:4]
    out = tuple(np.empty(r.shape) for _ in range(4))
    for a in range(0, r.size, _CHUNK):
        b = min(a + _CHUNK, r.size)
        for o, v in zip(out, geo.g.at_heights(z[a:b]).closest(r[a:b])[:4], strict=False):
            o[a:b] = v
    return out[0], out[1], out[2], out[3]


def tip_levels(
    part: AxisymmetricPart,
    tool_radius: float,
    step_down: float,
    max_wall_step: float | None = None,
) -> tuple[F64, bool]:
    """Tip heights [m] of the laps, top to bottom, and whether the path was truncated.

    Heights −Δz, −2Δz, … with the last at the full depth (a level closer than 1e-9 m to the bottom
    is merged into it); heights where the ball does not fit are dropped (truncated = True); then,
    if ``max_wall_step`` is given, heights inserted where the contacts of neighbouring laps are
    more than ``max_wall_step`` apart along the generatrix.
    """
    return _tip_levels(_Geometry(part), part.depth, tool_radius, step_down, max_wall_step)


def _tip_levels(
    geo: _Geometry,
    depth: float,
    tool_radius: float,
    step_down: float,
    max_wall_step: float | None,
) -> tuple[F64, bool]:
    n = math.ceil(depth / step_down - 1e-9)
    z: F64 = -np.arange(1, n + 1, dtype=float) * step_down
    z[-1] = -depth
    fits = _fits(geo, tool_radius, z)
    truncated = not bool(fits.all())
    if truncated:
        if not fits[0]:
            raise InputError(
                f"a Ø{2 * tool_radius * 1e3:g} mm ball does not fit in this part even at the first "
                f"level (tip z = {z[0] * 1e3:g} mm)",
                field="tool_radius",
            )
        z = z[: int(np.argmin(fits))]
        # the deepest height that fits, to 1 µm, as the last lap
        lo, hi = z[-1], z[-1] - step_down
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if _fits(geo, tool_radius, np.array([mid]))[0]:
                lo = mid
            else:
                hi = mid
        if z[-1] - lo > 1e-6:
            z = np.append(z, lo)
    if max_wall_step is not None:
        if not (max_wall_step > 0):
            raise InputError("must be > 0", field="max_wall_step")
        z = _refine_along_wall(geo, tool_radius, z, max_wall_step)
    return z, truncated


def _contact_s(geo: _Geometry, tool_radius: float, tip_z: F64) -> F64:
    """Wall arc length of the contact of the ball at tip heights ``tip_z``."""
    cr, _, q = _ball(geo, tool_radius, tip_z, fits=False)
    return _closest(geo, cr, tip_z + tool_radius, q)[3]


def _refine_along_wall(geo: _Geometry, R: float, z: F64, max_step: float) -> F64:
    """Insert tip heights so that neighbouring contacts are ≤ ``max_step`` apart along the wall.

    The contact arc length s(z) is monotone in the tip height, so the heights whose contacts are
    evenly spaced between two laps are found by one vectorised bisection over all gaps.
    """
    z_all = np.concatenate([[0.0], z])
    s_all = _contact_s(geo, R, z_all)
    m = np.maximum(1, np.ceil(np.abs(np.diff(s_all)) / max_step - 1e-9).astype(np.int64))
    gap = np.repeat(np.arange(len(z)), m - 1)  # gap index of each inserted height
    if gap.size == 0:
        return z
    j = np.concatenate([np.arange(1, k) for k in m])
    frac = j / m[gap]
    targets = s_all[gap] + (s_all[gap + 1] - s_all[gap]) * frac
    lo, hi = z_all[gap].copy(), z_all[gap + 1].copy()
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        below = _contact_s(geo, R, mid) < targets
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    inserted = 0.5 * (lo + hi)
    # merge: each gap's inserted heights come before the gap's lower level
    key_new = gap + frac  # in (gap, gap + 1)
    key_old = np.arange(len(z)) + 1.0
    order = np.argsort(np.concatenate([key_new, key_old]), kind="stable")
    return np.concatenate([inserted, z])[order]


def _lap_points(r: float, spacing: float) -> int:
    return max(8, math.ceil(2 * math.pi * r / spacing))


def _assemble(
    geo: _Geometry,
    tip_z: F64,
    phi: F64,
    lap: NDArray[np.int64],
    tool_radius: float,
    feed: float,
    meta: dict[str, object],
    cr: F64 | None = None,
) -> Toolpath:
    """Toolpath from per-point tip heights and polar angles (ball from :func:`ball_position`,
    or ``cr``: the ball centres' radii of the points, already solved)."""
    R = tool_radius
    if cr is None:
        levels, inverse = np.unique(tip_z, return_inverse=True)  # one solve per height
        cr = _ball(geo, R, levels, fits=False)[0][inverse]
    cz = tip_z + R
    rp, zp, _, _ = _closest(geo, cr, cz)
    nr, nz = cr - rp, cz - zp
    norm = np.hypot(nr, nz)
    nr, nz = nr / norm, nz / norm
    c, sn = np.cos(phi), np.sin(phi)
    contact = np.stack([rp * c, rp * sn, zp], axis=1)
    normal = np.stack([nr * c, nr * sn, nz], axis=1)
    wall_angle = np.arctan2(-nr, nz)
    return Toolpath.from_contact(contact, normal, wall_angle, lap, R, feed, meta)


def _meta(
    kind: str, part: AxisymmetricPart, step: float, spacing: float, z: F64, trunc: bool
) -> dict[str, object]:
    meta: dict[str, object] = {
        "kind": kind,
        "step_down": step,
        "spacing": spacing,
        "part": part.kind,
    }
    if trunc:
        meta["truncated"] = True
        meta["reachable_tip_z"] = float(z[-1])
    return meta


def step_down(
    part: AxisymmetricPart,
    tool_radius: float = 5e-3,
    step_down: float = 0.5e-3,
    *,
    spacing: float = 1e-3,
    feed: float = DEFAULT_FEED,
    max_wall_step: float | None = None,
    start_angle: float = 0.0,
    clockwise: bool = False,
    max_points: int | None = MAX_POINTS,
) -> Toolpath:
    """Step-down contour toolpath: lap k at tip height −kΔz (see the module docstring).

    Parameters
    ----------
    part : the nominal part
    tool_radius : float, m — ball radius (paper: 5 mm)
    step_down : float, m — Δz between laps (paper: 0.5 mm)
    spacing : float, m — max. arc length between points on a lap, at the contact radius
    feed : float, m/s — (paper: 750 mm/min)
    max_wall_step : float, m, optional — max. along-wall distance between laps
    start_angle : float, rad — polar angle of each lap's first point
    clockwise : bool — direction of travel seen from above (+z)
    max_points : int or None — refuse (:class:`InputError`, before generating) a path whose
        :func:`estimate_points` exceeds this (default :data:`MAX_POINTS`); None: no limit

    Raises
    ------
    InputError
        a non-positive parameter, a step-down deeper than the part, a ball that does not fit,
        or a path above ``max_points``.
    """
    _check(part, tool_radius, step_down, spacing, feed)
    geo = _Geometry(part)
    _check_size(geo, part, tool_radius, step_down, spacing, max_wall_step, max_points)
    z_levels, trunc = _tip_levels(geo, part.depth, tool_radius, step_down, max_wall_step)
    cr, _, q = _ball(geo, tool_radius, z_levels, fits=False)
    r_contact = _closest(geo, cr, z_levels + tool_radius, q)[0]
    sign = -1.0 if clockwise else 1.0
    counts = [_lap_points(float(r), spacing) for r in r_contact]
    phi = np.concatenate([start_angle + sign * 2 * math.pi * np.arange(m) / m for m in counts])
    lap = np.repeat(np.arange(len(counts), dtype=np.int64), counts)
    tip_z = np.repeat(z_levels, counts)
    return _assemble(
        geo,
        tip_z,
        phi,
        lap,
        tool_radius,
        feed,
        _meta("step_down", part, step_down, spacing, z_levels, trunc),
        cr=np.repeat(cr, counts),  # each lap's ball, solved once (the same bits per height)
    )


def spiral(
    part: AxisymmetricPart,
    tool_radius: float = 5e-3,
    step_down: float = 0.5e-3,
    *,
    spacing: float = 1e-3,
    feed: float = DEFAULT_FEED,
    max_wall_step: float | None = None,
    start_angle: float = 0.0,
    clockwise: bool = False,
    max_points: int | None = MAX_POINTS,
) -> Toolpath:
    """Spiral toolpath: within lap k the tip descends linearly from height k−1 to k.

    Same parameters as :func:`step_down`. The first lap starts with the tip in the sheet plane
    (ball resting on the rim); a final closed contour at the last height finishes the bottom edge.
    """
    _check(part, tool_radius, step_down, spacing, feed)
    geo = _Geometry(part)
    _check_size(geo, part, tool_radius, step_down, spacing, max_wall_step, max_points)
    z_levels, trunc = _tip_levels(geo, part.depth, tool_radius, step_down, max_wall_step)
    z_all = np.concatenate([[0.0], z_levels])
    sign = -1.0 if clockwise else 1.0
    z_mid = 0.5 * (z_all[1:] + z_all[:-1])
    cr_mid, _, q = _ball(geo, tool_radius, z_mid, fits=False)
    r_mid = _closest(geo, cr_mid, z_mid + tool_radius, q)[0]
    z_parts, phi_parts, lap_parts = [], [], []
    for k in range(len(z_levels)):
        m = _lap_points(float(r_mid[k]), spacing)
        u = np.arange(m) / m
        z_parts.append(z_all[k] + u * (z_all[k + 1] - z_all[k]))
        phi_parts.append(start_angle + sign * 2 * math.pi * u)
        lap_parts.append(np.full(m, k, dtype=np.int64))
    # closing contour at the last height
    m = _lap_points(float(r_mid[-1]), spacing)
    z_parts.append(np.full(m + 1, z_levels[-1]))
    phi_parts.append(start_angle + sign * 2 * math.pi * np.arange(m + 1) / m)
    lap_parts.append(np.full(m + 1, len(z_levels) - 1, dtype=np.int64))
    return _assemble(
        geo,
        np.concatenate(z_parts),
        np.concatenate(phi_parts),
        np.concatenate(lap_parts),
        tool_radius,
        feed,
        _meta("spiral", part, step_down, spacing, z_levels, trunc),
    )
