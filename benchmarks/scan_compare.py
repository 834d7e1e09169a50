"""Benchmark: one scan comparison (``compare_scan``) by step, and its compiled kernels against
the previous paths in the same run.

    PYTHONPATH=src python benchmarks/scan_compare.py --study STUDY_DIR [--run robot] [--repeat 3]
    PYTHONPATH=src python benchmarks/scan_compare.py [--points 2000000]   # synthetic cone

With ``--study`` (e.g. the paper cone written by ``benchmarks/analyze.py``) the run's scan,
part, toolpath and analysis options are those ``roboisf analyze`` uses; without it a shuffled
synthetic cone scan (1 % outliers) and the paper's 0.5 mm step-down toolpath.

Prints, per repeat, the whole comparison (reading the scan included) and its steps, wall and
CPU (user + system, all threads); then, on the same points, interleaved:
(a) the per-toolpath-point neighbourhoods by the compiled grid pass vs (b) scipy's k-d tree
and numpy (the reference path, what roboisf did before), and (c) the outlier k-NN query cell
by query cell vs (d) the per-point ring search (the previous kernel) — one thread each, so
their CPU times compare — with the ratios and whether the results are the same bits.
Issue #16: one 2 M-point scan comparison ≤ 2 s wall on 2 idle cores.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import time
from collections.abc import Iterator
from typing import Any

import numpy as np


class _Steps:
    """A :class:`roboisf.progress.Progress` that records each step's wall and CPU time."""

    def __init__(self) -> None:
        self.t: dict[str, tuple[float, float]] = {}

    @contextlib.contextmanager
    def task(self, description: str, total: float | None = None) -> Iterator[Any]:
        w, c = time.perf_counter(), time.process_time()
        yield lambda amount=1.0: None
        self.t[description] = (time.perf_counter() - w, time.process_time() - c)


def _inputs(args: argparse.Namespace) -> tuple[Any, Any, Any, Any]:
    from roboisf.scan import ScanCloud, read_scan

    if args.study:
        from roboisf.cell import cell_from_study
        from roboisf.decompose.pipeline import scan_options
        from roboisf.study.spec import load_study
        from roboisf.study.toolpaths import study_toolpath

        study = load_study(args.study)
        cell = cell_from_study(study)
        run = study.robot_run if args.run == "robot" else study.cnc
        tp = study_toolpath(study, run, cell.part)
        opts = scan_options(study)  # as analyze compares the study's scans
        return (lambda: read_scan(run.scan, unit=run.scan_unit)), cell.part, tp, opts
    from roboisf.parts import Cone
    from roboisf.scan import radial_offset, synthetic_scan
    from roboisf.toolpath import step_down

    cone = Cone()
    off = radial_offset(lambda z, phi: 0.5e-3 + 8e-3 * (-z), cone)
    s = synthetic_scan(cone, int(args.points), offset=off, outlier_fraction=0.01, seed=3)
    X = s.points[np.random.default_rng(0).permutation(len(s.points))]
    return (lambda: ScanCloud(X, None, "synthetic")), cone, step_down(cone, 5e-3, 0.5e-3), None


def _timed(fn: Any) -> tuple[float, float, Any]:
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return time.perf_counter() - w, time.process_time() - c, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--study", help="a study folder (default: a synthetic cone scan)")
    ap.add_argument("--run", choices=("robot", "cnc"), default="robot")
    ap.add_argument("--points", type=float, default=2e6, help="synthetic scan size")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    from roboisf.scan import compare_scan, knn_kernel, toolpath_deviations, toolpath_kernel
    from roboisf.scan.deviation import PointDeviations

    load, part, tp, opts = _inputs(args)
    print(f"cores: {os.cpu_count()}, load average {os.getloadavg()[0]:.1f} (contended if > 2)")
    res = None
    for rep in range(args.repeat):
        steps = _Steps()
        w, c = time.perf_counter(), time.process_time()
        cloud = load()
        res = compare_scan(cloud, part, toolpath=tp, options=opts, progress=steps)
        w, c = time.perf_counter() - w, time.process_time() - c
        by = "; ".join(f"{k} {v[0]:.2f}/{v[1]:.2f}" for k, v in steps.t.items())
        first = " (first: numba cache load or compile)" if rep == 0 else ""
        print(f"compare_scan {cloud.n_points:,} points: {w:.2f} s wall, {c:.2f} s CPU{first}")
        print(f"  by step (wall/CPU s): {by}")
    assert res is not None
    wall: PointDeviations = res.points
    o = res.options
    kw = dict(radius=o.radius, max_points=o.max_points, min_points=o.min_points, ordered=True)
    kw |= dict(exclude=tp.contact[:, 2] >= -(o.rim_band or 0.0))
    print(f"\ntoolpath neighbourhoods, {wall.n_points:,} wall points, {len(tp):,} contacts:")
    for _ in range(2):
        wa, ca, a = _timed(lambda: toolpath_deviations(wall, tp.contact, tp.normal, **kw))
        toolpath_kernel.HAVE_NUMBA = False
        try:
            wb, cb, b = _timed(lambda: toolpath_deviations(wall, tp.contact, tp.normal, **kw))
        finally:
            toolpath_kernel.HAVE_NUMBA = knn_kernel.HAVE_NUMBA
        same = all(
            np.array_equal(getattr(a, f), getattr(b, f)) for f in ("dn", "spread", "n_points")
        )
        print(
            f"  (a) grid {wa:.3f} s wall / {ca:.3f} CPU, (b) k-d tree {wb:.3f} / {cb:.3f}: "
            f"(a)/(b) CPU {ca / cb:.2f}, same bits: {same}"
        )
    # the outlier k-NN kernels on the wall points sorted by cell, one thread each
    k = o.outlier_k or 8
    lo, h, shape, key, start = knn_kernel._grid(wall.points, k, knn_kernel.MAX_CELLS)
    order = knn_kernel._counting_sort(key, start)
    Xs = knn_kernel._gather(wall.points, knn_kernel._NO_ROWS, order)
    n = Xs.shape[0]
    print(f"outlier k-NN (k = {k}), {n:,} points, one thread:")
    args_ = (Xs, start, lo, h, *shape, k + 1, knn_kernel.MAX_RINGS)
    mc, mr = np.empty(n), np.empty(n)

    def by_cell() -> None:  # the default k's kernel (k = 8); any other k: the ring search
        if k == 8:
            knn_kernel._knn_mean_block9(
                Xs, start, lo, h, *shape, knn_kernel._BLOCK, 0, start.size - 1, mc
            )
            knn_kernel._knn_mean_rows(*args_, np.flatnonzero(np.isnan(mc)), mc)
        else:
            knn_kernel._knn_mean(*args_, 0, n, mc)

    def by_ring() -> None:
        knn_kernel._knn_mean(*args_, 0, n, mr)

    for _ in range(2):
        wc, cc, _ = _timed(by_cell)
        wr, cr, _ = _timed(by_ring)
        print(
            f"  (c) by query cell {wc:.3f} s wall / {cc:.3f} CPU, (d) ring search {wr:.3f} / "
            f"{cr:.3f}: (c)/(d) CPU {cc / cr:.2f}, same bits: "
            f"{np.array_equal(mc, mr, equal_nan=True)}"
        )
    print(f"load average after {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
