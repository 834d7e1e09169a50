"""Stiffness maps over the work area (numbers only; plotting lives in ``roboisf.report``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError, UnreachableError
from roboisf.frames import invert
from roboisf.robot.ik import opw_ik, tool_poses
from roboisf.robot.model import RobotModel

__all__ = ["StiffnessMap", "stiffness_map"]

F64 = NDArray[np.float64]

#: Grid poses up to which a map is computed with numpy when the model's engine is "auto": a
#: 41 × 41 map takes 6 ms there and 0.48 s on the compiled engine in a process that has not
#: loaded numba yet (its import and first dispatch, +120 MB: ``robot show -o map.png`` 1.35 →
#: 0.85 s); at 201 × 201 the two are 0.09–0.10 s either way (2 vCPUs, 2026-11-28).
MAP_NUMPY_POSES = 100_000


@dataclass(frozen=True, eq=False)
class StiffnessMap:
    """Translational compliance over a grid of tool-down poses in the work plane.

    x, y : (nx,), (ny,) m — grid in the work frame at height z
    compliance : (ny, nx, 3) m/N — k_xx, k_yy, k_zz (work axes); NaN where unreachable
    reachable : (ny, nx) bool
    """

    x: F64
    y: F64
    z: float
    compliance: F64
    reachable: NDArray[np.bool_]
    robot: str


def stiffness_map(
    model: RobotModel,
    T_base_work: ArrayLike | None = None,
    *,
    half_width: float = 0.5,
    n: int = 41,
    z: float = 0.0,
    tool_rotation: float = 0.0,
    backend: str | None = None,
) -> StiffnessMap:
    """Diagonal translational compliance (work axes) of tool-down poses over a square grid.

    Points out of reach or beyond the joint limits are marked unreachable (not an error here:
    the map shows where the robot can work). ``backend``: the IK and VJM engine ("auto",
    "numba", "numpy"); default the model's, except that an "auto" model's map of at most
    :data:`MAP_NUMPY_POSES` poses is computed with numpy (faster than starting numba for it).
    """
    if T_base_work is None:
        T_base_work = model.default_placement
    if T_base_work is None:
        raise InputError(
            f"robot {model.name!r} has no default placement; give one", field="placement"
        )
    if not (half_width > 0) or n < 2:
        raise InputError("need half_width > 0 and n ≥ 2", field="grid")
    x = np.linspace(-half_width, half_width, n)
    y = np.linspace(-half_width, half_width, n)
    X, Y = np.meshgrid(x, y)
    pts = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], axis=1)
    if backend is None:
        small = model.backend == "auto" and X.size <= MAP_NUMPY_POSES
        backend = "numpy" if small else model.backend
    T_tip = tool_poses(pts, T_base_work, tool_rotation)
    q, ok = opw_ik(model, T_tip @ invert(model.T_flange_tip), backend=backend)
    qq = np.where(ok[:, None], q, 0.0)
    ok &= np.all((qq >= model.q_min) & (qq <= model.q_max), axis=1)
    k = np.full((X.size, 3), np.nan)
    if np.any(ok):
        kc = model.compliance(qq[ok], backend=backend)
        R = np.asarray(T_base_work, dtype=float)[:3, :3]
        kt = np.einsum("ji,njk,kl->nil", R, kc[:, :3, :3], R)
        k[ok] = np.diagonal(kt, axis1=1, axis2=2)
    elif not np.any(ok):
        raise UnreachableError("no grid point is reachable from this placement", indices=[])
    return StiffnessMap(x, y, float(z), k.reshape(n, n, 3), ok.reshape(n, n), model.name)
