"""The diagnosis over random hidden truths: verdict accuracy, interval coverage, compensation.

Run by hand:  PYTHONPATH=src python benchmarks/diagnosis.py [N_TRUTHS] [SEED] [N_EXTRA]
              [moment-bias]

Draws ``N_TRUTHS`` (default 40) truths — faults alone and in pairs among: joint stiffness
(each joint 0.4–1.6×), flange-sensor gain (0.85–1.15), crosstalk (force channels ≤ 0.03, force
into moment ≤ 30 mm = N·m per kN), a force bias (10–40 N), an unmodelled tool mass (1–5 kg),
a sideways scan shift (≤ 0.3 mm) and a rotation about the part axis (≤ 0.3°) — and, with
``moment-bias``, every second truth also a bias of the moment channels (0.2–3 N·m, drawn from
its own generator: the other draws stay those of the seed) — on the cone, the
VWACF, the pyramid and a mesh part (the cone tessellated), builds each as a small virtual study
(2–3 mm step-down, 40–60 k scan points), runs ``analyze`` and compares the diagnosis with the
truth. Then ``N_EXTRA`` (default 12) truths drawn from another stream (the first ``N_TRUTHS``
stay those of the runs before), each with the robot forming the part off: a thermal drift
(≤ 0.4 mm sideways at the end of the run) or a work object offset sideways (≤ 0.3 mm, a third of
them also tilted ≤ 0.3°), alone or beside one of the faults above:

* **verdicts** — per suspect: right (``fault`` for a fault beyond the detection limit, ``ok``
  for none), honest (``cannot_tell``), or wrong; "missed" counts ``ok`` for a fault beyond the
  limit. A sideways offset of the scan and one of the work object are the same pattern: both
  suspects are scored against their sum (``ok`` is right only when the sum is within the limit,
  ``fault`` only when the suspect's own truth is beyond it). The moment bias's truth is what the
  moment channels read at rest (the bias, and the tool's weight through the sensor's matrix).
  Every suspect is scored: what is ambiguous on the path alone — a force bias beside the axial
  force's crosstalk (both a constant along a wall), force-moment crosstalk beside a force bias
  (carried up the arm it makes a constant false tip moment) — the logs' unloaded start tells
  apart, and every virtual log has one (the second was left out before 2026-11-30). The moment
  crosstalk's truth is the larger of ``crosstalk_moment`` (mm) and the force crosstalk times the
  ~250 mm arm.
* **coverage** — the 95 % intervals against the truth: the robot's measured-over-modelled
  compliance (the true deflection against the VJM at the true forces), the gain, the shift's
  size, the rotation's size (when seen).
* **compensation** — where the robot is at fault: ``compensate --stiffness
  identified_stiffness.toml`` (no springback compensation), formed again in the same truth cell;
  the share of the compliance error (robot part − springback, below 20 mm) removed.

Prints one line per truth and the table of docs/diagnosis.md.
"""

from __future__ import annotations

import inspect
import json
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from roboisf.cell import at_ball_centre
from roboisf.compensate import CompensationOptions
from roboisf.compensate.study import compensate_study
from roboisf.decompose.diagnose import DETECTION_LIMITS, SUSPECTS
from roboisf.decompose.pipeline import analyze, write_results
from roboisf.frames import vertical_tool
from roboisf.parts import Cone
from roboisf.parts.mesh import tessellate
from roboisf.study.spec import load_study
from roboisf.virtual.cell import (
    PAPER_CELL_PLACEMENT,
    build_study,
    paper_cone_cell,
    paper_vwacf_cell,
    pyramid_cell,
    sensor_reading,
    simulate,
    tool_weight_at_sensor,
    virtual_cell,
)
from roboisf.virtual.truth import truth_from_table

SMALL = dict(spacing=3e-3, scan_points=50_000, force_rate=100.0, joint_rate=50.0)
PARTS = ("cone", "vwacf", "pyramid", "mesh")
FAULTS = ("joints", "gain", "crosstalk", "bias", "tool_mass", "shift", "rotation")
#: the robot forming the part off (the extra truths)
PART_FAULTS = ("drift", "work_object")
#: the suspects of the robot forming the part off (their cannot_tell is printed per truth)
NEW_SUSPECTS = ("work_object", "thermal_drift", "work_object_tilt")


def make_cell(part: str, table: dict):
    truth = truth_from_table(table)
    if part == "cone":
        return paper_cone_cell(truth=truth, step_down=3e-3, **SMALL)
    if part == "vwacf":
        return paper_vwacf_cell(truth=truth, step_down=2e-3, **SMALL)
    if part == "pyramid":
        return pyramid_cell(truth=truth, step_down=2e-3, **SMALL)
    mesh = tessellate(Cone(), chordal_error=0.2e-3, edge=4e-3)
    return virtual_cell(
        "mesh-cone", mesh, T_base_work=PAPER_CELL_PLACEMENT, truth=truth, step_down=3e-3, **SMALL
    )


