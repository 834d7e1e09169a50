"""Benchmark: peak memory and time of the whole scan comparison against the scan size.

    PYTHONPATH=src python benchmarks/scan_memory.py [--points 2e6 5e6 10e6] [--dir DIR]

For each size a synthetic formed cone (0.5 → 1.3 mm radial offset, 25 µm noise, 1 % outliers,
points shuffled as a scanner's file has them) is written as a binary float32 PLY in mm (in
chunks: the writer's memory is not measured), then a *fresh process* reads it
(``read_scan``: memory-mapped) and runs ``compare_scan`` with the paper's 0.5 mm step-down
toolpath (defaults: outlier filter k = 8, 3 σ; per-toolpath-point medians). That process
reports its own peak RSS (``ru_maxrss``: the interpreter and imports included) and its wall
and CPU time (user + system, all threads). Issue #16: a 10 M-point scan within 2 GB.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def write_scan(path: Path, n: int, chunk: int = 1_000_000) -> None:
    """A shuffled synthetic cone scan of ``n`` points as a binary PLY (float32, mm)."""
    from roboisf.parts import Cone
    from roboisf.scan import radial_offset, synthetic_scan

    cone = Cone()
    off = radial_offset(lambda z, phi: 0.5e-3 + 8e-3 * (-z), cone)
    head = (
        "ply\nformat binary_little_endian 1.0\ncomment units mm\n"
        f"element vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
        "end_header\n"
    )
    # chunks in a shuffled order of seeds, points shuffled within each: no spatial order
    with open(path, "wb") as fh:
        fh.write(head.encode("ascii"))
        for i, lo in enumerate(range(0, n, chunk)):
            m = min(chunk, n - lo)
            s = synthetic_scan(cone, m, offset=off, outlier_fraction=0.01, seed=1000 + i)
            X = s.points[np.random.default_rng(i).permutation(m)] * 1e3
            fh.write(X.astype("<f4").tobytes())


def child(path: str) -> None:
    from roboisf.parts import Cone
    from roboisf.scan import CompareOptions, compare_scan, read_scan
    from roboisf.toolpath import step_down

    t, c = time.perf_counter(), time.process_time()
    cone = Cone()
    tp = step_down(cone, 5e-3, 0.5e-3)
    cloud = read_scan(path, unit="mm")
    t_read = time.perf_counter() - t
    res = compare_scan(cloud, cone, toolpath=tp, options=CompareOptions(), consume=True)
    assert res.toolpath is not None
    out = {
        "wall_s": time.perf_counter() - t,
        "cpu_s": time.process_time() - c,
        "read_s": t_read,
        "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2,
        "used": res.counts["used"],
        "toolpath_points": int(res.toolpath.valid.size),
        "toolpath_valid": int(res.toolpath.valid.sum()),
    }
    print(json.dumps(out))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--points", type=float, nargs="+", default=[2e6, 5e6, 10e6])
    ap.add_argument("--dir", type=Path, default=None, help="where the PLY files go (temp dir)")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        child(a.child)
        return
    print(f"cores: {os.cpu_count()}, load average: {os.getloadavg()}")
    with tempfile.TemporaryDirectory(dir=a.dir) as tmp:
        for n in (int(v) for v in a.points):
            path = Path(tmp) / f"scan_{n}.ply"
            write_scan(path, n)
            r = subprocess.run(
                [sys.executable, __file__, "--child", str(path)],
                check=True,
                capture_output=True,
                text=True,
                env=os.environ,
            )
            d = json.loads(r.stdout.strip().splitlines()[-1])
            print(
                f"{n:>11,} points: peak RSS {d['peak_gb']:.2f} GB, wall {d['wall_s']:.1f} s "
                f"(read {d['read_s']:.1f} s), CPU {d['cpu_s']:.1f} s; {d['used']:,} wall points "
                f"used, {d['toolpath_valid']:,}/{d['toolpath_points']:,} toolpath points valid"
            )
            path.unlink()
    print(f"load average after: {os.getloadavg()} (2 shared cores: contended)")


if __name__ == "__main__":
    main()
