"""A command timed against an older revision of this repository, runs alternated (issue #31).

Run by hand:  python benchmarks/against.py REV [--runs 10] [--study DIR] [--compare]
              python benchmarks/against.py HEAD~3 --runs 8 -- plan --part cone --robot ...

The 2-vCPU VM these benchmarks run on moves by more than most changes between windows: on
2026-11-30 the same code's paper-cone ``analyze`` had ten-run medians from 2.98 s to 4.07 s
within an hour, ``benchmarks/machine.py`` unchanged (docs/speed.md). A change is measured by
alternating it with the revision before it, one run of each in turn, so that both see every
window alike; this script does that.

``REV`` (any git revision) is checked out in a temporary worktree and its C kernels built there
(``python -m roboisf.jit.native``: the kernels of that source, with the same flags as an
install); each run is ``python -m roboisf <command>`` in a fresh interpreter with ``PYTHONPATH``
on that tree's ``src`` or this one's. The command is ``analyze STUDY -o OUT -q`` by default (the
paper cone, built with the virtual cell unless ``--study`` is given; ``--scan-points``,
``--force-rate`` as benchmarks/analyze.py), or what follows ``--`` (``{out}`` is replaced by each
side's own output folder). Printed: the machine's pace before and after (benchmarks/machine.py),
each run's wall time, CPU time (user + system of the process and its children) and peak RSS
(the process's high-water mark, ``wait4``), then per side the median, mean and range, and the
ratio of the medians. ``--compare`` checks that both sides wrote the same bytes (every
file of the output folder but roboisf's ownership marker, whose times always differ). The peer
here is the older revision itself: no library does the analysis.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from machine import speed_line  # benchmarks/machine.py (this folder is on sys.path)

REPO = Path(__file__).resolve().parent.parent


def _run(src: Path, args: list[str]) -> tuple[float, float, float]:
    """(wall s, CPU s, peak RSS MiB) of ``python -m roboisf *args`` with ``src`` on the path."""
    env = dict(os.environ, PYTHONPATH=str(src))
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # compiled once, as an install would
    with tempfile.TemporaryFile() as log:  # (a pipe read after wait4 could fill and block)
        t = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, "-m", "roboisf", *args], env=env, stdout=log, stderr=log
        )
        _, status, ru = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t
        proc.returncode = os.waitstatus_to_exitcode(status)
        log.seek(0)
        err = log.read().decode(errors="replace")
    if proc.returncode != 0:
        raise SystemExit(f"roboisf {' '.join(args)} (PYTHONPATH={src}) failed:\n{err[-2000:]}")
    return wall, ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024


#: What roboisf writes beside its outputs to know them again (times and sizes: never the same).
_MARKER = ".roboisf-output.json"


def _same_bytes(a: Path, b: Path) -> list[str]:
    """The files of output folder ``a`` whose bytes differ from ``b``'s (or are missing), its
    ownership marker aside."""
    diff = []
    for f in sorted(p for p in a.rglob("*") if p.is_file() and p.name != _MARKER):
        g = b / f.relative_to(a)
        if not g.is_file() or g.read_bytes() != f.read_bytes():
            diff.append(str(f.relative_to(a)))
    return diff


def _paper_cone(root: Path, scan_points: int, force_rate: float) -> Path:
    from roboisf.virtual.cell import build_study, paper_cone_cell

    cell = paper_cone_cell(scan_points=scan_points, force_rate=force_rate)
    return Path(build_study(cell, root / cell.name))


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    command = argv[argv.index("--") + 1 :] if "--" in argv else None
    argv = argv[: argv.index("--")] if "--" in argv else argv
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("rev", help="the older revision (git), e.g. HEAD~1 or a commit")
    ap.add_argument("--runs", type=int, default=10, help="pairs of runs (default 10)")
    ap.add_argument("--study", type=Path, default=None, help="analyze this study (paper cone)")
    ap.add_argument("--scan-points", type=int, default=2_000_000)
    ap.add_argument("--force-rate", type=float, default=1000.0)
    ap.add_argument("--compare", action="store_true", help="both sides wrote the same bytes")
    a = ap.parse_args(argv)
    if a.runs < 1:
        ap.error("--runs must be at least 1")

    tmp = Path(tempfile.mkdtemp(prefix="roboisf-against-"))
    tree = tmp / "old"
    try:
        subprocess.run(
            ["git", "-C", str(REPO), "worktree", "add", "--detach", "-q", str(tree), a.rev],
            check=True,
        )
        built = subprocess.run(
            [sys.executable, "-m", "roboisf.jit.native"],
            cwd=tree,
            env=dict(os.environ, PYTHONPATH=str(tree / "src")),
            capture_output=True,
            text=True,
        )
        if built.returncode != 0:
            print(f"note: the old tree's C kernels did not all build:\n{built.stderr[-2000:]}")
        study = a.study
        if command is None and study is None:
            t = time.perf_counter()
            study = _paper_cone(tmp, a.scan_points, a.force_rate)
            dt = time.perf_counter() - t
            print(f"paper cone built ({a.scan_points:,} scan points): {dt:.1f} s")
        sides = {"old": tree / "src", "new": REPO / "src"}
        outs = {name: tmp / f"out-{name}" for name in sides}

        def args_of(name: str) -> list[str]:
            if command is None:
                return ["analyze", str(study), "-o", str(outs[name]), "-q"]
            return [w.replace("{out}", str(outs[name])) for w in command]

        for name, src in sides.items():  # once each, not timed: bytecode written, caches warm
            _run(src, args_of(name))
        print(speed_line(), flush=True)
        rows: dict[str, list[tuple[float, float, float]]] = {name: [] for name in sides}
        for i in range(a.runs):
            for name, src in sides.items() if i % 2 == 0 else reversed(sides.items()):
                r = _run(src, args_of(name))
                rows[name].append(r)
                line = f"  {name} {r[0]:6.2f} s  CPU {r[1]:5.2f} s  peak {r[2]:4.0f} MiB"
                print(line, flush=True)
        print(speed_line())
        med = {}
        for name, rs in rows.items():
            wall = [r[0] for r in rs]
            med[name] = statistics.median(wall)
            print(
                f"{name} ({a.rev if name == 'old' else 'this tree'}): median {med[name]:.3f} s, "
                f"mean {statistics.mean(wall):.3f} s, {min(wall):.2f}–{max(wall):.2f} s; CPU "
                f"median {statistics.median(r[1] for r in rs):.2f} s; peak ≤ "
                f"{max(r[2] for r in rs):.0f} MiB"
            )
        print(f"new / old (medians): {med['new'] / med['old']:.3f}")
        if a.compare:
            diff = _same_bytes(outs["old"], outs["new"]) + _same_bytes(outs["new"], outs["old"])
            differ = ", ".join(sorted(set(diff)))
            print("same bytes" if not diff else f"files that differ: {differ}")
        return 0
    finally:
        subprocess.run(
            ["git", "-C", str(REPO), "worktree", "remove", "--force", str(tree)],
            capture_output=True,
        )
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    raise SystemExit(main())
