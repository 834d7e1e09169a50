"""The one interface every nominal part offers, whatever its shape.

Code that consumes a part (toolpaths, registration, deviations, the cell, planning) types it as
:class:`Part` and uses only what is declared here — no ``isinstance`` checks on concrete part
classes. Work frame: origin at the blank centre in the sheet plane, z along the tool axis (up,
out of the part), the part below z = 0. All lengths in metres.

Symmetry (what a 6-DOF registration on the part's own surface cannot observe, and what it may
use): :class:`Symmetry` names a continuous rotation about the z axis (surfaces of revolution), a
discrete one of order n (a square pyramid: 4, a rectangular one: 2), or none.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from roboisf.parts.axisymmetric import SurfaceQuery

F64 = NDArray[np.float64]

__all__ = ["Part", "Symmetry"]


@dataclass(frozen=True)
class Symmetry:
    """Rotational symmetry of a part about the work z axis.

    Attributes
    ----------
    order : int — 0 for a continuous symmetry (surface of revolution), n ≥ 2 for a discrete one
        (the part maps onto itself after a turn of 2π/n), 1 for none.
    """

    order: int

    @property
    def continuous(self) -> bool:
        return self.order == 0

    @property
    def angle(self) -> float:
        """Smallest non-zero turn [rad] that maps the part onto itself (0 if continuous, 2π if
        none)."""
        return 0.0 if self.order == 0 else 2.0 * np.pi / self.order


@runtime_checkable
class Part(Protocol):
    """A nominal part surface (work frame, m).

    Implemented by :class:`~roboisf.parts.AxisymmetricPart` (cone, VWACF, profile),
    :class:`~roboisf.parts.Pyramid` and :class:`~roboisf.parts.MeshPart` (STL/OBJ/PLY/STEP/IGES),
    and by any new part kind.
    """

    kind: ClassVar[str]

    @property
    def sheet_thickness(self) -> float:
        """Initial sheet thickness [m] (read-only, so frozen dataclasses implement it)."""
        ...

    @property
    def depth(self) -> float:
        """Depth of the deepest formed point below the sheet plane [m] (positive)."""
        ...

    @property
    def bounds(self) -> tuple[F64, F64]:
        """Lower and upper corners (3,) [m] of the formed surface's bounding box."""
        ...

    @property
    def symmetry(self) -> Symmetry:
        """Rotational symmetry about the work z axis."""
        ...

    def closest_point(self, points: ArrayLike) -> SurfaceQuery:
        """Exact closest point, tool-side unit normal and signed distance for ``points`` (N, 3)
        [m]."""
        ...

    def signed_distance(self, points: ArrayLike) -> F64:
        """Signed distance [m] of ``points`` (N, 3) to the surface (+ on the tool side)."""
        ...

    def to_dict(self) -> dict[str, object]:
        """The part TOML table (mm, degrees) that :func:`roboisf.parts.part_from_dict` reads."""
        ...
