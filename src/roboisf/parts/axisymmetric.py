"""Nominal geometry of axisymmetric ISF parts: cone, variable-wall-angle cone (VWACF), profile.

Work frame: origin at the blank centre in the sheet plane, z along the tool axis pointing up,
part below (z ≤ 0). All lengths in m and angles in rad here; the TOML/CLI edge speaks mm and deg.

The nominal surface is the **tool-side surface** of the sheet (the surface the ball touches).
Its normal ``n`` points to the tool side (away from the material). Signed distances are positive
on the tool side.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf import jit
from roboisf.errors import InputError
from roboisf.parts.base import Symmetry
from roboisf.parts.defaults import PAPER_SHEET_THICKNESS, VWACF_DEFAULT_ARC_RADIUS
from roboisf.parts.generatrix import Arc, Generatrix, Segment

__all__ = [
    "PAPER_SHEET_THICKNESS",
    "VWACF",
    "AxisymmetricPart",
    "Cone",
    "ProfilePart",
    "SurfaceQuery",
    "sine_law_thickness",
]

F64 = NDArray[np.float64]


REGION_CODES = {"flange": 0, "wall": 1, "bottom": 2}


def _compiled(backend: str) -> bool:
    """Whether a closest-point query with ``backend`` (checked) runs the compiled kernel in
    this process: "numba" always (with numba installed), "auto" once the kernels are built —
    their C form (:mod:`roboisf.jit.native`), numba needed or not, or numba's cache
    (:func:`roboisf.jit.ready`). The compiled kernel runs its C form where it is built."""
    backend = jit.check_backend(backend)
    if backend == "numba":
        return jit.HAVE_NUMBA
    return backend == "auto" and jit.ready("mesh")


def sine_law_thickness(wall_angle: ArrayLike, t0: float) -> F64:
    """Sine-law wall thickness ``t = t0 · cos α`` [m] for wall angle α [rad]."""
    return t0 * np.cos(np.asarray(wall_angle, dtype=float))


@dataclass(frozen=True)
class SurfaceQuery:
    """Result of a closest-point query, one row per query point.

    Attributes
    ----------
    point : (N, 3) float, m — closest point on the nominal surface (work frame)
    normal : (N, 3) float — unit tool-side normal there
    distance : (N,) float, m — signed distance of the query point (+ on the tool side)
    wall_angle : (N,) float, rad — local wall angle at the closest point
    depth : (N,) float, m — ``−z`` of the closest point
    s : (N,) float, m — arc length along the generatrix from the top of the wall
    region : (N,) int — 0 flange, 1 wall, 2 bottom
    """

    point: F64
    normal: F64
    distance: F64
    wall_angle: F64
    depth: F64
    s: F64
    region: NDArray[np.int64]


def query_buffers(n: int) -> tuple[F64, F64, F64, F64, F64, NDArray[np.int64]]:
    """Uninitialised arrays for a compiled closest-point kernel to fill for ``n`` points: foot
    (n, 3), normal (n, 3), signed distance, wall angle, arc length (n,) and region (n,) int64
    (:mod:`roboisf.parts.axisym_kernel`, :mod:`roboisf.parts.pyramid_kernel`)."""
    return (
        np.empty((n, 3)),
        np.empty((n, 3)),
        np.empty(n),
        np.empty(n),
        np.empty(n),
        np.empty(n, dtype=np.int64),
    )


@dataclass(frozen=True)
class AxisymmetricPart:
    """Base of the axisymmetric parts. Subclasses build :attr:`generatrix`."""

    kind: ClassVar[str] = "axisymmetric"
    sheet_thickness: float = field(default=PAPER_SHEET_THICKNESS, kw_only=True)
    flange_width: float = field(default=10e-3, kw_only=True)

    @property
    def generatrix(self) -> Generatrix:  # pragma: no cover - abstract
        raise NotImplementedError

    @property
    def opening_radius(self) -> float:
        return float(self.generatrix.wall_at_s(0.0)[0][0])

    @property
    def depth(self) -> float:
        """Depth of the wall's bottom below the sheet plane [m] (positive)."""
        return -self.generatrix.wall_bottom_z

    @property
    def bounds(self) -> tuple[F64, F64]:
        """Lower and upper corners (3,) [m] of the surface (flange included)."""
        g = self.generatrix
        r_max = max(self.opening_radius + self.flange_width, self.opening_radius)
        lo = np.array([-r_max, -r_max, g.wall_bottom_z])
        return lo, np.array([r_max, r_max, 0.0])

    @property
    def symmetry(self) -> Symmetry:
        """A surface of revolution: continuous symmetry about z."""
        return Symmetry(0)

    def _check_common(self) -> None:
        if not (self.sheet_thickness > 0 and math.isfinite(self.sheet_thickness)):
            raise InputError(
                f"must be > 0 mm, got {self.sheet_thickness * 1e3:g}", field="sheet_thickness"
            )
        if not (self.flange_width >= 0 and math.isfinite(self.flange_width)):
            raise InputError(
                f"must be ≥ 0 mm, got {self.flange_width * 1e3:g}", field="flange_width"
            )

    def _with_flange_and_bottom(self, wall: Sequence[Segment | Arc]) -> Generatrix:
        """Wrap wall primitives with the flange (z = 0 outside the opening) and flat bottom."""
        prims: list[Segment | Arc] = []
        regions: list[str] = []
        r_top, _, _ = wall[0].at(np.array([0.0]))
        r_bot, z_bot, _ = wall[-1].at(np.array([wall[-1].length]))
        if self.flange_width > 0:
            prims.append(Segment(float(r_top[0]) + self.flange_width, 0.0, float(r_top[0]), 0.0))
            regions.append("flange")
        prims.extend(wall)
        regions.extend(["wall"] * len(wall))
        if r_bot[0] > 0:
            prims.append(Segment(float(r_bot[0]), float(z_bot[0]), 0.0, float(z_bot[0])))
            regions.append("bottom")
        return Generatrix(tuple(prims), tuple(regions))

    # -- queries ------------------------------------------------------------------------------
    def closest_point(self, points: ArrayLike, *, backend: str = "auto") -> SurfaceQuery:
        """Exact closest point on the nominal surface for each of ``points`` (N, 3) [m].

        ``backend``: ``"auto"`` (the compiled kernel of :mod:`roboisf.parts.axisym_kernel` —
        its C form when built, else numba's once cached: :func:`roboisf.jit.ready` — else
        numpy), ``"numba"`` (compiled) or ``"numpy"``; the same numbers to rounding
        (1e-12 m)."""
        X = np.atleast_2d(np.asarray(points, dtype=float))
        if X.ndim != 2 or X.shape[-1] != 3:
            raise InputError(f"points must have shape (N, 3), got {X.shape}")
        g = self.generatrix
        if _compiled(backend):
            from roboisf.parts import axisym_kernel

            P, N, signed, alpha, s, region = axisym_kernel.closest(
                X, axisym_kernel.pack(g, REGION_CODES)
            )
            return SurfaceQuery(P, N, signed, alpha, -P[:, 2], s, region)
        r = np.hypot(X[:, 0], X[:, 1])
        rp, zp, alpha, s, idx = g.closest(r, X[:, 2])
        # the meridian's direction (cos φ, sin φ) = (x, y)/r; (1, 0) on the axis, as arctan2
        # gives φ = 0 there (two divisions instead of an arctan2, a cos and a sin a point)
        on_axis = r == 0.0
        rr = np.where(on_axis, 1.0, r)
        c = np.where(on_axis, 1.0, X[:, 0] / rr)
        sn = X[:, 1] / rr
        P = np.stack([rp * c, rp * sn, zp], axis=1)
        nr, nz = -np.sin(alpha), np.cos(alpha)
        N = np.stack([nr * c, nr * sn, nz], axis=1)
        dist = np.hypot(r - rp, X[:, 2] - zp)
        side = (r - rp) * nr + (X[:, 2] - zp) * nz
        signed = np.where(side < 0, -dist, dist)
        codes = np.array([REGION_CODES[x] for x in g.regions], dtype=np.int64)
        return SurfaceQuery(P, N, signed, alpha, -zp, s, codes[idx])

    def signed_distance(self, points: ArrayLike) -> F64:
        """Signed distance [m] of ``points`` (N, 3) to the nominal surface (+ on the tool side)."""
        return self.closest_point(points).distance

    def wall_at_z(self, z: ArrayLike) -> tuple[F64, F64]:
        """Radius [m] and wall angle [rad] of the wall at height ``z`` [m] (z ≤ 0)."""
        g = self.generatrix
        r, _, a = g.wall_at_s(g.wall_s_at_z(z))
        return r, a

    def thickness(self, wall_angle: ArrayLike) -> F64:
        """Sine-law thickness [m] for wall angles [rad]."""
        return sine_law_thickness(wall_angle, self.sheet_thickness)

    def surface_grid(self, n_s: int = 200, n_phi: int = 360) -> tuple[F64, F64]:
        """Points (n_s·n_phi, 3) [m] and normals on the wall, for plots and synthetic scans."""
        g = self.generatrix
        s = np.linspace(0.0, g.wall_length, n_s)
        r, z, a = g.wall_at_s(s)
        phi = np.linspace(0.0, 2 * np.pi, n_phi, endpoint=False)
        R, P = np.meshgrid(r, phi, indexing="ij")
        Z = np.broadcast_to(z[:, None], R.shape)
        A = np.broadcast_to(a[:, None], R.shape)
        pts = np.stack([R * np.cos(P), R * np.sin(P), Z], axis=-1).reshape(-1, 3)
        nrm = np.stack(
            [-np.sin(A) * np.cos(P), -np.sin(A) * np.sin(P), np.cos(A)], axis=-1
        ).reshape(-1, 3)
        return pts, nrm

    def to_dict(self) -> dict[str, object]:  # pragma: no cover - overridden
        raise NotImplementedError


