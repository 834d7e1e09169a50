"""Logs as real equipment writes them: a drifting clock, an offset start, pauses.

The virtual cell's clean logs run on the toolpath's nominal clock (``path_length / feed``). A
real controller's log does not: its clock counts at its own rate, recording starts some seconds
before the program, the operator stops the robot for half a minute, and a force logger on
another computer has a clock of its own. :class:`Equipment` models that, and
:func:`apply_equipment` rewrites a virtual study's logs with it (``roboisf virtual-cell
--clock-scale 1.02 --clock-offset 7 --pause 300,30``), so that ``analyze`` must recover the
timing by alignment (``[runs.X] sync``, :mod:`roboisf.sync`).

Time model (real time ``r`` [s], 0 when the controller's log starts):

* controller log clock ``τ = clock_scale · r``; the program starts at ``τ = offset``, i.e.
  ``r_s = offset / clock_scale``;
* nominal toolpath time ``t(r)``: ``r − r_s`` minus the pauses already taken; during a pause
  ``(t_p, d)`` the tool stands at ``t_p`` (nominal s) for ``d`` real seconds, still pressing;
* before the start the tool stands at the first point, out of contact (zero force); after the
  end, at the last point out of contact, for ``lead_out`` s;
* the force logger: on the controller's clock (``force_clock = "joint"``, one controller), or
  its own, ``τ_f = force_offset + force_clock_scale · r`` (``"own"``: a separate DAQ).

Sensor bias/gain and tool weight are the truth file's business (not modelled here).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
import tomli_w
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.frames import vertical_tool
from roboisf.io.atomic import atomic_write
from roboisf.logs.forcelog import ForceLog
from roboisf.study.sensors import tip_to_sensor
from roboisf.study.spec import ForceSensorSpec
from roboisf.toolpath import Toolpath

if TYPE_CHECKING:
    from roboisf.virtual.cell import CellTruth, VirtualCell

__all__ = ["Equipment", "apply_equipment", "parse_pauses"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class Equipment:
    """How the cell's loggers keep time (see the module docstring). Times in s.

    clock_scale : controller log seconds per real second (1.02: runs 2 % fast), > 0
    offset : controller log time at which the program starts, ≥ 0
    pauses : ((nominal toolpath time, duration), …) — stops, tool pressing, in nominal order
    force_clock : ``"joint"`` (force log on the controller's clock) or ``"own"``
    force_offset : own clock: force-log time at the controller log's start (real time 0)
    force_clock_scale : own clock: force-log seconds per real second
    lead_out : s logged after the program ends
    cnc_force_profile, robot_force_profile : file layout of the force logs, a registered
        force-log format with a writer (``roboisf``, ``ati``, ``kistler``, …;
        :mod:`roboisf.virtual.logformats`)
    joint_profile : file layout of the joint log (``roboisf``, ``abb``, ``kuka``, …)
    """

    clock_scale: float = 1.0
    offset: float = 0.0
    pauses: tuple[tuple[float, float], ...] = ()
    force_clock: Literal["joint", "own"] = "joint"
    force_offset: float = 0.0
    force_clock_scale: float = 1.0
    lead_out: float = 2.0
    cnc_force_profile: str = "roboisf"
    robot_force_profile: str = "roboisf"
    joint_profile: str = "roboisf"

    def __post_init__(self) -> None:
        for name in ("clock_scale", "force_clock_scale"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0.5 <= v <= 2.0):
                raise InputError(f"must be in [0.5, 2] (a clock rate), got {v}", field=name)
        for name in ("offset", "lead_out"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f"must be ≥ 0 s, got {v}", field=name)
        if not math.isfinite(self.force_offset):
            raise InputError("must be finite", field="force_offset")
        if self.force_clock not in ("joint", "own"):
            raise InputError(
                f"expected 'joint' or 'own', got {self.force_clock!r}", field="force_clock"
            )
        from roboisf.virtual.logformats import force_profiles, joint_profiles

        for name, options in (
            ("cnc_force_profile", force_profiles()),
            ("robot_force_profile", force_profiles()),
            ("joint_profile", joint_profiles()),
        ):
            if getattr(self, name) not in options:
                raise InputError(
                    f"expected one of {', '.join(options)}, got {getattr(self, name)!r}",
                    field=name,
                )
        last = -math.inf
        for t, d in self.pauses:
            if not (math.isfinite(t) and t >= 0 and math.isfinite(d) and d > 0):
                raise InputError(
                    f"a pause is (nominal time ≥ 0 s, duration > 0 s), got ({t}, {d})",
                    field="pauses",
                )
            if t <= last:
                raise InputError("pauses must be in increasing time order", field="pauses")
            last = t

    @property
    def clock_is_nominal(self) -> bool:
        """True when the logs run on the toolpath's nominal clock (nothing to align)."""
        return (
            self.clock_scale == 1.0
            and self.offset == 0.0
            and not self.pauses
            and self.force_clock == "joint"
        )

    @property
    def is_clean(self) -> bool:
        """True when the logs would be the virtual cell's own (nominal clock, roboisf CSV)."""
        profiles = (self.cnc_force_profile, self.robot_force_profile, self.joint_profile)
        return self.clock_is_nominal and all(p == "roboisf" for p in profiles)

    @property
    def start(self) -> float:
        """Real time [s] at which the program starts."""
        return self.offset / self.clock_scale

    def nominal_time(self, r: ArrayLike, duration: float) -> F64:
        """Nominal toolpath time at real times ``r`` (clamped to ``[0, duration]``)."""
        e = np.asarray(r, dtype=float) - self.start
        out = e.copy()
        shift = 0.0
        for t_p, d in self.pauses:
            # real elapsed e maps to t_p during [t_p + shift, t_p + shift + d]
            a = t_p + shift
            out = np.where(e >= a + d, out - d, np.where(e >= a, t_p, out))
            shift += d
        return np.clip(out, 0.0, duration)

    def real_end(self, duration: float) -> float:
        """Real time [s] at which the program ends."""
        return self.start + duration + sum(d for t, d in self.pauses if t < duration)

    def contact(self, r: ArrayLike, duration: float) -> NDArray[np.bool_]:
        """True while the program runs (the tool presses the sheet)."""
        rr = np.asarray(r, dtype=float)
        return (rr >= self.start) & (rr <= self.real_end(duration))

    def controller_real(self, tau: ArrayLike) -> F64:
        """Real time of controller-log times."""
        return np.asarray(tau, dtype=float) / self.clock_scale

    def force_real(self, tau_f: ArrayLike) -> F64:
        """Real time of force-log times."""
        tf = np.asarray(tau_f, dtype=float)
        if self.force_clock == "joint":
            return tf / self.clock_scale
        return (tf - self.force_offset) / self.force_clock_scale

    def force_log_time(self, r: ArrayLike) -> F64:
        """Force-log time of real times."""
        rr = np.asarray(r, dtype=float)
        if self.force_clock == "joint":
            return rr * self.clock_scale
        return self.force_offset + self.force_clock_scale * rr


def parse_pauses(items: list[str] | None) -> tuple[tuple[float, float], ...]:
    """``["300,30", …]`` (nominal time s, duration s) → sorted pauses (CLI ``--pause``)."""
    out = []
    for it in items or []:
        parts = it.replace(";", ",").split(",")
        try:
            t, d = (float(p) for p in parts)
        except ValueError:
            raise InputError(
                f"expected TIME,DURATION in s (e.g. 300,30), got {it!r}", field="--pause"
            ) from None
        out.append((t, d))
    return tuple(sorted(out))


def _samples(eq: Equipment, duration: float, rate: float, *, force: bool) -> tuple[F64, F64]:
    """(log times, real times) of a logger at ``rate`` [Hz] from its start to the lead-out."""
    r_end = eq.real_end(duration) + eq.lead_out
    if force:
        t0 = max(0.0, float(eq.force_log_time(0.0)))
        t1 = float(eq.force_log_time(r_end))
    else:
        t0, t1 = 0.0, r_end * eq.clock_scale
    tau = t0 + np.arange(math.floor((t1 - t0) * rate) + 1) / rate
    r = eq.force_real(tau) if force else eq.controller_real(tau)
    return tau, r


def _interp(t: F64, tp: Toolpath, values: F64) -> F64:
    return np.column_stack([np.interp(t, tp.time, values[:, j]) for j in range(values.shape[1])])


def equipment_force_log(
    eq: Equipment,
    tp: Toolpath,
    W_tip: F64,
    sensor: ForceSensorSpec,
    rate: float,
    noise: float,
    tool_rotation: float,
    rng: np.random.Generator,
    reading: Callable[[F64, F64], F64] | None = None,
    resolution: tuple[float, float] = (0.0, 0.0),
) -> ForceLog:
    """The sensor's log [N, N·m] on the equipment's clock: the tip wrench (N, 6) of the
    toolpath's points, zero out of contact, in the sensor frame, with white noise ``noise`` [N].
    ``reading(W_sensor (M, 6), tip (M, 3) m) -> (M, 6)``: what the transducer makes of the load
    (a truth's bias, gain, crosstalk and tool weight, :func:`roboisf.virtual.cell.sensor_reading`);
    applied after the noise, which passes through the same calibration; the result is rounded
    to the sensor's ``resolution`` (force N, moment N·m;
    :func:`~roboisf.virtual.cell.quantize_wrench`)."""
    duration = float(tp.time[-1])
    tau, r = _samples(eq, duration, rate, force=True)
    t = eq.nominal_time(r, duration)
    W = _interp(t, tp, W_tip)
    W *= eq.contact(r, duration)[:, None]
    tip = _interp(t, tp, tp.tip)
    W_s = tip_to_sensor(W, sensor, tip, vertical_tool(tool_rotation))
    W_s[:, :3] += rng.normal(scale=noise, size=(tau.size, 3))
    W_s[:, 3:] += rng.normal(scale=noise * 5e-3, size=(tau.size, 3))
    if reading is not None:
        W_s = reading(W_s, tip)
    from roboisf.virtual.cell import quantize_wrench

    return ForceLog(tau, quantize_wrench(W_s, resolution), "sensor")


def equipment_joint_log(eq: Equipment, tp: Toolpath, q: F64, rate: float) -> tuple[F64, F64]:
    """(controller times (M,) s, joint angles (M, 6) rad) at the points' IK ``q`` (N, 6)."""
    duration = float(tp.time[-1])
    tau, r = _samples(eq, duration, rate, force=False)
    return tau, _interp(eq.nominal_time(r, duration), tp, q)


def apply_equipment(
    eq: Equipment,
    cell: VirtualCell,
    truth: CellTruth,
    folder: Path,
    cnc: ForceSensorSpec,
    rob: ForceSensorSpec,
) -> None:
    """Rewrite a virtual study's logs in ``folder`` on the equipment's clock, in its file
    layouts (:mod:`roboisf.virtual.logformats`), and set the study's alignment keys: the robot
    run by ``sync = "position"`` (its joint log), its force log on the controller's clock or its
    own (``forces.clock``); the CNC run, which has no joint log, by ``sync = "force"`` unless the
    clock is nominal — or its path cannot be timed by the force direction
    (:func:`roboisf.sync.force.expected_azimuth`: a path that turns back), when its log keeps
    the nominal clock (``sync = "time"``). Both runs share the clock model (same drift, offset,
    pauses). The file names stay those of the clean study; a layout other than roboisf's is
    read by the readers' automatic format detection (no ``format`` key is written); the ABB
    joint layout, whose header declares no units, gets ``joints = {file, units}``."""
    if eq.is_clean:
        return
    from roboisf.logs.jointlog import unstated_units
    from roboisf.sync.force import expected_azimuth
    from roboisf.virtual.logformats import write_force_profile, write_joint_profile

    rng = np.random.default_rng(cell.seed + 7919)
    tp = truth.toolpath
    rot = cell.tool_rotation
    try:  # the CNC run can be aligned only by its force signature
        expected_azimuth(tp)
        cnc_eq = eq
    except InputError:  # a path force alignment cannot time (turns back, ...): nominal clock
        cnc_eq = Equipment(lead_out=eq.lead_out)
    from roboisf.virtual.cell import sensor_reading, tool_weight_at_sensor

    robot_reading = None
    t_spec = cell.truth
    if t_spec is not None and not t_spec.sensor_ideal:  # the truth's flange sensor (robot run)
        R = vertical_tool(rot)

        def robot_reading(W_s: F64, tip: F64) -> F64:
            return sensor_reading(t_spec, W_s, tool_weight_at_sensor(cell, t_spec, rob, tip, R))

    for W, sensor, name, profile, e, reading in (
        (truth.wrench_cnc, cnc, "cnc", eq.cnc_force_profile, cnc_eq, None),
        (truth.wrench_robot, rob, "robot", eq.robot_force_profile, eq, robot_reading),
    ):
        log = equipment_force_log(
            e,
            tp,
            W,
            sensor,
            cell.force_rate,
            cell.force.noise,
            rot,
            rng,
            reading,
            cell.force_resolution,
        )
        write_force_profile(log, folder / f"{name}_forces.csv", profile)
    tau, q = equipment_joint_log(eq, tp, truth.q, cell.joint_rate)
    write_joint_profile(folder / "robot_joints.csv", tau, q, eq.joint_profile)
    study = folder / "study.toml"
    data = tomllib.loads(study.read_text(encoding="utf-8"))
    units = unstated_units(eq.joint_profile)
    if units:  # a layout whose header declares no units (ABB): the study says them, as its user
        data["runs"]["robot"]["joints"] = {"file": "robot_joints.csv", "units": units}
    if eq.clock_is_nominal:
        with atomic_write(study, "wb") as fh:
            fh.write(tomli_w.dumps(data).encode())
        return
    data["runs"]["robot"]["sync"] = "position"
    data["runs"]["robot"]["forces"]["clock"] = eq.force_clock
    data["runs"]["cnc"]["sync"] = "time" if cnc_eq.clock_is_nominal else "force"
    with atomic_write(study, "wb") as fh:
        fh.write(tomli_w.dumps(data).encode())
