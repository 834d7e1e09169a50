"""Placement sweep throughput: 1,000 placements × a 20,000-point toolpath (20 M pose evaluations:
IK + singularity margin + continuity + VJM δ + tool δ) on the default scheduler (threads of this
process with the compiled engine), against a Dask LocalCluster of as many worker processes on
the same placements in the same run (the peer; ``--no-dask`` skips it).

Run by hand:  PYTHONPATH=src python benchmarks/plan.py [--placements 1000] [--workers 2]

The paper's cone (Ø87, 71°) with the paper cell's tool on an IRB 7600, point spacing chosen to
give ≈ 20,000 tip points; placements on a grid around the robot's front. The serial reference is
timed on a subset (``--serial-subset``) in this process and extrapolated — said in the printout.
The peer is the plain per-placement loop a user would write with the robot module
(``ik_toolpath`` + ``RobotModel.deflection``), timed on the same subset.
Also the serial subset on the numpy engines (IK + VJM without numba) for the engine ratio.
Targets (2 cores): ≤ 60 s for the 1,000 placements; issue #16: 20 M pose evaluations ≤ 10 s.
Wall-clock figures on a shared machine are contended; the CPU times (``time.process_time``) of
the serial runs are printed too.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np

from roboisf.errors import UnreachableError
from roboisf.plan import placement_grid, plan_placements, problem_from_cell
from roboisf.plan.problem import placement_transforms
from roboisf.plan.sweep import default_scheduler
from roboisf.robot import SingularityWarning, ik_toolpath
from roboisf.virtual.cell import PAPER_CELL_PLACEMENT, paper_cone_cell


def _grid(n: int) -> np.ndarray:
    # k x × k y × k z (k³ > n) kept in the reachable front region; trimmed to n. One yaw: the
    # cone is round, so plan_placements evaluates rows that differ in yaw alone once
    # (docs/plan.md, "A round part's yaw") — a second yaw would not be timed
    k = max(2, round(n ** (1 / 3)) + 1)
    P = placement_grid(
        np.linspace(1.1, 2.3, k), np.linspace(-0.6, 0.6, k), np.linspace(0.0, 1.2, k), [0.0]
    )
    rng = np.random.default_rng(0)
    return P[rng.permutation(len(P))[:n]]


def _malloc_as_workers() -> str:
    """Give this process the allocator settings of the local cluster's workers
    (``roboisf.plan.sweep.WORKER_ENV``), so serial and parallel run under the same conditions."""
    import ctypes
    import ctypes.util

    from roboisf.plan.sweep import WORKER_ENV

    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        m_trim, m_mmap = -1, -3  # glibc mallopt parameters
        ok = libc.mallopt(m_mmap, WORKER_ENV["MALLOC_MMAP_THRESHOLD_"]) and libc.mallopt(
            m_trim, WORKER_ENV["MALLOC_TRIM_THRESHOLD_"]
        )
    except (OSError, AttributeError):
        ok = 0
    return "as the workers (mallopt)" if ok else "default (mallopt unavailable)"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--placements", type=int, default=1000)
    ap.add_argument("--points", type=int, default=20_000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--serial-subset", type=int, default=40)
    ap.add_argument("--scheduler", default="auto")
    ap.add_argument("--no-dask", action="store_true", help="Skip the Dask LocalCluster peer run.")
    ap.add_argument(
        "--sweep-only",
        action="store_true",
        help="Only the sweep on --scheduler (to time the whole process with /usr/bin/time).",
    )
    ap.add_argument(
        "--default-malloc", action="store_true", help="Keep this process's allocator defaults."
    )
    a = ap.parse_args()
    alloc = "default" if a.default_malloc else _malloc_as_workers()

    # spacing for ≈ the asked number of points (the cone path is ~34.8 m long at 1 mm spacing)
    spacing = 34.8 / a.points
    vc = paper_cone_cell(spacing=spacing)
    prob, _ = problem_from_cell(vc.cell, **vc.path_settings)
    P = _grid(a.placements)
    n_pose = len(P) * prob.n_points
    print(
        f"toolpath {prob.n_points} points ({prob.n_laps} laps), {len(P)} placements → "
        f"{n_pose / 1e6:.1f} M pose evaluations; {os.cpu_count()} CPUs, load "
        f"{os.getloadavg()[0]:.1f}; serial allocator {alloc}"
    )

    if a.sweep_only:
        t, c = time.perf_counter(), time.process_time()
        res = plan_placements(
            prob, P, baseline=PAPER_CELL_PLACEMENT, scheduler=a.scheduler, n_workers=a.workers
        )
        t_par, c_par = time.perf_counter() - t, time.process_time() - c
        print(
            f"{a.scheduler} ({a.workers} workers), sweep only, kernels from numba's cache: "
            f"{t_par:.1f} s wall, {c_par:.1f} s CPU of this process "
            f"({c_par / n_pose * 1e6:.2f} µs CPU/pose); feasible {res.order.size}/{len(P)}; "
            f"load average now {os.getloadavg()[0]:.1f}"
        )
        return
    sub = P[: a.serial_subset]
    # compile (or load from numba's cache) the main-thread and the worker-thread kernels first
    plan_placements(prob, P[:2], scheduler="serial", detail=1)
    plan_placements(prob, P[:2], scheduler="threads", n_workers=2, detail=0)
    t, c = time.perf_counter(), time.process_time()
    ser = plan_placements(prob, sub, scheduler="serial")
    t_ser, c_ser = time.perf_counter() - t, time.process_time() - c
    per, cpu = t_ser / len(sub), c_ser / len(sub)
    print(
        f"serial (subset of {len(sub)}, extrapolated): {per * 1e3:.1f} ms/placement wall, "
        f"{cpu * 1e3:.1f} ms CPU; {prob.n_points / per / 1e6:.3f} M poses/s → "
        f"{per * len(P):.1f} s for {len(P)}; CPU-time projection on 2 idle cores "
        f"{cpu * len(P) / 2:.1f} s"
    )

    # per-pose CPU of the placements' evaluation alone (no shortlist detail), both engines
    t, c = time.perf_counter(), time.process_time()
    plan_placements(prob, sub, scheduler="serial", detail=0)
    cpu0 = (time.process_time() - c) / len(sub)
    print(
        f"serial, evaluation only (detail=0, {len(sub)} placements): "
        f"{(time.perf_counter() - t) / len(sub) * 1e3:.1f} ms/placement wall, "
        f"{cpu0 * 1e3:.1f} ms CPU = {cpu0 / prob.n_points * 1e6:.2f} µs CPU/pose"
    )
    if prob.model.backend != "numpy":
        from dataclasses import replace

        prob_np = replace(prob, model=prob.model.with_backend("numpy"))
        sub_np = sub[: max(1, len(sub) // 4)]
        c = time.process_time()
        plan_placements(prob_np, sub_np, scheduler="serial", detail=0)
        cpu_np = (time.process_time() - c) / len(sub_np)
        print(
            f"  the same on the numpy engines ({len(sub_np)} placements): "
            f"{cpu_np / prob.n_points * 1e6:.2f} µs CPU/pose ({cpu_np / cpu0:.1f}× the compiled)"
        )

    # the peer: a hand loop over the robot module's public calls (IK + deflection per placement)
    Ts = placement_transforms(sub)
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SingularityWarning)
        for T in Ts:
            try:
                q = ik_toolpath(prob.model, prob.tip, T).q
            except UnreachableError:  # skipped, as the sweep does
                continue
            prob.model.deflection(q, prob.wrench, T_base_work=T)
    t_peer = (time.perf_counter() - t) / len(sub)
    print(f"peer loop (ik_toolpath + RobotModel.deflection): {t_peer * 1e3:.1f} ms/placement")

    load0 = os.getloadavg()[0]
    t, c = time.perf_counter(), time.process_time()
    res = plan_placements(
        prob, P, baseline=PAPER_CELL_PLACEMENT, scheduler=a.scheduler, n_workers=a.workers
    )
    t_par, c_par = time.perf_counter() - t, time.process_time() - c
    same = all(
        x.mean_abs == y.mean_abs or (x.status != "ok" and y.status != "ok")
        for x, y in zip(ser.scores, res.scores[: len(sub)], strict=True)
    )
    print(
        f"{a.scheduler} ({default_scheduler(prob) if a.scheduler == 'auto' else a.scheduler}, "
        f"{a.workers} workers): {t_par:.1f} s wall, {c_par:.1f} s CPU of this process "
        f"({c_par / n_pose * 1e6:.2f} µs CPU/pose), {n_pose / t_par / 1e6:.3f} M poses/s; "
        f"serial/parallel = {per * len(P) / t_par:.2f}; subset identical to serial: {same}; "
        f"load average before/after {load0:.1f}/{os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"
    )
    if not a.no_dask and a.scheduler != "local":
        load1 = os.getloadavg()[0]
        t = time.perf_counter()
        res_d = plan_placements(
            prob, P, baseline=PAPER_CELL_PLACEMENT, scheduler="local", n_workers=a.workers
        )
        t_dask = time.perf_counter() - t
        same_d = all(
            x.mean_abs == y.mean_abs or (x.status == y.status and x.reason == y.reason)
            for x, y in zip(res.scores, res_d.scores, strict=True)
        )
        print(
            f"peer: Dask LocalCluster ({a.workers} worker processes), incl. cluster start: "
            f"{t_dask:.1f} s wall; Dask / {a.scheduler} = {t_dask / t_par:.2f}; every score "
            f"identical: {same_d}; load average before/after {load1:.1f}/"
            f"{os.getloadavg()[0]:.1f}"
        )
    print(
        f"feasible {res.order.size}/{len(P)} {res.rejected()}; best mean robot |δ| "
        f"{res.best.mean_robot * 1e3:.4f} mm vs paper-like cell "
        f"{res.baseline.mean_robot * 1e3:.4f} mm ({100 * res.improvement():.1f} % lower)"
    )
    print(f"target ≤ 60 s on 2 cores: {'met' if t_par <= 60 else 'MISSED'}")
    t20 = t_par * 20e6 / n_pose
    # the CPU time of the whole sweep (threads: every thread's; else the serial evaluation's)
    threads = (a.scheduler == "auto" and default_scheduler(prob) == "threads") or (
        a.scheduler == "threads"
    )
    cpu20 = c_par * 20e6 / n_pose if threads else cpu0 * 20e6 / prob.n_points
    src = "this sweep's CPU time (every thread)" if threads else "the serial evaluation's CPU time"
    print(
        f"issue #16 target, 20 M pose evaluations ≤ 10 s on 2 cores: {t20:.1f} s at this run's "
        f"{a.scheduler} rate ({'met' if t20 <= 10 else 'not met in this run'}); {cpu20 / 2:.1f} s "
        f"from {src} split over 2 cores (contended if the load average above exceeds ~0.5)"
    )


if __name__ == "__main__":
    main()
