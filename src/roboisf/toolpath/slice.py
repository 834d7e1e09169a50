"""Toolpaths on any part: z-level contours and spirals sliced from the ball-centre surface.

For a ball tool of radius R the set of ball centres that do not enter the nominal surface is
``F = {C : d(C) ≥ R}`` (d the part's signed distance, + on the tool side); its boundary
``d(C) = R`` is the offset of the nominal by R along its normal **with the self-intersections
of concave corners already trimmed** (a centre where two offset sheets cross is closer than R to
one of the two walls, so it is not in F's boundary). Slicing that boundary at the ball-centre
height ``z_c = z_tip + R`` gives the lap: the ball touches the nominal all round and never gouges
it, at a concave corner it touches both walls, over a convex edge it rolls.

Method (works through :meth:`roboisf.parts.Part.closest_point` only, so it serves every part
kind): the lap at tip height z is traced by rays from the part's centre ``c`` in the horizontal
plane ``z_c``; on each ray the centre is placed at ``ρ* = sup{ρ : d(c + ρu) ≥ R}`` by a
safeguarded Newton iteration on ``d(ρ) − R`` (the gradient of d is ``(C − P)/|C − P|``, P the
closest point) inside a bracket kept by bisection, to 0.1 nm. The contact point is then the
closest point P of the centre on the nominal and the normal ``n = (C − P)/R`` (the nominal's
normal wherever P is inside a face; on a convex edge the direction the ball rolls over it),
so ``C = P + R n`` holds as the :class:`~roboisf.toolpath.Toolpath` contract says.

Limits: the horizontal slices of F must be **star-shaped about c** (every ray leaves F once).
That holds for every pit whose horizontal sections are convex — cones, VWACF, pyramids, elliptic
domes — and is not checked. On a part with re-entrant sections (a cross-shaped pit, two
pockets) each ray stops at its first exit: the path stays free of gouges but leaves the
re-entrant pockets unformed; such parts need a general contouring that this module does not do.
Consecutive centres are joined by straight chords; inside a convex slice a chord never leaves
F, so the path does not gouge between points either. A centre path with sharp corners (a
concave corner of radius < R sin α: the trimmed offset) is sampled on both sides of the corner,
not at the corner itself; the chord then cuts the corner by at most the point spacing.

Levels are tool-tip heights as in :mod:`roboisf.toolpath.generate` (−Δz, −2Δz, …, the last at
the full depth; truncated where the ball no longer fits at c). With ``scallop_height`` h the
step is chosen per lap from the smallest wall angle α met by the lap's contacts: two balls whose
contacts lie ``w`` apart on a flat wall leave a cusp ``h = R − sqrt(R² − w²/4)``, and a tip step
Δz moves the contact ``w = Δz / sin α`` along a wall of angle α, so

    Δz = 2 sin α · sqrt(h (2R − h))

clipped to ``[min_step, step_down]`` (``step_down`` is then the largest step).

Points: each lap starts on the ray at ``start_angle`` and runs counter-clockwise seen from +z
(``clockwise`` reverses it); a step-down lap ends with its start point again (closed), and the
next lap steps down from there along the same ray. Points are placed at equal arc length of the
ball-centre (= tip) path, at least 8 per lap; then every chord of the path (within laps, and the
steps between laps) is checked and halved until it is ≤ ``spacing`` and its midpoint is no
closer than ``R −`` :data:`GOUGE_TOL` to the nominal. The second test matters only over convex
edges (the rim), where the centre path is a circle of radius R about the edge and a straight
step of Δz would cut ``≈ Δz²/(8R)`` into it (6 µm for 0.5 mm and R = 5 mm); there a step down
gets intermediate points on the start ray.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.parts.base import Part
from roboisf.path.toolpath import Toolpath
from roboisf.toolpath.generate import DEFAULT_FEED, MAX_POINTS, refuse_size

__all__ = ["ball_centre_rays", "level_contour", "scallop_step", "sliced_spiral", "sliced_step_down"]

F64 = NDArray[np.float64]

#: A centre closer than R − FIT_TOL to the nominal counts as gouging [m].
FIT_TOL = 1e-12
#: Ray solution accuracy [m].
RAY_TOL = 1e-10
#: A chord of the centre path may come this much closer than R to the nominal [m] (over a
#: convex edge, where the ball rolls, chords are shortened until it holds).
GOUGE_TOL = 0.1e-6
#: A centre at R ± TOUCH_TOL from the nominal touches it [m].
TOUCH_TOL = 1e-11
#: Samples of the march to the first exit for centres above the sheet plane.
_MARCH = 32
#: With at least :data:`_MARCH_SPLIT` rays to march, their samples are evaluated in these chunks
#: (ends, exclusive), a ray's later chunks only while it has not met a sample where the ball does
#: not fit: the first such sample is all the march keeps, so the result is the same as from all
#: 32 (4–12 fewer closest points a ray where the rim is 60–80 % of the way out, as on the tests'
#: pyramids and domes). Fewer rays take one call: a closest-point call costs ~1,000 points.
_MARCH_CHUNKS = (16, 20, 24, 28, _MARCH)
_MARCH_SPLIT = 1024
#: Coarse rays per lap for the arc-length estimate.
_N_COARSE = 128
#: How far a centre on a flat face is moved out along its ray to find the wall it also
#: touches [m].
_TIE_NUDGE = 1e-7
_MAX_ITER = 80


def scallop_step(scallop_height: float, tool_radius: float, wall_angle: float) -> float:
    """Tip step Δz [m] between laps that leaves a cusp of ``scallop_height`` [m] on a flat wall
    of ``wall_angle`` [rad] with a ball of ``tool_radius`` [m]: ``2 sin α sqrt(h (2R − h))``."""
    h, R = scallop_height, tool_radius
    return 2.0 * math.sin(wall_angle) * math.sqrt(h * (2.0 * R - h))


def _centre(part: Part, center: tuple[float, float] | None) -> F64:
    if center is not None:
        c = np.asarray(center, dtype=float)
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise InputError("must be two finite numbers (x, y) [m]", field="center")
        return c
    lo, hi = part.bounds
    return 0.5 * (np.asarray(lo, dtype=float)[:2] + np.asarray(hi, dtype=float)[:2])


def _ray_limit(part: Part, c: F64, ux: F64, uy: F64) -> F64:
    """Distance from c along (ux, uy) to the part's bounding box edge (plus 1 mm)."""
    lo, hi = part.bounds
    with np.errstate(divide="ignore"):
        tx = np.where(ux > 0, (hi[0] - c[0]) / ux, np.where(ux < 0, (lo[0] - c[0]) / ux, np.inf))
        ty = np.where(uy > 0, (hi[1] - c[1]) / uy, np.where(uy < 0, (lo[1] - c[1]) / uy, np.inf))
    return np.maximum(np.minimum(tx, ty), 0.0) + 1e-3


