"""Bringing a force sensor's wrench to the tool tip, and back (the virtual cell writes logs).

Two mounts (``ForceSensorSpec.mount``):

* ``fixture`` — sensor fixed in the work frame at ``T_work_sensor`` (a dynamometer under the
  fixture). Its wrench, about the sensor origin in sensor axes, is rotated into work axes and its
  moment moved to the tool tip's current position ``p_tip`` (work frame):
  ``W_tip = shift(transform(W_s, T_work_sensor), from = 0_work, to = p_tip)``.
* ``flange`` — sensor carried by the robot, ``T_tip_sensor`` fixed: the wrench goes to the tip
  frame with ``transform(W_s, T_tip_sensor)`` and then into work axes with ``R_work_tip``.

``load_on = "workpiece"`` flips the sign so that every wrench inside roboisf is the sheet's load
on the tool (``docs/conventions.md``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.frames import invert, shift_wrench, transform_wrench
from roboisf.frames.se3 import make_transform
from roboisf.study.spec import ForceSensorSpec, RunSpec, Study

if TYPE_CHECKING:
    from roboisf.logs.forcelog import ForceLog
    from roboisf.toolpath import Toolpath

__all__ = [
    "condition_study_log",
    "read_study_force_log",
    "sensor_forces_to_work",
    "sensor_to_tip",
    "tip_to_sensor",
]

F64 = NDArray[np.float64]


def sensor_to_tip(
    W_s: ArrayLike, sensor: ForceSensorSpec, tip_work: ArrayLike, R_work_tip: ArrayLike
) -> F64:
    """Sensor wrench (N, 6) [N, N·m] → the sheet's wrench on the tool about the tip, work axes.

    tip_work : (N, 3) m — tool-tip positions; R_work_tip : (3, 3) or (N, 3, 3).
    """
    W_s = np.asarray(W_s, dtype=float)
    sign = -1.0 if sensor.load_on == "workpiece" else 1.0
    if sensor.mount == "fixture":
        W_w = transform_wrench(W_s, sensor.pose)
        return sign * shift_wrench(W_w, np.zeros(3), np.asarray(tip_work, dtype=float))
    W_t = transform_wrench(W_s, sensor.pose)
    R = np.asarray(R_work_tip, dtype=float)
    return sign * transform_wrench(W_t, make_transform(R))


def sensor_forces_to_work(F_s: ArrayLike, sensor: ForceSensorSpec, R_work_tip: ArrayLike) -> F64:
    """The force part of :func:`sensor_to_tip` alone: sensor forces (N, 3) [N] → the sheet's
    force on the tool in work axes (N, 3) [N]; ``R_work_tip`` (3, 3) or (N, 3, 3).

    The same operations on the force columns as :func:`sensor_to_tip` (the force of a wrench
    turns with the frames and does not depend on the moments or the tip), so the same bits,
    without the moments' columns and the tips' (N, 3) zeros: a 2.3 M-sample log's force
    alignment peaked at ~385 MiB of temporaries through the whole wrench, ~110 MiB this way."""
    F = np.asarray(F_s, dtype=float)
    sign = -1.0 if sensor.load_on == "workpiece" else 1.0
    R_s = np.asarray(sensor.pose, dtype=float)[:3, :3]
    f = np.einsum("...ij,...j->...i", R_s, F)
    if sensor.mount != "fixture":
        f = np.einsum("...ij,...j->...i", np.asarray(R_work_tip, dtype=float), f)
    return sign * f


def tip_to_sensor(
    W_tip: ArrayLike, sensor: ForceSensorSpec, tip_work: ArrayLike, R_work_tip: ArrayLike
) -> F64:
    """Inverse of :func:`sensor_to_tip`: what the sensor would read."""
    W = np.asarray(W_tip, dtype=float)
    sign = -1.0 if sensor.load_on == "workpiece" else 1.0
    if sensor.mount == "fixture":
        W_w0 = shift_wrench(W, np.asarray(tip_work, dtype=float), np.zeros(3))
        return sign * transform_wrench(W_w0, invert(sensor.pose))
    R = np.asarray(R_work_tip, dtype=float)
    W_t = transform_wrench(W, make_transform(np.swapaxes(R, -1, -2)))
    return sign * transform_wrench(W_t, invert(sensor.pose))


def _declared(path: object, key: str) -> bool:
    try:
        with open(str(path), encoding="utf-8", errors="replace") as fh:
            for line in fh:
                s = line.strip()
                if not s.startswith("#"):
                    return False
                if s[1:].strip().lower().startswith(key + ":"):
                    return True
    except OSError:
        return False
    return False


def read_study_force_log(study: Study, run: RunSpec) -> ForceLog:
    """A run's force log as its ``[runs.X.forces]`` table says (format, columns, units).

    Units: the table's ``units``; for a roboisf CSV without a ``# units:`` line, the study's
    ``[units]`` (as before). Other formats take units from the file or the table only — the
    study-wide defaults are never applied to an instrument's export (no guess).
    """
    from roboisf.logs.forcelog import is_roboisf_force_log, read_force_log

    f = run.forces
    u = dict(f.units or {})
    is_roboisf = f.file.suffix.lower() != ".parquet" and (
        f.format == "roboisf" or (f.format == "auto" and is_roboisf_force_log(f.file))
    )
    if is_roboisf and not u and not _declared(f.file, "units"):
        su = study.units
        u = {"time": su.time, "force": su.force, "moment": su.moment}
    frame = "sensor" if not (is_roboisf and _declared(f.file, "frame")) else None
    return read_force_log(
        f.file,
        frame=frame,
        time_unit=u.get("time"),
        force_unit=u.get("force"),
        moment_unit=u.get("moment"),
        length_unit=u.get("length"),
        fmt="auto" if f.format == "columns" else f.format,
        columns=f.columns,
        timestamps=f.timestamps,
    )


#: A toolpath point deeper than this [m] forms the sheet: the tool is loaded from there on.
FORMING_DEPTH = 20e-6


def condition_study_log(
    study: Study,
    run: RunSpec,
    log: ForceLog,
    R_work_tip: ArrayLike,
    *,
    tp: Toolpath | None = None,
    R_base_tip: ArrayLike | None = None,
    point_time: ArrayLike | None = None,
) -> tuple[ForceLog, list[str]]:
    """Tare and gravity compensation of a run's log (``roboisf.sensor``), with its warnings.

    The sensor's orientation in the world (gravity along −z of the robot base, or of the work
    frame without a ``[robot]``): for a flange sensor ``R_base_tip(t) · R_tip_sensor`` with
    ``R_base_tip`` the forward kinematics of the joints at the toolpath points (given with
    ``tp``; each log sample takes the toolpath point it is matched to by time, samples before
    the toolpath the first; ``point_time`` (N_tp,) s, the log time at which the tool passed each
    point when the log was aligned by :mod:`roboisf.sync`, replaces the nominal time), else
    ``R_base_work · R_work_tip · R_tip_sensor`` (the toolpath's tool orientation);
    ``R_base_work · R_work_sensor`` for a fixture sensor.
    """
    from roboisf.sensor import Conditioning, ToolLoad, condition_wrench

    f = run.forces
    R_bw = study.robot.T_base_work[:3, :3] if study.robot is not None else np.eye(3)
    R: F64
    R_index = None
    if f.mount == "flange" and R_base_tip is not None and tp is not None:
        R = np.asarray(R_base_tip, dtype=float) @ f.pose[:3, :3]
        t_pt = tp.time + f.time_offset if point_time is None else np.asarray(point_time, float)
        k = np.searchsorted(t_pt, log.time, side="right") - 1
        R_index = np.clip(k, 0, len(R) - 1)  # each sample: its toolpath point's orientation
    elif f.mount == "flange":
        R = R_bw @ np.asarray(R_work_tip, dtype=float) @ f.pose[:3, :3]
    else:
        R = R_bw @ f.pose[:3, :3]
    tool = None
    if f.tool_mass is not None and f.tool_cog is not None:
        tool = ToolLoad(f.tool_mass, np.asarray(f.tool_cog), np.zeros(6))
    cond = (
        Conditioning(f.tare, tool)
        if isinstance(f.tare, tuple)
        else Conditioning("auto" if f.tare == "auto" else "none", tool)
    )
    # where the tool begins to form on the log's clock (the first toolpath point below the sheet
    # plane: a first lap in the plane carries no load): the unloaded approach ends there
    load_start = None
    if tp is not None:
        t_pts = tp.time + f.time_offset if point_time is None else np.asarray(point_time, float)
        below = np.flatnonzero(tp.depth > FORMING_DEPTH)
        load_start = float(t_pts[below[0]]) if below.size else None
    W, notes, _ = condition_wrench(
        log.time,
        log.wrench,
        cond,
        R_world_sensor=R,
        R_index=R_index,
        file=f.file,
        load_start=load_start,
    )
    if not log.moments_known and np.any(W[:, 3:] != 0.0):
        W = W.copy() if W is log.wrench else W
        W[:, 3:] = 0.0
    if W is log.wrench:
        return log, notes  # nothing removed: the log as read (no copy, no second validation)
    return replace(log, wrench=W), notes
