"""The poses of a designed stiffness experiment (``roboisf robot identify --design``,
:func:`roboisf.robot.identify.design_experiment`) as a robot program of the robot's maker that
stops at each: a RAPID module (ABB), a KRL program (KUKA) or a TP program (FANUC), joint angles
in the controller's convention, in degrees."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from roboisf.errors import InputError
from roboisf.robot.identify import ExperimentDesign
from roboisf.robot.model import RobotModel

__all__ = ["joint_program_suffix", "write_joint_program"]


def joint_program_suffix(model: RobotModel) -> str | None:
    """The suffix of :func:`write_joint_program`'s program for ``model``'s controller —
    ``.mod`` (ABB), ``.src`` (KUKA), ``.ls`` (FANUC) — or None when no program can be written
    right: a model read from a URDF has the URDF's joint angles, not the pendant's (FANUC's J3
    is the pendant's J3 + J2; signs and zeros differ by maker), and a maker roboisf writes no
    program for. Presets and robot TOML files give the controller's angles (``θ = sign·q +
    offset``, :mod:`roboisf.robot.kinematics`)."""
    if model.source.startswith("URDF "):
        return None
    text = f"{model.name} {model.source}".lower()
    if model.chain.couple23 != 0 or "fanuc" in text:
        return ".ls"
    if model.name.lower().startswith("kr") or "kuka" in text:
        return ".src"
    if "irb" in text or "abb" in text:
        return ".mod"
    return None


def write_joint_program(design: ExperimentDesign, path: str | Path, module: str) -> Path:
    """The poses as a robot program that stops at each (a RAPID module of ``MoveAbsJ`` for a
    ``.mod`` path, a KRL ``PTP {A1 …}`` program for ``.src``, a FANUC TP program of joint
    positions ``J P[i]`` for ``.ls``): joint angles in degrees, in the controller's convention,
    the external axes unused. Each stop is a ``Stop`` / ``HALT`` / ``PAUSE`` for the load and
    the reading."""
    from roboisf.io.atomic import atomic_write

    p = Path(path)
    qd = np.degrees(design.q)
    if p.suffix.lower() == ".ls":
        from roboisf.programs.fanuc import joint_positions_program

        with atomic_write(p) as fh:
            fh.write(joint_positions_program(module.upper(), qd, "roboisf identify"))
        return p
    if p.suffix.lower() == ".src":
        body = [f"DEF {module}()", "  ; roboisf robot identify --design: one stop per experiment"]
        for i, q in enumerate(qd):
            a = ",".join(f"A{j + 1} {v:.4f}" for j, v in enumerate(q))
            body += [f"  PTP {{{a}}} ; experiment {i + 1}", "  HALT"]
        body.append("END")
    elif p.suffix.lower() == ".mod":
        body = [f"MODULE {module}", "  ! roboisf robot identify --design: one stop per experiment"]
        for i, q in enumerate(qd):
            v = ",".join(f"{x:.4f}" for x in q)
            body.append(f"  CONST jointtarget jt{i + 1}:=[[{v}],[9E9,9E9,9E9,9E9,9E9,9E9]];")
        body.append("  PROC main()")
        for i in range(len(qd)):
            body += [f"    MoveAbsJ jt{i + 1},v100,fine,tool0; ! experiment {i + 1}", "    Stop;"]
        body += ["  ENDPROC", "ENDMODULE"]
    else:
        raise InputError(
            f"expected a .mod (RAPID), .src (KRL) or .ls (FANUC TP) program, got {p.name}", file=p
        )
    with atomic_write(p) as fh:
        fh.write("\n".join(body) + "\n")
    return p
