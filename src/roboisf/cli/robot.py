"""``roboisf robot …``: list, show, identify, deflect."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer
from rich.markup import escape

from roboisf.cli.console import state
from roboisf.cli.outputs import FILE_HELP, Overwrite, output_file
from roboisf.errors import InputError

if TYPE_CHECKING:  # numpy and the robot are imported by the command that runs (fast --help)
    import numpy as np

    from roboisf.robot import RobotModel

__all__ = ["register"]

robot_app = typer.Typer(
    help="Robot models, joint stiffness and VJM deflection along a toolpath.", no_args_is_help=True
)


def register(app: typer.Typer) -> None:
    app.add_typer(robot_app, name="robot")


def _floats(text: str, n: int, field: str) -> np.ndarray:
    import numpy as np

    try:
        v = np.array([float(t) for t in text.split(",")])
    except ValueError:
        raise InputError(
            f"expected {n} comma-separated numbers, got {text!r}", field=field
        ) from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise InputError(f"expected {n} comma-separated finite numbers, got {text!r}", field=field)
    return v


def _model(robot: str, stiffness: Path | None, tool: str | None) -> RobotModel:
    from roboisf.frames import make_transform
    from roboisf.robot import load_robot, load_stiffness

    m = load_robot(robot)
    if stiffness is not None:
        m = m.with_stiffness(load_stiffness(stiffness), source=str(stiffness))
    if tool is not None:
        m = m.with_tool(make_transform(None, _floats(tool, 3, "--tool") * 1e-3))
    return m


def _placement(text: str | None, model: RobotModel) -> np.ndarray:
    import numpy as np

    from roboisf.frames import make_transform, rot_z

    if text is None:
        if model.default_placement is None:
            raise InputError(
                f"robot {model.name} has no default placement; give --placement",
                field="--placement",
            )
        return model.default_placement
    v = _floats(text, 4, "--placement")
    return make_transform(rot_z(np.radians(v[3])), v[:3] * 1e-3)


ROBOT_OPT = typer.Option(
    "irb7600-500-2.55", "--robot", "-r", help="Preset name, robot .toml or .urdf."
)
STIFF_OPT = typer.Option(
    None, "--stiffness", help="Joint stiffness TOML ([stiffness] K = [6] N*m/rad)."
)
PLACEMENT_OPT = typer.Option(
    None,
    "--placement",
    help="x,y,z,yaw of the work frame in the base (mm, deg); default: preset's.",
)
TOOL_OPT = typer.Option(None, "--tool", help="Tool tip in the flange frame: x,y,z (mm).")


@robot_app.command("list")
def list_cmd() -> None:
    """List the built-in robot presets."""
    from roboisf.robot import list_robots, load_robot

    for name in list_robots():
        m = load_robot(name)
        k = "K_θ given" if m.stiffness is not None else "K_θ: user input"
        state.out.print(f"{name:20s}  {k}")


def _files(*names: str | None) -> list[Path]:
    """The robot/tool arguments that name files (inputs the output may not overwrite)."""
    return [Path(n) for n in names if n is not None and Path(n).is_file()]


@robot_app.command("show")
def show_cmd(
    robot: str = ROBOT_OPT,
    stiffness: Path | None = STIFF_OPT,
    tool: str | None = TOOL_OPT,
    placement: str | None = PLACEMENT_OPT,
    output: Path | None = typer.Option(
        None, "--output", "-o", help=f"Stiffness map PNG over the work area. {FILE_HELP}"
    ),
    overwrite: Overwrite = False,
    half_width: float = typer.Option(500.0, "--half-width", help="Map half width (mm)."),
) -> None:
    """Show a robot's limits and joint stiffness; optionally write a stiffness map PNG."""
    import numpy as np

    if output is not None:
        output_file(output, "robot show", overwrite, [stiffness, *_files(robot, tool)])
    m = _model(robot, stiffness, tool)
    state.out.print(f"[bold]{escape(m.name)}[/bold]")
    if m.source:
        state.out.print(m.source, markup=False)
    for i in range(6):
        K = "—" if m.stiffness is None else f"{m.stiffness[i]:.4g} N·m/rad"
        state.out.print(
            f"A{i + 1}: limits [{np.degrees(m.q_min[i]):7.1f}, "
            f"{np.degrees(m.q_max[i]):7.1f}] deg   K = {K}"
        )
    if m.stiffness is None:
        state.warn("no joint stiffness for this robot; compliance needs --stiffness")
    if output is not None:
        from roboisf.report.robot_maps import plot_stiffness_map
        from roboisf.robot import stiffness_map

        smap = stiffness_map(m, _placement(placement, m), half_width=half_width * 1e-3)
        plot_stiffness_map(smap, output)
        state.info(f"wrote {output}")


