"""A study run's logs aligned to its toolpath, as ``[runs.X] sync`` asks.

* ``sync = "time"`` — toolpath point i was passed at log time ``time[i] + forces.time_offset``
  (both logs on the toolpath's nominal clock; the behaviour before alignment existed).
* ``sync = "position"`` (the default with a joint log) — FK of the logged joints gives the tool's
  actual path, tracked along the toolpath (:func:`~roboisf.sync.align_by_position`). The force
  log is on the joint log's clock (``forces.clock = "joint"``: one controller logs both) or on
  its own (``"own"``: a separate DAQ); then its own force-direction map
  (:func:`~roboisf.sync.align_by_force`) is fitted to the joint-log map by one affine clock
  relation ``τ_force = a + b · τ_joint`` (two crystal clocks differ by an offset and a rate),
  so every point keeps the joint log's precision.
* ``sync = "force"`` — the force log alone, by the turning of the force direction. A joint log,
  if any, is then read on the nominal clock (``time_offset``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.cell import Cell
from roboisf.errors import InputError
from roboisf.frames import vertical_tool
from roboisf.logs.forcelog import ForceLog
from roboisf.logs.jointlog import JointLog
from roboisf.study.sensors import sensor_forces_to_work
from roboisf.study.spec import RunSpec
from roboisf.sync.alignment import Alignment, clock_fit
from roboisf.sync.force import align_by_force
from roboisf.sync.position import align_by_position
from roboisf.toolpath import Toolpath

__all__ = [
    "CLOCK_FIT_MAX",
    "RunAlignment",
    "align_by_time",
    "align_forces_to_joints",
    "align_joints",
    "align_run",
    "fit_clock",
    "joint_step",
]

F64 = NDArray[np.float64]

#: Largest RMS misfit [toolpath points] of the affine relation between a force logger's own
#: clock and the joint log's.
CLOCK_FIT_MAX = 2.0


def align_by_time(tp: Toolpath, offset: float, *, source: str = "") -> Alignment:
    """The nominal map: point i at ``tp.time[i] + offset``, windows half-way to the neighbours."""
    tt = tp.time + offset
    mid = 0.5 * (tt[1:] + tt[:-1])
    lo = np.concatenate([tt[:1], mid])
    hi = np.concatenate([mid, tt[-1:]])
    nan = np.full(len(tp), np.nan)
    return Alignment("time", tt, lo, hi, nan, "mm", 1.0, float(tt[0]), [], source)


def fit_clock(own: Alignment, ref: Alignment) -> tuple[float, float, float]:
    """Affine ``τ_own = a + b · τ_ref`` over the points both maps read; returns
    ``(b, a, rms misfit in toolpath points)``. Points off by more than two toolpath points or
    3 MAD (a pause the force signature places inside the stop) are dropped once, and the misfit
    is that of the points kept."""
    ok = np.isfinite(own.residual) if own.method == "force" else np.ones(len(own), dtype=bool)
    x, y = ref.point_time[ok], own.point_time[ok]
    step = max(float(np.median(np.diff(own.point_time))), 1e-12)
    b, a = np.polyfit(x, y, 1)
    r = y - (a + b * x)
    mad = float(np.median(np.abs(r - np.median(r))))
    keep = np.abs(r - np.median(r)) <= max(3 * 1.4826 * mad, 2 * step)
    if keep.sum() >= 2:
        b, a = np.polyfit(x[keep], y[keep], 1)
    r = (y[keep] - (a + b * x[keep])) / step
    return float(b), float(a), float(np.sqrt(np.mean(r**2)))


@dataclass(frozen=True)
class RunAlignment:
    """A run's maps: ``forces`` on the force log's clock, ``joints`` on the joint log's (None
    unless ``sync = "position"``), and the affine relation of an own force clock."""

    run: str
    method: str
    forces: Alignment
    joints: Alignment | None = None
    force_clock: dict[str, float] | None = None

    @property
    def primary(self) -> Alignment:
        return self.joints if self.joints is not None else self.forces

    def to_dict(self) -> dict[str, Any]:
        """``summary.json`` ``alignment[run]``: method, residual_rms, residual_max (mm for
        position, toolpath points for force, null for time), clock_scale, offset [s], pauses."""
        out = self.primary.to_dict()
        out["method"] = self.method
        if self.force_clock is not None:
            out["force_clock"] = self.force_clock
        return out


def _force_work(log: ForceLog, run: RunSpec, tool_rotation: float) -> F64:
    """The logged force in work axes [N] (moments are not needed: no tip position yet)."""
    return sensor_forces_to_work(log.wrench[:, :3], run.forces, vertical_tool(tool_rotation))


def _end_shift(tp: Toolpath, residual: F64) -> float:
    """s — how far the position alignment may place the toolpath's ends in time when the
    logged tip stands ``residual`` (N,) m off them: that distance at the feed there."""
    if len(tp) < 3 or len(residual) != len(tp):
        return 0.0
    dS = np.diff(np.asarray(tp.path_length, dtype=float))
    dt = np.diff(np.asarray(tp.time, dtype=float))
    shift = 0.0
    for r, sl in ((residual[0], slice(0, 3)), (residual[-1], slice(-3, None))):
        ok = dt[sl] > 0
        v = float(np.max(dS[sl][ok] / dt[sl][ok])) if np.any(ok) else 0.0
        if v > 0 and np.isfinite(r):
            shift = max(shift, float(r) / v)
    return shift


def _clip(a: Alignment, t0: float, t1: float) -> Alignment:
    return Alignment(
        a.method,
        np.clip(a.point_time, t0, t1),
        np.clip(a.lo, t0, t1),
        np.clip(a.hi, t0, t1),
        a.residual,
        a.residual_unit,
        a.clock_scale,
        a.offset,
        a.pauses,
        a.source,
        a.notes,
    )


def align_run(
    cell: Cell,
    run: RunSpec,
    tp: Toolpath,
    force_log: ForceLog,
    joint_log: JointLog | None,
) -> RunAlignment:
    """Align ``run``'s logs to ``tp`` by ``run.sync`` (see the module docstring).

    Raises
    ------
    InputError
        naming the log: the alignment failed (residual above its bound, log not covering the
        path, force direction running backwards), or an own force clock that no affine relation
        fits.
    """
    sync = run.sync
    if sync == "time":
        return RunAlignment(
            run.name, "time", align_by_time(tp, run.forces.time_offset, source=str(run.forces.file))
        )
    if sync == "force":
        F = _force_work(force_log, run, cell.tool_rotation)
        a = align_by_force(force_log.time, F, tp, file=run.forces.file)
        return RunAlignment(run.name, "force", a)
    if joint_log is None:
        raise InputError(
            'sync = "position" needs a joint log (runs.X.joints)',
            file=run.forces.file,
            field="sync",
        )
    j = align_joints(cell, run, tp, joint_log)
    return align_forces_to_joints(cell, run, tp, j, force_log, joint_step(joint_log))


def joint_step(joint_log: JointLog) -> float:
    """s — the joint log's largest sampling interval (what :func:`align_forces_to_joints`
    allows the toolpath's ends to stand beyond the force log's span)."""
    t = joint_log.time
    return float(np.max(np.diff(t))) if t.size > 1 else 0.0


def align_joints(cell: Cell, run: RunSpec, tp: Toolpath, joint_log: JointLog) -> Alignment:
    """The joint log's map of ``sync = "position"`` (the first half of :func:`align_run`): FK
    of the logged joints tracked along ``tp``. Needs no force log: the analysis aligns the
    joints, takes the joint angles and frees the joint log before it reads the force log (the
    two logs of a 1 kHz run, 0.16 GB, never side by side)."""
    tip = cell.robot.tip_positions(joint_log.q, check_limits=False, T_base_work=cell.T_base_work)
    try:
        j = align_by_position(joint_log.time, tip, tp, file=joint_log.path)
    except InputError as e:
        # the program's own import may know why: a ball-centre program read as tips (or the
        # reverse) puts the path a ball radius off, which the logged tip then misses
        warned = tp.meta.get("warnings", [])
        said = [
            w
            for w in (warned if isinstance(warned, list) else [])
            if isinstance(w, str) and "does the program name" in w
        ]
        if not said:
            raise
        raise InputError(
            f"{e.message}. The toolpath's import warned: {said[0]} (set runs.{run.name}."
            'toolpath_point = "center" or "tip" to match the program)',
            file=e.file,
            line=e.line,
            field=e.field,
        ) from None
    return j


def align_forces_to_joints(
    cell: Cell,
    run: RunSpec,
    tp: Toolpath,
    j: Alignment,
    force_log: ForceLog,
    joint_step: float,
) -> RunAlignment:
    """The second half of :func:`align_run` for ``sync = "position"``: the force log's map
    from the joints' ``j`` (:func:`align_joints`), on the joint log's clock or its own.
    ``joint_step``: :func:`joint_step` of the joint log [s]."""
    if run.forces.clock == "joint":
        # the force log's clock is the joint log's, shifted by time_offset (0 for one controller;
        # the meaning time_offset had before alignment: joints at t, forces at t + time_offset)
        off = run.forces.time_offset
        f = j if off == 0 else j.mapped(1.0, off, method="position", source=str(run.forces.file))
        t0, t1 = float(force_log.time[0]), float(force_log.time[-1])
        # the joint log's sampling places the ends to within one of its samples; a commanded
        # path off the toolpath at an end (a compensated or online-corrected run: the residual
        # there) moves where the tool is taken to pass it by up to that offset over the feed
        slack = joint_step + 1e-6
        slack += _end_shift(tp, j.residual)
        if f.lo[0] < t0 - slack or f.hi[-1] > t1 + slack:
            raise InputError(
                f"the force log covers {t0:.3f} … {t1:.3f} s but the joint log puts the toolpath "
                f"at {f.lo[0]:.3f} … {f.hi[-1]:.3f} s: is the force log on the controller's "
                'clock? If it has its own, set forces.clock = "own"',
                file=run.forces.file,
                field="clock",
            )
        f = _clip(f, t0, t1)
        return RunAlignment(run.name, "position", f, j)
    F = _force_work(force_log, run, cell.tool_rotation)
    own = align_by_force(force_log.time, F, tp, file=run.forces.file)
    scale_f, offset_f, rms = fit_clock(own, j)
    if rms > CLOCK_FIT_MAX:
        raise InputError(
            f"the force log's own clock does not follow the joint log's: the best affine "
            f"relation misses by {rms:.2g} toolpath points RMS (limit {CLOCK_FIT_MAX:g}); "
            "a force log of another run?",
            file=run.forces.file,
            field="clock",
        )
    f = j.mapped(scale_f, offset_f, method="position", source=str(run.forces.file))
    scale, offset, pauses = clock_fit(tp.time, f.point_time)
    f = Alignment(
        f.method,
        f.point_time,
        f.lo,
        f.hi,
        f.residual,
        f.residual_unit,
        scale,
        offset,
        pauses,
        f.source,
        f.notes,
    )
    clock = {"scale": scale_f, "offset": offset_f, "fit_rms_points": rms}
    return RunAlignment(run.name, "position", f, j, clock)
