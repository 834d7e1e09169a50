"""Paper-scale analysis: both studies with 1 kHz force logs over the full forming time and 2 M-point
scans. Targets: issue #6 (2 cores) analyze ≤ 60 s for both, ≤ 6 GB peak, `roboisf demo` ≤ 90 s;
issue #16: analyze of the paper cone ≤ 10 s and ≤ 1 GB (per step: wall, CPU, peak RSS).

Run by hand:  python benchmarks/analyze.py [--scan-points 2000000] [--keep DIR]
              python benchmarks/analyze.py --study DIR   # analyze an existing study only

Prints the time of each step of the analysis (the progress tasks, nested) so the dominant one is
visible. There is no peer library that performs this decomposition; as reference points the run
prints, in the same run and on the same data: pandas' C CSV parser on the force logs, and the
scan's statistical outlier removal by roboisf (``roboisf.scan.statistical_outliers``, scan in
file order) against Open3D's ``remove_statistical_outlier`` (pip install roboisf[bench]) on the
same points (issue #16: within 1.5×). On a shared machine the wall-clock times are contended;
the ratios are what carries over.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import resource
import shutil
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path


class StepTimes:
    """A :class:`roboisf.progress.Progress` that records the wall and CPU time of every task.

    CPU time is the process's (user + system, all threads): on a shared machine the wall time
    is contended, the CPU time much less so. The peak RSS is the process's high-water mark at the
    end of the step. Safe to call from worker threads (their tasks are listed at depth 2; the
    CPU time of overlapping tasks then counts every thread).
    """

    def __init__(self) -> None:
        self.rows: list[tuple[int, str, float, float, float]] = []
        self._depth = 0
        self._lock = threading.Lock()

    @contextlib.contextmanager
    def task(self, description: str, total: float | None = None) -> Iterator[object]:
        with self._lock:
            row = len(self.rows)
            depth = self._depth if threading.current_thread() is threading.main_thread() else 2
            self.rows.append((depth, description, 0.0, 0.0, 0.0))
            if threading.current_thread() is threading.main_thread():
                self._depth += 1
        t, c = time.perf_counter(), time.process_time()
        try:
            yield lambda amount=1.0: None
        finally:
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


def outliers_vs_open3d(scan: Path, unit: str | None) -> None:
    """roboisf's statistical outlier filter vs Open3D's on the same scan points (file order)."""
    import numpy as np

    from roboisf.scan import read_scan, statistical_outliers

    X = read_scan(scan, unit=unit).points
    t = time.perf_counter()
    ours = statistical_outliers(X, 8, 3.0)
    t_ours = time.perf_counter() - t
    try:
        import open3d as o3d
    except ImportError:
        print(f"    outliers {scan.name}: roboisf {t_ours:.2f} s (Open3D not installed)")
        return
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(X))
    t = time.perf_counter()
    _, keep = pc.remove_statistical_outlier(nb_neighbors=9, std_ratio=3.0)
    t_o3d = time.perf_counter() - t
    theirs = np.zeros(len(X), dtype=bool)
    theirs[np.asarray(keep, dtype=np.int64)] = True
    print(
        f"    outliers {scan.name} ({len(X):,} points): roboisf {t_ours:.2f} s, Open3D "
        f"{t_o3d:.2f} s, ratio {t_ours / t_o3d:.2f}x (target ≤ 1.5); masks differ in "
        f"{int((ours != theirs).sum())} points"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--scan-points", type=int, default=2_000_000)
    ap.add_argument("--force-rate", type=float, default=1000.0)
    ap.add_argument("--keep", type=Path, default=None, help="keep the studies in this folder")
    ap.add_argument("--study", type=Path, default=None, help="only analyze this existing study")
    ap.add_argument("--no-demo", action="store_true", help="skip the `roboisf demo` run")
    a = ap.parse_args(argv)

    import pandas as pd

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
            f"{peak_an:.2f} GB (targets for the cone: ≤ 10 s, ≤ 1 GB); load average "
            f"{os.getloadavg()[0]:.1f} (contended if > 2 on 2 cores), by step:"
        )
        steps.print(dt)
        spec = load_study(s)
        logs = [f.file for f in (spec.cnc.forces, spec.robot_run.forces) if f.file.suffix == ".csv"]
        if logs:
            tp = time.perf_counter()
            for f in logs:
                pd.read_csv(f, comment="#")
            t_pd = time.perf_counter() - tp
            print(f"    pandas alone reads the CSV force logs in {t_pd:.1f} s = {t_pd / dt:.0%}")
        outliers_vs_open3d(spec.cnc.scan, spec.cnc.scan_unit)
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