@robot_app.command("identify")
def identify_cmd(
    calib: Path = typer.Argument(..., help="Calibration CSV (see docs/robot.md)."),
    output: Path = typer.Option(
        ..., "--output", "-o", help=f"stiffness TOML to write. {FILE_HELP}"
    ),
    overwrite: Overwrite = False,
    robot: str = ROBOT_OPT,
    tool: str | None = TOOL_OPT,
    sigma: float = typer.Option(0.01, "--sigma", help="Measurement std of displacements (mm)."),
    sigma_rot: float = typer.Option(
        1e-5, "--sigma-rot", help="Measurement std of rotations (rad)."
    ),
) -> None:
    """Identify joint stiffness K_1..K_6 from elasto-static experiments."""
    import warnings

    import numpy as np
    import tomli_w

    from roboisf.io.atomic import atomic_write, check_not_input
    from roboisf.robot import PoorExcitationWarning, identify_stiffness, read_calibration_csv

    check_not_input(output, [calib])
    output_file(output, "robot identify", overwrite, [calib, *_files(robot, tool)])
    m = _model(robot, None, tool)
    data = read_calibration_csv(calib, m)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", PoorExcitationWarning)
        r = identify_stiffness(m, data, sigma_translation=sigma * 1e-3, sigma_rotation=sigma_rot)
    for w in caught:
        state.warn(str(w.message))
    for i in range(6):
        state.out.print(
            f"K{i + 1} = {r.K[i]:.4g} N·m/rad  95% CI [{r.K_ci[i, 0]:.4g}, {r.K_ci[i, 1]:.4g}]"
            + ("  (weakly excited)" if r.weak[i] else "")
        )
    state.out.print(
        f"residual RMS {r.residual_rms * 1e3:.4g} mm, condition number {r.condition_number:.3g}"
    )
    doc = {
        "stiffness": {
            "K": r.K.tolist(),
            "ci_low": r.K_ci[:, 0].tolist(),
            "ci_high": [float(x) if np.isfinite(x) else 1e300 for x in r.K_ci[:, 1]],
            "weak": r.weak.tolist(),
            "residual_rms_m": r.residual_rms,
            "condition_number": r.condition_number,
            "source": f"roboisf robot identify {calib.name} ({m.name})",
        }
    }
    with atomic_write(output, "wb", encoding=None) as f:
        f.write(b"# joint stiffness K in N*m/rad, 95 % confidence interval [ci_low, ci_high]\n")
        tomli_w.dump(doc, f)
    state.info(f"wrote {output}")


