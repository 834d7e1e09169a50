"""The virtual cell's truth beyond the model: how the simulated cell differs from what a user knows.

Without a truth file the virtual cell forms its parts with exactly the model ``analyze`` later
uses (nominal joint stiffness, rigid links, exact kinematics, an ideal sensor, a perfectly
registered scan), so the decomposition agrees with the truth *by construction*. A truth file
(``roboisf virtual-cell … --truth TRUTH.toml``) makes the cell differ from the model; the study
written still carries only what a user would know (nominal robot, nominal compliances), and
``truth/truth.json`` records the true values.

Every key is optional; every effect is off when its key is absent. Units as in ``study.toml``
(mm, deg, N, N·m, kg); SI inside :class:`TruthSpec`::

    [robot]
    joint_stiffness_scale = 0.6          # true K = scale · nominal K; a number or six
    link_compliance = true               # beams of the arm links (roboisf.virtual.links)
    thermal_drift = [0.0, 0.0, 0.8]      # mm, tip drift (work axes) growing linearly over the run
    [robot.kinematic_error]              # the true robot's geometry differs from the model's
    joint_offset = [0, 0.01, -0.01, 0, 0, 0]   # deg, zero offsets of the six joints
    c2 = 0.2                             # mm, OPW parameter errors (a1 a2 b c1 c2 c3 c4)
    work_object = [0, 0, 0, 0, 0.3, 0]   # mm, deg: the taught work object's error (x y z rx ry
                                         # rz; rotations about the work origin, applied x, y, z)

    [force_sensor]                       # the robot's flange F/T sensor
    bias = [30, 0, 0, 0, 0, 0]           # N, N·m in the sensor's axes
    gain = 1.02                          # a number or six (per channel)
    crosstalk_force = 0.01               # 1 (N per N): each force channel reads this share of
                                         # the other two force channels
    crosstalk_moment = 2.0               # mm (N·m per kN): each moment channel reads this much
                                         # moment per newton on each force channel
    # crosstalk = [[...], ...]           # or the whole 6×6 coupling in the sensor's own units
                                         # (rows read, columns cause; N per N, N per N·m, m, 1);
                                         # a single number fills every off-diagonal entry (mixing
                                         # N and N·m: kept for old files, prefer the two above)

    [tool]
    mass = 4.0                           # kg, the weight below the flange sensor (no tare)
    cog = [0, 0, 150]                    # mm, its centre of gravity in the flange frame

    [scan]                               # the robot part's scan, misregistered
    shift = [0.3, 0, 0]                  # mm, work axes
    rotation = [0, 0, 0.2]               # deg, about the work x, y, z axes (applied x, y, z)

    [springback]
    deflection_coupling = 0.3            # s_run = s − c(depth) · (n · δ_machine), each run
    coupling_depth = 30.0                # mm, c(depth) = c · exp(−depth / this) (absent: c)
    amplitude = 1.33                     # mm, the springback model's amplitude (both runs)
    curvature_gain = 0.4                 # the geometry rule: × (1 − gain·tanh(κ·length))
    curvature_length = 15.0              # mm (κ: the contour's curvature, springback.py)

    [cnc]
    compliance = 2e-5                    # mm/N, the CNC's translational compliance (1 or 3)

The sensor reads ``diag(gain) · (I + crosstalk) · W + bias (+ the tool's weight)``, its axes,
``W = [F; M]`` in N and N·m; ``crosstalk_force`` and ``crosstalk_moment`` add to ``crosstalk``'s
force-to-force and force-to-moment blocks.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.io.text import read_text
from roboisf.plausible import check_plausible

__all__ = [
    "OPW_KEYS",
    "SCENARIOS",
    "TruthSpec",
    "load_truth",
    "merge_truth_tables",
    "scenario_table",
    "truth_from_table",
]

F64 = NDArray[np.float64]

#: OPW geometry parameters a kinematic error may perturb (mm in the file).
OPW_KEYS = ("a1", "a2", "b", "c1", "c2", "c3", "c4")
#: The named scenarios shipped with the package: ``(scenario, part) → file``.
SCENARIOS: dict[tuple[str, str], str] = {
    ("paper", "cone"): "paper_cone.toml",
    ("paper", "vwacf"): "paper_vwacf.toml",
}

_KEYS: dict[str, tuple[str, ...]] = {
    "robot": ("joint_stiffness_scale", "link_compliance", "thermal_drift", "kinematic_error"),
    "force_sensor": ("bias", "gain", "crosstalk", "crosstalk_force", "crosstalk_moment"),
    "tool": ("mass", "cog"),
    "scan": ("shift", "rotation"),
    "springback": (
        "deflection_coupling",
        "coupling_depth",
        "amplitude",
        "curvature_gain",
        "curvature_length",
    ),
    "cnc": ("compliance",),
}
_KIN_KEYS = ("joint_offset", "work_object", *OPW_KEYS)


@dataclass(frozen=True, eq=False)
class TruthSpec:
    """What the virtual cell does differently from the model (SI; defaults: nothing).

    Attributes
    ----------
    joint_stiffness_scale : (6,) float — true joint stiffness over the nominal (ones: nominal)
    link_compliance : bool — add the bending of the arm links (:mod:`roboisf.virtual.links`)
    thermal_drift : (3,) float, m — tip drift in work axes reached at the end of the run,
        growing linearly with the elapsed time
    joint_offset : (6,) float, rad — zero-offset errors of the joints (true − model)
    opw_error : dict str → float, m — errors of the OPW parameters (true − model)
    work_object_error : (6,) float, m and rad — the taught work object's error: the robot forms
        in ``T_err = [R(rx, ry, rz) | (x, y, z)]`` of the blank's true frame
    sensor_bias : (6,) float, N and N·m — flange-sensor bias in the sensor's axes
    sensor_gain : (6,) float — per-channel gain
    sensor_crosstalk : (6, 6) float — off-diagonal coupling (zero diagonal), rows read, columns
        cause, SI (force→moment entries in m = N·m per N)
    tool_mass : float, kg — weight below the flange sensor (0: none)
    tool_cog : (3,) float, m — its centre of gravity in the flange frame
    scan_shift : (3,) float, m — the robot scan's misregistration, work axes
    scan_rotation : (3,) float, rad — its rotation about work x, y, z (applied in that order)
    springback_coupling : float — each run: ``s − c(depth) · (n · δ_machine)``
    springback_coupling_depth : float, m — ``c(depth) = c · exp(−depth / this)`` (inf: constant)
    springback_amplitude : float or None, m — replaces the cell's springback amplitude
    springback_curvature_gain : float — the geometry rule of
        :class:`~roboisf.virtual.springback.SpringbackModel` (0: off)
    springback_curvature_length : float, m — its length scale
    cnc_compliance : (3,) float, m/N — the CNC's translational compliance (zeros: rigid)
    source : str — the file(s) or scenario it came from
    """

    joint_stiffness_scale: F64 = field(default_factory=lambda: np.ones(6))
    link_compliance: bool = False
    thermal_drift: F64 = field(default_factory=lambda: np.zeros(3))
    joint_offset: F64 = field(default_factory=lambda: np.zeros(6))
    opw_error: dict[str, float] = field(default_factory=dict)
    work_object_error: F64 = field(default_factory=lambda: np.zeros(6))
    sensor_bias: F64 = field(default_factory=lambda: np.zeros(6))
    sensor_gain: F64 = field(default_factory=lambda: np.ones(6))
    sensor_crosstalk: F64 = field(default_factory=lambda: np.zeros((6, 6)))
    tool_mass: float = 0.0
    tool_cog: F64 = field(default_factory=lambda: np.zeros(3))
    scan_shift: F64 = field(default_factory=lambda: np.zeros(3))
    scan_rotation: F64 = field(default_factory=lambda: np.zeros(3))
    springback_coupling: float = 0.0
    springback_coupling_depth: float = math.inf
    springback_amplitude: float | None = None
    springback_curvature_gain: float = 0.0
    springback_curvature_length: float = 15e-3
    cnc_compliance: F64 = field(default_factory=lambda: np.zeros(3))
    source: str = ""

    def __post_init__(self) -> None:
        shapes = {
            "joint_stiffness_scale": (6,),
            "thermal_drift": (3,),
            "joint_offset": (6,),
            "work_object_error": (6,),
            "sensor_bias": (6,),
            "sensor_gain": (6,),
            "sensor_crosstalk": (6, 6),
            "tool_cog": (3,),
            "scan_shift": (3,),
            "scan_rotation": (3,),
            "cnc_compliance": (3,),
        }
        for name, shape in shapes.items():
            a = np.array(getattr(self, name), dtype=float)
            if a.shape != shape or not np.all(np.isfinite(a)):
                raise InputError(
                    f"expected {shape} finite values, got shape {a.shape}", field=f"truth.{name}"
                )
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        if np.any(self.joint_stiffness_scale <= 0):
            raise InputError("must be > 0", field="truth.joint_stiffness_scale")
        if np.any(self.sensor_gain <= 0):
            raise InputError("must be > 0", field="truth.sensor_gain")
        if np.any(np.diag(self.sensor_crosstalk) != 0):
            raise InputError(
                "the crosstalk matrix holds the off-diagonal couplings: its diagonal must be 0 "
                "(use gain for the channels' own sensitivity)",
                field="truth.sensor_crosstalk",
            )
        if not (math.isfinite(self.tool_mass) and self.tool_mass >= 0):
            raise InputError("must be ≥ 0 kg", field="truth.tool_mass")
        if not (math.isfinite(self.springback_coupling) and 0 <= self.springback_coupling < 1):
            raise InputError("must be in [0, 1)", field="truth.springback_coupling")
        if not self.springback_coupling_depth > 0:
            raise InputError("must be > 0 mm", field="truth.springback_coupling_depth")
        amp = self.springback_amplitude
        if amp is not None and not (math.isfinite(amp) and amp >= 0):
            raise InputError("must be ≥ 0", field="truth.springback_amplitude")
        if not (0 <= self.springback_curvature_gain < 1):
            raise InputError("must be in [0, 1)", field="truth.springback.curvature_gain")
        if not (0 < self.springback_curvature_length < math.inf):
            raise InputError("must be > 0 mm", field="truth.springback.curvature_length")
        if np.any(self.cnc_compliance < 0):
            raise InputError("must be ≥ 0", field="truth.cnc_compliance")
        for k, v in self.opw_error.items():
            if k not in OPW_KEYS or not math.isfinite(v):
                raise InputError(f"unknown OPW parameter or non-finite value {k!r} = {v}", field=k)

    @property
    def kinematic_error(self) -> bool:
        """True when the true robot's geometry differs from the model's."""
        return bool(
            np.any(self.joint_offset != 0)
            or any(self.opw_error.values())
            or np.any(self.work_object_error != 0)
        )

    @property
    def sensor_ideal(self) -> bool:
        """True when the flange sensor reads the load exactly."""
        return bool(
            not np.any(self.sensor_bias)
            and np.all(self.sensor_gain == 1)
            and not np.any(self.sensor_crosstalk)
            and self.tool_mass == 0
        )

    @property
    def is_model(self) -> bool:
        """True when the cell is exactly the model (every effect off)."""
        return bool(
            np.all(self.joint_stiffness_scale == 1)
            and not self.link_compliance
            and not np.any(self.thermal_drift)
            and not self.kinematic_error
            and self.sensor_ideal
            and not np.any(self.scan_shift)
            and not np.any(self.scan_rotation)
            and self.springback_coupling == 0
            and not np.any(self.cnc_compliance)
        )

    def coupling_at(self, depth: F64) -> F64:
        """The springback coupling ``c(depth)`` (N,) at contact depths (N,) m."""
        d = np.asarray(depth, dtype=float)
        if math.isinf(self.springback_coupling_depth):
            return np.full(d.shape, self.springback_coupling)
        return np.asarray(
            self.springback_coupling * np.exp(-d / self.springback_coupling_depth), dtype=float
        )

    def sensor_matrix(self) -> F64:
        """``diag(gain) · (I + crosstalk)`` (6, 6): true wrench → sensor reading (before bias)."""
        return np.asarray(np.diag(self.sensor_gain) @ (np.eye(6) + self.sensor_crosstalk))

    def to_table(self) -> dict[str, Any]:
        """The truth in file units (mm, deg, N, N·m, kg), every key (for ``truth/truth.json``)."""
        mm = 1e3
        return {
            "robot": {
                "joint_stiffness_scale": self.joint_stiffness_scale.tolist(),
                "link_compliance": self.link_compliance,
                "thermal_drift": (self.thermal_drift * mm).tolist(),
                "kinematic_error": {
                    "joint_offset": np.degrees(self.joint_offset).tolist(),
                    "work_object": [
                        *(self.work_object_error[:3] * mm).tolist(),
                        *np.degrees(self.work_object_error[3:]).tolist(),
                    ],
                    **{k: v * mm for k, v in self.opw_error.items()},
                },
            },
            "force_sensor": {
                "bias": self.sensor_bias.tolist(),
                "gain": self.sensor_gain.tolist(),
                "crosstalk": self.sensor_crosstalk.tolist(),
            },
            "tool": {"mass": self.tool_mass, "cog": (self.tool_cog * mm).tolist()},
            "scan": {
                "shift": (self.scan_shift * mm).tolist(),
                "rotation": np.degrees(self.scan_rotation).tolist(),
            },
            "springback": {
                "deflection_coupling": self.springback_coupling,
                **(
                    {"coupling_depth": self.springback_coupling_depth * mm}
                    if math.isfinite(self.springback_coupling_depth)
                    else {}
                ),
                **(
                    {"amplitude": self.springback_amplitude * mm}
                    if self.springback_amplitude is not None
                    else {}
                ),
                **(
                    {
                        "curvature_gain": self.springback_curvature_gain,
                        "curvature_length": self.springback_curvature_length * mm,
                    }
                    if self.springback_curvature_gain
                    else {}
                ),
            },
            "cnc": {"compliance": (self.cnc_compliance * mm).tolist()},
            "source": self.source,
            "is_model": self.is_model,
        }


def _vector(v: Any, n: int, where: str, *, scalar_ok: bool = False) -> F64:
    if isinstance(v, bool):
        raise InputError(f"expected numbers, got {v!r}", field=where)
    if scalar_ok and isinstance(v, int | float):
        return np.full(n, float(v))
    try:
        a = np.array(v, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"expected {n} numbers, got {v!r}", field=where) from None
    if a.shape != (n,):
        what = f"a number or {n} numbers" if scalar_ok else f"{n} numbers"
        raise InputError(f"expected {what}, got shape {a.shape}", field=where)
    if not np.all(np.isfinite(a)):
        raise InputError("contains NaN or inf", field=where)
    return a


def _bounded(a: F64, bound: str, where: str) -> F64:
    """``a`` (file units) with every value in the range a real cell has
    (:data:`roboisf.plausible.BOUNDS`), else the InputError naming the unit slip."""
    for i, x in enumerate(np.ravel(a)):
        check_plausible(float(x), bound, field=where if a.size == 1 else f"{where}[{i}]")
    return a


def _number(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise InputError(f"expected a finite number, got {v!r}", field=where)
    return float(v)


def _table(data: Mapping[str, Any], key: str, where: str) -> Mapping[str, Any]:
    t = data.get(key, {})
    if not isinstance(t, Mapping):
        raise InputError(f"expected a table [{key}], got {t!r}", field=where)
    return t


def _check_keys(t: Mapping[str, Any], allowed: tuple[str, ...], where: str) -> None:
    for k in t:
        if k not in allowed:
            raise InputError(
                f"unknown key {k!r}; expected one of {', '.join(allowed)}",
                field=f"{where}.{k}" if where else k,
            )


def truth_from_table(data: Mapping[str, Any], source: str = "") -> TruthSpec:
    """A :class:`TruthSpec` from a parsed truth file (file units, see the module docstring).

    Raises :class:`InputError` naming ``source`` and the key for unknown keys, wrong shapes or
    values out of range.
    """
    try:
        return _from_table(data, source)
    except InputError as e:
        if source and e.file is None:
            raise InputError(e.message, file=source, field=e.field) from None
        raise


def _from_table(data: Mapping[str, Any], source: str) -> TruthSpec:
    _check_keys(data, tuple(_KEYS), "")
    kw: dict[str, Any] = {"source": source}
    rob = _table(data, "robot", "robot")
    _check_keys(rob, _KEYS["robot"], "robot")
    if "joint_stiffness_scale" in rob:
        kw["joint_stiffness_scale"] = _bounded(
            _vector(rob["joint_stiffness_scale"], 6, "robot.joint_stiffness_scale", scalar_ok=True),
            "stiffness_scale",
            "robot.joint_stiffness_scale",
        )
    if "link_compliance" in rob:
        if not isinstance(rob["link_compliance"], bool):
            raise InputError(
                f"expected true or false, got {rob['link_compliance']!r}",
                field="robot.link_compliance",
            )
        kw["link_compliance"] = rob["link_compliance"]
    if "thermal_drift" in rob:
        drift = _vector(rob["thermal_drift"], 3, "robot.thermal_drift")
        kw["thermal_drift"] = _bounded(drift, "drift", "robot.thermal_drift") * 1e-3
    kin = _table(rob, "kinematic_error", "robot.kinematic_error")
    _check_keys(kin, _KIN_KEYS, "robot.kinematic_error")
    if "joint_offset" in kin:
        where = "robot.kinematic_error.joint_offset"
        off = _vector(kin["joint_offset"], 6, where, scalar_ok=True)
        kw["joint_offset"] = np.radians(_bounded(off, "joint_offset", where))
    if "work_object" in kin:
        wo = _vector(kin["work_object"], 6, "robot.kinematic_error.work_object")
        _bounded(wo[:3], "work_object_shift", "robot.kinematic_error.work_object")
        _bounded(wo[3:], "work_object_turn", "robot.kinematic_error.work_object")
        kw["work_object_error"] = np.concatenate([wo[:3] * 1e-3, np.radians(wo[3:])])
    kw["opw_error"] = {
        k: check_plausible(
            _number(kin[k], f"robot.kinematic_error.{k}"),
            "geometry_error",
            field=f"robot.kinematic_error.{k}",
        )
        * 1e-3
        for k in OPW_KEYS
        if k in kin
    }
    fs = _table(data, "force_sensor", "force_sensor")
    _check_keys(fs, _KEYS["force_sensor"], "force_sensor")
    if "bias" in fs:
        kw["sensor_bias"] = _bounded(
            _vector(fs["bias"], 6, "force_sensor.bias"), "sensor_bias", "force_sensor.bias"
        )
    if "gain" in fs:
        kw["sensor_gain"] = _bounded(
            _vector(fs["gain"], 6, "force_sensor.gain", scalar_ok=True),
            "sensor_gain",
            "force_sensor.gain",
        )
    if "crosstalk" in fs:
        c = fs["crosstalk"]
        if isinstance(c, int | float) and not isinstance(c, bool):
            ct = check_plausible(
                _number(c, "force_sensor.crosstalk"), "crosstalk", field="force_sensor.crosstalk"
            )
            kw["sensor_crosstalk"] = ct * (np.ones((6, 6)) - np.eye(6))
        else:
            try:
                m = np.array(c, dtype=float)
            except (TypeError, ValueError):
                m = np.array([])
            if m.shape != (6, 6):
                raise InputError(
                    f"expected a number or a 6×6 matrix (six rows of six), got {c!r}"[:200],
                    field="force_sensor.crosstalk",
                )
            off_diag = m[~np.eye(6, dtype=bool)]
            if np.all(np.isfinite(off_diag)):
                _bounded(off_diag, "crosstalk", "force_sensor.crosstalk")
            kw["sensor_crosstalk"] = m
    if "crosstalk_force" in fs or "crosstalk_moment" in fs:
        C = np.array(kw.get("sensor_crosstalk", np.zeros((6, 6))), dtype=float)
        off = np.ones((3, 3)) - np.eye(3)
        if "crosstalk_force" in fs:
            C[:3, :3] += _number(fs["crosstalk_force"], "force_sensor.crosstalk_force") * off
        if "crosstalk_moment" in fs:  # mm = N·m per kN → m = N·m per N
            cm = _number(fs["crosstalk_moment"], "force_sensor.crosstalk_moment") * 1e-3
            C[3:, :3] += cm
        kw["sensor_crosstalk"] = C
    tool = _table(data, "tool", "tool")
    _check_keys(tool, _KEYS["tool"], "tool")
    if "mass" in tool:
        kw["tool_mass"] = check_plausible(
            _number(tool["mass"], "tool.mass"), "tool_mass", field="tool.mass"
        )
    if "cog" in tool:
        kw["tool_cog"] = (
            _bounded(_vector(tool["cog"], 3, "tool.cog"), "tool_cog", "tool.cog") * 1e-3
        )
    scan = _table(data, "scan", "scan")
    _check_keys(scan, _KEYS["scan"], "scan")
    if "shift" in scan:
        shift = _vector(scan["shift"], 3, "scan.shift")
        kw["scan_shift"] = _bounded(shift, "scan_shift", "scan.shift") * 1e-3
    if "rotation" in scan:
        rot = _vector(scan["rotation"], 3, "scan.rotation")
        kw["scan_rotation"] = np.radians(_bounded(rot, "scan_rotation", "scan.rotation"))
    sb = _table(data, "springback", "springback")
    _check_keys(sb, _KEYS["springback"], "springback")
    if "deflection_coupling" in sb:
        kw["springback_coupling"] = _number(
            sb["deflection_coupling"], "springback.deflection_coupling"
        )
    if "coupling_depth" in sb:
        where = "springback.coupling_depth"
        depth = check_plausible(_number(sb["coupling_depth"], where), "coupling_depth", field=where)
        kw["springback_coupling_depth"] = depth * 1e-3
    if "amplitude" in sb:
        where = "springback.amplitude"
        amp = check_plausible(_number(sb["amplitude"], where), "springback_amplitude", field=where)
        kw["springback_amplitude"] = amp * 1e-3
    if "curvature_gain" in sb:
        kw["springback_curvature_gain"] = _number(sb["curvature_gain"], "springback.curvature_gain")
    if "curvature_length" in sb:
        kw["springback_curvature_length"] = (
            _number(sb["curvature_length"], "springback.curvature_length") * 1e-3
        )
    cnc = _table(data, "cnc", "cnc")
    _check_keys(cnc, _KEYS["cnc"], "cnc")
    if "compliance" in cnc:
        cc = _vector(cnc["compliance"], 3, "cnc.compliance", scalar_ok=True)
        kw["cnc_compliance"] = _bounded(cc, "cnc_compliance", "cnc.compliance") * 1e-3
    return TruthSpec(**kw)


def _read_toml(path: Path) -> dict[str, Any]:
    if not path.exists():
        raise InputError("truth file not found", file=str(path))
    try:  # UTF-8 only: another encoding is refused with the line and byte, not a traceback
        return tomllib.loads(read_text(path, what="truth TOML"))
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"not valid TOML: {e}", file=str(path)) from None


def scenario_table(scenario: str, part: str) -> dict[str, Any]:
    """The truth table of a named scenario for ``part`` (``cone`` / ``vwacf``), file units."""
    key = (scenario, part)
    if key not in SCENARIOS:
        known = sorted({f"{s} ({p})" for s, p in SCENARIOS})
        raise InputError(
            f"no scenario {scenario!r} for the part {part!r}; scenarios: {', '.join(known)}",
            field="--scenario",
        )
    text = resources.files("roboisf.virtual").joinpath("scenarios", SCENARIOS[key]).read_text()
    return tomllib.loads(text)


def merge_truth_tables(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """``over``'s keys replace ``base``'s, table by table (nested tables merged)."""
    out: dict[str, Any] = dict(base)
    for k, v in over.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), Mapping):
            out[k] = merge_truth_tables(out[k], v)
        else:
            out[k] = v
    return out


def load_truth(
    path: str | Path | None = None, *, scenario: str | None = None, part: str | None = None
) -> TruthSpec:
    """The truth of a file, a named scenario, or a scenario with the file's keys overriding it.

    Parameters
    ----------
    path : truth TOML (see the module docstring), or None
    scenario : a scenario name (``"paper"``) for ``part``, or None
    part : ``"cone"`` or ``"vwacf"`` (needed with ``scenario``)
    """
    table: dict[str, Any] = {}
    sources = []
    if scenario is not None:
        table = scenario_table(scenario, part or "")
        sources.append(f"scenario {scenario} ({part})")
    if path is not None:
        p = Path(path)
        over = _read_toml(p)
        truth_from_table(over, str(p))  # errors name the user's file and key
        table = merge_truth_tables(table, over)
        sources.append(str(p))
    return truth_from_table(table, " + ".join(sources))
