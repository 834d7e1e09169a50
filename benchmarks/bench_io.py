"""Speed of toolpath generation and the toolpath I/O layer, against peers in the same run.

Run by hand:  PYTHONPATH=src python benchmarks/bench_io.py

* generation of the paper cone (step-down and spiral, 1 mm spacing)
* toolpath CSV write/read (with all validation) vs pandas to_csv/read_csv of the same 18 columns
* force log 1 kHz over the whole cone path (~2.3 M samples) attached by time: cumulative-sum window
  means vs a per-point masked mean (the obvious loop), on the same windows
* RAPID / KRL / G-code writers
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from roboisf.cam.gcode import write_gcode
from roboisf.cam.toolpath_csv import (
    TOOLPATH_COLUMNS,
    read_toolpath_csv,
    toolpath_table,
    write_toolpath_csv,
)
from roboisf.logs.forcelog import ForceLog, attach_to_toolpath
from roboisf.parts import Cone
from roboisf.programs.fanuc import write_fanuc
from roboisf.programs.krl import write_krl
from roboisf.programs.rapid import write_rapid
from roboisf.toolpath import spiral, step_down


def timeit(fn, repeat=3):
    best = math.inf
    out = None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def main() -> None:
    part = Cone(87e-3, math.radians(71.0), 102.97e-3)
    t_sd, tp = timeit(lambda: step_down(part, 5e-3, 0.5e-3))
    t_sp, tps = timeit(lambda: spiral(part, 5e-3, 0.5e-3))
    print(
        f"generation  step_down {len(tp)} pts: {t_sd * 1e3:7.1f} ms   spiral {len(tps)} pts: "
        f"{t_sp * 1e3:7.1f} ms"
    )

    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        f = d / "p.csv"
        t_w, _ = timeit(lambda: write_toolpath_csv(tp, f))
        t_r, back = timeit(lambda: read_toolpath_csv(f))
        data = toolpath_table(tp)
        df = pd.DataFrame(data, columns=TOOLPATH_COLUMNS)
        g = d / "pd.csv"
        t_pw, _ = timeit(lambda: df.to_csv(g, index=False, float_format="%.9f"))
        t_pr, _ = timeit(lambda: pd.read_csv(g))
        print(
            f"CSV write   roboisf {t_w * 1e3:7.1f} ms   pandas {t_pw * 1e3:7.1f} ms   "
            f"ratio {t_w / t_pw:5.2f}"
        )
        print(
            f"CSV read    roboisf {t_r * 1e3:7.1f} ms   pandas {t_pr * 1e3:7.1f} ms   "
            f"ratio {t_r / t_pr:5.2f}  (roboisf validates every row)"
        )
        assert np.abs(back.tip - tp.tip).max() < 1e-11

        base = {"T_base_work": np.eye(4)}  # robot programs have no default placement
        for name, fn, suffix, kw in (
            ("RAPID", write_rapid, ".mod", base),
            ("KRL", write_krl, ".src", base),
            ("FANUC", write_fanuc, ".ls", base),
            ("G-code", write_gcode, ".nc", {}),
        ):
            t, _ = timeit(lambda fn=fn, suffix=suffix, kw=kw: fn(tp, d / f"p{suffix}", **kw))
            print(f"{name:7s} write {len(tp)} moves: {t * 1e3:7.1f} ms")

    rng = np.random.default_rng(0)
    t_log = np.arange(0.0, tp.time[-1] + 1e-3, 1e-3)
    w = rng.normal(0, 10, (t_log.size, 6))
    w[:, 2] += -400
    log = ForceLog(t_log, w, "sensor")
    t_a, W = timeit(lambda: attach_to_toolpath(log, tp, by="time"))
    # peer: per-point masked mean of the samples inside each window (subset, extrapolated)
    tt = tp.time
    mid = 0.5 * (tt[1:] + tt[:-1])
    lo = np.concatenate([[tt[0]], mid])
    hi = np.concatenate([mid, [tt[-1]]])
    sub = np.linspace(0, len(tp) - 1, 300).astype(int)

    def loop():
        return np.array([w[(t_log >= lo[i]) & (t_log <= hi[i])].mean(axis=0) for i in sub])

    t_l, Wl = timeit(loop, repeat=1)
    t_l_full = t_l * len(tp) / sub.size
    print(
        f"attach by time {len(tp)} pts, {t_log.size} samples: roboisf {t_a * 1e3:7.1f} ms   "
        f"masked-mean loop ≈ {t_l_full:7.1f} s (extrapolated)   ratio {t_l_full / t_a:7.0f}x"
    )
    print(
        f"  agreement on the subset (N): max |Δ| = {np.abs(W[sub] - Wl).max():.3g} "
        "(exact interpolant mean vs sample mean)"
    )


if __name__ == "__main__":
    main()
