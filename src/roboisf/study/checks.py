"""Plausibility of a study's files against each other (``docs/study.md``, "Checks").

Each file is validated by its reader; these checks compare files that are each valid on their own
but cannot belong together: a ball diameter the toolpath was not made for, forces in the wrong
unit, logs recorded along another path. Impossible combinations raise :class:`InputError` naming
the files; combinations a real cell can produce (a log that runs on after the path) return a
warning for the report. Every check is cheap (vectorised, or on a sample of points).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.logs.forcelog import ForceLog
from roboisf.logs.jointlog import JointLog
from roboisf.toolpath import Toolpath

__all__ = [
    "FORCE_MAX",
    "FORCE_MIN",
    "MOMENT_MAX",
    "PATH_TOL",
    "TOOL_RADIUS_TOL",
    "check_distinct_runs",
    "check_force_log",
    "check_joint_log",
    "check_tool_radius",
]

F64 = NDArray[np.float64]

#: Largest plausible forming force [N] (99th percentile of |F| over the log). Incremental sheet
#: forming of steel and aluminium sheets up to ~2 mm needs 0.1–5 kN; 20 kN is beyond any ISF
#: cell's tool and a log 1000× too large (kN read as N) lands far above it.
FORCE_MAX = 20e3
#: Below this peak |F| [N] the log holds no forming force (a log in kN read as N, or a sensor
#: that was not connected).
FORCE_MIN = 1.0
#: Largest plausible moment [N·m] (99th percentile of |M|): FORCE_MAX at a 1 m lever.
MOMENT_MAX = 20e3
#: Accepted difference [m] between the study's ball radius and the toolpath's: 1 % or 0.02 mm.
TOOL_RADIUS_TOL = (0.01, 0.02e-3)
#: Median distance [m] above which logged positions (force-log x,y,z, joint-log FK) do not
#: follow the toolpath: 5 mm, well above robot deflection (~1 mm) and interpolation error.
PATH_TOL = 5e-3
#: Points of the toolpath at which the joint log's forward kinematics is evaluated.
_FK_SAMPLES = 64


def check_tool_radius(ball_diameter: float, tp: Toolpath, *, study_file: Path) -> None:
    """The study's ``[tool] ball_diameter`` [m] must match the toolpath's own tool radius (the
    contact–centre distance it was generated with); else every deviation is off by the
    difference."""
    r = ball_diameter / 2
    tol = max(TOOL_RADIUS_TOL[0] * r, TOOL_RADIUS_TOL[1])
    if abs(tp.tool_radius - r) > tol:
        raise InputError(
            f"ball_diameter is {ball_diameter * 1e3:g} mm but the toolpath "
            f"{tp.meta.get('source', '')} was made for a Ø{2 * tp.tool_radius * 1e3:.4g} mm ball "
            f"(its contact–centre distance, # tool_radius); use the toolpath of this tool or fix "
            "the diameter",
            file=study_file,
            field="tool.ball_diameter",
        )


def _magnitude(log: ForceLog, first: int) -> F64:
    """|F| (``first`` = 0) or |M| (3) per sample (N,) (:func:`roboisf.logs.forcelog.row_norms`:
    the bits of ``np.linalg.norm(log.force, axis=1)`` without its (N, 3) temporaries). One at
    a time: the two (N,) arrays of a 1 kHz paper log were 37 MB at the analysis's peak."""
    from roboisf.logs.forcelog import row_norms

    return row_norms(log.wrench, first)


