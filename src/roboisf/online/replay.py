"""Replay a study's robot force and joint logs through the online core.

:class:`ReplaySensor` stands in for a Net F/T in :class:`roboisf.online.loop.Loop`: it hands
out the samples of the study's robot force log (sensor frame, as logged) whose time has come on
the loop's clock. :func:`replay_study` runs the core through both logs with no network at all:
every joint-log sample is a controller cycle fed with the force samples logged up to it, so a
user sees, before forming, what the loop would have sent on a part already formed.

The study's robot run must have a flange-mounted force sensor (``mount = "flange"``, its pose
``T_tip_sensor``); the logs are taken as tared and weight-compensated (what ``analyze`` reads).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from roboisf.cell import Cell, cell_from_study
from roboisf.errors import InputError
from roboisf.logs.forcelog import read_force_log
from roboisf.logs.jointlog import read_joint_log
from roboisf.online.core import (
    Limits,
    OnlineCompensator,
    Plausibility,
    SensorSetup,
    check_cutoff,
)
from roboisf.study import load_study

__all__ = [
    "ReplaySensor",
    "StudyReplay",
    "expected_peak_force",
    "load_replay",
    "replay_study",
    "sample_rate",
]

F64 = NDArray[np.float64]


class ReplaySensor:
    """Samples ``wrench`` (N, 6) [N; N·m] at ``time`` (N,) s, released as the clock passes them
    (``speed`` × real time; the first call starts the clock at the log's first sample)."""

    def __init__(self, time: F64, wrench: F64, speed: float = 1.0) -> None:
        if not speed > 0:
            raise InputError(f"must be > 0, got {speed}", field="speed")
        self.time = np.asarray(time, dtype=float)
        self.wrench = np.asarray(wrench, dtype=float)
        self.speed = speed
        self._i = 0
        self._t0: float | None = None

    def samples_until(self, t: float) -> tuple[F64, F64]:
        """The samples logged up to loop time ``t`` [s], as views (times on the loop's clock)."""
        if self._t0 is None:
            self._t0 = t - self.time[0] / self.speed
        lt = (t - self._t0) * self.speed
        j = int(np.searchsorted(self.time, lt, side="right"))
        i, self._i = self._i, max(self._i, j)
        return self._t0 + self.time[i:j] / self.speed, self.wrench[i:j]


@dataclass(frozen=True, eq=False)
class StudyReplay:
    """A study's cell, flange sensor and robot logs (SI)."""

    cell: Cell
    sensor: SensorSetup
    force_time: F64
    force: F64
    joint_time: F64
    q: F64


def sample_rate(time: F64) -> float:
    """The rate [Hz] of samples at ``time`` (N,) s: one over their median spacing (NaN for
    fewer than two samples or no spacing)."""
    dt = np.diff(np.asarray(time, dtype=float))
    dt = dt[np.isfinite(dt) & (dt > 0)]
    return 1.0 / float(np.median(dt)) if len(dt) else math.nan


def load_replay(study_dir: str | Path, *, cutoff: float = 20.0) -> StudyReplay:
    """Read ``study_dir``'s cell, robot force log and joint log (errors name the file).

    A ``cutoff`` [Hz] at or above half the force log's rate filters nothing and is refused
    (:func:`~roboisf.online.core.check_cutoff`, field ``cutoff``)."""
    study = load_study(study_dir)
    cell = cell_from_study(study)
    run = study.robot_run
    spec = run.forces
    if spec.mount != "flange":
        raise InputError(
            "online replay needs the robot run's force sensor on the flange (mount = 'flange')",
            file=study.root / "study.toml",
            field=f"runs.{run.name}.forces.mount",
        )
    if run.joints is None:
        raise InputError(
            "online replay needs the robot run's joint log",
            file=study.root / "study.toml",
            field=f"runs.{run.name}.joints",
        )
    fl = read_force_log(spec.file)
    rate = sample_rate(fl.time)
    if math.isfinite(rate):
        check_cutoff(cutoff, rate, f"the force log {Path(spec.file).name}, sampled at")
    jl = read_joint_log(run.joints)
    sensor = SensorSetup(cell.T_flange_tip @ spec.pose, load_on=spec.load_on, cutoff=cutoff)
    return StudyReplay(cell, sensor, fl.time + spec.time_offset, fl.wrench, jl.time, jl.q)


def expected_peak_force(force: F64) -> float:
    """The expected peak forming force [N] of a force log ``force`` (N, 6) [N; N·m]: the
    99.9th percentile of ‖f‖ (a single spike in the log does not set it); NaN when empty."""
    f = np.asarray(force, dtype=float)
    if f.ndim != 2 or f.shape[1] < 3 or len(f) == 0:
        return math.nan
    n = np.linalg.norm(f[:, :3], axis=1)
    n = n[np.isfinite(n)]
    return float(np.percentile(n, 99.9)) if len(n) else math.nan


def replay_study(
    rep: StudyReplay, limits: Limits | None = None, plausibility: Plausibility | None = None
) -> tuple[OnlineCompensator, F64]:
    """Run the core through the logs: one cycle per joint sample, with the live loop's
    ``limits`` and ``plausibility`` bounds (what it would have held). Returns the compensator
    and a (M, 10) array per cycle: time s, correction (3,) m (work axes), tip wrench force (3,)
    N (base axes), status, ‖δ‖ m, compute s."""
    import time as _time

    lim = limits or Limits()
    oc = OnlineCompensator.from_cell(rep.cell, rep.sensor, lim, plausibility)
    oc.warm_up()
    out = np.zeros((len(rep.joint_time), 10))
    j = 0
    ft, fw = rep.force_time, rep.force
    for k, (t, q) in enumerate(zip(rep.joint_time, rep.q, strict=True)):
        c0 = _time.perf_counter()
        oc.set_joints(q)
        while j < len(ft) and ft[j] <= t:
            oc.sample(float(ft[j]), fw[j])
            j += 1
        c = oc.cycle(float(t), q)
        out[k, 0] = t
        out[k, 1:4] = c
        out[k, 4:7] = oc.tip_wrench[:3]
        out[k, 7] = oc.status
        out[k, 8] = np.linalg.norm(oc.deflection[:3])
        out[k, 9] = _time.perf_counter() - c0
    return oc, out