def ball_centre_rays(
    part: Part,
    tool_radius: float,
    centre_z: F64,
    angle: F64,
    *,
    center: F64,
    guess: F64 | None = None,
) -> tuple[F64, NDArray[np.bool_]]:
    """Ball-centre distance ``ρ*`` [m] from ``center`` along horizontal rays, and a mask of the
    rays where the ball fits at ``center`` at all.

    Parameters
    ----------
    part : the nominal part
    tool_radius : float, m
    centre_z : (M,) float, m — ball-centre heights
    angle : (M,) float, rad — ray directions about ``center``
    center : (2,) float, m — ray origin (x, y)
    guess : (M,) float, m, optional — a starting ρ (e.g. the previous lap's)

    ``ρ*``: where the ray first leaves ``{d(c + ρu, z_c) ≥ R}``, found by Newton steps on
    ``d − R`` safeguarded by a bisection bracket, to ``|d − R| ≤`` :data:`TOUCH_TOL` (or a
    bracket of :data:`RAY_TOL` where d = R along the ray, e.g. over a flat bottom); where the
    ball does not fit at the origin ρ* is 0 and the mask False.
    """
    R = tool_radius
    zc = np.asarray(centre_z, dtype=float)
    ux, uy = np.cos(angle), np.sin(angle)
    m = zc.shape[0]

    def points(rho: F64, idx: NDArray[np.int64]) -> F64:
        X = np.empty((idx.shape[0], 3))
        X[:, 0] = center[0] + rho * ux[idx]
        X[:, 1] = center[1] + rho * uy[idx]
        X[:, 2] = zc[idx]
        return X

    def query(rho: F64, idx: NDArray[np.int64]) -> tuple[F64, F64]:
        X = points(rho, idx)
        q = part.closest_point(X)
        d = q.distance
        g = X - q.point
        nrm = np.linalg.norm(g, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            slope = np.where(nrm > 0, (g[:, 0] * ux[idx] + g[:, 1] * uy[idx]) / nrm, 0.0)
        return d - R, slope * np.sign(d)

    all_idx = np.arange(m)
    # at ρ = 0 the rays of one height share their point (a lap's rays all of it): query each
    # distinct point (bit for bit) once. This, the march's chunks and the refinement's new chords
    # query points in other batches than one query of all: a part whose closest point moves by
    # rounding with its batch (Pyramid: numpy's matmul of one row sums in another order) gives
    # distances that differ by ~1e-18 m, which only feed comparisons with FIT_TOL and GOUGE_TOL
    X0 = points(np.zeros(m), all_idx)
    _, first, inverse = np.unique(X0.view(np.dtype((np.void, 24))).ravel(), return_index=True,
                                  return_inverse=True)  # fmt: skip
    f0 = part.closest_point(X0[first]).distance[inverse.reshape(-1)] - R
    fits = f0 >= -FIT_TOL
    lo = np.zeros(m)
    hi = _ray_limit(part, center, ux, uy)
    # a centre above (or in) the sheet plane fits again beyond the flange's outer edge, where
    # the modelled sheet ends: march out to the first ray point that does not fit
    high = np.flatnonzero(fits & (zc > -1e-6))
    if high.size:
        frac = np.arange(1, _MARCH + 1) / _MARCH
        rr = hi[high, None] * frac
        no = np.zeros((high.size, _MARCH), dtype=bool)
        left = np.arange(high.size)  # rays that have not met a sample where it does not fit
        start = 0
        for end in _MARCH_CHUNKS if high.size >= _MARCH_SPLIT else (_MARCH,):
            if left.size == 0:
                break
            fm, _ = query(rr[left, start:end].ravel(), np.repeat(high[left], end - start))
            chunk = (fm < -FIT_TOL).reshape(left.size, end - start)
            no[left, start:end] = chunk
            left = left[~chunk.any(axis=1)]
            start = end
        j = np.argmax(no, axis=1)
        anyno = no.any(axis=1)
        hi[high] = np.where(anyno, hi[high] * (j + 1) / _MARCH, hi[high])
        lo[high] = np.where(anyno, hi[high] * j / np.maximum(j + 1, 1), 0.0)
    f_hi, _ = query(hi, all_idx)
    out = f_hi >= -FIT_TOL  # fits up to the box edge (no flange): keep the edge
    x = 0.5 * (lo + hi) if guess is None else np.clip(guess, lo, hi)
    x = np.where((x <= lo) | (x >= hi), 0.5 * (lo + hi), x)
    active = np.flatnonzero(fits & ~out)
    for _ in range(_MAX_ITER):
        if active.size == 0:
            break
        f, s = query(x[active], active)
        ok = f >= -FIT_TOL
        a_ok, a_no = active[ok], active[~ok]
        lo[a_ok] = x[a_ok]
        hi[a_no] = x[a_no]
        # converged: the centre touches (|d − R| ≤ TOUCH_TOL on a descending slope: Newton's
        # root), or the bracket closed (a flat bottom: d = R on a whole interval)
        touch = (np.abs(f) <= TOUCH_TOL) & (s < -1e-3)
        lo[active[touch]] = x[active[touch]]
        done = touch | (hi[active] - lo[active] <= RAY_TOL)
        # Newton from the point just evaluated, kept strictly inside the bracket
        with np.errstate(invalid="ignore", divide="ignore"):
            xn = x[active] - np.where(s < -1e-9, f / s, np.nan)
        a, b = lo[active], hi[active]
        inside = np.isfinite(xn) & (xn > a) & (xn < b)
        x[active] = np.where(inside, xn, 0.5 * (a + b))
        active = active[~done]
    rho = np.where(out, hi, lo)
    return np.where(fits, rho, 0.0), fits


def level_contour(
    part: Part,
    z: float,
    offset: float = 0.0,
    *,
    n: int = 360,
    center: tuple[float, float] | None = None,
) -> F64:
    """Closed horizontal contour (n, 3) [m] at height ``z`` [m] of the part's surface offset by
    ``offset`` [m] to the tool side (0: the nominal's own section; R: the ball centres of a
    ball of radius R, trimmed) — n rays at equal angles about ``center`` (default: the centre
    of ``part.bounds``), counter-clockwise from +x. Same method and limits as the toolpaths
    (module docstring). Raises :class:`InputError` where the centre itself is not on the
    tool side at that height."""
    if not (math.isfinite(offset) and offset >= 0):
        raise InputError(f"must be ≥ 0 m, got {offset:g}", field="offset")
    if n < 3:
        raise InputError(f"need at least 3 points, got {n}", field="n")
    c = _centre(part, center)
    phi = 2.0 * math.pi * np.arange(n) / n
    rho, fits = ball_centre_rays(part, offset, np.full(n, float(z)), phi, center=c)
    if not fits.all():
        raise InputError(
            f"at z = {z * 1e3:g} mm the centre ({c[0] * 1e3:g}, {c[1] * 1e3:g}) mm is not "
            f"{offset * 1e3:g} mm on the tool side of the part",
            field="z",
        )
    return np.c_[c[0] + rho * np.cos(phi), c[1] + rho * np.sin(phi), np.full(n, float(z))]


@dataclass
class _Laps:
    """Laps as parameter ranges. Lap k runs over u ∈ [0, 1]: φ = φ0 ± 2πu, tip height
    ``z0 + u (z1 − z0)``. A step-down lap also owns its step down from the lap above along the
    start ray, u ∈ (−1, 0): φ = φ0, tip height ``z0 + (−u)(zprev − z0)``; its points are only
    made where the straight step would cut into the nominal (over a convex edge)."""

    z0: F64
    z1: F64
    zprev: F64
    spiral: bool


class _Slicer:
    def __init__(
        self,
        part: Part,
        R: float,
        center: F64,
        start_angle: float,
        clockwise: bool,
    ) -> None:
        self.part, self.R, self.c = part, R, center
        self.phi0, self.sign = start_angle, (-1.0 if clockwise else 1.0)

    def centres(
        self, lap: NDArray[np.int64], u: F64, laps: _Laps, guess: F64 | None = None
    ) -> tuple[F64, F64, NDArray[np.bool_]]:
        phi = self.phi0 + self.sign * 2.0 * math.pi * np.maximum(u, 0.0)
        z_tip = np.where(
            u >= 0,
            laps.z0[lap] + u * (laps.z1[lap] - laps.z0[lap]),
            laps.z0[lap] - u * (laps.zprev[lap] - laps.z0[lap]),
        )
        # a tip exactly in the sheet plane lets the ball rest anywhere on the flange: 1 nm below
        z_tip = np.minimum(z_tip, -1e-9)
        rho, fits = ball_centre_rays(
            self.part, self.R, z_tip + self.R, phi, center=self.c, guess=guess
        )
        C = np.empty((rho.shape[0], 3))
        C[:, 0] = self.c[0] + rho * np.cos(phi)
        C[:, 1] = self.c[1] + rho * np.sin(phi)
        C[:, 2] = z_tip + self.R
        return C, rho, fits

    def sample(self, laps: _Laps, spacing: float) -> tuple[NDArray[np.int64], F64, F64]:
        """(lap, u, centre) of every point: chords of the centre path ≤ spacing, and no chord
        closer than R − GOUGE_TOL to the nominal at its midpoint."""
        n = laps.z0.shape[0]
        # coarse pass: arc length of each lap's centre path as a function of u
        uc = np.arange(_N_COARSE + 1) / _N_COARSE
        lap_c = np.repeat(np.arange(n), uc.size)
        u_c = np.tile(uc, n)
        Cc, rho_c, _ = self.centres(lap_c, u_c, laps)
        Cc = Cc.reshape(n, uc.size, 3)
        rho_c = rho_c.reshape(n, uc.size)
        seg = np.linalg.norm(np.diff(Cc, axis=1), axis=2)
        s_c = np.concatenate([np.zeros((n, 1)), np.cumsum(seg, axis=1)], axis=1)
        lap_l, u_l, g_l = [], [], []
        for k in range(n):
            L = s_c[k, -1]
            m = max(8, math.ceil(L / spacing * 1.02))
            # a spiral ramp ends where the next one starts: its end point belongs to the next
            end = 0 if laps.spiral and k < n - 1 else 1
            targets = np.arange(m + end) / m * L
            uk = np.interp(targets, s_c[k], uc) if L > 0 else np.arange(m + end) / m
            lap_l.append(np.full(uk.size, k, dtype=np.int64))
            u_l.append(uk)
            g_l.append(np.interp(uk, uc, rho_c[k]))
        lap = np.concatenate(lap_l)
        u = np.concatenate(u_l)
        C, _, _ = self.centres(lap, u, laps, np.concatenate(g_l))
        # refine the path (every chord between consecutive points, laps and steps included); a
        # chord between two points that were neighbours before the last insertion keeps its
        # length and midpoint distance, only the new chords are measured
        chord = np.linalg.norm(np.diff(C, axis=0), axis=1)
        d_mid = self.part.signed_distance(0.5 * (C[1:] + C[:-1]))
        src: NDArray[np.int64] | None = None  # each point's index before the last insertion
        for _ in range(20):
            if src is not None:
                a, b = src[:-1], src[1:]
                kept = (a >= 0) & (b == a + 1)
                chord, d_mid = chord[np.where(kept, a, 0)], d_mid[np.where(kept, a, 0)]
                redo = np.flatnonzero(~kept)
                C0, C1 = C[redo], C[redo + 1]
                chord[redo] = np.linalg.norm(C1 - C0, axis=1)
                d_mid[redo] = self.part.signed_distance(0.5 * (C1 + C0))
            bad = np.flatnonzero((chord > spacing) | (d_mid < self.R - GOUGE_TOL))
            if bad.size == 0:
                break
            la, ua, lb, ub = lap[bad], u[bad], lap[bad + 1], u[bad + 1]
            same = la == lb
            if laps.spiral:  # the ramp of lap a runs on to u = 1 (the next lap's start)
                l_new, u_new = la, np.where(same, 0.5 * (ua + ub), 0.5 * (ua + 1.0))
            else:  # the step from lap a's end (u = 1 ≡ lap b's u = −1) down to lap b's start
                l_new = lb
                u_new = np.where(same, 0.5 * (ua + ub), 0.5 * (-1.0 + ub))
            C_new, _, _ = self.centres(l_new, u_new, laps)
            key = np.r_[3.0 * lap + u, 3.0 * l_new + u_new]
            order = np.argsort(key, kind="stable")
            src = np.r_[np.arange(lap.size), np.full(l_new.size, -1)][order]
            lap = np.r_[lap, l_new][order]
            u = np.r_[u, u_new][order]
            C = np.r_[C, C_new][order]
        return lap, u, C


def _check(part: Part, R: float, step: float, spacing: float, feed: float) -> None:
    for name, v in (("tool_radius", R), ("step_down", step), ("spacing", spacing), ("feed", feed)):
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"must be > 0, got {v:g} (SI)", field=name)
    if not part.depth > 0:
        raise InputError(
            "the part does not reach below the sheet plane z = 0; give its surface in the work "
            "frame (sheet plane z = 0, part below, tool along +z)",
            field="part",
        )
    if step > part.depth:
        raise InputError(
            f"step-down {step * 1e3:g} mm is larger than the part depth {part.depth * 1e3:g} mm",
            field="step_down",
        )


