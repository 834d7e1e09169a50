"""Laps of imported programs follow the part, not the rounding (issue #28): a helix whose z moves
~1 µm per block, z-level programs whose z wiggles inside a level, ramps, uneven step-downs, a
pyramid off the work origin — laps equal turns or levels."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from roboisf.parts import Cone, Pyramid
from roboisf.toolpath.importer import import_toolpath
from roboisf.toolpath.laps import detect_laps

MM = 1e-3


def _program(tmp_path: Path, tip_mm: np.ndarray, decimals: int = 3) -> Path:
    """An ISO program as a CAM post writes it: rounded to ``decimals`` mm, modal words."""
    f = f"{{:.{decimals}f}}"
    lines = ["%", "G90 G21 G17", "G0 X{} Y{} Z5.".format(*(f.format(v) for v in tip_mm[0, :2]))]
    lines.append("G1 F1500")
    for x, y, z in tip_mm:
        lines.append(f"G1 X{f.format(x)} Y{f.format(y)} Z{f.format(z)}")
    lines += ["G0 Z5.", "M30", "%"]
    p = tmp_path / "p.nc"
    p.write_text("\n".join(lines) + "\n")
    return p


def _helix(turns: float, pitch_mm: float, per_turn: int, r0=40.0, slope=1.0) -> np.ndarray:
    """A helix down a cone wall (radius shrinks with depth), ``per_turn`` blocks per turn."""
    n = round(turns * per_turn) + 1
    th = np.linspace(0.0, 2 * math.pi * turns, n)
    z = -pitch_mm * th / (2 * math.pi)
    r = r0 + slope * z
    return np.column_stack([r * np.cos(th), r * np.sin(th), z])


def _levels(
    depths_mm, per_turn: int, r0=40.0, wiggle_mm=0.0, ramp_deg=0.0, seed=0, centre=(0.0, 0.0)
) -> np.ndarray:
    """A z-level path: one closed contour per depth, each reached by a ramp of ``ramp_deg``
    (0: a plunge) at the start angle, z wiggling by ±``wiggle_mm`` inside a level."""
    rng = np.random.default_rng(seed)
    pts = []
    z_prev = 0.0
    for z in depths_mm:
        if ramp_deg > 0:
            k = max(2, int(per_turn * ramp_deg / 360))
            th = np.linspace(0.0, math.radians(ramp_deg), k, endpoint=False)
            zz = np.linspace(z_prev, z, k, endpoint=False)
            r = r0 + zz
            pts.append(np.column_stack([r * np.cos(th), r * np.sin(th), zz]))
            a0 = math.radians(ramp_deg)
        else:
            a0 = 0.0
        th = a0 + np.linspace(0.0, 2 * math.pi, per_turn + 1)
        zz = z + wiggle_mm * rng.uniform(-1.0, 1.0, th.size)
        r = r0 + z
        pts.append(np.column_stack([r * np.cos(th), r * np.sin(th), zz]))
        z_prev = z
    out = np.vstack(pts)
    out[:, 0] += centre[0]
    out[:, 1] += centre[1]
    return out


@pytest.fixture(scope="module")
def cone():
    # r = 40 mm + z: the tip paths below (_helix, _levels with r0 = 40 mm) run on its wall
    return Cone(opening_diameter=80e-3, wall_angle=math.radians(45), depth=30e-3)


def test_rounded_helix_is_a_spiral_of_its_turns(tmp_path, cone):
    """16.6 turns, 0.36 mm pitch, 360 blocks per turn at 3 decimals: z moves 0 or 1 µm per block
    (most segments 'flat' to 1.5 µm) — the old rule read 300+ z levels; laps = 17 turns."""
    tip = _helix(16.6, 0.36, 360)
    dz = np.abs(np.diff(np.round(tip[:, 2], 3)))
    assert (dz <= 1.5e-3).mean() > 0.5  # the trap: most blocks keep their z
    tp = import_toolpath(_program(tmp_path, tip), cone, 5e-3)
    assert tp.meta["laps_rule"] == "spiral"
    assert tp.n_laps == 17
    # each lap starts where the tip has turned a whole number of times
    th = np.unwrap(np.arctan2(tp.tip[:, 1], tp.tip[:, 0]))
    k = np.flatnonzero(np.diff(tp.lap))
    np.testing.assert_allclose((th[k + 1] - th[0]) / (2 * math.pi), np.arange(1, 17), atol=0.01)
    assert any("turn(s) about the part's axis" in n for n in tp.meta["notes"])


def test_helix_with_a_closing_contour(tmp_path, cone):
    """A helix ending with one turn at constant depth: the closing turn stays in the last lap."""
    tip = _helix(8.0, 0.5, 200)
    th = np.linspace(0, 2 * math.pi, 201)[1:]
    r = 40.0 + tip[-1, 2]
    tip = np.vstack([tip, np.column_stack([r * np.cos(th), r * np.sin(th), np.full(200, -4.0)])])
    tp = import_toolpath(_program(tmp_path, tip), cone, 5e-3)
    assert tp.meta["laps_rule"] == "spiral"
    assert tp.n_laps == 8
    assert (tp.lap[-200:] == 7).all()


@pytest.mark.parametrize(
    ("n_levels", "wiggle", "ramp"),
    [(16, 0.02, 0.0), (16, 0.03, 20.0), (50, 0.01, 10.0), (12, 0.0, 15.0)],
)
def test_z_levels_with_wiggles_and_ramps(tmp_path, cone, n_levels, wiggle, ramp):
    """z wiggling by up to ±30 µm inside a level (a 0.5 mm step), ramps of 10–20° or plunges:
    laps = levels, and every ramp point is in the level below."""
    depths = -0.5 * np.arange(1, n_levels + 1)
    tip = _levels(depths, 180, wiggle_mm=wiggle, ramp_deg=ramp, seed=n_levels)
    tp = import_toolpath(_program(tmp_path, tip), cone, 5e-3)
    assert tp.meta["laps_rule"] == "z-level"
    assert tp.n_laps == n_levels
    # the lap's points lie at its depth (ramp points between it and the level above; the first
    # ramp points within twice the wiggle of a level are the level's)
    for k in range(n_levels):
        z = tp.tip[tp.lap == k, 2] / MM
        assert z.min() >= depths[k] - 2 * wiggle - 0.05 - 1e-3
        assert z.max() <= (depths[k - 1] if k else 0.0) + wiggle + 1e-3
        # most of the lap sits on its level
        assert np.mean(np.abs(z - depths[k]) <= wiggle + 1e-3) > 0.9


def test_uneven_step_downs(tmp_path, cone):
    """Exact levels with step-downs from 0.05 to 1 mm (a scallop-spaced path): each level is a
    lap even where the step is far below the mean."""
    steps = np.r_[np.full(10, 0.05), np.full(10, 1.0), np.full(5, 0.2)]
    depths = -np.cumsum(steps)
    tip = _levels(depths, 180)
    tp = import_toolpath(_program(tmp_path, tip), cone, 5e-3)
    assert tp.meta["laps_rule"] == "z-level"
    assert tp.n_laps == len(depths)


def test_helix_of_uneven_pitch_is_still_a_spiral():
    """A spiral whose pitch changes 5× along the part (scallop-spaced on a varying wall): no
    stretch of it is a level, laps = turns."""
    a = _helix(10.0, 0.1, 180)
    b = _helix(6.0, 0.5, 180)
    b[:, 2] += a[-1, 2]
    tip = np.vstack([a, b[1:]]) * MM
    rule = detect_laps(tip)
    assert rule.rule == "spiral"
    assert rule.lap.max() + 1 == 16


def test_turns_about_the_parts_axis(tmp_path):
    """A path about (30, −20) mm: turns and levels are counted about the part's axis (the importer
    passes the centre of the part's bounds), not the work origin."""
    part = Pyramid(top_length=80e-3, top_width=80e-3, wall_angle=math.radians(50), depth=10e-3)
    tip = _levels(-0.5 * np.arange(1, 11), 120, r0=30.0, wiggle_mm=0.02, seed=3)
    off = np.array([30.0, -20.0, 0.0])
    rule_here = detect_laps(tip * MM)
    assert rule_here.rule == "z-level" and rule_here.lap.max() + 1 == 10
    about = detect_laps((tip + off) * MM, (30e-3, -20e-3))
    np.testing.assert_array_equal(about.lap, rule_here.lap)
    # the importer takes the axis from the part (a pyramid: its bounds' centre, the origin)
    tp = import_toolpath(_program(tmp_path, tip), part, 5e-3)
    np.testing.assert_array_equal(tp.lap, rule_here.lap)


