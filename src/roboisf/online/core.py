"""The streaming core of online compensation: force samples in, a path correction out.

Per force sample (:meth:`OnlineCompensator.sample`) the sensor's wrench loses its tare and the
tool's weight and is low-pass filtered; per controller cycle (:meth:`OnlineCompensator.cycle`)
the filtered wrench is brought to the tool tip, the compliance of the robot at the *current*
joint angles (VJM, :class:`~roboisf.robot.RobotModel` with its joint stiffness) plus tool and
holder (:func:`roboisf.cell.tip_compliances`) gives the tip deflection ``δ``, and the correction
for the next cycle is the pre-deflection ``c = −δ`` (translation, work axes) — the same model as
offline ``roboisf compensate`` (:mod:`roboisf.compensate.compliance`), evaluated as the robot
moves. The correction then passes, in this order:

1. **dead band** — ``‖c‖ < deadband`` sends zero (no correction from sensor noise in the air);
2. **size limit** — ``‖c‖ ≤ max_correction`` (scaled down along its direction);
3. **rate limit** — ``‖c_k − c_{k−1}‖ ≤ max_rate · dt``, ``dt`` the time since the last cycle
   (the controller's messages' arrival times; at most two cycles): a burst of messages moves
   the correction by no more than the time it spans allows;
4. **watchdog** — no sample for longer than ``watchdog`` s: the last correction is held; after
   twice that, ramped to zero at ``ramp_rate`` (mm/s, in time as well);
5. **plausibility** (:class:`Plausibility`) — a force sample too large, too far from the
   filtered force for the time since the last sample, or with too large a moment about the tool
   tip never reaches the filter; the correction is held until ``watchdog`` s after the last
   such sample (and ramps to zero, as for a silent sensor, when they go on);
6. **stop** (:meth:`OnlineCompensator.begin_stop`) — the correction ramps to zero at
   ``ramp_rate`` whatever the force. A cycle therefore never sends a correction outside
   ``max_correction``, nor one that moved by more than ``max_rate · dt``.

Everything is preallocated at construction; :meth:`sample` and :meth:`cycle` run a compiled
kernel (:mod:`roboisf.online.kernel`) on those buffers and allocate nothing.

Units: SI (m, N, N·m, rad, s). Frames: ``T_flange_sensor`` places the F/T sensor on the flange;
the sensor reports the load on the tool, in its axes, about its origin (``load_on="tool"``; use
``"workpiece"`` for a sensor whose sign convention is the opposite).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.cell import Cell, tip_compliances
from roboisf.errors import InputError
from roboisf.frames import check_rigid, invert
from roboisf.frames.wrench import wrench_transform_matrix
from roboisf.online import kernel as kn
from roboisf.robot import RobotModel
from roboisf.robot.kinematics import rotate_6x6

__all__ = [
    "Limits",
    "OnlineCompensator",
    "Plausibility",
    "SensorSetup",
    "check_cutoff",
    "episodes",
    "status_text",
]

F64 = NDArray[np.float64]

#: standard gravity in the robot base (z up) [m/s²]
GRAVITY_BASE = (0.0, 0.0, -9.80665)


def _pos(v: float, name: str, *, zero: bool = False) -> float:
    v = float(v)
    if not math.isfinite(v) or v < 0 or (v == 0 and not zero):
        raise InputError(f"must be {'≥' if zero else '>'} 0, got {v}", field=name)
    return v


def check_cutoff(cutoff: float, rate: float, source: str) -> None:
    """Refuse a low-pass corner ``cutoff`` [Hz] at or above half the force samples' ``rate``
    [Hz] (``source`` says whose rate, for the message; the error's field is ``cutoff``).

    The filter's step ``α = 1 − exp(−2π f_c Δt)`` is ≥ 1 − e^−π ≈ 0.96 there: each sample
    passes almost whole and nothing is filtered (a sampled signal holds no frequency above half
    its rate for a corner there to cut). ``--cutoff 1e6`` ran a cone with the raw sensor noise
    in every correction.
    """
    if cutoff >= rate / 2:
        raise InputError(
            f"{cutoff:g} Hz is at or above half the rate of the force samples ({source} "
            f"{rate:g} Hz): there the low-pass passes each sample almost whole "
            f"(α ≥ {1.0 - math.exp(-math.pi):.2f}) and filters nothing; give a corner below "
            f"{rate / 2:g} Hz (the default is 20 Hz)",
            field="cutoff",
        )


@dataclass(frozen=True)
class Limits:
    """What the loop may send (SI).

    Attributes
    ----------
    deadband : float, m — corrections shorter than this are sent as zero (default 5 µm)
    max_correction : float, m — the longest correction ever sent (default 2 mm)
    max_rate : float, m/s — the fastest a correction may change (default 20 mm/s)
    cycle : float, s — the controller's cycle (EGM 4 ms, RSI 4 or 12 ms)
    watchdog : float, s — no sample for this long: hold; twice this long: ramp to zero
    ramp_rate : float, m/s — the ramp-down rate of the watchdog (default 5 mm/s)
    """

    deadband: float = 5e-6
    max_correction: float = 2e-3
    max_rate: float = 20e-3
    cycle: float = 4e-3
    watchdog: float = 0.05
    ramp_rate: float = 5e-3

    def __post_init__(self) -> None:
        _pos(self.deadband, "deadband", zero=True)
        for name in ("max_correction", "max_rate", "cycle", "watchdog", "ramp_rate"):
            _pos(getattr(self, name), name)

    def array(self) -> F64:
        return np.array(
            [
                self.deadband,
                self.max_correction,
                self.max_rate,
                self.cycle,
                self.watchdog,
                self.ramp_rate,
            ],
            dtype=float,  # float64 whatever the arguments' types: the C kernel takes no other
        )


@dataclass(frozen=True)
class Plausibility:
    """Bounds on a force sample (tare and tool weight removed; SI). ``inf`` switches one off.

    A sample is implausible — dropped before the filter, the correction held — when

    * ``‖f‖ > max_force`` [N] (magnitude);
    * ``‖f − f_filtered‖ > force_band + max_force_rate · Δt`` [N, N/s] (rate: the jump from the
      filtered force, ``Δt`` the time since the last sample taken — so a real change of the
      force, slower than the rate bound, is taken once it persists);
    * ``‖m_tip‖ > max_tip_moment`` [N·m] (the moment about the tool tip: a ball-end tool takes
      the sheet's load as a force at its tip; a large moment there is a load elsewhere).
    """

    max_force: float = math.inf
    force_band: float = math.inf
    max_force_rate: float = math.inf
    max_tip_moment: float = math.inf

    def __post_init__(self) -> None:
        for name in ("max_force", "force_band", "max_force_rate", "max_tip_moment"):
            v = float(getattr(self, name))
            if math.isnan(v) or v <= 0:
                raise InputError(f"must be > 0 (inf: no bound), got {v}", field=name)

    @classmethod
    def from_expected(cls, peak_force: float, tool_length: float = 0.02) -> Plausibility:
        """Bounds from the expected peak forming force [N]: magnitude 2×, band ½×, the whole
        force in 50 ms as the rate, and the peak acting ``tool_length`` m off the tip as the
        tip moment."""
        f = float(peak_force)
        if not math.isfinite(f) or f <= 0:
            raise InputError(f"must be a finite force > 0 N, got {f}", field="expected force")
        return cls(2.0 * f, 0.5 * f, f / 0.05, f * tool_length)

    def array(self) -> F64:
        return np.array(
            [self.max_force, self.force_band, self.max_force_rate, self.max_tip_moment],
            dtype=float,  # float64 whatever the arguments' types: the C kernel takes no other
        )


@dataclass(frozen=True, eq=False)
class SensorSetup:
    """The flange F/T sensor (SI).

    Attributes
    ----------
    T_flange_sensor : (4, 4) float, m — the sensor frame in the flange frame
    load_on : "tool" (the sensor reports the load on the tool) or "workpiece" (the opposite sign)
    tare : (6,) float [N; N·m] — the reading with no load and no tool weight (sensor axes,
        before the ``load_on`` sign)
    tool_mass : float, kg — what hangs below the sensor (0: no weight compensation)
    tool_cog : (3,) float, m — its centre of gravity in the sensor frame
    cutoff : float, Hz — corner frequency of the first-order low-pass on the wrench
    """

    T_flange_sensor: F64 = field(default_factory=lambda: np.eye(4))
    load_on: str = "tool"
    tare: F64 = field(default_factory=lambda: np.zeros(6))
    tool_mass: float = 0.0
    tool_cog: F64 = field(default_factory=lambda: np.zeros(3))
    cutoff: float = 20.0

    def __post_init__(self) -> None:
        T = np.asarray(self.T_flange_sensor, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise InputError("expected a finite (4, 4) transform", field="T_flange_sensor")
        check_rigid(T, "T_flange_sensor")
        if self.load_on not in ("tool", "workpiece"):
            raise InputError(
                f"must be 'tool' or 'workpiece', got {self.load_on!r}", field="load_on"
            )
        tare = np.asarray(self.tare, dtype=float)
        if tare.shape != (6,) or not np.all(np.isfinite(tare)):
            raise InputError("expected 6 finite values [N; N·m]", field="tare")
        cog = np.asarray(self.tool_cog, dtype=float)
        if cog.shape != (3,) or not np.all(np.isfinite(cog)):
            raise InputError("expected 3 finite values [m]", field="tool_cog")
        _pos(self.tool_mass, "tool_mass", zero=True)
        _pos(self.cutoff, "cutoff")
        object.__setattr__(self, "T_flange_sensor", T)
        object.__setattr__(self, "tare", tare)
        object.__setattr__(self, "tool_cog", cog)


class OnlineCompensator:
    """Force samples → tip wrench → deflection at the current joints → limited correction.

    Parameters
    ----------
    robot : RobotModel — kinematics, joint stiffness (identified or preset) and the tool
        ``T_flange_tip``; its stiffness is required
    T_base_work : (4, 4) float, m — the work frame (the frame of the corrections)
    k_tip : (6, 6) float — tool + holder compliance at the tip, **work** axes (SI); the tool is
        vertical in the work frame, as in :class:`roboisf.cell.Cell`
    sensor : SensorSetup
    limits : Limits
    plausibility : Plausibility — bounds on a force sample (default: none)

    After :meth:`cycle`, ``correction`` (3,) m (work axes), ``tip_wrench`` (6,) and
    ``deflection`` (6,) (base axes) and ``status`` hold the cycle's values; they are the
    object's own buffers (copy them to keep them).
    """

    def __init__(
        self,
        robot: RobotModel,
        T_base_work: ArrayLike,
        k_tip: ArrayLike,
        sensor: SensorSetup | None = None,
        limits: Limits | None = None,
        plausibility: Plausibility | None = None,
    ) -> None:
        self.robot = robot
        self.plausibility = plausibility or Plausibility()
        self._plaus = self.plausibility.array()
        self.sensor = sensor or SensorSetup()
        self.limits = limits or Limits()
        T_bw = np.asarray(T_base_work, dtype=float)
        if T_bw.shape != (4, 4) or not np.all(np.isfinite(T_bw)):
            raise InputError("expected a finite (4, 4) placement", field="T_base_work")
        k = np.asarray(k_tip, dtype=float)
        if k.shape != (6, 6) or not np.all(np.isfinite(k)):
            raise InputError("expected a finite (6, 6) compliance", field="k_tip")
        F = robot.chain.F.copy()
        F[6] = F[6] @ robot.T_flange_tip
        self._F = np.ascontiguousarray(F)
        self._sign = np.ascontiguousarray(robot.chain.sign, dtype=float)
        self._offset = np.ascontiguousarray(robot.chain.offset, dtype=float)
        self._c23 = float(robot.chain.couple23)  # FANUC J2/J3 coupling (0 for the others)
        self._kinv = np.ascontiguousarray(1.0 / robot.joint_stiffness)
        T_tip_sensor = invert(robot.T_flange_tip) @ self.sensor.T_flange_sensor
        sgn = -1.0 if self.sensor.load_on == "workpiece" else 1.0
        # the tare and the weight are removed in the sensor's own convention; the sign after
        self._X_ts = np.ascontiguousarray(sgn * wrench_transform_matrix(invert(T_tip_sensor)))
        self._R_tip_sensor = np.ascontiguousarray(T_tip_sensor[:3, :3])
        g = np.asarray(GRAVITY_BASE)
        self._grav = np.concatenate([[self.sensor.tool_mass], self.sensor.tool_cog, g])
        # tool's weight as the sensor reads it: the load on the tool is m g; a "workpiece"
        # sensor reads its negative
        self._grav[0] *= sgn
        self._tare = self.sensor.tare.copy()
        self._cutoff = float(self.sensor.cutoff)
        self._k_tip_base = np.ascontiguousarray(rotate_6x6(k[None], T_bw[:3, :3])[0])
        self._R_bw = np.ascontiguousarray(T_bw[:3, :3])
        self._lim = self.limits.array()
        self._q = np.zeros(6)
        # no joint angles yet: the tool's weight cannot be oriented (q = 0 is the robot's zero
        # pose, not where it is), so a weighed tool's samples wait for the first ones
        self._q_known = False
        self._unoriented = np.zeros(1)
        self._Ws = np.zeros(6)
        self.st = np.zeros(kn.N_STATE)
        self._clear_clocks()
        self.filtered = np.zeros(6)
        self.correction = np.zeros(3)
        self.tip_wrench = np.zeros(6)
        self.deflection = np.zeros(6)
        self._scr = np.zeros((20, 6))
        self.status = kn.STATUS_NO_SAMPLE

    def _clear_clocks(self) -> None:
        self.st[kn.S_LAST_SAMPLE] = -math.inf
        self.st[kn.S_LAST_CYCLE] = -math.inf
        self.st[kn.S_LAST_BAD] = -math.inf

    @classmethod
    def from_cell(
        cls,
        cell: Cell,
        sensor: SensorSetup | None = None,
        limits: Limits | None = None,
        plausibility: Plausibility | None = None,
    ) -> OnlineCompensator:
        """The compensator of a :class:`~roboisf.cell.Cell`: its robot (joint stiffness,
        tool), placement and tool + holder compliance at the tip."""
        _, _, k_t, k_th = tip_compliances(cell)
        return cls(cell.robot, cell.T_base_work, k_t + k_th, sensor, limits, plausibility)

    @property
    def implausible(self) -> int:
        """Force samples rejected as implausible so far."""
        return int(self.st[kn.S_BAD])

    @property
    def joints_known(self) -> bool:
        """Joint angles have been given (:meth:`set_joints`, :meth:`cycle`) since construction
        or :meth:`reset`."""
        return self._q_known

    @property
    def unoriented(self) -> int:
        """Force samples not used because no joint angles had come yet (a tool with a mass: its
        weight cannot be removed without the sensor's orientation)."""
        return int(self._unoriented[0])

    @property
    def stopping(self) -> bool:
        """:meth:`begin_stop` was called: every cycle ramps the correction towards zero."""
        return bool(self.st[kn.S_STOP] > 0)

    def begin_stop(self) -> None:
        """From the next cycle on, ramp the correction to zero at ``ramp_rate`` (the loop's
        way out: Ctrl-C, SIGTERM, an error, a lost sensor or controller)."""
        self.st[kn.S_STOP] = 1.0

    def set_joints(self, q: ArrayLike) -> None:
        """The latest joint angles (6,) rad (controller convention), used to orient the tool's
        weight for the samples that follow."""
        self._q[:] = q
        self._q_known = True

    def sample(self, t: float, W_s: F64) -> bool:
        """One sensor sample ``W_s`` (6,) [N; N·m] (sensor axes) at time ``t`` [s].

        Returns False when it was dropped (non-finite, not later than the previous one, or
        implausible: :attr:`implausible` counts those), and for a tool with a mass before the
        first joint angles (:meth:`set_joints` or :meth:`cycle`; :attr:`unoriented` counts
        those): its weight would be removed at the robot's zero pose, a force the tool never
        felt (up to twice the weight), filtered into the first cycles' corrections.
        """
        if not self._q_known and self._grav[0] != 0.0:
            self._unoriented[0] += 1.0
            return False
        self._Ws[:] = W_s
        return bool(
            kn.sample_kernel(
                self._F,
                self._sign,
                self._offset,
                self._c23,
                self._kinv,
                self._R_tip_sensor,
                self._X_ts,
                self._grav,
                self._tare,
                self._plaus,
                self._cutoff,
                t,
                self._Ws,
                self._q,
                self.st,
                self.filtered,
                self._scr,
            )
        )

    def cycle(self, t: float, q: ArrayLike) -> F64:
        """One controller cycle at time ``t`` [s], joints ``q`` (6,) rad → ``correction`` (3,) m,
        work axes (the object's buffer)."""
        self._q[:] = q
        self._q_known = True
        self.status = int(
            kn.cycle_kernel(
                self._F,
                self._sign,
                self._offset,
                self._c23,
                self._kinv,
                self._X_ts,
                self._k_tip_base,
                self._R_bw,
                self._lim,
                t,
                self._q,
                self.st,
                self.filtered,
                self.correction,
                self.tip_wrench,
                self.deflection,
                self._scr,
            )
        )
        return self.correction

    def reset(self) -> None:
        """Forget the filter, the last correction, tip wrench and deflection, the watchdog's
        clock, a stop and the joint angles: it starts as a new one."""
        self._q_known = False
        self._unoriented[0] = 0.0
        self.st[:] = 0.0
        self._clear_clocks()
        self.filtered[:] = 0.0
        self.correction[:] = 0.0
        self.tip_wrench[:] = 0.0
        self.deflection[:] = 0.0
        self.status = kn.STATUS_NO_SAMPLE

    def warm_up(self) -> None:
        """Compile the kernels (first call) without touching the state: everything a sample and
        a cycle write is put back. (The tip wrench and deflection were not, until 2026-11-29:
        a loop whose first cycle had no sample yet — the controller speaking before the sensor's
        first oriented record — logged the warm-up's, the tool's weight at the zero pose and the
        tare, ~35 N, as the first row's tip wrench.)"""
        state = (self.st, self.filtered, self.correction, self.tip_wrench, self.deflection, self._q)
        saved = [a.copy() for a in state]
        known, self._q_known = self._q_known, True  # the sample kernel is compiled too
        self.sample(0.0, np.zeros(6))
        self.cycle(0.0, np.zeros(6))
        for a, b in zip(state, saved, strict=True):
            a[:] = b
        self._q_known = known
        self.status = kn.STATUS_NO_SAMPLE


def status_text(status: int) -> str:
    """``"ok"`` or the names of the status bits, ``+``-joined."""
    names = [n for b, n in kn.STATUS_NAMES.items() if status & b]
    return "+".join(names) if names else "ok"


def episodes(status: ArrayLike, t: ArrayLike) -> dict[str, tuple[int, float]]:
    """Per status bit, its episodes in a run: ``{name: (count, longest s)}``.

    ``status`` (n,) int, the cycles' status bits (the log's ``status`` column), ``t`` (n,) s
    their times. An episode is a run of consecutive cycles with the bit set; its length runs
    from its first cycle to the first cycle after it (to its last cycle at the end of the log).
    Bits never set are left out.
    """
    st = np.asarray(status, dtype=np.int64)
    tt = np.asarray(t, dtype=float)
    if st.shape != tt.shape or st.ndim != 1:
        raise InputError("status and t must be (n,) arrays of one length", field="status")
    out: dict[str, tuple[int, float]] = {}
    for bit, name in kn.STATUS_NAMES.items():
        on = (st & bit) != 0
        if not on.any():
            continue
        edges = np.diff(np.concatenate([[0], on.astype(np.int8), [0]]))
        starts = np.flatnonzero(edges == 1)
        ends = np.flatnonzero(edges == -1)  # first cycle after (may be n)
        t_end = tt[np.minimum(ends, len(tt) - 1)]
        out[name] = (len(starts), float(np.max(t_end - tt[starts])))
    return out
