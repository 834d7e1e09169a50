"""``summary.json``: the analysis summary as typed, versioned value objects (docs/summary.md).

:class:`AnalysisSummary` is what ``roboisf analyze`` writes for a study with a CNC and a robot
run, :class:`RobotOnlySummary` what it writes for a study with a robot run only. Both are
frozen; :func:`dumps` is the one serialiser to ``summary.json``, :func:`read_summary` /
:func:`from_json` the one reader, and :func:`json_schema` generates the published JSON Schema
(``docs/summary.schema.json``) from the dataclasses' fields and their ``doc`` metadata.

Units are the file's: lengths in mm, forces in N, moments in N·m, angles in deg, time in s,
compliances in SI (m/N, rad/(N·m)) unless a field's name or doc says otherwise; frames are in
the field names (``placement_T_base_work_m``: the work frame in the robot base frame, metres).

Version policy: :data:`SCHEMA_VERSION` is raised whenever a field is removed, renamed or changes
its type or unit; the reader refuses a file of another version (or one without
``schema_version``, written before the summary was versioned) with a one-line error naming the
file and telling to re-run ``roboisf analyze``. Adding an optional field raises it too, so that a
file always validates against the schema of its version.
"""

from __future__ import annotations

import dataclasses
import json
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Union

from roboisf.errors import InputError
from roboisf.io.jsonvalues import jsonable

__all__ = [
    "SCHEMA_VERSION",
    "AnalysisSummary",
    "RobotInfo",
    "RobotOnlySummary",
    "ToolInfo",
    "Units",
    "dumps",
    "from_json",
    "json_schema",
    "read_summary",
    "schema_text",
]

#: The version of ``summary.json``'s layout (the module docstring's version policy).
SCHEMA_VERSION = 1


def _doc(doc: str, *, omit_if_none: bool = False) -> dict[str, Any]:
    """A field's metadata: its documentation (units, frames) for the schema; ``omit_if_none``:
    the key is left out of the file when the value is None (an optional section), else written
    as null."""
    return {"doc": doc, "omit_if_none": omit_if_none}


@dataclass(frozen=True)
class RobotInfo:
    """The robot of the analysed run."""

    model: str = field(metadata=_doc("the robot's preset or model name"))
    preset: str = field(
        metadata=_doc("the preset the study names (same as model for a preset robot)")
    )
    placement_T_base_work_m: list[list[float]] = field(
        metadata=_doc(
            "(4, 4) homogeneous transform of the work frame in the robot base frame; "
            "translation in m"
        )
    )
    joint_angles_from: str = field(
        metadata=_doc(
            "where the run's joint angles come from (the joint log and how it was aligned, or "
            "inverse kinematics)"
        )
    )


@dataclass(frozen=True)
class ToolInfo:
    """The forming tool and its holder."""

    ball_diameter_mm: float = field(metadata=_doc("tool ball diameter [mm]"))
    method: str = field(metadata=_doc("how the compliances were computed: beam, fe or a file"))
    lateral_compliance_m_per_N: float = field(
        metadata=_doc("the tool's lateral compliance at the ball [m/N]")
    )
    holder_lateral_compliance_m_per_N: float | None = field(
        metadata=_doc(
            "the tool holder's lateral compliance [m/N]; null when the study has no holder"
        )
    )


@dataclass(frozen=True)
class Units:
    """The units of the file's numbers (names: ``mm``, ``N``, ``N*m``, ``deg``, ``s``, ``SI``)."""

    length: str = field(metadata=_doc("unit of lengths (mm)"))
    force: str = field(metadata=_doc("unit of forces (N)"))
    moment: str = field(metadata=_doc("unit of moments (N*m)"))
    angle: str = field(metadata=_doc("unit of angles (deg)"))
    time: str = field(metadata=_doc("unit of times (s)"))
    compliance: str = field(metadata=_doc("unit of compliances (SI: m/N, rad/(N*m))"))


_JsonObject = dict[str, Any]