def test_levels_in_alternating_directions():
    """Climb and conventional levels in turn (the contour reverses at each level): travel, not net
    turning, counts the turns; laps = levels."""
    tip = _levels(-0.5 * np.arange(1, 13), 120, wiggle_mm=0.01, ramp_deg=10.0, seed=5)
    per = len(tip) // 12
    for k in range(1, 12, 2):
        tip[k * per : (k + 1) * per, 1] *= -1.0  # mirrored: turns the other way
    rule = detect_laps(tip * MM)
    assert rule.rule == "z-level"
    assert rule.lap.max() + 1 == 12


def test_short_paths_keep_the_exact_rule():
    """A path turning less than once (a test snippet): a lap per run of points at one z."""
    tip = np.array([[20, 0, -0.5], [20, 10, -0.5], [0, 20, -1], [-10, 20, -1]]) * MM
    rule = detect_laps(tip)
    assert rule.rule == "z-level"
    np.testing.assert_array_equal(rule.lap, [0, 0, 1, 1])


def test_program_without_f_takes_the_given_feed(tmp_path, cone):
    """issue #28: a G-code program posted without F words is refused naming the line and saying
    how to give the feed; with the feed given it imports, its times from that feed, and says so."""
    from roboisf.errors import InputError
    from roboisf.toolpath.importer import ImportOptions

    p = tmp_path / "nof.nc"
    p.write_text("G90 G21\nG0 X40 Y0 Z5\nG1 Z-0.5\nG1 X40 Y10\nG1 X30 Y10 F600\nG1 X30 Y0\n")
    with pytest.raises(InputError, match=r"before any F word.*--feed") as e:
        import_toolpath(p, cone, 5e-3)
    assert e.value.line == 3
    tp = import_toolpath(p, cone, 5e-3, ImportOptions(feed=1200 / 60e3))
    # the plunge ends the first forming point; then 10 mm at 1200 mm/min, 2 × 10 mm at 600
    np.testing.assert_allclose(np.diff(tp.time), [0.5, 1.0, 1.0])
    assert any("before any F word" in w and "1200 mm/min" in w for w in tp.meta["warnings"])


