"""The compensated command: springback adjustment of the target, then compliance pre-deflection.

Per toolpath point (work frame, SI; ``n`` the nominal tool-side normal, ``T_nom`` the nominal
tip, ``c`` the commanded normal offset of the ball)::

    target  = T_nom + c_{k+1} n                        c_{k+1} = c_k − λ S[D_k]
    command : p + δ(p) = target                          (compliance pre-deflection)

``D_k`` is the measured normal deviation of the part formed by the command ``F`` (default the
nominal) minus what the new command removes by design — with compliance pre-deflection on, the
predicted landing error of ``F``::

    D_k = dn_measured − n · (F + δ(F) − T_nom − c_k n)        (δ ≡ 0 with compliance off)

so a first step from an uncompensated part feeds back the springback estimate (and the model
error), and later steps the residual of a compensated part. Springback is assumed independent of
the command (the model of :func:`roboisf.virtual.cell.simulate`); the iteration corrects what that
assumption misses.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from roboisf.cam.program import RobotTool
from roboisf.compensate.adjust import Adjustment, displacement_adjustment
from roboisf.compensate.compliance import (
    ComplianceCompensation,
    DeflectionModel,
    precompensate,
)
from roboisf.compensate.gouge import GougeReport, gouge_check
from roboisf.errors import InputError
from roboisf.io.atomic import atomic_write, staged_directory
from roboisf.parts.base import Part
from roboisf.path.toolpath import Toolpath
from roboisf.programs.export import write_toolpath
from roboisf.programs.registry import program_formats
from roboisf.progress import Progress, task

if TYPE_CHECKING:
    from roboisf.robot.model import RobotModel

__all__ = [
    "Compensation",
    "CompensationOptions",
    "compensate",
    "edge_source",
    "lap_table",
    "nominal_of",
    "rim_blend",
    "write_compensation",
]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class CompensationOptions:
    """What to compensate and how (SI).

    compliance, springback : which terms to compensate
    gain : λ of the displacement adjustment, in (0, 2)
    along, across : m — Gaussian smoothing widths of the measured deviation
    min_support, on_gap : holes that cannot be filled: raise, or hold and flag
    relax, tol, max_iter, partial : the compliance fixed point
        (``partial``: return non-converged points flagged instead of raising)
    gouge_tol, max_overbend : m — gouge rule (:mod:`roboisf.compensate.gouge`)
    rim_blend : m — depth over which the springback adjustment ramps in inside the rim band, up
        to its edge (a smoothstep, :func:`rim_blend`; 0: a hard edge). Without it the command
        steps by the full offset between the last lap of the band and the first below it.
    """

    compliance: bool = True
    springback: bool = True
    gain: float = 0.8
    along: float = 3e-3
    across: float = 1e-3
    min_support: float = 0.05
    on_gap: Literal["raise", "hold"] = "raise"
    relax: float = 0.8
    tol: float = 1e-7
    max_iter: int = 50
    partial: bool = False
    gouge_tol: float = 10e-6
    max_overbend: float = 2e-3
    rim_blend: float = 5e-3

    def __post_init__(self) -> None:
        if not (self.compliance or self.springback):
            raise InputError("nothing to compensate: enable compliance or springback")
        for name in ("along", "across", "gouge_tol", "max_overbend", "rim_blend"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f"must be ≥ 0, got {v:g}", field=name)


@dataclass(frozen=True, eq=False)
class Compensation:
    """A compensated command and how it was obtained (work frame, SI).

    toolpath : Toolpath — nominal contacts and normals, the commanded ``tip``
    nominal : Toolpath — the nominal command
    offset : (N,) float, m — commanded normal offset ``c`` of the target (springback)
    target : (N, 3) float, m — where the loaded tip must land
    deflection : (N, 3) float, m — predicted deflection at the command (0 without a model)
    adjustment, compliance : the two steps' results (None when not run)
    gouge : GougeReport
    complete : bool — False for a partial (flagged) compliance result
    """

    toolpath: Toolpath
    nominal: Toolpath
    offset: F64
    target: F64
    deflection: F64
    adjustment: Adjustment | None
    compliance: ComplianceCompensation | None
    gouge: GougeReport
    options: CompensationOptions
    complete: bool = True
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def command_offset(self) -> F64:
        """Commanded tip − nominal tip (N, 3) m."""
        return self.toolpath.tip - self.nominal.tip

    def per_point(self) -> pd.DataFrame:
        """Per-point table in mm with the flags (converged, filled, held, gouge)."""
        tp, n = self.toolpath, self.nominal.normal
        off = self.command_offset
        cols: dict[str, Any] = {"index": np.arange(len(tp)), "lap": tp.lap}
        for j, ax in enumerate("xyz"):
            cols[f"tip_{ax}"] = tp.tip[:, j] * 1e3
        for j, ax in enumerate("xyz"):
            cols[f"command_d{ax}"] = off[:, j] * 1e3
        cols["command_dn"] = np.einsum("ij,ij->i", off, n) * 1e3
        cols["springback_offset_dn"] = self.offset * 1e3
        cols["predicted_deflection_dn"] = np.einsum("ij,ij->i", self.deflection, n) * 1e3
        comp = self.compliance
        cols["residual"] = np.zeros(len(tp)) if comp is None else comp.residual * 1e3
        cols["converged"] = np.ones(len(tp), bool) if comp is None else comp.converged
        adj = self.adjustment
        z = np.zeros(len(tp), bool)
        cols["filled"] = z if adj is None else adj.filled
        cols["held"] = z if adj is None else adj.held
        cols["gouge_margin"] = (self.gouge.distance - self.gouge.allowed) * 1e3
        cols["gouge"] = self.gouge.gouge
        return pd.DataFrame(cols)

    def lap_steps(self) -> dict[str, float]:
        """Largest change [m] between consecutive laps of the per-lap mean springback offset
        ``c`` and of the commanded normal offset (a ledge in the next part if large)."""
        cdn = np.einsum("ij,ij->i", self.command_offset, self.nominal.normal)
        t = lap_table(self.toolpath.lap, offset=self.offset, command_dn=cdn)
        out = {}
        for col in ("offset", "command_dn"):
            d = np.abs(np.diff(t[col].to_numpy()))
            d = d[np.isfinite(d)]
            out[col] = float(d.max()) if d.size else 0.0
        return out

    def summary(self) -> dict[str, Any]:
        o = self.options
        off = np.linalg.norm(self.command_offset, axis=1)
        steps = self.lap_steps()
        return {
            "complete": self.complete,
            "terms": {"compliance": o.compliance, "springback": o.springback},
            "n_points": len(self.toolpath),
            "max_command_offset_mm": float(off.max()) * 1e3,
            "mean_command_offset_mm": float(off.mean()) * 1e3,
            "rim_blend_mm": o.rim_blend * 1e3,
            "max_lap_step_springback_offset_mm": steps["offset"] * 1e3,
            "max_lap_step_command_dn_mm": steps["command_dn"] * 1e3,
            "compliance": None if self.compliance is None else self.compliance.report(),
            "springback": None if self.adjustment is None else self.adjustment.report(),
            "gouge": self.gouge.report(),
            **self.meta,
        }


def nominal_of(toolpath: Toolpath) -> Toolpath:
    """The nominal command of a toolpath: the tip from its contacts and normals (a compensated
    path's ``tip`` is replaced by ``contact + R n − R ẑ``)."""
    return Toolpath.from_contact(
        toolpath.contact,
        toolpath.normal,
        toolpath.wall_angle,
        toolpath.lap,
        toolpath.tool_radius,
        toolpath.feed,
        toolpath.meta,
    )


def compensate(
    part: Part,
    nominal: Toolpath,
    *,
    model: DeflectionModel | None = None,
    wrench: ArrayLike | None = None,
    deviation: ArrayLike | None = None,
    valid: ArrayLike | None = None,
    region: ArrayLike | None = None,
    blend: ArrayLike | None = None,
    source: ArrayLike | None = None,
    formed: ArrayLike | None = None,
    previous_offset: ArrayLike | None = None,
    options: CompensationOptions | None = None,
    progress: Progress | None = None,
) -> Compensation:
    """The compensated command for ``nominal`` (module docstring for the equations).

    Parameters
    ----------
    part : the nominal part (gouge check)
    nominal : the nominal toolpath (its ``tip`` is recomputed from contacts: :func:`nominal_of`)
    model : DeflectionModel — needed for compliance compensation; used for the gouge check and
        the deflection correction of ``deviation`` whenever given
    wrench : (N, 6) float [N; N·m] — tip wrench on the tool, work axes (predicted or measured)
    deviation : (N,) float, m — measured normal deviation ``dn`` of the part formed by ``formed``
    valid : (N,) bool — where ``deviation`` is a measurement (holes are filled and flagged)
    region : (N,) bool — points to springback-compensate (default all)
    blend : (N,) float in [0, 1] — share of the springback update applied per point (default 1
        in the region; :func:`rim_blend` ramps it in across a rim band's edge)
    source : (N,) int — the point whose smoothed deviation each point takes (:func:`edge_source`)
    formed : (N, 3) float, m — the commanded tip that formed the measured part (default nominal)
    previous_offset : (N,) float, m — ``c_k`` of the command that formed it (default 0)
    """
    o = options or CompensationOptions()
    nom = nominal_of(nominal)
    N = len(nom)
    n = nom.normal
    W = None if wrench is None else np.asarray(wrench, dtype=float)
    if W is not None and W.shape != (N, 6):
        raise InputError(f"expected a wrench per point ({N}, 6), got {W.shape}", field="wrench")
    if o.compliance and (model is None or W is None):
        raise InputError("compliance compensation needs a deflection model and the wrench")
    c_prev = np.zeros(N) if previous_offset is None else np.asarray(previous_offset, dtype=float)
    if c_prev.shape != (N,):
        raise InputError(f"expected ({N},) previous offsets", field="previous_offset")
    with_model = model is not None and W is not None

    adj = None
    c = c_prev
    if o.springback:
        if deviation is None:
            raise InputError("springback compensation needs a measured deviation (dn)")
        D = np.asarray(deviation, dtype=float)
        if D.shape != (N,):
            raise InputError(f"expected one deviation per point ({N},), got {D.shape}")
        F = nom.tip if formed is None else np.asarray(formed, dtype=float)
        if F.shape != (N, 3) or not np.all(np.isfinite(F)):
            raise InputError(f"expected finite formed tips ({N}, 3)", field="formed")
        landing = F.copy()
        if o.compliance:
            assert model is not None and W is not None
            with task(progress, "deflection of the formed command"):
                landing = landing + model.deflection(F, W)[0]
        expected = np.einsum("ij,ij->i", landing - nom.tip, n) - c_prev
        adj = displacement_adjustment(
            nom,
            D - expected,
            offset=c_prev,
            valid=valid,
            region=region,
            blend=blend,
            source=source,
            gain=o.gain,
            along=o.along,
            across=o.across,
            min_support=o.min_support,
            on_gap=o.on_gap,
        )
        c = adj.offset
    target = nom.tip + c[:, None] * n

    comp = None
    complete = True
    if o.compliance:
        assert model is not None and W is not None
        comp = precompensate(
            target,
            W,
            model,
            relax=o.relax,
            tol=o.tol,
            max_iter=o.max_iter,
            partial=o.partial,
            progress=progress,
        )
        cmd = comp.commanded
        defl = comp.deflection
        complete = bool(comp.converged.all())
    else:
        cmd = target
        defl = model.deflection(cmd, W)[0] if with_model else np.zeros((N, 3))  # type: ignore[union-attr,arg-type]
    tp = nom.with_tip(cmd)
    gouge = gouge_check(
        part,
        cmd,
        nom.tool_radius,
        deflection=defl,
        normal_offset=c,
        tol=o.gouge_tol,
        max_overbend=o.max_overbend,
    )
    return Compensation(tp, nom, c, target, defl, adj, comp, gouge, o, complete)


def rim_blend(depth: ArrayLike, rim_band: float, width: float) -> F64:
    """Blend weights (N,) in [0, 1]: 1 below the rim band (``depth > rim_band``: the analysed
    wall gets the whole adjustment), a smoothstep ``3t² − 2t³`` over the last ``width`` [m] of the
    band (slope at most 1.5/width), 0 above ``rim_band − width``. ``width`` 0: the hard edge.

    The ramp lies inside the band, where the method has no deviation of its own: blended band
    points take the offset of the first lap below it (:func:`edge_source`), scaled by the weight.
    Iterations keep the shape (a band point never feeds back a residual of its own, so it
    converges to ``b`` × the edge's offset) and the analysed wall loses nothing."""
    d = np.asarray(depth, dtype=float)
    if width <= 0:
        return (d > rim_band).astype(float)
    t = np.clip((d - rim_band + width) / width, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def edge_source(toolpath: Toolpath, rim_band: float, blend: ArrayLike) -> NDArray[np.int64]:
    """For the blended points in the rim band (``depth ≤ rim_band``, ``blend > 0``): the point
    nearest in angle on the first lap below the band, whose smoothed deviation they take (the
    method has none of their own); every other point is its own source."""
    tp = toolpath
    b = np.asarray(blend, dtype=float)
    src = np.arange(len(tp))
    need = (tp.depth <= rim_band) & (b > 0)
    below = tp.depth > rim_band
    if not need.any() or not below.any():
        return src
    first = tp.lap[below].min()
    cand = np.flatnonzero((tp.lap == first) & below)
    ang = tp.angle[cand]
    order = np.argsort(ang)
    a_s, c_s = ang[order], cand[order]
    a = tp.angle[need]
    # periodic nearest neighbour in angle
    ext_a = np.concatenate([a_s - 2 * np.pi, a_s, a_s + 2 * np.pi])
    ext_c = np.concatenate([c_s, c_s, c_s])
    j = np.clip(np.searchsorted(ext_a, a), 1, len(ext_a) - 1)
    left_closer = (a - ext_a[j - 1]) <= (ext_a[j] - a)
    src[need] = np.where(left_closer, ext_c[j - 1], ext_c[j])
    return src


def lap_table(lap: ArrayLike, **series: ArrayLike) -> pd.DataFrame:
    """Per-lap means of per-point series (NaN-aware); ``lap`` (N,) int. Columns as given."""
    lap = np.asarray(lap)
    L = int(lap.max()) + 1
    out: dict[str, Any] = {"lap": np.arange(L)}
    for name, v in series.items():
        v = np.asarray(v, dtype=float)
        ok = np.isfinite(v)
        cnt = np.bincount(lap[ok], minlength=L)
        s = np.bincount(lap[ok], weights=v[ok], minlength=L)
        with np.errstate(invalid="ignore", divide="ignore"):
            out[name] = np.where(cnt > 0, s / np.maximum(cnt, 1), np.nan)
    return pd.DataFrame(out)


def write_compensation(
    comp: Compensation,
    out_dir: str | Path,
    *,
    T_base_work: ArrayLike,
    tool: RobotTool,
    tool_rotation: float = 0.0,
    robot: RobotModel | None = None,
    dn_before: ArrayLike | None = None,
    dn_after: ArrayLike | None = None,
    after_label: str = "predicted",
    inputs: tuple[Path, ...] = (),
    png: bool = False,
    progress: Progress | None = None,
) -> Path:
    """Write the compensated command and the before/after comparison into ``out_dir``.

    Files: ``compensated<suffix>`` in every registered format (:mod:`roboisf.programs.registry`;
    built in: ``compensated.csv`` (toolpath CSV), ``compensated.mod`` (RAPID; with part modules
    ``compensated_<k>.mod`` for a long path), ``compensated.src`` + ``.dat`` (KRL),
    ``compensated.ls`` (FANUC), ``compensated.nc`` (G-code: the CNC command, no pre-deflection)),
    ``per_point.csv`` (mm, flags),
    ``compensation.json``, ``compensation.html`` and ``compensation.png`` (with ``png``). The
    folder is replaced only when everything is written. Refuses a gouging command, and a
    partial (non-converged) one unless the options asked for it (then ``complete`` is false in
    the JSON and the per-point ``converged`` flags say where).

    The robot programs carry the full command (robot/tool/holder pre-deflection + springback
    adjustment) in the frames given (``T_base_work``, ``tool``), with the configuration data of
    the IK branch of ``robot`` (the robot model with its tool) along the command. The G-code
    carries only what applies to any machine: the nominal tip + the springback adjustment
    (``target``), not the robot's compliance pre-deflection.
    """
    from roboisf.report.compensation import write_compensation_report

    out_dir = Path(out_dir)
    for p in inputs:
        rp, ro = Path(p).resolve(), out_dir.resolve()
        if rp == ro or ro in rp.parents:
            raise InputError(
                "the output folder must not hold an input; choose another -o", file=out_dir
            )
    comp.gouge.raise_if_gouging()
    if not comp.complete and not comp.options.partial:
        raise InputError("refusing to write a partial compensation that was not asked for")
    N = len(comp.toolpath)
    pp = comp.per_point()
    series: dict[str, Any] = {
        "command_dn": pp["command_dn"].to_numpy(),
        "command_norm": np.linalg.norm(comp.command_offset, axis=1) * 1e3,
    }
    if dn_before is not None:
        b = np.asarray(dn_before, dtype=float)
        if b.shape != (N,):
            raise InputError(f"expected ({N},) dn_before", field="dn_before")
        pp["dn_before"] = b * 1e3
        series["abs_dn_before"] = np.abs(b) * 1e3
    if dn_after is not None:
        a = np.asarray(dn_after, dtype=float)
        if a.shape != (N,):
            raise InputError(f"expected ({N},) dn_after", field="dn_after")
        pp[f"dn_after_{after_label}"] = a * 1e3
        series["abs_dn_after"] = np.abs(a) * 1e3
    laps = lap_table(comp.toolpath.lap, **series)
    summary = comp.summary()
    summary["units"] = "mm"
    if dn_before is not None:
        summary["mean_abs_dn_before_mm"] = float(np.nanmean(series["abs_dn_before"]))
        # the points it is over (the robot scan's): the analysis's tables use those valid on
        # both scans, so the two means differ by their point sets (1.651 vs 1.660 mm)
        summary["n_points_before"] = int(np.count_nonzero(np.isfinite(series["abs_dn_before"])))
    if dn_after is not None:
        key = after_label.replace(" ", "_")
        summary[f"mean_abs_dn_after_{key}_mm"] = float(np.nanmean(series["abs_dn_after"]))
    summary["after"] = after_label
    config = None
    if robot is not None:
        from roboisf.robot.armconfig import program_config

        with task(progress, "IK along the compensated command"):
            config = program_config(robot, comp.toolpath, T_base_work, tool_rotation)
    cnc = comp.nominal.with_tip(comp.target)
    summary["gcode"] = (
        "compensated.nc: nominal tip + springback adjustment only (no robot/tool pre-deflection)"
    )
    with staged_directory(out_dir, "compensate") as d:
        with task(progress, "programs"):
            sb = "with" if comp.options.springback else "without"
            for fmt in program_formats():  # every registered format, each once
                if fmt.kind == "cnc":  # a CNC machine is stiff: no pre-deflection
                    write_toolpath(
                        cnc,
                        d / f"compensated{fmt.suffixes[0]}",
                        fmt.name,
                        gcode_notes=(
                            f"roboisf compensate: nominal path {sb} the springback adjustment",
                            "NOT in it: the robot/tool/holder pre-deflection of the robot programs",
                        ),
                    )
                else:
                    write_toolpath(
                        comp.toolpath,
                        d / f"compensated{fmt.suffixes[0]}",
                        fmt.name,
                        T_base_work=T_base_work,
                        tool=tool,
                        tool_rotation=tool_rotation,
                        config=config,
                    )
        with atomic_write(d / "per_point.csv") as fh:
            pp.to_csv(fh, index=False, float_format="%.6g")
        with atomic_write(d / "compensation.json") as fh:
            json.dump(summary, fh, indent=2)
        with task(progress, "report"):
            write_compensation_report(laps, summary, d, png=png)
    return out_dir
