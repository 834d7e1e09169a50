"""``roboisf analyze``: the paper's decomposition from a study folder's raw files.

1. Forces from the sensor frames to the tool tip, matched to the toolpath by time.
2. Tool and holder deflection per toolpath point (``k_t W``, ``J_th k_th J_thᵀ W``).
3. CNC scan → normal deviation per toolpath point → springback ``δs = δ_CNC − δt``.
4. Robot scan → deviation → ``δc,exp = δ_robot − δs − δt − δth``.
5. VJM prediction ``δc,VJM = k_c W`` at the logged joint angles (or IK), ``Δ = δc,exp − δc,VJM``,
   compliance statistics along the path and the force-component contributions (Table 4).
6. The contribution table (Table 5), per-axis and normal-projected.

Compliance files from the FE/beam model (``roboisf tool-stiffness``) have z along the tool axis
pointing up; with the tool vertical in the work frame their axes are the work axes (a tool whose
compliance is not axisymmetric is assumed to have its FE x-axis along work x).
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from roboisf.cell import Cell, at_ball_centre, cell_from_study, tip_compliances
from roboisf.decompose.check import (
    VjmCheck,
    lateral_offset,
    term_statistics,
    vjm_check,
)
from roboisf.decompose.core import (
    FACTORS,
    Decomposition,
    contribution_rows,
    decompose,
    resultant_mean_deviation,
)
from roboisf.decompose.diagnose import (
    CorrectedRobotTerm,
    Diagnosis,
    Finding,
    diagnose,
    diagnosis_headline,
    forming_time,
    offset_seen,
)
from roboisf.decompose.identify import (
    FormingIdentification,
    identify_from_forming,
    write_stiffness_toml,
)
from roboisf.errors import InputError
from roboisf.fem import ComplianceResult
from roboisf.frames import vertical_tool
from roboisf.io.arrow import float_column
from roboisf.io.atomic import atomic_path, atomic_write, staged_directory
from roboisf.jit import heap
from roboisf.logs.forcelog import ForceLog, attach_to_toolpath
from roboisf.logs.jointlog import JointLog, read_joint_log
from roboisf.logs.thickness import read_thickness_csv
from roboisf.parts import sine_law_thickness
from roboisf.progress import Cancelled, Progress, cancellable, task
from roboisf.robot import compliance_stats, deflection_contributions, ik_toolpath
from roboisf.robot.vjm_kernel import single_blas_thread
from roboisf.scan import (
    CompareOptions,
    PreparedScan,
    ScanComparison,
    finish_scan,
    prepare_scan,
    read_scan,
)
from roboisf.sensor import UnloadedStretch, unloaded_stretches
from roboisf.study.checks import (
    check_distinct_runs,
    check_force_log,
    check_joint_log,
    check_tool_radius,
)
from roboisf.study.fingerprint import study_fingerprint
from roboisf.study.sensors import condition_study_log, read_study_force_log, sensor_to_tip
from roboisf.study.spec import ForceSensorSpec, RunSpec, Study, load_study
from roboisf.study.toolpaths import study_toolpath
from roboisf.summary import AnalysisSummary, RobotInfo, ToolInfo, Units, dumps
from roboisf.sync import Alignment
from roboisf.sync.run import (
    RunAlignment,
    align_forces_to_joints,
    align_joints,
    align_run,
    joint_step,
)
from roboisf.toolpath import Toolpath

if TYPE_CHECKING:  # the tables' libraries are imported where the tables are made
    import pandas as pd
    import pyarrow as pa

__all__ = [
    "AnalysisResult",
    "analyze",
    "read_run_force_log",
    "run_tip_wrench",
    "write_results",
]

F64 = NDArray[np.float64]
_AX = "xyz"
_WRENCH = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")


@dataclass(frozen=True)
class AnalysisResult:
    """Everything ``analyze`` found. Tables in mm, N, N·m, deg, s (the report's contract)."""

    study: Study
    cell: Cell
    decomposition: Decomposition
    per_point: pd.DataFrame
    contributions: pd.DataFrame
    contributions_normal: pd.DataFrame
    #: ``summary.json`` (:mod:`roboisf.summary`)
    summary: AnalysisSummary
    scans: dict[str, ScanComparison]
    #: the robot's compliance identified from this run (None when it cannot be)
    identification: FormingIdentification | None = None
    #: (N, 6) rad — the robot run's joint angles at each toolpath point, as the VJM used them
    #: (joint log aligned by position, or inverse kinematics)
    q_robot: F64 | None = None


def read_run_force_log(study: Study, run: RunSpec) -> ForceLog:
    """A run's force log as the study declares it (format, columns, units; ``docs/study.md``)."""
    return read_study_force_log(study, run)


def read_run_joint_log(run: RunSpec) -> JointLog:
    """A run's joint log as the study declares it (format, columns, units)."""
    assert run.joints is not None
    ju = run.joints_units or {}
    return read_joint_log(
        run.joints,
        fmt="auto" if run.joints_format == "columns" else run.joints_format,
        columns=run.joints_columns,
        time_unit=ju.get("time"),
        angle_unit=ju.get("angle"),
        timestamps=run.joints_timestamps,
    )


def run_tip_wrench(
    study: Study,
    run: RunSpec,
    tp: Toolpath,
    *,
    warnings: list[str] | None = None,
    alignment: Alignment | None = None,
    log: ForceLog | None = None,
    R_base_tip: F64 | None = None,
    unloaded: list[UnloadedStretch] | None = None,
) -> F64:
    """A run's force log at each toolpath point, moved to the tool tip: (N, 6) [N, N·m], work
    axes, the sheet's load on the tool (units from the log or the study's ``[units]``).

    The log is aligned to the toolpath (``alignment`` on the force log's clock,
    :mod:`roboisf.sync`; without it the run is aligned here as its ``sync`` says — nominal time
    + ``time_offset`` for ``"time"``), then conditioned (tare, the tool's weight below a flange
    sensor: :func:`roboisf.study.sensors.condition_study_log`; each sample takes the sensor
    orientation of the toolpath point the alignment puts it at, ``R_base_tip`` (N_tp, 3, 3) the
    forward kinematics of the joints), then checked against the toolpath
    (:func:`roboisf.study.checks.check_force_log`: forming-force magnitudes, logged positions on
    the path); warnings are appended to ``warnings``. The alignment runs on the raw log: the
    position sync does not use the forces, and the force sync uses the turning direction of the
    horizontal force, which a constant bias small against the forming force barely moves.

    ``unloaded``: the conditioned log's stretches with the tool off the sheet
    (:func:`roboisf.sensor.unloaded_stretches`), moved to the tip in work axes like the log, are
    appended to it (the diagnosis reads a sensor's static offset there, docs/diagnosis.md)."""
    f = run.forces
    rot = study.robot.tool_rotation if study.robot is not None else 0.0
    log = read_run_force_log(study, run) if log is None else log
    if alignment is None and run.sync != "time":
        joints = None if run.joints is None else read_run_joint_log(run)
        alignment = align_run(cell_from_study(study), run, tp, log, joints).forces
    log, cond_notes = condition_study_log(
        study,
        run,
        log,
        vertical_tool(rot),
        tp=tp,
        R_base_tip=R_base_tip,
        point_time=None if alignment is None else alignment.point_time,
    )
    off = f.time_offset if alignment is None else alignment.offset - float(tp.time[0])
    pt = None if alignment is None else alignment.point_time
    notes = check_force_log(log, tp, time_offset=off, point_time=pt)
    if warnings is not None:
        warnings.extend(cond_notes + notes)
    if alignment is None:
        W_s = attach_to_toolpath(log, tp, by="time", time_offset=f.time_offset)
    else:
        W_s = alignment.average(log.time, log.wrench, file=f.file)
    W_tip = sensor_to_tip(W_s, f, tp.tip, vertical_tool(rot))
    if unloaded is not None:
        t_path = tp.time[[0, -1]] + off if pt is None else np.asarray(pt)[[0, -1]]
        unloaded.extend(_unloaded_at_tip(log, f, tp, vertical_tool(rot), t_path))
    if not log.moments_known:
        # a 3-component dynamometer: the load is a point force at the contact point, so its
        # moment about the tip is (contact − tip) × F (a few N·m on a Ø10 mm ball: dropping it
        # moved the springback share by 3 points, tests/test_equipment_e2e.py)
        W_tip[:, 3:] = np.cross(tp.contact - tp.tip, W_tip[:, :3])
        if warnings is not None:
            warnings.append(
                f"{f.file.name}: no moment channels (3-component log); the load is taken as a "
                "point force at the contact point (tip moments (contact − tip) × F)"
            )
    return W_tip


def _unloaded_at_tip(
    log: ForceLog, f: ForceSensorSpec, tp: Toolpath, R_work_tip: F64, t_path: F64
) -> list[UnloadedStretch]:
    """The conditioned log's unloaded stretches outside ``t_path`` (the log times of the path's
    first and last point), their readings moved to the tip like the log's (at the path's first
    tip: the forces do not depend on it). A stretch inside the tare window reads zero by
    construction: marked ``tared``."""

    def to_tip(B: F64) -> F64:
        return sensor_to_tip(B, f, np.repeat(tp.tip[:1], len(B), 0), R_work_tip)

    out = []
    path = (float(t_path[0]), float(t_path[1]))
    for s in unloaded_stretches(log.time, log.wrench, path=path):
        if f.tare == "auto":
            tared = s.where == "start"
        elif isinstance(f.tare, tuple):
            tared = s.t0 < float(f.tare[1]) and float(f.tare[0]) < s.t1
        else:
            tared = False
        out.append(replace(s.map(to_tip), tared=tared))
    return out


def _joint_angles(
    cell: Cell,
    run: RunSpec,
    tp: Toolpath,
    joints: Alignment | None = None,
    log: JointLog | None = None,
) -> tuple[F64, str]:
    if run.joints is None:
        q = ik_toolpath(cell.robot, tp.tip, cell.T_base_work, tool_rotation=cell.tool_rotation).q
        return q, "inverse kinematics of the toolpath"
    log = read_run_joint_log(run) if log is None else log
    if joints is not None:  # aligned by position: the joints where the tool passed each point
        q = np.column_stack([np.interp(joints.point_time, log.time, log.q[:, j]) for j in range(6)])
        return q, f"joint log {run.joints.name} (aligned by position)"
    t0, t1 = float(tp.time[0]), float(tp.time[-1])
    if log.time[0] > t0 + 1e-6 or log.time[-1] < t1 - 1e-6:
        raise InputError(
            f"the joint log covers {log.time[0]:.3f} … {log.time[-1]:.3f} s but the toolpath runs "
            f"{t0:.3f} … {t1:.3f} s (a log that stops half-way?)",
            file=run.joints,
        )
    check_joint_log(cell.robot, cell.T_base_work, log, tp, file=run.joints)
    q = np.column_stack([np.interp(tp.time, log.time, log.q[:, j]) for j in range(6)])
    return q, f"joint log {run.joints.name}"


def scan_options(study: Study) -> CompareOptions:
    """The scan comparison's options as the analysis uses them for ``study``: per-point
    deviations over the whole wall (the paper's polar plot sits at z = −11 mm, inside the rim
    band); the rim band leaves the statistics through the ``used`` mask."""
    a = study.analysis
    return CompareOptions(
        register=a.registration,
        rim_band=0.0,
        radius=a.point_radius,
        # the scan's polar summary: the paper's contour (z = −11 mm) unless the study asks another
        contour_z=CompareOptions.contour_z if a.contour_z is None else a.contour_z,
        max_distance=a.max_distance,
    )


def _compare(
    study: Study,
    cell: Cell,
    run: RunSpec,
    tp: Toolpath,
    progress: Progress | None,
    keep_points: bool = False,
    prepared: PreparedScan | None = None,
) -> ScanComparison:
    """``run``'s scan compared with the part and ``tp`` (its first half done already if
    ``prepared``: :func:`_prepare`)."""
    prep = _prepare(study, cell, run, progress) if prepared is None else prepared
    return finish_scan(
        prep,
        cell.part,
        toolpath=tp,
        toolpath_source=str(run.toolpath),
        progress=progress,
        keep_points=keep_points,
    )


def _prepare(study: Study, cell: Cell, run: RunSpec, progress: Progress | None) -> PreparedScan:
    """``run``'s scan read, registered, sorted and cut to the wall (:func:`prepare_scan`)."""
    cloud = read_scan(run.scan, unit=run.scan_unit)
    return prepare_scan(
        cloud,
        cell.part,
        options=scan_options(study),
        progress=progress,
        consume=True,  # the raw points freed once sorted (the cloud is dropped here anyway)
        # a wrong unit is fixed in study.toml, not with the scan command's --unit
        unit_setting=(study.root / "study.toml", f"runs.{run.name}.scan_unit"),
    )


def _logs_part(
    study: Study,
    cell: Cell,
    tp: Toolpath,
    progress: Progress | None,
    tp_robot: Toolpath | None = None,
) -> tuple[
    dict[str, RunAlignment],
    F64,
    str,
    list[str],
    F64,
    F64,
    dict[str, list[UnloadedStretch]],
    bool,
]:
    """The logs' part of the analysis: read, align, joint angles, tip wrenches of both runs,
    each run's unloaded stretches (at the tip, work axes: :func:`run_tip_wrench`) and whether
    the robot's force log has moment channels (a 3-component log's tip moments are the
    point-contact moment the analysis puts there).

    One run at a time: a run's raw logs (2.3 M samples at 1 kHz on the paper cone, ~0.15 GB as
    float64) are freed before the next run's are read, so that only one sits beside the scan
    comparison running in the other thread (holding both made the command's peak RSS depend on
    how the two threads met: 0.83–1.03 GiB on the paper cone). ``tp_robot``: the robot run's
    own path when it was formed with a commanded (compensated) version of ``tp``."""
    cnc, rob = study.cnc, study.robot_run
    aligned: dict[str, RunAlignment] = {}
    wrench: dict[str, F64] = {}
    unloaded: dict[str, list[UnloadedStretch]] = {}
    input_warnings: list[str] = []
    q: F64 | None = None
    q_source = ""
    rob_moments = True
    for r in (cnc, rob):
        tp_run = tp_robot if (r is rob and tp_robot is not None) else tp
        # aligned by position: the joint log is read, aligned, turned into the robot's joint
        # angles and freed before the force log is read — each 1 kHz log alone beside the
        # scan comparison in the other thread (the two side by side were the command's peak)
        by_joints = r.sync == "position" and r.joints is not None
        joint_notes: list[str] = []
        j_map: Alignment | None = None
        j_step = 0.0
        log: ForceLog | None = None
        with task(progress, f"{r.name} logs: alignment"):
            joints = None if r.joints is None else read_run_joint_log(r)
            if joints is not None and r.joints is not None:
                # what timestamps = "repair" changed is said in the summary's warnings
                joint_notes = [f"{r.joints.name}: {n}" for n in joints.notes]
            if by_joints:
                assert joints is not None
                j_map, j_step = align_joints(cell, r, tp_run, joints), joint_step(joints)
            else:
                log = read_run_force_log(study, r)
                input_warnings.extend(f"{r.forces.file.name}: {n}" for n in log.notes)
                input_warnings.extend(joint_notes)
                aligned[r.name] = align_run(cell, r, tp_run, log, joints)
        R_fk = None
        if r is rob:
            with task(progress, "robot joint angles"):
                j_rob = j_map if by_joints else aligned[rob.name].joints
                q, q_source = _joint_angles(cell, rob, tp_run, j_rob, joints)
            if rob.forces.tool_mass is not None:
                # the sensor's orientation for its tool-weight model
                R_fk = cell.robot.fk(q, check_limits=False)[:, :3, :3]
        joints = None  # the log's angles are q now: not beside the force log
        if log is None:
            assert j_map is not None
            with task(progress, f"{r.name} logs: force alignment"):
                log = read_run_force_log(study, r)
                input_warnings.extend(f"{r.forces.file.name}: {n}" for n in log.notes)
                input_warnings.extend(joint_notes)
                aligned[r.name] = align_forces_to_joints(cell, r, tp_run, j_map, log, j_step)
        if r is rob:
            rob_moments = log.moments_known
        with task(progress, f"{r.name} logs: forces to the tool tip"):
            wrench[r.name] = run_tip_wrench(
                study,
                r,
                tp_run,
                warnings=input_warnings,
                alignment=None if r.sync == "time" else aligned[r.name].forces,
                log=log,
                R_base_tip=R_fk,
                unloaded=unloaded.setdefault(r.name, []),
            )
        del log, joints
        _trim()
    assert q is not None
    return (
        aligned,
        q,
        q_source,
        input_warnings,
        wrench[cnc.name],
        wrench[rob.name],
        {"cnc": unloaded[cnc.name], "robot": unloaded[rob.name]},
        rob_moments,
    )


def _then(study: Study) -> dict[str, Any]:
    """What the analysis needs besides the scans, for the scans' thread once its scan is done:
    the inputs' fingerprint (which study and files these results came from: compensate
    --results checks it; SHA-256 of ~100 MB on the paper cone) and the report's modules loaded
    (plotly, pandas: ~0.3 s of write_results otherwise; with plotly's HTML writer, 0.035 s
    more: :func:`roboisf.report.document.preload`)."""
    fingerprint = study_fingerprint(study)
    import roboisf.report.document
    import roboisf.report.render

    roboisf.report.document.preload()
    return fingerprint


def _trim() -> None:
    """Give the heap's freed pages back to the system (glibc's ``malloc_trim``; a no-op
    elsewhere). After the logs and after each scan: numpy's large temporaries come from the
    heap once glibc's mmap threshold has grown, and their freed pages stayed resident under
    the next scan's peak (the command's peak RSS 1.04 → 0.86–1.0 GB on the paper cone, same
    time; a fixed mmap threshold instead cost 4 s of page faults)."""
    heap.trim()


class _ScansBeside:
    """The scan comparisons of ``runs`` in a worker thread, beside the log reading.

    The scans need only the part and the toolpath; the logs' reading, alignment and conditioning
    run in the calling thread meanwhile (mostly pandas/numpy holding the GIL, while the scan
    kernels release it), so the two cores are both busy (issue #16). The first scan is read
    and registered while the calling thread reads the toolpath (:meth:`set_toolpath`). Done
    with the logs, the calling thread compares the last scan itself (:meth:`compare_last`),
    unless the worker has begun it: two lanes, one scan each, whose parallel outlier filters
    fill each other's idle core (issue #31: the worker finishing both scans while the calling
    thread only waited left a core idle through the last scan's serial steps, ~0.3 s).

    The last scan's first half (reading, registration, spatial order: :func:`_prepare`, which
    needs only the part) is the worker's too, right after the first scan's, unless the calling
    thread got there first: the logs' lane was the longer one, and its serial steps ran at the
    end with the other core idle (0.5-0.7 s of a paper-cone run). The peak RSS is then the
    first scan's filter beside the last scan's registered wall points (~50 MB) and the logs.
    The work after the scans (``then``: the inputs' fingerprint, the report's imports) gets a
    thread of its own once both scans are read and registered — or as soon as the calling
    thread, done with its logs, would wait for the worker's reading of the last scan: its core
    was idle there (~0.26 s of a paper-cone run, 0.9 cores busy; 1.7 with it).

    :meth:`result` waits for them and re-raises their error (in the runs' order, whichever
    thread met it); :meth:`cancel` stops them at their next step (the logs were refused, or
    Ctrl-C) and waits, so no thread outlives the analysis."""

    def __init__(
        self,
        study: Study,
        cell: Cell,
        runs: tuple[RunSpec, ...],
        progress: Progress | None,
        keep_points: bool = False,
        then: Callable[[], Any] | None = None,
    ) -> None:
        self._study, self._cell, self._runs = study, cell, runs
        self._keep = keep_points
        #: what ``then`` returned: the worker calls it after its scans (work that needs none of
        #: them, done while the calling thread may still compare the last scan)
        self.then: Any = None
        # the toolpath, once the calling thread has read it (the first scan's first half needs
        # only the part: it runs beside the toolpath's reading)
        self._tp: Toolpath | None = None
        self._tp_ready = threading.Event()
        self._cancel = threading.Event()
        self._scans: dict[str, ScanComparison] = {}
        self._error: BaseException | None = None
        self._claim_lock = threading.Lock()
        self._claimed: set[str] = set()
        # the error the calling thread met comparing a scan (None: done), and when
        self._theirs: dict[str, BaseException | None] = {}
        self._ready = {run.name: threading.Event() for run in runs}
        # the last scan's first half, prepared ahead by the worker (or its error), and when
        self._ahead: PreparedScan | None = None
        self._ahead_error: BaseException | None = None
        self._ahead_ready = threading.Event()
        # ``then`` in a thread of its own, started once both scans are read and registered:
        # beside the scans' filters (compiled code, the lock free) instead of after the
        # worker's scan, where it came after the last scan too once the lanes ended together
        self._then_thread: threading.Thread | None = None
        self._then_closed = False  # set by the worker before its last join: no later start
        self._then_error: Exception | None = None
        prog = cancellable(progress, self._cancel)

        def run_then() -> None:
            assert then is not None
            try:
                self.then = then()
            except Exception as e:  # raised by the worker after the scans' errors
                self._then_error = e

        def start_then() -> None:
            # by the worker once both scans are read and registered, or by the calling thread
            # when it would otherwise wait for the last one's (its logs done first: its core
            # idle, ~0.26 s of a paper-cone run) — never after the worker has joined it
            with self._claim_lock:
                if then is not None and self._then_thread is None and not self._then_closed:
                    self._then_thread = threading.Thread(target=run_then, name="roboisf-then")
                    self._then_thread.start()

        self._start_then: Callable[[], None] = start_then

        def work() -> None:
            theirs = []  # the runs the calling thread compares: their errors raised in order
            try:
                for i, run in enumerate(runs):
                    if not self._claim(run.name):
                        theirs.append(run.name)
                        continue
                    for name in theirs:  # a first scan's error before a later one's
                        self._raise_theirs(name)
                    theirs.clear()
                    if i == 0 and len(runs) > 1:
                        with task(prog, f"scan {run.name}: read and register"):
                            prep = _prepare(study, cell, run, prog)
                        self._prepare_ahead(prog)  # the last scan's first half, here
                        start_then()
                    elif i == len(runs) - 1 and self._ahead_ready.is_set():
                        prep = self._take_ahead(run)  # prepared after the first's
                    else:
                        prep = None
                    with task(prog, f"scan {run.name}"):
                        if prep is None:
                            prep = _prepare(study, cell, run, prog)
                        self._wait(self._tp_ready, run.name)
                        assert self._tp is not None
                        self._scans[run.name] = _compare(
                            study, cell, run, self._tp, prog, keep_points, prep
                        )
                        del prep
                        _trim()
                with self._claim_lock:
                    inline = then is not None and self._then_thread is None
                    self._then_closed = True
                if inline:
                    run_then()  # one run: here, after its scan
                elif self._then_thread is not None:
                    self._then_thread.join()
                for name in theirs:
                    self._raise_theirs(name)
                if self._then_error is not None:  # after the calling thread's scan's error
                    raise self._then_error
            except Cancelled:
                pass
            except BaseException as e:  # re-raised in the caller's thread by result()
                self._error = e
            finally:
                self._ahead_ready.set()  # never left waited for
                with self._claim_lock:
                    self._then_closed = True
                if self._then_thread is not None:  # no thread outlives the analysis
                    self._then_thread.join()

        self._thread = threading.Thread(target=work, name="roboisf-scans")
        self._thread.start()

    def set_toolpath(self, tp: Toolpath) -> None:
        """The toolpath the scans are compared along (read by the calling thread)."""
        self._tp = tp
        self._tp_ready.set()

    def _wait(self, event: threading.Event, name: str) -> None:
        """In the worker: wait for ``event``, or stop (:class:`Cancelled`) once cancelled."""
        while not event.wait(0.05):
            if self._cancel.is_set():
                raise Cancelled(name)

    def _raise_theirs(self, name: str) -> None:
        """In the worker: wait for the calling thread's comparison of scan ``name``; its error
        raised here (:meth:`result` re-raises it in the caller's thread)."""
        self._wait(self._ready[name], name)
        err = self._theirs.pop(name)
        if err is not None:
            raise err

    def _claim(self, name: str) -> bool:
        with self._claim_lock:
            if name in self._claimed:
                return False
            self._claimed.add(name)
            return True

    def _prepare_ahead(self, progress: Progress | None) -> None:
        """In the worker, after the first scan's first half: the last scan's, unless the
        calling thread has begun it. Its error is kept for whoever compares that scan (raised
        in the runs' order); Ctrl-C or a cancel stops the worker as before."""
        run = self._runs[-1]
        if not self._claim(f"prepare {run.name}"):
            return
        try:
            with task(progress, f"scan {run.name}: read and register"):
                self._ahead = _prepare(self._study, self._cell, run, progress)
        except Exception as e:
            self._ahead_error = e
        finally:
            self._ahead_ready.set()

    def _take_ahead(self, run: RunSpec) -> PreparedScan:
        """The last scan's first half as the worker prepared it (its error raised here)."""
        err, self._ahead_error = self._ahead_error, None
        if err is not None:
            raise err
        prep, self._ahead = self._ahead, None
        if prep is None:  # cancelled while preparing: stop as the worker did
            raise Cancelled(run.name)
        return prep

    def _last_first_half(self, run: RunSpec, progress: Progress | None) -> PreparedScan:
        """In the calling thread: the last scan's first half, prepared here unless the worker
        has begun it (then waited for: the worker stops only when this thread cancels it)."""
        if self._claim(f"prepare {run.name}"):
            with task(progress, f"scan {run.name}: read and register"):
                return _prepare(self._study, self._cell, run, progress)
        if not self._ahead_ready.is_set():
            self._start_then()  # this core would wait: the work after the scans, here
        while not self._ahead_ready.wait(0.05):
            if not self._thread.is_alive():
                break
        return self._take_ahead(run)

    def compare_last(self, progress: Progress | None) -> None:
        """In the calling thread: the last run's scan compared (read, registered, filtered,
        along the toolpath), unless the worker has begun it; its first half is the worker's
        when it got there first. An error there is the worker's to raise, in the runs' order
        (a first scan's error first); Ctrl-C is raised here."""
        run = self._runs[-1]
        if len(self._runs) < 2 or not self._thread.is_alive() or not self._claim(run.name):
            return
        err: BaseException | None = None
        try:
            prep = self._last_first_half(run, progress)
            with task(progress, f"scan {run.name}"):
                assert self._tp is not None  # set before the logs (set_toolpath)
                self._scans[run.name] = _compare(
                    self._study, self._cell, run, self._tp, progress, self._keep, prep
                )
                del prep
                _trim()
        except Exception as e:
            err = e
        except BaseException:
            err = Cancelled(run.name)
            raise
        finally:
            self._theirs[run.name] = err
            self._ready[run.name].set()

    def result(self) -> dict[str, ScanComparison]:
        """The scans' comparisons, in the study's order of the runs — not the order the two
        lanes finished in, which the machine's load decides: the summary's warnings and every
        table built by walking this dict came out in either order (two analyses of one study
        gave two summary.json, 2026-11-29)."""
        self._thread.join()
        if self._error is not None:
            raise self._error
        return {run.name: self._scans[run.name] for run in self._runs if run.name in self._scans}

    def running(self) -> bool:
        return self._thread.is_alive()

    def cancel(self) -> None:
        self._cancel.set()
        self._thread.join()


def analyze(
    study: Study | str | Path,
    *,
    progress: Progress | None = None,
    overlap: bool = True,
    keep_points: bool = False,
) -> AnalysisResult:
    """Run the decomposition on a study (a :class:`Study` or a folder/``study.toml``).

    ``overlap``: compare the scans in a worker thread while the logs are read and aligned (the
    same results; False runs every step in turn, in the calling thread). ``keep_points``: keep
    each scan's per-point arrays in ``result.scans`` (:meth:`ScanComparison.without_points`:
    by default only their statistics, so that the first scan's 0.18 GB per 2 M points does not
    sit under the second scan's peak; the results use the per-toolpath-point deviations).

    BLAS runs on one thread inside (:func:`~roboisf.robot.vjm_kernel.single_blas_thread`): the
    work is already parallel (the scans beside the logs, their chunks on every core), and
    OpenBLAS's own threads, spinning between small products, took the cores from it."""
    with single_blas_thread():
        return _analyze(study, progress=progress, overlap=overlap, keep_points=keep_points)


def _toolpaths(study: Study, cell: Cell, progress: Progress | None) -> tuple[Toolpath, Toolpath]:
    """The CNC run's toolpath and the robot run's (the same path, or a commanded version of
    it: a compensated run), checked against the tool and the part."""
    cnc, rob = study.cnc, study.robot_run
    with task(progress, "toolpath"):
        tp = study_toolpath(study, cnc, cell.part)  # a toolpath CSV or a CAM program
        tp_r = tp if rob.toolpath == cnc.toolpath else study_toolpath(study, rob, cell.part)
        if len(tp_r) != len(tp) or np.max(np.abs(tp_r.contact - tp.contact)) > 1e-6:
            raise InputError(
                "the CNC and robot runs must use the same toolpath (the method "
                "compares the two parts point by point)",
                file=rob.toolpath,
            )
        for path in (tp, tp_r):
            check_tool_radius(study.tool.ball_diameter, path, study_file=study.root / "study.toml")
        off = np.abs(cell.part.closest_point(tp.contact).distance)
        if off.max() > 0.1e-3:
            i = int(np.argmax(off))
            raise InputError(
                f"toolpath point {i} is {off[i] * 1e3:.2f} mm off the part: the contact points are "
                "not on the nominal surface of [part] (a toolpath of another part?)",
                file=cnc.toolpath,
            )
    return tp, tp_r


def _analyze(
    study: Study | str | Path,
    *,
    progress: Progress | None,
    overlap: bool,
    keep_points: bool,
) -> AnalysisResult:
    if not isinstance(study, Study):
        study = load_study(study)
    cell = cell_from_study(study)
    cnc, rob = study.cnc, study.robot_run
    check_distinct_runs(  # the robot part measured on its own, not the CNC's files copied
        {"scan": cnc.scan, "forces.file": cnc.forces.file},
        {"scan": rob.scan, "forces.file": rob.forces.file},
    )
    # the scans' thread starts first: the first scan's reading, registration and sort need only
    # the part (the toolpath, read meanwhile, is handed over after it); done with its scan, it
    # takes the inputs' fingerprint and loads the report's modules, which need no scan
    beside = (
        _ScansBeside(study, cell, (cnc, rob), progress, keep_points, then=partial(_then, study))
        if overlap
        else None
    )
    # everything before the scans' results inside: an error here (a refused toolpath or log, a
    # tool's FE model, Ctrl-C) stops the scans' thread at its next step, none outlives the
    # analysis
    try:
        tp, tp_r = _toolpaths(study, cell, progress)
        # a compensated robot run: its commanded tips minus the nominal (the ball centre
        # moves alike)
        command = tp_r.tip - tp.tip
        has_command = bool(np.max(np.abs(command)) > 1e-9)
        truth_dir = run_truth_dir(study)
        truth_file = truth_dir / "per_point.parquet"
        truth = _read_truth(truth_file) if truth_file.is_file() else None  # before the long work
        if beside is not None:
            beside.set_toolpath(tp)
        aligned, q, q_source, input_warnings, W_cnc, W_rob, unloaded, rob_moments = _logs_part(
            study, cell, tp, progress, tp_r if has_command else None
        )
        _trim()
        with task(progress, "tool and holder compliance"):
            k_tool, k_holder, k_t, k_th = tip_compliances(cell, progress=progress)
        # deflections of the ball centre (the paper's reference: its normal motion forms the part)
        R_ball = cell.tool.radius
        tool_cnc = at_ball_centre(W_cnc @ k_t.T, R_ball)
        tool_rob = at_ball_centre(W_rob @ k_t.T, R_ball)
        holder_rob = at_ball_centre(W_rob @ k_th.T, R_ball)
        # what needs only the logs, done while the scans may still run (≈ 0.1 s off the serial
        # tail): the robot's joint compliance along the path and the inputs' fingerprint (which
        # study and files these results came from: compensate --results checks it)
        with task(progress, "robot VJM"):
            k_c = cell.robot.compliance(q, T_base_work=cell.T_base_work)
            vjm = at_ball_centre(np.einsum("nij,nj->ni", k_c, W_rob), R_ball)
        if beside is not None:
            # the last scan in this thread, beside the first in the worker
            beside.compare_last(progress)
    except BaseException:
        if beside is not None:
            beside.cancel()
        raise

    if beside is not None:
        scans = beside.result()
        fingerprint = beside.then
    else:
        fingerprint = _then(study)
        scans = {}
        for run in (cnc, rob):
            with task(progress, f"scan {run.name}"):
                scans[run.name] = _compare(study, cell, run, tp, progress, keep_points)
                _trim()
    dev_c, dev_r = scans[cnc.name].toolpath, scans[rob.name].toolpath
    assert dev_c is not None and dev_r is not None

    valid = dev_c.valid & dev_r.valid & (tp.depth > study.analysis.rim_band)
    cmd = command if has_command else None
    d = decompose(tp.normal, dev_c.dn, dev_r.dn, tool_cnc, tool_rob, holder_rob, vjm, valid, cmd)
    # each point's forming time over the robot run (a thermal drift grows with it; a scan is
    # one snapshot), and whether the robot scan's registration fitted its tilts (the flange)
    tau = forming_time(aligned[rob.name].primary.point_time, len(tp))
    tilt_registered = {"rx", "ry"} <= set(scans[rob.name].registration.fitted)
    with task(progress, "diagnosis"):
        lever = sensor_lever(rob.forces, tp.tip[0], vertical_tool(cell.tool_rotation))
        diag, corr = _diagnose(
            cell,
            tp,
            q,
            W_cnc,
            W_rob,
            d,
            k_t,
            k_th,
            k_c,
            unloaded,
            tau,
            tilt_registered,
            lever,
            rob_moments,
        )
    W_used = W_rob
    if diag.forces_corrected:
        # the terms a force drives, at the forces the diagnosis corrected (a flange sensor at
        # fault against the CNC dynamometer: docs/diagnosis.md); the logs' columns stay measured
        W_used = corr.W_rob
        tool_rob = at_ball_centre(W_used @ k_t.T, R_ball)
        holder_rob = at_ball_centre(W_used @ k_th.T, R_ball)
        vjm = at_ball_centre(np.einsum("nij,nj->ni", k_c, W_used), R_ball)
        d = decompose(
            tp.normal, dev_c.dn, dev_r.dn, tool_cnc, tool_rob, holder_rob, vjm, valid, cmd
        )

    per_point = _per_point(cell, tp, W_cnc, W_rob, dev_c, dev_r, d)
    if has_command:
        per_point["command_dn"] = d.normal["command"] * 1e3
    thick = rob.thickness or cnc.thickness
    if thick is not None:
        per_point["thickness_measured"] = read_thickness_csv(thick).at(tp.depth) * 1e3
    import pandas as pd  # the tables: after the scans, not under their peak (docs/analyze.md)

    contributions = pd.DataFrame(_mm_rows(contribution_rows(d, projected=False)))
    contributions_normal = pd.DataFrame(_mm_rows(contribution_rows(d, projected=True)))
    # the summary's fields, in the file's order, as the steps below find them; built into the
    # typed AnalysisSummary once they are all known
    summary = _summary(study, cell, tp, d, k_c, W_used, valid, k_tool, k_holder, q_source, scans)
    summary["fingerprint"] = fingerprint
    summary["warnings"].extend(input_warnings)
    summary["alignment"] = {name: a.to_dict() for name, a in aligned.items()}
    for entry in summary["alignment"].values():
        entry["source"] = _in_study(entry["source"], study.root)
    for a in aligned.values():
        summary["warnings"].extend(f"{a.run} alignment: {n}" for n in a.primary.notes)
    with task(progress, "model check and identification"):
        ident = _model_checks(cell, tp, W_cnc, W_rob, d, summary, diag, corr)
    if diag.forces_corrected:  # what compensate pre-deflects with (docs/diagnosis.md)
        for j, name in enumerate(_WRENCH):
            per_point[f"robot_corrected_{name}"] = corr.W_rob[:, j]
    pattern = diag.scan_pattern(tp.normal, tp.contact)
    if pattern is not None:  # what the diagnosis put on the scan: never pre-deflected for
        per_point["scan_pattern_dn"] = pattern * 1e3
    offset = diag.offset_pattern(tp.normal, tp.contact)
    if offset is not None:  # the scan's or the part's: compensate asks which (--offset)
        per_point["offset_pattern_dn"] = offset * 1e3
    drift = diag.drift_pattern(tp.normal, tau)
    if drift is not None:  # the formed part's: compensate corrects it, and says it may change
        per_point["drift_pattern_dn"] = drift * 1e3
    if ident is not None:
        per_point["identified_dn"] = ident.predicted * 1e3
    if truth is not None:
        _attach_truth(truth_file, per_point, summary, d, truth)
        k_model = None if cell.robot.stiffness is None else cell.robot.joint_stiffness
        _truth_vs_model(truth_dir, per_point, summary, d, k_model)
    if ident is not None:
        # the file write_results writes beside summary.json, relative to the results folder,
        # never the absolute path: the same inputs give the same bytes anywhere (issue 29)
        summary["identified_stiffness"] = IDENTIFIED_STIFFNESS
    return AnalysisResult(
        study,
        cell,
        d,
        per_point,
        contributions,
        contributions_normal,
        AnalysisSummary(**summary),
        scans,
        ident,
        q,
    )


#: A sideways scan shift below this [m] is not worth a warning.
LATERAL_WARN = 0.05e-3
#: A robot-vs-CNC difference of the lap-mean lateral force above this [N] is flagged.
FORCE_BIAS_WARN = 5.0


def _diagnose(
    cell: Cell,
    tp: Toolpath,
    q: F64,
    W_cnc: F64,
    W_rob: F64,
    d: Decomposition,
    k_t: F64,
    k_th: F64,
    k_c: F64,
    unloaded: dict[str, list[UnloadedStretch]] | None = None,
    tau: F64 | None = None,
    tilt_registered: bool = True,
    lever: F64 | None = None,
    moments_measured: bool = True,
) -> tuple[Diagnosis, CorrectedRobotTerm]:
    """The diagnosis of the decomposition ``d`` at the measured forces (docs/diagnosis.md);
    ``unloaded``: each run's stretches with the tool off the sheet (keys "cnc", "robot");
    ``tau``: each point's forming time over the robot run in [0, 1]; ``tilt_registered``: the
    robot scan's registration fitted its tilts; ``lever``: the robot's force sensor's origin
    relative to the tip (:func:`sensor_lever`); ``moments_measured``: the robot's force log
    has moment channels."""
    return diagnose(
        robot=cell.robot,
        q=q,
        T_base_work=cell.T_base_work,
        k_t=k_t,
        k_th=k_th,
        k_c=k_c,
        ball_radius=cell.tool.radius,
        normal=tp.normal,
        contact=tp.contact,
        tip=tp.tip,
        lap=tp.lap,
        depth=tp.depth,
        W_cnc=W_cnc,
        W_rob=W_rob,
        measured=d.normal["robot_compliance"],
        valid=d.valid,
        axisymmetric=cell.part.symmetry.order == 0,
        unloaded=unloaded,
        tau=tau,
        tilt_registered=tilt_registered,
        sensor_lever=lever,
        moments_measured=moments_measured,
    )


def sensor_lever(spec: ForceSensorSpec, tip: F64, R_work_tip: F64) -> F64:
    """(3,) m — a force sensor's origin relative to the tool tip ``tip`` (3,), work axes: the arm
    on which a force the sensor reads makes a moment about the tip (a force offset of the
    sensor makes one there and none about the sensor). Read off :func:`sensor_to_tip` — the
    same transform as the log's — for three unit forces: ``M = lever × F``."""
    W = np.zeros((3, 6))
    W[:, :3] = np.eye(3)
    T = sensor_to_tip(W, spec, np.repeat(np.asarray(tip, dtype=float)[None, :], 3, 0), R_work_tip)
    # rows F_i, M_i = [lever]× F_i: [lever]× = Mᵀ (Fᵀ)⁻¹
    S = T[:, 3:].T @ np.linalg.inv(T[:, :3].T)
    return np.array([S[2, 1], S[0, 2], S[1, 0]])


def _model_checks(
    cell: Cell,
    tp: Toolpath,
    W_cnc: F64,
    W_rob: F64,
    d: Decomposition,
    summary: Any,
    diag: Diagnosis,
    corr: CorrectedRobotTerm,
) -> FormingIdentification | None:
    """``vjm_check``, the identification, the term statistics and the warnings of the robot
    term (docs/analyze.md, "Does the model hold?") and the diagnosis's findings
    (docs/diagnosis.md), into ``summary``. ``d`` is at the forces the diagnosis corrected when
    it corrected them; the identification runs on the robot term less the scan's pattern."""
    meas, pred, valid = d.normal["robot_compliance"], d.normal["vjm"], d.valid
    vc = vjm_check(meas, pred, valid, tp.lap, tp.depth)
    summary["vjm_check"] = vc.to_dict()
    summary["vjm_check"]["forces"] = (
        "corrected by the diagnosis (flange sensor against the CNC dynamometer)"
        if diag.forces_corrected
        else "measured"
    )
    summary["diagnosis"] = diag.to_list()
    summary["diagnosis_headline"] = diagnosis_headline(diag.findings)
    summary["diagnosis_forces_corrected"] = diag.forces_corrected
    verdicts = {f.suspect: f for f in diag.findings}
    summary["terms_normal"] = term_statistics(
        {k: d.normal[k] for k in (*FACTORS, "vjm", "delta", "cnc", "robot")}, valid
    )
    ident: FormingIdentification | None = None
    if vc.verdict == "not_observable":
        summary["identification"] = {"mode": None, "observability": vc.reason}
        summary["warnings"].append(
            "the robot's compliance is not identified from this run: " + vc.reason
        )
    else:
        try:
            ident = identify_from_forming(
                corr.A, corr.measured, valid, tp.lap, cell.robot.joint_stiffness
            )
        except InputError as e:
            summary["identification"] = {"mode": None, "observability": e.message}
            summary["warnings"].append(f"robot compliance not identified: {e.message}")
        else:
            summary["identification"] = ident.to_dict()
    summary["identified_stiffness"] = None  # named by analyze when identified
    if vc.verdict == "mismatch":
        if verdicts["robot_stiffness"].verdict == "ok":
            # the diagnosis puts the difference elsewhere (a scan's misregistration, a sensor):
            # "the VJM's prediction is off — use the identified stiffness" contradicted it
            elsewhere = [
                f.suspect.replace("_", " ")
                for f in diag.findings
                if f.verdict == "fault" and f.suspect != "robot_stiffness"
            ]
            if diag.robot is not None and any(offset_seen(diag.robot)):
                elsewhere.append(
                    "an offset of the robot part (the robot scan's registration or the robot's "
                    "work object: cannot tell apart)"
                )
            summary["warnings"].append(
                f"the robot term differs from the VJM's: {vc.reason}; the diagnosis finds the "
                "robot's stiffness as modelled and puts the difference on "
                + (", ".join(elsewhere) if elsewhere else "no single suspect")
                + " (docs/diagnosis.md)"
            )
        else:
            use = (
                " — use the identified stiffness (identified_stiffness.toml) for compensate and "
                "plan"
                if ident is not None
                else ""
            )
            summary["warnings"].append(
                f"the robot model does not hold: {vc.reason}; the robot term is the measured "
                f"one, the VJM's prediction is off{use}"
            )
    summary["warnings"].extend(
        _lateral_warnings(tp, d, vc, summary, verdicts["scan_shift"], verdicts["thermal_drift"])
    )
    if verdicts["force_bias"].verdict == "fault":
        summary["warnings"].extend(_force_bias_warnings(tp, W_cnc, W_rob, valid))
    for name in (
        "force_gain",
        "force_moment_crosstalk",
        "force_moment_bias",
        "force_crosstalk",
        "scan_rotation",
        "thermal_drift",
    ):
        if verdicts[name].verdict == "fault":
            summary["warnings"].append(verdicts[name].headline)
    return ident


def _lateral_warnings(
    tp: Toolpath,
    d: Decomposition,
    vc: VjmCheck,
    summary: dict[str, Any],
    shift: Finding | None = None,
    drift: Finding | None = None,
) -> list[str]:
    """A sideways scan shift the fixture registration cannot see (z and tilts only). The robot
    scan's is warned only when the diagnosis's ``shift`` finding calls it a fault (a joint-by-joint
    stiffness error or a sensor fault leaves a similar pattern beside one scale); a
    ``cannot_tell`` is said as such, unless a ``drift`` at fault explains the pattern (an offset
    growing over the run, which a fit of a constant shift takes for one: its own warning)."""
    reg = summary.get("registration") or {}
    out = []
    fits = {}
    r = vc.ratio if np.isfinite(vc.ratio) else 1.0
    # the CNC part: springback alone should carry no n·s pattern; the robot part: what the
    # scaled VJM leaves of the robot term
    fields = {
        "cnc": d.normal["springback"],
        "robot": d.normal["robot_compliance"] - r * d.normal["vjm"],
    }
    for run, field_ in fields.items():
        lo = lateral_offset(field_, tp.normal, tp.lap, d.valid)
        if lo is None:
            continue
        fits[run] = {
            "shift_mm": [float(v) * 1e3 for v in lo.shift],
            "size_mm": lo.size * 1e3,
            "direction_deg": lo.direction_deg,
            "se_mm": lo.se * 1e3,
            "explained_variance": lo.explained,
        }
        if not (lo.size > LATERAL_WARN and lo.size > 4 * lo.se):
            continue
        if run == "robot" and shift is not None and shift.verdict != "fault":
            drifted = drift is not None and drift.verdict == "fault"
            if shift.verdict == "cannot_tell" and not drifted:
                out.append(f"robot scan: {shift.explanation}")
            continue
        # the registrations are in run order (CNC, robot)
        regs = [v for v in reg.values() if isinstance(v, dict)]
        this = (regs[0] if run == "cnc" else regs[-1]) if regs else {}
        fitted = set(this.get("fitted") or [])
        booked = "springback" if run == "cnc" else "the robot term"
        pattern = (
            f"{run} scan: its normal deviation carries the pattern of a sideways shift of "
            f"{lo.size * 1e3:.3f} mm towards {lo.direction_deg:.0f}° (work x,y: "
            f"{lo.shift[0] * 1e3:+.3f}, {lo.shift[1] * 1e3:+.3f} mm; "
            f"{lo.explained:.0%} of the lap-wise variance), booked in {booked}"
        )
        if {"x", "y"} <= fitted:
            out.append(
                f"{pattern}; the registration fitted x and y, so this is not a shift it missed "
                "but an error that varies once around the part"
            )
        else:
            out.append(
                f"{pattern} — the scan's lateral registration is ambiguous (the "
                f"{this.get('method', '?')} registration fits {', '.join(sorted(fitted)) or '-'}"
                ", not x and y); re-register the scan laterally (reference marks) before "
                "trusting the terms"
            )
    summary["lateral_offset"] = fits
    return out


def _force_bias_warnings(tp: Toolpath, W_cnc: F64, W_rob: F64, valid: Any) -> list[str]:
    """Flag a force-sensor offset: on the same path, the lap means of the two runs' tip forces
    should agree (the lateral ones ~0 on a round part); a constant difference is a bias (untared
    sensor, tool weight). Only flagged: the logs are corrected at reading, if at all."""
    if not np.any(valid):
        return []
    laps, inv = np.unique(tp.lap[valid], return_inverse=True)
    if laps.size < 3:
        return []
    cnt = np.bincount(inv).astype(float)
    diff = W_rob[valid, :3] - W_cnc[valid, :3]
    lap_mean = np.stack([np.bincount(inv, weights=diff[:, j]) / cnt for j in range(3)], 1)
    med = np.median(lap_mean, axis=0)
    fz = float(np.median(np.abs(W_cnc[valid, 2])))
    limit = np.array([FORCE_BIAS_WARN, FORCE_BIAS_WARN, max(2 * FORCE_BIAS_WARN, 0.05 * fz)])
    if np.all(np.abs(med) <= limit):
        return []
    return [
        "robot force log: the robot run's tip force differs from the CNC run's by a constant "
        f"({med[0]:+.1f}, {med[1]:+.1f}, {med[2]:+.1f}) N (median of the lap means, work axes) "
        "— a sensor bias (no tare) or the tool's weight; the tool, holder and VJM terms use the "
        "biased force"
    ]


def _truth_vs_model(
    truth_dir: Path,
    per_point: pd.DataFrame,
    summary: dict[str, Any],
    d: Decomposition,
    model_stiffness: F64 | None = None,
) -> None:
    """Does the virtual cell's truth equal the study's model? Then the VJM check holds by
    construction and the report says so instead of quoting a zero difference. A flag in
    ``truth/truth.json`` (``model_equals_truth``, or a ``truth`` table of effects) wins — unless
    the study's joint stiffness ``model_stiffness`` (N·m/rad) is no longer the file's
    ``true_joint_stiffness`` (a study edited after the cell wrote it); else the truth's robot term
    is compared with the VJM at the measured forces (equal within 3 %)."""
    meta: dict[str, Any] = {}
    try:
        meta = json.loads((truth_dir / "truth.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        meta = {}
    flag = meta.get("model_equals_truth") if isinstance(meta, dict) else None
    how = "truth/truth.json"
    k_true = meta.get("true_joint_stiffness") if isinstance(meta, dict) else None
    if flag is True and model_stiffness is not None and isinstance(k_true, list):
        kt = np.asarray(k_true, dtype=float).ravel()
        km = np.asarray(model_stiffness, dtype=float).ravel()
        if kt.shape != km.shape or not np.allclose(km, kt, rtol=1e-6, atol=0.0):
            flag = False
            how = "truth/truth.json's true_joint_stiffness against the study's joint stiffness"
    if not isinstance(flag, bool):
        if "truth_robot_compliance_dn" not in per_point:
            return
        u = d.valid
        t = per_point["truth_robot_compliance_dn"].to_numpy()[u]
        v = per_point["vjm_dn"].to_numpy()[u]
        rms_t = float(np.sqrt(np.mean(t**2))) if t.size else 0.0
        flag = bool(rms_t > 0 and np.sqrt(np.mean((t - v) ** 2)) <= 0.03 * rms_t)
        how = "the truth's robot term against the VJM at the measured forces"
    summary.setdefault("truth", {})["model_equals_truth"] = flag
    summary["truth"]["model_equals_truth_from"] = how
    # what the report says about the study: a truth from a shipped scenario was tuned (the
    # paper's shares), and a springback coupling explains the robot panel's truth vs recovered
    table = meta.get("truth") if isinstance(meta, dict) else None
    if isinstance(table, dict):
        # file names only: the report carries no absolute path
        summary["truth"]["truth_source"] = " + ".join(
            part if part.startswith("scenario ") else Path(part).name
            for part in str(table.get("source") or "").split(" + ")
            if part
        )
        sb = table.get("springback")
        if isinstance(sb, dict) and sb.get("deflection_coupling"):
            summary["truth"]["springback_coupling"] = {
                "coupling": float(sb["deflection_coupling"]),
                "depth_mm": float(sb["coupling_depth"]) if "coupling_depth" in sb else None,
            }
    if flag and "vjm_check" in summary:
        summary["vjm_check"]["by_construction"] = True


def _mm_rows(rows: list[dict[str, float | str]]) -> list[dict[str, float | str]]:
    out = []
    for r in rows:
        out.append({k: (v * 1e3 if k.startswith(("mean_abs", "R_m")) else v) for k, v in r.items()})  # type: ignore[operator]
    return out


def _per_point(
    cell: Cell, tp: Toolpath, W_cnc: F64, W_rob: F64, dev_c: Any, dev_r: Any, d: Decomposition
) -> pd.DataFrame:
    cols: dict[str, Any] = {
        "index": np.arange(len(tp)),
        "lap": tp.lap,
        "time": tp.time,
        "angle_deg": np.degrees(tp.angle),
        "depth": tp.depth * 1e3,
        "wall_angle_deg": np.degrees(tp.wall_angle),
    }
    for j, ax in enumerate(_AX):
        cols[f"contact_{ax}"] = tp.contact[:, j] * 1e3
    for j, ax in enumerate(_AX):
        cols[f"normal_{ax}"] = tp.normal[:, j]
    for run, W in (("cnc", W_cnc), ("robot", W_rob)):
        for j, name in enumerate(_WRENCH):
            cols[f"{run}_{name}"] = W[:, j]
    for run, dev in (("cnc", dev_c), ("robot", dev_r)):
        for j, ax in enumerate(_AX):
            cols[f"{run}_d{ax}"] = dev.delta[:, j] * 1e3
        cols[f"{run}_dn"] = dev.dn * 1e3
        cols[f"{run}_n_points"] = dev.n_points
        cols[f"{run}_valid"] = dev.valid
    names = {f: f for f in FACTORS} | {"vjm": "vjm", "delta": "delta"}
    for key, col in names.items():
        v = d.vectors[key]
        for j, ax in enumerate(_AX):
            cols[f"{col}_d{ax}"] = v[:, j] * 1e3
        cols[f"{col}_dn"] = d.normal[key] * 1e3
    cols["thickness_predicted"] = sine_law_thickness(tp.wall_angle, cell.part.sheet_thickness) * 1e3
    cols["used"] = d.valid
    import pandas as pd

    return pd.DataFrame(cols)


def _contour_height(study: Study, tp: Toolpath, valid: NDArray[np.bool_]) -> float:
    """The report's contour height (m, work z): the study's ``[analysis] contour_z``, else the
    middle of the analysed wall — half way between its highest and lowest analysed contact (the
    rim band left out), or between the band and the part's depth when no point was analysed."""
    if study.analysis.contour_z is not None:
        return study.analysis.contour_z
    z = tp.contact[np.asarray(valid, bool), 2]
    if z.size:
        return float(z.max() + z.min()) / 2.0
    return -(study.analysis.rim_band + float(np.max(tp.depth))) / 2.0


def _summary(
    study: Study,
    cell: Cell,
    tp: Toolpath,
    d: Decomposition,
    k_c: F64,
    W: F64,
    valid: Any,
    k_tool: ComplianceResult,
    k_holder: ComplianceResult | None,
    q_source: str,
    scans: dict[str, ScanComparison],
) -> dict[str, Any]:
    st = compliance_stats(k_c[valid])
    stats = {
        f"k_{i + 1}{j + 1}": {
            "mean": float(st.mean[i, j]),
            "std": float(st.std[i, j]),
            "min": float(st.min[i, j]),
            "max": float(st.max[i, j]),
        }
        for i in range(6)
        for j in range(6)
    }
    contrib = deflection_contributions(k_c[valid], W[valid])
    table4 = {
        f"d{ax}": {w: float(contrib.mean_abs[i, j]) * 1e3 for j, w in enumerate(_WRENCH)}
        for i, ax in enumerate(_AX)
    }
    vjm_cmp = _vjm_vs_experiment(d, valid)
    warnings = []
    below_rim = tp.depth > study.analysis.rim_band
    for name, sc in scans.items():
        dev = sc.toolpath
        holes = 0 if dev is None else int(np.sum(~dev.valid & below_rim))
        if holes:
            warnings.append(
                f"{name} scan: {holes} toolpath points below the rim band fall in holes of the "
                "scan and are left out"
            )
    warnings.extend(_beyond_cut_warnings(scans, study.analysis.max_distance))
    return {
        "study": study.name,
        "description": study.description,
        "part": cell.part.to_dict(),
        "part_symmetry": cell.part.symmetry.order,  # the report: polar plot only when 0
        "robot": RobotInfo(
            model=cell.robot_name,
            preset=cell.robot_name,
            placement_T_base_work_m=cell.T_base_work.tolist(),
            joint_angles_from=q_source,
        ),
        "tool": ToolInfo(
            ball_diameter_mm=cell.tool.ball_diameter * 1e3,
            method=k_tool.method,
            lateral_compliance_m_per_N=k_tool.lateral,
            holder_lateral_compliance_m_per_N=None if k_holder is None else k_holder.lateral,
        ),
        "units": Units(
            length="mm", force="N", moment="N*m", angle="deg", time="s", compliance="SI"
        ),
        "n_points": len(tp),
        "n_points_used": int(np.sum(valid)),
        "rim_band_mm": study.analysis.rim_band * 1e3,
        "max_distance_mm": study.analysis.max_distance * 1e3,
        "beyond_max_distance": {
            name: {
                "n": int(sc.counts.get("wall_beyond_max_distance", 0)),
                "of": int(sc.counts.get("wall_total", 0)),
            }
            for name, sc in scans.items()
        },
        "contour_z": _contour_height(study, tp, valid) * 1e3,
        "compliance_stats": stats,
        "force_contributions": table4,
        "vjm_vs_experiment": vjm_cmp["normal"],
        "vjm_vs_experiment_per_axis": vjm_cmp["per_axis"],
        "registration": {name: sc.registration.to_dict() for name, sc in scans.items()},
        "warnings": warnings,
    }


def _vjm_vs_experiment(d: Decomposition, valid: Any) -> dict[str, dict[str, float]]:
    """The paper's Δ_i = mean|δc,exp,i| − mean|δc,VJM,i| [mm] and its resultant, both books.

    (The paper's cone: Δ = (0.311, 0.5, −0.840), resultant 1.02 mm.) Per-axis vectors carry the
    VJM's tangential part, which no scan observes, so only the ``normal`` book can be ~0 when the
    model is right.
    """
    out = {}
    for book in ("per_axis", "normal"):
        if book == "per_axis":
            exp, vjm = d.vectors["robot_compliance"][valid], d.vectors["vjm"][valid]
        else:
            n = d.n[valid]
            exp = d.normal["robot_compliance"][valid, None] * n
            vjm = d.normal["vjm"][valid, None] * n
        delta = (np.abs(exp).mean(axis=0) - np.abs(vjm).mean(axis=0)) * 1e3
        out[book] = {
            "x": float(delta[0]),
            "y": float(delta[1]),
            "z": float(delta[2]),
            "resultant": float(np.linalg.norm(delta)),
        }
    return out


#: Columns of a virtual cell's ``truth/per_point.parquet`` that ``analyze`` reads (mm).
TRUTH_COLUMNS = (
    *(f"{f}_dn" for f in FACTORS),
    "dn_cnc",
    "dn_robot",
    *(f"{f}_d{ax}" for f in ("tool_cnc", *FACTORS) for ax in _AX),
)


def run_truth_dir(study: Study) -> Path:
    """A virtual cell's ground truth of the study's robot run: ``truth/runs/<run>/`` for a run
    it re-formed with a commanded path (``roboisf virtual-cell --from``), else ``truth/``."""
    own = study.root / "truth" / "runs" / study.robot_run.name
    return own if own.is_dir() else study.root / "truth"


def _in_study(path: str | Path, root: Path) -> str:
    """A file's name as ``summary.json`` records it: relative to the study folder (POSIX) when it
    lies inside it — so the record stays true when the folder is moved or was built in a staging
    folder, as ``roboisf demo`` does — else the absolute path; an empty name stays empty."""
    if not str(path):
        return ""
    p = Path(path).resolve()
    try:
        return p.relative_to(root.resolve()).as_posix()
    except ValueError:
        return str(p)


def _read_truth(path: Path) -> pa.Table:
    """A virtual cell's ground truth, validated: readable Parquet, the columns ``analyze`` uses
    (:data:`TRUTH_COLUMNS`), finite numbers. Read before the analysis so that a corrupt file
    fails in a second, not after the scans; an Arrow table (its frame is made when attached:
    pandas is not loaded under the scans' peak)."""
    import pyarrow.parquet as pq

    try:
        # ParquetFile.read: pq.read_table imports pandas for the file's pandas metadata
        df = pq.ParquetFile(path).read(use_pandas_metadata=False)
    except Exception as e:  # pyarrow raises many types for a damaged file
        raise InputError(
            f"not a readable Parquet file ({type(e).__name__}: {e}); delete the truth/ folder "
            "to analyze without ground truth, or regenerate the study (roboisf virtual-cell)",
            file=path,
        ) from None
    missing = [c for c in TRUTH_COLUMNS if c not in df.column_names]
    if missing:
        raise InputError(
            f"missing column(s) {', '.join(missing)} (not a virtual-cell truth file?)",
            file=path,
            field=missing[0],
        )
    for c in TRUTH_COLUMNS:
        v = float_column(df.column(c))  # without pandas (Arrow's to_numpy imports it)
        if v is None:  # another type, or nulls (NaN below)
            try:
                v = np.asarray(df.column(c).to_numpy(), dtype=float)
            except (TypeError, ValueError, ArithmeticError):
                raise InputError("expected numbers (mm)", file=path, field=c) from None
        if not np.all(np.isfinite(v)):
            raise InputError(
                f"NaN or inf in row {int(np.argmax(~np.isfinite(v)))}", file=path, field=c
            )
    return df


def _attach_truth(
    path: Path,
    per_point: pd.DataFrame,
    summary: dict[str, Any],
    d: Decomposition,
    table: pa.Table | None = None,
) -> None:
    """Virtual-cell studies ship their ground truth: put it beside the recovered values.

    Two references. ``shares_normal`` — the physical truth projected on the normal (what a scan
    can observe), to compare with the normal book. ``shares_per_axis`` — the paper's recipe
    applied to the *noise-free* truth, to compare with the per-axis book: that book's robot
    term lacks the VJM's tangential part on any data, so only the recipe's own truth isolates
    the estimation error. ``R_m_physical`` gives the full-vector truth for the record.
    """
    truth = (_read_truth(path) if table is None else table).to_pandas()
    if len(truth) != len(per_point):
        summary["warnings"].append(f"truth file {path} does not match the toolpath; ignored")
        return
    used = d.valid

    def vec(name: str) -> F64:
        return truth[[f"{name}_d{ax}" for ax in _AX]].to_numpy() * 1e-3

    rms: dict[str, float] = {}
    for f in FACTORS:
        per_point[f"truth_{f}_dn"] = truth[f"{f}_dn"].to_numpy()
        err = per_point[f"{f}_dn"].to_numpy()[used] - per_point[f"truth_{f}_dn"].to_numpy()[used]
        rms[f] = float(np.sqrt(np.mean(err**2)))
    ideal = decompose(
        d.n,
        truth["dn_cnc"].to_numpy() * 1e-3,
        truth["dn_robot"].to_numpy() * 1e-3,
        vec("tool_cnc"),
        vec("tool"),
        vec("tool_holder"),
        vec("robot_compliance"),
        used,
        vec("command_offset") if "command_offset_dx" in truth else None,
    )
    shares = {}
    for book, projected in (("per_axis", False), ("normal", True)):
        rows = contribution_rows(ideal, projected=projected)
        shares[book] = {str(r["factor"]): float(r["share_percent"]) for r in rows[:-1]}
    physical = {f: resultant_mean_deviation(vec(f)[used]) * 1e3 for f in FACTORS}
    summary["truth"] = {
        "rms_error_dn_mm": rms,
        "shares_per_axis": shares["per_axis"],
        "shares_normal": shares["normal"],
        "R_m_physical_mm": physical,
        "source": _in_study(path, path.parent.parent),
    }


#: The stiffness file ``analyze`` writes into its results (``[stiffness] K``, N·m/rad).
IDENTIFIED_STIFFNESS = "identified_stiffness.toml"


def write_results(
    result: AnalysisResult,
    out_dir: str | Path,
    *,
    png: bool = False,
    progress: Progress | None = None,
) -> Path:
    """Write ``report.html``, ``contributions.csv``, ``contributions_normal.csv``,
    ``per_point.parquet``, ``summary.json``, ``identified_stiffness.toml`` (when the robot's
    compliance was identified; its name, relative to ``out_dir``, in
    ``summary.identified_stiffness``) and
    ``figures/*.png`` into ``out_dir`` (replaced only when everything is written)."""
    from roboisf.report import write_report

    out_dir = Path(out_dir)
    study_root = result.study.root.resolve()
    if out_dir.resolve() == study_root or study_root in out_dir.resolve().parents:
        raise InputError(
            "the output folder must not be the study folder or inside it (never "
            "overwrite an input)",
            file=out_dir,
        )
    ident = result.identification
    with staged_directory(out_dir, "analyze") as stage:
        if ident is not None:
            write_stiffness_toml(
                ident,
                stage / IDENTIFIED_STIFFNESS,
                f"roboisf analyze {result.study.name} ({result.cell.robot_name}): "
                f"identified from the forming run, mode {ident.mode}",
                robot=result.cell.robot.name,
            )
        with task(progress, "tables"):
            with atomic_path(stage / "per_point.parquet") as tmp:
                # no dictionary pages: 61 float columns of distinct values (3.5× faster, smaller)
                result.per_point.to_parquet(tmp, index=False, use_dictionary=False)
            for name, df in (
                ("contributions.csv", result.contributions),
                ("contributions_normal.csv", result.contributions_normal),
            ):
                with atomic_write(stage / name) as fh:  # mm and percent (docs/analyze.md)
                    df.to_csv(fh, index=False, float_format="%.6g")
            with atomic_write(stage / "summary.json") as fh:
                fh.write(dumps(result.summary))
        write_report(  # its own "report" task (one per figure drawn)
            result.per_point,
            result.contributions,
            result.contributions_normal,
            result.summary.to_dict(),
            stage,
            png=png,
            progress=progress,
        )
    return out_dir


#: fraction of a scan's wall points beyond ``[analysis] max_distance`` above which the analysis
#: warns (the virtual cell's scans carry ~1 % stray points; a real scan's fixture and clamps
#: mostly lie off the wall's footprint)
BEYOND_CUT_WARN = 0.02


def _beyond_cut_warnings(scans: dict[str, ScanComparison], max_distance: float) -> list[str]:
    """One warning per scan whose wall loses more than :data:`BEYOND_CUT_WARN` of its points to
    the ``max_distance`` [m] cut (a part that deviates more than the cut: its largest errors
    would leave the statistics unseen)."""
    out = []
    for name, sc in scans.items():
        n = int(sc.counts.get("wall_beyond_max_distance", 0))
        total = int(sc.counts.get("wall_total", 0))
        if total and n > BEYOND_CUT_WARN * total:
            out.append(
                f"{name} scan: {n} of {total} wall points ({n / total:.1%}) lie more than "
                f"{max_distance * 1e3:g} mm from the nominal and are left out; if the part "
                "deviates that much, raise [analysis] max_distance in study.toml (mm)"
            )
    return out
