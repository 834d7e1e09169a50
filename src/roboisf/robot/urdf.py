"""URDF robots: load any 6R arm through pinocchio (optional extra ``roboisf[urdf]``), write a URDF.

Loading maps the six revolute joints of the chain to :class:`~roboisf.robot.kinematics.Chain`
(each joint axis aligned with a local z-axis), takes the joint limits from the URDF and leaves the
joint stiffness unset (a URDF does not carry it). The URDF joint values are taken as the
controller angles (sign +1, offset 0), as ROS-Industrial robot descriptions are built.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.frames import matrix_to_rpy
from roboisf.robot.kinematics import Chain
from roboisf.robot.model import RobotModel

__all__ = ["load_urdf", "to_urdf"]

F64 = NDArray[np.float64]


def _align_z(axis: F64) -> F64:
    """A rotation whose z-column is ``axis`` (unit)."""
    a = axis / np.linalg.norm(axis)
    h = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
    x = np.cross(h, a)
    x /= np.linalg.norm(x)
    y = np.cross(a, x)
    return np.stack([x, y, a], axis=1)


def load_urdf(path: str | Path, tip_frame: str | None = None) -> RobotModel:
    """A :class:`RobotModel` from a URDF with six revolute joints (needs pinocchio).

    ``tip_frame``: the URDF frame used as the flange (default: ``tool0``/``flange`` if present,
    else the last link).
    """
    try:
        import pinocchio as pin
    except ImportError:
        raise InputError(
            "loading a URDF needs pinocchio: pip install 'roboisf[urdf]' (package 'pin')",
            file=path,
        ) from None
    p = Path(path)
    if not p.is_file():
        raise InputError("URDF file not found", file=p)
    try:
        pm = pin.buildModelFromUrdf(str(p))
    except Exception as e:  # pinocchio raises plain RuntimeError/ValueError
        raise InputError(f"cannot read URDF: {e}", file=p) from None
    joints = [j for j in pm.joints[1:]]
    if pm.nq != 6 or len(joints) != 6:
        raise InputError(
            f"expected a 6-joint arm, URDF has {len(joints)} joints (nq={pm.nq})", file=p
        )
    F = []
    prev_align = np.eye(3)
    q_min = np.asarray(pm.lowerPositionLimit, dtype=float).copy()
    q_max = np.asarray(pm.upperPositionLimit, dtype=float).copy()
    for k, j in enumerate(joints):
        sn = j.shortname()
        if "RevoluteUnaligned" in sn:
            axis = np.asarray(j.extract().axis, dtype=float)
        elif sn.startswith("JointModelR") and sn[-1] in "XYZ":
            axis = np.eye(3)["XYZ".index(sn[-1])]
        else:
            raise InputError(f"joint {k + 1} is {sn}; only revolute joints are supported", file=p)
        if pm.parents[k + 1] != k:
            raise InputError("the URDF is not a serial chain", file=p)
        Rz = _align_z(axis)
        M = pm.jointPlacements[k + 1].homogeneous.copy()
        T = np.eye(4)
        T[:3, :3] = prev_align.T @ M[:3, :3] @ Rz
        T[:3, 3] = prev_align.T @ M[:3, 3]
        F.append(T)
        prev_align = Rz
    names = [f.name for f in pm.frames]
    if tip_frame is None:
        tip_frame = next((n for n in ("tool0", "flange", "link_6", "link6") if n in names), None)
    if tip_frame is not None:
        if tip_frame not in names:
            raise InputError(f"frame {tip_frame!r} not in URDF; frames: {', '.join(names)}", file=p)
        fr = pm.frames[pm.getFrameId(tip_frame)]
        if fr.parentJoint != 6:
            raise InputError(f"frame {tip_frame!r} is not attached after joint 6", file=p)
        Mt = fr.placement.homogeneous.copy()
    else:
        Mt = np.eye(4)
    T = np.eye(4)
    T[:3, :3] = prev_align.T @ Mt[:3, :3]
    T[:3, 3] = prev_align.T @ Mt[:3, 3]
    F.append(T)
    bad = ~np.isfinite(q_min) | ~np.isfinite(q_max) | (q_min >= q_max)
    q_min[bad] = -2 * np.pi
    q_max[bad] = 2 * np.pi
    return RobotModel(
        name=p.stem,
        chain=Chain(np.array(F), np.ones(6), np.zeros(6)),
        q_min=q_min,
        q_max=q_max,
        source=f"URDF {p}",
    )


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
