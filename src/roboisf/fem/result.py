"""The compliance result and its JSON file (read by the rest of roboisf).

File format (``format: "roboisf.compliance"``, ``version: 1``), all values SI::

    {
      "format": "roboisf.compliance", "version": 1,
      "method": "fe" | "beam" | "assembly",
      "units": {...human-readable reminder...},
      "order": ["Fx", "Fy", "Fz", "Mx", "My", "Mz"],
      "compliance": [[6 × 6]],   # [δ; θ] = k [f; m]; blocks m/N, 1/N, 1/N, rad/(N·m)
      "reference_point": [x, y, z],   # m, in "frame"
      "frame": "tool: origin at the tip ..., z along the tool axis up",
      "quality": {...},          # figures of the FE run (see ComplianceResult)
      "geometry": {...}          # what produced it (dimensions in m, materials)
    }
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.frames import check_compliance
from roboisf.io.atomic import atomic_write

__all__ = [
    "LOAD_CASES",
    "ComplianceResult",
    "load_compliance_json",
    "save_compliance_json",
]

F64 = NDArray[np.float64]

LOAD_CASES = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")
FORMAT = "roboisf.compliance"
UNITS = {
    "compliance": "SI: [δ; θ] = k [f; m]; k[:3,:3] m/N, k[:3,3:] and k[3:,:3] 1/N, "
    "k[3:,3:] rad/(N*m)",
    "reference_point": "m",
    "geometry": "m, Pa",
}


@dataclass(frozen=True)
class ComplianceResult:
    """A 6×6 compliance about a reference point, with how it was obtained.

    Attributes
    ----------
    compliance : (6, 6) float, SI — rows/cols Fx Fy Fz Mx My Mz (m/N, 1/N, rad/(N·m))
    reference_point : (3,) float, m — in ``frame``
    frame : str — which axes and origin
    method : str — "fe", "beam" or "assembly"
    quality : dict — FE quality figures (JSON-able): ``symmetry_error``, ``resultant_error``,
        ``pnr`` (per load case), ``ci95`` (6×6: half-width of each fitted parameter, column =
        load case), ``kabsch_rel_diff``, ``mesh_size`` [m], ``n_nodes``, ``n_tets``, ``n_dofs``,
        ``mesh_convergence`` {``coarse_mesh_size``, ``rel_change``, ``richardson_error``, ...},
        ``beam_rel_diff`` and ``timings`` [s]
    geometry : dict — what produced it
    """

    compliance: F64
    reference_point: F64
    frame: str
    method: str = "fe"
    quality: dict[str, Any] = field(default_factory=dict)
    geometry: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "compliance", np.asarray(self.compliance, dtype=float))
        object.__setattr__(self, "reference_point", np.asarray(self.reference_point, dtype=float))
        if self.reference_point.shape != (3,):
            raise InputError("reference_point must have 3 coordinates", field="reference_point")
        if self.compliance.shape != (6, 6):
            raise InputError("compliance must be 6×6", field="compliance")

    @property
    def stiffness(self) -> F64:
        """``K = k⁻¹`` (6, 6) [N/m, N, N·m/rad]."""
        return np.asarray(np.linalg.inv(self.compliance), dtype=np.float64)

    @property
    def lateral(self) -> float:
        """Mean lateral compliance ``(k_xx + k_yy)/2`` [m/N]."""
        return 0.5 * float(self.compliance[0, 0] + self.compliance[1, 1])

    @property
    def axial(self) -> float:
        """Axial compliance ``k_zz`` [m/N]."""
        return float(self.compliance[2, 2])

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "version": 1,
            "method": self.method,
            "units": UNITS,
            "order": list(LOAD_CASES),
            "compliance": self.compliance.tolist(),
            "reference_point": self.reference_point.tolist(),
            "frame": self.frame,
            "quality": _jsonable(self.quality),
            "geometry": _jsonable(self.geometry),
        }


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return _jsonable(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None if math.isnan(obj) else ("inf" if obj > 0 else "-inf")
    if isinstance(obj, Path):
        return str(obj)
    return obj


def save_compliance_json(result: ComplianceResult, path: str | Path) -> Path:
    """Write ``result`` as the documented JSON file (atomically). Returns the path."""
    path = Path(path)
    text = json.dumps(result.to_dict(), indent=2, allow_nan=False)
    with atomic_write(path) as fh:
        fh.write(text + "\n")
    return path


def load_compliance_json(path: str | Path) -> ComplianceResult:
    """Read a compliance JSON file; validates the 6×6 (finite, symmetric, PSD) and the keys."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("compliance file not found", file=path) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        line = getattr(e, "lineno", None)
        raise InputError(f"not a JSON file: {e}", file=path, line=line) from None
    if not isinstance(data, dict):
        raise InputError("expected a JSON object with a 'compliance' key", file=path)
    if data.get("format", FORMAT) != FORMAT:
        raise InputError(
            f"expected format {FORMAT!r}, got {data.get('format')!r}", file=path, field="format"
        )
    for key in ("compliance", "reference_point"):
        if key not in data:
            raise InputError(f"missing key {key!r}", file=path, field=key)
    try:
        k = np.asarray(data["compliance"], dtype=float)
        p = np.asarray(data["reference_point"], dtype=float)
    except (TypeError, ValueError):
        raise InputError("compliance and reference_point must be numbers", file=path) from None
    if p.shape != (3,):
        raise InputError(
            "reference_point must be 3 numbers (m)", file=path, field="reference_point"
        )
    try:
        k = check_compliance(k, "compliance")
    except InputError as e:
        raise InputError(e.message, file=path, field="compliance") from None
    return ComplianceResult(
        compliance=k,
        reference_point=p,
        frame=str(data.get("frame", "")),
        method=str(data.get("method", "fe")),
        quality=dict(data.get("quality") or {}),
        geometry=dict(data.get("geometry") or {}),
    )