def draw(rng: np.random.Generator, faults: tuple[str, ...]) -> dict:
    t: dict = {}
    for f in faults:
        if f == "joints":
            t["robot"] = {"joint_stiffness_scale": list(np.round(rng.uniform(0.4, 1.6, 6), 3))}
        elif f == "gain":
            g = rng.uniform(0.85, 1.15)
            t.setdefault("force_sensor", {})["gain"] = round(float(g), 4)
        elif f == "crosstalk":
            fs = t.setdefault("force_sensor", {})
            fs["crosstalk_force"] = round(float(rng.uniform(0.0, 0.03)), 4)
            fs["crosstalk_moment"] = round(float(rng.uniform(0.0, 30.0)), 2)
        elif f == "bias":
            b = rng.uniform(10, 40) * rng.normal(size=3)
            b = b / np.linalg.norm(b) * rng.uniform(10, 40)
            t.setdefault("force_sensor", {})["bias"] = [*np.round(b, 2).tolist(), 0, 0, 0]
        elif f == "tool_mass":
            t["tool"] = {"mass": round(float(rng.uniform(1, 5)), 2), "cog": [0, 0, 150]}
        elif f == "shift":
            a = rng.uniform(0, 2 * math.pi)
            s = rng.uniform(0.0, 0.3)
            t.setdefault("scan", {})["shift"] = [s * math.cos(a), s * math.sin(a), 0.0]
        elif f == "rotation":
            t.setdefault("scan", {})["rotation"] = [0.0, 0.0, float(rng.uniform(-0.3, 0.3))]
        elif f == "drift":
            a = rng.uniform(0, 2 * math.pi)
            d = rng.uniform(0.0, 0.4)
            t.setdefault("robot", {})["thermal_drift"] = [
                round(d * math.cos(a), 4),
                round(d * math.sin(a), 4),
                0.0,
            ]
        elif f == "work_object":
            a = rng.uniform(0, 2 * math.pi)
            s = rng.uniform(0.0, 0.3)
            wo = [round(s * math.cos(a), 4), round(s * math.sin(a), 4), 0.0, 0.0, 0.0, 0.0]
            if rng.uniform() < 1 / 3:
                b = rng.uniform(0, 2 * math.pi)
                tilt = rng.uniform(0.0, 0.3)
                wo[3], wo[4] = round(tilt * math.cos(b), 4), round(tilt * math.sin(b), 4)
            rob = t.setdefault("robot", {})
            rob.setdefault("kinematic_error", {})["work_object"] = wo
    return t


def truth_values(cell, t, u, study: Path) -> dict[str, float]:
    """The true value of each suspect in the diagnosis's units (nan: not defined)."""
    tr = cell.truth
    k_c = cell.cell.robot.compliance(t.q, T_base_work=cell.cell.T_base_work)
    vjm = at_ball_centre(np.einsum("nij,nj->ni", k_c, t.wrench_robot), cell.cell.tool.radius)
    x = np.einsum("ij,ij->i", vjm, t.toolpath.normal)[u]
    y = np.einsum("ij,ij->i", t.robot, t.toolpath.normal)[u]
    # what the flange sensor reads at rest (the diagnosis's static offset): the tool's weight in
    # the sensor's axes through its gain and crosstalk, plus its bias — as the cell makes it
    spec = load_study(study).robot_run.forces
    tip, R = t.toolpath.tip[:1], vertical_tool(cell.tool_rotation)
    rest = sensor_reading(tr, np.zeros((1, 6)), tool_weight_at_sensor(cell, tr, spec, tip, R))
    bias = np.linalg.norm(rest[0, :3])
    return {
        # what the moment channels read of their own at rest (sensor axes: the size is the same
        # in any)
        "force_moment_bias": float(np.linalg.norm(rest[0, 3:])),
        "robot_stiffness": float(x @ y / (x @ x)),
        "force_gain": float(np.mean(tr.sensor_gain)),
        "force_bias": float(bias),
        # the axial force into the lateral channels (sensor axes; the size turns with the tool)
        "force_crosstalk": float(np.hypot(tr.sensor_crosstalk[0, 2], tr.sensor_crosstalk[1, 2])),
        # force into moment channels (mm), or force crosstalk carried ~0.25 m up the arm
        "force_moment_crosstalk": float(
            max(
                np.max(np.abs(tr.sensor_crosstalk[3:, :3])) * 1e3,
                np.max(np.abs(tr.sensor_crosstalk[:3, :3])) * 250.0,
            )
        ),
        "scan_shift": float(np.linalg.norm(tr.scan_shift[:2]) * 1e3),
        "work_object": float(np.linalg.norm(tr.work_object_error[:2]) * 1e3),
        # the pattern the two make together (a scan shift s and a work object offset t both
        # move the robot part's normal deviation by n · (s + t))
        "offset": float(np.linalg.norm(tr.scan_shift[:2] + tr.work_object_error[:2]) * 1e3),
        "scan_rotation": float(abs(math.degrees(tr.scan_rotation[2] + tr.work_object_error[5]))),
        "thermal_drift": float(np.linalg.norm(tr.thermal_drift[:2]) * 1e3),
        # the tilt's sideways offset at the deepest analysed point, mm
        "work_object_tilt": float(
            np.linalg.norm(tr.work_object_error[3:5]) * -t.toolpath.contact[u, 2].min() * 1e3
        ),
        "springback_coupling": 0.0,
    }


