"""What the CAM program readers return: the machine moves of a program, in order, in SI.

A CAM program (ISO G-code, Sinumerik, APT/CL data, a bare point list) is read into
:class:`CamMoves` — one row per straight move, arcs already linearised — by its dialect's reader
(:mod:`roboisf.cam.gcode`, :mod:`roboisf.cam.sinumerik`, :mod:`roboisf.cam.apt`,
:mod:`roboisf.cam.xyz`). :func:`roboisf.toolpath.importer.import_toolpath` turns the moves into a
roboisf toolpath against the nominal part. :func:`arc_points` is the one arc lineariser the
readers share.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError

__all__ = [
    "DEFAULT_CHORD_TOL",
    "FEED",
    "RAPID",
    "CamMoves",
    "MoveList",
    "ReadOptions",
    "arc_center_from_radius",
    "arc_points",
]

F64 = NDArray[np.float64]

#: Move kinds.
RAPID, FEED = 0, 1

#: Accepted difference of the start and end radius of an arc [m] (or 0.1 % of the radius).
ARC_RADIUS_TOL = 10e-6
#: Default chord tolerance of linearised arcs [m] (1 µm, the resolution of roboisf's programs).
DEFAULT_CHORD_TOL = 1e-6


@dataclass(frozen=True)
class ReadOptions:
    """How a CAM reader interprets what a program leaves open.

    Attributes
    ----------
    chord_tol : float, m — arcs are linearised so that no chord is farther than this from the arc
    work_offsets : dict[str, (3,) float] — values [m] of the work offsets (``G54`` … ``G59``, also
        Sinumerik ``G505`` …) in machine coordinates; a program that switches offsets has its
        points moved into the frame of the offset active at its first move. Without values the
        coordinates are taken as they are, with a warning.
    ignore_words : frozenset[str] — address letters a 3-axis path cannot use (``A B C U V W``)
        to ignore with a one-line warning (listing the lines) instead of refusing the file
    feed : float or None, m/s — the feed of feed moves before the program's first F word (a
        program posted without feeds); None: such a move is refused, naming its line
    """

    chord_tol: float = DEFAULT_CHORD_TOL
    work_offsets: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    ignore_words: frozenset[str] = frozenset()
    feed: float | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.chord_tol) and self.chord_tol > 0):
            raise InputError(
                f"must be > 0 mm, got {self.chord_tol * 1e3:g}", field="chord_tolerance"
            )


@dataclass(frozen=True)
class CamMoves:
    """The moves of a CAM program (work frame, SI).

    Attributes
    ----------
    point : (M, 3) float, m — end point of each move as the program names it (ball tip or centre;
        the importer's ``point`` option says which); NaN for an axis at an unknown position (after
        a reference-point return ``G28`` / ``GOHOME``, or a machine-coordinate move)
    kind : (M,) int — :data:`RAPID` (positioning) or :data:`FEED` (a move at the feed)
    feed : (M,) float, m/s — feed of each feed move (NaN for rapids)
    line : (M,) int — 1-based source line of each move
    dwell : (M,) float, s — dwell programmed before the move where its unit is unambiguous
        (G04 X/U, Sinumerik G4 F; Fanuc/LinuxCNC G04 P differ, ms or s: not recorded); not
        counted in the toolpath times
    tool_axis : (M, 3) float or None — programmed tool axis (APT TLAXIS, x,y,z,i,j,k lists)
    notes : list[str] — what was read but has no effect on the path (M codes, modes), one line each
    warnings : list[str] — what the user must know (ignored words, unknown offsets), one line each
    meta : dict — dialect, units, program number, work offsets, tools …
    """

    path: Path
    point: F64
    kind: NDArray[np.int64]
    feed: F64
    line: NDArray[np.int64]
    dwell: F64
    tool_axis: F64 | None = None
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    meta: dict[str, object] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.point.shape[0])


class MoveList:
    """Collects moves while a reader interprets a program (see :class:`CamMoves`)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.points: list[F64] = []
        self.kinds: list[int] = []
        self.feeds: list[float] = []
        self.lines: list[int] = []
        self.dwells: list[float] = []
        self.axes: list[F64] = []
        self.pending_dwell = 0.0
        self.notes: list[str] = []
        self.warnings: list[str] = []
        self.meta: dict[str, object] = {}

    def add(
        self,
        points: F64,
        kind: int,
        feed: float,
        line: int,
        axis: F64 | None = None,
    ) -> None:
        """Append moves ending at ``points`` (K, 3) m, all of one kind, feed [m/s] and line."""
        if points.ndim == 1:  # one move (the common case)
            self.points.append(np.array(points, dtype=float))
            self.kinds.append(kind)
            self.feeds.append(feed if kind == FEED else math.nan)
            self.lines.append(line)
            self.dwells.append(self.pending_dwell)
            if axis is not None:
                self.axes.append(np.asarray(axis, dtype=float))
            self.pending_dwell = 0.0
            return
        for k, p in enumerate(points):
            self.points.append(np.asarray(p, dtype=float))
            self.kinds.append(kind)
            self.feeds.append(feed if kind == FEED else math.nan)
            self.lines.append(line)
            self.dwells.append(self.pending_dwell if k == 0 else 0.0)
            if axis is not None:
                self.axes.append(np.asarray(axis, dtype=float))
        self.pending_dwell = 0.0

    def note_once(self, text: str) -> None:
        if text not in self.notes:
            self.notes.append(text)

    def warn_once(self, text: str) -> None:
        if text not in self.warnings:
            self.warnings.append(text)

    def result(self) -> CamMoves:
        if not self.points:
            raise InputError("the program has no moves", file=self.path)
        axes = None
        if self.axes:
            if len(self.axes) != len(self.points):  # pragma: no cover - readers add all or none
                raise AssertionError("tool axis given for some moves only")
            axes = np.array(self.axes)
        return CamMoves(
            path=self.path,
            point=np.array(self.points),
            kind=np.array(self.kinds, dtype=np.int64),
            feed=np.array(self.feeds),
            line=np.array(self.lines, dtype=np.int64),
            dwell=np.array(self.dwells),
            tool_axis=axes,
            notes=self.notes,
            warnings=self.warnings,
            meta=self.meta,
        )