def _positive(name: str, value: float, unit: str = "mm", scale: float = 1e3) -> None:
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"must be > 0 {unit}, got {value * scale:g}", field=name)


@dataclass(frozen=True)
class Cone(AxisymmetricPart):
    """Constant-wall-angle truncated cone.

    Parameters
    ----------
    opening_diameter : float, m — diameter of the wall at the sheet plane (paper: 87 mm)
    wall_angle : float, rad — angle between wall and sheet plane, in (0, 90°) (paper: 71°)
    depth : float, m — depth of the wall (paper: 102.97 mm)
    """

    kind: ClassVar[str] = "cone"
    opening_diameter: float = 87e-3
    wall_angle: float = math.radians(71.0)
    depth: float = 102.97e-3

    def __post_init__(self) -> None:
        self._check_common()
        _positive("opening_diameter", self.opening_diameter)
        _positive("depth", self.depth)
        if not (0 < self.wall_angle < math.pi / 2):
            raise InputError(
                f"must be in (0, 90) deg for a cone, got {math.degrees(self.wall_angle):g}",
                field="wall_angle",
            )
        r_bottom = self.opening_diameter / 2 - self.depth / math.tan(self.wall_angle)
        if r_bottom < 0:
            raise InputError(
                f"a {math.degrees(self.wall_angle):g}° cone of Ø{self.opening_diameter * 1e3:g} mm "
                "reaches the axis at "
                f"{self.opening_diameter / 2 * math.tan(self.wall_angle) * 1e3:.3f}"
                f" mm depth; depth {self.depth * 1e3:g} mm is too deep",
                field="depth",
            )

    @property
    def generatrix(self) -> Generatrix:
        r0 = self.opening_diameter / 2
        r1 = r0 - self.depth / math.tan(self.wall_angle)
        return self._with_flange_and_bottom([Segment(r0, 0.0, r1, -self.depth)])

    def to_dict(self) -> dict[str, object]:
        return {
            "kind": "cone",
            "opening_diameter": self.opening_diameter * 1e3,
            "wall_angle": math.degrees(self.wall_angle),
            "depth": self.depth * 1e3,
            "sheet_thickness": self.sheet_thickness * 1e3,
            "flange_width": self.flange_width * 1e3,
        }


