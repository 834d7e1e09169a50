"""A CAM program (ISO G-code, Sinumerik, APT/CL, a bare point list) → a roboisf toolpath.

The readers (:mod:`roboisf.cam.gcode`, :mod:`roboisf.cam.sinumerik`, :mod:`roboisf.cam.apt`,
:mod:`roboisf.cam.xyz`) give the program's moves; this module rebuilds what roboisf needs per
point against the nominal part (docs/toolpaths.md, "Importing a CAM program"):

1. **Which point the program names** (``point``): ``"tip"`` (default) — the lowest point of the
   ball, what CAM systems post for a ball-end tool whose length is set to the tip (``G43 H`` to
   the tip, the usual CNC set-up, and what roboisf's own programs contain); ``"center"`` — the
   ball centre (CAM "tool centre" output, many robot post-processors). Centre
   ``C = T + R ẑ``.
2. **Forming points** (after subtracting ``origin``, the work origin in program coordinates, when
   the program zero is not the blank centre on the sheet top): feed moves (G01/G02/G03, APT GOTO
   without RAPID, every row of a list) whose tip is at or below the sheet plane
   (``tip z ≤ SHEET_TOL``). Rapids (G00, G28/G53, APT RAPID/GOHOME) and feed moves with the tip
   above the sheet (approach, retract, moves over the clamp) are dropped; a rapid that goes below
   the sheet plane is reported as a warning.
3. **Resampled** on request: with ``spacing`` a forming segment longer than it is split evenly
   (so a long straight CAM move still gives points every ``spacing`` for the force and scan
   look-ups; without it segments over ``LONG_SEGMENT`` are reported); consecutive
   points closer than ``MERGE_TOL`` are merged (the first kept: a repeated point adds no time).
4. **Contact and normal**: the closest point P of the nominal surface to the ball centre C
   (``Part.closest_point``); the normal is the contact normal ``(C − P)/|C − P|`` (the surface's
   tool-side normal on a smooth wall; at a convex edge such as the rim, where the ball rolls over
   the edge, the direction from the edge to the centre); the wall angle is ``acos(n_z)``. The gap
   ``|C − P| − R`` (0 for a path that follows the nominal exactly) is reported; a large one
   usually means the wrong ``--point`` or ball diameter.
5. **Laps** (:mod:`roboisf.toolpath.laps`): levels of a z-level path — runs that turn at least
   half a turn about the part's axis with z in a band (exact, or wiggling by less than a quarter
   of the step) and no trend; a ramp belongs to the level below — or else turns of a spiral about
   the part's axis (the centre of its bounding box), a closing contour staying in the last lap.
6. **Times** from the feeds: each feed move takes its length / its feed (G93: 1/F min), rapids
   take their length / ``rapid_rate`` or no time when no rapid rate is given; dwells are not
   counted. A point's time is the program time since the first forming point, so time spent in
   dropped moves between forming points (a retract between laps) is included. ``path_length`` is
   the tip path through the forming points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from roboisf.cam.cam import DEFAULT_CHORD_TOL, FEED, CamMoves, ReadOptions
from roboisf.cam.camformat import CamSpec, head_lines
from roboisf.errors import InputError
from roboisf.formats import FileFormat, file_formats
from roboisf.parts.base import Part
from roboisf.path.toolpath import Toolpath
from roboisf.toolpath.laps import detect_laps
from roboisf.toolpath.limits import MAX_POINTS

__all__ = [
    "ImportOptions",
    "cam_format_names",
    "cam_formats",
    "detect_toolpath_format",
    "import_toolpath",
    "load_toolpath",
    "moves_to_toolpath",
    "read_cam_moves",
    "read_toolpath_file",
]

F64 = NDArray[np.float64]


def cam_formats() -> tuple[FileFormat, ...]:
    """The CAM formats ``import`` reads: the registered ``cnc`` formats with a :class:`CamSpec`
    (:mod:`roboisf.formats`; built in: ``sinumerik``, ``apt``, ``xyz``, ``iso``, one module each in
    :mod:`roboisf.cam.formats`), in detection order."""
    return tuple(f for f in file_formats("cnc") if isinstance(f.spec, CamSpec))


def cam_format_names() -> tuple[str, ...]:
    """The names ``--format``/``toolpath_format`` accept besides ``auto`` (and a study's
    ``csv``), in detection order."""
    return tuple(f.name for f in cam_formats())


#: A forming point has its tip at most this far above the sheet plane [m].
SHEET_TOL = 1e-6
#: Consecutive points closer than this are one point [m].
MERGE_TOL = 1e-6
#: Feed [m/s] of a point list when none is given (750 mm/min).
POINT_LIST_FEED = 750.0 / 60e3
#: Without ``spacing``, forming segments longer than this [m] are reported.
LONG_SEGMENT = 5e-3
#: A gap |C − P| − R above this [m] is reported.
GAP_WARN = 50e-6


@dataclass(frozen=True)
class ImportOptions:
    """Options of :func:`import_toolpath` (SI).

    Attributes
    ----------
    point : ``"tip"`` or ``"center"`` — which point of the ball the program names
    fmt : ``"auto"`` or one of :func:`cam_format_names`
    chord_tol : float, m — arcs linearised to this chord error
    spacing : float or None, m — longest forming segment (split evenly beyond); None (default):
        the points as programmed, with a warning when a forming segment exceeds ``LONG_SEGMENT``
    rapid_rate : float or None, m/s — rapid traverse rate for the times; None: rapids take no time
    work_offsets : dict[str, (3,) float m] — work-offset values (see ``ReadOptions``)
    ignore_words : frozenset[str] — extra-axis letters to ignore with a warning
    units : str or None — length unit of a point list (``mm`` default, ``m``, ``in``)
    feed : float or None, m/s — feed of a point list (it has none; default 750 mm/min), and of
        a program's feed moves before its first F word (a program without F; default: refused)
    origin : (3,) float, m — where roboisf's work origin (the blank centre on the sheet top) is in
        the program's coordinates; subtracted from every point (default: the program zero is it)
    """

    point: str = "tip"
    fmt: str = "auto"
    chord_tol: float = DEFAULT_CHORD_TOL
    spacing: float | None = None
    rapid_rate: float | None = None
    work_offsets: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    ignore_words: frozenset[str] = frozenset()
    units: str | None = None
    feed: float | None = None
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if self.point not in ("tip", "center"):
            raise InputError(f"expected 'tip' or 'center', got {self.point!r}", field="point")
        names = cam_format_names()
        if self.fmt not in ("auto", *names):
            raise InputError(
                f"expected auto or one of {', '.join(names)}, got {self.fmt!r}",
                field="format",
            )
        for name, v in (("spacing", self.spacing), ("rapid_rate", self.rapid_rate)):
            if v is not None and not (math.isfinite(v) and v > 0):
                raise InputError(f"must be > 0, got {v:g}", field=name)
        if self.feed is not None and not (math.isfinite(self.feed) and self.feed > 0):
            raise InputError(f"must be > 0, got {self.feed * 60e3:g} mm/min", field="feed")
        if len(self.origin) != 3 or not all(math.isfinite(v) for v in self.origin):
            raise InputError(f"expected 3 finite numbers, got {self.origin!r}", field="origin")
        from roboisf.cam.xyz import XYZ_UNITS

        if self.units is not None and self.units not in XYZ_UNITS:
            raise InputError(
                f"unknown length unit {self.units!r}; expected one of {', '.join(XYZ_UNITS)}",
                field="units",
            )

    def read_options(self) -> ReadOptions:
        return ReadOptions(
            chord_tol=self.chord_tol,
            work_offsets=dict(self.work_offsets),
            ignore_words=self.ignore_words,
            feed=self.feed,
        )


def detect_toolpath_format(path: str | Path) -> str:
    """The format of a toolpath file: ``"csv"`` (roboisf's own toolpath CSV), ``"iso"``,
    ``"sinumerik"``, ``"apt"`` or ``"xyz"``.

    By content first (the first 40 lines): the ``# roboisf toolpath`` line or its
    ``index,lap,…`` header → csv; ``%_N_…``, ``;$PATH``, ``X=`` words, ``G642``-style or
    ``CYCLE832`` words → sinumerik; ``GOTO/``, ``FEDRAT/`` … → apt; G-code words → iso; rows of
    numbers → xyz. The suffix decides only between formats the content leaves open (``.mpf`` is
    always Sinumerik). Raises :class:`InputError` when nothing fits.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("toolpath file not found", file=path)
    head = head_lines(path)
    if any(ln.lower().startswith("# roboisf toolpath") for ln in head) or any(
        ln.replace(" ", "").lower().startswith("index,lap,contact_x") for ln in head
    ):
        return "csv"
    formats = cam_formats()
    for fmt in formats:  # by content, in rank order (each format's own detector)
        if fmt.detect is not None and fmt.detect(path):
            return fmt.name
    suffix = path.suffix.lower()
    for fmt in formats:  # the suffix decides only what the content leaves open
        if fmt.spec.by_suffix and suffix in fmt.suffixes:
            return fmt.name
    raise InputError(
        "cannot tell the toolpath format from the content or the suffix; expected a roboisf "
        "toolpath CSV, ISO G-code, a Sinumerik .mpf, APT/CL data or an x,y,z list (pass --format)",
        file=path,
    )


def read_cam_moves(path: str | Path, options: ImportOptions | None = None) -> CamMoves:
    """The moves of a CAM file in ``options.fmt`` (``auto``: :func:`detect_toolpath_format`)."""
    path = Path(path)
    opt = options or ImportOptions()
    fmt = opt.fmt if opt.fmt != "auto" else detect_toolpath_format(path)
    if fmt == "csv":
        raise InputError(
            "this is already a roboisf toolpath CSV; use it as it is (nothing to import)",
            file=path,
        )
    cam = next((f for f in cam_formats() if f.name == fmt), None)
    if cam is None or cam.reader is None:  # pragma: no cover - ImportOptions checked the name
        raise InputError(f"unknown CAM format {fmt!r}", field="format")
    if opt.units is not None and not cam.spec.takes_units:
        raise InputError(
            f"units applies to an x,y,z point list; a {fmt} program declares its own unit "
            "(G20/G21, INCH/METRIC, UNITS/): leave --units out",
            field="units",
        )
    feed = POINT_LIST_FEED if opt.feed is None else opt.feed
    moves: CamMoves = cam.reader(path, opt.read_options(), units=opt.units, feed=feed)
    moves.meta["format"] = fmt
    return moves


def _check_axis(moves: CamMoves, keep: NDArray[np.bool_]) -> None:
    if moves.tool_axis is None:
        return
    # ±z: lists differ on whether i,j,k points up the tool or down to the tip
    tilt = np.degrees(np.arccos(np.clip(np.abs(moves.tool_axis[keep, 2]), 0.0, 1.0)))
    if tilt.size and tilt.max() > 0.01:
        i = int(np.argmax(tilt))
        raise InputError(
            f"tool axis tilted {tilt[i]:.3f}° from +z: a 3-axis (vertical tool) path is expected",
            file=moves.path,
            line=int(moves.line[keep][i]),
        )


def _move_times(moves: CamMoves, rapid_rate: float | None) -> F64:
    """Program time [s] at the end of every move."""
    p = moves.point
    prev = np.vstack([np.full((1, 3), np.nan), p[:-1]])
    seg = np.linalg.norm(p - prev, axis=1)
    seg = np.where(np.isfinite(seg), seg, 0.0)  # from or to an unknown position: no time known
    dt = np.zeros(len(moves))
    feed_m = moves.kind == FEED
    dt[feed_m] = seg[feed_m] / moves.feed[feed_m]
    if rapid_rate is not None:
        dt[~feed_m] = seg[~feed_m] / rapid_rate
    return np.cumsum(dt)


def _resample(
    spacing: float, tip: F64, t: F64, lines: NDArray[np.int64], feeds: F64, cont: NDArray[np.bool_]
) -> tuple[F64, F64, NDArray[np.int64], F64, NDArray[np.bool_]]:
    """Split every contiguous forming segment longer than ``spacing`` evenly; refused before any
    allocation when the result would exceed :data:`MAX_POINTS` (``--spacing 1e-6`` asked for
    26 GiB)."""
    seg = np.linalg.norm(np.diff(tip, axis=0), axis=1)
    n_new = np.where(cont[1:], np.ceil(seg / spacing - 1e-9), 1.0)
    total = float(np.sum(np.maximum(n_new, 1.0))) + 1
    if total > MAX_POINTS:
        length = float(np.sum(seg[cont[1:]]))
        least = length / (MAX_POINTS - len(tip))
        raise InputError(
            f"a spacing of {spacing * 1e3:g} mm splits the program's {length * 1e3:.6g} mm of "
            f"forming path into {total:.3g} points, more than the {MAX_POINTS:,} roboisf builds "
            f"(≈ 1 kB each); use a spacing of at least {least * 1e3:.2g} mm",
            field="spacing",
        )
    p = np.maximum(n_new.astype(np.int64), 1)
    if not (p > 1).any():
        return tip, t, lines, feeds, cont
    src = np.repeat(np.arange(1, len(tip)), p)
    k = np.arange(len(src)) - np.repeat(np.cumsum(p) - p, p) + 1
    frac = k / np.repeat(p, p)
    new_tip = tip[src - 1] + frac[:, None] * (tip[src] - tip[src - 1])
    new_t = t[src - 1] + frac * (t[src] - t[src - 1])
    return (
        np.vstack([tip[:1], new_tip]),
        np.concatenate([t[:1], new_t]),
        np.concatenate([lines[:1], lines[src]]),
        np.concatenate([feeds[:1], feeds[src]]),
        np.concatenate([cont[:1], np.repeat(cont[1:], p)]),
    )


#: Probe height [m] and jump [m] of the corner tie-break in :func:`_contacts`.
_TIE_PROBE, _TIE_JUMP, _TIE_TOL = 5e-6, 50e-6, 2e-6


#: The median |gap| of the ball to the part above which the program is refused as not being on
#: the part [m] (with the ball's diameter, whichever is larger): a tip/centre mix-up is a gap of
#: one radius (warned), a program in inches read as mm or an incremental one (G91) read as
#: absolute is tens to thousands of mm off.
OFF_PART = 10e-3


def _refuse_off_part(tip: F64, gap: F64, part: Part, R: float, source: Path | str | None) -> None:
    """Refuse a program whose geometry cannot be on ``part``, naming the likely cause: a unit
    (the tips scaled by 25.4 or 1000 would fit), incremental coordinates (the points run far
    outside the part and keep going), or another part."""
    med = float(np.median(np.abs(gap)))
    limit = max(OFF_PART, 2 * R)
    deepest = int(np.argmin(gap))
    if med <= limit and gap[deepest] >= -limit:
        return
    lo, hi = (np.asarray(b, dtype=float) for b in part.bounds)
    span = float(np.max(hi - lo))
    reach = float(np.max(np.abs(tip[:, :2]))) * 1e3
    depth = float(-np.min(tip[:, 2])) * 1e3
    if med <= limit:  # on the part mostly, but somewhere through it: a deeper or other part
        raise InputError(
            f"the ball goes {-gap[deepest] * 1e3:.4g} mm into the part at point {deepest} (tip "
            f"z = {tip[deepest, 2] * 1e3:.4g} mm; the part is {part.depth * 1e3:.4g} mm deep): "
            "the program is for a deeper or another part; nothing written (check the program "
            "and the part)",
            file=source,
        )
    where = (
        f"the ball is {med * 1e3:.4g} mm (median) off the nominal part; the program's points "
        f"reach {reach:.4g} mm from the axis and {depth:.4g} mm deep, the part spans "
        f"{span * 1e3:.4g} mm and is {part.depth * 1e3:.4g} mm deep"
    )
    cause = ""
    sample = tip[:: max(1, len(tip) // 2000)]
    for name, factor in (
        ("inches (G20) read as mm", 25.4),
        ("mm read as inches", 1 / 25.4),
        ("m read as mm", 1e3),
        ("µm read as mm", 1e-3),
    ):
        c = sample * factor
        c[:, 2] += R
        g = np.abs(np.asarray(part.closest_point(c).distance, dtype=float) - R)
        if float(np.median(g)) < 0.1 * med and float(np.median(g)) < max(2 * R, 1e-3):
            cause = f"the program is likely in {name} (the points × {factor:.4g} lie on the part)"
            break
    if not cause:
        steps = np.diff(tip[:, 2])
        runaway = depth > 3 * part.depth * 1e3 or reach > 3 * span * 1e3
        if runaway and np.mean(steps <= 0) > 0.95:
            cause = (
                "the points keep moving one way far past the part: incremental moves (G91) "
                "where absolute ones (G90) were meant?"
            )
        elif runaway:
            cause = "the points run far outside the part: a wrong --origin or work offset?"
        else:
            cause = "the program is for another part, or its zero is not the blank centre"
    raise InputError(
        f"{where}: {cause}; nothing written (check the program, --units, --origin, the part)",
        file=source,
    )


def _contacts(part: Part, center: F64) -> tuple[F64, F64, F64]:
    """Contact point, tool-side normal and signed distance of ``center`` (N, 3) m to ``part``.

    Where the ball touches two surfaces at once (a concave corner: wall and flat bottom) the
    closest point is a tie that the program's 1 µm rounding breaks at random. The tie is found by
    probing from ``ε = 5 µm`` above the centre (the steeper surface comes closer): when the probe's
    closest point jumps away (> 50 µm) and that surface is as close to the centre as the first
    (within 2 µm), the steeper surface's contact, moved back to the centre
    (``P − ε (ẑ − n_z n)``, exact on a straight wall), is taken — as roboisf's generator does.
    """
    q = part.closest_point(center)
    contact = np.array(q.point, dtype=float)
    normal = np.array(q.normal, dtype=float)
    dist = np.array(q.distance, dtype=float)
    probe = center.copy()
    probe[:, 2] += _TIE_PROBE
    q1 = part.closest_point(probe)
    p1, n1 = np.asarray(q1.point, dtype=float), np.asarray(q1.normal, dtype=float)
    back = p1 - _TIE_PROBE * (np.array([0.0, 0.0, 1.0]) - n1[:, 2:3] * n1)
    d1 = np.linalg.norm(center - back, axis=1)
    tie = (np.linalg.norm(p1 - contact, axis=1) > _TIE_JUMP) & (
        np.abs(d1 - np.abs(dist)) < _TIE_TOL
    )
    tie &= n1[:, 2] < normal[:, 2]
    contact[tie], normal[tie] = back[tie], n1[tie]
    dist[tie] = np.sign(dist[tie]) * d1[tie]
    # the contact normal: from the contact to the centre (at a convex edge — the rim — the ball
    # rolls over the edge and this is not the surface normal on either side)
    v = center - contact
    vn = np.linalg.norm(v, axis=1)
    ok = vn > 1e-9
    normal[ok] = v[ok] / vn[ok, None] * np.where(dist[ok] < 0, -1.0, 1.0)[:, None]
    return contact, normal, dist


def moves_to_toolpath(
    moves: CamMoves, part: Part, tool_radius: float, options: ImportOptions | None = None
) -> Toolpath:
    """The forming toolpath of ``moves`` against ``part`` (module docstring, steps 1–6).

    Parameters
    ----------
    moves : the program's moves (work frame, m)
    part : the nominal part (its ``closest_point`` gives contact and normal)
    tool_radius : float, m — ball radius
    options : which point the program names, spacing, rapid rate …

    Returns
    -------
    Toolpath, its ``meta`` holding ``source``, ``format``, ``laps_rule``, ``notes``, ``warnings``,
    ``gap_max`` [m], ``dropped_moves`` and ``feeds_mm_min``.
    """
    opt = options or ImportOptions()
    if not (math.isfinite(tool_radius) and tool_radius > 0):
        raise InputError(f"must be > 0 mm, got {tool_radius * 2e3:g}", field="tool_diameter")
    R = tool_radius
    warnings = list(moves.warnings)
    notes = list(moves.notes)
    tip_all = moves.point - np.asarray(opt.origin, dtype=float)
    if opt.point == "center":
        tip_all[:, 2] -= R
    known = np.all(np.isfinite(tip_all), axis=1)
    feed_m = moves.kind == FEED
    above = np.zeros(len(moves), dtype=bool)
    above[known] = tip_all[known, 2] > SHEET_TOL
    forming = feed_m & known & ~above
    rapid_below = ~feed_m & known & (tip_all[:, 2] < -SHEET_TOL)
    if rapid_below.any():
        lines = moves.line[rapid_below]
        warnings.append(
            f"{int(rapid_below.sum())} rapid move(s) end below the sheet plane (first on line "
            f"{int(lines[0])}); rapids are never forming moves"
        )
    if not forming.any():
        raise InputError(
            f"no forming moves: no feed move has its {opt.point} with the tip at or below the "
            "sheet plane z = 0 (is the program zero on the sheet? is --point right?)",
            file=moves.path,
        )
    _check_axis(moves, forming)
    dropped = int(len(moves) - forming.sum())
    if (feed_m & above).any():
        notes.append(
            f"{int((feed_m & above).sum())} feed move(s) above the sheet plane (approach, "
            "retract) dropped"
        )
    times = _move_times(moves, opt.rapid_rate)
    idx = np.flatnonzero(forming)
    tip = tip_all[idx]
    t = times[idx]
    lines = moves.line[idx]
    feeds = moves.feed[idx]
    contiguous = np.concatenate([[False], np.diff(idx) == 1])
    # resample long forming segments (only between consecutive forming moves)
    if opt.spacing is not None and len(tip) > 1:
        tip, t, lines, feeds, contiguous = _resample(opt.spacing, tip, t, lines, feeds, contiguous)
    elif len(tip) > 1:
        seg = np.linalg.norm(np.diff(tip, axis=0), axis=1)
        long = contiguous[1:] & (seg > LONG_SEGMENT)
        if long.any():
            warnings.append(
                f"{int(long.sum())} forming move(s) longer than {LONG_SEGMENT * 1e3:g} mm (longest "
                f"{seg[long].max() * 1e3:.1f} mm, line {int(lines[1:][long][0])}): forces and "
                "scans are looked up per point; pass --spacing 1 to resample"
            )
    # merge repeated points
    keep = np.ones(len(tip), dtype=bool)
    if len(tip) > 1:
        d = np.linalg.norm(np.diff(tip, axis=0), axis=1)
        keep[1:] = d > MERGE_TOL  # a run of repeats collapses onto its first point
    merged = int((~keep).sum())
    if merged:
        notes.append(f"{merged} repeated point(s) merged")
    tip, t, lines, feeds = tip[keep], t[keep], lines[keep], feeds[keep]
    center = tip.copy()
    center[:, 2] += R
    contact, normal, dist = _contacts(part, center)
    gap = dist - R
    gmax = float(np.max(np.abs(gap)))
    if gmax > GAP_WARN:
        i = int(np.argmax(np.abs(gap)))
        med = float(np.median(gap))
        hint = ""
        if abs(med) > 0.3 * R:
            other = "center" if opt.point == "tip" else "tip"
            hint = f"; the median gap is {med * 1e3:.3f} mm — does the program name the {other}?"
        warnings.append(
            f"the ball is {gap[i] * 1e3:+.3f} mm off the nominal at point {i} (line "
            f"{int(lines[i])}; + clear of it, − into it){hint}"
        )
    _refuse_off_part(tip, gap, part, R, moves.path)
    lo, hi = part.bounds
    laps = detect_laps(tip, (0.5 * float(lo[0] + hi[0]), 0.5 * float(lo[1] + hi[1])))
    lap, rule = laps.lap, laps.rule
    notes.append(laps.describe())
    seg = np.linalg.norm(np.diff(tip, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    time = t - t[0]
    time = np.maximum.accumulate(time)
    # the forming feed: the feed that covers the most path
    uniq, inv = np.unique(np.round(feeds, 12), return_inverse=True)
    length_by_feed = np.bincount(inv[1:], weights=seg, minlength=len(uniq)) if len(seg) else None
    feed = float(uniq[int(np.argmax(length_by_feed))] if length_by_feed is not None else uniq[0])
    meta: dict[str, object] = {
        "part": part.kind,
        "kind": f"imported {moves.meta.get('format', moves.meta.get('dialect', 'cam'))}",
        "source": str(moves.path),
        "format": moves.meta.get("format", moves.meta.get("dialect")),
        "point": opt.point,
        "laps_rule": rule,
        "notes": notes,
        "warnings": warnings,
        "gap_max": gmax,
        "dropped_moves": dropped,
        "merged_points": merged,
        "feeds_mm_min": sorted({round(float(f) * 60e3, 6) for f in uniq}),
        "lines": lines.tolist(),  # the program line of every point
    }
    return Toolpath(
        contact=contact,
        normal=normal,
        center=center,
        tip=tip,
        wall_angle=np.arccos(np.clip(normal[:, 2], -1.0, 1.0)),
        lap=lap,
        path_length=s,
        time=time,
        tool_radius=float(R),
        feed=feed,
        meta=meta,
    )


def import_toolpath(
    path: str | Path, part: Part, tool_radius: float, options: ImportOptions | None = None
) -> Toolpath:
    """Read a CAM program (any of :func:`cam_format_names`) and rebuild its toolpath against
    ``part``.

    Parameters
    ----------
    path : the program file
    part : the nominal part
    tool_radius : float, m — ball radius
    options : :class:`ImportOptions`

    Raises
    ------
    InputError
        naming the file and line of anything not understood.
    """
    opt = options or ImportOptions()
    return moves_to_toolpath(read_cam_moves(path, opt), part, tool_radius, opt)


def load_toolpath(
    path: str | Path,
    part: Part,
    tool_radius: float,
    *,
    fmt: str = "auto",
    point: str = "tip",
) -> Toolpath:
    """A study's ``toolpath``: roboisf's toolpath CSV as it is, any CAM program imported.

    The study hook: ``analyze``, ``compensate`` and ``plan --study`` read every run's toolpath
    through this, with the nominal of ``[part]``, the ball radius of ``[tool]`` and the run's
    ``toolpath_format`` / ``toolpath_point`` (``fmt`` ``"csv"`` | ``"auto"`` | a CAM format).
    """
    from roboisf.cam.toolpath_csv import read_toolpath_csv

    path = Path(path)
    if fmt == "auto":
        fmt = detect_toolpath_format(path)
    if fmt == "csv":
        return read_toolpath_csv(path)
    return import_toolpath(path, part, tool_radius, ImportOptions(fmt=fmt, point=point))


def read_toolpath_file(
    path: str | Path,
    part: Part | None = None,
    tool_radius: float | None = None,
    *,
    option: str = "--toolpath",
) -> Toolpath:
    """A command's toolpath argument: roboisf's toolpath CSV, or a CAM program imported against
    ``part`` with the ball radius ``tool_radius`` [m] (tip point, as :func:`load_toolpath`).

    Raises
    ------
    InputError
        a CAM program without a part or a ball diameter (pointing to ``roboisf toolpath
        import``), or any error of the readers.
    """
    from roboisf.cam.toolpath_csv import read_toolpath_csv

    path = Path(path)
    fmt = detect_toolpath_format(path)
    if fmt == "csv":
        return read_toolpath_csv(path)
    if part is None or tool_radius is None:
        need = "a part and a ball diameter" if part is None else "the ball diameter"
        raise InputError(
            f"a {fmt} CAM program, not a roboisf toolpath CSV: importing it needs {need}; "
            "convert it first with `roboisf toolpath import FILE --part PART.toml "
            "--tool-diameter MM -o toolpath.csv`"
            + (" or give --tool-diameter" if part is not None else ""),
            file=path,
            field=option,
        )
    return load_toolpath(path, part, tool_radius, fmt=fmt)