@robot_app.command("deflect")
def deflect_cmd(
    toolpath: Path = typer.Option(..., "--toolpath", help="Toolpath CSV (roboisf format)."),
    forces: Path = typer.Option(
        ..., "--forces", help="Force log CSV, wrench at the tool tip in frame work, base or tip."
    ),
    output: Path = typer.Option(
        ..., "--output", "-o", help=f"Deflection CSV to write. {FILE_HELP}"
    ),
    overwrite: Overwrite = False,
    robot: str = ROBOT_OPT,
    stiffness: Path | None = STIFF_OPT,
    tool: str | None = TOOL_OPT,
    placement: str | None = PLACEMENT_OPT,
    joints: Path | None = typer.Option(
        None, "--joints", help="Joint log CSV (controller degrees) instead of IK."
    ),
    tool_rotation: float = typer.Option(
        0.0, "--tool-rotation", help="Tool rotation about its own axis (deg)."
    ),
) -> None:
    """VJM deflection of the tool tip along a toolpath under the logged forming wrench."""
    import numpy as np

    from roboisf.io.atomic import atomic_write, check_not_input
    from roboisf.io.forcelog import attach_to_toolpath, read_force_log
    from roboisf.io.jointlog import read_joint_log
    from roboisf.io.table import format_rows
    from roboisf.io.toolpath_csv import read_toolpath_csv
    from roboisf.robot import ik_toolpath, rotate_6

    inputs: list[str | Path] = [toolpath, forces]
    if joints is not None:
        inputs.append(joints)
    check_not_input(output, inputs)
    output_file(output, "robot deflect", overwrite, [*inputs, stiffness, *_files(robot, tool)])
    m = _model(robot, stiffness, tool)
    K = m.joint_stiffness  # fail early, before IK
    del K
    T_base_work = _placement(placement, m)
    tp = read_toolpath_csv(toolpath)
    log = read_force_log(forces)
    W = attach_to_toolpath(log, tp, by="time")
    if joints is not None:
        jl = read_joint_log(joints)
        if tp.time[0] < jl.time[0] - 1e-9 or tp.time[-1] > jl.time[-1] + 1e-9:
            raise InputError(
                f"toolpath times [{tp.time[0]:.3f}, {tp.time[-1]:.3f}] s are outside the joint log "
                f"[{jl.time[0]:.3f}, {jl.time[-1]:.3f}] s",
                file=joints,
                field="time",
            )
        q = np.stack([np.interp(tp.time, jl.time, jl.q[:, j]) for j in range(6)], axis=1)
        q = m.check_q(q, field=str(joints))
    else:
        q = ik_toolpath(m, tp.tip, T_base_work, tool_rotation=np.radians(tool_rotation)).q
    frame = log.frame.strip().lower()
    R_base_work = T_base_work[:3, :3]
    T_tip = m.fk(q)
    if frame == "work":
        W_base = rotate_6(W, R_base_work)
    elif frame == "base":
        W_base = W
    elif frame in ("tip", "tool"):
        W_base = rotate_6(W, T_tip[:, :3, :3])
    else:
        raise InputError(
            f"force log frame {log.frame!r}: expected work, base or tip (move sensor wrenches to "
            "the tip first, roboisf.frames.transform_wrench)",
            file=forces,
            field="frame",
        )
    d_base = m.deflection(q, W_base)
    d_work = rotate_6(d_base, R_base_work.T)
    data = np.column_stack(
        [
            np.arange(len(tp)),
            tp.time,
            tp.tip * 1e3,
            d_work[:, :3] * 1e3,
            d_work[:, 3:],
            np.degrees(q),
        ]
    )
    head = (
        f"# roboisf robot deflection ({m.name})\n"
        "# units: time=s length=mm rotation=rad angle=deg\n# frame: work\n"
        "index,time,tip_x,tip_y,tip_z,dx,dy,dz,rx,ry,rz,q1,q2,q3,q4,q5,q6\n"
    )
    with atomic_write(output) as f:
        f.write(
            head + format_rows(data, ["%d", "%.6f"] + ["%.9f"] * 6 + ["%.9e"] * 3 + ["%.9f"] * 6)
        )
    state.info(
        f"wrote {output}: {len(tp)} points, mean |δ| "
        f"{np.linalg.norm(d_work[:, :3], axis=1).mean() * 1e3:.4f} mm"
    )