def _min_wall_angle(slicer: _Slicer, z_tip: float) -> float:
    """Smallest wall angle [rad] at the contacts of the lap at tip height ``z_tip`` (contacts
    within 1° of horizontal — the flange, a flat bottom — are ignored unless all are)."""
    uc = np.arange(_N_COARSE) / _N_COARSE
    laps = _Laps(np.array([z_tip]), np.array([z_tip]), np.array([z_tip]), spiral=False)
    C, _, _ = slicer.centres(np.zeros(uc.size, dtype=np.int64), uc, laps)
    q = slicer.part.closest_point(C)
    n = (C - q.point) / slicer.R
    alpha = np.arccos(np.clip(n[:, 2], -1.0, 1.0))
    steep = alpha > math.radians(1.0)
    return float(alpha[steep].min()) if steep.any() else 0.0


def _levels(
    slicer: _Slicer,
    step: float,
    scallop_height: float | None,
    min_step: float,
) -> tuple[F64, bool]:
    """Tip heights [m] of the laps, top to bottom, and whether the path stops above the depth."""
    part, R = slicer.part, slicer.R
    depth = part.depth
    if scallop_height is None:
        n = math.ceil(depth / step - 1e-9)
        z = -np.arange(1, n + 1, dtype=float) * step
        z[-1] = -depth
    else:
        if not (math.isfinite(scallop_height) and 0 < scallop_height < R):
            raise InputError(
                f"must be in (0, R = {R * 1e3:g} mm), got {scallop_height * 1e3:g} mm",
                field="scallop_height",
            )
        if not (math.isfinite(min_step) and 0 < min_step <= step):
            raise InputError("must be > 0 and ≤ step_down", field="min_step")
        zs: list[float] = []
        zk = 0.0
        angles: dict[float, float] = {}  # the corrector's height is most often the next lap's

        def min_wall_angle(z_tip: float) -> float:
            if z_tip not in angles:
                angles[z_tip] = _min_wall_angle(slicer, z_tip)
            return angles[z_tip]

        while zk > -depth + 1e-9:
            a = min_wall_angle(zk) if zs else min_wall_angle(-min_step)
            dz = min(max(scallop_step(scallop_height, R, a), min_step), step)
            # corrector: the wall may be shallower at the next lap
            a2 = min_wall_angle(max(zk - dz, -depth))
            if a2 < a:
                dz = min(max(scallop_step(scallop_height, R, a2), min_step), step)
            zk = max(zk - dz, -depth)
            if zk - (-depth) < 1e-9:
                zk = -depth
            zs.append(zk)
        z = np.array(zs)
    c = slicer.c
    fits = part.signed_distance(np.c_[np.tile(c, (z.size, 1)), z + R]) >= R - FIT_TOL
    if not fits[0]:
        raise InputError(
            f"a Ø{2 * R * 1e3:g} mm ball does not fit in this part even at the first level "
            f"(tip z = {z[0] * 1e3:g} mm, centre ({c[0] * 1e3:g}, {c[1] * 1e3:g}) mm)",
            field="tool_radius",
        )
    truncated = not bool(fits.all())
    if truncated:
        z = z[: int(np.argmin(fits))]
    return z, truncated


