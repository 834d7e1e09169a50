"""The cell's history and the learned springback model, end to end on virtual cells (issue #32).

Run by hand:  python benchmarks/history.py [--keep DIR] [--skip-studies]

1. **Training history.** Ten virtual studies whose springback follows the geometry rule of
   docs/virtual-cell.md (``[springback] curvature_gain = 0.4``): four cones (30–71°), three
   VWACFs, three pyramids (40–60°), coarse paths (1.5 mm step-down, 3 mm spacing) and 150 k-point
   scans; each analysed (``roboisf analyze``) and added (``roboisf history add``).
2. **A part of another shape.** An elliptic paraboloid pit (a mesh dome, 100 × 70 mm, 30 mm deep)
   is predicted with ``roboisf predict`` and compared with the virtual cell's true springback on
   the same toolpath: RMS error / RMS springback over the analysed wall (below the rim band) and
   over every point, and the share of points inside the interval. Done when ≤ 30 % and the
   interval covers (≥ its nominal 90 % on the wall).
3. **First-part program.** ``roboisf compensate --predicted`` writes the command; the dome's
   virtual cell re-forms it (:func:`roboisf.virtual.cell.simulate` with ``commanded``): the share
   of the nominal program's total normal error (RMS over the wall) it removes. Done when ≥ 60 %.
4. **Scale.** One analysis result copied 100 times (each with its own fingerprint): one
   ``history add`` of all 100 and one ``history trend``, wall time each. Done when seconds.

Everything is timed with wall and CPU time; the machine is shared (2 cores), CPU is what carries.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from roboisf.cli.main import main

TRUTH = "[springback]\ncurvature_gain = 0.4\ncurvature_length = 15.0\n"
PATH = ["--step-down", "1.5", "--spacing", "3"]
CELL = ["--scan-points", "150000", "--force-rate", "50", "--joint-rate", "20", *PATH]
PLACEMENT = "2200,-500,200,0"  # the virtual cell's placement (mm, deg)
TRAINING = {
    "cone60": ["cone", "--opening-diameter", "90", "--wall-angle", "60", "--depth", "40"],
    "cone45": ["cone", "--opening-diameter", "100", "--wall-angle", "45", "--depth", "30"],
    "cone71": ["cone", "--opening-diameter", "70", "--wall-angle", "71", "--depth", "45"],
    "cone30": ["cone", "--opening-diameter", "110", "--wall-angle", "30", "--depth", "25"],
    "vwacf80": ["vwacf", "--opening-diameter", "88", "--final-wall-angle", "80"],
    "vwacf70": [
        "vwacf", "--opening-diameter", "100", "--arc-radius", "50", "--final-wall-angle", "70"
    ],
    "vwacf50": [
        "vwacf", "--opening-diameter", "100", "--arc-radius", "60", "--final-wall-angle", "50"
    ],
    "pyramid60": ["pyramid", "--top-length", "100", "--wall-angle", "60", "--depth", "35"],
    "pyramid50": [
        "pyramid", "--top-length", "90", "--top-width", "70", "--wall-angle", "50",
        "--depth", "30", "--corner-radius", "15",
    ],
    "pyramid40": [
        "pyramid", "--top-length", "100", "--top-width", "80", "--wall-angle", "40",
        "--depth", "25", "--corner-radius", "20",
    ],
}  # fmt: skip


def run(*args: str) -> float:
    t = time.perf_counter()
    code = main(["-q", *args])
    if code != 0:
        sys.exit(f"roboisf {' '.join(args)} exited {code}")
    return time.perf_counter() - t


def elliptic_pit_stl(path: Path, a: float = 50.0, b: float = 35.0, d: float = 30.0) -> None:
    """An elliptic paraboloid pit z = −d (1 − (x/a)² − (y/b)²) [mm] with a 10 mm flat flange,
    written as ASCII STL (rings of a polar grid, triangles fanned to the bottom point)."""
    nt, nr = 240, 50
    rho = np.r_[np.linspace(0, 1, nr + 1)[1:], 1.15, 1.3]
    th = np.linspace(0, 2 * np.pi, nt, endpoint=False)
    ring = [
        np.c_[a * r * np.cos(th), b * r * np.sin(th), np.full(nt, -d * max(0.0, 1 - r * r))]
        for r in rho
    ]
    tris = []
    bottom = np.array([0.0, 0.0, -d])
    for j in range(nt):
        k = (j + 1) % nt
        tris.append((bottom, ring[0][j], ring[0][k]))
        for i in range(len(rho) - 1):
            p, q = ring[i], ring[i + 1]
            tris += [(p[j], q[j], q[k]), (p[j], q[k], p[k])]
    with path.open("w") as f:
        f.write("solid pit\n")
        for v in tris:
            f.write(" facet normal 0 0 0\n  outer loop\n")
            f.writelines(f"   vertex {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in v)
            f.write("  endloop\n endfacet\n")
        f.write("endsolid pit\n")


def build(root: Path) -> None:
    (root / "truth.toml").write_text(TRUTH)
    for name, spec in TRAINING.items():
        if (root / f"R_{name}" / "summary.json").is_file():
            continue
        part = root / f"{name}.toml"
        run("part", *spec, "-o", str(part), "--overwrite")
        t1 = run("virtual-cell", "--part", str(part), "--truth", str(root / "truth.toml"),
                 *CELL, "-o", str(root / f"S_{name}"), "--overwrite")  # fmt: skip
        t2 = run("analyze", str(root / f"S_{name}"), "-o", str(root / f"R_{name}"), "--overwrite")
        print(f"{name}: virtual-cell {t1:.1f} s, analyze {t2:.1f} s", flush=True)
    if not (root / "dome.toml").is_file():
        elliptic_pit_stl(root / "dome.stl")
        run("part", "mesh", str(root / "dome.stl"), "-o", str(root / "dome.toml"))


def dome_cell(root: Path) -> Any:
    from roboisf.parts.io import load_part
    from roboisf.virtual.cell import PAPER_CELL_PLACEMENT, virtual_cell
    from roboisf.virtual.truth import load_truth

    return virtual_cell(
        "dome",
        load_part(root / "dome.toml"),
        T_base_work=PAPER_CELL_PLACEMENT,
        truth=load_truth(root / "truth.toml"),
        step_down=1.5e-3,
        spacing=3e-3,
    )


def main_(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--keep", type=Path, help="work folder to keep (and reuse) the studies in")
    args = ap.parse_args(argv)
    root = args.keep or Path(tempfile.mkdtemp(prefix="roboisf-history-"))
    root.mkdir(parents=True, exist_ok=True)
    c0 = time.process_time()
    build(root)
    print(f"studies ready in {root} (CPU {time.process_time() - c0:.1f} s)", flush=True)
    stage2(root)


def stage2(root: Path) -> None:
    import pandas as pd

    from roboisf.virtual.cell import simulate

    db = root / "history.db"
    db.unlink(missing_ok=True)
    t = run("history", "add", *(str(root / f"R_{n}") for n in TRAINING), "--db", str(db))
    print(f"history add of {len(TRAINING)} studies: {t:.2f} s")
    t = run("predict", "--part", str(root / "dome.toml"), "--history", str(db),
            "--placement", PLACEMENT, *PATH, "-o", str(root / "P_dome"), "--overwrite")  # fmt: skip
    print(f"predict: {t:.1f} s")
    pred = pd.read_parquet(root / "P_dome" / "prediction.parquet")
    summary = json.loads((root / "P_dome" / "prediction.json").read_text())
    vc = dome_cell(root)
    truth = simulate(vc)
    s_true = truth.springback * 1e3
    if len(s_true) != len(pred):
        sys.exit(f"toolpaths differ: truth {len(s_true)} points, prediction {len(pred)}")
    s_pred = pred["springback_dn"].to_numpy()
    lo, hi = pred["springback_dn_low"].to_numpy(), pred["springback_dn_high"].to_numpy()
    rim = summary["rim_band_mm"]
    nominal = summary["springback_model"]["coverage"]
    wall = pred["depth"].to_numpy() > rim
    for name, m in (("wall (below the rim band)", wall), ("every point", np.ones_like(wall))):
        rms = math.sqrt(np.mean(s_true[m] ** 2))
        err = math.sqrt(np.mean((s_pred[m] - s_true[m]) ** 2))
        cover = np.mean((s_true[m] >= lo[m]) & (s_true[m] <= hi[m]))
        print(
            f"dome springback, {name}: RMS {rms:.3f} mm, prediction RMS error {err:.3f} mm "
            f"= {100 * err / rms:.1f} % of it; interval ±{(hi - lo)[0] / 2:.3f} mm covers "
            f"{100 * cover:.1f} % of the points (nominal {100 * nominal:.0f} %)"
        )
    # the reference a model has to beat: the history's mean springback, everywhere
    import sqlite3

    with sqlite3.connect(db) as con:
        (mean,) = con.execute("SELECT avg(springback_dn) FROM points WHERE used = 1").fetchone()
    base = math.sqrt(np.mean((mean * 1e3 - s_true[wall]) ** 2))
    rms = math.sqrt(np.mean(s_true[wall] ** 2))
    print(f"reference: the history's mean springback ({mean * 1e3:.3f} mm) everywhere on the "
          f"wall: RMS error {base:.3f} mm = {100 * base / rms:.1f} %")  # fmt: skip
    val = summary["springback_model"]["validation"]
    print("leave-one-part-out on the history: " + ", ".join(
        f"{v['part_kind']} {100 * v['relative_error']:.0f} %" for v in val))  # fmt: skip

    t = run("compensate", "--predicted", str(root / "P_dome"), "-o", str(root / "C_dome"),
            "--overwrite", "--no-png")  # fmt: skip
    print(f"compensate --predicted: {t:.1f} s")
    comp = pd.read_csv(root / "C_dome" / "compensated.csv", comment="#")
    from roboisf.cam.toolpath_csv import read_toolpath_csv

    commanded = read_toolpath_csv(root / "C_dome" / "compensated.csv")
    reformed = simulate(vc, commanded=commanded)
    for name, m in (("wall", wall), ("every point", np.ones_like(wall))):
        before = math.sqrt(np.mean(truth.dn_robot[m] ** 2)) * 1e3
        after = math.sqrt(np.mean(reformed.dn_robot[m] ** 2)) * 1e3
        print(
            f"re-formed dome, {name}: total normal error RMS {before:.3f} mm (nominal program) → "
            f"{after:.3f} mm (--predicted program): {100 * (1 - after / before):.1f} % removed"
        )
    del comp
    stage3(root)


def stage3(root: Path) -> None:
    many = root / "many"
    shutil.rmtree(many, ignore_errors=True)
    many.mkdir()
    src = root / f"R_{next(iter(TRAINING))}"
    for i in range(100):
        d = many / f"R{i:03d}"
        shutil.copytree(src, d)
        s = json.loads((d / "summary.json").read_text())
        s["study"] = f"{s['study']}-{i:03d}"
        (d / "summary.json").write_text(json.dumps(s))
    db = root / "many.db"
    db.unlink(missing_ok=True)
    c = time.process_time()
    t = run("history", "add", *sorted(str(p) for p in many.iterdir()), "--db", str(db))
    cpu = time.process_time() - c
    size = db.stat().st_size / 1e6
    print(f"history add of 100 studies: wall {t:.2f} s (CPU {cpu:.2f} s), database {size:.1f} MB")
    t = run("history", "trend", "--db", str(db), "--by", "robot")
    print(f"history trend over 100 parts: wall {t:.2f} s")


if __name__ == "__main__":
    main_()
