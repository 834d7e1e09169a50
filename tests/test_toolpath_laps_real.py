"""Laps of real CAM programs equal their turns or levels (issue #28).

The programs (``tests/data/cam/``, origin and licence in the README there) are Fusion 360 posts
that no one here wrote: a bore whose helix the post rounds to 3 decimals (the arc radius reads
0.313 at one end and 0.312 at the other) and a 2D contour cut in three z levels. The turns and
levels are counted here by a parser of this test's own — the swept angle of every block about
the axis from the program's own arc centres (I, J) and end points — never by roboisf's reader,
arc linearisation or ``detect_laps``.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from roboisf.cam.cam import FEED
from roboisf.toolpath.importer import ImportOptions, import_toolpath, read_cam_moves
from roboisf.toolpath.laps import detect_laps

CAM = Path(__file__).parent / "data" / "cam"
BORE = CAM / "fusion360_bore_helix.nc"
LEVELS = CAM / "fusion360_contour_levels.nc"
_WORD = re.compile(r"([A-Z])\s*(-?\d*\.?\d+)")


def _blocks(path: Path) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray | None]]:
    """(G mode, start, end, arc centre or None) of every feed block, mm. G17 arcs only."""
    mode, pos, out = 0, np.full(3, np.nan), []
    for raw in path.read_text().splitlines():
        line = re.sub(r"\(.*?\)", "", raw).strip().upper()
        words = _WORD.findall(line)
        g = [int(float(v)) for k, v in words if k == "G"]
        assert not {18, 19} & set(g), "this parser knows the XY plane only"
        mode = next((c for c in g if c in (0, 1, 2, 3)), mode)
        w = {k: float(v) for k, v in words if k in "XYZIJ"}
        if not {"X", "Y", "Z"} & w.keys():
            continue
        end = pos.copy()
        for i, k in enumerate("XYZ"):
            if k in w:
                end[i] = w[k]
        centre = None
        if mode in (2, 3):
            centre = pos[:2] + np.array([w.get("I", 0.0), w.get("J", 0.0)])
        if mode != 0 and np.all(np.isfinite(pos)):
            out.append((mode, pos.copy(), end, centre))
        pos = end
    return out


def _swept(mode: int, a: np.ndarray, b: np.ndarray, c: np.ndarray | None, axis) -> float:
    """|angle| a block sweeps about the vertical line through ``axis`` [rad]."""
    if c is None:  # a line: its end points' angle difference (every step here is < π)
        d = math.atan2(b[1] - axis[1], b[0] - axis[0]) - math.atan2(a[1] - axis[1], a[0] - axis[0])
        return abs((d + math.pi) % (2 * math.pi) - math.pi)
    # an arc about ``axis``: from its own centre, in its direction (a full circle if a == b)
    assert np.allclose(c, axis, atol=1e-3), (c, axis)
    d = math.atan2(b[1] - c[1], b[0] - c[0]) - math.atan2(a[1] - c[1], a[0] - c[0])
    d = d % (2 * math.pi) if mode == 3 else (-d) % (2 * math.pi)
    return d if d > 1e-9 else 2 * math.pi


def _forming_points(path: Path, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
    """roboisf's reading of the program: feed-move end points at or below the sheet, m."""
    m = read_cam_moves(path)
    f = (m.kind == FEED) & (m.point[:, 2] <= 1e-9)
    return m.point[f] - np.asarray(origin)


def test_bore_helix_laps_equal_its_turns():
    """The helix descends 12.8 mm at 0.5 mm a turn: 0.25 turn of lead-in at z = 0, 51 half-turn
    arcs, 0.1 turn to the bottom (25.85 turns), then a full circle and a lead-out at the bottom,
    which stay in the last turn: laps = ⌈25.85⌉ = 26."""
    blocks = [b for b in _blocks(BORE) if b[2][2] <= 0.0]  # forming: the tip at or below z = 0
    axis = (30.0, 0.0)  # every arc of the helix is about X30 Y0 (asserted in _swept)
    z_end = min(b[2][2] for b in blocks)
    last = max(i for i, b in enumerate(blocks) if b[1][2] != b[2][2])  # the last z-changing block
    assert blocks[last][2][2] == z_end == -12.8
    turns = sum(_swept(*b, axis) for b in blocks[: last + 1]) / (2 * math.pi)
    assert turns == pytest.approx(25.85, abs=0.01)
    expected = math.ceil(turns)

    tip = _forming_points(BORE, (30e-3, 0.0, 0.0))
    rule = detect_laps(tip, (0.0, 0.0))
    assert rule.rule == "spiral" and int(rule.lap.max()) + 1 == expected
    # the full import (roboisf's work origin on the hole axis; a Ø3.8 mm, 89° cone stands in for
    # the hole wall, which the 1.5875 mm tool radius reaches from the 0.3125 mm helix)
    cone_part = _cone(3.8e-3, 89.0, 12.8e-3)
    tp = import_toolpath(BORE, cone_part, 1.5875e-3, ImportOptions(origin=(30e-3, 0.0, 0.0)))
    assert tp.meta["laps_rule"] == "spiral" and tp.n_laps == expected
    # every lap but the last is one turn: its first point is k turns along from the first point
    phi = np.unwrap(np.arctan2(tp.tip[:, 1], tp.tip[:, 0]))
    travel = np.abs(phi - phi[0]) / (2 * math.pi)
    starts = np.flatnonzero(np.diff(tp.lap)) + 1
    np.testing.assert_array_equal(np.floor(travel[starts] + 1e-9), np.arange(1, expected))


def _cone(opening: float, wall_deg: float, depth: float):
    from roboisf.parts import Cone

    return Cone(opening_diameter=opening, wall_angle=math.radians(wall_deg), depth=depth)


def test_contour_levels_laps_equal_its_levels():
    """Three z levels (−1, −2, −3 mm), each a full turn about the square's centre, reached by
    a plunge at the corner: laps = 3."""
    blocks = [b for b in _blocks(LEVELS) if b[2][2] <= 0.0]
    xy = np.array([p[:2] for b in blocks for p in b[1:3]])
    axis = tuple((xy.min(axis=0) + xy.max(axis=0)) / 2)
    by_z: dict[float, float] = {}
    for b in blocks:
        if b[1][2] == b[2][2]:
            by_z[b[2][2]] = by_z.get(b[2][2], 0.0) + _swept(*b, axis) / (2 * math.pi)
    levels = sorted(z for z, t in by_z.items() if t >= 1.0 - 1e-9)
    assert levels == [-3.0, -2.0, -1.0]

    tip = _forming_points(LEVELS)
    rule = detect_laps(tip, (axis[0] * 1e-3, axis[1] * 1e-3))
    assert rule.rule == "z-level" and int(rule.lap.max()) + 1 == len(levels)
    # each lap is one level: its points' z are that level's
    for k, z in enumerate(sorted(levels, reverse=True)):
        np.testing.assert_allclose(tip[rule.lap == k, 2], z * 1e-3, atol=1e-9)
