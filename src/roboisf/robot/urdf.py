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
from dataclasses import dataclass, field
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
#: Largest rounding [rad] of a URDF angle that ``snap`` undoes: an ``rpy`` angle this close to a
#: multiple of 15° (π/12), or an axis component this close to 0 or ±1, is taken as that value —
#: any angle written to 3 decimals (``1.571``, ``3.142``) or more (``3.1415926``); 1e-3 rad moves a
#: point 1 m away by 1 mm, and the model says by how much its FK moved.
SNAP_TOL = 1e-3


def _snap_rpy(v: F64, where: str, notes: list[str]) -> F64:
    out = v.copy()
    for i, a in enumerate(v):
        k = round(float(a) / (math.pi / 12))
        d = float(a) - k * math.pi / 12
        if 0 < abs(d) <= SNAP_TOL:
            out[i] = k * math.pi / 12
            notes.append(f"{where} rpy[{i}] {a:.10g} → {k * 15}° ({d:+.2g} rad)")
    return out


def _snap_axis(v: F64, where: str, notes: list[str]) -> F64:
    n = float(np.linalg.norm(v))
    if n == 0:
        return v
    u = v / n
    small = (np.abs(u) > 0) & (np.abs(u) <= SNAP_TOL)
    if small.any():
        ax = " ".join(f"{c:g}" for c in v)
        notes.append(f"{where} axis {ax} → components {np.flatnonzero(small).tolist()} = 0")
        u = np.where(small, 0.0, u)
        return u / np.linalg.norm(u)
    return v


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
    snapped : list[str] — angles and axis components moved to the value they round (read with
        ``snap=True``): ``joint 'j' rpy[0] 3.1415926 → 180°``
    """

    chain: Chain
    q_min: F64
    q_max: F64
    joints: list[str]
    tip_frame: str
    skipped: list[str]
    name: str
    snapped: list[str] = field(default_factory=list)


def read_urdf_arm(path: str | Path, tip_frame: str | None = None, *, snap: bool = False) -> UrdfArm:
    """Read the base→tip 6R chain of a URDF (see the module docstring).

    ``snap``: undo the rounding of angles written with few decimals (:data:`SNAP_TOL`), each
    change listed in :attr:`UrdfArm.snapped`.
    """
    snapped: list[str] = []
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
        if snap:
            rpy = _snap_rpy(rpy, f"joint {name!r}", snapped)
        M = np.eye(4)
        M[:3, :3] = _rpy(*rpy)
        M[:3, 3] = xyz
        ax_el = el.find("axis")
        axis = _floats(
            None if ax_el is None else ax_el.get("xyz"), 3, (1, 0, 0), f"joint {name!r} axis", p
        )
        if snap:
            axis = _snap_axis(axis, f"joint {name!r}", snapped)
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
        if tip_frame is None:
            # the link reached through the most revolute joints (and then the deepest) with only
            # revolute and fixed joints on the way: a gripper's fingers (prismatic) or a mimic
            # branch is not the arm's end
            def depth(link: str) -> tuple[int, int] | None:
                k = n = 0
                while link in by_child and n <= len(joints):
                    j = by_child[link]
                    if j.type not in ("revolute", "continuous", "fixed") or j.mimic is not None:
                        return None
                    k += j.type != "fixed"
                    n += 1
                    link = j.parent
                return k, n

            ranked = [(d, ln) for ln in links if (d := depth(ln)) is not None]
            tip_frame = max(ranked)[1] if ranked else None
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
                "revolute joints are supported there: name the arm's flange link with "
                "--tip-link",
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
        what = (
            f"a {len(active)}-joint arm: roboisf models 6-joint arms (6R) only"
            if len(active) > 6
            else "is the tip link right? name the arm's flange link with --tip-link"
        )
        raise InputError(
            f"expected 6 actuated revolute joints between the base and {tip_frame!r}, found "
            f"{len(active)} ({', '.join(j.name for j in active)}): {what}",
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
        snapped=snapped,
    )


def _flanges_on_axis6(chain: Chain) -> list[tuple[Chain, F64]]:
    """The chain with its tip frame moved to an OPW flange — origin on axis 6 where the tip's
    origin projects, z along axis 6 one way or the other — and the tip frame in that flange
    frame (a constant: both ride on link 6)."""
    F6 = chain.F[6]  # tip in the joint-6 frame, whose z is axis 6
    out = []
    for s in (1.0, -1.0):
        Fl = np.eye(4)
        Fl[:3, :3] = np.diag([1.0, s, s])  # z along ±axis 6 (a half turn about x for −)
        Fl[2, 3] = F6[2, 3]
        F = chain.F.copy()
        F[6] = Fl
        out.append((Chain(F, chain.sign, chain.offset), np.linalg.inv(Fl) @ F6))
    return out


def _fk_gap(a: Chain, b: Chain, q_min: F64, q_max: F64, n: int = 200) -> float:
    """Largest tip position difference [m] of two chains at random configurations."""
    from roboisf.robot.kinematics import chain_fk

    rng = np.random.default_rng(1)
    q = rng.uniform(np.maximum(q_min, -2 * np.pi), np.minimum(q_max, 2 * np.pi), (n, 6))
    return float(
        np.max(np.linalg.norm(chain_fk(a, q)[:, :3, 3] - chain_fk(b, q)[:, :3, 3], axis=1))
    )


def load_urdf(path: str | Path, tip_frame: str | None = None, *, opw: bool = True) -> RobotModel:
    """A :class:`RobotModel` of the 6R arm of a URDF.

    ``tip_frame``: the URDF link used as the flange (default ``tool0``/``flange`` if present,
    else the link behind the most revolute joints with only revolute and fixed joints on its way,
    the deepest of those). With ``opw`` (default) the chain is re-expressed as an OPW robot when
    its structure fits (:func:`roboisf.robot.opw_fit.fit_opw`: parameters, signs and offsets,
    accepted only when FK agrees to 1e-9 m / rad at random configurations): closed-form IK and
    the compiled kernels then apply. Two things a real URDF does that the 1e-9 test refuses are
    undone, and said in the model's ``source``:

    * **angles rounded** in the file (``rpy="3.1415926 -1.570796 0"``): read again with every
      ``rpy`` angle within :data:`SNAP_TOL` (1e-3 rad) of a multiple of 15° snapped to it (and
      axis components within it of 0 set to 0); the FK of the snapped chain is compared with the
      file's and the largest tip difference stated;
    * **a tip link that is not an OPW flange** (its z not along axis 6, e.g. x along it): the
      flange is put on axis 6 (the tip link's origin projected on it, z along it) and the tip
      link becomes a constant transform on it (``RobotModel.T_flange_link``): tools given to
      :meth:`~RobotModel.with_tool` stay in the tip link's frame.

    Otherwise the model has no OPW geometry, :func:`~roboisf.robot.ik.ik_toolpath` uses the
    numerical IK and ``RobotModel.ik_note`` says why (a warning repeats it at every IK).
    """
    from roboisf.robot.opw_fit import explain_opw

    p = Path(path)
    arm = read_urdf_arm(p, tip_frame)
    src = f"URDF {p.name} (tip {arm.tip_frame}"
    if arm.skipped:
        src += f"; joints off the tool's chain skipped: {', '.join(arm.skipped)}"
    src += ")"
    chain, g = arm.chain, None
    T_fl = np.eye(4)
    note = ""
    if opw:
        fit, why = explain_opw(arm.chain, arm.q_min, arm.q_max)
        tried = [arm]
        if fit is None:
            snapped = read_urdf_arm(p, arm.tip_frame, snap=True)
            if snapped.snapped:
                tried.append(snapped)
        for a in tried:
            cands: list[tuple[Chain, F64]] = [(a.chain, np.eye(4))]
            cands += [
                c
                for c in _flanges_on_axis6(a.chain)
                if not np.allclose(c[1], np.eye(4), atol=1e-12)
            ]
            for k, (ch0, T) in enumerate(cands):
                f, w = explain_opw(ch0, a.q_min, a.q_max)
                if f is None:
                    if k == 0 and a is not arm:
                        why = w  # the snapped chain's reason: its structure, not the rounding
                    continue
                fit, chain, g, T_fl = f, f[0], f[1], T
                if a is not arm:
                    gap = _fk_gap(a.chain, arm.chain, arm.q_min, arm.q_max)
                    src += (
                        f"; angles rounded in the file snapped to their exact values (within "
                        f"{SNAP_TOL:g} rad: {'; '.join(a.snapped)}); FK moves by ≤ "
                        f"{gap * 1e6:.3g} µm at the tip link"
                    )
                if T is not cands[0][1]:
                    src += (
                        f"; the tip link {arm.tip_frame!r} is not an OPW flange (its z is not "
                        "along axis 6): the flange is taken on axis 6, the tip link fixed on it"
                    )
                break
            if g is not None:
                break
        if g is None:
            note = (
                f"closed-form IK not available for {p.name} (tip {arm.tip_frame}): {why}; IK "
                "along a toolpath is numerical (slower; the start configuration only by "
                "joints, no confdata or S/T)"
            )
            src += "; " + note
        else:
            src += "; OPW parameters extracted, FK-checked"
    else:
        note = f"closed-form IK not tried for {p.name} (opw=False); IK is numerical"
    return RobotModel(
        name=p.stem,
        chain=chain,
        q_min=arm.q_min,
        q_max=arm.q_max,
        opw=g,
        source=src,
        T_flange_tip=T_fl,
        T_flange_link=T_fl,
        ik_note=note,
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