@dataclass(frozen=True)
class AnalysisSummary:
    """``summary.json`` of ``roboisf analyze`` for a study with a CNC and a robot run.

    The fields are written in this order; ``truth``, ``robot_run`` and ``iterations`` only when
    set. Objects typed ``dict[str, Any]`` are the documented sections of the named modules
    (docs/analyze.md, docs/diagnosis.md); their numbers are finite or null.
    """

    study: str = field(metadata=_doc("the study's name"))
    description: str = field(metadata=_doc("the study's description"))
    part: _JsonObject = field(
        metadata=_doc(
            "the part as its file describes it: kind and shape parameters (lengths mm, angles deg)"
        )
    )
    part_symmetry: int = field(
        metadata=_doc("the part's rotational symmetry order: 0 continuous (round), n >= 1 n-fold")
    )
    robot: RobotInfo = field(metadata=_doc("the robot of the robot run"))
    tool: ToolInfo = field(metadata=_doc("the tool and holder"))
    units: Units = field(metadata=_doc("the units of the file's numbers"))
    n_points: int = field(metadata=_doc("number of toolpath points"))
    n_points_used: int = field(
        metadata=_doc("toolpath points used in the statistics (below the rim band, scanned)")
    )
    rim_band_mm: float = field(metadata=_doc("points shallower than this are left out [mm]"))
    max_distance_mm: float = field(
        metadata=_doc("scan points farther than this from the nominal are cut [mm]")
    )
    beyond_max_distance: dict[str, dict[str, int]] = field(
        metadata=_doc(
            "per scan (cnc, robot): n wall points beyond max_distance of the wall's points"
        )
    )
    contour_z: float = field(metadata=_doc("the report's contour height [mm, work frame]"))
    compliance_stats: dict[str, dict[str, float | None]] = field(
        metadata=_doc(
            "the robot's Cartesian compliance k_ij (i,j = 1..6) over the used points: mean, std, "
            "min, max [SI: m/N, m/(N*m), rad/N, rad/(N*m)]"
        )
    )
    force_contributions: dict[str, dict[str, float | None]] = field(
        metadata=_doc(
            "the paper's Table 4: mean |deflection| [mm] per axis (dx, dy, dz) from each wrench "
            "component (Fx..Mz)"
        )
    )
    vjm_vs_experiment: dict[str, float | None] = field(
        metadata=_doc(
            "mean |robot term| - mean |VJM| along the normal, per work axis x, y, z and "
            "resultant [mm]"
        )
    )
    vjm_vs_experiment_per_axis: dict[str, float | None] = field(
        metadata=_doc("the same, per-axis book (the paper's Delta_i) [mm]")
    )
    registration: dict[str, _JsonObject] = field(
        metadata=_doc(
            "per scan (cnc, robot): how it was registered to the nominal (method, fitted dofs, "
            "transform; docs/scan.md)"
        )
    )
    warnings: list[str] = field(metadata=_doc("the analysis's warnings, one sentence each"))
    fingerprint: _JsonObject = field(
        metadata=_doc(
            "the study and input files these results are of (compensate --results checks it)"
        )
    )
    alignment: dict[str, _JsonObject] = field(
        metadata=_doc(
            "per run: how its logs were matched to the toolpath (source relative to the study)"
        )
    )
    vjm_check: _JsonObject = field(
        metadata=_doc(
            "does the robot model hold: ratio, interval, verdict, per depth (lengths mm; "
            "docs/analyze.md)"
        )
    )
    diagnosis: list[_JsonObject] = field(
        metadata=_doc(
            "one entry per suspect: verdict fault/ok/cannot_tell with a 95 % interval "
            "(docs/diagnosis.md)"
        )
    )
    diagnosis_headline: str = field(metadata=_doc("the diagnosis in one sentence"))
    diagnosis_forces_corrected: bool = field(
        metadata=_doc(
            "whether the diagnosis corrected the robot's forces against the CNC dynamometer"
        )
    )
    terms_normal: dict[str, _JsonObject] = field(
        metadata=_doc("statistics of each term's normal deviation over the used points [mm]")
    )
    identification: _JsonObject = field(
        metadata=_doc(
            "the robot's joint stiffness identified from the run (K in N*m/rad), or mode null with "
            "the reason"
        )
    )
    identified_stiffness: str | None = field(
        metadata=_doc(
            "the identified stiffness file, relative to the results folder; null when none"
        )
    )
    lateral_offset: dict[str, _JsonObject] = field(
        metadata=_doc("per run: the sideways scan shift its normal deviation carries (mm, deg)")
    )
    truth: _JsonObject | None = field(
        default=None,
        metadata=_doc(
            "virtual-cell studies: the ground truth beside the recovered values (mm, %)",
            omit_if_none=True,
        ),
    )
    robot_run: str | None = field(
        default=None,
        metadata=_doc(
            "the robot run these results are of (compensate --results checks it)",
            omit_if_none=True,
        ),
    )
    iterations: list[_JsonObject] | None = field(
        default=None,
        metadata=_doc(
            "several robot runs: one row per run (RMS, max, share per term [mm, %])",
            omit_if_none=True,
        ),
    )
    schema_version: int = field(
        default=SCHEMA_VERSION, metadata=_doc("summary.json's layout version")
    )

    def to_dict(self) -> dict[str, Any]:
        """The file's object, keys in the file's order (``schema_version`` first), values as
        held (numpy scalars and non-finite floats are converted by :func:`dumps` only)."""
        return _to_dict(self)


