"""Expand a ROS-Industrial robot ``*_macro.xacro`` into a plain kinematic URDF (test data).

Only what these macro files use is supported: one ``xacro:macro`` instantiated with
``prefix=""`` (and ``package_name``), ``${...}`` arithmetic with ``pi``/``radians``, calls of
other macros of the same file with literal arguments, and ``xacro:if``. ``visual``,
``collision`` and ``inertial`` elements and ``xacro:material_*``/``xacro:include`` are dropped:
the kinematics (links, joints with origin, axis, limit, mimic) are kept unchanged.

Usage: python expand_xacro.py MACRO.xacro MACRO_NAME OUT.urdf "origin comment"
"""

from __future__ import annotations

import math
import re
import sys
import xml.etree.ElementTree as ET


def _xacro_name(tag: str) -> str | None:
    """The local name of a xacro element (any of the namespace spellings in use), else None."""
    if tag.startswith("{") and "xacro" in tag[: tag.index("}")]:
        return tag[tag.index("}") + 1 :]
    return None


def _eval(text: str, env: dict[str, object]) -> str:
    def sub(m: re.Match[str]) -> str:
        v = eval(m.group(1), {"__builtins__": {}}, {"pi": math.pi, "radians": math.radians, **env})
        return repr(v) if isinstance(v, float) else str(v)

    return re.sub(r"\$\{([^}]*)\}", sub, text)


def _expand(
    el: ET.Element, env: dict[str, object], macros: dict[str, ET.Element]
) -> list[ET.Element]:
    tag = el.tag
    if tag in ("visual", "collision", "inertial"):
        return []
    name = _xacro_name(tag)
    if name is not None:
        if name == "if":
            v = _eval(el.get("value", ""), env).strip().lower()
            if v in ("true", "1"):
                return [c for ch in el for c in _expand(ch, env, macros)]
            return []
        if name in macros:
            m = macros[name]
            sub_env = dict(env)
            for p in m.get("params", "").split():
                sub_env[p] = _eval(el.get(p, ""), env)
                if sub_env[p] in ("true", "false"):
                    sub_env[p] = sub_env[p] == "true"
            return [c for ch in m for c in _expand(ch, sub_env, macros)]
        return []  # materials, includes, properties not used by the kinematics
    out = ET.Element(tag, {k: _eval(v, env) for k, v in el.attrib.items()})
    for ch in el:
        out.extend(_expand(ch, env, macros))
    return [out]


def main() -> None:
    src, macro, dst, origin = sys.argv[1:5]
    root = ET.parse(src).getroot()
    macros = {m.get("name"): m for m in root.iter() if _xacro_name(m.tag) == "macro"}
    robot = ET.Element("robot", {"name": macro})
    env: dict[str, object] = {"prefix": "", "package_name": "pkg"}
    for ch in macros[macro]:
        robot.extend(_expand(ch, env, macros))
    ET.indent(robot)
    text = ET.tostring(robot, encoding="unicode")
    with open(dst, "w", encoding="utf-8") as f:
        f.write(f'<?xml version="1.0"?>\n<!-- {origin} -->\n{text}\n')


if __name__ == "__main__":
    main()
