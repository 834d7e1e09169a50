"""URDF robots: read the 6R arm of any URDF (passive and mimic branches skipped), write a URDF.

The URDF is read with the standard library's XML parser (no ROS, no pinocchio needed; pinocchio
is the independent oracle of the tests). From the tip frame (``tool0``/``flange`` or
``tip_frame=``) back to the root, the chain must hold exactly six actuated revolute (or
continuous) joints; fixed joints on the way are folded into the fixed transforms. Joints *off*
that path — the passive parallelogram links, balancers and pistons of the IRB 6640, IRB 6700 and
FANUC M-900 descriptions, most of them ``<mimic>`` joints — do not move the tip and are skipped
(:attr:`UrdfArm.skipped` names them). A mimic or prismatic joint *on* the path is refused with a
message naming it.

Each joint's axis is aligned with a local z-axis, giving the
:class:`~roboisf.robot.kinematics.Chain` form; the URDF joint values are the controller angles
(sign +1, offset 0), as ROS-Industrial descriptions are built (FANUC: the ROS J3 is the
pendant's J3 + J2, see ``docs/robot.md``).
Limits come from the URDF; the joint stiffness is left unset (a URDF does not carry it).

:func:`load_urdf` then tries to express the chain as an OPW robot
(:func:`roboisf.robot.opw_fit.fit_opw`, checked by FK at random configurations); when it fits,
the model gets the closed-form IK and compiled kernels of the presets, otherwise IK along a
toolpath uses the numerical solver of :mod:`roboisf.robot.numik`.
"""

from __future__ import annotations

import math
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.frames import matrix_to_rpy
from roboisf.robot.kinematics import Chain
from roboisf.robot.model import RobotModel

__all__ = ["UrdfArm", "load_urdf", "read_urdf_arm", "to_urdf"]

F64 = NDArray[np.float64]

_TIP_NAMES = ("tool0", "flange")


def _align_z(axis: F64) -> F64:
    """A rotation whose z-column is ``axis`` (unit)."""
    a = axis / np.linalg.norm(axis)
    h = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
    x = np.cross(h, a)
    x /= np.linalg.norm(x)
    y = np.cross(a, x)
    return np.stack([x, y, a], axis=1)


def _rpy(r: float, p: float, y: float) -> F64:
    """URDF fixed-axis roll-pitch-yaw: ``Rz(y) Ry(p) Rx(r)``."""
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _floats(text: str | None, n: int, default: tuple[float, ...], where: str, p: Path) -> F64:
    if text is None:
        return np.array(default, dtype=float)
    try:
        v = np.array([float(t) for t in text.split()], dtype=float)
    except ValueError:
        raise InputError(f"{where}: expected {n} numbers, got {text!r}", file=p) from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise InputError(f"{where}: expected {n} finite numbers, got {text!r}", file=p)
    return v


def _limit(lim: Any, attr: str, joint: str, jt: str, p: Path) -> float:
    """A joint's ``<limit lower/upper>`` (rad); NaN when absent (the arm then gets ±2π, as for a
    continuous joint). A value given but not a finite number, or beyond ±720° (degrees written
    where URDF has radians), is refused like a robot TOML's limits, not widened to ±360°."""
    text = None if lim is None else lim.get(attr)
    if text is None or jt != "revolute":
        return math.nan
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise InputError(
            f"joint {joint!r}: <limit {attr}={text!r}> must be a finite angle in rad", file=p
        )
    if abs(v) > 4 * math.pi:
        raise InputError(
            f"joint {joint!r}: <limit {attr}={text!r}> is {math.degrees(v):.6g}° in rad, beyond "
            f"the ±720° a joint turns; URDF limits are radians ({v:g}° is "
            f"{math.radians(v):.4g} rad)",
            file=p,
        )
    return v


@dataclass(frozen=True)
class _Joint:
    name: str
    type: str
    parent: str
    child: str
    M: F64  # (4, 4) parent link → joint frame (the URDF <origin>)
    axis: F64  # (3,) unit, joint frame
    lower: float
    upper: float
    mimic: str | None


@dataclass(frozen=True, eq=False)
class UrdfArm:
    """The 6R arm read from a URDF.

    chain : Chain — base link → tip frame, URDF joint values as controller angles
    q_min, q_max : (6,) float, rad — URDF limits (±2π where the URDF gives none)
    joints : list[str] — the six actuated joints, base to tip
    tip_frame : str
    skipped : list[str] — joints off the base→tip path (passive/mimic branches), ignored
    name : str — the URDF's robot name
    """

    chain: Chain
    q_min: F64
    q_max: F64
    joints: list[str]
    tip_frame: str
    skipped: list[str]
    name: str


