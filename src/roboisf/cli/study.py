"""``roboisf study init``: draft a study.toml from the files of a folder; ``roboisf study
formats``: the registered file formats (:mod:`roboisf.formats`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from roboisf.cli.console import state
from roboisf.cli.lazy import FullHelpGroup
from roboisf.cli.outputs import Overwrite, output_file
from roboisf.cli.robot import TipLink
from roboisf.errors import InputError

__all__ = ["register"]

study_app = typer.Typer(
    help="Study folders: draft a study.toml from the files you have.",
    no_args_is_help=True,
    cls=FullHelpGroup,
)

POSE_HELP = "x,y,z,roll,pitch,yaw in mm and deg"


def register(app: typer.Typer) -> None:
    app.add_typer(study_app, name="study")


def _pose(text: str | None, field: str) -> list[float] | None:
    if text is None:
        return None
    from roboisf.frames.pose import XYZ_RPY_MM_DEG, pose_numbers

    return pose_numbers(text, XYZ_RPY_MM_DEG, field=field)


def _roles(data: dict[str, Any], prefix: str = "") -> dict[str, list[str]]:
    """File name → the study keys that name it (the sync key beside a run's log)."""
    out: dict[str, list[str]] = {}
    for k, v in data.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            for name, keys in _roles(v, key + ".").items():
                out.setdefault(name, []).extend(keys)
        elif isinstance(v, str) and not v.startswith("TODO") and "." in v:
            label = key
            if k == "joints" or (k == "file" and "sync" in data):
                label += f" (sync = {data.get('sync')})"
            out.setdefault(Path(v).name, []).append(label)
    return out


@study_app.command("init")
def _init(
    folder: Annotated[Path, typer.Argument(help="The folder with your files.")],
    output: Annotated[
        Path | None,
        typer.Option("--output", "-o", help="The study file to write (default FOLDER/study.toml)."),
    ] = None,
    overwrite: Overwrite = False,
    robot: Annotated[
        str | None, typer.Option(help="Robot preset (roboisf robot list) or robot file.")
    ] = None,
    placement: Annotated[
        str | None,
        typer.Option(help=f"T_base_work, the work frame in the robot base: {POSE_HELP}."),
    ] = None,
    flange_to_tip: Annotated[
        str | None, typer.Option(help=f"T_flange_tip, the tool tip in the flange: {POSE_HELP}.")
    ] = None,
    tool_rotation: Annotated[
        float | None, typer.Option(help="Tool rotation about its axis (deg).")
    ] = None,
    part: Annotated[
        Path | None, typer.Option(help="Part TOML (roboisf part …) when none is in FOLDER.")
    ] = None,
    cnc_sensor_pose: Annotated[
        str | None,
        typer.Option(help=f"T_work_sensor of the CNC dynamometer under the fixture: {POSE_HELP}."),
    ] = None,
    robot_sensor_pose: Annotated[
        str | None,
        typer.Option(help=f"T_tip_sensor of the robot's flange F/T sensor: {POSE_HELP}."),
    ] = None,
    holder_offset: Annotated[
        float | None,
        typer.Option(help="Tool holder nose → tool tip along the tool axis (mm)."),
    ] = None,
    tip_link: TipLink = None,
) -> None:
    """Look at every file in FOLDER, say what it is, and write a study.toml to confirm.

    Each file is tried with roboisf's readers (toolpath CSV, force logs — roboisf, ATI Net
    F/T, Kistler DynoWare, 3-component —, joint logs — roboisf, ABB J1..J6, KUKA A1..A6 —,
    scans — PLY, XYZ, PTS, E57, LAS —, thickness, part TOML, compliance JSON, and last CAM
    programs — G-code, .mpf, APT, x,y,z — as a toolpath; `roboisf study formats` lists every
    registered format); the table shows what was detected
    (profile, units, size) and the role given to it. A log's units the file does not declare,
    and the ball diameter a CAM program does not say, are written as "TODO" values for you to
    fill in — never guessed. Roles: the CNC and robot runs by "cnc" and "robot"/"rob" in the
    names, the joint log to the robot run (sync = "position"). What no file says — robot,
    placement, sensor poses, the part — comes from the options or is written as a "TODO: …" value
    that `roboisf analyze` refuses by name. An existing study.toml is never replaced without
    --overwrite.

    Example: roboisf study init my-cell/ --robot irb7600-500-2.55 --placement 2200,0,200,0,0,0
    """
    from rich.markup import escape
    from rich.table import Table

    from roboisf.io.atomic import atomic_write
    from roboisf.study.init import detect_files, draft_study, render_toml

    if not folder.is_dir():
        raise InputError("not a folder (the folder with your files)", file=folder)
    out = output if output is not None else folder / "study.toml"
    output_file(out, "study init", overwrite)
    files = detect_files(folder)
    draft = draft_study(
        folder,
        files,
        robot=robot,
        placement=_pose(placement, "--placement"),
        flange_to_tip=_pose(flange_to_tip, "--flange-to-tip"),
        tool_rotation=tool_rotation,
        part=part,
        cnc_sensor_pose=_pose(cnc_sensor_pose, "--cnc-sensor-pose"),
        robot_sensor_pose=_pose(robot_sensor_pose, "--robot-sensor-pose"),
        holder_offset=holder_offset,
        tip_link=tip_link,
    )
    t = Table(title=f"{escape(str(folder))}: detected files")
    for c in ("file", "kind", "format", "details", "study key"):
        t.add_column(c)
    roles = _roles(draft.data)
    for f in files:
        det = ", ".join(f"{k} {v}" for k, v in f.details.items()) if f.details else f.problem
        key = ", ".join(roles.get(f.path.name, [])) or "–"
        t.add_row(escape(f.path.name), f.kind, escape(f.format), escape(det), escape(key))
    if state.verbosity >= 1:
        state.out.print(t)
    with atomic_write(out) as fh:
        fh.write(render_toml(draft))
    for n in draft.notes:
        state.info(f"note: {n}")
    if draft.todo:
        state.warn(
            f"wrote {out} with {len(draft.todo)} TODO value(s): {', '.join(draft.todo)} — fill "
            "them in, then: roboisf analyze " + str(folder)
        )
    else:
        state.info(f"wrote {out}; check it, then: roboisf analyze {folder}")


@study_app.command("formats")
def study_formats(
    kind: Annotated[
        str | None,
        typer.Argument(
            help="Only this kind: toolpath, cnc, robot, force_log, joint_log, scan or part.",
            show_default=False,
        ),
    ] = None,
) -> None:
    """List the registered file formats a study can name (a log's format, a part's kind, a
    program's format): name, kind, suffixes, what roboisf does with it (read, write, detect).

    One registry holds them (roboisf.formats, docs/extending.md): a format added by a module —
    roboisf's or yours — is listed here, detected by the readers and offered by the virtual cell.

    Example: roboisf study formats force_log
    """
    from rich.markup import escape
    from rich.table import Table

    from roboisf.formats import KINDS, file_formats

    if kind is not None and kind not in KINDS:
        raise InputError(f"unknown kind {kind!r}; expected one of {', '.join(KINDS)}", field="kind")
    t = Table(title="registered file formats")
    for c in ("kind", "name", "label", "suffixes", "roboisf"):
        t.add_column(c)
    for f in file_formats(*((kind,) if kind else ())):
        does = [w for w, on in (("read", f.reader), ("write", f.writer)) if on is not None]
        t.add_row(
            f.kind,
            f.name,
            escape(f.label),
            " ".join(f.suffixes) or "–",
            ", ".join(does) or "–",
        )
    state.out.print(t)
