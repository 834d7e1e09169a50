"""Paper-scale analysis: both studies with 1 kHz force logs over the full forming time and 2 M-point
scans. Targets: issue #6 (2 cores) analyze ≤ 60 s for both, ≤ 6 GB peak, `roboisf demo` ≤ 90 s;
issue #16: analyze of the paper cone ≤ 10 s and ≤ 1 GB (per step: wall, CPU, peak RSS); issue #31:
the paper cone ≤ 3 s and ≤ 0.6 GB, the demo ≤ 8 s (warm, 2 cores).

Run by hand:  python benchmarks/analyze.py [--scan-points 2000000] [--keep DIR]
              python benchmarks/analyze.py --study DIR   # analyze an existing study only

Prints the time of each step of the analysis (the progress tasks, nested) so the dominant one is
visible, then each step against its floor measured in the same run on the same files (reading the
file's bytes; one numpy pass over the scan's points: :func:`step_floors`) and against a peer
library doing the same work where one exists (scipy's k-d tree / Open3D for the outlier k-NN,
Open3D's ICP for the registration, numpy's argsort for the spatial order, pyarrow / pandas for the
logs). There is no peer library that performs the decomposition itself. On a shared machine the
wall-clock times are contended; the ratios are what carries over.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import resource
import shutil
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from functools import partial
from pathlib import Path
from typing import Any

from machine import speed_line  # benchmarks/machine.py (this folder is on sys.path)

from roboisf.progress import Advance, noop_advance


class StepTimes:
    """A :class:`roboisf.progress.Progress` that records the wall and CPU time of every task.

    CPU time is the process's (user + system, all threads): on a shared machine the wall time
    is contended, the CPU time much less so. The peak RSS is the process's high-water mark at the
    end of the step. Safe to call from worker threads (their tasks are listed at depth 2; the
    CPU time of overlapping tasks then counts every thread).
    """

    def __init__(self) -> None:
        self.rows: list[tuple[int, str, float, float, float]] = []
        #: the run ("cnc", "robot") of each row inside a ``scan <run>`` task (its thread's)
        self.scan_of: dict[int, str] = {}
        #: the ``scan <run>`` row each row ran inside (its thread's: the analysis prepares the
        #: last scan in the calling thread, then finishes it in the worker — two such rows)
        self.inside: dict[int, int] = {}
        self._depth = 0
        self._lock = threading.Lock()
        self._scan = threading.local()

    @contextlib.contextmanager
    def task(self, description: str, total: float | None = None) -> Iterator[Advance]:
        with self._lock:
            row = len(self.rows)
            depth = self._depth if threading.current_thread() is threading.main_thread() else 2
            self.rows.append((depth, description, 0.0, 0.0, 0.0))
            if threading.current_thread() is threading.main_thread():
                self._depth += 1
            if description.startswith("scan "):
                self._scan.run = description[5:]
                self._scan.row = row
            run = getattr(self._scan, "run", None)
            if run is not None:
                self.scan_of[row] = run
                if self._scan.row != row:
                    self.inside[row] = self._scan.row
        t, c = time.perf_counter(), time.process_time()
        try:
            yield noop_advance
        finally:
            if description.startswith("scan "):
                self._scan.run = None
                self._scan.row = None
            with self._lock:
                if threading.current_thread() is threading.main_thread():
                    self._depth -= 1
                self.rows[row] = (
                    depth,
                    description,
                    time.perf_counter() - t,
                    time.process_time() - c,
                    resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2,
                )

    def print(self, total: float) -> None:
        print(f"    {'step':<40} {'wall':>9}  {'share':>5} {'CPU':>11} {'peak RSS at end':>16}")
        for depth, name, dt, cpu, rss in self.rows:
            print(
                f"    {'  ' * depth}{name:<{40 - 2 * depth}} {dt:7.2f} s  {dt / total:5.1%}"
                f" {cpu:9.2f} s {rss:12.2f} GB"
            )


def _best(f: Callable[[], object], repeats: int = 3) -> float:
    """Best wall time of ``repeats`` calls of ``f`` (s): a floor is what the machine can do."""
    best = math.inf
    for _ in range(repeats):
        t = time.perf_counter()
        f()
        best = min(best, time.perf_counter() - t)
    return best


def _read_bytes(*files: Path) -> None:
    for f in files:
        f.read_bytes()


def _one_pass(X: Any) -> None:
    """One numpy pass over the points (N, 3): the norm of each (reads N×3, writes N)."""
    import numpy as np

    np.sqrt(np.einsum("ij,ij->i", X, X))


def _knn_scipy(X: Any, k: int) -> None:
    """scipy's k-d tree: build + the k + 1 nearest of every point, in chunks on every core."""
    from scipy.spatial import cKDTree

    tree = cKDTree(X)
    for lo in range(0, len(X), 262_144):
        tree.query(X[lo : lo + 262_144], k=k + 1, workers=-1)


