"""Benchmark: FE compliance of the Ø10 × 60 mm steel ball-end tool at the default mesh (R/3).

Prints wall time per stage, peak memory (tracemalloc for Python-side arrays, ru_maxrss for the
whole process incl. gmsh and the factor), the vectorised assembly vs scikit-fem's generic
``BilinearForm`` assembly on the same mesh (time ratio, max relative difference), and the
accuracy against a finer mesh. Run by hand:

    PYTHONPATH=src python benchmarks/fem_tool.py [--solver superlu] [--reference] [--convergence]

``--reference`` also solves at R/6 (the accuracy figure); ``--convergence`` solves the paper's
66 mm tool at R/3 and R/6 (188k DOFs: minutes and >2 GB with SuperLU; PARDISO recommended).
"""

from __future__ import annotations

import argparse
import resource
import time
import tracemalloc

import numpy as np

from roboisf.fem import (
    PAPER_TOOL_LENGTH,
    STEEL,
    BallEndTool,
    assemble_stiffness,
    assemble_stiffness_skfem,
    fe_compliance,
    mesh_geometry,
    solve_six_cases,
)


def _lateral(k: np.ndarray) -> float:
    return 0.5 * float(k[0, 0] + k[1, 1])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--solver", default="auto")
    ap.add_argument("--reference", action="store_true")
    ap.add_argument("--convergence", action="store_true")
    args = ap.parse_args()

    tool = BallEndTool(10e-3, 60e-3)
    # warm-up: imports, gmsh start, solver library load (not part of a user's repeated runs)
    solve_six_cases(tool, 5e-3, solver=args.solver)

    tracemalloc.start()
    t0 = time.perf_counter()
    res = fe_compliance(tool, solver=args.solver, convergence=False)
    wall = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    q = res.quality
    print(
        f"tool Ø10 × 60 mm, mesh {q['mesh_size'] * 1e3:.2f} mm (R/3): {q['n_tets']} tets, "
        f"{q['n_dofs']} free DOFs, solver {q['solver']}"
    )
    print("  stages [s]: " + ", ".join(f"{k} {v:.3f}" for k, v in q["timings"].items()))
    print(f"  wall {wall:.2f} s (target ≤ 10 s); Python peak {peak / 2**20:.0f} MiB (tracemalloc)")
    t0 = time.perf_counter()
    res_c = fe_compliance(tool, solver=args.solver, convergence=True)
    wall_c = time.perf_counter() - t0
    conv = res_c.quality["mesh_convergence"]
    print(
        f"  with the 2h Richardson run: wall {wall_c:.2f} s; Richardson error (lateral) "
        f"{conv['richardson_error_lateral'] * 100:.3f} %"
    )
    print(
        f"  lateral {_lateral(res.compliance):.5e} m/N, axial {res.axial:.4e} m/N; symmetry "
        f"{q['symmetry_error']:.1e}, resultant {q['resultant_error']:.1e}, "
        f"Kabsch vs area fit {q['kabsch_rel_diff']:.2e}"
    )

    mesh = mesh_geometry(tool, q["mesh_size"])
    lame = np.array([STEEL.lame])
    times = {}
    for name, fn in (("roboisf", assemble_stiffness), ("skfem", assemble_stiffness_skfem)):
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            K = fn(mesh, lame)
            best = min(best, time.perf_counter() - t0)
        times[name] = (best, K)
    diff = abs(times["roboisf"][1] - times["skfem"][1]).max() / abs(times["skfem"][1]).max()
    print(
        f"  assembly: roboisf {times['roboisf'][0]:.3f} s, skfem BilinearForm "
        f"{times['skfem'][0]:.3f} s → ratio {times['skfem'][0] / times['roboisf'][0]:.1f}×; "
        f"max rel diff {diff:.1e}"
    )

    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**10
    print(f"  process (all of the above) peak RSS {rss:.0f} MiB (target ≤ 1024 MiB)")
    if args.reference:
        ref = solve_six_cases(tool, 5e-3 / 6, solver=args.solver).compliance
        print(
            f"  vs R/6 reference ({_lateral(ref):.5e} m/N): lateral "
            f"{(_lateral(res.compliance) / _lateral(ref) - 1) * 100:+.3f} %, axial "
            f"{(res.axial / ref[2, 2] - 1) * 100:+.3f} %"
        )
    if args.convergence:
        paper = BallEndTool(10e-3, PAPER_TOOL_LENGTH)
        a = solve_six_cases(paper, 5e-3 / 3, solver=args.solver)
        b = solve_six_cases(paper, 5e-3 / 6, solver=args.solver)
        print(
            f"  paper tool {PAPER_TOOL_LENGTH * 1e3:g} mm: R/3 {_lateral(a.compliance):.5e}, "
            f"R/6 {_lateral(b.compliance):.5e} m/N ({b.quality['n_dofs']} DOFs) → "
            f"{(_lateral(a.compliance) / _lateral(b.compliance) - 1) * 100:+.3f} % (≤ 0.3 %)"
        )


if __name__ == "__main__":
    main()
