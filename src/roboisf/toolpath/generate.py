"""Toolpath generation for axisymmetric parts: step-down contours and spirals.

* **Step-down** (the paper's "step toolpath"): closed contours at z = −Δz, −2Δz, …, the last one
  at the full depth; between contours the tool steps down at the lap's start angle.
* **Spiral**: z ramps linearly within each lap from one level to the next (no plunge marks).
* **Along-wall step** (``max_wall_step``): where the wall is shallow (VWACF near 0°) a constant
  Δz gives laps far apart along the wall; extra levels are inserted so that consecutive laps are
  at most ``max_wall_step`` apart *along the generatrix*.

Point spacing: points on a lap are evenly spaced in angle with at most ``spacing`` of arc between
neighbours at the contact radius (and at least 8 points per lap).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.parts.axisymmetric import AxisymmetricPart
from roboisf.toolpath.toolpath import Toolpath

__all__ = ["DEFAULT_FEED", "lap_levels", "spiral", "step_down"]

F64 = NDArray[np.float64]

#: Paper feed rate, 750 mm/min in m/s.
DEFAULT_FEED = 750e-3 / 60.0


def _check(part: AxisymmetricPart, tool_radius: float, step: float, spacing: float, feed: float) -> None:
    for name, v in (("tool_radius", tool_radius), ("step_down", step), ("spacing", spacing), ("feed", feed)):
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"must be > 0, got {v:g} (SI)", field=name)
    if step > part.depth:
        raise InputError(
            f"step-down {step * 1e3:g} mm is larger than the part depth {part.depth * 1e3:g} mm",
            field="step_down",
        )


def lap_levels(part: AxisymmetricPart, step_down: float, max_wall_step: float | None = None) -> F64:
    """Wall arc-length positions ``s`` [m] of the laps, top to bottom.

    z-levels −Δz, −2Δz, … with the last at the full depth (a level closer than 1e-9 m to the
    bottom is merged into it); then, if ``max_wall_step`` is given, levels inserted where the
    along-wall distance between neighbours exceeds it.
    """
    g = part.generatrix
    depth = part.depth
    n = math.ceil(depth / step_down - 1e-9)
    z = -np.arange(1, n + 1) * step_down
    z[-1] = -depth
    s = g.wall_s_at_z(z)
    if max_wall_step is not None:
        if not (max_wall_step > 0):
            raise InputError("must be > 0", field="max_wall_step")
        s_all = np.concatenate([[0.0], s])
        pieces = []
        for a, b in zip(s_all[:-1], s_all[1:], strict=True):
            k = max(1, math.ceil((b - a) / max_wall_step - 1e-9))
            pieces.append(a + (b - a) * np.arange(1, k + 1) / k)
        s = np.concatenate(pieces)
    return s


def _lap_points(r: float, spacing: float) -> int:
    return max(8, math.ceil(2 * math.pi * r / spacing))


def _assemble(
    part: AxisymmetricPart, s: F64, phi: F64, lap: NDArray[np.int64], tool_radius: float,
    feed: float, meta: dict[str, object],
) -> Toolpath:
    r, z, a = part.generatrix.wall_at_s(s)
    c, sn = np.cos(phi), np.sin(phi)
    contact = np.stack([r * c, r * sn, z], axis=1)
    normal = np.stack([-np.sin(a) * c, -np.sin(a) * sn, np.cos(a)], axis=1)
    return Toolpath.from_contact(contact, normal, a, lap, tool_radius, feed, meta)


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
) -> Toolpath:
    """Step-down contour toolpath.

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
    """
    _check(part, tool_radius, step_down, spacing, feed)
    s_levels = lap_levels(part, step_down, max_wall_step)
    r_levels = part.generatrix.wall_at_s(s_levels)[0]
    sign = -1.0 if clockwise else 1.0
    s_parts, phi_parts, lap_parts = [], [], []
    for k, (s_k, r_k) in enumerate(zip(s_levels, r_levels, strict=True)):
        m = _lap_points(r_k, spacing)
        # closed contour: m points, the m+1-th would repeat the first
        phi_parts.append(start_angle + sign * 2 * math.pi * np.arange(m) / m)
        s_parts.append(np.full(m, s_k))
        lap_parts.append(np.full(m, k, dtype=np.int64))
    meta = {"kind": "step_down", "step_down": step_down, "spacing": spacing, "part": part.kind}
    return _assemble(
        part, np.concatenate(s_parts), np.concatenate(phi_parts), np.concatenate(lap_parts),
        tool_radius, feed, meta,
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
) -> Toolpath:
    """Spiral toolpath: within lap k the contact descends continuously from level k−1 to k.

    Same parameters as :func:`step_down`. The first lap starts at the top of the wall (s = 0);
    a final closed contour at the full depth finishes the bottom edge.
    """
    _check(part, tool_radius, step_down, spacing, feed)
    s_levels = np.concatenate([[0.0], lap_levels(part, step_down, max_wall_step)])
    sign = -1.0 if clockwise else 1.0
    g = part.generatrix
    s_parts, phi_parts, lap_parts = [], [], []
    for k in range(len(s_levels) - 1):
        r_mid = g.wall_at_s(0.5 * (s_levels[k] + s_levels[k + 1]))[0][0]
        m = _lap_points(r_mid, spacing)
        u = np.arange(m) / m
        s_parts.append(s_levels[k] + u * (s_levels[k + 1] - s_levels[k]))
        phi_parts.append(start_angle + sign * 2 * math.pi * u)
        lap_parts.append(np.full(m, k, dtype=np.int64))
    # closing contour at the bottom level
    r_last = g.wall_at_s(s_levels[-1])[0][0]
    m = _lap_points(r_last, spacing)
    s_parts.append(np.full(m + 1, s_levels[-1]))
    phi_parts.append(start_angle + sign * 2 * math.pi * np.arange(m + 1) / m)
    lap_parts.append(np.full(m + 1, len(s_levels) - 2, dtype=np.int64))
    meta = {"kind": "spiral", "step_down": step_down, "spacing": spacing, "part": part.kind}
    return _assemble(
        part, np.concatenate(s_parts), np.concatenate(phi_parts), np.concatenate(lap_parts),
        tool_radius, feed, meta,
    )
