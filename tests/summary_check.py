"""Every ``summary.json`` a test's study produces, checked against the published JSON Schema
(``docs/summary.schema.json``, with the ``jsonschema`` library) and read back by the one reader
(:func:`roboisf.summary.read_summary`), whose serialiser must give the same bytes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np

from roboisf.summary import (
    AnalysisSummary,
    RobotInfo,
    ToolInfo,
    Units,
    dumps,
    read_summary,
)

SCHEMA_FILE = Path(__file__).resolve().parents[1] / "docs" / "summary.schema.json"


def schema() -> dict[str, Any]:
    return json.loads(SCHEMA_FILE.read_text(encoding="utf-8"))


def validated(path: Path) -> dict[str, Any]:
    """``path`` (a summary.json or its results folder) as a dict, after checking that it
    validates against the schema and that reading and writing it again gives the same text."""
    path = Path(path)
    if path.is_dir():
        path = path / "summary.json"
    text = path.read_text(encoding="utf-8")
    data = json.loads(text)
    jsonschema.Draft202012Validator(schema()).validate(data)
    assert dumps(read_summary(path)) == text, f"{path}: read and written again differs"
    return data


def minimal_summary(**kw: object) -> AnalysisSummary:
    """A valid summary with small made-up values (``kw`` replaces fields)."""
    base: dict[str, object] = {
        "study": "s",
        "description": "a test",
        "part": {"kind": "cone", "sheet_thickness": 1.22},
        "part_symmetry": 0,
        "robot": RobotInfo("irb", "irb", np.eye(4).tolist(), "inverse kinematics"),
        "tool": ToolInfo(10.0, "beam", 9.4e-7, None),
        "units": Units("mm", "N", "N*m", "deg", "s", "SI"),
        "n_points": 3,
        "n_points_used": 2,
        "rim_band_mm": 20.0,
        "max_distance_mm": 3.0,
        "beyond_max_distance": {"cnc": {"n": 0, "of": 10}},
        "contour_z": -11.0,
        "compliance_stats": {"k_11": {"mean": 1e-6, "std": 0.0, "min": 1e-6, "max": 1e-6}},
        "force_contributions": {"dx": {"Fx": 0.1}},
        "vjm_vs_experiment": {"x": np.float64(0.5), "resultant": float("nan")},
        "vjm_vs_experiment_per_axis": {"x": 0.3},
        "registration": {"cnc": {"method": "fixture"}},
        "warnings": ["w"],
        "fingerprint": {"format": "roboisf-study-fingerprint-1"},
        "alignment": {},
        "vjm_check": {"verdict": "consistent"},
        "diagnosis": [{"suspect": "force_bias", "verdict": "ok"}],
        "diagnosis_headline": "no fault",
        "diagnosis_forces_corrected": False,
        "terms_normal": {"tool": {"rms": 0.1}},
        "identification": {"mode": None},
        "identified_stiffness": None,
        "lateral_offset": {},
    }
    base.update(kw)
    return AnalysisSummary(**base)  # type: ignore[arg-type]
