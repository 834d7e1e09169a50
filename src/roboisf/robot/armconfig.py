"""The arm configuration of programmed points, as each robot controller names it.

:func:`arm_config` computes, from the joint angles, where the wrist centre is (in front of or
behind axis 1, ahead of or behind the lower arm); :func:`abb_confdata` (ABB ``confdata``),
:func:`kuka_status_turn` (KUKA ``S``/``T``) and :func:`fanuc_config` (FANUC ``CONFIG``) turn it
into each controller's bits. :func:`program_config` runs the IK along a toolpath and returns the
configuration of every point; :func:`parse_arm_config` reads a first-point configuration from the
command line. The program writers (:mod:`roboisf.programs`) and the IK's branch matching
(:mod:`roboisf.robot.ik`) both use these, which is why they live in ``robot`` and not with the
file formats.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError

if TYPE_CHECKING:
    from roboisf.path.toolpath import Toolpath
    from roboisf.robot.model import RobotModel

__all__ = [
    "ArmConfig",
    "abb_confdata",
    "arm_config",
    "fanuc_config",
    "kuka_status_turn",
    "parse_arm_config",
    "program_config",
]

F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class ArmConfig:
    """Joint angles and arm configuration of every programmed point (controller convention).

    Attributes
    ----------
    q : (N, 6) float, rad — joint angles, continuous along the path (IK or a joint log)
    front : (N,) bool — wrist centre in front of axis 1 (x > 0 in the axis-1 frame)
    ahead : (N,) bool — wrist centre ahead of the lower arm (on the +x side, in the axis-1 frame,
        of the line through axes 2 and 3)

    ``front`` and ``ahead`` are computed from the geometry, not copied from an IK branch name:
    the IK branch "front"/"back" is ``front`` and "up" is ``ahead == front`` (tested).
    """

    q: F64
    front: NDArray[np.bool_]
    ahead: NDArray[np.bool_]

    def __len__(self) -> int:
        return int(self.q.shape[0])


def arm_config(model: RobotModel, q: ArrayLike) -> ArmConfig:
    """The arm configuration of joint angles ``q`` (N, 6) rad of an OPW ``model``."""
    if model.opw is None:
        raise InputError(
            f"robot {model.name!r} has no OPW geometry; the configuration bits need it",
            field="robot",
        )
    qa = np.asarray(q, dtype=float)
    if qa.ndim != 2 or qa.shape[1] != 6 or not np.all(np.isfinite(qa)):
        raise InputError(f"expected finite joint angles (N, 6), got {qa.shape}", field="q")
    g = model.opw
    th = model.chain.theta(qa)
    t2, t3 = th[:, 1], th[:, 2]
    wx = g.a2 * np.cos(t3) + g.c3 * np.sin(t3)  # wrist centre ⟂ the lower arm (+: ahead of it)
    wz = g.c2 - g.a2 * np.sin(t3) + g.c3 * np.cos(t3)
    x_arm = g.a1 + wx * np.cos(t2) + wz * np.sin(t2)  # wrist centre x in the axis-1 frame
    return ArmConfig(q=qa, front=x_arm > 0, ahead=wx > 0)


def program_config(
    model: RobotModel,
    tp: Toolpath,
    T_base_work: ArrayLike,
    tool_rotation: ArrayLike = 0.0,
    *,
    match_q: ArrayLike | None = None,
    confdata: ArrayLike | None = None,
    kuka_st: ArrayLike | None = None,
) -> ArmConfig:
    """IK along ``tp`` (``model`` carries the tool) and the arm configuration of every point.

    Uses :func:`roboisf.robot.ik.ik_toolpath` (one continuous branch: by default front, elbow
    up, no flip; or the branch and turns of the first point matching ``match_q`` (6,) rad,
    ABB ``confdata`` (cf1, cf4, cf6, cfx) or KUKA ``kuka_st`` (S, T)). The confdata / S, T / FANUC
    CONFIG the writers put in the program are computed from these joints, so the chosen branch
    drives the program.
    """
    from roboisf.robot.ik import SingularityWarning, ik_toolpath

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SingularityWarning)
        ik = ik_toolpath(
            model,
            tp.tip,
            T_base_work,
            tool_rotation=tool_rotation,
            match_q=match_q,
            confdata=confdata,
            kuka_st=kuka_st,
        )
    return arm_config(model, ik.q)


def parse_arm_config(text: str | None, field: str = "--arm-config") -> dict[str, F64]:
    """The IK configuration of the first point from a command-line string, as keyword arguments
    of :func:`program_config` / :func:`roboisf.robot.ik.ik_toolpath`.

    2 integers → KUKA ``S,T``; 4 integers → ABB confdata ``cf1,cf4,cf6,cfx``; 6 numbers → joint
    angles q1..q6 in degrees (the solution nearest them). None or "" → {} (the default branch).
    """
    if text is None or not text.strip():
        return {}
    try:
        v = np.array([float(t) for t in text.split(",")])
    except ValueError:
        raise InputError(
            f"expected 2 (KUKA S,T), 4 (ABB cf1,cf4,cf6,cfx) or 6 (joints, deg) comma-separated "
            f"numbers, got {text!r}",
            field=field,
        ) from None
    if v.size not in (2, 4, 6) or not np.all(np.isfinite(v)):
        raise InputError(
            f"expected 2 (KUKA S,T), 4 (ABB cf1,cf4,cf6,cfx) or 6 (joints, deg) numbers, "
            f"got {text!r}",
            field=field,
        )
    if v.size == 6:
        return {"match_q": np.radians(v)}
    if np.any(v != np.round(v)):
        raise InputError(f"confdata and S,T are integers, got {text!r}", field=field)
    return {"kuka_st" if v.size == 2 else "confdata": v.astype(np.int64)}


def _deg(q: ArrayLike) -> F64:
    """Degrees rounded to 1e-6° so that a joint at a quadrant boundary (q6 = −180°) computed as
    −180.0000000001° or −179.9999999999° lands in the same quadrant."""
    return np.round(np.degrees(np.asarray(q, dtype=float)), 6)


def abb_confdata(cfg: ArmConfig) -> NDArray[np.int64]:
    """ABB ``confdata [cf1, cf4, cf6, cfx]`` (N, 4) of every point.

    cf1, cf4, cf6: the quadrant of axis 1, 4, 6 — ``floor(q / 90°)`` (0 for [0°, 90°), −1 for
    [−90°, 0°), −2 for [−180°, −90°), 2 for [180°, 270°), …), as the ABB RAPID reference defines
    confdata for serial robots. cfx (0…7) = 4·(wrist centre behind axis 1) + 2·(wrist centre behind
    the lower arm) + (axis 5 negative).
    """
    d = _deg(cfg.q)
    cf = np.floor(d[:, [0, 3, 5]] / 90.0).astype(np.int64)
    cfx = 4 * (~cfg.front) + 2 * (~cfg.ahead) + (d[:, 4] < 0)
    return np.column_stack([cf, cfx.astype(np.int64)])


def kuka_status_turn(cfg: ArmConfig) -> NDArray[np.int64]:
    """KUKA ``S`` and ``T`` (N, 2) of every point (KSS "Status" and "Turn").

    S bit 0: wrist centre in the overhead area (x < 0 in the A1 frame); bit 1: the arm bit, set
    with the wrist centre ahead of the lower arm (A3 ≥ φ: the usual elbow-up posture, S = 2 or 6);
    bit 2: A5 in [−180°, 0°) or ≥ 180°. T bit i: axis i+1 negative.
    """
    d = _deg(cfg.q)
    a5 = d[:, 4]
    b2 = ((a5 >= -180) & (a5 < 0)) | (a5 >= 180)
    s = (~cfg.front).astype(np.int64) + 2 * cfg.ahead + 4 * b2
    t = ((d < 0).astype(np.int64) << np.arange(6)).sum(axis=1)
    return np.column_stack([s, t])


def fanuc_config(cfg: ArmConfig) -> list[str]:
    """FANUC ``CONFIG : 'F U T, t1, t4, t6'`` strings of every point.

    F/N: wrist flipped (J5 < 0) or not; U/D: elbow up (wrist centre ahead of the lower arm, seen
    from the front) or down; T/B: wrist centre in front of (toward) or behind axis 1. Turn numbers
    of J1, J4, J6: ``floor((q + 180°) / 360°)`` — 0 for [−180°, 180°), 1 for [180°, 540°), …
    """
    d = _deg(cfg.q)
    up = cfg.ahead == cfg.front
    turns = np.floor((d[:, [0, 3, 5]] + 180.0) / 360.0).astype(np.int64)
    return [
        f"{'F' if d5 < 0 else 'N'} {'U' if u else 'D'} {'T' if f else 'B'}, {a}, {b}, {c}"
        for d5, u, f, (a, b, c) in zip(
            d[:, 4].tolist(), up.tolist(), cfg.front.tolist(), turns.tolist(), strict=True
        )
    ]
