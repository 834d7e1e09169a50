"""Per-point features of the local geometry, the same for a formed part and a planned one.

Every feature is computed from a toolpath's contacts, normals, wall angles and laps
(:mod:`roboisf.toolpath.geometry`) and the study's declared process values, never from
measured deviations, so the learner sees on a part not yet formed what it saw in the history:

==================== ======== ==========================================================
name                 unit     what
==================== ======== ==========================================================
wall_angle           rad      the nominal wall angle at the contact
contour_curvature    1/m      curvature of the lap in the sheet plane (along the path)
meridian_curvature   rad/m    change of the wall angle down the wall (across the path)
depth                m        contact depth below the sheet plane
rim_distance         m        distance to the first lap (the clamped rim)
step_down            m        the toolpath's step between laps
tool_radius          m        ball radius
sheet_thickness      m        the blank's thickness
==================== ======== ==========================================================

The material is not a number: :func:`point_features` returns it aside, and the learner keeps
one model input per material it has seen (:mod:`roboisf.learn.springback`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.toolpath.geometry import contour_curvature, meridian_curvature, rim_distance

__all__ = ["FEATURES", "FEATURE_TOLERANCE", "point_features"]

FEATURES = (
    "wall_angle",
    "contour_curvature",
    "meridian_curvature",
    "depth",
    "rim_distance",
    "step_down",
    "tool_radius",
    "sheet_thickness",
)

#: name → the absolute difference (in the feature's unit, SI) below which two values are the
#: same: floating-point noise (a cone's meridian curvature is ±1e-12 rad/m, not 0) must not read
#: as a value outside the history's range. Each is far below any difference that matters: 1e-4
#: rad (0.006°), a curvature of 1e-3 /m (a radius of 1 km), 1 µm.
FEATURE_TOLERANCE: dict[str, float] = {
    "wall_angle": 1e-4,
    "contour_curvature": 1e-3,
    "meridian_curvature": 1e-3,
    "depth": 1e-6,
    "rim_distance": 1e-6,
    "step_down": 1e-6,
    "tool_radius": 1e-6,
    "sheet_thickness": 1e-6,
}

F64 = NDArray[np.float64]


def point_features(
    contact: ArrayLike,
    normal: ArrayLike,
    wall_angle: ArrayLike,
    lap: ArrayLike,
    *,
    step_down: float,
    tool_radius: float,
    sheet_thickness: float,
) -> F64:
    """Features (N, len(FEATURES)) in the order of :data:`FEATURES` (SI).

    contact : (N, 3) m, normal : (N, 3), wall_angle : (N,) rad, lap : (N,) int — a toolpath in
    the work frame (z up, the part below z = 0); step_down, tool_radius, sheet_thickness : m.
    """
    c = np.asarray(contact, dtype=float)
    n = np.asarray(normal, dtype=float)
    a = np.asarray(wall_angle, dtype=float)
    k = np.asarray(lap, dtype=np.int64)
    N = len(c)
    if c.shape != (N, 3) or n.shape != (N, 3) or a.shape != (N,) or k.shape != (N,):
        raise InputError("expected contact (N, 3), normal (N, 3), wall_angle (N,), lap (N,)")
    for name, v in (
        ("step_down", step_down),
        ("tool_radius", tool_radius),
        ("sheet_thickness", sheet_thickness),
    ):
        if not (np.isfinite(v) and v > 0):
            raise InputError(f"must be > 0 and finite, got {v!r}", field=name)
    cols = {
        "wall_angle": a,
        "contour_curvature": contour_curvature(c, n, k),
        "meridian_curvature": meridian_curvature(c, a, k),
        "depth": -c[:, 2],
        "rim_distance": rim_distance(c, k),
        "step_down": np.full(N, float(step_down)),
        "tool_radius": np.full(N, float(tool_radius)),
        "sheet_thickness": np.full(N, float(sheet_thickness)),
    }
    return np.column_stack([cols[f] for f in FEATURES])