def read_urdf_arm(path: str | Path, tip_frame: str | None = None) -> UrdfArm:
    """Read the base→tip 6R chain of a URDF (see the module docstring)."""
    p = Path(path)
    if not p.is_file():
        raise InputError("URDF file not found", file=p)
    try:
        root = ET.parse(p).getroot()
    except ET.ParseError as e:
        raise InputError(f"cannot read URDF: not valid XML ({e})", file=p) from None
    if root.tag != "robot":
        raise InputError(
            f"cannot read URDF: root element is <{root.tag}>, expected <robot>", file=p
        )
    links = [el.get("name", "") for el in root.findall("link")]
    joints: dict[str, _Joint] = {}
    for el in root.findall("joint"):
        name = el.get("name", "?")
        jt = el.get("type", "")
        par, ch = el.find("parent"), el.find("child")
        if par is None or ch is None:
            raise InputError(f"joint {name!r} needs <parent link=…> and <child link=…>", file=p)
        org = el.find("origin")
        xyz = _floats(
            None if org is None else org.get("xyz"), 3, (0, 0, 0), f"joint {name!r} origin xyz", p
        )
        rpy = _floats(
            None if org is None else org.get("rpy"), 3, (0, 0, 0), f"joint {name!r} origin rpy", p
        )
        M = np.eye(4)
        M[:3, :3] = _rpy(*rpy)
        M[:3, 3] = xyz
        ax_el = el.find("axis")
        axis = _floats(
            None if ax_el is None else ax_el.get("xyz"), 3, (1, 0, 0), f"joint {name!r} axis", p
        )
        lim = el.find("limit")
        lo = _limit(lim, "lower", name, jt, p)
        hi = _limit(lim, "upper", name, jt, p)
        if jt == "revolute" and math.isfinite(lo) and math.isfinite(hi) and lo >= hi:
            raise InputError(
                f"joint {name!r}: <limit lower={lo:g} upper={hi:g}> (rad) needs lower < upper",
                file=p,
            )
        mim = el.find("mimic")
        child = ch.get("link", "")
        if child in {j.child for j in joints.values()}:
            raise InputError(f"link {child!r} has two parent joints: not a tree", file=p)
        joints[name] = _Joint(
            name,
            jt,
            par.get("link", ""),
            child,
            M,
            axis,
            lo,
            hi,
            None if mim is None else mim.get("joint"),
        )
    by_child = {j.child: j for j in joints.values()}
    if tip_frame is None:
        tip_frame = next((n for n in _TIP_NAMES if n in links), None)
        if tip_frame is None:  # the leaf reached through the most revolute joints
            leaves = [ln for ln in links if ln not in {j.parent for j in joints.values()}]

            def depth(link: str) -> tuple[int, int]:
                k = n = 0
                while link in by_child and n <= len(joints):
                    j = by_child[link]
                    k += j.type in ("revolute", "continuous") and j.mimic is None
                    n += 1
                    link = j.parent
                return k, n

            tip_frame = max(leaves, key=depth) if leaves else None
    if tip_frame is None or tip_frame not in links:
        raise InputError(f"frame {tip_frame!r} not in URDF; links: {', '.join(links)}", file=p)
    path_joints: list[_Joint] = []
    link = tip_frame
    while link in by_child:
        path_joints.append(by_child[link])
        link = by_child[link].parent
        if len(path_joints) > len(joints):
            raise InputError("the URDF's joints form a loop", file=p)
    path_joints.reverse()
    on_path = {j.name for j in path_joints}
    skipped = [n for n in joints if n not in on_path]
    active: list[_Joint] = []
    for j in path_joints:
        if j.type == "fixed":
            continue
        if j.type not in ("revolute", "continuous"):
            raise InputError(
                f"joint {j.name!r} ({j.type}) lies between the base and {tip_frame!r}; only "
                "revolute joints are supported there",
                file=p,
            )
        if j.mimic is not None:
            raise InputError(
                f"joint {j.name!r} mimics {j.mimic!r} and lies between the base and "
                f"{tip_frame!r}; a mimic joint on the tool's chain is not supported",
                file=p,
            )
        active.append(j)
    if len(active) != 6:
        raise InputError(
            f"expected 6 actuated revolute joints between the base and {tip_frame!r}, found "
            f"{len(active)} ({', '.join(j.name for j in active)})",
            file=p,
        )
    # F_0 … F_6 with every joint axis on its local z
    F: list[F64] = []
    acc = np.eye(4)  # transform since the previous joint frame (aligned)
    prev_align = np.eye(4)
    for j in path_joints:
        acc = acc @ j.M
        if j.type == "fixed":
            continue
        n = np.linalg.norm(j.axis)
        if n == 0:
            raise InputError(f"joint {j.name!r} has a zero axis", file=p)
        A = np.eye(4)
        A[:3, :3] = _align_z(j.axis / n)
        F.append(np.linalg.inv(prev_align) @ acc @ A)
        prev_align = A
        acc = np.eye(4)
    F.append(np.linalg.inv(prev_align) @ acc)
    q_min = np.array([j.lower for j in active])
    q_max = np.array([j.upper for j in active])
    bad = (
        ~np.isfinite(q_min)
        | ~np.isfinite(q_max)
        | (q_min >= q_max)
        | np.array([j.type == "continuous" for j in active])
    )
    q_min[bad] = -2 * np.pi
    q_max[bad] = 2 * np.pi
    Fa = np.array(F)
    Fa[np.abs(Fa) < 1e-15] = 0.0
    return UrdfArm(
        chain=Chain(Fa, np.ones(6), np.zeros(6)),
        q_min=q_min,
        q_max=q_max,
        joints=[j.name for j in active],
        tip_frame=tip_frame,
        skipped=skipped,
        name=root.get("name", p.stem),
    )