@dataclass(frozen=True)
class RobotOnlySummary:
    """``summary.json`` of ``roboisf analyze`` for a study without a CNC run: the model-based
    springback of one robot run (docs/analyze.md, "Robot-only studies")."""

    study: str = field(metadata=_doc("the study's name"))
    run: str = field(metadata=_doc("the analysed robot run"))
    kind: str = field(metadata=_doc("always robot-only"))
    robot: str = field(metadata=_doc("the robot's preset or model name"))
    joint_angles: str = field(metadata=_doc("where the run's joint angles come from"))
    springback_model_based: _JsonObject = field(
        metadata=_doc(
            "the springback estimate without a CNC run: separable, reason, beta, bounds (mm)"
        )
    )
    modelled_mean_abs_dn_mm: dict[str, float | None] = field(
        metadata=_doc(
            "mean |normal deviation| of each modelled term (tool, tool_holder, vjm, command) [mm]"
        )
    )
    measured_mean_abs_dn_mm: float | None = field(
        metadata=_doc("mean |normal deviation| of the scan [mm]")
    )
    warnings: list[str] = field(metadata=_doc("the analysis's warnings, one sentence each"))
    truth: _JsonObject | None = field(
        default=None,
        metadata=_doc(
            "virtual-cell studies: springback_rms_error_mm against the ground truth",
            omit_if_none=True,
        ),
    )
    schema_version: int = field(
        default=SCHEMA_VERSION, metadata=_doc("summary.json's layout version")
    )

    def to_dict(self) -> dict[str, Any]:
        """The file's object, keys in the file's order (``schema_version`` first)."""
        return _to_dict(self)


Summary = AnalysisSummary | RobotOnlySummary


# --------------------------------------------------------------------------- serialise


def _ordered_fields(cls: type) -> list[dataclasses.Field[Any]]:
    """``schema_version`` first, then the fields in declaration order."""
    fs = list(dataclasses.fields(cls))
    return [f for f in fs if f.name == "schema_version"] + [
        f for f in fs if f.name != "schema_version"
    ]


def _to_dict(obj: Any) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for f in _ordered_fields(type(obj)):
        v = getattr(obj, f.name)
        if v is None and f.metadata.get("omit_if_none"):
            continue
        out[f.name] = _to_dict(v) if dataclasses.is_dataclass(v) else v
    return out


def dumps(summary: Summary) -> str:
    """``summary.json``'s text (two-space indent, the fields' order; NaN and inf as null)."""
    return json.dumps(jsonable(summary.to_dict()), indent=2)


# --------------------------------------------------------------------------- read


def read_summary(path: str | Path) -> Summary:
    """Read ``summary.json`` (a results folder's or the file itself); a file that is not JSON,
    of another :data:`SCHEMA_VERSION`, or with a missing or mistyped field raises
    :class:`~roboisf.errors.InputError` naming the file and the field."""
    p = Path(path)
    if p.is_dir():
        p = p / "summary.json"
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as e:
        raise InputError(f"cannot read the summary ({e.strerror or e})", file=p) from None
    return from_json(text, file=p)


def from_json(text: str, *, file: str | Path | None = None) -> Summary:
    """The summary in ``text`` (``summary.json``'s content); ``file`` names it in errors."""
    try:
        data = json.loads(text)
    except ValueError as e:
        raise InputError(f"not JSON ({e})", file=file) from None
    if not isinstance(data, dict):
        raise InputError(f"expected a JSON object, got {type(data).__name__}", file=file)
    version = data.get("schema_version")
    if version != SCHEMA_VERSION:
        said = "none (written before summaries were versioned)" if version is None else version
        raise InputError(
            f"summary schema_version {said}, this roboisf reads version {SCHEMA_VERSION}: "
            "re-run roboisf analyze on the study",
            file=file,
            field="schema_version",
        )
    cls: type = RobotOnlySummary if data.get("kind") == "robot-only" else AnalysisSummary
    return typing.cast(Summary, _build(cls, data, "", file))


def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _build(cls: type, data: Mapping[str, Any], where: str, file: Any) -> Any:
    hints = _hints(cls)
    known = {f.name for f in dataclasses.fields(cls)}
    extra = [k for k in data if k not in known]
    if extra:
        raise InputError(
            f"unknown field (expected one of {', '.join(sorted(known))})",
            file=file,
            field=where + extra[0],
        )
    kw = {}
    for f in dataclasses.fields(cls):
        name = where + f.name
        if f.name not in data:
            if f.default is not dataclasses.MISSING:
                continue
            raise InputError("missing field", file=file, field=name)
        kw[f.name] = _value(hints[f.name], data[f.name], name, file)
    return cls(**kw)