def is_fault(name: str, v: float) -> bool:
    lo, hi = DETECTION_LIMITS[name]
    return v < lo or v > hi


def ambiguous(name: str, tr) -> bool:
    """A suspect whose truth the study cannot tell (not scored): none now. force_bias beside the
    axial force's crosstalk and force_moment_crosstalk beside a force bias are told apart by
    the logs' unloaded start, which every virtual log has (the latter was left out before
    2026-11-30: 7 of seed 2026's 40 truths and 11 of seed 7's, all then cannot_tell)."""
    return False


def compliance_removed(cell, root: Path, summary: dict) -> float | None:
    k = summary.get("identified_stiffness")
    if not k:
        return None
    tr = cell.truth
    # an offset the diagnosis cannot attribute: the truth says whose it is (as a user who
    # checked the scan's reference marks)
    own_scan = np.linalg.norm(tr.scan_shift[:2]) >= np.linalg.norm(tr.work_object_error[:2])
    # (a roboisf before --offset, for a run of the old code against these truths, has none)
    kw = {"offset": "scan" if own_scan else "part"}
    if "offset" not in inspect.signature(compensate_study).parameters:
        kw = {}
    comp = compensate_study(
        root / "study",
        results=root / "results",
        options=CompensationOptions(springback=False),
        stiffness=root / "results" / k,  # summary.json names it relative to the results
        **kw,
    )
    t0 = simulate(cell)
    t1 = simulate(cell, commanded=comp.compensation.toolpath)
    sel = t0.toolpath.depth > 20e-3

    def rms(v):
        return float(np.sqrt(np.mean(v**2)))

    before = (t0.dn_robot - t0.springback)[sel]
    after = (t1.dn_robot - t1.springback)[sel]
    return 1 - rms(after) / rms(before)