def _assemble(
    slicer: _Slicer,
    lap: NDArray[np.int64],
    C: F64,
    feed: float,
    meta: dict[str, object],
) -> Toolpath:
    q = slicer.part.closest_point(C)
    d = np.linalg.norm(C - q.point, axis=1)
    normal = (C - q.point) / d[:, None]
    # a ball that touches a flat face below the sheet (a flat bottom) and a wall at once — the
    # last lap, at the full depth — forms the wall: the ray stopped there because of it. The
    # closest point of the two is a tie that fell on the flat face (wall angle 0, so no forming
    # force: a pyramid's last lap read 662 N → 0 N → 662 N between neighbouring points). The
    # wall's contact is the closest point of the centre moved a hair outward along its ray,
    # moved back along the wall by the same hair (exact on a plane, O(nudge²/radius) on a curve)
    P = q.point.copy()
    flat = (normal[:, 2] > math.cos(math.radians(1.0))) & (q.point[:, 2] < -1e-6)
    if flat.any():
        u = np.zeros((int(flat.sum()), 3))
        u[:, :2] = C[flat, :2] - slicer.c
        u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-300)
        Pn = slicer.part.closest_point(C[flat] + _TIE_NUDGE * u).point
        g = C[flat] + _TIE_NUDGE * u - Pn
        nw = g / np.maximum(np.linalg.norm(g, axis=1), 1e-300)[:, None]
        Pw = Pn - _TIE_NUDGE * (u - np.einsum("ij,ij->i", u, nw)[:, None] * nw)
        dw = np.linalg.norm(C[flat] - Pw, axis=1)
        wall = (nw[:, 2] < math.cos(math.radians(1.0))) & (np.abs(dw - slicer.R) < 10 * _TIE_NUDGE)
        idx = np.flatnonzero(flat)[wall]
        P[idx] = Pw[wall]
        normal[idx] = (C[idx] - Pw[wall]) / dw[wall][:, None]
    wall_angle = np.arccos(np.clip(normal[:, 2], -1.0, 1.0))
    return Toolpath.from_contact(P, normal, wall_angle, lap, slicer.R, feed, meta)