@pytest.mark.parametrize(
    ("block", "token", "macro"),
    [
        ("IF [#1 GT 2] GOTO 10", "'IF' at column 1", True),
        ("G01 X[#101+5] Y0 F100", "'X[#101+5]' at column 5", True),
        ("#101=20.", "'#101=20.' at column 1", True),
        ("G01 X1 Y$2 F100", "'Y$2' at column 8", False),
    ],
)
def test_bad_block_names_the_token_as_written(tmp_path, block, token, macro):
    """issue #28: the refusal quotes the first token that is not an address word, as written
    (it quoted what was left once the words were removed: 'IF [#1 G] GOT'), and says a macro is
    one."""
    from roboisf.cam.gcode import read_iso_moves
    from roboisf.errors import InputError

    p = tmp_path / "m.nc"
    p.write_text(f"G90 G21\nG0 X0 Y0 Z5\n{block}\nG1 X1 F100\n")
    with pytest.raises(InputError) as e:
        read_iso_moves(p)
    assert e.value.line == 3 and token in e.value.message
    assert ("macro statement" in e.value.message) == macro


def _own_paths():
    from roboisf.toolpath import spiral, step_down, toolpath_for_part

    c = Cone(depth=30e-3)
    p = Pyramid(top_length=80e-3, top_width=60e-3, wall_angle=math.radians(50), depth=12e-3)
    return {
        "cone step": lambda: step_down(c, 5e-3, 0.5e-3, spacing=1e-3),
        "cone spiral": lambda: spiral(c, 5e-3, 0.5e-3, spacing=1e-3),
        # extra heights on the shallow wall: steps and pitches from 1 mm down to ~0.3 mm; the
        # spiral then descends ~1.2 µm per point, less than the 1.5 µm z tolerance
        "cone step, max wall step": lambda: step_down(
            c, 5e-3, 1e-3, spacing=1e-3, max_wall_step=0.3e-3
        ),
        "cone spiral, max wall step": lambda: spiral(
            c, 5e-3, 1e-3, spacing=1e-3, max_wall_step=0.3e-3
        ),
        "pyramid spiral": lambda: toolpath_for_part(p, 5e-3, 0.5e-3, spacing=1e-3, spiral=True),
        "pyramid scallop step": lambda: toolpath_for_part(
            p, 5e-3, 1e-3, spacing=1e-3, scallop_height=0.02e-3
        ),
    }


@pytest.mark.parametrize("name", list(_own_paths()))
@pytest.mark.parametrize("decimals", [3, 4])
def test_roboisf_paths_posted_at_any_resolution_keep_their_laps(name, decimals):
    """roboisf's own paths (the laps known) rounded as a post-processor writes them: the laps
    found are the generator's, point for point, on step-downs and spirals of a cone and a
    pyramid, with uneven steps."""
    tp = _own_paths()[name]()
    tip = np.round(tp.tip / MM, decimals) * MM
    rule = detect_laps(tip)
    assert rule.rule == ("spiral" if "spiral" in name else "z-level")
    np.testing.assert_array_equal(rule.lap, tp.lap)
