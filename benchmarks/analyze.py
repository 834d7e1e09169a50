"""Paper-scale analysis: both studies with 1 kHz force logs over the full forming time and 2 M-point
scans. Targets (issue #6, 2 cores): analyze ≤ 60 s for both, ≤ 6 GB peak; `roboisf demo` ≤ 90 s.

Run by hand:  python benchmarks/analyze.py [--scan-points 2000000] [--keep DIR]

There is no peer library that performs this decomposition; as a reference point the run prints
the share of the time spent in the two biggest peer-library steps we call (pandas' C CSV parser
on the force logs, scipy's cKDTree outlier filter) next to the end-to-end time.
"""

from __future__ import annotations

import argparse
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--scan-points", type=int, default=2_000_000)
    ap.add_argument("--force-rate", type=float, default=1000.0)
    ap.add_argument("--keep", type=Path, default=None, help="keep the studies in this folder")
    a = ap.parse_args(argv)

    import pandas as pd

    from roboisf.cli.main import main as cli
    from roboisf.decompose.pipeline import analyze, write_results
    from roboisf.virtual.cell import build_study, paper_cone_cell, paper_vwacf_cell

    root = a.keep or Path(tempfile.mkdtemp(prefix="roboisf-bench-"))
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
        rows = sum(1 for _ in open(s / "cnc_forces.csv")) + sum(
            1 for _ in open(s / "robot_forces.csv")
        )
        t = time.perf_counter()
        r = analyze(s)
        write_results(r, root / f"{s.name}-results")
        dt = time.perf_counter() - t
        t_an += dt
        tp = time.perf_counter()
        pd.read_csv(s / "cnc_forces.csv", comment="#")
        pd.read_csv(s / "robot_forces.csv", comment="#")
        t_pd = time.perf_counter() - tp
        print(
            f"  analyze {s.name}: {dt:.1f} s ({rows:,} force-log rows; pandas alone reads the "
            f"two logs in {t_pd:.1f} s = {t_pd / dt:.0%} of the analysis)"
        )
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
    print(
        f"analyze, both studies: {t_an:.1f} s (target ≤ 60 s: "
        f"{'met' if t_an <= 60 else 'MISSED'}); peak RSS {peak:.2f} GB (target ≤ 6 GB)"
    )

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