@dataclass(frozen=True)
class VWACF(AxisymmetricPart):
    """Variable-wall-angle conical frustum: a circular-arc generatrix tangent to the sheet at the
    rim, so the wall angle grows from 0 at the opening to ``final_wall_angle``.

    Parameters
    ----------
    opening_diameter : float, m — paper: 88.15 mm
    arc_radius : float, m — radius of the generatrix arc (default 39 mm, a documented assumption)
    final_wall_angle : float, rad — in (0, 90°] (paper: 90°)
    Depth follows: ``arc_radius · (1 − cos final_wall_angle)``.
    """

    kind: ClassVar[str] = "vwacf"
    opening_diameter: float = 88.15e-3
    arc_radius: float = VWACF_DEFAULT_ARC_RADIUS
    final_wall_angle: float = math.radians(90.0)

    def __post_init__(self) -> None:
        self._check_common()
        _positive("opening_diameter", self.opening_diameter)
        _positive("arc_radius", self.arc_radius)
        if not (0 < self.final_wall_angle <= math.pi / 2 + 1e-12):
            raise InputError(
                f"must be in (0, 90] deg, got {math.degrees(self.final_wall_angle):g}",
                field="final_wall_angle",
            )
        r_bottom = self.opening_diameter / 2 - self.arc_radius * math.sin(self.final_wall_angle)
        if r_bottom < 0:
            raise InputError(
                f"arc of {self.arc_radius * 1e3:g} mm crosses the axis of a "
                f"Ø{self.opening_diameter * 1e3:g} mm opening; must be ≤ "
                f"{self.opening_diameter / 2 / math.sin(self.final_wall_angle) * 1e3:.3f} mm",
                field="arc_radius",
            )

    @property
    def generatrix(self) -> Generatrix:
        r0 = self.opening_diameter / 2
        arc = Arc(r0, -self.arc_radius, self.arc_radius, 0.0, self.final_wall_angle)
        return self._with_flange_and_bottom([arc])

    def to_dict(self) -> dict[str, object]:
        return {
            "kind": "vwacf",
            "opening_diameter": self.opening_diameter * 1e3,
            "arc_radius": self.arc_radius * 1e3,
            "final_wall_angle": math.degrees(self.final_wall_angle),
            "sheet_thickness": self.sheet_thickness * 1e3,
            "flange_width": self.flange_width * 1e3,
        }