def load_urdf(path: str | Path, tip_frame: str | None = None, *, opw: bool = True) -> RobotModel:
    """A :class:`RobotModel` of the 6R arm of a URDF.

    ``tip_frame``: the URDF link used as the flange (default ``tool0``/``flange`` if present,
    else the leaf link behind the most revolute joints, the deepest of those). With ``opw``
    (default) the chain is re-expressed as an OPW robot when its structure fits
    (:func:`roboisf.robot.opw_fit.fit_opw`: parameters, signs and offsets, accepted only when FK
    agrees to 1e-9 m / rad at random configurations): closed-form IK and the compiled kernels
    then apply. Otherwise the model has no OPW geometry and
    :func:`~roboisf.robot.ik.ik_toolpath` uses the numerical IK.
    """
    from roboisf.robot.opw_fit import fit_opw

    p = Path(path)
    arm = read_urdf_arm(p, tip_frame)
    src = f"URDF {p.name} (tip {arm.tip_frame}"
    if arm.skipped:
        src += f"; joints off the tool's chain skipped: {', '.join(arm.skipped)}"
    src += ")"
    chain, g = arm.chain, None
    if opw:
        fit = fit_opw(arm.chain, arm.q_min, arm.q_max)
        if fit is not None:
            chain, g = fit
            src += "; OPW parameters extracted, FK-checked"
    return RobotModel(name=p.stem, chain=chain, q_min=arm.q_min, q_max=arm.q_max, opw=g, source=src)


def to_urdf(model: RobotModel, name: str | None = None) -> str:
    """URDF text of ``model``'s kinematics (joints = controller angles; tool as fixed ``tip``).

    Each joint's origin is ``F_{i-1} Rz(offset_i)`` and its axis ``(0, 0, sign_i)``.
    """
    ch = model.chain
    nm = name or model.name

    def origin(T: F64) -> str:
        with warnings.catch_warnings():  # gimbal lock is harmless: the matrix is reproduced
            warnings.simplefilter("ignore")
            rpy = matrix_to_rpy(T[:3, :3])
        xyz = T[:3, 3]
        return (
            f'<origin xyz="{xyz[0]:.17g} {xyz[1]:.17g} {xyz[2]:.17g}" '
            f'rpy="{rpy[0]:.17g} {rpy[1]:.17g} {rpy[2]:.17g}"/>'
        )

    lines = ['<?xml version="1.0"?>', f'<robot name="{nm}">', '  <link name="base_link"/>']
    parent = "base_link"
    for i in range(6):
        c, s = np.cos(ch.offset[i]), np.sin(ch.offset[i])
        Rz = np.eye(4)
        Rz[:2, :2] = [[c, -s], [s, c]]
        T = ch.F[i] @ Rz
        child = f"link_{i + 1}"
        lines += [
            f'  <link name="{child}"/>',
            f'  <joint name="joint_{i + 1}" type="revolute">',
            f'    <parent link="{parent}"/><child link="{child}"/>',
            f"    {origin(T)}",
            f'    <axis xyz="0 0 {int(ch.sign[i])}"/>',
            f'    <limit lower="{model.q_min[i]:.17g}" upper="{model.q_max[i]:.17g}" '
            'effort="1e4" velocity="3"/>',
            "  </joint>",
        ]
        parent = child
    lines += [
        '  <link name="tip"/>',
        '  <joint name="tip_joint" type="fixed">',
        f'    <parent link="{parent}"/><child link="tip"/>',
        f"    {origin(ch.F[6] @ model.T_flange_tip)}",
        "  </joint>",
        "</robot>",
    ]
    return "\n".join(lines) + "\n"
