"""The predicted error map of a part not yet formed, per term (work frame, SI).

Per toolpath point of the part's nominal step-down path in the given cell::

    springback   learned from the history (:mod:`roboisf.learn.springback`), with its interval
    tool, holder k_t W, k_th W — the cell's FE/beam compliances (roboisf.cell.tip_compliances)
    robot        the VJM k_c(q) W at the IK of the path, with the joint stiffness identified in
                 the history's latest part on the same robot when there is one (else the preset)

with ``W`` the forming wrench of the cell's force model (Aerens' axial force, wall angle from the
part; :func:`roboisf.cell.forces.tip_wrench`). Every term is the normal component at the ball
centre (positive towards the tool side), the book the scans can check; the total is their sum,
its interval the springback's (the model terms carry no interval: their error is the history's
VJM check, not a spread this prediction can estimate).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.cell import Cell, tip_compliances
from roboisf.cell.forces import ForceModel, tip_wrench
from roboisf.cell.model import at_ball_centre
from roboisf.errors import InputError
from roboisf.learn.features import FEATURES, point_features
from roboisf.learn.springback import SpringbackLearner
from roboisf.path.toolpath import Toolpath
from roboisf.progress import Progress, task
from roboisf.robot import ik_toolpath

__all__ = ["TERMS", "Prediction", "PredictionSetup", "identified_stiffness", "predict_part"]

F64 = NDArray[np.float64]
#: the predicted terms, in the analysis's names
TERMS = ("springback", "tool", "tool_holder", "robot_compliance")


@dataclass(frozen=True, eq=False)
class Prediction:
    """A part's predicted error (SI).

    toolpath : the nominal toolpath the prediction is for
    wrench : (N, 6) [N; N·m] — the predicted tip wrench, work axes
    dn : dict term → (N,) m — normal deviation per term (:data:`TERMS`)
    springback_low, springback_high : (N,) m — the springback interval
    features : (N, F) — the learner's inputs (:data:`roboisf.learn.features.FEATURES`)
    stiffness_source : str — where the robot's joint stiffness came from
    learner : SpringbackLearner
    """

    toolpath: Toolpath
    wrench: F64
    dn: dict[str, F64]
    springback_low: F64
    springback_high: F64
    features: F64
    stiffness_source: str
    learner: SpringbackLearner
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def total(self) -> F64:
        """(N,) m — the sum of the terms."""
        return np.asarray(sum(self.dn[t] for t in TERMS), dtype=float)

    def per_point(self) -> Any:
        """Per-point table (pandas) in mm and degrees, the analysis's column style."""
        import pandas as pd

        tp = self.toolpath
        cols: dict[str, Any] = {"index": np.arange(len(tp)), "lap": tp.lap}
        cols["depth"] = tp.depth * 1e3
        cols["wall_angle_deg"] = np.degrees(tp.wall_angle)
        for j, ax in enumerate("xyz"):
            cols[f"contact_{ax}"] = tp.contact[:, j] * 1e3
        for j, ax in enumerate("xyz"):
            cols[f"normal_{ax}"] = tp.normal[:, j]
        for j, c in enumerate(("Fx", "Fy", "Fz", "Mx", "My", "Mz")):
            cols[c] = self.wrench[:, j]
        for t in TERMS:
            cols[f"{t}_dn"] = self.dn[t] * 1e3
        cols["springback_dn_low"] = self.springback_low * 1e3
        cols["springback_dn_high"] = self.springback_high * 1e3
        total = self.total
        cols["total_dn"] = total * 1e3
        cols["total_dn_low"] = (total - self.dn["springback"] + self.springback_low) * 1e3
        cols["total_dn_high"] = (total - self.dn["springback"] + self.springback_high) * 1e3
        for j, f in enumerate(FEATURES):
            cols[f"feature_{f}"] = self.features[:, j]
        return pd.DataFrame(cols)

    def summary(self, scope: NDArray[np.bool_] | None = None) -> dict[str, Any]:
        """Per term the RMS and mean |dn| (mm), the model's figures, the inputs.

        ``scope`` (N,) bool: the points whose features are checked against the history's
        range (``extrapolated_features``) — ``roboisf predict`` passes the points below the rim
        band, where the history's analyses measured; above it every part's springback is
        extrapolated, which is said once instead (docs/history.md, Limits). None: every point.
        """
        X = self.features if scope is None else self.features[np.asarray(scope, dtype=bool)]
        terms = {
            t: {
                "rms_mm": float(np.sqrt(np.mean(v**2))) * 1e3,
                "mean_abs_mm": float(np.mean(np.abs(v))) * 1e3,
            }
            for t, v in {**self.dn, "total": self.total}.items()
        }
        return {
            "n_points": len(self.toolpath),
            "terms_normal": terms,
            "springback_model": self.learner.summary(),
            "joint_stiffness_from": self.stiffness_source,
            "extrapolated_features": self.learner.outside(X) if len(X) else {},
            "units": {"length": "mm", "angle": "deg", "force": "N", "moment": "N*m"},
            **self.meta,
        }


def identified_stiffness(db: Any, robot: str) -> tuple[list[float] | None, str]:
    """The joint stiffness (6 N·m/rad) identified in the latest part of ``robot`` in the
    history that has one, and a description of where it came from."""
    rows = db.query(
        "SELECT id, study, formed_at, identified_k_json FROM parts WHERE robot = ? "
        "AND identified_k_json IS NOT NULL ORDER BY formed_at DESC, id DESC",
        (robot,),
    )
    for pid, study, formed, text in rows:
        k = json.loads(text)
        if isinstance(k, list) and len(k) == 6 and all(float(v) > 0 for v in k):
            return [float(v) for v in k], f"identified in history part {pid} ({study}, {formed})"
    return None, "the robot preset (no identified stiffness for this robot in the history)"