def _describe(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if tp is Any:
        return "any value"
    if origin in (Union, types.UnionType):
        return " or ".join(_describe(a) for a in typing.get_args(tp))
    if origin is list:
        return "a list"
    if origin is dict or dataclasses.is_dataclass(tp):
        return "an object"
    return {str: "a string", int: "an integer", float: "a number", bool: "true or false"}.get(
        tp, "null" if tp is type(None) else str(tp)
    )


def _value(tp: Any, v: Any, where: str, file: Any) -> Any:
    """``v`` checked against the type hint ``tp`` (the path ``where`` names it in errors)."""
    origin = typing.get_origin(tp)
    if tp is Any:
        return v
    if origin in (Union, types.UnionType):
        args = typing.get_args(tp)
        if v is None and type(None) in args:
            return None
        for a in args:
            if a is type(None):
                continue
            try:
                return _value(a, v, where, file)
            except InputError:
                continue
        raise InputError(f"expected {_describe(tp)}, got {v!r:.60}", file=file, field=where)
    if dataclasses.is_dataclass(tp):
        if not isinstance(v, dict):
            raise InputError(f"expected an object, got {v!r:.60}", file=file, field=where)
        return _build(typing.cast(type, tp), v, where + ".", file)
    if origin is list:
        if not isinstance(v, list):
            raise InputError(f"expected a list, got {v!r:.60}", file=file, field=where)
        (item,) = typing.get_args(tp)
        return [_value(item, x, f"{where}[{i}]", file) for i, x in enumerate(v)]
    if origin is dict:
        if not isinstance(v, dict):
            raise InputError(f"expected an object, got {v!r:.60}", file=file, field=where)
        _, item = typing.get_args(tp)
        return {k: _value(item, x, f"{where}.{k}", file) for k, x in v.items()}
    ok = {
        str: isinstance(v, str),
        bool: isinstance(v, bool),
        int: isinstance(v, int) and not isinstance(v, bool),
        float: isinstance(v, int | float) and not isinstance(v, bool),
    }.get(tp)
    if ok is None:  # pragma: no cover - a field type the schema does not know
        raise TypeError(f"summary field {where}: unsupported type {tp}")
    if not ok:
        raise InputError(f"expected {_describe(tp)}, got {v!r:.60}", file=file, field=where)
    return v


# --------------------------------------------------------------------------- schema


def _schema_of(tp: Any, defs: dict[str, Any]) -> dict[str, Any]:
    origin = typing.get_origin(tp)
    if tp is Any:
        return {}
    if origin in (Union, types.UnionType):
        args = typing.get_args(tp)
        return {"anyOf": [_schema_of(a, defs) for a in args]}
    if tp is type(None):
        return {"type": "null"}
    if dataclasses.is_dataclass(tp):
        cls = typing.cast(type, tp)
        if cls.__name__ not in defs:
            defs[cls.__name__] = {}  # reserve: keeps the order of first use
            defs[cls.__name__] = _object_schema(cls, defs)
        return {"$ref": f"#/$defs/{cls.__name__}"}
    if origin is list:
        (item,) = typing.get_args(tp)
        return {"type": "array", "items": _schema_of(item, defs)}
    if origin is dict:
        _, item = typing.get_args(tp)
        return {"type": "object", "additionalProperties": _schema_of(item, defs)}
    return {"type": {str: "string", int: "integer", float: "number", bool: "boolean"}[tp]}


def _object_schema(cls: type, defs: dict[str, Any]) -> dict[str, Any]:
    hints = _hints(cls)
    props: dict[str, Any] = {}
    required = []
    for f in _ordered_fields(cls):
        s = _schema_of(hints[f.name], defs)
        if f.name == "schema_version":
            s = {"const": SCHEMA_VERSION}
        props[f.name] = {"description": f.metadata["doc"], **s}
        if f.default is dataclasses.MISSING or f.name == "schema_version":
            required.append(f.name)
    return {
        "description": " ".join((cls.__doc__ or "").split()),
        "type": "object",
        "properties": props,
        "required": required,
        "additionalProperties": False,
    }


def json_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of ``summary.json``, generated from the dataclasses."""
    defs: dict[str, Any] = {}
    analysis = _schema_of(AnalysisSummary, defs)
    robot_only = _schema_of(RobotOnlySummary, defs)
    # the two layouts: a robot-only summary says so in "kind"; an analysis summary has no "kind"
    defs["RobotOnlySummary"]["properties"]["kind"]["const"] = "robot-only"
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "roboisf analyze summary.json",
        "description": (
            f"summary.json schema_version {SCHEMA_VERSION}, generated by "
            "roboisf.summary.json_schema (docs/summary.md)."
        ),
        "oneOf": [analysis, robot_only],
        "$defs": defs,
    }


def schema_text() -> str:
    """:func:`json_schema` as ``docs/summary.schema.json`` holds it (indent 2, final newline)."""
    return json.dumps(json_schema(), indent=2, ensure_ascii=False) + "\n"