def _knn_open3d(X: Any, k: int) -> Callable[[], object] | None:
    try:
        import open3d as o3d
    except ImportError:
        return None
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(X))
    return lambda: pc.remove_statistical_outlier(nb_neighbors=k + 1, std_ratio=3.0)


def _icp_open3d(X: Any) -> Callable[[], object] | None:
    try:
        import open3d as o3d
    except ImportError:
        return None
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(X))
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(X + 1e-4))
    return lambda: o3d.pipelines.registration.registration_icp(pc, target, 1e-3)


def _read_logs(files: list[Path]) -> None:
    """The force/joint logs by the format's usual reader: pyarrow for parquet, pandas' C parser
    for CSV."""
    import pandas as pd
    import pyarrow.parquet as pq

    for f in files:
        if f.suffix == ".parquet":
            pq.read_table(f)
        else:
            pd.read_csv(f, comment="#")


def step_floors(spec: Any, steps: StepTimes) -> None:
    """Each step of the analysis against its floor, measured now on the same files (issue #31):

    * a scan's reading (``scan <run>`` minus its sub-steps): reading the file's bytes (from the
      page cache, as the analysis did) plus one numpy pass over its points;
    * a step over the scan's points (register, spatial order, closest points, outlier removal,
      wall deviations, toolpath deviations): one numpy pass over all the scan's points (the
      norm of each point: reads N×3, writes N float64); the outlier and later steps see only
      the wall (fewer);
    * a run's log step (``<run> logs: alignment``): reading the bytes of its force and joint logs.

    and, where a library does the same work, that library on the same data (``peer``): scipy's
    k-d tree (and Open3D's filter, if installed) for the outlier k-NN, Open3D's ICP for the
    registration, numpy's argsort of one coordinate for the spatial order, pyarrow / pandas for
    the logs. Floors are best of 3; the step times are the analysis' single run.
    """
    import numpy as np

    from roboisf.decompose.pipeline import scan_options
    from roboisf.parts.mesh import spatial_order
    from roboisf.scan import read_scan

    runs = {r.name: r for r in (spec.cnc, spec.robot_run)}
    k = scan_options(spec).outlier_k
    floor: dict[tuple[str, str], float] = {}
    peer: dict[tuple[str, str], tuple[str, float]] = {}
    for name, r in runs.items():
        X = read_scan(r.scan, unit=r.scan_unit).points
        X = np.take(X, spatial_order(X), axis=0)
        t_bytes = _best(partial(_read_bytes, r.scan))
        t_pass = _best(partial(_one_pass, X))
        floor[name, "read"] = t_bytes + t_pass
        for step in (
            "register",
            "spatial order",
            "closest points",
            "outlier removal",
            "wall deviations",
            "toolpath deviations",
        ):
            floor[name, step] = t_pass
        peer[name, "spatial order"] = ("numpy argsort", _best(partial(np.argsort, X[:, 0])))
        peer[name, "outlier removal"] = ("scipy cKDTree", _best(partial(_knn_scipy, X, k), 1))
        o3d_knn = _knn_open3d(X, k)
        if o3d_knn is not None:
            peer[name, "outlier removal"] = ("Open3D", _best(o3d_knn, 1))
        o3d_icp = _icp_open3d(X)
        if o3d_icp is not None:
            peer[name, "register"] = ("Open3D ICP", _best(o3d_icp, 1))
        del X
        logs = [f for f in (r.forces.file, r.joints) if f is not None]
        floor[name, "logs"] = _best(partial(_read_bytes, *logs))
        peer[name, "logs"] = ("pyarrow/pandas", _best(partial(_read_logs, logs), 1))

    def key(i: int, step: str) -> tuple[str, str] | None:
        if step.endswith(" logs: alignment"):
            return (step.split(" ")[0], "logs")
        run = steps.scan_of.get(i)
        if run is None:
            return None
        if step == f"scan {run}":
            return (run, "read")
        return (run, step.split(" (")[0])

    print(
        f"    {'step vs floor and peer (same run)':<40} {'wall':>7} {'floor':>9} {'x floor':>8}"
        f"  {'peer':<15} {'x peer':>7}"
    )
    for i, (_depth, step, dt, _cpu, _rss) in enumerate(steps.rows):
        kk = key(i, step)
        if kk is None or kk not in floor:
            continue
        if kk[1] == "read":  # the scan's own work: reading, without its sub-steps
            dt -= sum(steps.rows[j][2] for j, p in steps.inside.items() if p == i)
        run = steps.scan_of.get(i)
        label = f"{step} ({run})" if run and kk[1] != "read" else step
        label = label + ": reading, rest" if kk[1] == "read" else label
        f = floor[kk]
        line = f"    {label:<40} {dt:5.2f} s {f * 1e3:6.1f} ms {dt / f:7.0f}x"
        if kk in peer:
            pname, tp = peer[kk]
            line += f"  {pname:<15} {dt / tp:6.2f}x"
        print(line)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--scan-points", type=int, default=2_000_000)
    ap.add_argument("--force-rate", type=float, default=1000.0)
    ap.add_argument("--keep", type=Path, default=None, help="keep the studies in this folder")
    ap.add_argument("--study", type=Path, default=None, help="only analyze this existing study")
    ap.add_argument("--no-demo", action="store_true", help="skip the `roboisf demo` run")
    a = ap.parse_args(argv)

    from roboisf.cli.main import main as cli
    from roboisf.decompose.pipeline import analyze, write_results
    from roboisf.study.spec import load_study
    from roboisf.virtual.cell import build_study, paper_cone_cell, paper_vwacf_cell

    root = a.keep or Path(tempfile.mkdtemp(prefix="roboisf-bench-"))
    if a.study is not None:
        studies = [a.study]
    else:
        cells = [
            paper_cone_cell(scan_points=a.scan_points, force_rate=a.force_rate),
            paper_vwacf_cell(scan_points=a.scan_points, force_rate=a.force_rate),
        ]
        studies = []
        t0 = time.perf_counter()
        for cell in cells:
            studies.append(build_study(cell, root / cell.name))
        t_build = time.perf_counter() - t0
        print(
            f"virtual cell (2 studies, {a.scan_points:,} scan points, {a.force_rate:g} Hz): "
            f"{t_build:.1f} s"
        )

    print(speed_line(), flush=True)  # the machine's pace now (benchmarks/machine.py)
    t_an = 0.0
    for s in studies:
        steps = StepTimes()
        t, c = time.perf_counter(), time.process_time()
        r = analyze(s, progress=steps)
        write_results(r, root / f"{s.name}-results", progress=steps)
        dt, cpu = time.perf_counter() - t, time.process_time() - c
        t_an += dt
        peak_an = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
        print(
            f"  analyze + write {s.name}: {dt:.1f} s wall, {cpu:.1f} s CPU, peak RSS so far "
            f"{peak_an:.2f} GB (targets for the cone, #31: ≤ 3 s, ≤ 0.6 GB); load average "
            f"{os.getloadavg()[0]:.1f} (contended if > 2 on 2 cores), by step:"
        )
        steps.print(dt)
        spec = load_study(s)
        step_floors(spec, steps)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
    print(
        f"analyze, both studies: {t_an:.1f} s (target ≤ 60 s: "
        f"{'met' if t_an <= 60 else 'MISSED'}); peak RSS {peak:.2f} GB (target ≤ 6 GB)"
    )

    if a.no_demo or a.study is not None:
        if a.keep is None:
            shutil.rmtree(root, ignore_errors=True)
        return 0
    demo = root / "demo"
    t = time.perf_counter()
    code = cli(["-q", "demo", "-o", str(demo)])
    t_demo = time.perf_counter() - t
    print(
        f"roboisf demo: {t_demo:.1f} s (exit {code}; target ≤ 90 s: "
        f"{'met' if t_demo <= 90 else 'MISSED'})"
    )
    if a.keep is None:
        shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