def _meta(
    kind: str, part: Part, step: float, spacing: float, z: F64, trunc: bool, h: float | None
) -> dict[str, object]:
    meta: dict[str, object] = {
        "kind": kind,
        "step_down": step,
        "spacing": spacing,
        "part": part.kind,
        "slicer": "ball-centre offset",
    }
    if h is not None:
        meta["scallop_height"] = h
    if trunc:
        meta["truncated"] = True
        meta["reachable_tip_z"] = float(z[-1])
    return meta


def estimate_sliced_points(part: Part, step_down: float, spacing: float) -> int:
    """Upper estimate of a sliced path's points, before slicing: ``ceil(depth / step_down)`` laps
    (with a scallop height the steps are at most ``step_down``, so there may be more laps) of at
    most the perimeter of the part's bounding rectangle over ``spacing`` each (every lap lies
    inside the opening). Cost: nothing, whatever the step."""
    lo, hi = part.bounds
    laps = math.ceil(part.depth / step_down - 1e-9) + 1
    per_lap = max(8.0, 2.0 * float((hi[0] - lo[0]) + (hi[1] - lo[1])) / spacing)
    return math.ceil(laps * per_lap)


def sliced_step_down(
    part: Part,
    tool_radius: float = 5e-3,
    step_down: float = 0.5e-3,
    *,
    scallop_height: float | None = None,
    min_step: float = 0.01e-3,
    spacing: float = 1e-3,
    feed: float = DEFAULT_FEED,
    start_angle: float = 0.0,
    clockwise: bool = False,
    center: tuple[float, float] | None = None,
    max_points: int | None = MAX_POINTS,
) -> Toolpath:
    """Z-level contour toolpath on any part (see the module docstring).

    Parameters
    ----------
    part : any :class:`~roboisf.parts.Part`
    tool_radius : float, m — ball radius
    step_down : float, m — Δz between laps (with ``scallop_height``: the largest Δz)
    scallop_height : float, m, optional — choose Δz per lap for this cusp height instead
    min_step : float, m — smallest Δz of the scallop-driven spacing
    spacing : float, m — max. chord of the ball-centre (tip) path between points
    feed : float, m/s
    start_angle : float, rad — direction (about ``center``) of each lap's first point
    clockwise : bool — direction of travel seen from above (+z)
    center : (x, y) m, optional — origin of the rays (default: centre of ``part.bounds``)
    max_points : int or None — refuse (:class:`InputError`, before slicing) a path estimated
        above this many points (:func:`estimate_sliced_points`); None: no limit
    """
    _check(part, tool_radius, step_down, spacing, feed)
    refuse_size(estimate_sliced_points(part, step_down, spacing), part.depth, step_down, spacing,
                max_points)  # fmt: skip
    slicer = _Slicer(part, tool_radius, _centre(part, center), start_angle, clockwise)
    z, trunc = _levels(slicer, step_down, scallop_height, min_step)
    laps = _Laps(z, z, np.r_[0.0, z[:-1]], spiral=False)
    lap, _, C = slicer.sample(laps, spacing)
    meta = _meta("step_down", part, step_down, spacing, z, trunc, scallop_height)
    return _assemble(slicer, lap, C, feed, meta)


