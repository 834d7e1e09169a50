"""The machine's speed at the moment of a benchmark, printed beside its figures.

The 2-vCPU VM these benchmarks run on changes speed by up to 2× within an hour (2026-11-29: the
same 5 M Python additions at module level took 0.33 s at 11:21 UTC and 0.60 s at 11:29, the load
below 1.5 both times):
a wall time means little without the machine's pace at that moment. ``speed_line()`` times two
fixed workloads — a pure-Python loop (the interpreter: imports, typer, the report) and a numpy
sort (memory and vector units: the kernels' kind of work) — best of three each, and the load.

Used by benchmarks/analyze.py and benchmarks/cold_start.py (run as scripts: this folder is on
``sys.path``).
"""

from __future__ import annotations

import os
import time


def _best(fn: object, repeat: int = 3) -> float:
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        fn()  # type: ignore[operator]
        best = min(best, time.perf_counter() - t)
    return best


def _loop() -> None:
    s = 0
    for i in range(5_000_000):
        s += i


def speed_line() -> str:
    """One line: the Python loop's and the numpy sort's best time, and the load average."""
    import numpy as np

    x = np.random.default_rng(0).random(4_000_000)
    t_py = _best(_loop)
    t_np = _best(lambda: np.sort(x))
    load = " ".join(f"{v:.2f}" for v in os.getloadavg())
    return (
        f"machine now: 5 M Python additions {t_py:.3f} s, numpy sort of 4 M float64 "
        f"{t_np:.3f} s (best of 3: compare these between runs before their times); load {load}"
    )


if __name__ == "__main__":
    print(speed_line())