@dataclass(frozen=True)
class ProfilePart(AxisymmetricPart):
    """Any axisymmetric part from a polyline generatrix ``(r, z)`` [m], rim first.

    The polyline must start in the sheet plane region (z ≤ 0), never go up (z non-increasing),
    stay at r ≥ 0, and have wall angles in [0, 90°] (r non-increasing). ``source`` records the
    file it came from (for the TOML round trip).
    """

    kind: ClassVar[str] = "profile"
    r: tuple[float, ...] = ()
    z: tuple[float, ...] = ()
    source: str | None = None

    def __post_init__(self) -> None:
        self._check_common()
        r = np.asarray(self.r, dtype=float)
        z = np.asarray(self.z, dtype=float)
        where = self.source
        if r.shape != z.shape or r.size < 2:
            raise InputError("profile needs at least two (r, z) points", file=where)
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(z))):
            raise InputError("profile has NaN or inf coordinates", file=where)
        if np.any(r < 0):
            i = int(np.argmax(r < 0))
            raise InputError(f"point {i + 1} crosses the axis (r < 0)", file=where, line=i + 2)
        if np.any(z > 1e-12):
            i = int(np.argmax(z > 1e-12))
            raise InputError(
                f"point {i + 1} is above the sheet plane (z > 0)", file=where, line=i + 2
            )
        dz = np.diff(z)
        dr = np.diff(r)
        if np.any(dz > 0):
            i = int(np.argmax(dz > 0)) + 1
            raise InputError(f"generatrix goes up at point {i + 1}", file=where, line=i + 2)
        if np.any(dr > 0):
            i = int(np.argmax(dr > 0)) + 1
            raise InputError(
                f"generatrix turns outwards at point {i + 1} (wall angle > 90°, an overhang a "
                "vertical tool cannot form)",
                file=where,
                line=i + 2,
            )
        if np.any(np.hypot(dr, dz) == 0):
            i = int(np.argmax(np.hypot(dr, dz) == 0)) + 1
            raise InputError(f"point {i + 1} repeats the previous one", file=where, line=i + 2)
        if z[-1] >= z[0]:
            raise InputError("generatrix has no depth (last z equals first z)", file=where)

    @property
    def generatrix(self) -> Generatrix:
        segs = [
            Segment(self.r[i], self.z[i], self.r[i + 1], self.z[i + 1])
            for i in range(len(self.r) - 1)
        ]
        return self._with_flange_and_bottom(segs)

    def to_dict(self) -> dict[str, object]:
        d: dict[str, object] = {
            "kind": "profile",
            "sheet_thickness": self.sheet_thickness * 1e3,
            "flange_width": self.flange_width * 1e3,
        }
        if self.source is not None:
            d["file"] = self.source
        else:
            d["r"] = [v * 1e3 for v in self.r]
            d["z"] = [v * 1e3 for v in self.z]
        return d