def sliced_spiral(
    part: Part,
    tool_radius: float = 5e-3,
    step_down: float = 0.5e-3,
    *,
    scallop_height: float | None = None,
    min_step: float = 0.01e-3,
    spacing: float = 1e-3,
    feed: float = DEFAULT_FEED,
    start_angle: float = 0.0,
    clockwise: bool = False,
    center: tuple[float, float] | None = None,
    max_points: int | None = MAX_POINTS,
) -> Toolpath:
    """Continuous spiral on any part: within lap k the tip descends linearly from the height of
    lap k − 1 (0 for the first) to that of lap k; a final closed contour at the last height
    finishes the bottom edge. Same parameters as :func:`sliced_step_down`."""
    _check(part, tool_radius, step_down, spacing, feed)
    refuse_size(estimate_sliced_points(part, step_down, spacing), part.depth, step_down, spacing,
                max_points)  # fmt: skip
    slicer = _Slicer(part, tool_radius, _centre(part, center), start_angle, clockwise)
    z, trunc = _levels(slicer, step_down, scallop_height, min_step)
    z0 = np.r_[0.0, z[:-1], z[-1]]
    z1 = np.r_[z, z[-1]]
    laps = _Laps(z0, z1, z0, spiral=True)
    lap, _, C = slicer.sample(laps, spacing)
    lap = np.minimum(lap, z.size - 1)  # the closing contour belongs to the last lap
    meta = _meta("spiral", part, step_down, spacing, z, trunc, scallop_height)
    return _assemble(slicer, lap, C, feed, meta)