def predict_part(
    cell: Cell,
    toolpath: Toolpath,
    learner: SpringbackLearner,
    *,
    step_down: float,
    material: str = "unknown",
    stiffness_source: str = "",
    progress: Progress | None = None,
) -> Prediction:
    """Predict every term at each point of ``toolpath`` (the cell's nominal path) — module doc.

    ``cell`` carries the part, tool, holder, robot (with the joint stiffness to use), placement
    and force model (``None``: :class:`~roboisf.cell.forces.ForceModel`'s default).
    """
    force = cell.force if cell.force is not None else ForceModel()
    tp = toolpath
    X = point_features(
        tp.contact,
        tp.normal,
        tp.wall_angle,
        tp.lap,
        step_down=step_down,
        tool_radius=tp.tool_radius,
        sheet_thickness=cell.part.sheet_thickness,
    )
    s, lo, hi = learner.predict(X, material)
    W = tip_wrench(tp, force, thickness=cell.part.sheet_thickness, step_down=step_down)
    with task(progress, "tool and holder compliance"):
        _, _, k_t, k_th = tip_compliances(cell, progress=progress)
    R = cell.tool.radius
    n = tp.normal
    with task(progress, "robot IK and VJM"):
        ik = ik_toolpath(cell.robot, tp.tip, cell.T_base_work, tool_rotation=cell.tool_rotation)
        robot = at_ball_centre(cell.robot.deflection(ik.q, W, T_base_work=cell.T_base_work), R)
    if not np.all(np.isfinite(s)):
        raise InputError("the springback model returned non-finite values")
    dn = {
        "springback": s,
        "tool": np.einsum("ij,ij->i", at_ball_centre(W @ k_t.T, R), n),
        "tool_holder": np.einsum("ij,ij->i", at_ball_centre(W @ k_th.T, R), n),
        "robot_compliance": np.einsum("ij,ij->i", robot, n),
    }
    return Prediction(tp, W, dn, lo, hi, X, stiffness_source, learner)


@dataclass(frozen=True)
class PredictionSetup:
    """What a prediction is for, enough to rebuild its cell and toolpath (``compensate
    --predicted``). Lengths m, angles rad; ``part_file`` absolute, with its SHA-256.

    joint_stiffness : (6,) N·m/rad or None (the preset's)
    """

    part_file: str
    part_sha256: str
    robot: str
    T_base_work: tuple[tuple[float, ...], ...]
    step_down: float
    spacing: float
    compliance_method: str = "beam"
    tool_rotation: float = 0.0
    joint_stiffness: tuple[float, ...] | None = None
    material: str = "unknown"

    def to_json(self) -> dict[str, Any]:
        """File units: mm and degrees (the ``setup`` table of ``prediction.json``)."""
        T = np.asarray(self.T_base_work)
        return {
            "part_file": self.part_file,
            "part_sha256": self.part_sha256,
            "robot": self.robot,
            "placement_T_base_work_mm": [[*r[:3], r[3] * 1e3] for r in T[:3].tolist()]
            + [[0.0, 0.0, 0.0, 1.0]],
            "step_down_mm": self.step_down * 1e3,
            "spacing_mm": self.spacing * 1e3,
            "compliance_method": self.compliance_method,
            "tool_rotation_deg": float(np.degrees(self.tool_rotation)),
            "joint_stiffness_N_m_per_rad": None
            if self.joint_stiffness is None
            else list(self.joint_stiffness),
            "material": self.material,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any], file: str) -> PredictionSetup:
        """Read :meth:`to_json`'s table; ``file`` names it in errors."""
        try:
            T = np.array(data["placement_T_base_work_mm"], dtype=float)
            if T.shape != (4, 4):
                raise ValueError("placement is not 4 × 4")
            T[:3, 3] *= 1e-3
            k = data.get("joint_stiffness_N_m_per_rad")
            return cls(
                part_file=str(data["part_file"]),
                part_sha256=str(data["part_sha256"]),
                robot=str(data["robot"]),
                T_base_work=tuple(tuple(r) for r in T.tolist()),
                step_down=float(data["step_down_mm"]) * 1e-3,
                spacing=float(data["spacing_mm"]) * 1e-3,
                compliance_method=str(data.get("compliance_method", "beam")),
                tool_rotation=float(np.radians(float(data.get("tool_rotation_deg", 0.0)))),
                joint_stiffness=None if k is None else tuple(float(v) for v in k),
                material=str(data.get("material", "unknown")),
            )
        except (KeyError, TypeError, ValueError) as e:
            raise InputError(f"not a roboisf prediction setup ({e})", file=file) from None

    def build(self) -> tuple[Cell, Toolpath]:
        """The cell (force model: :class:`ForceModel`'s default) and its nominal toolpath."""
        import hashlib
        from pathlib import Path

        from roboisf.cell import make_cell
        from roboisf.parts import load_part

        path = Path(self.part_file)
        if not path.is_file():
            raise InputError("the predicted part's file is gone", file=path)
        if hashlib.sha256(path.read_bytes()).hexdigest() != self.part_sha256:
            raise InputError(
                "the part file changed since the prediction; predict it again", file=path
            )
        cell = make_cell(
            load_part(path),
            robot=self.robot,
            T_base_work=np.asarray(self.T_base_work, dtype=float),
            joint_stiffness=self.joint_stiffness,
            compliance_method=self.compliance_method,  # type: ignore[arg-type]
            tool_rotation=self.tool_rotation,
            force=ForceModel(),
        )
        return cell, cell.toolpath(self.step_down, spacing=self.spacing)
