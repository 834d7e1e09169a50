"""Start-up of the ``roboisf`` command line (issue #16: ``--help`` and bad input in ≤ 0.3 s).

Run by hand:  PYTHONPATH=src python benchmarks/cli_startup.py [--runs 10] [--baseline OTHER/src]

Each case is a fresh interpreter running ``roboisf ARGS`` (what the console script does), in an
empty temporary folder; the cases are interleaved round by round so that a change in the
machine's load hits them all alike. Printed per case: min and median of wall time and of CPU
time (user + sys of the child) over the runs, and the median's ratio to the peers measured in the
same rounds: the bare interpreter (``python -c pass``, the floor no CLI can beat) and ``import
typer`` (the CLI library alone). ``--baseline`` adds the same cases run from another roboisf
source tree (e.g. a checkout of the previous commit) for a before/after in one run. A first,
uncounted round writes the bytecode, as an installation has it.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

CASES: list[tuple[str, list[str]]] = [
    ("--help", ["--help"]),
    ("analyze --help", ["analyze", "--help"]),
    ("toolpath cone --help", ["toolpath", "cone", "--help"]),
    ("online --help", ["online", "--help"]),
    ("usage error (--bogus)", ["--bogus"]),
    ("input error (part cone -o c.txt)", ["part", "cone", "-o", "c.txt"]),
    ("input error (--step-down -1)", ["toolpath", "cone", "-o", "p.csv", "--step-down", "-1"]),
]
RUN = (
    "import sys; from roboisf.cli.main import entry; sys.argv = ['roboisf', *sys.argv[1:]]; entry()"
)


def _once(cmd: list[str], env: dict[str, str], cwd: str) -> tuple[float, float, int]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    r = subprocess.run(cmd, env=env, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, r.returncode


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--baseline", help="another roboisf src folder to compare against")
    a = ap.parse_args()

    here = os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir, "src")
    trees = {"": os.path.abspath(here)}
    if a.baseline:
        trees["baseline: "] = os.path.abspath(a.baseline)
    jobs: dict[str, tuple[list[str], str]] = {
        "peer: python -c pass": ([sys.executable, "-c", "pass"], trees[""]),
        "peer: import typer": ([sys.executable, "-c", "import typer"], trees[""]),
    }
    for prefix, src in trees.items():
        for label, argv in CASES:
            jobs[prefix + label] = ([sys.executable, "-c", RUN, *argv], src)
    wall: dict[str, list[float]] = {k: [] for k in jobs}
    cpu: dict[str, list[float]] = {k: [] for k in jobs}
    codes: dict[str, set[int]] = {k: set() for k in jobs}
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory() as cwd:
        for i in range(a.runs + 1):
            for k, (cmd, src) in jobs.items():
                # as installed: bytecode written once (the uncounted first round), then read
                env = {**os.environ, "PYTHONPATH": src}
                env.pop("PYTHONDONTWRITEBYTECODE", None)
                w, c, rc = _once(cmd, env, cwd)
                if i == 0:
                    continue
                wall[k].append(w)
                cpu[k].append(c)
                codes[k].add(rc)
        assert not os.listdir(cwd), "a start-up case wrote a file"
    load1 = os.getloadavg()

    floor = statistics.median(wall["peer: python -c pass"])
    typer_ = statistics.median(wall["peer: import typer"])
    print(f"{a.runs} runs per case, interleaved; load average {load0[0]:.2f} → {load1[0]:.2f}")
    print(f"{'case':44s} {'exit':>4s}  wall min / med [s]  CPU min / med [s]  ×python  ×typer")
    for k in jobs:
        w, c = wall[k], cpu[k]
        print(
            f"{k:44s} {','.join(map(str, sorted(codes[k]))):>4s}  "
            f"{min(w):7.3f} / {statistics.median(w):6.3f}   "
            f"{min(c):6.3f} / {statistics.median(c):6.3f}   "
            f"{statistics.median(w) / floor:6.2f}  {statistics.median(w) / typer_:6.2f}"
        )


if __name__ == "__main__":
    main()