def check_force_log(
    log: ForceLog, tp: Toolpath, *, time_offset: float = 0.0, point_time: ArrayLike | None = None
) -> list[str]:
    """Forces of forming magnitude, and a log recorded along ``tp``.

    The log time of each toolpath point is ``point_time`` (N,) s when the log was aligned
    (:mod:`roboisf.sync`: a drifting clock, pauses), else the nominal ``tp.time + time_offset``.

    Raises
    ------
    InputError
        |F| above :data:`FORCE_MAX` or never above :data:`FORCE_MIN`, |M| above
        :data:`MOMENT_MAX` (a unit mix-up), logged x,y,z farther than :data:`PATH_TOL` from the
        toolpath's tip (a log of another path).

    Returns
    -------
    warnings : list of str — the log runs on long after the toolpath ends.
    """
    f = _magnitude(log, 0)
    hint = "check the force/moment units ('# units:' line of the log, or [units] in study.toml)"
    f_max = float(f.max())
    # the 99th percentile only when a sample is above the limit (it cannot be otherwise): the
    # two percentiles of a 1 kHz log were ~0.2 s of every analyze
    f99 = float(np.percentile(f, 99)) if f_max > FORCE_MAX else f_max
    if f99 > FORCE_MAX:
        raise InputError(
            f"forces of {f99 / 1e3:.4g} kN (99th percentile of |F|) are far above incremental "
            f"sheet forming (0.1–5 kN; limit {FORCE_MAX / 1e3:g} kN): {hint}",
            file=log.path,
            field="units",
        )
    if f_max < FORCE_MIN:
        raise InputError(
            f"the largest force is {f_max:.3g} N: the log holds no forming force (below "
            f"{FORCE_MIN:g} N); {hint}",
            file=log.path,
            field="units",
        )
    del f
    m = _magnitude(log, 3)
    m_max = float(m.max())
    m99 = float(np.percentile(m, 99)) if m_max > MOMENT_MAX else m_max
    if m99 > MOMENT_MAX:
        raise InputError(
            f"moments of {m99 / 1e3:.4g} kN·m (99th percentile of |M|) are implausible for "
            f"forming (limit {MOMENT_MAX / 1e3:g} kN·m): {hint}",
            file=log.path,
            field="units",
        )
    t = tp.time + time_offset if point_time is None else np.asarray(point_time, dtype=float)
    if log.position is not None:
        inside = (t >= log.time[0]) & (t <= log.time[-1])
        if inside.any():
            p = np.column_stack(
                [np.interp(t[inside], log.time, log.position[:, j]) for j in range(3)]
            )
            d = np.linalg.norm(p - tp.tip[inside], axis=1)
            med = float(np.median(d))
            if med > PATH_TOL:
                raise InputError(
                    f"the logged tool positions (x,y,z) are {med * 1e3:.3g} mm (median) from "
                    f"the toolpath's tip at the same times (limit {PATH_TOL * 1e3:g} mm): a log "
                    "of another path, or a wrong time_offset / sync",
                    file=log.path,
                    field="x",
                )
    warnings = []
    span = float(tp.time[-1] - tp.time[0])
    ratio = float(log.time[-1] - log.time[0]) / span if span > 0 else 0.0
    if 300 <= ratio <= 3000:  # no forming run logs for 300× its path: a time unit slip
        raise InputError(
            f"the log lasts {log.time[-1] - log.time[0]:.4g} s, {ratio:.0f}× the toolpath's "
            f"{span:.4g} s: its time is likely in ms read as s; declare time=ms in its "
            "'# units:' line (or units = {time = \"ms\"} in study.toml)",
            file=log.path,
            field="time",
        )
    after = float(log.time[-1] - t[-1])
    if after > max(60.0, 0.5 * span):
        warnings.append(
            f"force log {log.path}: runs {after:.0f} s past the end of the toolpath "
            f"({span:.0f} s long): a log of a longer path? (only the toolpath's span is used)"
        )
    return warnings


def check_joint_log(
    model: object, T_base_work: F64, log: JointLog, tp: Toolpath, *, file: Path | None
) -> None:
    """Forward kinematics of the logged joint angles must follow the toolpath's tip.

    ``model`` is a :class:`~roboisf.robot.RobotModel` with the study's tool. Evaluated at
    :data:`_FK_SAMPLES` toolpath points (joint angles interpolated at their times); the median
    distance must stay below :data:`PATH_TOL`. Catches a joint log of another path, a wrong
    placement or tool, or a log in the other angle unit.
    """
    from roboisf.robot import RobotModel

    assert isinstance(model, RobotModel)
    idx = np.unique(np.linspace(0, len(tp) - 1, min(_FK_SAMPLES, len(tp))).astype(np.int64))
    t = np.clip(tp.time[idx], log.time[0], log.time[-1])
    q = np.column_stack([np.interp(t, log.time, log.q[:, j]) for j in range(6)])
    T = model.fk(q, check_limits=False, T_base_work=T_base_work)
    d = np.linalg.norm(T[:, :3, 3] - tp.tip[idx], axis=1)
    med = float(np.median(d))
    if not med <= PATH_TOL:
        raise InputError(
            f"the robot's forward kinematics at the logged joint angles is {med * 1e3:.4g} mm "
            f"(median over {idx.size} points) from the toolpath's tip (limit "
            f"{PATH_TOL * 1e3:g} mm): a joint log of another path, or a wrong [robot] placement, "
            "flange_to_tip or angle unit",
            file=file,
        )


def check_distinct_runs(cnc_files: dict[str, Path], robot_files: dict[str, Path]) -> None:
    """Refuse a robot run whose scan or force log is the same bytes as the CNC run's: one part
    measured twice, which the decomposition would report as "no robot error, the model does not
    hold (−0.06×)". ``cnc_files``/``robot_files`` map the study key's last part (``scan``,
    ``forces.file``) to the run's file. Sizes first, contents only when they agree."""
    import filecmp

    for key, fa in cnc_files.items():
        fb = robot_files.get(key)
        if fb is None or fb == fa:
            continue
        try:
            same = fa.stat().st_size == fb.stat().st_size and filecmp.cmp(fa, fb, shallow=False)
        except OSError:
            continue
        if same:
            what = "scan" if key == "scan" else "force log"
            raise InputError(
                f"the robot run's {what} is the same bytes as the CNC run's ({fb.name} = "
                f"{fa.name}): each machine's part is measured on its own",
                file=fb,
                field=f"runs.robot.{key}",
            )
