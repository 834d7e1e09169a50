"""Robot presets (TOML data files a user can copy and edit) and :func:`load_robot`.

A robot file has the keys (angles in degrees, lengths in metres, stiffness N·m/rad)::

    name = "my-robot"
    source = "where the numbers come from"
    [kinematics]
    type = "opw"                      # or "dh"
    a1 = …  a2 = …  b = …  c1 = …  c2 = …  c3 = …  c4 = …      # opw
    # d = [6], a = [6], alpha_deg = [6]                          # dh (standard, distal)
    sign = [1, 1, 1, 1, 1, 1]         # θ = sign·q + offset (q: controller angle)
    offset_deg = [0, 0, 90, 0, 0, 0]
    couple23 = 0                      # optional, FANUC: θ3 = sign3·(q3 + couple23·q2) + offset3
    [limits]
    q_min_deg = [6]  q_max_deg = [6]
    [stiffness]                       # optional: leave out when no value is known
    K = [6]  source = "…"
    [tool]                            # optional flange → tip
    xyz_m = [3]  rpy_deg = [3]
    [placement]                       # optional default T_base_work
    xyz_m = [3]  rpy_deg = [3]
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from roboisf.errors import InputError
from roboisf.frames.pose import XYZ_RPY_M_DEG, pose_transform
from roboisf.io.text import read_text
from roboisf.robot.kinematics import Chain, chain_from_dh, chain_from_opw
from roboisf.robot.model import OPWGeometry, RobotModel

__all__ = [
    "PresetInfo",
    "list_robots",
    "load_robot",
    "load_stiffness",
    "preset_info",
    "robot_from_dict",
]

_OPW_KEYS = ("a1", "a2", "b", "c1", "c2", "c3", "c4")


def _preset_dir() -> Any:
    return resources.files("roboisf.robot") / "presets"


def list_robots() -> list[str]:
    """Names of the built-in robot presets, sorted."""
    return sorted(
        p.name[: -len(".toml")] for p in _preset_dir().iterdir() if p.name.endswith(".toml")
    )


def load_robot(name_or_path: str | Path, *, tip_link: str | None = None) -> RobotModel:
    """Load a preset by name (see :func:`list_robots`), a robot TOML file, or a URDF file.

    ``tip_link``: the URDF link that is the arm's flange (default: ``tool0``/``flange``, else the
    link behind the most revolute joints; :func:`roboisf.robot.urdf.load_urdf`); only for a URDF.
    """
    s = str(name_or_path)
    p = Path(s)
    if p.suffix.lower() == ".urdf":
        from roboisf.robot.urdf import load_urdf

        return load_urdf(p, tip_link)
    if tip_link is not None:
        raise InputError(
            f"--tip-link names a link of a URDF robot; {s!r} is not a .urdf file",
            field="--tip-link",
        )
    if p.suffix.lower() == ".toml" or p.exists():
        return robot_from_dict(_read_toml(p, "robot"), file=p)
    known = list_robots()
    if s not in known:
        raise InputError(
            f"unknown robot {s!r}; known presets: {', '.join(known)} (or give a .toml/.urdf path)",
            field="robot",
        )
    text = (_preset_dir() / f"{s}.toml").read_text(encoding="utf-8")
    return robot_from_dict(tomllib.loads(text), file=f"<preset {s}>")


def _read_toml(p: Path, what: str) -> dict[str, Any]:
    if not p.is_file():
        raise InputError(f"{what} file not found", file=p)
    try:
        return tomllib.loads(read_text(p, what=f"{what} file"))
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"not valid TOML: {e}", file=p) from None


def _vec(d: dict[str, Any], key: str, n: int, file: Any, section: str) -> np.ndarray:
    if key not in d:
        raise InputError(f"missing key {key!r} ({n} numbers)", file=file, field=f"{section}.{key}")
    try:
        v = np.asarray(d[key], dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"expected {n} numbers", file=file, field=f"{section}.{key}") from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise InputError(
            f"expected {n} finite numbers, got {d[key]!r}", file=file, field=f"{section}.{key}"
        )
    return v


def _pose(d: dict[str, Any], file: object, section: str) -> np.ndarray:
    """``[section] xyz_m`` (m) and ``rpy_deg`` (deg, roll-pitch-yaw; default 0) → T (4, 4) m."""
    xyz = _vec(d, "xyz_m", 3, file, section)
    rpy = _vec(d, "rpy_deg", 3, file, section) if "rpy_deg" in d else np.zeros(3)
    return pose_transform([*xyz, *rpy], XYZ_RPY_M_DEG)


def robot_from_dict(data: dict[str, Any], *, file: object = None) -> RobotModel:
    """Build and validate a :class:`RobotModel` from parsed robot-file data."""
    f: Any = file
    try:
        name = str(data["name"])
        kin = data["kinematics"]
        lim = data["limits"]
    except KeyError as e:
        raise InputError(f"missing required key {e.args[0]!r}", file=f, field=e.args[0]) from None
    sign = _vec(kin, "sign", 6, f, "kinematics") if "sign" in kin else np.ones(6)
    offset = (
        np.radians(_vec(kin, "offset_deg", 6, f, "kinematics"))
        if "offset_deg" in kin
        else np.zeros(6)
    )
    ktype = kin.get("type", "opw")
    couple23 = kin.get("couple23", 0.0)
    if isinstance(couple23, bool) or couple23 not in (-1, 0, 1):
        raise InputError(
            f"expected -1, 0 or 1 (FANUC J2/J3 coupling: 1), got {couple23!r}",
            file=f,
            field="kinematics.couple23",
        )
    opw = None
    try:
        if ktype == "opw":
            missing = [k for k in _OPW_KEYS if k not in kin]
            if missing:
                raise InputError(f"missing OPW parameters {missing}", file=f, field="kinematics")
            opw = OPWGeometry(**{k: float(kin[k]) for k in _OPW_KEYS})
            chain = chain_from_opw(opw, sign=sign, offset=offset, couple23=float(couple23))
        elif ktype == "dh":
            chain = chain_from_dh(
                _vec(kin, "d", 6, f, "kinematics"),
                _vec(kin, "a", 6, f, "kinematics"),
                np.radians(_vec(kin, "alpha_deg", 6, f, "kinematics")),
                offset,
                sign,
            )
            if couple23:
                chain = Chain(chain.F, chain.sign, chain.offset, float(couple23))
        else:
            raise InputError(
                f"unknown kinematics type {ktype!r}; expected 'opw' or 'dh'",
                file=f,
                field="kinematics.type",
            )
        K = None
        ksrc = ""
        if "stiffness" in data:
            K = _vec(data["stiffness"], "K", 6, f, "stiffness")
            ksrc = str(data["stiffness"].get("source", ""))
        return RobotModel(
            name=name,
            chain=chain,
            q_min=np.radians(_vec(lim, "q_min_deg", 6, f, "limits")),
            q_max=np.radians(_vec(lim, "q_max_deg", 6, f, "limits")),
            stiffness=K,
            T_flange_tip=_pose(data["tool"], f, "tool") if "tool" in data else np.eye(4),
            opw=opw,
            default_placement=_pose(data["placement"], f, "placement")
            if "placement" in data
            else None,
            source=str(data.get("source", "")),
            stiffness_source=ksrc,
        )
    except InputError as e:
        if e.file is None and f is not None:
            raise InputError(e.message, file=f, field=e.field) from None
        raise


@dataclass(frozen=True)
class PresetInfo:
    """What ``roboisf robot list`` shows of a preset.

    name, manufacturer, description, source : str
    source_brief : str — one line of ``source``
    reach_m : float or None — wrist-centre reach from the geometry, ``a1 + c2 + √(a2² + c3²)`` (m;
        the data sheets' "reach" is this distance, limits aside)
    payload_kg : float or None — rated payload (the preset's ``payload_kg``)
    stiffness_source : str or None — where K_θ comes from; None: unknown — identify
    """

    name: str
    manufacturer: str
    description: str
    source: str
    source_brief: str
    reach_m: float | None
    payload_kg: float | None
    stiffness_source: str | None


def preset_info(name: str) -> PresetInfo:
    """:class:`PresetInfo` of the built-in preset ``name``."""
    m = load_robot(name)
    data = tomllib.loads((_preset_dir() / f"{name}.toml").read_text(encoding="utf-8"))
    g = m.opw
    reach = None if g is None else g.a1 + g.c2 + math.hypot(g.a2, g.c3)
    pl = data.get("payload_kg")
    return PresetInfo(
        name=name,
        manufacturer=str(data.get("manufacturer", "")),
        description=str(data.get("description", "")),
        source=m.source,
        source_brief=str(data.get("source_brief", m.source.split(". ")[0])),
        reach_m=reach,
        payload_kg=None if pl is None else float(pl),
        stiffness_source=None if m.stiffness is None else (m.stiffness_source or "given"),
    )


def load_stiffness(path: str | Path, *, robot: str | None = None) -> np.ndarray:
    """Joint stiffness (6,) N·m/rad from a TOML file with ``[stiffness] K = [...]``.

    This is the format ``roboisf robot identify`` and ``roboisf analyze`` write; they record the
    robot model it was identified on (``[stiffness] robot``, the model's name). Given ``robot``
    (the name of the model it is about to be used with), a file identified on another robot is
    refused: a joint stiffness belongs to one robot.
    """
    p = Path(path)
    data = _read_toml(p, "stiffness")
    if "stiffness" not in data:
        raise InputError(
            "missing [stiffness] table with K = [6 values] N*m/rad", file=p, field="stiffness"
        )
    on = data["stiffness"].get("robot") if isinstance(data["stiffness"], dict) else None
    if robot is not None and isinstance(on, str) and on and on != robot:
        raise InputError(
            f"this stiffness was identified on the robot {on!r}, not on {robot!r}: a joint "
            f"stiffness belongs to one robot model; give the stiffness of {robot!r} (or "
            "identify it: roboisf robot identify)",
            file=p,
            field="stiffness.robot",
        )
    K = _vec(data["stiffness"], "K", 6, p, "stiffness")
    if np.any(K <= 0):
        raise InputError(
            f"joint stiffness must be > 0 N·m/rad, got {K.tolist()}", file=p, field="stiffness.K"
        )
    return K