def _unit(v: F64) -> F64:
    return v / np.linalg.norm(v)


def arc_points(
    start: F64,
    end: F64,
    center: F64,
    axis: F64,
    ccw: bool,
    chord_tol: float,
    *,
    file: Path | None = None,
    line: int | None = None,
) -> F64:
    """Linearise a circular (or helical) arc: the points after ``start``, ending at ``end``.

    Parameters
    ----------
    start, end : (3,) float, m — end points of the arc (``end == start``: a full circle)
    center : (3,) float, m — a point on the arc's axis
    axis : (3,) float — unit normal of the arc's plane; the helix advances along it from the
        start's to the end's axial coordinate
    ccw : bool — counter-clockwise seen from the tip of ``axis`` (right-handed about ``axis``)
    chord_tol : float, m — largest distance of a chord from the arc: the angle step is
        ``2 acos(1 − tol/r)``; the result is within ``chord_tol`` of the true arc

    Returns
    -------
    (K, 3) float, m — K ≥ 1 points, the last one exactly ``end``. Start and end radii may differ
    by ``ARC_RADIUS_TOL`` (or 0.1 %); the radius then changes linearly along the arc.

    Raises
    ------
    InputError
        naming the line, when the end is not on the circle or the radius is zero.
    """
    n = _unit(np.asarray(axis, dtype=float))
    s = np.asarray(start, dtype=float) - center
    e = np.asarray(end, dtype=float) - center
    a0, a1 = float(s @ n), float(e @ n)
    u, v = s - a0 * n, e - a1 * n
    r0, r1 = float(np.linalg.norm(u)), float(np.linalg.norm(v))
    if r0 <= 1e-9 or r1 <= 1e-9:
        raise InputError(
            "arc of zero radius (the centre is on the end point)", file=file, line=line
        )
    if abs(r0 - r1) > max(ARC_RADIUS_TOL, 1e-3 * max(r0, r1)):
        raise InputError(
            f"arc end point is not on the circle: radius {r0 * 1e3:.4f} mm at the start, "
            f"{r1 * 1e3:.4f} mm at the end (centre and end point disagree)",
            file=file,
            line=line,
        )
    uh = u / r0
    wh = np.cross(n, uh)
    theta = math.atan2(float(v @ wh), float(v @ uh))  # (−π, π], counter-clockwise about n
    if np.linalg.norm(u - v) <= 1e-9:
        theta = 2 * math.pi if ccw else -2 * math.pi  # full circle
    elif ccw and theta <= 0:
        theta += 2 * math.pi
    elif not ccw and theta >= 0:
        theta -= 2 * math.pi
    r = max(r0, r1)
    step = math.pi / 2 if chord_tol >= r else 2 * math.acos(1 - chord_tol / r)
    m = max(1, math.ceil(abs(theta) / step - 1e-9))
    t = np.arange(1, m + 1) / m
    phi = t * theta
    rad = r0 + t * (r1 - r0)
    pts = (
        center
        + rad[:, None] * (np.cos(phi)[:, None] * uh + np.sin(phi)[:, None] * wh)
        + (a0 + t * (a1 - a0))[:, None] * n
    )
    pts[-1] = end
    return pts


def arc_center_from_radius(
    start: F64,
    end: F64,
    radius: float,
    axis: F64,
    ccw: bool,
    *,
    file: Path | None = None,
    line: int | None = None,
) -> F64:
    """Centre of an arc given by its radius (ISO ``R``, Sinumerik ``CR=``), m.

    ``radius > 0`` picks the arc of at most 180°, ``radius < 0`` the longer one. The centre lies in
    the plane of ``start`` (normal ``axis``). A full circle cannot be given by a radius.
    """
    n = _unit(np.asarray(axis, dtype=float))
    d = np.asarray(end, dtype=float) - start
    d = d - (d @ n) * n
    chord = float(np.linalg.norm(d))
    if chord <= 1e-9:
        raise InputError(
            "an arc given by R needs distinct start and end points (a full circle needs I/J/K)",
            file=file,
            line=line,
        )
    R = abs(radius)
    if chord > 2 * R + ARC_RADIUS_TOL:
        raise InputError(
            f"arc radius R{radius * 1e3:g} mm is smaller than half the chord "
            f"({chord * 1e3 / 2:.4f} mm)",
            file=file,
            line=line,
        )
    h = math.sqrt(max(R * R - chord * chord / 4, 0.0))
    left = np.cross(n, d / chord)
    sign = (1.0 if ccw else -1.0) * (1.0 if radius > 0 else -1.0)
    return np.asarray(start, dtype=float) + d / 2 + sign * h * left