def main(n: int = 40, seed: int = 2026, n_extra: int = 12, moment_bias: bool = False) -> None:
    rng = np.random.default_rng(seed)
    rng_m = np.random.default_rng([seed, 2])  # the moment biases: the other draws unchanged
    plans = []
    for i in range(n):
        part = PARTS[i % len(PARTS)]
        k = 1 if i % 3 == 0 else 2
        faults = tuple(sorted(rng.choice(FAULTS, size=k, replace=False)))
        table = draw(rng, faults)
        if moment_bias and i % 2 == 1:
            m = rng_m.normal(size=3)
            m = m / np.linalg.norm(m) * rng_m.uniform(0.2, 3.0)
            fs = table.setdefault("force_sensor", {})
            fs["bias"] = [*fs.get("bias", [0.0, 0.0, 0.0])[:3], *np.round(m, 3).tolist()]
            faults = (*faults, "moment_bias")
        plans.append((part, faults, table))
    # the robot forming the part off, from a stream of their own (the first n stay as before)
    rng_x = np.random.default_rng([seed, 1])
    for i in range(n_extra):
        part = PARTS[i % len(PARTS)]
        faults = (PART_FAULTS[i % 2],)
        if i % 4 >= 2:  # beside one of the others
            faults = tuple(sorted((*faults, str(rng_x.choice(FAULTS)))))
        plans.append((part, faults, draw(rng_x, faults)))
    suspects = [s for s in SUSPECTS if s in DETECTION_LIMITS]

    def blank() -> dict[str, dict[str, int]]:
        return {s: {"right": 0, "cannot_tell": 0, "wrong": 0, "missed": 0} for s in suspects}

    score, score_first = blank(), blank()
    covered = (
        "robot_stiffness",
        "force_gain",
        "force_moment_bias",
        "force_bias",
        "force_crosstalk",
    )
    cover = {
        s: [0, 0]
        for s in (*covered, *("scan_shift", "work_object", "scan_rotation"), *NEW_SUSPECTS[1:])
    }
    removal: dict[str, list[float]] = {"robot only": [], "robot and sensor": []}
    tmp = Path(tempfile.mkdtemp(prefix="roboisf-diag-"))
    t_start = time.perf_counter()
    try:
        for i, (part, faults, table) in enumerate(plans):
            root = tmp / f"t{i:02d}"
            cell = make_cell(part, table)
            build_study(cell, root / "study")
            r = analyze(root / "study")
            write_results(r, root / "results", png=False)
            s = json.loads((root / "results" / "summary.json").read_text(encoding="utf-8"))
            t = simulate(cell)
            u = r.per_point["used"].to_numpy()
            tv = truth_values(cell, t, u, root / "study")
            diag = {d["suspect"]: d for d in s["diagnosis"]}
            marks = []
            tallies = (score, score_first) if i < n else (score,)
            for name in suspects:
                d, v = diag[name], tv[name]
                if ambiguous(name, cell.truth):
                    marks.append(f"{name}:{d['verdict'][0]}?")
                    continue
                fault = is_fault(name, v)
                if name in ("scan_shift", "work_object"):  # one pattern, two readings
                    v = tv["offset"]
                    fault = is_fault(name, v) if d["verdict"] == "ok" else fault
                if d["verdict"] == "cannot_tell":
                    key = "cannot_tell"
                    if name in NEW_SUSPECTS:  # where the new suspects cannot tell, and why
                        marks.append(f"{name}:c({v:.3g})")
                elif (d["verdict"] == "fault") == fault:
                    key = "right"
                else:
                    key = "wrong"
                    marks.append(f"{name}:{d['verdict']}≠{'fault' if fault else 'ok'}({v:.3g})")
                for sc in tallies:
                    sc[name][key] += 1
                    if key == "wrong" and fault and d["verdict"] == "ok":
                        sc[name]["missed"] += 1
                if name in cover and d["ci_low"] is not None and d["ci_high"] is not None:
                    cover[name][1] += 1
                    hit = d["ci_low"] <= v <= d["ci_high"]
                    cover[name][0] += hit
                    if not hit:
                        marks.append(f"{name}∉[{d['ci_low']:.4g},{d['ci_high']:.4g}]∌{v:.4g}")
            rem = None
            if diag["robot_stiffness"]["verdict"] == "fault" and is_fault(
                "robot_stiffness", tv["robot_stiffness"]
            ):
                rem = compliance_removed(cell, root, s)
                sensor = any(f in faults for f in ("gain", "crosstalk", "bias", "tool_mass"))
                if rem is not None:
                    removal["robot and sensor" if sensor else "robot only"].append(rem)
            shutil.rmtree(root, ignore_errors=True)
            print(
                f"{i:2d} {part:8s} {'+'.join(faults):20s} "
                f"removed {'-' if rem is None else f'{rem:.3f}'}  {' '.join(marks)}",
                flush=True,
            )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    wall = time.perf_counter() - t_start
    print(f"\n{n} + {n_extra} truths, seed {seed}, {wall:.0f} s")
    for title, sc in ((f"the first {n} (as drawn before)", score_first), ("all", score)):
        print(f"\n{title}\n")
        print("| suspect | right | cannot tell | wrong | of which ok for a fault |")
        print("|---|---|---|---|---|")
        tot = {"right": 0, "cannot_tell": 0, "wrong": 0, "missed": 0}
        for name, c in sc.items():
            print(f"| {name} | {c['right']} | {c['cannot_tell']} | {c['wrong']} | {c['missed']} |")
            for k in tot:
                tot[k] += c[k]
        m = tot["right"] + tot["cannot_tell"] + tot["wrong"]
        row = (tot["right"], tot["cannot_tell"], tot["wrong"], tot["missed"])
        print("| **all** | " + " | ".join(str(c) for c in row) + " |")
        print(f"\nright or honestly cannot tell: {(tot['right'] + tot['cannot_tell']) / m:.1%}")
    print("\n| interval | covers the truth |\n|---|---|")
    for name, (h, k) in cover.items():
        print(f"| {name} | {h}/{k} ({h / k:.0%}) |" if k else f"| {name} | – |")
    hk = sum(h for h, _ in cover.values()), sum(k for _, k in cover.values())
    print(f"| **all** | {hk[0]}/{hk[1]} ({hk[0] / max(hk[1], 1):.0%}) |")
    print("\n| compensation | cases | compliance error removed: min / median |\n|---|---|---|")
    for k, v in removal.items():
        if v:
            print(f"| {k} | {len(v)} | {min(v):.1%} / {float(np.median(v)):.1%} |")
        else:
            print(f"| {k} | 0 | – |")


if __name__ == "__main__":
    args = [int(a) for a in sys.argv[1:] if a != "moment-bias"]
    main(*args, moment_bias="moment-bias" in sys.argv[1:])
