"""Compensation throughput on the paper's cone (0.5 mm step, 1 mm spacing: ≈ 35,000 points).

Run by hand:  PYTHONPATH=src python benchmarks/compensate.py [--subset 300]

* compliance pre-deflection: roboisf's vectorised fixed point (IK + VJM of the whole path per
  iteration) side by side with the textbook per-point solve, ``scipy.optimize.root`` (hybr) on
  ``p + δ(p) − p_target = 0`` one point at a time with the same IK + VJM; the per-point solve is
  timed on a subset and extrapolated (said in the printout); both answers are compared.
* displacement adjustment (smoothing along and across laps with holes) on the whole path.
* one full virtual-cell iteration (simulate + compensate + simulate).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import root

from roboisf.compensate import displacement_adjustment, precompensate
from roboisf.compensate.virtual import cell_deflection_model, iterate_virtual
from roboisf.virtual.cell import paper_cone_cell, simulate


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--subset", type=int, default=300)
    args = ap.parse_args()
    cell = paper_cone_cell()
    truth = simulate(cell)
    tp, W = truth.toolpath, truth.wrench_robot
    n = len(tp)
    model = cell_deflection_model(cell.cell)
    precompensate(tp, W[:], model)  # warm-up
    t0 = time.perf_counter()
    res = precompensate(tp, W, model)
    t_vec = time.perf_counter() - t0
    print(f"points: {n}, fixed-point iterations: {res.iterations}")
    print(f"roboisf precompensate: {t_vec:.3f} s  ({n / t_vec:,.0f} points/s)")

    idx = np.linspace(0, n - 1, args.subset).astype(int)
    out = np.empty((idx.size, 3))
    t0 = time.perf_counter()
    for j, i in enumerate(idx):
        target, w = tp.tip[i].copy(), W[i : i + 1]

        # unknown u = p − target (MINPACK's relative difference step needs |x| well away from 0)
        def f(u: np.ndarray, target: np.ndarray = target, w: np.ndarray = w) -> np.ndarray:
            d, _ = model.deflection((target + u)[None, :], w)
            return np.asarray(u + d[0])

        out[j] = target + root(f, np.zeros(3), tol=1e-12).x
    t_loop = (time.perf_counter() - t0) / idx.size * n
    err = np.max(np.linalg.norm(out - res.commanded[idx], axis=1))
    print(
        f"scipy.optimize.root per point (timed on {idx.size}, extrapolated): {t_loop:.1f} s  "
        f"({n / t_loop:,.0f} points/s); ratio {t_loop / t_vec:.0f}x; max |Δp| {err * 1e9:.2f} nm"
    )

    rng = np.random.default_rng(0)
    D = truth.dn_robot + rng.normal(scale=25e-6, size=n)
    valid = rng.random(n) > 0.01
    t0 = time.perf_counter()
    for _ in range(5):
        displacement_adjustment(tp, D, valid=valid)
    t_adj = (time.perf_counter() - t0) / 5
    print(f"displacement_adjustment ({tp.n_laps} laps, 1 % holes): {t_adj * 1e3:.1f} ms")

    t0 = time.perf_counter()
    iterate_virtual(cell, iterations=1)
    print(
        f"one virtual-cell iteration (simulate, compensate, simulate): "
        f"{time.perf_counter() - t0:.2f} s"
    )


if __name__ == "__main__":
    main()
