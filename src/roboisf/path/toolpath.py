"""The toolpath: per point the contact on the nominal surface, the ball centre and the tip.

For a ball tool of radius R touching the nominal surface at contact point P with tool-side
normal n (tool axis = work-frame z, pointing up)::

    C = P + R n          (ball centre)
    T = C − R ẑ          (programmed tip: lowest point of the ball, the TCP of a ball tool)

All arrays are work-frame, SI: (N, 3) m, angles rad, time s.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError

__all__ = ["Toolpath", "tool_points"]

F64 = NDArray[np.float64]


def tool_points(contact: F64, normal: F64, tool_radius: float) -> tuple[F64, F64]:
    """Ball centre ``C = P + R n`` and tip ``T = C − R ẑ`` (both (N, 3) m)."""
    center = contact + tool_radius * normal
    tip = center.copy()
    tip[:, 2] -= tool_radius
    return center, tip


@dataclass(frozen=True)
class Toolpath:
    """A forming toolpath (work frame, SI).

    Attributes
    ----------
    contact : (N, 3) float, m — contact point on the nominal surface
    normal : (N, 3) float — unit tool-side surface normal at the contact
    center : (N, 3) float, m — ball centre
    tip : (N, 3) float, m — programmed tool tip (TCP)
    wall_angle : (N,) float, rad
    lap : (N,) int — 0-based lap (contour) index
    path_length : (N,) float, m — cumulative length of the *tip* path
    time : (N,) float, s — at the feed rate
    tool_radius : float, m
    feed : float, m/s
    """

    contact: F64
    normal: F64
    center: F64
    tip: F64
    wall_angle: F64
    lap: NDArray[np.int64]
    path_length: F64
    time: F64
    tool_radius: float
    feed: float
    meta: dict[str, object] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        n = self.contact.shape[0]
        for name in ("contact", "normal", "center", "tip"):
            a = getattr(self, name)
            if a.shape != (n, 3):
                raise InputError(f"expected shape ({n}, 3), got {a.shape}", field=name)
        for name in ("wall_angle", "lap", "path_length", "time"):
            a = getattr(self, name)
            if a.shape != (n,):
                raise InputError(f"expected shape ({n},), got {a.shape}", field=name)
        if n == 0:
            raise InputError("toolpath has no points")
        if not (self.tool_radius > 0):
            raise InputError("tool radius must be > 0", field="tool_radius")
        if not (self.feed > 0):
            raise InputError("feed must be > 0", field="feed")

    def __len__(self) -> int:
        return int(self.contact.shape[0])

    @property
    def depth(self) -> F64:
        """Depth of the contact point below the sheet plane, (N,) m (positive)."""
        return -self.contact[:, 2]

    @property
    def n_laps(self) -> int:
        return int(self.lap.max()) + 1

    @property
    def angle(self) -> F64:
        """Polar angle of the contact point about the part axis, (N,) rad in (−π, π]."""
        return np.arctan2(self.contact[:, 1], self.contact[:, 0])

    @classmethod
    def from_contact(
        cls,
        contact: F64,
        normal: F64,
        wall_angle: F64,
        lap: NDArray[np.int64],
        tool_radius: float,
        feed: float,
        meta: dict[str, object] | None = None,
    ) -> Toolpath:
        """Derive centre, tip, path length and time from contact points and normals."""
        contact = np.ascontiguousarray(contact, dtype=float)
        normal = np.ascontiguousarray(normal, dtype=float)
        center, tip = tool_points(contact, normal, tool_radius)
        seg = np.linalg.norm(np.diff(tip, axis=0), axis=1)
        s = np.concatenate([[0.0], np.cumsum(seg)])
        return cls(
            contact,
            normal,
            center,
            tip,
            np.asarray(wall_angle, dtype=float),
            np.asarray(lap, dtype=np.int64),
            s,
            s / feed,
            float(tool_radius),
            float(feed),
            dict(meta or {}),
        )

    def with_tip(self, tip: F64) -> Toolpath:
        """A copy with a new commanded tip (compensation); path length and time recomputed."""
        tip = np.asarray(tip, dtype=float)
        seg = np.linalg.norm(np.diff(tip, axis=0), axis=1)
        s = np.concatenate([[0.0], np.cumsum(seg)])
        center = tip.copy()
        center[:, 2] += self.tool_radius
        return replace(self, tip=tip, center=center, path_length=s, time=s / self.feed)
