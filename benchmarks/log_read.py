"""Reading a long force log as instruments write it, against pandas in the same run.

Run by hand:  PYTHONPATH=src python benchmarks/log_read.py [--rows 2294068] [--repeat 2]

A 1 kHz force log over the paper cone's forming time (2.3 M rows, ~160 MB) is written in four
layouts: the roboisf CSV (``# units:`` line), a generic export (``Fx [N]`` header, comma), a
blank-separated export with a units row, and a semicolon / decimal-comma export in cp1252 with
a status column. Each is read by ``roboisf.logs.forcelog.read_force_log`` (every check: units,
finiteness, monotonic time, the named line of a bad cell) and by the peer, ``pandas.read_csv``
of the same file whole into float64 (no checks), each in a fresh interpreter so that the peak
RSS is the reader's own. Prints wall time, peak RSS and the ratios. Issue #16: the analysis of
the paper cone within 1 GB; a log reader that peaks at 2 GB by itself cannot meet it.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

HEADERS = {
    "roboisf": "# units: time=s force=N moment=N*m\n# frame: sensor\ntime,Fx,Fy,Fz,Mx,My,Mz\n",
    "generic": "Time [s],Fx [N],Fy [N],Fz [N],Tx [Nm],Ty [Nm],Tz [Nm]\n",
    "blanks": (
        "Logger export\nSample rate: 1000 Hz\n\nTime Fx Fy Fz Mx My Mz\ns N N N N*m N*m N*m\n"
    ),
    "decimal-comma": (
        "Messung °C\nRate;1000\nZeit [s];Fx [N];Fy [N];Fz [N];Mx [N*m];My [N*m];Mz [N*m];Status\n"
    ),
}
#: pandas' arguments for the same file (rows to skip, separator, decimal mark, columns)
PEER = {
    "roboisf": dict(skiprows=3, sep=","),
    "generic": dict(skiprows=1, sep=","),
    "blanks": dict(skiprows=5, sep=r"\s+"),
    "decimal-comma": dict(skiprows=3, sep=";", decimal=",", usecols=range(7), encoding="cp1252"),
}

_HWM = """
def hwm():  # this image's peak RSS (KiB); ru_maxrss would keep the forking parent's
    return next(int(x.split()[1]) for x in open("/proc/self/status") if x.startswith("VmHWM"))
"""

_ROBOISF = (
    _HWM
    + """
import sys, time
from roboisf.logs.forcelog import read_force_log
t = time.perf_counter()
log = read_force_log(sys.argv[1])
dt = time.perf_counter() - t
print(dt, hwm(), len(log.time))
"""
)

_PANDAS = (
    _HWM
    + """
import sys, time, json
import numpy as np, pandas as pd
kw = json.loads(sys.argv[2])
if "usecols" in kw:
    kw["usecols"] = list(range(kw["usecols"]))
t = time.perf_counter()
a = pd.read_csv(sys.argv[1], header=None, dtype=np.float64, engine="c", **kw).to_numpy()
dt = time.perf_counter() - t
print(dt, hwm(), len(a))
"""
)


def _write(folder: Path, rows: int) -> dict[str, Path]:
    rng = np.random.default_rng(7)
    t = np.arange(rows) * 1e-3
    w = rng.normal(size=(rows, 6)) * [40, 40, 900, 3, 3, 1]
    df = pd.DataFrame(np.column_stack([t, w]))
    out = {}
    for name, head in HEADERS.items():
        p = folder / f"{name}.csv"
        enc = "cp1252" if name == "decimal-comma" else "utf-8"
        with open(p, "w", encoding=enc, newline="\n") as f:
            f.write(head)
            if name == "decimal-comma":
                d = df.copy()
                d[7] = "OK"
                d.to_csv(f, index=False, header=False, sep=";", decimal=",", float_format="%.7g")
            else:
                sep = " " if name == "blanks" else ","
                df.to_csv(f, index=False, header=False, sep=sep, float_format="%.7g")
        out[name] = p
    return out


def _run(code: str, *args: str) -> tuple[float, float, int]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[1] / "src")
    p = subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, env=env, check=True
    )
    dt, rss, n = p.stdout.split()
    return float(dt), float(rss) / 1024**2, int(n)  # s, GiB (VmHWM is KiB)


def main() -> None:
    import json

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=2_294_068)
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    print(f"{args.rows:,} rows; 2 CPUs shared? load average {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as d:
        files = _write(Path(d), args.rows)
        print(
            f"{'layout':15s} {'MB':>6s} {'roboisf s':>10s} {'GiB':>6s} {'pandas s':>9s} {'GiB':>6s}"
            f" {'time ×':>7s} {'peak ×':>7s}"
        )
        for name, path in files.items():
            ours, peer = [], []
            for _ in range(args.repeat):  # interleaved
                ours.append(_run(_ROBOISF, str(path)))
                kw = dict(PEER[name])
                if "usecols" in kw:
                    kw["usecols"] = 7
                peer.append(_run(_PANDAS, str(path), json.dumps(kw)))
            o = min(ours)
            p = min(peer)
            assert o[2] == p[2] == args.rows, (o, p)
            print(
                f"{name:15s} {path.stat().st_size / 1e6:6.0f} {o[0]:10.2f} {o[1]:6.2f} {p[0]:9.2f}"
                f" {p[1]:6.2f} {o[0] / p[0]:7.2f} {o[1] / p[1]:7.2f}"
            )
    print("time × and peak ×: roboisf / pandas (roboisf checks every cell, unit and time step;")
    print("the peer only parses). Peak: the whole interpreter's, imports included.")


if __name__ == "__main__":
    main()
