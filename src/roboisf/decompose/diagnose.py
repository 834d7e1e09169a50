"""Blame the right part: a verdict per suspect from the redundancies a study holds.

``analyze`` measures the robot's deflection as what is left of the robot part's deviation when
springback, tool and holder are taken out, and compares it with the VJM at the *measured* forces.
That robot term is also where a miscalibrated flange sensor (the VJM then runs on wrong forces),
a misregistered scan (its geometry error lands in the robot part) and an unmodelled tool weight
end up. This module tells them apart, suspect by suspect, with what the study holds twice:

* **The two force logs.** The CNC run's fixture dynamometer and the robot's flange sensor record
  the same toolpath in the same material. On the deeper half of the used laps (the robot's first
  laps form with somewhat less force while its deflection settles: the "stated difference of the
  two processes", whose size is taken from the shallow half's disagreement — twice it is added to
  the interval away from the shallow half, once towards it) the robot's tip force is fitted as
  ``F_rob = g F_cnc + b``: ``g`` one gain (the lateral forces, which turn around the part, carry
  it), ``b`` (3,) N a constant (a bias: an untared sensor, the tool's weight below the sensor).
  The lateral channels' coupling is fitted on what is left. A constant may also be the axial
  force's crosstalk into the lateral channels (the axial force barely changes along a wall): a
  second fit with that crosstalk beside the constant says whether the two can be told apart.
  The CNC dynamometer is the reference.
* **A physical bound on the tip moment.** The ball touches the sheet at one point, so the tip
  moment is ``(contact − tip) × F`` (friction acts at the contact and is in ``F``): at most
  ``R · |F|``. What the moment channels add beyond it, fitted as ``C F_xy + m₀`` (``C`` in
  N·m per N = m, quoted in mm), is crosstalk into the moment channels (through the arm from
  the sensor to the tip, a force crosstalk makes one too) — or, for the constant ``m₀``, a
  bias of the moment channels or a force offset carried up that arm. The logs at rest tell
  them apart: a bias reads there without load, crosstalk does not; without them a constant
  that matters is ``cannot_tell`` for both ``force_moment_crosstalk`` and
  ``force_moment_bias``.
* **The robot term's pattern along the path.** With the forces corrected (``G⁻¹ (F − b)``, the
  moments replaced by the point-contact moment when the moment channels fail their bound) the
  measured robot term ``y`` is fitted as ``r · x + n_x s_x + n_y s_y + θ n · (ẑ × p)``: a
  stiffness error follows the VJM's ``x = n · J K⁻¹ Jᵀ W`` pose by pose, a sideways scan shift
  ``s`` the normals, a rotation ``θ`` of the scan about the part's axis the tangential direction
  at the contact ``p`` — zero on a surface of revolution, where it cannot be seen (nor does it
  matter). A second fit puts one column per joint (``J_i K_i⁻¹ J_iᵀ W``, the joints that carry a
  share of the prediction) in place of ``r x``: a shift that only the one-scale model needs is
  told apart from a joint-by-joint stiffness error, or named ``cannot_tell`` when the data
  cannot choose.

Intervals: moving-block bootstrap over laps (:func:`roboisf.decompose.check.lap_blocks`) of each
fit, widened by the model error — the disagreement between the competing fits (one scale or per
joint, with or without a shift), the shallow/deep gain difference — and the robot ratio by the
gain's interval (relative to the fitted gain when the forces were corrected, to 1 when not:
the VJM runs on the forces it corrects or leaves). Verdicts against stated
detection limits (``DETECTION_LIMITS``): ``fault`` when the whole interval lies beyond the limit,
``ok`` when it lies within, ``cannot_tell`` otherwise.

``springback_coupling`` (the sheet recovering part of the machine's deflection) scales the robot
term exactly as a stiffer robot would: it is ``cannot_tell`` whenever the robot term is off, and
``ok`` only when the robot term agrees with the model; a robot term below the model's makes
``robot_stiffness`` ``cannot_tell`` too (a stiffer robot or a coupling, which one run cannot
tell apart).

A robot that forms the part displaced leaves the scan's patterns too (docs/diagnosis.md, "What
separates what"): a constant offset or a turn about the part axis is the robot scan's
registration or the robot's work object, which the study's files cannot tell apart
(``cannot_tell`` for both, never a scan ``fault``); an offset growing with the points' forming
time is a thermal drift (a scan is one rigid snapshot), told from a tilt of the formed part
(which grows with depth) by fitting both.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from roboisf.decompose.check import (
    RATIO_TOLERANCE,
    boot_weights,
    lap_index,
    lap_normal_equations,
    min_norm_solve,
    min_norm_solve_many,
)
from roboisf.report.statements import DIAGNOSIS_NUMBERS, diagnosis_number, diagnosis_unit

if TYPE_CHECKING:
    from roboisf.sensor import UnloadedStretch

__all__ = [
    "DETECTION_LIMITS",
    "SUSPECTS",
    "Diagnosis",
    "Finding",
    "PatternFit",
    "RobotTermFit",
    "SensorFit",
    "UnloadedEvidence",
    "diagnosis_headline",
    "fit_robot_term",
    "fit_sensor",
    "forming_time",
    "offset_seen",
    "size_interval",
    "verdict",
]

F64 = NDArray[np.float64]

#: The suspects, in the order summary.json lists them.
SUSPECTS = (
    "robot_stiffness",
    "force_gain",
    "force_moment_crosstalk",
    "force_moment_bias",
    "force_bias",
    "force_crosstalk",
    "scan_shift",
    "work_object",
    "scan_rotation",
    "thermal_drift",
    "work_object_tilt",
    "springback_coupling",
)

#: Detection limits: (low, high) of the ``ok`` band in each suspect's unit. A fault beyond them
#: is never called ``ok`` (unless the interval misses); within them it is not worth acting on.
DETECTION_LIMITS: dict[str, tuple[float, float]] = {
    # measured over modelled compliance: the accepted model error of the VJM check
    "robot_stiffness": (1 - RATIO_TOLERANCE, 1 + RATIO_TOLERANCE),
    # flange over dynamometer force: 3 % (a 3 % force error is 3 % of every force-driven term)
    "force_gain": (0.97, 1.03),
    # false tip moment per newton of force, mm (1 mm: 0.6 N·m at 600 N, ~0.01 mm of tool term)
    "force_moment_crosstalk": (0.0, 1.0),
    # what the moment channels read of their own at rest, N·m: the false moment of the
    # crosstalk's limit at 500 N, a sixth of the point-contact moment's bound R·|F| (3 N·m on a
    # Ø10 mm ball at 600 N)
    "force_moment_bias": (0.0, 0.5),
    # a constant force, N (the old warning's 5 N on the lateral channels)
    "force_bias": (0.0, 5.0),
    # the axial force's crosstalk into the lateral channels, N per N (1 % of a 600 N axial force
    # is 6 N on a lateral channel: the bias's limit)
    "force_crosstalk": (0.0, 0.01),
    # sideways shift of the robot scan, mm
    "scan_shift": (0.0, 0.05),
    # sideways offset of the robot's work object, mm: the same offset as the scan's shift (the
    # study's files cannot tell the two apart), read as the part's
    "work_object": (0.0, 0.05),
    # rotation of the robot scan about the part axis, deg
    "scan_rotation": (0.0, 0.05),
    # sideways tip drift reached at the end of the run, mm: growing from 0, it leaves a mean
    # offset of half that over the part — the shift's 0.05 mm
    "thermal_drift": (0.0, 0.1),
    # tilt of the formed part against the clamped flange about a horizontal work axis, as the
    # sideways offset it makes at the deepest analysed point, mm: growing from 0 at the flange
    # as a drift does over the run, the drift's limit
    "work_object_tilt": (0.0, 0.1),
    # fraction of the machine's deflection the sheet recovers
    "springback_coupling": (0.0, 0.1),
}

#: Each suspect's unit in summary.json.
UNITS = {
    "robot_stiffness": "1",
    "force_gain": "1",
    "force_moment_crosstalk": "mm",
    "force_moment_bias": "N·m",
    "force_bias": "N",
    "force_crosstalk": "1",
    "scan_shift": "mm",
    "work_object": "mm",
    "scan_rotation": "deg",
    "thermal_drift": "mm",
    "work_object_tilt": "mm",
    "springback_coupling": "1",
}

#: Bootstrap replicates of the diagnosis's fits.
N_BOOT_DIAG = 400
#: A joint whose column carries less than this share of the nominal prediction is held at its
#: nominal compliance in the per-joint fit.
JOINT_SHARE = 0.02
#: Ridge of the per-joint fit on its equilibrated columns: directions of the joints' scales whose
#: singular value is well below this are held at the one scale (the path cannot tell them).
JOINT_RIDGE = 0.05
#: Relative model error added to each end of the robot ratio's interval, beyond the spread of
#: the competing fits (the other terms' systematic errors: calibrated by coverage,
#: benchmarks/diagnosis.py).
RATIO_MODEL_ERROR = 0.01
#: Model error added to each end of the shift's interval, m: the other terms leave a first
#: harmonic of ~0.01 mm in the robot term of a cell whose scan is right (calibrated by coverage,
#: benchmarks/diagnosis.py).
SHIFT_MODEL_ERROR = 0.01e-3
#: Model error of the rotation's pattern, m of RMS normal deviation, added to each end of the
#: rotation's interval as ``ROTATION_MODEL_ERROR / RMS(n · (ẑ × p))``. A part whose walls are
#: all passed in the same rotational sense (a pyramid) turns whatever differs between a wall's
#: entry and its exit into this pattern, which is odd along each wall: the per-point force
#: averages read the force along the wall's normal 6–12 N low at the wall ends (unevenly
#: between entry and exit) and where the path steps down, and the other terms' errors. Clean
#: pyramids left 0.4–2.2 µm of it (+0.001° … +0.007°, the same sign for true rotations of
#: −0.2°, 0 and +0.2° and over seeds: no linearisation, no noise), which the bootstrap's
#: ±0.003° did not cover (calibrated by coverage, benchmarks/diagnosis.py).
ROTATION_MODEL_ERROR = 3e-6

#: Model error added to each end of a tilt's interval, rad: beside a drift on a cone the other
#: terms leave 0.01–0.03° of tilt where there is none (calibrated by coverage,
#: benchmarks/diagnosis.py).
TILT_MODEL_ERROR = math.radians(0.025)
#: Below this share of its columns beyond the offset's and the VJM's (equilibrated), a drift is
#: not told from a constant offset: the analysed laps are formed in too short a part of the run
#: (the VWACF's deep laps, small circles, take the last 4 % of its run: 0.012). The cone's
#: 0.27 and the pyramid's 0.12 (2 mm step-down) separate a 0.3 mm drift by 10 times its error.
DRIFT_SEPARABLE = 0.08


def verdict(lo: float, hi: float, limits: tuple[float, float]) -> str:
    """``fault`` when ``[lo, hi]`` lies wholly outside ``limits``, ``ok`` when wholly inside,
    else ``cannot_tell`` (also for a non-finite interval)."""
    a, b = limits
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "cannot_tell"
    if hi < a or lo > b:
        return "fault"
    if lo >= a and hi <= b:
        return "ok"
    return "cannot_tell"


#: Decimals each suspect's numbers are printed with in its explanation and headline — the
#: report's (:data:`roboisf.report.statements.DIAGNOSIS_NUMBERS`, with its unit: a crosstalk
#: in N/kN), so the text and the report's estimate column print the same numbers. The text's
#: estimates and intervals are formatted from the summary's own values (:func:`_finding`), so
#: what the terminal and the report print is what summary.json holds, at this precision.
PRECISION = {s: d for s, (_, _, d) in DIAGNOSIS_NUMBERS.items()}


def _json_number(v: float | None) -> float | None:
    """A number as summary.json holds it (None for a missing or non-finite one)."""
    return float(v) if v is not None and math.isfinite(v) else None


@dataclass(frozen=True)
class Part:
    """A named estimate behind a finding (the one-scale and the per-joint fit's shift, the false
    moment's part that follows the force …), in the finding's unit; ``signed`` when it has a
    direction (a rotation's sign) and is printed with it."""

    name: str
    estimate: float | None
    ci_low: float | None
    ci_high: float | None
    signed: bool = False
    #: its unit when it is not the finding's (a tilt in degrees beside an offset in mm)
    unit: str | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "name": self.name,
            "estimate": _json_number(self.estimate),
            "ci_low": _json_number(self.ci_low),
            "ci_high": _json_number(self.ci_high),
            "signed": self.signed,
        }
        if self.unit is not None:
            out["unit"] = self.unit
        return out


@dataclass(frozen=True)
class Finding:
    """One suspect's verdict. ``estimate``, ``ci_low``, ``ci_high`` in ``unit`` (None when the
    data hold no estimate); ``headline`` one short line for the terminal and the report;
    ``parts`` the named estimates the explanation also quotes (summary.json's ``parts``)."""

    suspect: str
    verdict: str
    estimate: float | None
    ci_low: float | None
    ci_high: float | None
    unit: str
    explanation: str
    headline: str
    limits: tuple[float, float] = (math.nan, math.nan)
    parts: tuple[Part, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        f = _json_number
        out: dict[str, Any] = {
            "suspect": self.suspect,
            "verdict": self.verdict,
            "estimate": f(self.estimate),
            "ci_low": f(self.ci_low),
            "ci_high": f(self.ci_high),
            "unit": self.unit,
            "explanation": self.explanation,
            "headline": self.headline,
            "detection_limits": [f(self.limits[0]), f(self.limits[1])],
        }
        if self.parts:
            out["parts"] = [p.to_dict() for p in self.parts]
        return out


# --------------------------------------------------------------------------------------------
# lap-block least squares


class _LapSums:
    """The per-lap sums of :func:`~roboisf.decompose.check.lap_normal_equations` for fits
    whose columns repeat (the robot term's fits share their VJM, joint, shift and pattern
    columns: ~360 column products, ~105 distinct): each product of two equilibrated columns,
    and of a column with a right-hand side, summed once. The same bits: an entry is the same
    ``bincount`` of the same elementwise product (``a·b = b·a`` exactly).

    Columns are known by identity and their equilibration scale: the caller passes the same
    array objects for the same columns (kept alive here while cached, so an id is not reused)."""

    def __init__(self, inv: NDArray[np.intp], L: int) -> None:
        self.inv, self.L = inv, L
        self._sums: dict[tuple[Any, ...], F64] = {}
        self._kept: dict[int, F64] = {}

    def _sum(self, key: tuple[Any, ...], a: F64, b: F64) -> F64:
        v: F64 = np.asarray(np.bincount(self.inv, weights=a * b, minlength=self.L), dtype=float)
        self._sums[key] = v
        return v

    def normal_equations(self, cols: Sequence[F64], scale: F64, y: F64) -> tuple[F64, F64]:
        """``(G, h)`` of :func:`lap_normal_equations` for ``X = column_stack(cols) / scale``."""
        for c in (*cols, y):
            self._kept.setdefault(id(c), c)
        k, L = len(cols), self.L
        ids = [(id(c), float(s)) for c, s in zip(cols, scale, strict=True)]
        scaled: list[F64 | None] = [None] * k

        def xs(i: int) -> F64:  # the column X[:, i] / scale[i], as X / scale gives it
            if scaled[i] is None:
                scaled[i] = np.asarray(cols[i], dtype=float) / scale[i]
            out = scaled[i]
            assert out is not None
            return out

        G = np.empty((L, k, k))
        h = np.empty((L, k))
        for i in range(k):
            for j in range(i, k):
                key: tuple[Any, ...] = (*min(ids[i], ids[j]), *max(ids[i], ids[j]))
                v = self._sums[key] if key in self._sums else self._sum(key, xs(i), xs(j))
                G[:, i, j] = v
                G[:, j, i] = v
            key = ("h", *ids[i], id(y))
            h[:, i] = self._sums[key] if key in self._sums else self._sum(key, xs(i), y)
        return G, h


def _lap_ls(
    X: F64,
    y: F64,
    inv: NDArray[np.intp],
    L: int,
    weights: F64,
    *,
    prior: F64 | None = None,
    penalty: F64 | None = None,
    sums: _LapSums | None = None,
    cols: Sequence[F64] | None = None,
) -> tuple[F64, F64]:
    """Least squares ``X β ≈ y`` (columns equilibrated to unit norm) and its bootstrap
    replicates (n_boot, k) over the lap weights ``weights`` (n_boot, L). ``penalty`` (k,) adds
    ``Σ penalty_j (β_j − prior_j)²`` in the equilibrated coordinates, per unit of the normal
    matrix's mean eigenvalue (a ridge towards ``prior``, in β's units). ``sums`` and ``cols``
    (X's columns, as the arrays ``X`` was stacked from): the per-lap sums shared with other
    fits of the same laps (:class:`_LapSums`)."""
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    if sums is not None and cols is not None:
        G, h = sums.normal_equations(cols, scale, y)
    else:
        G, h = lap_normal_equations(X / scale, y, inv, L)
    k = X.shape[1]
    pen = np.zeros(k) if penalty is None else np.asarray(penalty, dtype=float)
    p0 = np.zeros(k) if prior is None else np.asarray(prior, dtype=float) * scale

    def solve(M: F64, v: F64) -> F64:
        t = float(np.trace(M)) / k
        return min_norm_solve(M + np.diag(pen * t), v + pen * t * p0)

    beta = solve(G.sum(axis=0), h.sum(axis=0)) / scale
    Gb = np.einsum("bl,lij->bij", weights, G)
    hb = np.einsum("bl,li->bi", weights, h)
    # each replicate as solve() above, all at once (the penalty's terms in the same order)
    tb = np.trace(Gb, axis1=1, axis2=2) / k
    pt = pen[None, :] * tb[:, None]  # (n_boot, k): pen · t of each replicate
    Gb[:, np.arange(k), np.arange(k)] += pt
    boot = min_norm_solve_many(Gb, hb + pt * p0) / scale
    return beta, boot


def _pct(v: F64) -> tuple[float, float]:
    v = v[np.isfinite(v)]
    if v.size < 10:
        return math.nan, math.nan
    lo, hi = np.percentile(v, [2.5, 97.5])
    return float(lo), float(hi)


# --------------------------------------------------------------------------------------------
# the two force logs


def size_interval(b: F64, se: F64) -> tuple[float, float]:
    """95 % interval of ``|b|`` for a vector ``b`` (k,) with independent normal errors of
    standard deviation ``se`` (k,): the percentiles of the size over draws, reaching down to 0
    when ``b = 0`` is inside the vector's 95 % region (χ² test: a size is biased upward, so a
    true zero would never be covered otherwise) and always containing ``|b|``."""
    # χ² quantile from scipy.special (chi2.ppf(0.95, k) = chdtri(k, 0.05), to 1e-15):
    # importing scipy.stats costs 0.6-1.2 s on every analyze
    from scipy.special import chdtri

    b = np.asarray(b, dtype=float)
    se = np.maximum(np.asarray(se, dtype=float), 1e-300)
    draws = b[None, :] + np.random.default_rng(7).standard_normal((N_BOOT_DIAG, b.size)) * se
    lo, hi = np.percentile(np.linalg.norm(draws, axis=1), [2.5, 97.5])
    est = float(np.linalg.norm(b))
    if float(np.sum((b / se) ** 2)) < float(chdtri(b.size, 0.05)):
        lo = 0.0
    return min(float(lo), est), max(float(hi), est)


@dataclass(frozen=True)
class UnloadedEvidence:
    """What the two logs read with the tool off the sheet (tip forces, work axes, N).

    robot, robot_se : (3,) the flange sensor's mean reading over its untared unloaded stretches
    and its standard error (block means: :class:`roboisf.sensor.UnloadedStretch`), widened by
    half the start–end difference when the two disagree (a drifting zero); cnc, cnc_se : (3,)
    the dynamometer's, zero when its log has no untared unloaded stretch (``cnc_seen`` False:
    its zero is then taken as right, and said); drift : N, the flange sensor's |start − end|
    (nan with one stretch); where : the stretches, in words.

    The moment channels at rest (N·m, work axes): robot_m, robot_m_se the flange sensor's tip
    moment; robot_ms, robot_ms_se its moment about the sensor's own origin, ``M − lever × F``
    block by block (what its moment channels read: a force offset makes none there); lever :
    (3,) m the sensor's origin relative to the tip (the path's first tip, work axes; zero for a
    sensor at the tip)."""

    robot: F64
    robot_se: F64
    cnc: F64
    cnc_se: F64
    cnc_seen: bool
    drift: float
    where: str
    #: a robot stretch lies on the toolpath (the log starts or ends forming below the onset):
    #: both logs read forming force there, and the processes' own difference is in their gap
    on_path: bool = False
    robot_m: F64 = field(default_factory=lambda: np.zeros(3))
    robot_m_se: F64 = field(default_factory=lambda: np.zeros(3))
    robot_ms: F64 = field(default_factory=lambda: np.zeros(3))
    robot_ms_se: F64 = field(default_factory=lambda: np.zeros(3))
    lever: F64 = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def from_stretches(
        cls,
        robot: list[UnloadedStretch],
        cnc: list[UnloadedStretch],
        *,
        lever: F64 | None = None,
    ) -> UnloadedEvidence | None:
        """None when the robot's log has no untared unloaded stretch (it starts loaded, or was
        tared on the one it has: that reads zero by construction). ``lever`` (3,) m: the flange
        sensor's origin relative to the tip, work axes (None: at the tip)."""
        L = np.zeros(3) if lever is None else np.asarray(lever, dtype=float)
        r = [u for u in robot if not u.tared]
        if not r:
            return None
        c = [u for u in cnc if not u.tared]
        on_path = any(u.on_path for u in r)
        if on_path and not c:
            # the flange sensor's reading there is forming force, and no dynamometer reading
            # of the same stretch says how much: no evidence of a static offset
            return None

        from scipy.special import stdtrit  # Student's t quantile, without scipy.stats

        def forces(B: F64) -> F64:
            return B[:, :3]

        def moments(B: F64) -> F64:
            return B[:, 3:6]

        def at_sensor(B: F64) -> F64:  # the moment about the sensor's origin
            return B[:, 3:6] - np.cross(L, B[:, :3])

        def pooled(
            us: list[UnloadedStretch], ch: Any = forces, drifts: bool = True
        ) -> tuple[F64, F64]:
            # each stretch about its own mean (a drift is added below), the standard error
            # stretched by Student's t over the normal's 1.96: few blocks estimate it
            B = np.vstack([ch(u.blocks) - ch(u.blocks).mean(axis=0) for u in us])
            dof = len(B) - len(us)
            sd = np.sqrt(np.sum(B**2, axis=0) / max(dof, 1))
            t = float(stdtrit(max(dof, 1), 0.975)) / 1.96
            mean = np.vstack([ch(u.blocks) for u in us]).mean(axis=0)
            se = t * sd / np.sqrt(len(B))
            for u in us:
                if u.on_path:  # forming below the threshold: its creep is in the error
                    q = max(1, len(u.blocks) // 4)
                    creep = ch(u.blocks[-q:]).mean(axis=0) - ch(u.blocks[:q]).mean(axis=0)
                    se = np.sqrt(se**2 + creep**2)
            if drifts and len(us) == 2:  # a drifting zero: half the start–end difference
                d = ch(us[0].blocks).mean(axis=0) - ch(us[1].blocks).mean(axis=0)
                se = np.sqrt(se**2 + (0.5 * d) ** 2)
            return mean, se

        b_r, se_r = pooled(r)
        drift = math.nan
        if len(r) == 2:
            drift = float(np.linalg.norm(r[0].mean[:3] - r[1].mean[:3]))
        b_c, se_c = pooled(c, drifts=False) if c else (np.zeros(3), np.zeros(3))
        m_r, m_se = pooled(r, moments)
        ms_r, ms_se = pooled(r, at_sensor)
        where = " and ".join(
            f"{u.where} {u.t0:.2f}–{u.t1:.2f} s"
            + (", on the path below the onset" if u.on_path else "")
            for u in r
        )
        return cls(b_r, se_r, b_c, se_c, bool(c), drift, where, on_path, m_r, m_se, ms_r, ms_se, L)

    def static_offset(self, gain: float, spread: float = 0.0) -> tuple[F64, F64]:
        """(3,) N the flange sensor's constant beyond the dynamometer's at rest, in the fit's
        terms (``b`` of ``F_rob = g F_cnc + b``), and its standard error.

        ``spread``: the relative gain the two processes may differ by (the gain's interval
        half-width over the gain). On the path — the log's first or last laps, in the rim band
        the sensor fit leaves out — at least :data:`RIM_PROCESS_GAP`, added to the error as
        ``spread · g · |cnc|`` per axis (a 95 % half-width): the robot's first laps form with
        less force than the CNC's (the virtual cell: 6 % at the rim), so two stretches of
        forming force differ by that much with no offset at all — a clean cell whose first lap
        formed at 138 N was called a 6.6 N bias FAULT."""
        se = np.sqrt(self.robot_se**2 + (gain * self.cnc_se) ** 2)
        if self.on_path:  # at the rim, outside the fit's laps: at least RIM_PROCESS_GAP
            spread = max(spread, RIM_PROCESS_GAP)
            se = np.sqrt(se**2 + (spread * gain * np.abs(self.cnc) / 1.96) ** 2)
        return self.robot - gain * self.cnc, se

    def _forming_moment_se(self, gain: float, reach: float) -> F64:
        """On the path, the forming force's own tip moment at the stretch, ``(a₀ − ā) × g F``
        with ``|a₀ − ā| ≤ reach`` (m): a 95 % half-width per axis (zero off the path)."""
        if not self.on_path:
            return np.zeros(3)
        return np.full(3, reach * gain * float(np.linalg.norm(self.cnc)) / 1.96)

    def static_moment(self, gain: float, arm: F64, reach: float) -> tuple[F64, F64]:
        """(3,) N·m the flange sensor's tip moment at rest beyond the point-contact moment of
        its reading, ``M − ā × F`` (``arm`` ā (3,) m the mean contact − tip of the sensor
        fit's points), and its standard error: the constant ``m₀`` the forming fit of the false
        moment (``C F_xy + m₀``) finds when the load adds nothing to it (a moment bias, a force
        offset carried up the arm). ``reach``: see :meth:`_forming_moment_se`."""
        m = self.robot_m - np.cross(arm, self.robot)
        se = np.sqrt(
            self.robot_m_se**2 + _cross_se(arm, self.robot_se) ** 2
            + self._forming_moment_se(gain, reach) ** 2
        )  # fmt: skip
        return m, se

    def moment_offset(
        self, gain: float, arm: F64, reach: float, spread: float = 0.0
    ) -> tuple[F64, F64]:
        """(3,) N·m what the moment channels read at rest of their own — the moment about the
        sensor's origin, where a force offset makes none, less what the dynamometer's force
        there (on the path) makes about it, ``M_s + (lever − ā) × g F_cnc`` — and its standard
        error: a bias of the moment channels, or the tool's weight acting off the sensor's
        axis (its moment about the sensor). On the path the two processes' forces differ by
        ``spread`` (at least :data:`RIM_PROCESS_GAP`, as :meth:`static_offset`), and that
        difference acts on the lever: ``|lever − ā| · spread · g · |F_cnc|`` per axis (95 %)."""
        c = self.lever - arm
        mu = self.robot_ms + np.cross(c, gain * self.cnc)
        gap = 0.0
        if self.on_path:
            gap = float(np.linalg.norm(c)) * max(spread, RIM_PROCESS_GAP) * gain
            gap *= float(np.linalg.norm(self.cnc)) / 1.96
        se = np.sqrt(
            self.robot_ms_se**2 + _cross_se(c, gain * self.cnc_se) ** 2
            + self._forming_moment_se(gain, reach) ** 2 + gap**2
        )  # fmt: skip
        return mu, se


def _cross_se(c: F64, se: F64) -> F64:
    """(3,) standard error of ``c × b`` for ``b`` with independent errors ``se`` (3,)."""
    cx, cy, cz = (float(v) for v in c)
    sx, sy, sz = (float(v) ** 2 for v in se)
    return np.sqrt([cy**2 * sz + cz**2 * sy, cz**2 * sx + cx**2 * sz, cx**2 * sy + cy**2 * sx])


@dataclass(frozen=True)
class SensorFit:
    """The flange sensor against the CNC dynamometer (work axes at the tip).

    lateral_coupling : (c_xy, c_yx) the lateral channels' coupling (removed by :meth:`corrected`);
    gain, gain_ci : ``g`` of ``F_rob = g F_cnc + b`` and its 95 % interval (the processes' own
    difference included); gain_boot : its bootstrap replicates; b : (3,) N the constant; bias,
    bias_ci : ``|b|`` N; bias_axial, bias_axial_ci, axial_crosstalk : ``|b|`` fitted beside the
    axial force's crosstalk into the lateral channels (c_xz, c_yz); force_crosstalk : largest
    lateral coupling left after the gain;
    moment_crosstalk, moment_crosstalk_ci : RMS of the false tip moment (beyond the point-contact
    moment, the part explained by the force) per RMS newton of force, m; moment_proportional,
    moment_proportional_ci : the same for the part that follows the lateral force (not a
    constant); moment_excess : RMS of
    the moment beyond the point-contact moment / RMS of ``R|F|``; process_gap : shallow-half over
    deep-half gain − 1.

    The moment channels' constant ``m₀``: moment_constant, moment_constant_ci the size (N·m) of
    ``m₀ − (lever − ā) × b`` — the constant beyond what the force constant makes up the arm
    from the sensor (``lever``, m) to the tip (``ā`` the mean contact − tip, m), fitted on the
    path: a moment bias, or the axial force's crosstalk into the moment channels (nearly
    constant along a wall); moment_upper, moment_upper_ci the false moment per RMS newton (m)
    were all of that constant crosstalk (the most the path alone allows). With the logs at
    rest: moment_load, moment_load_ci the false moment per RMS newton (m) less the static
    moment at rest (``static_moment`` (3,) N·m, the tip moment at rest beyond the
    point-contact moment): what the load adds, crosstalk;
    moment_bias, moment_bias_se (3,) N·m what the moment channels read at rest of their own
    (:meth:`UnloadedEvidence.moment_offset`); lever (3,) m; moment_carried the
    false moment per RMS newton (m) that the axial force's crosstalk into the lateral force
    channels makes carried up the lever (left out of moment_load: force_crosstalk's)."""

    gain: float
    gain_ci: tuple[float, float]
    gain_boot: F64
    b: F64
    bias: float
    bias_ci: tuple[float, float]
    bias_axial: float
    bias_axial_ci: tuple[float, float]
    axial_crosstalk: tuple[float, float]
    force_crosstalk: float
    lateral_coupling: tuple[float, float]
    moment_crosstalk: float
    moment_crosstalk_ci: tuple[float, float]
    moment_proportional: float
    moment_proportional_ci: tuple[float, float]
    moment_excess: float
    process_gap: float
    n_laps: int
    axial_force: float = math.nan
    unloaded: UnloadedEvidence | None = None
    static_b: F64 | None = None
    static_bias_ci: tuple[float, float] | None = None
    axial_fixed: tuple[float, float] | None = None
    axial_fixed_ci: tuple[float, float] | None = None
    #: Set by the diagnosis when the crosstalk is at fault: :meth:`corrected` removes it.
    correct_axial: bool = False
    moment_constant: float = math.nan
    moment_constant_ci: tuple[float, float] = (math.nan, math.nan)
    moment_upper: float = math.nan
    moment_upper_ci: tuple[float, float] = (math.nan, math.nan)
    lever: F64 | None = None
    moment_carried: float = 0.0
    moment_load: float | None = None
    moment_load_ci: tuple[float, float] | None = None
    static_moment: F64 | None = None
    moment_bias: F64 | None = None
    moment_bias_se: F64 | None = None

    def corrected(self, W_rob: F64, arm: F64, *, moments: bool) -> F64:
        """The robot's tip wrench (N, 6) corrected: forces ``(F − b) / g`` and the lateral
        coupling undone; moments replaced by
        the point-contact moment ``arm × F`` (``arm`` (N, 3) m, contact − tip) when ``moments``,
        else divided by ``g``."""
        W = np.array(W_rob, dtype=float)
        b = self.b
        if self.correct_axial and self.static_b is not None and self.axial_fixed is not None:
            # F_read,xy = g (F_xy + c F_z) + b: the static offset, then the axial share
            b = self.static_b
            W[:, :3] = (W_rob[:, :3] - b[None, :]) / self.gain
            W[:, :2] -= np.outer(W[:, 2], self.axial_fixed)
        else:
            W[:, :3] = (W_rob[:, :3] - b[None, :]) / self.gain
        cxy, cyx = self.lateral_coupling
        C = np.array([[1.0, cxy], [cyx, 1.0]])
        W[:, :2] = W[:, :2] @ np.linalg.inv(C).T
        if moments:
            W[:, 3:] = np.cross(arm, W[:, :3])
        else:
            W[:, 3:] = W_rob[:, 3:] / self.gain
        return W


def _gain_design(Fc: F64) -> F64:
    """Rows of ``F_rob = g F_cnc + b`` stacked x, y, z: (3M, 4) columns [F_cnc, e_x, e_y, e_z]."""
    M = len(Fc)
    X = np.zeros((3 * M, 4))
    X[:, 0] = Fc.T.ravel()
    for i in range(3):
        X[i * M : (i + 1) * M, 1 + i] = 1.0
    return X


def _gain_fit(Fc: F64, Fr: F64, inv: NDArray[np.intp], L: int, weights: F64) -> tuple[F64, F64]:
    """One gain shared by the three force channels and a constant per channel: ([g, b] (4,),
    bootstrap (n_boot, 4)). The lateral forces turn around the part, so they carry the gain; the
    axial force, nearly constant along a wall, carries the constant."""
    X = _gain_design(Fc)
    return _lap_ls(X, Fr.T.ravel(), np.tile(inv, 3), L, weights)


def _false_moment(
    Fc: F64, Mres: F64, inv: NDArray[np.intp], L: int, weights: F64
) -> tuple[F64, F64, F64]:
    """The moment beyond the point-contact moment fitted as ``C F_xy + m₀`` per channel:
    (fitted (M, 3) N·m, coefficient rows (3, 3), bootstrap (n_boot, 3, 3)). The axial force's
    share folds into ``m₀`` (it barely varies along a wall)."""
    X = np.column_stack([Fc[:, :2], np.ones(len(Fc))])
    rows, boots = [], []
    for i in range(3):
        beta, boot = _lap_ls(X, Mres[:, i], inv, L, weights)
        rows.append(beta)
        boots.append(boot)
    B = np.stack(rows)
    return X @ B.T, B, np.stack(boots, axis=1)


def _rms_fitted(X: F64, B: F64) -> F64:
    """(n_boot,) — ``sqrt(mean over rows of |X Bᵦᵀ|²)`` for each coefficient set ``B[β]``
    (3, p) of ``B`` (n_boot, 3, p), X (M, p): through the Gram matrix ``XᵀX`` (p × p) once,
    ``Σᵢ Bᵦ,ᵢ XᵀX Bᵦ,ᵢᵀ / M``, instead of an (M, 3) product per replicate (400 of them on the
    paper cone's 17 k deep points: 0.14 s of the diagnosis). Equal to the direct sum to
    rounding (tests/test_diagnosis.py); the sum of squares is non-negative, clipped at 0."""
    G = X.T @ X
    q = np.einsum("bip,pq,biq->b", B, G, B)
    return np.asarray(np.sqrt(np.maximum(q, 0.0) / X.shape[0]))


def fit_sensor(
    W_cnc: F64,
    W_rob: F64,
    arm: F64,
    valid: NDArray[np.bool_],
    lap: NDArray[Any],
    depth: F64,
    *,
    n_boot: int = N_BOOT_DIAG,
    seed: int = 0,
    unloaded: UnloadedEvidence | None = None,
    lever: F64 | None = None,
) -> SensorFit | None:
    """The flange sensor against the CNC dynamometer on the same path (module docstring).

    W_cnc, W_rob : (N, 6) [N, N·m] tip wrenches of the two runs, work axes; arm : (N, 3) m
    contact − tip; valid : (N,) bool; lap : (N,); depth : (N,) m; unloaded : the logs at rest,
    when they have an untared unloaded stretch: the static offset, and the axial force's
    crosstalk fitted with the constant held at it; the static moment, and the false moment the
    load adds beyond it. lever : (3,) m the flange sensor's origin relative to the tip, work
    axes (None: ``unloaded``'s, else at the tip). None with fewer than 6 laps."""
    sel = np.asarray(valid, bool) & np.all(np.isfinite(W_cnc), 1) & np.all(np.isfinite(W_rob), 1)
    lp = np.asarray(lap)[sel]
    laps = np.unique(lp)
    if laps.size < 6:
        return None
    depth_sel = depth[sel]
    lap_depth = np.array([np.mean(depth_sel[lp == v]) for v in laps])
    deep_laps = laps[lap_depth >= np.median(lap_depth)]
    deep = np.isin(lp, deep_laps)
    Fc, Fr = W_cnc[sel, :3], W_rob[sel, :3]
    # deep half: the reference fit
    inv, L = lap_index(lp[deep])
    weights = boot_weights(L, n_boot, seed)
    beta, boot = _gain_fit(Fc[deep], Fr[deep], inv, L, weights)
    gain, b = float(beta[0]), beta[1:4]
    # shallow half: how much the processes themselves differ there
    inv_s, L_s = lap_index(lp[~deep])
    G_s, h_s = lap_normal_equations(
        _gain_design(Fc[~deep]), Fr[~deep].T.ravel(), np.tile(inv_s, 3), L_s
    )
    g_sh = float(min_norm_solve(G_s.sum(0), h_s.sum(0))[0])
    gap = g_sh / gain - 1 if gain else math.nan
    lo, hi = _pct(boot[:, 0])
    # the processes' difference fades with depth, so the deep half keeps some of it, on the
    # shallow half's side of the truth: twice the halves' difference away from the shallow
    # half, once towards it
    widen = abs(gain * gap) if math.isfinite(gap) else 0.0
    w_lo, w_hi = (widen, 2 * widen) if gap < 0 else (2 * widen, widen)
    gain_ci = (min(lo, gain) - w_lo, max(hi, gain) + w_hi)
    bias = float(np.linalg.norm(b))
    blo, bhi = _size_ci(boot[:, 1:4], b)
    # the same with the axial force's crosstalk into the lateral channels beside the constant:
    # along a wall the axial force barely changes, so that crosstalk may look like a bias
    Md = int(deep.sum())
    Xa = np.zeros((3 * Md, 6))
    Xa[:, :4] = _gain_design(Fc[deep])
    Xa[:Md, 4] = Fc[deep, 2]
    Xa[Md : 2 * Md, 5] = Fc[deep, 2]
    beta_a, boot_a = _lap_ls(Xa, Fr[deep].T.ravel(), np.tile(inv, 3), L, weights)
    b_axial = beta_a[1:4]
    bias_axial_ci = _size_ci(boot_a[:, 1:4], b_axial)
    # lateral force crosstalk: the residual of each lateral channel against the other's force
    res = Fr[deep] - gain * Fc[deep] - b[None, :]
    xt = []
    for i, j in ((0, 1), (1, 0)):
        fj = gain * Fc[deep, j]
        xt.append(float(fj @ res[:, i]) / float(fj @ fj) if float(fj @ fj) > 0 else 0.0)
    xtalk = float(np.max(np.abs(xt)))
    # moment channels beyond the point-contact moment
    Mres = W_rob[sel, 3:] - np.cross(arm[sel], W_rob[sel, :3])
    fitted, _B, bootM = _false_moment(Fc[deep], Mres[deep], inv, L, weights)
    Fn = np.sqrt(np.mean(np.sum(Fc[deep] ** 2, 1)))
    cm = float(np.sqrt(np.mean(np.sum(fitted**2, 1)))) / Fn
    Xd = np.column_stack([Fc[deep, :2], np.ones(int(deep.sum()))])
    cb = _rms_fitted(Xd, bootM) / Fn
    clo, chi = _pct(cb)
    # the part that follows the lateral force alone (a force bias carried up the arm from the
    # flange to the tip is a constant moment; crosstalk from the axial force is one too)
    Xp = np.column_stack([Fc[deep, :2], np.zeros(int(deep.sum()))])
    cp = float(np.sqrt(np.mean(np.sum((Xp @ _B.T) ** 2, 1)))) / Fn
    cpb = _rms_fitted(Xp, bootM) / Fn
    cplo, cphi = _pct(cpb)
    bound = np.linalg.norm(arm[sel], axis=1) * np.linalg.norm(W_rob[sel, :3], axis=1)
    excess = float(np.sqrt(np.mean(np.sum(Mres**2, 1))) / max(np.sqrt(np.mean(bound**2)), 1e-300))
    Fz = gain * Fc[deep, 2]  # the axial force as the flange sensor should read it
    axial_force = float(np.sqrt(np.mean(Fz**2)))
    spread = max(gain - gain_ci[0], gain_ci[1] - gain) / gain if gain else 0.0
    static = _static_fit(unloaded, gain, Fz, Fr[deep], Fc[deep], inv, L, weights, spread)
    moments = _moment_constant(
        arm[sel][deep], b, boot[:, 1:4], Xd, _B, bootM, Fn, gain, unloaded, lever, seed, spread
    )
    if unloaded is not None and static.get("axial_fixed") is not None:
        # what the axial force's crosstalk into the lateral force channels (force_crosstalk)
        # makes about the tip, carried up the arm from the sensor: that suspect's, not the
        # moment channels' (a 3.6 % crosstalk made 9.7 mm of false moment per newton)
        c = np.array([*static["axial_fixed"], 0.0])
        f = np.outer(Fz, c)  # the false lateral force the sensor reads, N
        lev = np.asarray(moments["lever"], dtype=float)
        carried = np.cross(lev[None, :] - arm[sel][deep], f)
        _f, B_adj, boot_adj = _false_moment(Fc[deep], Mres[deep] - carried, inv, L, weights)
        moments.update(
            _moment_load(Xd, B_adj, boot_adj, Fn, gain, unloaded, arm[sel][deep], seed, spread),
            moment_carried=float(np.sqrt(np.mean(np.sum(carried**2, 1)))) / Fn,
        )
    return SensorFit(
        gain=gain,
        gain_ci=gain_ci,
        gain_boot=boot[:, 0],
        b=b,
        bias=bias,
        bias_ci=(blo, bhi),
        bias_axial=float(np.linalg.norm(b_axial)),
        bias_axial_ci=bias_axial_ci,
        axial_crosstalk=(float(beta_a[4] / gain), float(beta_a[5] / gain)),
        force_crosstalk=xtalk,
        lateral_coupling=(xt[0], xt[1]),
        moment_crosstalk=cm,
        moment_crosstalk_ci=(min(clo, cm), max(chi, cm)),
        moment_proportional=cp,
        moment_proportional_ci=(min(cplo, cp), max(cphi, cp)),
        moment_excess=excess,
        process_gap=gap,
        n_laps=int(laps.size),
        axial_force=axial_force,
        **static,
        **moments,
    )


def _moment_constant(
    arm: F64,
    b: F64,
    b_boot: F64,
    X: F64,
    B: F64,
    B_boot: F64,
    Fn: float,
    gain: float,
    unloaded: UnloadedEvidence | None,
    lever: F64 | None,
    seed: int,
    spread: float = 0.0,
) -> dict[str, Any]:
    """The false moment's constant ``m₀`` (``B[:, 2]`` of ``C F_xy + m₀``, bootstrap
    ``B_boot`` (n_boot, 3, 3); X (M, 3) ``[F_xy, 1]`` of the deep points, ``arm`` (M, 3) m their
    contact − tip, ``b`` (3,) N the force constant and its replicates ``b_boot``, ``Fn`` the
    RMS force): beyond what the force constant makes up the arm from the sensor, and — with the
    logs at rest — beyond the static moment there (:class:`SensorFit`'s fields)."""
    a_bar = arm.mean(axis=0)
    if lever is None:
        lever = unloaded.lever if unloaded is not None else np.zeros(3)
    c = np.asarray(lever, dtype=float) - a_bar
    mc = B[:, 2] - np.cross(c, b)
    mc_boot = B_boot[:, :, 2] - np.cross(c, b_boot)
    Bu = B.copy()
    Bu[:, 2] = mc
    Bu_boot = B_boot.copy()
    Bu_boot[:, :, 2] = mc_boot
    mu_ = float(np.sqrt(np.mean(np.sum((X @ Bu.T) ** 2, 1)))) / Fn
    ulo, uhi = _pct(_rms_fitted(X, Bu_boot) / Fn)
    out: dict[str, Any] = {
        "lever": np.asarray(lever, dtype=float),
        "moment_constant": float(np.linalg.norm(mc)),
        "moment_constant_ci": _size_ci(mc_boot, mc),
        "moment_upper": mu_,
        "moment_upper_ci": (min(ulo, mu_), max(uhi, mu_)),
    }
    if unloaded is None:
        return out
    out.update(_moment_load(X, B, B_boot, Fn, gain, unloaded, arm, seed, spread))
    return out


def _moment_load(
    X: F64,
    B: F64,
    B_boot: F64,
    Fn: float,
    gain: float,
    unloaded: UnloadedEvidence,
    arm: F64,
    seed: int,
    spread: float = 0.0,
) -> dict[str, Any]:
    """The false moment the load brings: ``C F_xy + m₀`` (``B``, replicates ``B_boot``) less
    the static moment the sensor reads at rest, per RMS newton ``Fn`` (m); the static moment
    drawn with its standard error in each replicate."""
    a_bar = arm.mean(axis=0)
    reach = float(np.max(np.linalg.norm(arm, axis=1)) + np.linalg.norm(a_bar))
    m_rest, se_m = unloaded.static_moment(gain, a_bar, reach)
    Bl = B.copy()
    Bl[:, 2] -= m_rest
    z = np.random.default_rng(seed + 17).standard_normal((len(B_boot), 3))
    Bl_boot = B_boot.copy()
    Bl_boot[:, :, 2] -= m_rest[None, :] + z * se_m[None, :]
    ml = float(np.sqrt(np.mean(np.sum((X @ Bl.T) ** 2, 1)))) / Fn
    lo, hi = _pct(_rms_fitted(X, Bl_boot) / Fn)
    mu, se_mu = unloaded.moment_offset(gain, a_bar, reach, spread)
    return {
        "moment_load": ml,
        "moment_load_ci": (min(lo, ml), max(hi, ml)),
        "static_moment": m_rest,
        "moment_bias": mu,
        "moment_bias_se": se_mu,
    }


def _static_fit(
    unloaded: UnloadedEvidence | None,
    gain: float,
    Fz: F64,
    Fr: F64,
    Fc: F64,
    inv: NDArray[np.intp],
    L: int,
    weights: F64,
    spread: float = 0.0,
) -> dict[str, Any]:
    """The static offset from the logs at rest and, with the constant held at it, the axial
    force's crosstalk into the lateral channels: ``F_rob,xy − g F_cnc,xy − b_xy = c g F_cnc,z``
    (lap-block bootstrap; the offset's standard error moves ``c`` by ``se / |F_z|``, added to
    both ends). {} without an unloaded stretch."""
    if unloaded is None:
        return {}
    b_s, se = unloaded.static_offset(gain, spread)
    M = len(Fz)
    X = np.zeros((2 * M, 2))
    X[:M, 0] = Fz
    X[M:, 1] = Fz
    y = (Fr[:, :2] - gain * Fc[:, :2] - b_s[None, :2]).T.ravel()
    c, boot = _lap_ls(X, y, np.tile(inv, 2), L, weights)
    c_size = float(np.hypot(c[0], c[1]))
    clo, chi = _pct(np.hypot(boot[:, 0], boot[:, 1]))
    widen = 1.96 * float(np.hypot(se[0], se[1])) / max(float(np.mean(np.abs(Fz))), 1e-300)
    return {
        "unloaded": unloaded,
        "static_b": b_s,
        "static_bias_ci": size_interval(b_s, se),
        "axial_fixed": (float(c[0]), float(c[1])),
        "axial_fixed_ci": (max(min(clo, c_size) - widen, 0.0), max(chi, c_size) + widen),
    }


# --------------------------------------------------------------------------------------------
# the robot term's pattern


@dataclass(frozen=True)
class PatternFit:
    """A sideways pattern's vector (2,) fitted beside one stiffness scale (``one``) and beside
    the per-joint fit (``joint``), in m (an offset) or rad (a tilt about work x, y), each with
    the 95 % interval of its size (model error included)."""

    one: F64
    one_ci: tuple[float, float]
    joint: F64
    joint_ci: tuple[float, float]

    def verdict(self, limits: tuple[float, float], scale: float = 1e3) -> str:
        """``fault`` or ``ok`` when both fits say so (sizes times ``scale``: mm, deg), else
        ``cannot_tell``."""
        v1 = verdict(self.one_ci[0] * scale, self.one_ci[1] * scale, limits)
        vj = verdict(self.joint_ci[0] * scale, self.joint_ci[1] * scale, limits)
        return v1 if v1 == vj else "cannot_tell"

    def ci(self, scale: float = 1e3) -> tuple[float, float]:
        """The interval spanning both fits', times ``scale``."""
        return (
            min(self.one_ci[0], self.joint_ci[0]) * scale,
            max(self.one_ci[1], self.joint_ci[1]) * scale,
        )


@dataclass(frozen=True)
class RobotTermFit:
    """The robot term fitted by the competing explanations (module docstring).

    ratio, ratio_ci : measured over modelled compliance (model error included); shift, shift_ci :
    (2,) m beside one scale and the interval of its size (m); shift_joint, shift_joint_ci : the
    same beside the per-joint fit; rotation, rotation_ci, rotation_joint, rotation_joint_ci :
    rad, the same for a rotation about work z (None when the part's symmetry hides it); rms_vjm,
    rms_shift_pattern, rms_rotation_pattern : m, RMS of the VJM's normal deflection and of the
    fitted patterns ``n · s`` and ``θ n · (ẑ × p)``; joints_fitted : 1-based joints of the
    per-joint fit; n_laps.

    With the points' forming time ``τ`` (0 at the run's first point, 1 at its last): drift : the
    sideways offset growing as ``d τ`` (m, ``d`` reached at the end of the run) fitted beside
    the shift; drift_beside_tilt : the same with a tilt of the formed part about work x and y
    fitted too; tilt : that tilt (rad); tilt_alone : the tilt fitted beside the shift without a
    drift (what rules a tilt out: both grow with depth on a step-down path); drift_separable :
    the share of the drift's columns the offset's and the VJM's do not explain (equilibrated;
    below :data:`DRIFT_SEPARABLE` the analysed laps are formed in too short a part of the run to
    tell a drift from a constant offset, and drift, drift_beside_tilt are None); drift_kappa :
    per axis, the share of a drift a constant offset fitted alone takes (the analysed laps'
    forming time, weighted); depth_max : m, the deepest analysed point (a tilt θ sits θ·depth_max
    sideways there); model : which patterns the shift, the rotation and the
    ratio above were fitted beside — ``"shift"`` (the scan's shift and rotation only),
    ``"drift"`` (and a drift: one is seen), ``"tilt"`` (and a drift and a tilt: a tilt is
    seen) or ``"tilt_only"`` (and a tilt, where a drift cannot be told from the offset);
    tilt_registered : the robot scan's registration fitted its tilts (from the flange), so a
    tilt left in the robot term is the formed part's, not the scan's; rms_drift_pattern : m;
    rotation_model_error : rad, added to each end of both rotation intervals
    (:data:`ROTATION_MODEL_ERROR` over the pattern's RMS per radian)."""

    ratio: float
    ratio_ci: tuple[float, float]
    shift: F64
    shift_ci: tuple[float, float]
    shift_joint: F64
    shift_joint_ci: tuple[float, float]
    rotation: float | None
    rotation_ci: tuple[float, float] | None
    rotation_joint: float | None
    rotation_joint_ci: tuple[float, float] | None
    rms_vjm: float
    rms_shift_pattern: float
    rms_rotation_pattern: float
    joints_fitted: list[int] = field(default_factory=list)
    n_laps: int = 0
    drift: PatternFit | None = None
    drift_beside_tilt: PatternFit | None = None
    tilt: PatternFit | None = None
    tilt_alone: PatternFit | None = None
    drift_separable: float = 0.0
    drift_kappa: tuple[float, float] = (math.nan, math.nan)
    depth_max: float = 0.0
    model: str = "shift"
    tilt_registered: bool = True
    rms_drift_pattern: float = 0.0
    rotation_model_error: float = 0.0

    @property
    def shift_fit(self) -> PatternFit:
        """The shift as a :class:`PatternFit`."""
        return PatternFit(self.shift, self.shift_ci, self.shift_joint, self.shift_joint_ci)

    def drift_used(self) -> PatternFit | None:
        """The drift of the model the other estimates are beside (with the tilt when seen)."""
        return self.drift_beside_tilt if self.model == "tilt" else self.drift

    @property
    def tilted(self) -> bool:
        """A tilt of the formed part is seen (the other estimates are beside it)."""
        return self.model in ("tilt", "tilt_only")


def _widen(ci: tuple[float, float], e: float) -> tuple[float, float]:
    """A size's interval widened by ``e`` on each side, kept ≥ 0."""
    return max(ci[0] - e, 0.0), ci[1] + e


def _size_ci(boot: F64, est: F64) -> tuple[float, float]:
    """Interval of ``|s|`` from bootstrap replicates (n, k) of a vector ``s`` (k,): 0 at the
    low end when the replicates' 95 % ellipse holds the origin."""
    size = np.linalg.norm(boot, axis=1)
    lo, hi = _pct(size)
    cov = np.atleast_2d(np.cov(boot.T))
    try:
        d2 = float(est @ np.linalg.solve(cov, est))
    except np.linalg.LinAlgError:
        d2 = math.inf
    crit = {1: 3.84, 2: 5.99, 3: 7.81}.get(est.size, 9.49)
    if d2 < crit:
        lo = 0.0
    s = float(np.linalg.norm(est))
    return min(lo, s), max(hi, s)


def _separable(cols: F64, others: F64) -> float:
    """The smallest share (0–1) of the equilibrated ``cols`` (N, k) that the equilibrated
    ``others`` (N, m) do not explain: 0 when a column is a combination of the others."""

    def unit(a: F64) -> F64:
        nrm = np.linalg.norm(a, axis=0)
        return a / np.where(nrm > 0, nrm, 1.0)

    q, _ = np.linalg.qr(unit(others))
    c = unit(cols)
    return float(np.min(np.linalg.norm(c - q @ (q.T @ c), axis=0)))


def forming_time(point_time: F64 | None, n: int) -> F64:
    """(n,) each toolpath point's forming time normalised to [0, 1] over the run (0 at its
    first point, 1 at its last): from the log time at which the tool passed it (the alignment,
    pauses included — a drift keeps growing while the robot stands) when that is finite and
    non-decreasing, else the points' order along the path."""
    if point_time is not None and len(point_time) == n and n > 1:
        t = np.asarray(point_time, dtype=float)
        span = float(t[-1] - t[0]) if np.all(np.isfinite(t)) else math.nan
        if span > 0 and np.all(np.diff(t) >= 0):
            return (t - t[0]) / span
    return np.linspace(0.0, 1.0, n) if n > 1 else np.zeros(n)


def fit_robot_term(
    measured: F64,
    vjm: F64,
    per_joint: F64,
    normal: F64,
    contact: F64,
    valid: NDArray[np.bool_],
    lap: NDArray[Any],
    *,
    n_boot: int = N_BOOT_DIAG,
    seed: int = 1,
    tau: F64 | None = None,
    tilt_registered: bool = True,
) -> RobotTermFit | None:
    """Fit the measured normal robot term by one scale on the VJM and by one column per joint,
    each with a sideways shift and (where the geometry shows it) a rotation about work z.

    measured, vjm : (N,) m normal robot term and the VJM's (corrected forces); per_joint : (N, 6)
    m each joint's nominal share of ``vjm``; normal : (N, 3); contact : (N, 3) m work frame;
    valid : (N,) bool; lap : (N,). None with fewer than 20 points or 3 laps.

    ``tau`` (N,): each point's forming time over the run in [0, 1] (:func:`forming_time`). With
    it the fits are repeated with a sideways offset growing linearly in time, ``n_xy · d τ``
    (a thermal drift of the robot: a scan is one rigid snapshot, so an offset that grows with
    forming time is not the scan's), and once more with a tilt of the formed part about work x
    and y, ``n · (θ × p)``: on a step-down path forming time follows depth, and a tilt leaves
    a sideways offset growing with depth too. ``tilt_registered``: the robot scan's
    registration fitted its tilts (the flange), so such a tilt is not the scan's."""
    sel = (
        np.asarray(valid, bool)
        & np.isfinite(measured)
        & np.isfinite(vjm)
        & np.all(np.isfinite(per_joint), 1)
    )
    y, x, Aj, n, p, lp = (
        measured[sel],
        vjm[sel],
        per_joint[sel],
        normal[sel],
        contact[sel],
        np.asarray(lap)[sel],
    )
    inv, L = lap_index(lp)
    if y.size < 20 or L < 3 or not np.any(x):
        return None
    rot_col = np.einsum("ij,ij->i", n, np.cross([0.0, 0.0, 1.0], p))  # n · (ẑ × p), m/rad
    rho = float(np.sqrt(np.mean(np.sum(p[:, :2] ** 2, 1))))
    # a rotation is seen when its column is not ~0 nor ~ a combination of the others
    rot_seen = bool(np.sqrt(np.mean(rot_col**2)) > 0.02 * rho)
    shift_cols = n[:, :2]
    weights = boot_weights(L, n_boot, seed)
    ns = 2 + int(rot_seen)  # the scan's columns: the shift and, when seen, the rotation

    # one scale on the VJM without the scan's patterns (the scan taken as right)
    b0, B0 = _lap_ls(x[:, None], y, inv, L, weights)
    r0 = float(b0[0])
    # one column per joint that carries a share, the others at nominal; the joints' scales are
    # drawn towards the one scale ``r0`` where the path cannot separate them (ridge on the
    # equilibrated columns), the scan's patterns are not (a shift hidden among the joints'
    # patterns stays uncertain instead of being called zero)
    share = np.sqrt(np.mean(Aj**2, 0))
    share = share / share.sum() if share.sum() > 0 else share
    live = np.flatnonzero(share >= JOINT_SHARE)
    held = np.setdiff1d(np.arange(6), live)
    k = live.size
    yj = y - Aj[:, held].sum(axis=1)  # the others at nominal
    # the per-joint model's scale on the nominal prediction (linear in its joint scales)
    xx = float(x @ x)
    v = np.einsum("i,ij->j", x, Aj[:, live]) / xx
    c_held = float(x @ Aj[:, held].sum(axis=1)) / xx

    # the fits below share their columns: each (the same array object each time) summed per
    # lap once with each other (_LapSums)
    sums = _LapSums(inv, L)
    joint_cols = [Aj[:, i] for i in live]
    scan_cols = [shift_cols[:, 0], shift_cols[:, 1]] + ([rot_col] if rot_seen else [])

    def fits(extra: list[F64]) -> tuple[F64, F64, F64, F64]:
        """Both fits with the scan's patterns and the ``extra`` columns (each (N,), the same
        objects from fit to fit): (β, replicates) of the one scale's and of the per-joint fit."""
        S = scan_cols + extra
        one = [x, *S]
        b1, B1 = _lap_ls(np.column_stack(one), y, inv, L, weights, sums=sums, cols=one)
        per_joint = [*joint_cols, *S]
        Xj = np.column_stack(per_joint)
        prior = np.zeros(Xj.shape[1])
        prior[:k] = r0
        pen = np.zeros(Xj.shape[1])
        pen[:k] = JOINT_RIDGE**2
        bj, Bj = _lap_ls(
            Xj, yj, inv, L, weights, prior=prior, penalty=pen, sums=sums, cols=per_joint
        )
        return b1, B1, bj, Bj

    def pattern(f: tuple[F64, F64, F64, F64], i: int, err: float) -> PatternFit:
        """The two columns from the ``i``-th past the scan's of both fits in ``f``."""
        b1, B1, bj, Bj = f
        a, c = 1 + i, k + i
        return PatternFit(
            b1[a : a + 2],
            _widen(_size_ci(B1[:, a : a + 2], b1[a : a + 2]), err),
            bj[c : c + 2],
            _widen(_size_ci(Bj[:, c : c + 2], bj[c : c + 2]), err),
        )

    m1 = fits([])
    chosen, model = m1, "shift"
    drift = drift_t = tilt = tilt_alone = None
    separable, kappa = 0.0, (math.nan, math.nan)
    depth_max = float(max(-np.min(p[:, 2]), 0.0))  # the deepest analysed point below the flange
    t = None if tau is None else np.asarray(tau, dtype=float)[sel]
    if t is not None:
        drift_cols = n[:, :2] * t[:, None]
        tilt_cols = np.column_stack(
            [np.einsum("ij,ij->i", n, np.cross(e, p)) for e in ([1.0, 0, 0], [0, 1.0, 0])]
        )
        separable = _separable(drift_cols, np.column_stack([x, shift_cols]))
        # a drift d seen as a constant offset over the analysed laps: κ d (κ the forming time
        # the offset's columns weigh, per axis)
        kappa = (
            float(np.sum(shift_cols[:, 0] ** 2 * t) / max(np.sum(shift_cols[:, 0] ** 2), 1e-300)),
            float(np.sum(shift_cols[:, 1] ** 2 * t) / max(np.sum(shift_cols[:, 1] ** 2), 1e-300)),
        )
        drift_c = [drift_cols[:, 0], drift_cols[:, 1]]
        tilt_c = [tilt_cols[:, 0], tilt_cols[:, 1]]
        m4 = fits(tilt_c)  # a tilt beside the offset, no drift
        tilt_alone = pattern(m4, ns, TILT_MODEL_ERROR)
        # a tilt is seen beyond its limit, as the sideways offset it makes at the deepest point
        lim_t, lever = DETECTION_LIMITS["work_object_tilt"], depth_max * 1e3
        tilt_seen = tilt_alone.verdict(lim_t, lever) == "fault"
        if separable >= DRIFT_SEPARABLE:
            m2 = fits(drift_c)
            m3 = fits(drift_c + tilt_c)
            drift = pattern(m2, ns, SHIFT_MODEL_ERROR)
            drift_t = pattern(m3, ns, SHIFT_MODEL_ERROR)
            tilt = pattern(m3, ns + 2, TILT_MODEL_ERROR)
            # the shift, the rotation and the ratio are taken beside the patterns the data
            # hold: a tilt when one is seen beside a drift, a drift when one is (a drift's
            # column widens the shift's interval: on a clean cell the shift is fitted without
            # it, as before)
            if tilt.verdict(lim_t, lever) == "fault":
                chosen, model = m3, "tilt"
            elif drift.verdict(DETECTION_LIMITS["thermal_drift"]) == "fault":
                chosen, model = m2, "drift"
        elif tilt_seen:
            # forming time varies too little over the analysed laps to tell a drift from a
            # constant offset (it is one there), but depth does: a tilt beside the offset
            tilt = tilt_alone
            chosen, model = m4, "tilt_only"
    b1, B1, bj, Bj = chosen
    r1 = float(b1[0])
    r_joint = float(v @ bj[:k]) + c_held
    rj_boot = Bj[:, :k] @ v + c_held
    s1, sj = b1[1:3], bj[k : k + 2]
    s1_ci = _widen(_size_ci(B1[:, 1:3], s1), SHIFT_MODEL_ERROR)
    sj_ci = _widen(_size_ci(Bj[:, k : k + 2], sj), SHIFT_MODEL_ERROR)
    lim = DETECTION_LIMITS["scan_shift"]
    shifted = verdict(s1_ci[0] * 1e3, s1_ci[1] * 1e3, lim) == "fault" and (
        verdict(sj_ci[0] * 1e3, sj_ci[1] * 1e3, lim) == "fault"
    )
    seen = shifted or model != "shift"  # a drift or a tilt is chosen only when seen
    # model error: the interval spans the competing fits — the per-joint fit, and the one scale
    # with the patterns when both fits see one, else without them
    cands = [(r_joint, _pct(rj_boot)), (r1, _pct(B1[:, 0])) if seen else (r0, _pct(B0[:, 0]))]
    est = r1 if seen else r0
    lo = min(min(c[0], c[1][0]) for c in cands)
    hi = max(max(c[0], c[1][1]) for c in cands)
    ratio_ci = (lo - RATIO_MODEL_ERROR * est, hi + RATIO_MODEL_ERROR * est)
    rot = rot_ci = rotj = rotj_ci = None
    rot_err = 0.0
    if rot_seen:
        # the direction of travel's pattern (ROTATION_MODEL_ERROR), per radian of rotation
        rot_err = ROTATION_MODEL_ERROR / float(np.sqrt(np.mean(rot_col**2)))
        rot = float(b1[3])
        lo_r, hi_r = _pct(B1[:, 3])
        rot_ci = (min(lo_r, rot) - rot_err, max(hi_r, rot) + rot_err)
        rotj = float(bj[k + 2])
        lo_r, hi_r = _pct(Bj[:, k + 2])
        rotj_ci = (min(lo_r, rotj) - rot_err, max(hi_r, rotj) + rot_err)
    d_used = drift_t if model == "tilt" else drift
    rms_drift = 0.0
    if d_used is not None and t is not None:
        rms_drift = float(np.sqrt(np.mean((shift_cols @ d_used.one * t) ** 2)))
    return RobotTermFit(
        ratio=est,
        ratio_ci=ratio_ci,
        shift=s1,
        shift_ci=s1_ci,
        shift_joint=sj,
        shift_joint_ci=sj_ci,
        rotation=rot,
        rotation_ci=rot_ci,
        rotation_joint=rotj,
        rotation_joint_ci=rotj_ci,
        rms_vjm=float(np.sqrt(np.mean(x**2))),
        rms_shift_pattern=float(np.sqrt(np.mean((shift_cols @ s1) ** 2))),
        rms_rotation_pattern=float(np.sqrt(np.mean((rot_col * (rot or 0.0)) ** 2))),
        joints_fitted=[int(i) + 1 for i in live],
        n_laps=L,
        drift=drift,
        drift_beside_tilt=drift_t,
        tilt=tilt,
        tilt_alone=tilt_alone,
        drift_separable=separable,
        drift_kappa=kappa,
        depth_max=depth_max,
        model=model,
        tilt_registered=tilt_registered,
        rms_drift_pattern=rms_drift,
        rotation_model_error=rot_err,
    )


# --------------------------------------------------------------------------------------------
# the findings


@dataclass(frozen=True)
class Diagnosis:
    """Every suspect's :class:`Finding`, the sensor and robot-term fits behind them."""

    findings: list[Finding]
    sensor: SensorFit | None
    robot: RobotTermFit | None
    #: the robot's corrected tip wrench was used for the robot term (the sensor was at fault)
    forces_corrected: bool

    def to_list(self) -> list[dict[str, Any]]:
        return [f.to_dict() for f in self.findings]

    def by_suspect(self) -> dict[str, Finding]:
        return {f.suspect: f for f in self.findings}

    def scan_pattern(self, normal: F64, contact: F64) -> F64 | None:
        """(N,) m — the normal deviation the scan's faults put on the robot part: ``n · s`` for
        a shift and ``θ n · (ẑ × p)`` for a rotation, each only when its verdict is ``fault``
        (None when neither is). ``normal``, ``contact`` (N, 3) work frame."""
        f = self.by_suspect()
        rf = self.robot
        if rf is None:
            return None
        out = np.zeros(len(normal))
        hit = False
        if f["scan_shift"].verdict == "fault":
            out += normal[:, :2] @ rf.shift
            hit = True
        if f["scan_rotation"].verdict == "fault" and rf.rotation is not None:
            rot_col = np.einsum("ij,ij->i", normal, np.cross([0.0, 0.0, 1.0], contact))
            out += rf.rotation * rot_col
            hit = True
        return out if hit else None

    def offset_pattern(self, normal: F64, contact: F64) -> F64 | None:
        """(N,) m — the normal deviation of the sideways offset ``n · s`` and of the turn about
        the part axis ``θ n · (ẑ × p)`` the robot term holds beyond their limits but the study
        cannot attribute (:func:`offset_seen`): the robot scan's registration (the part is right
        there) or the robot's work object (the part formed so). None when neither is seen (or
        the scan's verdict is a ``fault``: then it is in :meth:`scan_pattern`)."""
        rf = self.robot
        if rf is None or model_off(rf):  # the robot's own compliance may carry it as well
            return None
        f = self.by_suspect()
        shift, turned = offset_seen(rf)
        shift = shift and f["scan_shift"].verdict != "fault"
        turned = turned and f["scan_rotation"].verdict != "fault" and rf.rotation is not None
        # a tilt seen where the scan's registration did not fit the tilts: the scan's or the
        # work object's as well
        tilted = rf.tilted and not rf.tilt_registered
        if not (shift or turned or tilted):
            return None
        out = normal[:, :2] @ rf.shift if shift else np.zeros(len(normal))
        if turned:
            assert rf.rotation is not None
            out = out + rf.rotation * np.einsum(
                "ij,ij->i", normal, np.cross([0.0, 0.0, 1.0], contact)
            )
        if tilted:
            out = out + self._tilt_pattern(normal, contact)
        return out

    def _tilt_pattern(self, normal: F64, contact: F64) -> F64:
        """(N,) m — ``n · (θ × p)`` of the tilt the fit found (zero when none)."""
        rf = self.robot
        out = np.zeros(len(normal))
        if rf is not None and rf.tilted and rf.tilt is not None:
            for a, e in zip(rf.tilt.one, ([1.0, 0, 0], [0, 1.0, 0]), strict=True):
                out += a * np.einsum("ij,ij->i", normal, np.cross(e, contact))
        return out

    def drift_pattern(self, normal: F64, tau: F64) -> F64 | None:
        """(N,) m — the normal deviation of the thermal drift ``n_xy · d τ`` when its verdict is
        ``fault`` (the formed part's: compensate corrects it), else None. ``tau`` (N,) the
        points' forming time in [0, 1] (:func:`forming_time`)."""
        rf = self.robot
        d = None if rf is None else rf.drift_used()
        if d is None or self.by_suspect()["thermal_drift"].verdict != "fault":
            return None
        return (normal[:, :2] @ d.one) * np.asarray(tau, dtype=float)

    def beside_stiffness(self, normal: F64, contact: F64, tau: F64 | None) -> F64 | None:
        """(N,) m — every pattern the robot term's fit found beside the robot's compliance (a
        scan's fault, the unattributed offset, a drift at fault, a tilt seen): what the
        identification of the robot's stiffness leaves out. None when there is none."""
        parts = [self.scan_pattern(normal, contact), self.offset_pattern(normal, contact)]
        rf = self.robot
        if tau is not None:
            parts.append(self.drift_pattern(normal, tau))
        if rf is not None and rf.tilted and rf.tilt_registered and not model_off(rf):
            parts.append(self._tilt_pattern(normal, contact))
        got = [p for p in parts if p is not None]
        return sum(got[1:], got[0]) if got else None


def _finding(
    suspect: str,
    est: float | None,
    ci: tuple[float, float] | None,
    unit: str,
    text: str,
    todo: str,
    *,
    force: str | None = None,
    parts: tuple[Part, ...] = (),
) -> Finding:
    """A suspect's finding. ``text`` may quote the finding's numbers by placeholder — ``{est}``,
    ``{ci}`` (``[lo, hi]``) and ``{est:NAME}``, ``{ci:NAME}`` for the part ``NAME`` — which are
    formatted here from the values summary.json holds (:data:`PRECISION`): the text cannot say
    another number than the JSON."""
    limits = DETECTION_LIMITS[suspect]
    if est is None or ci is None:
        v = "cannot_tell"
        lo = hi = None
    else:
        lo, hi = ci
        v = force or verdict(lo, hi, limits)
    f = Finding(suspect, v, est, lo, hi, unit, "", "", limits, tuple(parts))
    text = _fill(text, f.to_dict())
    label = suspect.replace("_", " ")
    if v == "fault":
        head = f"{label}: FAULT — {_first_clause(text)}; {todo}"
    elif v == "ok":
        head = f"{label}: ok"
    else:
        head = f"{label}: cannot tell — {_first_clause(text)}"
    return replace(f, explanation=text, headline=head)


def _num(suspect: str, v: float | None, *, signed: bool = False, scaled: bool = True) -> str:
    """``v`` (summary.json's unit) as the report prints it for ``suspect`` (its decimals and
    display unit; a small real value keeps two significant digits, never "-0.00")."""
    return diagnosis_number(suspect, v, signed=signed, scaled=scaled, none="n/a")


_PLACEHOLDER = re.compile(r"\{(est|ci)(?::([a-z_]+))?\}")


def _fill(text: str, d: dict[str, Any]) -> str:
    """``text`` with its placeholders (:func:`_finding`) replaced by the numbers of ``d`` (a
    finding's summary.json entry) at the suspect's precision."""
    suspect = d["suspect"]
    parts = {p["name"]: p for p in d.get("parts", [])}

    def one(m: re.Match[str]) -> str:
        what, name = m.group(1), m.group(2)
        src = d if name is None else parts[name]
        sg = bool(src.get("signed", False))
        sc = name is None or src.get("unit") is None  # a part in its own unit: as it is
        if what == "est":
            return _num(suspect, src["estimate"], signed=sg, scaled=sc)
        lo = _num(suspect, src["ci_low"], signed=sg, scaled=sc)
        return f"[{lo}, {_num(suspect, src['ci_high'], signed=sg, scaled=sc)}]"

    return _PLACEHOLDER.sub(one, text)


def _first_clause(text: str) -> str:
    """``text`` up to its first ``;`` outside brackets (a ``;`` inside an interval's parenthesis
    does not end the clause, so the headline keeps its brackets balanced)."""
    depth = 0
    for i, ch in enumerate(text):
        if ch in "([":
            depth += 1
        elif ch in ")]":
            depth = max(0, depth - 1)
        elif ch == ";" and depth == 0:
            return text[:i]
    return text


def _unknown(suspects: tuple[str, ...], why: str) -> list[Finding]:
    """``cannot_tell`` without an estimate for each of ``suspects``, saying ``why``."""
    return [_finding(s, None, None, UNITS[s], why, "") for s in suspects]


def sensor_findings(
    sf: SensorFit | None, R: float, unloaded: UnloadedEvidence | None = None
) -> list[Finding]:
    """force_gain, force_moment_crosstalk, force_bias, force_crosstalk from the sensor fit
    (None: no fit; then ``unloaded``, the logs at rest, still tells the bias)."""
    if sf is None:
        why = "fewer than 6 used laps to compare the flange sensor with the CNC dynamometer"
        out = _unknown(("force_gain", "force_moment_crosstalk"), why)
        if unloaded is None:
            return out + _unknown(("force_moment_bias", "force_bias", "force_crosstalk"), why)
        # no contact arm without the fit: the forming force's moment at a stretch on the path
        # is within the ball's diameter of the tip
        return [
            *out,
            _moment_bias_at_rest(unloaded, *unloaded.moment_offset(1.0, np.zeros(3), 2 * R)),
            _static_bias_finding(unloaded, 1.0, None),
            *_unknown(("force_crosstalk",), why),
        ]
    g = sf.gain
    gain_text = (
        "the flange sensor reads {est}× the CNC dynamometer's force on the same path (95 % "
        "{ci}, deeper half of the laps; the shallow half differs by "
        f"{sf.process_gap:+.1%}, the processes' own difference, added to the interval); "
        "largest force crosstalk "
        f"{_num('force_crosstalk', sf.force_crosstalk)} {diagnosis_unit('force_crosstalk', '1')}"
    )
    ct_finding, mb_finding = _moment_findings(sf, R)
    b = sf.b
    bias_limits = DETECTION_LIMITS["force_bias"]
    v_b = verdict(sf.bias_ci[0], sf.bias_ci[1], bias_limits)
    v_ba = verdict(sf.bias_axial_ci[0], sf.bias_axial_ci[1], bias_limits)
    bias_text = (
        f"a constant {_vec(b)} (work axes; its size {{est}} N, 95 % {{ci}}) between the flange "
        "sensor's and the dynamometer's tip forces, the gain fitted beside it; an untared sensor "
        "or the tool's weight below the sensor"
    )
    bias_force = None
    bias_ci = sf.bias_ci
    if sf.unloaded is not None:
        # the logs at rest tell the static offset apart from what the load brings
        bias_finding = _static_bias_finding(sf.unloaded, sf.gain, sf)
        xt_finding = _axial_crosstalk_finding(sf)
    # no constant on this path (ok) rules out both; a constant may be either
    elif v_b == "fault" and v_ba != "fault":
        bias_force = "cannot_tell"
        bias_ci = (min(sf.bias_ci[0], sf.bias_axial_ci[0]), max(sf.bias_ci[1], sf.bias_axial_ci[1]))
        cx, cy = sf.axial_crosstalk
        bias_text += (
            f"; or crosstalk of the axial force into the lateral channels ({cx:+.3f}, {cy:+.3f}) "
            f"with a constant of {sf.bias_axial:.1f} N: the path's axial force varies too little "
            "to tell them apart (either way the analysis removed the constant)"
        )
    if sf.unloaded is None:
        bias_finding = _finding(
            "force_bias",
            sf.bias,
            bias_ci,
            "N",
            bias_text,
            BIAS_ACTION,
            force=bias_force,
        )
        xt_finding = _axial_crosstalk_unseen(sf, v_b)
    return [
        _finding(
            "force_gain",
            g,
            sf.gain_ci,
            "1",
            gain_text,
            "recalibrate the flange sensor (the analysis used forces divided by the gain)",
        ),
        ct_finding,
        mb_finding,
        bias_finding,
        xt_finding,
    ]


CT_ACTION = "check the sensor's calibration matrix (the analysis used the point-contact moment)"
MB_ACTION = "tare the sensor with the tool mounted (the analysis used the point-contact moment)"


def _moment_findings(sf: SensorFit, R: float) -> tuple[Finding, Finding]:
    """force_moment_crosstalk and force_moment_bias from the false tip moment ``C F_xy + m₀``:
    what follows the force is crosstalk; the constant ``m₀`` needs the logs at rest — there a
    bias reads without load, crosstalk does not (it scales with the force). Without them the
    constant (beyond what the force constant makes up the arm) is crosstalk of the nearly
    constant axial force or a moment bias: both ``cannot_tell`` when it matters, naming each
    other. A moment bias was called crosstalk FAULT 6.05 mm (a clean cone, 3.6 N·m of bias)."""
    cm = sf.moment_crosstalk * 1e3
    clo, chi = (v * 1e3 for v in sf.moment_crosstalk_ci)
    cp = sf.moment_proportional * 1e3
    plo, phi = (v * 1e3 for v in sf.moment_proportional_ci)
    bound = (
        "beyond the point-contact moment (contact − tip) × F, whose size is at most R·|F| "
        f"(R = {R * 1e3:.1f} mm)"
    )
    whole_text = (
        "the whole false moment, {est:whole} mm ({ci:whole}; "
        f"{sf.moment_excess:.0%} of that bound)"
    )
    whole = Part("whole", cm, clo, chi)
    lim_ct = DETECTION_LIMITS["force_moment_crosstalk"]
    if sf.moment_load is not None and sf.moment_load_ci is not None:
        assert sf.unloaded is not None and sf.static_moment is not None
        ml = sf.moment_load * 1e3
        mlo, mhi = (v * 1e3 for v in sf.moment_load_ci)
        ct = _finding(
            "force_moment_crosstalk",
            ml,
            (mlo, mhi),
            "mm",
            "the moment channels carry {est} mm (N·m per kN) of false tip moment per unit force "
            "that the load brings (95 % {ci}) " + bound + f"; {whole_text}, also holds what the "
            f"sensor reads with the tool off the sheet ({_mvec(sf.static_moment)} at the tip "
            "beyond its reading's point-contact moment), which needs no load and is no crosstalk "
            "(force_moment_bias, force_bias)"
            + (
                f"; nor is the {sf.moment_carried * 1e3:.2f} mm that the axial force's crosstalk "
                "into the lateral force channels (force_crosstalk) makes carried up the "
                f"{float(np.linalg.norm(sf.lever)) * 1e3:.0f} mm arm from the sensor to the tip"
                if sf.moment_carried > 0 and sf.lever is not None
                else ""
            ),
            CT_ACTION,
            parts=(whole,),
        )
        assert sf.moment_bias is not None and sf.moment_bias_se is not None
        return ct, _moment_bias_at_rest(sf.unloaded, sf.moment_bias, sf.moment_bias_se)
    # the path alone: what follows the force is crosstalk for sure; the constant beyond what
    # the force constant makes up the arm may be crosstalk of the axial force or a moment bias
    ulo, uhi = (v * 1e3 for v in sf.moment_upper_ci)
    follows = Part("follows_force", cp, plo, phi)
    upper = Part("with_constant", sf.moment_upper * 1e3, ulo, uhi)
    ci = (plo, max(phi, uhi))
    v_ct = verdict(ci[0], ci[1], lim_ct)
    text = (
        "the moment channels carry {est} mm (N·m per kN) of false tip moment per unit force "
        "that follows the lateral force, at least (95 % {ci}, up to {est:with_constant} mm "
        "with the constant false moment) " + bound + f"; {whole_text}"
    )
    mc = sf.moment_constant
    mc_ci = sf.moment_constant_ci
    v_mb = verdict(mc_ci[0], mc_ci[1], DETECTION_LIMITS["force_moment_bias"])
    apart = (
        "; the constant false moment, {mc} N·m beyond what the force constant makes up the arm "
        "from the sensor, is crosstalk of the axial force into the moment channels (it barely "
        "varies along a wall) or a bias of the moment channels: without a stretch of the log "
        "at rest (the tool off the sheet, untared) the two cannot be told apart "
        "(force_moment_crosstalk, force_moment_bias)"
    )
    ct_force = None
    if v_ct == "cannot_tell" and verdict(plo, phi, lim_ct) != "cannot_tell":
        text += apart.replace("{mc}", _num("force_moment_bias", mc))
        ct_force = "cannot_tell"
    ct = _finding(
        "force_moment_crosstalk",
        cp,
        ci,
        "mm",
        text,
        CT_ACTION,
        force=ct_force,
        parts=(follows, upper, whole),
    )
    mb_text = (
        "a constant false tip moment of {est} N·m (95 % {ci}) beyond what the force constant "
        "makes up the arm from the sensor to the tip"
    )
    mb_force = None
    if v_mb != "ok":
        mb_force = "cannot_tell"
        mb_text += (
            ": a bias of the moment channels, or crosstalk of the axial force into them (it "
            "barely varies along a wall): without a stretch of the log at rest (the tool off "
            "the sheet, untared) the two cannot be told apart (force_moment_bias, "
            "force_moment_crosstalk)"
        )
    mb = _finding("force_moment_bias", mc, mc_ci, "N·m", mb_text, MB_ACTION, force=mb_force)
    return ct, mb


def _moment_bias_at_rest(u: UnloadedEvidence, mu: F64, se: F64) -> Finding:
    """force_moment_bias from the logs at rest: what the moment channels read of their own with
    the tool off the sheet, ``mu`` (3,) N·m and its standard error ``se``
    (:meth:`UnloadedEvidence.moment_offset`)."""
    ci = size_interval(mu, se)
    text = (
        f"with the tool off the sheet ({u.where} of the log) the moment channels read "
        f"{_mvec(mu)} of their own (about the sensor's origin, work axes, beyond what the "
        "force there makes; its size {est} N·m, 95 % {ci}): a moment that needs no load is no "
        "crosstalk (that scales with the force) — a bias of the moment channels, or the "
        "tool's weight acting off the sensor's axis"
    )
    return _finding("force_moment_bias", float(np.linalg.norm(mu)), ci, "N·m", text, MB_ACTION)


#: The suspects of the flange sensor's moment channels.
MOMENT_SUSPECTS = ("force_moment_crosstalk", "force_moment_bias")


def _no_moment_channels(suspect: str) -> Finding:
    """A moment suspect of a force log without moment channels: nothing to be off. (Its tip
    moments are the point-contact moment; compared with a reading at rest they made a force
    bias carried up the arm look like 10.6 mm of moment crosstalk.)"""
    text = (
        "the flange sensor's log has no moment channels: the analysis takes the point-contact "
        "moment (contact − tip) × F for the tip moment, so no moment channel can be off"
    )
    return _finding(suspect, 0.0, (0.0, 0.0), UNITS[suspect], text, "")


def _mvec(v: F64) -> str:
    """A moment vector (3,) N·m as the explanations print it: the moment bias's numbers
    (:func:`~roboisf.report.statements.diagnosis_number`: a real small component keeps two
    significant digits, a floating-point zero reads 0.00, never "-0.00")."""
    c = ", ".join(diagnosis_number("force_moment_bias", float(x), signed=True) for x in v[:3])
    return f"({c}) N·m"


#: The relative force difference of the two processes allowed for a stretch on the path (the
#: rim, which the sensor fit's laps leave out): the virtual cell's robot forms its rim with 6 %
#: less force than the CNC; doubled, as the fit's gain interval widens its own difference.
RIM_PROCESS_GAP = 0.12

BIAS_ACTION_UNFITTED = (
    "tare the sensor with the tool mounted, or declare tool_mass (not removed: too few laps to "
    "fit the forces against the dynamometer)"
)
BIAS_ACTION = (
    "tare the sensor with the tool mounted, or declare tool_mass (the analysis removed it)"
)
XT_ACTION = "check the sensor's calibration matrix (the analysis removed the axial force's share)"


def _vec(v: F64) -> str:
    """A force vector (3,) N as the explanations print it: the force bias's numbers (a real
    small component keeps two significant digits, no "-0.0")."""
    c = ", ".join(diagnosis_number("force_bias", float(x), signed=True) for x in v[:3])
    return f"({c}) N"


def _static_bias_finding(u: UnloadedEvidence, gain: float, sf: SensorFit | None) -> Finding:
    """force_bias from the logs at rest: the flange sensor's reading with the tool off the sheet
    beyond the dynamometer's (a constant that does not need the load)."""
    if sf is not None and sf.static_b is not None and sf.static_bias_ci is not None:
        b_s, ci = sf.static_b, sf.static_bias_ci
    else:
        b_s, se = u.static_offset(gain)
        ci = size_interval(b_s, se)
    text = (
        f"with the tool off the sheet ({u.where} of the log) the flange sensor reads "
        f"{_vec(u.robot)} at the tip (work axes)"
    )
    text += (
        f", the dynamometer {_vec(u.cnc)}: a static offset of {_vec(b_s)} between them (its "
        "size {est} N, 95 % {ci})"
        + (
            " (both forming there: the processes' own force difference is in its interval)"
            if u.on_path
            else ""
        )
        if u.cnc_seen
        else " (its size {est} N, 95 % {ci}; the dynamometer's log has no unloaded stretch: its "
        "zero is taken as right)"
    )
    text += "; an untared sensor or the tool's weight below the sensor"
    if math.isfinite(u.drift) and u.drift > BIAS_DRIFT:
        text += f"; its zero drifts: start and end differ by {u.drift:.1f} N (in the interval)"
    if sf is not None:
        text += (
            f"; while forming, the fitted constant is {_vec(sf.b)}, the static offset and what "
            "the load adds (force_crosstalk)"
        )
    # removed only where a sensor fit corrects the forces (with fewer than 6 laps it cannot)
    action = BIAS_ACTION if sf is not None else BIAS_ACTION_UNFITTED
    return _finding("force_bias", float(np.linalg.norm(b_s)), ci, "N", text, action)


#: A start–end difference of the flange sensor at rest above this [N] is said as a drift.
BIAS_DRIFT = 2.0


def _axial_crosstalk_finding(sf: SensorFit) -> Finding:
    """force_crosstalk with the constant held at the static offset."""
    assert sf.axial_fixed is not None and sf.axial_fixed_ci is not None
    cx, cy = sf.axial_fixed
    text = (
        "beyond the static offset, the lateral channels read {est} N/kN (95 % {ci}) "
        f"of the axial force (x {_num('force_crosstalk', cx, signed=True)}, "
        f"y {_num('force_crosstalk', cy, signed=True)}, work axes; {sf.axial_force:.0f} N RMS "
        "axial force): crosstalk of the axial force into the lateral channels — along a wall it "
        "is a near-constant lateral force that only the logs at rest tell from a bias"
    )
    return _finding("force_crosstalk", math.hypot(cx, cy), sf.axial_fixed_ci, "1", text, XT_ACTION)


def _axial_crosstalk_unseen(sf: SensorFit, v_b: str) -> Finding:
    """force_crosstalk without the logs at rest: no constant on the path rules it out (it would
    make one); a constant may be it or a bias."""
    Fz = max(sf.axial_force, 1e-300)
    if v_b == "ok":
        hi = sf.bias_ci[1] / Fz
        text = (
            f"no constant between the two sensors on this path (|b| ≤ {sf.bias_ci[1]:.1f} N), "
            "so the axial force's crosstalk into the lateral channels lies in {ci} N/kN "
            f"({sf.axial_force:.0f} N RMS axial force)"
        )
        return _finding("force_crosstalk", sf.bias / Fz, (0.0, hi), "1", text, XT_ACTION)
    text = (
        f"a constant of {sf.bias:.1f} N between the sensors on this path may be the axial "
        "force's crosstalk into the lateral channels ({est} N/kN, 95 % {ci}) or a "
        "bias: the path's axial force varies too little to tell, and the logs have no unloaded "
        "stretch to read the sensor at rest (either way the analysis removed the constant)"
    )
    # the estimate: all of the constant read as crosstalk (the free fit of both is degenerate
    # along a wall: its crosstalk could fall outside this interval)
    return _finding(
        "force_crosstalk",
        sf.bias / Fz,
        (0.0, sf.bias_ci[1] / Fz),
        "1",
        text,
        XT_ACTION,
        force="cannot_tell",
    )


#: The suspects the robot term's pattern gives a verdict on (:func:`robot_findings`): the
#: stiffness and every suspect :data:`SUSPECTS` lists after the force sensor's.
ROBOT_TERM_SUSPECTS = ("robot_stiffness", *SUSPECTS[SUSPECTS.index("scan_shift") :])
#: Why the study's files cannot tell the robot scan's registration from the robot's work object
#: (docs/diagnosis.md, "What separates what").
OFFSET_WHY = (
    "the fixture registration fits z and the tilts from the flange only, the joint logs follow "
    "the controller's work object (a wrong one too), and the CNC part's scan is another "
    "placement of the scanner"
)
#: What tells them apart, in a few words (the headline's).
OFFSET_SHORT = "check the scan's reference marks, or measure the work object"
#: What tells them apart, and what to do meanwhile.
OFFSET_CHECK = (
    "check the robot scan's reference marks (a lateral registration on the fixture) or measure "
    "the robot's work object, then compensate with --offset scan (only the scan is misplaced: "
    "left out of the correction) or --offset part (the robot formed it so: corrected)"
)


def _rotation_sizes(
    rf: RobotTermFit,
) -> tuple[float, tuple[float, float], float, tuple[float, float]] | None:
    """The rotation about the part axis in degrees: the one-scale fit's estimate and interval,
    the per-joint fit's estimate and the size's interval over both (None when not seen)."""
    if rf.rotation is None or rf.rotation_ci is None:
        return None
    r1 = math.degrees(rf.rotation)
    ci1 = (math.degrees(rf.rotation_ci[0]), math.degrees(rf.rotation_ci[1]))
    rj = math.degrees(rf.rotation_joint or 0.0)
    cij = tuple(math.degrees(v) for v in (rf.rotation_joint_ci or (math.nan, math.nan)))
    ci = (min(ci1[0], cij[0]), max(ci1[1], cij[1]))
    # the size's interval (a signed angle: |θ| within [0, max |end|] when it spans 0)
    lo_abs = 0.0 if ci[0] <= 0 <= ci[1] else min(abs(ci[0]), abs(ci[1]))
    hi_abs = max(abs(ci[0]), abs(ci[1]))
    return r1, ci1, rj, (lo_abs, hi_abs)


def _rotation_joint_ci(rf: RobotTermFit) -> tuple[float, float]:
    """The per-joint fit's signed rotation interval in degrees (nan when not seen)."""
    c = rf.rotation_joint_ci or (math.nan, math.nan)
    return math.degrees(c[0]), math.degrees(c[1])


def offset_seen(rf: RobotTermFit) -> tuple[bool, bool]:
    """Whether the robot term holds a sideways offset and a rotation about the part axis beyond
    their detection limits (both fits agree): the robot scan's registration or the robot's work
    object, which the study's files cannot tell apart."""
    shift = rf.shift_fit.verdict(DETECTION_LIMITS["scan_shift"]) == "fault"
    rot = _rotation_sizes(rf)
    turned = rot is not None and (
        verdict(rot[3][0], rot[3][1], DETECTION_LIMITS["scan_rotation"]) == "fault"
    )
    return shift, turned


def _offset_findings(rf: RobotTermFit, *, axisymmetric: bool) -> list[Finding]:
    """scan_shift, work_object and scan_rotation: a sideways offset (or a turn about the part
    axis) of the robot part is the robot scan's registration — the part is right, its
    measurement misplaced — or the robot's work object — the part formed displaced. Seen beyond
    its limit it is ``cannot_tell`` for both, never a ``fault`` of one."""
    sf = rf.shift_fit
    s1, sj = sf.one * 1e3, sf.joint * 1e3
    c1 = (sf.one_ci[0] * 1e3, sf.one_ci[1] * 1e3)
    cj = (sf.joint_ci[0] * 1e3, sf.joint_ci[1] * 1e3)
    lim = DETECTION_LIMITS["scan_shift"]
    v1, vj = verdict(c1[0], c1[1], lim), verdict(cj[0], cj[1], lim)
    ci = sf.ci()
    beside = {
        "shift": "",
        "drift": " (a drift over the run fitted beside it)",
        "tilt": " (a drift and a tilt of the formed part fitted beside it)",
        "tilt_only": " (a tilt of the formed part fitted beside it)",
    }[rf.model]
    shift_parts = [
        Part("one_scale", float(np.linalg.norm(s1)), c1[0], c1[1]),
        Part("per_joint", float(np.linalg.norm(sj)), cj[0], cj[1]),
    ]
    fitted = (
        "the robot term carries the pattern of a sideways offset of {est:one_scale} mm "
        f"(x {s1[0]:+.3f}, y {s1[1]:+.3f}; 95 % of its size {{ci:one_scale}} mm) beside one "
        "stiffness scale, and {est:per_joint} mm ({ci:per_joint}) beside a per-joint fit" + beside
    )
    est = float(np.linalg.norm(s1 if v1 == vj else sj))
    shift_seen, turned = offset_seen(rf)
    if shift_seen:
        shift_text = (
            "a sideways offset of the robot part of {est} mm {ci}: "
            "the robot scan's registration or the robot's work object — cannot tell apart from "
            f"these files ({OFFSET_SHORT}); {fitted}; {OFFSET_WHY}; {OFFSET_CHECK}"
        )
    elif v1 == vj:
        shift_text = fitted
    else:
        shift_text = (
            f"{fitted}; the two explanations disagree: an offset of {{est:one_scale}} mm "
            f"(RMS {rf.rms_shift_pattern * 1e3:.3f} mm of normal deviation) with one stiffness "
            "scale, or joint stiffness errors that differ joint by joint with an offset of "
            "{est:per_joint} mm; an offset would be the robot scan's registration or "
            "the robot's work object alike"
        )
    if shift_seen and rf.tilt_alone is not None and rf.drift is None:
        shift_text += (
            "; on this path a thermal drift of the robot reads as a constant offset too "
            "(thermal_drift)"
        )
    v_shift = "cannot_tell" if shift_seen or v1 != vj else v1
    out = [
        _finding(
            "scan_shift", est, ci, "mm", shift_text, "", force=v_shift, parts=tuple(shift_parts)
        ),
    ]
    rot = _rotation_sizes(rf)
    if rot is None:
        why = (
            "the part is a surface of revolution: a rotation of the scan about its axis moves no "
            "point off the surface, so it can be neither seen nor matter"
            if axisymmetric
            else "the geometry does not show a rotation about the part axis apart from the "
            "other patterns"
        )
        rot_finding = _finding("scan_rotation", None, None, "deg", why, "")
    else:
        r1, ci1, rj, size_ci = rot
        cij = _rotation_joint_ci(rf)
        rot_parts = (
            Part("one_scale", r1, ci1[0], ci1[1], signed=True),
            Part("per_joint", rj, cij[0], cij[1], signed=True),
        )
        rot_fitted = (
            "the robot term carries the pattern of a rotation about the part axis of "
            "{est:one_scale}° (95 % {ci:one_scale}°; {est:per_joint}° ({ci:per_joint}°) beside a "
            "per-joint fit; each interval widened by "
            f"±{math.degrees(rf.rotation_model_error):.3f}° for the pattern the direction of "
            "travel leaves, the walls passed in one rotational sense), RMS "
            f"{rf.rms_rotation_pattern * 1e3:.3f} mm of normal deviation"
        )
        rot_text = rot_fitted
        if turned:
            rot_text = (
                "the robot part is turned about the part axis by {est:one_scale}° ({est}° in "
                "size, 95 % {ci}°): the robot scan's registration "
                f"or the robot's work object turned — cannot tell apart from these files "
                f"({OFFSET_SHORT}); {rot_fitted}; {OFFSET_WHY}; {OFFSET_CHECK}"
            )
        rot_finding = _finding(
            "scan_rotation",
            abs(r1),
            size_ci,
            "deg",
            rot_text,
            "",
            force="cannot_tell" if turned else None,
            parts=rot_parts,
        )
    # the work object: the same offset (and turn), read as the part's
    if shift_seen or turned:
        seen = []
        if shift_seen:
            seen.append("a sideways offset of {est} mm {ci}")
        if turned and rot is not None:
            shift_parts.append(Part("turn", abs(rot[0]), rot[3][0], rot[3][1], unit="deg"))
            seen.append(
                f"a turn about the part axis of {{est:turn}}° in size ({rot[0]:+.3f}°; 95 % "
                "{ci:turn}°)"
            )
        wo_text = (
            f"the robot part carries {' and '.join(seen)}: the robot's work object (the part "
            "formed so) or the robot scan's registration (only its measurement misplaced) — "
            f"cannot tell apart from these files ({OFFSET_SHORT}); {OFFSET_WHY}; {OFFSET_CHECK}"
        )
        v_wo = "cannot_tell"
    else:
        wo_text = (
            "the robot's work object would displace the formed part as a scan's shift "
            f"(or turn) misplaces its measurement: {shift_text}"
        )
        # the offset's own verdict: a turn that is only not ruled out is scan_rotation's to say
        v_wo = v_shift
    out.append(
        _finding("work_object", est, ci, "mm", wo_text, "", force=v_wo, parts=tuple(shift_parts))
    )
    out.append(rot_finding)
    return out


def _drift_finding(rf: RobotTermFit) -> Finding:
    """thermal_drift: a sideways offset growing over the run (linear in forming time) is the
    formed part's — a scan is one rigid snapshot —, told from a tilt of the formed part (which
    grows with depth, and forming time follows depth) when the data can, and from a constant
    offset where the analysed laps span enough of the run."""
    lim = DETECTION_LIMITS["thermal_drift"]
    todo = (
        "compensate corrects it as the part's, but a drift changes from run to run: the "
        "correction holds only if the next run drifts alike (form after the same warm-up)"
    )
    if rf.tilt_alone is None:
        return _finding(
            "thermal_drift",
            None,
            None,
            "mm",
            "the points' forming time is not known: an offset growing over the run cannot be "
            "told from a constant one",
            "",
        )
    owner = (
        "the robot's work object tilted (the robot scan's tilts are registered from the flange)"
        if rf.tilt_registered
        else "the robot's work object tilted, or the robot scan tilted (its registration did "
        "not fit the tilts)"
    )
    d2, d3, tl = rf.drift, rf.drift_beside_tilt, rf.tilt
    if d2 is None or d3 is None:
        # the analysed laps are formed in too short a part of the run: a drift is a constant
        # offset there, of κ times its size
        k = max(min(rf.drift_kappa), 1e-9)
        sf = rf.shift_fit
        lo, hi = sf.ci()
        where = (
            f"the analysed laps are formed within a short part of the run (a drift's pattern is "
            f"{rf.drift_separable:.0%} beyond a constant offset's), where a drift reads as a "
            f"constant offset of {k:.2f}× its size"
        )
        if sf.verdict(DETECTION_LIMITS["scan_shift"]) == "ok":
            text = (
                f"{where}: none is seen — the offset is at most {hi:.3f} mm, a drift at most "
                f"{hi / k:.3f} mm (unless a constant offset the other way hid it)"
            )
            return _finding(
                "thermal_drift", float(np.linalg.norm(sf.one)) * 1e3 / k, (0.0, hi / k), "mm",
                text, todo, force="ok",
            )  # fmt: skip
        text = (
            f"{where}: the robot part's offset ({{est:offset}} mm, 95 % {{ci:offset}}) may be a "
            "thermal drift of the robot as well as the robot scan's registration or the robot's "
            "work object — cannot tell apart on this path"
        )
        offset = Part("offset", float(np.linalg.norm(sf.one)) * 1e3, lo, hi)
        return _finding(
            "thermal_drift", float(np.linalg.norm(sf.one)) * 1e3 / k, (0.0, hi / k), "mm", text,
            todo, force="cannot_tell", parts=(offset,),
        )  # fmt: skip
    assert tl is not None
    deg = math.degrees(1.0)
    parts: list[Part] = []

    def grows(d: PatternFit, beside: str, name: str = "") -> str:
        """The drift ``d`` of both fits, its numbers as the parts ``one_scale{name}`` and
        ``per_joint{name}``."""
        e = d.one * 1e3
        for fit, v, c in (("one_scale", d.one, d.one_ci), ("per_joint", d.joint, d.joint_ci)):
            if fit + name not in {q.name for q in parts}:
                parts.append(
                    Part(fit + name, float(np.linalg.norm(v)) * 1e3, c[0] * 1e3, c[1] * 1e3)
                )
        return (
            f"the robot term carries a sideways offset growing over the run to "
            f"{{est:one_scale{name}}} mm at its end (x {e[0]:+.3f}, y {e[1]:+.3f}; 95 % of its "
            f"size {{ci:one_scale{name}}} mm) beside one stiffness scale{beside}, and "
            f"{{est:per_joint{name}}} mm ({{ci:per_joint{name}}}) beside a per-joint fit"
        )

    t = tl.one * deg
    parts.append(
        Part("tilt", float(np.linalg.norm(t)), tl.one_ci[0] * deg, tl.one_ci[1] * deg, unit="deg")
    )
    tilt_text = (
        f"a tilt of the formed part of {{est:tilt}}° about work x, y (x {t[0]:+.3f}°, "
        f"y {t[1]:+.3f}°; 95 % of its size {{ci:tilt}}°)"
    )
    v2, v3 = d2.verdict(lim), d3.verdict(lim)
    if rf.model == "tilt":
        d, v, ci = d3, v3, d3.ci()
        text = f"{grows(d3, ' and ' + tilt_text, '_with_tilt')}"
        if v == "ok":
            text += f"; the offset that grows with depth is that tilt, not a drift: {owner}"
        elif v == "cannot_tell":
            text += f"; a drift or that tilt ({owner}) — cannot tell apart on this path"
    elif v2 == "fault" and v3 != "fault":
        d, v = d2, "cannot_tell"
        ci = (min(d2.ci()[0], d3.ci()[0]), max(d2.ci()[1], d3.ci()[1]))
        text = (
            "a sideways offset growing over the run to {est} mm {ci}: a thermal drift of the "
            f"robot, or a tilt of the formed part about a horizontal axis ({owner}) — cannot "
            f"tell apart on this path (forming time follows depth); {grows(d2, '')}; with a "
            f"tilt fitted too, {grows(d3, ' and ' + tilt_text, '_with_tilt')}"
        )
    elif v2 == "fault":
        d, v = d2, "fault"
        ci = (min(d2.ci()[0], d3.ci()[0]), max(d2.ci()[1], d3.ci()[1]))
        text = (
            "the robot's tip drifted sideways over the run, {est} mm at its end {ci}: a thermal "
            "drift — a scan is one rigid snapshot, so an offset that grows with forming time is "
            f"the formed part's, not the scan's; {grows(d2, '')}; with a tilt of the formed part "
            f"fitted too (not seen), {grows(d3, '', '_with_tilt')}"
        )
    else:
        d, v, ci = d2, v2, d2.ci()
        text = grows(d2, "")
    if "{est:tilt}" not in text:
        parts = [q for q in parts if q.name != "tilt"]
    return _finding(
        "thermal_drift",
        float(np.linalg.norm(d.one)) * 1e3,
        ci,
        "mm",
        text,
        todo,
        force=v,
        parts=tuple(parts),
    )


def _tilt_finding(rf: RobotTermFit) -> Finding:
    """work_object_tilt: the formed part tilted against the clamped flange about a horizontal
    axis — the robot's work object (or its kinematics) when the robot scan's registration fitted
    its tilts from the flange; the scan's tilt just as well when it did not. Seen beside a drift
    (when the path tells a drift from a constant offset), ruled out beside the offset alone."""
    alone = rf.tilt_alone
    if alone is None:
        return _finding(
            "work_object_tilt",
            None,
            None,
            "mm",
            "the points' forming time is not known: a tilt is fitted only beside a drift, "
            "which it passes for on a step-down path",
            "",
        )
    deg = math.degrees(1.0)
    lever = rf.depth_max * 1e3  # rad → mm sideways at the deepest analysed point
    lim = DETECTION_LIMITS["work_object_tilt"]
    beside_drift = rf.drift is not None and rf.tilt is not None
    tl = rf.tilt if beside_drift and rf.tilt is not None else alone
    v = tl.verdict(lim, lever)
    either = False
    if beside_drift and v != "fault":
        va = alone.verdict(lim, lever)
        if va == "ok":  # no offset growing with depth at all: no tilt
            tl, v = alone, "ok"
        elif va == "fault":  # a tilt without a drift, a drift beside no tilt: either
            either = True
    t = tl.one * deg
    ci = tl.ci(lever)
    est = float(np.linalg.norm(tl.one)) * lever

    def in_deg(name: str, f: F64, c: tuple[float, float]) -> Part:
        return Part(name, float(np.linalg.norm(f)) * deg, c[0] * deg, c[1] * deg, unit="deg")

    parts = [in_deg("one_scale", tl.one, tl.one_ci), in_deg("per_joint", tl.joint, tl.joint_ci)]
    at = f"{{est}} mm sideways at the deepest analysed point ({lever:.0f} mm)"
    text = (
        f"the formed part is tilted against the clamped flange by {{est:one_scale}}°, {at} "
        f"(about work x {t[0]:+.3f}°, y {t[1]:+.3f}°; 95 % of its size {{ci:one_scale}}°) "
        "beside one stiffness scale, "
        + ("a drift and an offset" if tl is rf.tilt and beside_drift else "an offset")
        + ", and {est:per_joint}° ({ci:per_joint}) beside a per-joint fit"
    )
    if either:
        parts.append(in_deg("without_drift", alone.one, alone.one_ci))
        text += (
            "; fitted without a drift the tilt is {est:without_drift}° "
            "({ci:without_drift}): a tilt, or a drift "
            "over the run — cannot tell apart on this path (forming time follows depth)"
        )
    if v == "fault" and rf.tilt_registered:
        text = (
            "the formed part is tilted {est:one_scale}° against the clamped flange, "
            f"{{est}} mm {{ci}} sideways at {lever:.0f} mm depth: the "
            "robot's work object tilted about a horizontal axis "
            "(or the robot's kinematics) — the robot scan's tilts are registered from the "
            f"flange, so it is not the scan's; {text}"
        )
    elif v == "fault":
        text = (
            f"the formed part is tilted {{est:one_scale}}°, {{est}} mm {{ci}} sideways at "
            f"{lever:.0f} mm depth: the robot's work object tilted, or "
            "the robot scan tilted (its registration did not fit "
            f"the tilts) — cannot tell apart from these files ({OFFSET_SHORT}); {text}; "
            f"{OFFSET_CHECK}"
        )
        v = "cannot_tell"
    return _finding(
        "work_object_tilt",
        est,
        ci,
        "mm",
        text,
        "measure the robot's work object (its tilt); compensate corrects it as the part's",
        force=v,
        parts=tuple(parts),
    )


def robot_findings(rf: RobotTermFit | None, *, axisymmetric: bool) -> list[Finding]:
    """robot_stiffness, scan_shift, work_object, scan_rotation, thermal_drift,
    work_object_tilt, springback_coupling from the robot term."""
    if rf is None:
        why = "too few used points or laps to fit the robot term"
        return _unknown(ROBOT_TERM_SUSPECTS, why)
    out = []
    lo, hi = rf.ratio_ci
    rs_text = (
        "the robot gives way {est}× the VJM's prediction at the corrected forces "
        "(95 % {ci}, spanning the one-scale and per-joint fits, joints "
        f"{rf.joints_fitted} fitted, the others at nominal); VJM RMS "
        f"{rf.rms_vjm * 1e3:.3f} mm"
    )
    rs_limit = DETECTION_LIMITS["robot_stiffness"]
    # a robot term smaller than the model's is a stiffer robot, or a sheet recovering part of
    # the robot's deflection (springback coupling): one run cannot tell them apart — a
    # coupling of 0.3 on a nominal robot was called a robot stiffness FAULT at 0.71×
    stiffer = verdict(lo, hi, rs_limit) == "fault" and hi < 1.0
    if stiffer:
        rs_text += (
            "; a stiffer robot than modelled, or the sheet recovering part of the robot's "
            "deflection (springback coupling): one run cannot tell them apart — either way, "
            "identified_stiffness.toml compensates this process"
        )
    out.append(
        _finding(
            "robot_stiffness",
            rf.ratio,
            rf.ratio_ci,
            "1",
            rs_text,
            "use identified_stiffness.toml for compensate and plan",
            force="cannot_tell" if stiffer else None,
        )
    )
    patterns = [*_offset_findings(rf, axisymmetric=axisymmetric), _drift_finding(rf)]
    patterns.append(_tilt_finding(rf))
    if model_off(rf):
        patterns = [_beside_a_wrong_robot_model(f, rf) for f in patterns]
    out += patterns
    in_band = verdict(lo, hi, DETECTION_LIMITS["robot_stiffness"]) == "ok"
    out.append(
        _finding(
            "springback_coupling",
            0.0 if in_band else None,
            (0.0, max(1 - lo, hi - 1)) if in_band else None,
            "1",
            "a sheet that recovers part of the robot's deflection scales the robot term as a "
            "stiffer robot would: "
            + (
                "the robot term agrees with the model: neither is off, unless a softer robot "
                "and a coupling cancel (one run cannot tell)"
                if in_band
                else (
                    f"the ratio {rf.ratio:.3f} is a stiffer robot, or a coupling, or both"
                    if rf.ratio < 1
                    else f"the ratio {rf.ratio:.3f} is a softer robot, and a coupling may hide "
                    "more of it"
                )
            ),
            "",
        )
    )
    return out


#: Suspects whose ``cannot_tell`` may be an error of the part beyond its limit that the study's
#: files cannot attribute (the headline says it).
UNATTRIBUTED = (
    "scan_shift",
    "work_object",
    "scan_rotation",
    "thermal_drift",
    "work_object_tilt",
)


def _beyond(f: Finding) -> bool:
    """A ``cannot_tell`` whose whole interval lies beyond the ``ok`` band: something is off,
    and which part cannot be told."""
    if f.verdict != "cannot_tell" or f.ci_low is None or f.ci_high is None:
        return False
    return verdict(f.ci_low, f.ci_high, f.limits) == "fault"


def diagnosis_headline(findings: list[Finding]) -> str:
    """One line: the faults (or that nothing is off, or what cannot be told)."""
    faults = [f for f in findings if f.verdict == "fault"]
    # an offset of the robot part beyond its limit whose owner cannot be told (the scan's
    # registration or the robot's work object; a drift or a tilt): said, not hidden among the
    # names; the work object's restates the scan's
    off = [f for f in findings if f.suspect in UNATTRIBUTED and _beyond(f)]
    if any(f.suspect in ("scan_shift", "scan_rotation") for f in off):
        off = [f for f in off if f.suspect != "work_object"]
    if faults or off:
        return "diagnosis: " + " | ".join(f.headline for f in faults + off)
    unsure = [f.suspect for f in findings if f.verdict == "cannot_tell"]
    if unsure:
        # in words, as each finding's own headline says its suspect (not the summary's keys)
        return "diagnosis: no fault found; cannot tell: " + ", ".join(
            u.replace("_", " ") for u in unsure
        )
    return "diagnosis: no fault found"


@dataclass(frozen=True)
class CorrectedRobotTerm:
    """The robot term and the robot wrench after the diagnosis's force correction.

    W_rob : (N, 6) [N, N·m] tip wrench, work axes; measured : (N,) m normal robot term (less
    the pattern of the scan's faults);
    vjm : (N,) m the VJM's normal deflection at ``W_rob``; A : (N, 6) the identification's
    design at ``W_rob`` (ball centre)."""

    W_rob: F64
    measured: F64
    vjm: F64
    A: F64


def model_off(rf: RobotTermFit) -> bool:
    """The robot's own compliance may leave the sideways patterns the fit found: the ratio's
    interval lies outside the model's tolerance (a softer or a stiffer robot, or a coupling),
    and the part of the robot term the model misses, ``|ratio − 1| · RMS(VJM)``, is at least as
    large as every pattern (offset, turn, drift: RMS of their normal deviation). A robot that
    is the model scaled by one factor leaves no pattern, but a real arm's misfit beyond the
    factor is of the misfit's order; a pattern larger than the whole misfit is not the robot's."""
    lo, hi = rf.ratio_ci
    if verdict(lo, hi, DETECTION_LIMITS["robot_stiffness"]) != "fault":
        return False
    misfit = abs(rf.ratio - 1.0) * rf.rms_vjm
    pattern = max(rf.rms_shift_pattern, rf.rms_rotation_pattern, rf.rms_drift_pattern)
    return pattern <= misfit


#: What a pattern's text says when the robot's own compliance may carry it (:func:`model_off`);
#: ``analyze`` then asks no ``--offset`` (compensate corrects it with the robot term).
ROBOT_MISFIT = "cannot tell apart while the robot model is off"

#: Suspects whose patterns the robot term's fit attributes beside the stiffness: an offset, a
#: turn, a drift and a tilt of the formed part, which a robot model that is off can leave too.
_PATTERN_SUSPECTS = (
    "scan_shift",
    "work_object",
    "scan_rotation",
    "thermal_drift",
    "work_object_tilt",
)


def _beside_a_wrong_robot_model(f: Finding, rf: RobotTermFit) -> Finding:
    """``f`` (an offset, turn, drift or tilt of the robot part seen beyond its limit) when the
    robot's compliance is not the model's (:func:`model_off`): ``cannot_tell``, naming the
    robot's own compliance as a third suspect. The VJM scaled by one factor, or joint by joint,
    leaves out what a real arm also has (its links bending, a coupling of the axial force into a
    sideways give that changes over the path): on a path at nearly constant force such a misfit
    is a sideways pattern that is constant or grows with depth — an offset or a drift. The
    paper's demo cell (joints 0.22×, bending links) read a 0.88 mm "thermal drift: FAULT" and a
    0.61 mm unattributed offset that compensate refused to guess, with no drift nor offset in
    its truth."""
    if f.suspect not in _PATTERN_SUSPECTS or not (f.verdict == "fault" or _beyond(f)):
        return f
    ci = (f.ci_low, f.ci_high) if f.ci_low is not None and f.ci_high is not None else None
    why = (
        f"the robot gives way {rf.ratio:.3f}× the model's prediction (robot_stiffness), and the "
        "part of its compliance the model does not hold (its links bending, a coupling of the "
        "axial force into a sideways give that changes over the path) leaves such a pattern as "
        "well: identify the robot's stiffness (identified_stiffness.toml) and analyse a run "
        "formed with it"
    )
    # the headline is the first clause: it names the third suspect too
    first = _first_clause(f.explanation)
    rest = f.explanation[len(first) :]
    text = f"{first} — or the robot's own compliance ({ROBOT_MISFIT}){rest}; {why}"
    return _finding(f.suspect, f.estimate, ci, f.unit, text, "", force="cannot_tell", parts=f.parts)


def _unchecked_forces(f: Finding, force_verdicts: dict[str, str]) -> Finding:
    """``f`` when the forces could not be fitted against the dynamometer (fewer than 6 laps):
    a robot stiffness fault is a gain error just as well (it scales the robot term alike), and
    a scan shift fault a force bias left in the forces (a constant lateral force deflects the
    robot sideways) unless that bias is ruled out — both ``cannot_tell``, saying why. A
    sensor reading 0.85× on a part of 5 laps was called a robot stiffness FAULT at 1.21×, a
    25 N bias a scan shift FAULT of 0.10 mm. An offset of the robot part the diagnosis cannot
    attribute (the scan's registration or the robot's work object) may be that bias too."""
    offset = f.suspect in ("scan_shift", "work_object") and _beyond(f)
    if f.verdict != "fault" and not offset:
        return f
    if f.suspect == "robot_stiffness":
        why = (
            "the force sensor's gain could not be checked against the dynamometer (fewer than "
            "6 used laps): a gain error scales the robot term alike"
        )
    elif f.suspect in ("scan_shift", "work_object") and force_verdicts.get("force_bias") != "ok":
        why = (
            "a force bias could not be ruled out nor removed (fewer than 6 used laps): a constant "
            "lateral force moves the robot term as a shift does"
        )
    else:
        return f
    ci = (f.ci_low, f.ci_high) if f.ci_low is not None and f.ci_high is not None else None
    text = f"{f.explanation}; {why}"
    return _finding(f.suspect, f.estimate, ci, f.unit, text, "", force="cannot_tell", parts=f.parts)


def diagnose(
    *,
    robot: Any,
    q: F64,
    T_base_work: F64,
    k_t: F64,
    k_th: F64 | None,
    k_c: F64,
    ball_radius: float,
    normal: F64,
    contact: F64,
    tip: F64,
    lap: NDArray[Any],
    depth: F64,
    W_cnc: F64,
    W_rob: F64,
    measured: F64,
    valid: NDArray[np.bool_],
    axisymmetric: bool,
    unloaded: dict[str, list[UnloadedStretch]] | None = None,
    tau: F64 | None = None,
    tilt_registered: bool = True,
    sensor_lever: F64 | None = None,
    moments_measured: bool = True,
) -> tuple[Diagnosis, CorrectedRobotTerm]:
    """Every suspect's verdict for one study (module docstring) and the corrected robot term.

    robot : the study's :class:`roboisf.robot.RobotModel`; q : (N, 6) rad; k_t, k_th : (6, 6)
    tool and holder compliance at the tip (None: rigid holder); k_c : (N, 6, 6) the robot's
    VJM compliance at the tip; ball_radius : m; normal, contact, tip : (N, 3) work frame, m;
    W_cnc, W_rob : (N, 6) tip wrenches [N, N·m]; measured : (N,) m the analysis's normal robot
    term (at the measured robot forces); valid : (N,) bool; unloaded : each run's stretches
    with the tool off the sheet at the tip, work axes (keys "cnc", "robot"; the static offset
    and the axial crosstalk, docs/diagnosis.md); tau : (N,) each point's forming time over
    the robot run in [0, 1] (:func:`forming_time`; a thermal drift grows with it), None when
    unknown; tilt_registered : the robot scan's registration fitted its tilts; sensor_lever :
    (3,) m the flange sensor's origin relative to the tip at the path's first point, work axes
    (None: at the tip) — a force offset makes a moment about the tip on that arm, none about
    the sensor; moments_measured : False when the robot's force log has no moment channels
    (its tip moments are the point-contact moment the analysis puts there): the moment suspects
    are then ok by construction, and said so."""
    from roboisf.cell import at_ball_centre
    from roboisf.decompose.identify import forming_design

    arm = contact - tip
    ev = (
        UnloadedEvidence.from_stretches(
            unloaded.get("robot", []), unloaded.get("cnc", []), lever=sensor_lever
        )
        if unloaded
        else None
    )
    sf = fit_sensor(W_cnc, W_rob, arm, valid, lap, depth, unloaded=ev, lever=sensor_lever)
    findings = sensor_findings(sf, ball_radius, ev)
    if not moments_measured:
        findings = [
            _no_moment_channels(f.suspect) if f.suspect in MOMENT_SUSPECTS else f for f in findings
        ]
    fv = {f.suspect: f.verdict for f in findings}
    correct = sf is not None and any(
        fv[s] == "fault"
        for s in (
            "force_gain",
            "force_moment_crosstalk",
            "force_moment_bias",
            "force_bias",
            "force_crosstalk",
        )
    )
    if sf is not None and fv["force_crosstalk"] == "fault" and sf.axial_fixed is not None:
        sf = replace(sf, correct_axial=True)
    W = W_rob
    y = measured
    if correct:
        assert sf is not None
        # the tip moment is replaced by the point-contact moment whenever it is in doubt: the
        # moment channels not ok, or a force offset or axial crosstalk removed from the forces
        # (carried up the arm from the sensor, it is in the measured tip moment too: a 3.6 %
        # crosstalk put 6 N·m there, which the tool terms turned into a 0.12 mm "scan shift")
        moments_ok = fv["force_moment_crosstalk"] == fv["force_moment_bias"] == "ok"
        offsets = "fault" in (fv["force_bias"], fv["force_crosstalk"])
        W = sf.corrected(W_rob, arm, moments=offsets or not moments_ok)

        def tool_terms(Wx: F64) -> F64:
            d = at_ball_centre(Wx @ k_t.T, ball_radius)
            if k_th is not None:
                d = d + at_ball_centre(Wx @ k_th.T, ball_radius)
            return np.einsum("ij,ij->i", d, normal)

        # the robot term keeps what the scans measured; only the force-driven terms change
        y = measured + tool_terms(W_rob) - tool_terms(W)
    vjm = np.einsum(
        "ij,ij->i", at_ball_centre(np.einsum("nij,nj->ni", k_c, W), ball_radius), normal
    )
    A = forming_design(robot, q, W, T_base_work, normal, ball_radius)
    per_joint = A / robot.joint_stiffness[None, :]
    rf = fit_robot_term(
        y, vjm, per_joint, normal, contact, valid, lap, tau=tau, tilt_registered=tilt_registered
    )
    if rf is not None and sf is not None:
        # the VJM runs on the forces as measured, or divided by the fitted gain: the ratio
        # carries the gain's uncertainty (a gain inside the ok band is not corrected, but a
        # 2 % gain is 2 % of the ratio)
        g_lo, g_hi = sf.gain_ci
        if correct:
            g_lo, g_hi = g_lo / sf.gain, g_hi / sf.gain
        lo, hi = rf.ratio_ci
        rf = replace(rf, ratio_ci=(lo * min(g_lo, 1.0), hi * max(g_hi, 1.0)))
    findings += robot_findings(rf, axisymmetric=axisymmetric)
    if sf is None:  # the forces could not be checked against the dynamometer, nor corrected
        findings = [_unchecked_forces(f, fv) for f in findings]
    order = {s: i for i, s in enumerate(SUSPECTS)}
    findings.sort(key=lambda f: order[f.suspect])
    diag = Diagnosis(findings, sf, rf, correct)
    pattern = diag.beside_stiffness(normal, contact, tau)
    if pattern is not None:  # the identification sees the robot's compliance alone: not the
        y = y - pattern  # scan's misregistration, an offset, a drift or a tilt of the part
    return diag, CorrectedRobotTerm(W, y, vjm, A)
